"""The XML form of an RTC Profile (§3.1, §6, sample §9.2).

Parsing goes through defusedxml with DTDs forbidden: a profile never needs one, and
refusing it stops entity-expansion bombs and external entities before expat sees
them.  Known attributes are matched in their namespace (``rtc:``, ``rtcDoc:``,
``rtcExt:``) or unqualified (as in the §8.1 samples); element names accept the
spellings the spec uses in its schema and its samples (``VersionUpLogs`` and
``VersionUpLog``, ``propertyIsEqualTo`` and ``PropertyIsEqualTo``).  Writing
follows the XSD spelling and child order and declares ``xsi:type`` of the richest
profile an element uses.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from datetime import datetime

from defusedxml import (
    DefusedXmlException,
    DTDForbidden,
    EntitiesForbidden,
    ExternalReferenceForbidden,
)

from ...positioned import Location, XmlPositions, did_you_mean
from ..constraints import (
    RTC_NS,
    Constraint,
    ConstraintError,
    constraint_from_xml,
    constraint_to_xml,
)
from ._codec import Sink, SinkScalar, Source, is_extension_key, read_profile, write_profile
from .errors import MAX_DEPTH, MAX_NODES, ProfileError
from .model import Extra, ExtraValue, Position, RtcProfile, validate_profile

__all__ = [
    "DOC_NS",
    "EXT_NS",
    "RTC_NS",
    "XSI_NS",
    "dumps_constraint_xml",
    "dumps_xml",
    "loads_constraint_xml",
    "loads_xml",
]

DOC_NS = "http://www.openrtp.org/namespaces/rtc_doc"
EXT_NS = "http://www.openrtp.org/namespaces/rtc_ext"
XSI_NS = "http://www.w3.org/2001/XMLSchema-instance"
PREFIXES = {RTC_NS: "rtc", DOC_NS: "rtcDoc", EXT_NS: "rtcExt", XSI_NS: "xsi"}
DOCUMENT = "<document>"
ROOT = "rtcProfile"
_XSI_TYPE = f"{{{XSI_NS}}}type"
_KEY_NS = {"rtcExt": EXT_NS, "rtcDoc": DOC_NS}

# YAML key -> (namespace, accepted element names (first is written), children's namespace)
# for the keys whose XML element is not just the key with a capital first letter.
_SPECIAL: dict[str, tuple[str, tuple[str, ...], str]] = {
    "rtcDoc::doc": (DOC_NS, ("Doc",), DOC_NS),
    "rtcExt::versionUpLogs": (EXT_NS, ("VersionUpLogs", "VersionUpLog"), EXT_NS),
    "rtcExt::property": (EXT_NS, ("Properties", "Property"), EXT_NS),
    "rtcExt::targets": (EXT_NS, ("targets",), EXT_NS),
    "transMethod": (RTC_NS, ("TransMethods", "TransMethod"), RTC_NS),
    "cpus": (EXT_NS, ("cpus",), EXT_NS),
    "osVersions": (EXT_NS, ("osVersions",), EXT_NS),
    "libraries": (EXT_NS, ("libraries",), EXT_NS),
    "constraint": (RTC_NS, ("Constraint",), RTC_NS),
}


def _split_clark(name: str) -> tuple[str | None, str]:
    if name.startswith("{"):
        uri, _, local = name[1:].partition("}")
        return uri, local
    return None, name


def _split(key: str, default_ns: str) -> tuple[str, str]:
    """(namespace, local name) of a YAML-style key."""
    uri, local = _split_clark(key)
    if uri is not None:
        return uri, local
    prefix, sep, rest = key.partition("::")
    if sep and prefix in _KEY_NS:
        return _KEY_NS[prefix], rest
    return default_ns, key


def _key(name: str, default_ns: str) -> str:
    """YAML-style key of an attribute/element name (inverse of ``_split``)."""
    uri, local = _split_clark(name)
    if uri is None or uri == default_ns:
        return local
    for prefix, ns in _KEY_NS.items():
        if uri == ns:
            return f"{prefix}::{local}"
    return name


def _child_spec(key: str, default_ns: str) -> tuple[str, tuple[str, ...], str]:
    special = _SPECIAL.get(key)
    if special is not None:
        return special
    ns, local = _split(key, default_ns)
    return ns, (local[:1].upper() + local[1:],), ns


def _element_extra(elem: ET.Element, path: str, depth: int) -> dict[str, ExtraValue]:
    """An unknown element as attributes, ``#text`` and grouped children."""
    if depth > MAX_DEPTH:
        raise ProfileError(path, f"nested deeper than {MAX_DEPTH} levels")
    ns = _split_clark(elem.tag)[0] or RTC_NS
    out: dict[str, ExtraValue] = {_key(k, ns): v for k, v in elem.attrib.items()}
    text = elem.text or ""
    if text.strip():
        # Text next to child elements is re-indented on writing, so keep it stripped.
        out["#text"] = text.strip() if len(elem) else text
    _add_children(out, list(elem), ns, path, depth)
    return out


def _add_children(
    out: dict[str, ExtraValue], children: list[ET.Element], ns: str, path: str, depth: int
) -> None:
    elements: set[str] = set()  # keys that came from elements (not attributes)
    groups: dict[str, list[ExtraValue]] = {}  # keys of repeated elements
    for child in children:
        key = _key(child.tag, ns)
        value = _element_value(child, f"{path}.{key}", depth + 1)
        if key not in out:
            out[key] = value
            elements.add(key)
        elif key not in elements:
            raise ProfileError(f"{path}.{key}", "name used by both an attribute and an element")
        elif key in groups:
            groups[key].append(value)
        else:
            groups[key] = out[key] = [out[key], value]


def _element_value(elem: ET.Element, path: str, depth: int) -> ExtraValue:
    """A text-only element (no attributes, no children) reads as its text, so that plain
    values written as repeated elements read back as the same list."""
    if not elem.attrib and not len(elem) and (elem.text or "").strip():
        return elem.text
    return _element_extra(elem, path, depth)


def _shown_name(name: str) -> str:
    """An attribute/element name as written with the spec's prefixes (rtc:executionRate)."""
    uri, local = _split_clark(name)
    if uri is None:
        return local
    return f"{PREFIXES.get(uri, '{' + uri + '}')}:{local}"


class _Places(XmlPositions):
    """Where each element starts in the document and its attributes are written, and
    which element each key path names."""

    def __init__(self, source: str) -> None:
        super().__init__(source)
        self._paths: dict[str, ET.Element] = {}

    def add(self, path: str, elem: ET.Element) -> None:
        self._paths.setdefault(path, elem)

    def locate(self, path: str) -> Location:
        """The position of the field an error path names (its nearest element's)."""
        best = ""
        for known in self._paths:
            if len(known) > len(best) and (
                path == known or path.startswith((known + ".", known + "["))
            ):
                best = known
        if not best:
            return Location(self.source)
        elem = self._paths[best]
        rest = path[len(best) :]
        if rest.startswith(".") and "." not in rest[1:] and "[" not in rest:
            ns, local = _split(rest[1:], RTC_NS)
            for name in (f"{{{ns}}}{local}", local):
                if name in elem.attrib:
                    return self.attribute(elem, name)
        return self.element(elem)


class _XmlSource(Source):
    def __init__(self, elem: ET.Element, path: str, ns: str, places: _Places) -> None:
        self._elem = elem
        self.path = path
        self._ns = ns
        self._used_attrs: set[str] = {_XSI_TYPE}
        self._used_children: set[int] = set()
        self._known: set[str] = set()  # names asked for, as written (rtc:name...)
        self._places = places
        places.add(path, elem)

    def raw(self, key: str) -> object:
        ns, local = _split(key, self._ns)
        self._known.add(_shown_name(f"{{{ns}}}{local}"))
        for name in (f"{{{ns}}}{local}", local):
            if name in self._elem.attrib:
                self._used_attrs.add(name)
                return self._elem.attrib[name]
        return None

    def _find(self, key: str) -> tuple[list[ET.Element], str]:
        ns, names, child_ns = _child_spec(key, self._ns)
        self._known.update(_shown_name(f"{{{ns}}}{n}") for n in names)
        wanted = {f"{{{ns}}}{n}" for n in names} | set(names)
        found: list[ET.Element] = []
        for i, child in enumerate(self._elem):
            if child.tag in wanted:
                self._used_children.add(i)
                found.append(child)
        return found, child_ns

    def child(self, key: str) -> Source | None:
        found, child_ns = self._find(key)
        if not found:
            return None
        if len(found) > 1:
            raise ProfileError(f"{self.path}.{key}", f"expected one element, got {len(found)}")
        return _XmlSource(found[0], f"{self.path}.{key}", child_ns, self._places)

    def children(self, key: str) -> list[Source]:
        found, child_ns = self._find(key)
        return [
            _XmlSource(e, f"{self.path}.{key}[{i}]", child_ns, self._places)
            for i, e in enumerate(found)
        ]

    def texts(self, key: str) -> list[object]:
        found, _ = self._find(key)
        for i, e in enumerate(found):
            if len(e):
                raise ProfileError(f"{self.path}.{key}[{i}]", "must contain only text")
        return [e.text or "" for e in found]

    def constraint(self, key: str) -> Constraint | None:
        found, _ = self._find(key)
        path = f"{self.path}.{key}"
        if not found:
            return None
        if len(found) > 1:
            raise ProfileError(path, f"expected one element, got {len(found)}")
        try:
            return constraint_from_xml(found[0], path)
        except ConstraintError as e:
            raise ProfileError(e.path or path, e.message) from None

    def has_ext(self, keys: Sequence[str]) -> bool:
        if self._elem.get(_XSI_TYPE, "").endswith("_ext"):
            return True
        for key in keys:
            ns, local = _split(key, self._ns)
            if f"{{{ns}}}{local}" in self._elem.attrib or local in self._elem.attrib:
                return True
            cns, names, _ = _child_spec(key, self._ns)
            tags = {f"{{{cns}}}{n}" for n in names}
            if any(child.tag in tags for child in self._elem):
                return True
        return False

    def unread(self) -> list[str]:
        attributes = [n for n in self._elem.attrib if n not in self._used_attrs]
        children = [c for i, c in enumerate(self._elem) if i not in self._used_children]
        return [_key(n, self._ns) for n in attributes] + [_key(c.tag, self._ns) for c in children]

    def locate(self, key: str) -> Location | None:
        for name in self._elem.attrib:
            if _key(name, self._ns) == key:
                return self._places.attribute(self._elem, name)
        for child in self._elem:
            if _key(child.tag, self._ns) == key:
                return self._places.element(child)
        return None

    def _refuse(self, what: str, name: str, location: Location) -> ProfileError:
        shown = _shown_name(name)
        return ProfileError(
            self.path,
            f"unknown {what} {shown!r} ({did_you_mean(shown, self._known)}; "
            "extensions: any name in a namespace other than rtc)",
            location=location,
        )

    def extras(self) -> dict[str, ExtraValue]:
        """The extension attributes/elements not read; anything else unknown (a name in
        the element's own or the rtc namespace, or text) is refused."""
        for name in self._elem.attrib:
            if name not in self._used_attrs and not is_extension_key(_key(name, self._ns)):
                where = self._places.attribute(self._elem, name)
                raise self._refuse("attribute", name, where)
        rest = [c for i, c in enumerate(self._elem) if i not in self._used_children]
        for child in rest:
            if not is_extension_key(_key(child.tag, self._ns)):
                raise self._refuse("element", child.tag, self._places.element(child))
        text = self._elem.text or ""
        if text.strip():
            raise ProfileError(
                self.path,
                f"unexpected text {_clip(text.strip())!r} (this element holds no text)",
                location=self._places.element(self._elem),
            )
        out: dict[str, ExtraValue] = {
            _key(k, self._ns): v for k, v in self._elem.attrib.items() if k not in self._used_attrs
        }
        _add_children(out, rest, self._ns, self.path, 1)
        return out


def _scalar_text(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, datetime):
        return value.isoformat()
    return str(value)


# XML 1.0 NCName (no colon), so an unknown YAML key never becomes markup; a namespace
# URI must not contain what would break the Clark notation or the declaration.
_NAME_START = "A-Z_a-z\u00c0-\u00d6\u00d8-\u00f6\u00f8-\u02ff\u0370-\u037d\u037f-\u1fff\u200c-\u200d\u2070-\u218f\u2c00-\u2fef\u3001-\ud7ff\uf900-\ufdcf\ufdf0-\ufffd\U00010000-\U000effff"
_NCNAME = re.compile(f"[{_NAME_START}][{_NAME_START}\\-.0-9\u00b7\u0300-\u036f\u203f-\u2040]*")
_URI = re.compile(r"[^\s{}<>\"'&\x00-\x1f]+")


def _clip(text: str) -> str:
    return text if len(text) <= 80 else text[:80] + "..."


def _check_writable(items: Sequence[ExtraValue], value: ExtraValue, path: str) -> None:
    """Refuse extras that XML cannot tell apart from another value when read back."""
    if not isinstance(value, Mapping) and len(items) < 2:
        raise ProfileError(
            path, "a list of fewer than 2 items cannot be told from one value in XML"
        )
    for item in items:
        if isinstance(item, Mapping):
            if set(item) == {"#text"}:
                raise ProfileError(
                    path, "a mapping of only '#text' reads back as plain text in XML"
                )
        elif isinstance(item, str):
            if not item.strip():
                raise ProfileError(path, "an empty text item cannot be written as an XML element")
        elif item is None or isinstance(item, Sequence):
            raise ProfileError(path, "an empty item or a list inside a list has no XML form")


def _write_extra(elem: ET.Element, extra: Extra, ns: str, path: str) -> None:
    for key, value in extra.items():
        if value is None:
            continue
        if key == "#text":
            elem.text = _scalar_text(value)
            continue
        uri, local = _split(key, ns)
        if not _NCNAME.fullmatch(local) or not _URI.fullmatch(uri):
            raise ProfileError(
                f"{path}.{_clip(key)}", "key cannot be written as an XML name (not an NCName)"
            )
        name = f"{{{uri}}}{local}"
        items: Sequence[ExtraValue]
        if isinstance(value, Mapping) or (
            isinstance(value, Sequence) and not isinstance(value, str)
        ):
            items = [value] if isinstance(value, Mapping) else value
            _check_writable(items, value, f"{path}.{_clip(key)}")
            for item in items:
                child = ET.SubElement(elem, name)
                if isinstance(item, Mapping):
                    _write_extra(child, item, uri, f"{path}.{key}")
                elif item is not None:
                    child.text = _scalar_text(item)
        elif name in elem.attrib:
            raise ProfileError(f"{path}.{key}", "extra key collides with a known field")
        else:
            elem.set(name, _scalar_text(value))


class _XmlSink(Sink):
    def __init__(self, elem: ET.Element, path: str, ns: str) -> None:
        self._elem = elem
        self._path = path
        self._ns = ns

    def scalar(self, key: str, value: SinkScalar | None) -> None:
        if value is not None:
            ns, local = _split(key, self._ns)
            self._elem.set(f"{{{ns}}}{local}", _scalar_text(value))

    def position(self, key: str, value: Position) -> None:
        self.scalar(key, value.value.upper())  # OpenRTP's RtcProfile_ext.xsd: LEFT, RIGHT...

    def child(self, key: str) -> Sink:
        ns, names, child_ns = _child_spec(key, self._ns)
        elem = ET.SubElement(self._elem, f"{{{ns}}}{names[0]}")
        return _XmlSink(elem, f"{self._path}.{key}", child_ns)

    def add(self, key: str) -> Sink:
        return self.child(key)

    def texts(self, key: str, values: Sequence[str]) -> None:
        ns, names, _ = _child_spec(key, self._ns)
        for value in values:
            ET.SubElement(self._elem, f"{{{ns}}}{names[0]}").text = value

    def constraint(self, key: str, value: Constraint | None) -> None:
        if value is not None:
            self._elem.append(constraint_to_xml(value, RTC_NS))

    def declare(self, base: str, *, doc: bool, ext: bool) -> None:
        # The ext types extend the doc types (§6.3), so ext covers both.
        if ext:
            self._elem.set(_XSI_TYPE, f"rtcExt:{base}_ext")
        elif doc:
            self._elem.set(_XSI_TYPE, f"rtcDoc:{base}_doc")

    def extras(self, extra: Extra) -> None:
        _write_extra(self._elem, extra, self._ns, self._path)


# --- parsing and serializing -------------------------------------------------------

_INVALID_CHAR = re.compile("[^\t\n\r\x20-\ud7ff\ue000-\ufffd\U00010000-\U0010ffff]")
_TEXT_ESCAPES = {"&": "&amp;", "<": "&lt;", ">": "&gt;", "\r": "&#13;"}
_ATTR_ESCAPES = {**_TEXT_ESCAPES, '"': "&quot;", "\n": "&#10;", "\t": "&#9;"}


def _escape(value: str, table: Mapping[str, str], where: str) -> str:
    bad = _INVALID_CHAR.search(value)
    if bad is not None:
        raise ProfileError(where, f"character {bad.group()!r} cannot be written in XML")
    return "".join(table.get(ch, ch) for ch in value)


def _serialize(root: ET.Element, *, declare_all: bool) -> str:
    """Indented XML with the spec's prefixes (ElementTree would invent ns0, ns1...)."""
    prefixes = dict(PREFIXES) if declare_all else {}
    for elem in root.iter():
        for name in (elem.tag, *elem.attrib):
            uri = _split_clark(name)[0]
            if uri is not None and uri not in prefixes:
                prefixes[uri] = PREFIXES.get(uri, f"ns{len(prefixes)}")

    def qname(name: str) -> str:
        uri, local = _split_clark(name)
        return local if uri is None else f"{prefixes[uri]}:{local}"

    lines = ['<?xml version="1.0" encoding="UTF-8" standalone="yes"?>']

    def emit(elem: ET.Element, level: int) -> None:
        tag = qname(elem.tag)
        attrs = [(qname(k), v) for k, v in elem.attrib.items()]
        if level == 0:
            attrs = [(f"xmlns:{p}", uri) for uri, p in prefixes.items()] + attrs
        head = "  " * level + "<" + tag
        head += "".join(f' {k}="{_escape(v, _ATTR_ESCAPES, tag)}"' for k, v in attrs)
        text = _escape(elem.text or "", _TEXT_ESCAPES, tag)
        if len(elem) == 0:
            lines.append(f"{head}>{text}</{tag}>" if text else f"{head}/>")
            return
        lines.append(f"{head}>{text}")
        for child in elem:
            emit(child, level + 1)
        lines.append("  " * level + f"</{tag}>")

    emit(root, 0)
    return "\n".join(lines) + "\n"


_DECLARATION = re.compile(
    rb"""^<\?xml[^>]*?encoding\s*=\s*(["'])([A-Za-z][A-Za-z0-9._-]*)\1""", re.ASCII
)
# Encodings expat reads itself; anything else is decoded here first.
_EXPAT_ENCODINGS = frozenset(
    {"utf-8", "utf8", "utf-16", "utf16", "iso-8859-1", "latin-1", "latin1", "us-ascii", "ascii"}
)


def _decode(data: bytes) -> str | bytes:
    """Bytes in an encoding expat cannot read (Shift_JIS, EUC-JP...) as text, decoded
    as their XML declaration says; other bytes are left to expat."""
    if data.startswith((b"\xef\xbb\xbf", b"\xff\xfe", b"\xfe\xff")):
        return data  # a BOM: UTF-8/16, expat's own
    m = _DECLARATION.match(data)
    if m is None or m.group(2).decode().lower() in _EXPAT_ENCODINGS:
        return data
    name = m.group(2).decode()
    try:
        text = data.decode(name)
    except LookupError:
        raise ProfileError(DOCUMENT, f"unknown encoding {name!r} in the XML declaration") from None
    except UnicodeDecodeError as e:
        raise ProfileError(DOCUMENT, f"not valid {name}: {e}") from None
    return text


def _check_budget(root: ET.Element) -> None:
    nodes = 0
    stack = [(root, 0)]
    while stack:
        elem, depth = stack.pop()
        if depth > MAX_DEPTH:
            raise ProfileError(DOCUMENT, f"nested deeper than {MAX_DEPTH} levels")
        nodes += 1 + 2 * len(elem.attrib) + (1 if (elem.text or "").strip() else 0)
        if nodes > MAX_NODES:
            raise ProfileError(DOCUMENT, f"more than {MAX_NODES} nodes")
        stack.extend((child, depth + 1) for child in elem)


def _parse(text: str | bytes, source: str = "<string>") -> tuple[ET.Element, _Places]:
    if isinstance(text, bytes):
        try:
            text = _decode(text)
        except ProfileError as e:
            raise e.at(Location(source)) from None
    places = _Places(source)
    try:
        root = _parse_safely(text, places)
        _check_budget(root)
    except ProfileError as e:
        raise e.at(Location(source)) from None
    return root, places


def _parse_safely(text: str | bytes, places: _Places) -> ET.Element:
    refused = "unsafe XML refused: "
    try:
        root = places.parse(text)
    except DTDForbidden:
        raise ProfileError(
            DOCUMENT,
            refused + "a DTD (<!DOCTYPE ...>) is not allowed: it can declare entities "
            "(entity expansion, external entities)",
        ) from None
    except EntitiesForbidden:
        raise ProfileError(DOCUMENT, refused + "entity declarations are not allowed") from None
    except ExternalReferenceForbidden:
        raise ProfileError(DOCUMENT, refused + "external references are not allowed") from None
    except DefusedXmlException as e:
        raise ProfileError(DOCUMENT, refused + str(e)) from None
    except ET.ParseError as e:
        line, column = e.position
        where = Location(places.source, line, column + 1)
        message = re.sub(r": line \d+, column \d+$", "", str(e))
        raise ProfileError(DOCUMENT, f"invalid XML: {message}", location=where) from None
    except (ValueError, LookupError, RecursionError) as e:
        raise ProfileError(DOCUMENT, f"invalid XML: {e}") from None
    return root


def loads_xml(text: str | bytes, source: str = "<string>") -> RtcProfile:
    """Parse and validate an XML RTC Profile; raises ProfileError only, located in
    ``source`` (the file name shown in messages) at the line and column of the field."""
    root, places = _parse(text, source)
    uri, local = _split_clark(root.tag)
    if local != "RtcProfile" or uri not in (RTC_NS, None):
        raise ProfileError(
            DOCUMENT,
            f"expected an rtc:RtcProfile root element, got {root.tag!r}",
            location=places.element(root),
        )
    try:
        profile = read_profile(_XmlSource(root, ROOT, RTC_NS, places))
        validate_profile(profile)
    except ProfileError as e:
        raise e.at(places.locate(e.path)) from None
    return profile


def dumps_xml(profile: RtcProfile) -> str:
    """The XML form of a profile (validated first; raises ProfileError)."""
    validate_profile(profile)
    root = ET.Element(f"{{{RTC_NS}}}RtcProfile")
    write_profile(profile, _XmlSink(root, ROOT, RTC_NS))
    _check_budget(root)  # never write what loads_xml would refuse
    return _serialize(root, declare_all=True)


def loads_constraint_xml(text: str | bytes) -> Constraint:
    """A standalone ``Constraint`` element (namespaced or not, as in §8.1)."""
    try:
        return constraint_from_xml(_parse(text)[0])
    except ConstraintError as e:
        raise ProfileError(e.path, e.message) from None


def dumps_constraint_xml(constraint: Constraint) -> str:
    """A standalone ``rtc:Constraint`` element."""
    return _serialize(constraint_to_xml(constraint), declare_all=False)
