"""rtsys XML checked against OpenRTP's own schema (``schema/RtsProfile.xsd`` and
``schema/RtsProfile_ext.xsd``, shipped with this package; see ``schema/README.md``).

Every element and attribute in the ``rts`` and ``rtsExt`` namespaces must be one the
schema declares for the element it is in: the element's ``xsi:type`` when it has one
(which must name a type derived from the declared one), else the declared type or an
``rtsExt`` extension of it (RTSystemEditor writes ``rtsExt:comment`` on
``rts:RtsProfile`` without ``xsi:type``).  Unqualified names are refused too (the
schema qualifies every name).  Names in any other namespace are extensions and are
kept out of the check, as the RTC Profile readers keep ``rtcExt``-style extensions.

What the schema says beyond names (child order, required attributes, enumerations,
value types) is not enforced: RTSystemEditor reads rtsys files without the schema, and
real files written by RTSystemEditor, rtshell and Choreonoid break those rules
(``rtsExt:Properties`` before ``rts:DataPorts``, no ``rts:creationDate``,
``rtsExt:direction="right"``).  The values this runtime uses are checked by the loader.

Positions: every element's start (expat's) and every attribute's (found in the start
tag's text), with columns counted in characters.
"""

from __future__ import annotations

import difflib
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from functools import cache
from importlib.resources import files
from typing import TYPE_CHECKING, Any

from defusedxml import DefusedXmlException

from ...positioned import Location, XmlPositions, did_you_mean
from .model import SystemFileError

if TYPE_CHECKING:
    import xmlschema

__all__ = ["RTS_EXT_NS", "RTS_NS", "RtsysDocument", "check_rtsys", "parse_rtsys", "schema"]

RTS_NS = "http://www.openrtp.org/namespaces/rts"
RTS_EXT_NS = "http://www.openrtp.org/namespaces/rts_ext"
XSI_NS = "http://www.w3.org/2001/XMLSchema-instance"
XML_NS = "http://www.w3.org/XML/1998/namespace"
SCHEMA_DIR = "schema"
SCHEMA_FILE = "RtsProfile_ext.xsd"
_PREFIXES = {RTS_NS: "rts", RTS_EXT_NS: "rtsExt", XSI_NS: "xsi", XML_NS: "xml"}
_XSI_TYPE = f"{{{XSI_NS}}}type"
# OpenRTP's other namespaces: not near misses of rts/rts_ext
_OTHER_OPENRTP = frozenset(
    f"http://www.openrtp.org/namespaces/{n}" for n in ("rtc", "rtc_ext", "rtc_doc", "rts_doc")
)
_ROOT = "rts:RtsProfile"
_CHECKED = (RTS_NS, RTS_EXT_NS, None)  # None: unqualified names


@cache
def schema() -> xmlschema.XMLSchema:
    """OpenRTP's RtsProfile_ext.xsd (which imports RtsProfile.xsd), loaded once, on
    first use (importing xmlschema costs about a second)."""
    import xmlschema

    path = files(__package__).joinpath(SCHEMA_DIR).joinpath(SCHEMA_FILE)
    return xmlschema.XMLSchema(str(path))


@dataclass(frozen=True, slots=True)
class _Type:
    name: str
    elements: dict[str, str | None]  # child element -> its type (None: a simple type)
    attributes: frozenset[str]


@dataclass(frozen=True, slots=True)
class _Names:
    types: dict[str, _Type]
    derived: dict[str, frozenset[str]]  # type -> the types derived from it (itself too)
    extensions: dict[str, frozenset[str]]  # type -> itself and its direct rtsExt extensions
    root_type: str


@cache
def _names() -> _Names:
    """The element and attribute names of every complex type of the schema."""
    maps = schema().maps
    types: dict[str, _Type] = {}
    bases: dict[str, str] = {}
    for name, xsd_type in maps.types.items():
        if not name.startswith((f"{{{RTS_NS}}}", f"{{{RTS_EXT_NS}}}")):
            continue
        content: Any = getattr(xsd_type, "content", None)
        elements: dict[str, str | None] = {}
        if content is not None and hasattr(content, "iter_elements"):
            for element in content.iter_elements():
                child_type = element.type
                elements[element.name] = child_type.name if child_type.is_complex() else None
        attributes = frozenset(a for a in getattr(xsd_type, "attributes", {}) if a)
        types[name] = _Type(name, elements, attributes)
        base = getattr(xsd_type, "base_type", None)
        if base is not None and base.name in maps.types:
            bases[name] = base.name
    derived: dict[str, set[str]] = {name: {name} for name in types}
    for name in types:
        base = bases.get(name)
        while base is not None:
            derived.setdefault(base, {base}).add(name)
            base = bases.get(base)
    extensions = {
        name: frozenset(
            {name}
            | {t for t, b in bases.items() if b == name and t.startswith(f"{{{RTS_EXT_NS}}}")}
        )
        for name in types
    }
    root = str(maps.elements[f"{{{RTS_NS}}}RtsProfile"].type.name)
    return _Names(types, {k: frozenset(v) for k, v in derived.items()}, extensions, root)


def _split(name: str) -> tuple[str | None, str]:
    if name.startswith("{"):
        uri, _, local = name[1:].partition("}")
        return uri, local
    return None, name


def shown(name: str) -> str:
    """A Clark name as the schema's prefixes write it (``rts:portName``)."""
    uri, local = _split(name)
    if uri is None:
        return local
    prefix = _PREFIXES.get(uri)
    return f"{prefix}:{local}" if prefix else name


# -- parsing with positions ---------------------------------------------------------------


class RtsysDocument(XmlPositions):
    """A parsed rtsys file: ``root`` and the place of every element and attribute."""

    def __init__(self, source: str) -> None:
        super().__init__(source)
        self.root = ET.Element("placeholder")


def parse_rtsys(raw: str | bytes, source: str) -> RtsysDocument:
    """Parse (DTDs refused), keeping positions; SystemFileError located in ``source``
    for anything that is not well-formed XML."""
    doc = RtsysDocument(source)
    try:
        doc.root = doc.parse(raw)
    except ET.ParseError as exc:
        line, column = exc.position
        message = re.sub(r": line \d+, column \d+$", "", str(exc))
        raise SystemFileError("<document>", f"not a readable rtsys XML: {message}").at(
            Location(source, line, column + 1)
        ) from None
    except DefusedXmlException as exc:
        raise SystemFileError("<document>", f"unsafe XML refused: {exc}").at(
            Location(source)
        ) from None
    except (ValueError, LookupError, RecursionError) as exc:
        raise SystemFileError("<document>", f"not a readable rtsys XML: {exc}").at(
            Location(source)
        ) from None
    return doc


# -- the check ---------------------------------------------------------------------------


def _qname(value: str, scope: dict[str, str]) -> str:
    prefix, colon, local = value.strip().partition(":")
    if not colon:
        uri = scope.get("")
        return f"{{{uri}}}{prefix}" if uri else prefix
    return f"{{{scope.get(prefix, prefix)}}}{local}"


def _refuse(doc: RtsysDocument, path: str, message: str, location: Location) -> SystemFileError:
    return SystemFileError(path, message).at(location)


def _allowed(names: _Names, type_names: frozenset[str]) -> tuple[dict[str, str | None], set[str]]:
    elements: dict[str, str | None] = {}
    attributes: set[str] = set()
    for type_name in sorted(type_names):
        found = names.types.get(type_name)
        if found is not None:
            for child, child_type in found.elements.items():
                elements.setdefault(child, child_type)
            attributes |= found.attributes
    return elements, attributes


def _effective(
    doc: RtsysDocument, elem: ET.Element, declared: str, names: _Names, path: str
) -> frozenset[str]:
    """The types whose names ``elem`` may use: its xsi:type (derived from
    ``declared``), else ``declared`` and its rtsExt extensions."""
    written = elem.get(_XSI_TYPE)
    if written is None:
        return names.extensions.get(declared, frozenset({declared}))
    actual = _qname(written, doc.namespaces(elem))
    allowed = names.derived.get(declared, frozenset({declared}))
    if actual not in allowed:
        where = doc.attribute(elem, _XSI_TYPE)
        uri, _ = _split(actual)
        if uri not in (RTS_NS, RTS_EXT_NS):
            _extension(doc, uri, path, where)  # a namespace typo, said as such
        options = [shown(t) for t in allowed]
        raise _refuse(
            doc,
            path,
            f"xsi:type {written!r} is not a type this element can have "
            f"({did_you_mean(shown(actual), options)})",
            where,
        )
    return frozenset({actual})


def _extension(doc: RtsysDocument, uri: str | None, path: str, location: Location) -> None:
    """Accept a name in another namespace, unless that namespace is a near miss of
    rts/rts_ext (a typo in ``xmlns:rtsExt`` would turn every rtsExt name into an
    extension, silently)."""
    if uri is None or uri in _OTHER_OPENRTP:
        return
    close = difflib.get_close_matches(uri, (RTS_NS, RTS_EXT_NS), n=1, cutoff=0.9)
    if close:
        raise _refuse(
            doc,
            path,
            f"namespace {uri!r} is not OpenRTP's (did you mean {close[0]!r}?)",
            location,
        )


def _text(doc: RtsysDocument, elem: ET.Element, path: str) -> None:
    """Refuse text in an element the schema gives element-only content."""
    for text in (elem.text, *(child.tail for child in elem)):
        if text is not None and text.strip():
            shown_text = text.strip()
            shown_text = shown_text if len(shown_text) <= 40 else shown_text[:40] + "..."
            raise _refuse(
                doc,
                path,
                f"unexpected text {shown_text!r} (this element holds no text)",
                doc.element(elem),
            )


def _check(doc: RtsysDocument, elem: ET.Element, declared: str, names: _Names, path: str) -> None:
    types = _effective(doc, elem, declared, names, path)
    elements, attributes = _allowed(names, types)
    for name in elem.attrib:
        uri, _ = _split(name)
        if uri in (XSI_NS, XML_NS):
            continue  # xsi:type (checked above), xml:lang...
        if uri not in _CHECKED:
            _extension(doc, uri, path, doc.attribute(elem, name))
            continue
        if name not in attributes:
            raise _refuse(
                doc,
                path,
                f"unknown attribute {shown(name)!r} "
                f"({did_you_mean(shown(name), (shown(a) for a in attributes))}; "
                "extensions: names in another namespace)",
                doc.attribute(elem, name),
            )
    _text(doc, elem, path)
    counts: dict[str, int] = {}
    for child in elem:
        tag = child.tag
        if not isinstance(tag, str):
            continue  # comments, processing instructions
        uri, _ = _split(tag)
        if uri not in _CHECKED:
            _extension(doc, uri, path, doc.element(child))
            continue  # an extension element, with whatever it holds
        if tag not in elements:
            raise _refuse(
                doc,
                path,
                f"unknown element {shown(tag)!r} "
                f"({did_you_mean(shown(tag), (shown(e) for e in elements))}; "
                "extensions: names in another namespace)",
                doc.element(child),
            )
        index = counts.get(tag, 0)
        counts[tag] = index + 1
        child_path = f"{path}.{shown(tag)}[{index}]" if path != _ROOT else f"{shown(tag)}[{index}]"
        child_type = elements[tag]
        if child_type is None:
            if len(child) or child.attrib:
                raise _refuse(
                    doc,
                    child_path,
                    "holds text only (no attributes, no elements)",
                    doc.element(child),
                )
            continue
        _check(doc, child, child_type, names, child_path)


def check_rtsys(doc: RtsysDocument) -> None:
    """Refuse the first element or attribute (in document order) that OpenRTP's schema
    does not declare where it is written, with a "did you mean"."""
    names = _names()
    root = doc.root
    if root.tag != f"{{{RTS_NS}}}RtsProfile":
        raise _refuse(
            doc,
            "<document>",
            f"expected rts:RtsProfile ({{{RTS_NS}}}RtsProfile), got {root.tag}",
            doc.element(root),
        )
    _check(doc, root, names.root_type, names, _ROOT)
