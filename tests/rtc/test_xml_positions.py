"""XmlPositions: the one XML position tracker of the profile and rtsys readers."""

from __future__ import annotations

import pytest
from defusedxml import DTDForbidden

from openel_async.positioned import Location, XmlPositions

XML_NS = "http://www.w3.org/XML/1998/namespace"
TEXT = '<a xmlns:q="u">\n <bé q:x="1" xml:lang="en" y="2"/></a>'


@pytest.mark.parametrize("text", [TEXT, TEXT.encode()])
def test_elements_and_attributes_are_placed_in_characters(text: str | bytes) -> None:
    places = XmlPositions("f.xml")
    root = places.parse(text)
    child = root[0]
    assert places.element(root) == Location("f.xml", 1, 1)
    assert places.element(child) == Location("f.xml", 2, 2)
    assert places.attribute(child, "{u}x") == Location("f.xml", 2, 6)  # after 'é', one column
    assert places.attribute(child, f"{{{XML_NS}}}lang") == Location("f.xml", 2, 14)
    assert places.attribute(child, "y") == Location("f.xml", 2, 28)
    assert places.attribute(child, "missing") == places.element(child)
    assert places.namespaces(child) == {"q": "u"}


def test_a_dtd_is_refused() -> None:
    with pytest.raises(DTDForbidden):
        XmlPositions("f.xml").parse('<!DOCTYPE a [<!ENTITY e "x">]><a>&e;</a>')
