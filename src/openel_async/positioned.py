"""Positioned, strict documents: YAML that remembers where each key was, and the error
that says ``FILE:LINE:COL``.

Every configuration document the project reads (RTC profiles, system files, rig files,
MuJoCo descriptions) refuses keys it does not know.  This module holds what they share:

* :func:`load_yaml` parses YAML (:data:`SAFE_LOADER`: PyYAML's libyaml-backed
  ``CSafeLoader`` where the wheel has libyaml, else ``SafeLoader``; or a subclass of it) and keeps the
  line and column of every mapping key, value and sequence item, so that a refusal
  found later, on the plain data, can still point into the file.  YAML syntax errors
  and duplicate keys are refused with the file name the caller gives (never
  ``<unicode string>``).
* :class:`DocumentError` carries the file, line, column, the key path and the message;
  ``str()`` is ``"FILE:LINE:COL: message"``.
* :func:`unknown_key_message` words a refused key with a "did you mean" for near misses
  (:func:`difflib.get_close_matches`) and the allowed keys.
* :class:`XmlPositions` parses XML (DTDs, and so entities, refused) and keeps where
  each element and attribute is written, columns counted in characters.
* :func:`convert` runs :func:`msgspec.convert` into structs declared with
  ``forbid_unknown_fields=True`` and turns msgspec's ``$.a[0].b`` error path back into
  a position in the file.
"""

from __future__ import annotations

import difflib
import re
import xml.etree.ElementTree as ET
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, TypeVar

import defusedxml.ElementTree as DefusedET
import msgspec
import yaml
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode

SAFE_LOADER: type[yaml.SafeLoader] = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
"""The safe loader every document of the project is parsed with: libyaml's parser (about
ten times faster than the pure-Python one) under PyYAML's safe constructor."""
SAFE_DUMPER: type[yaml.SafeDumper] = getattr(yaml, "CSafeDumper", yaml.SafeDumper)
"""The safe dumper the project writes YAML with (libyaml's emitter where present)."""

__all__ = [
    "SAFE_DUMPER",
    "SAFE_LOADER",
    "DocumentError",
    "Location",
    "XmlPositions",
    "YamlDocument",
    "convert",
    "did_you_mean",
    "is_namespaced",
    "load_yaml",
    "relocate",
    "unknown_key_message",
]

_T = TypeVar("_T")
_E = TypeVar("_E", bound=BaseException)
_MERGE_TAG = "tag:yaml.org,2002:merge"


@dataclass(frozen=True, slots=True)
class Location:
    """A place in a file; ``line`` and ``column`` count from 1 (None: the whole file)."""

    source: str
    line: int | None = None
    column: int | None = None

    def __str__(self) -> str:
        if self.line is None:
            return self.source
        if self.column is None:
            return f"{self.source}:{self.line}"
        return f"{self.source}:{self.line}:{self.column}"


class DocumentError(ValueError):
    """A document refused: ``location`` (file, line, column), ``path`` (the key path,
    e.g. ``rtcProfile.basicInfo``) and ``message``; ``str()`` is
    ``"FILE:LINE:COL: message"``."""

    def __init__(self, message: str, *, path: str = "", location: Location | None = None) -> None:
        super().__init__(f"{location}: {message}" if location is not None else message)
        self.message = message
        self.path = path
        self.location = location

    @property
    def source(self) -> str | None:
        return None if self.location is None else self.location.source

    @property
    def line(self) -> int | None:
        return None if self.location is None else self.location.line

    @property
    def column(self) -> int | None:
        return None if self.location is None else self.location.column


def relocate(error: _E, cause: DocumentError) -> _E:
    """``error`` (a project error type such as BadParameterError) worded as ``cause``:
    its text becomes ``str(cause)`` and it carries ``cause``'s location, path and message
    as attributes (``location``, ``source``, ``line``, ``column``)."""
    error.args = (str(cause),)
    for name in ("location", "source", "line", "column"):
        setattr(error, name, getattr(cause, name))
    return error


def did_you_mean(key: str, allowed: Iterable[str]) -> str:
    """``"did you mean 'x'?; allowed: a, b"`` (without the suggestion when none is close)."""
    names = sorted(dict.fromkeys(allowed))
    close = difflib.get_close_matches(key, names, n=1, cutoff=0.6)
    hint = f"did you mean {close[0]!r}?; " if close else ""
    return f"{hint}allowed: {', '.join(names) if names else 'none'}"


def unknown_key_message(key: object, where: str, allowed: Iterable[str]) -> str:
    """``"unknown key 'executionRat' in rtcProfile.basicInfo (did you mean
    'executionRate'?; allowed: ...)"``."""
    inside = f" in {where}" if where else ""
    return f"unknown key {_shown(key)}{inside} ({did_you_mean(str(key), allowed)})"


def is_namespaced(key: str) -> bool:
    """True for ``prefix:name`` and ``prefix::name`` keys (and ``{uri}name``): the keys
    that mark themselves as extensions."""
    if key.startswith("{") and "}" in key:
        return True
    prefix, sep, name = key.partition(":")
    return bool(sep and prefix and name.lstrip(":"))


def _shown(key: object) -> str:
    text = repr(key)
    return text if len(text) <= 60 else text[:60] + "..."


# -- YAML with positions ----------------------------------------------------------------------


def _location(source: str, mark: yaml.Mark | None) -> Location:
    if mark is None:
        return Location(source)
    return Location(source, mark.line + 1, mark.column + 1)


@dataclass(slots=True)
class _Marks:
    container: object  # kept alive, so that its id stays unique
    start: yaml.Mark
    keys: dict[object, tuple[yaml.Mark, yaml.Mark]]  # mapping: key -> (key mark, value mark)
    items: list[yaml.Mark]  # sequence: the item marks


class YamlDocument:
    """A YAML document (``data``) and the position of every key, value and item in it.

    Positions are looked up by container *object*: pass the very mapping or list found
    in ``data`` (not a copy)."""

    def __init__(self, data: object, source: str, marks: dict[int, _Marks]) -> None:
        self.data = data
        self.source = source
        self._marks = marks

    def where(self, container: object = None) -> Location:
        """Where a mapping or list starts (the whole file when unknown)."""
        marks = self._marks.get(id(container))
        return _location(self.source, marks.start if marks else None)

    def key(self, mapping: object, key: object) -> Location:
        """Where ``key`` is written in ``mapping`` (the mapping's start when absent)."""
        marks = self._marks.get(id(mapping))
        if marks is None:
            return Location(self.source)
        pair = marks.keys.get(key)
        return _location(self.source, pair[0] if pair else marks.start)

    def value(self, container: object, key: object) -> Location:
        """Where the value under ``key`` (a mapping key or a list index) is written."""
        marks = self._marks.get(id(container))
        if marks is None:
            return Location(self.source)
        if isinstance(key, int) and marks.items:
            return _location(self.source, marks.items[key] if key < len(marks.items) else None)
        pair = marks.keys.get(key)
        return _location(self.source, pair[1] if pair else marks.start)

    def follow(self, path: Sequence[str | int], start: object = None) -> tuple[object, Location]:
        """The value at ``path`` (keys and indices from ``start``, default ``data``) and
        its location; stops at the deepest part of the path that exists."""
        node: object = self.data if start is None else start
        location = self.where(node)
        for part in path:
            found = (isinstance(node, Mapping) and part in node) or (
                isinstance(node, list) and isinstance(part, int) and 0 <= part < len(node)
            )
            if not found:
                break
            location = self.value(node, part)
            node = node[part]  # type: ignore[index]
        return node, location

    def key_error(
        self, mapping: object, key: object, where: str, allowed: Iterable[str]
    ) -> DocumentError:
        """The error for an unknown ``key`` of ``mapping`` (at the key's position)."""
        return DocumentError(
            unknown_key_message(key, where, allowed),
            path=where,
            location=self.key(mapping, key),
        )

    def check_keys(self, mapping: Mapping[Any, Any], where: str, allowed: Iterable[str]) -> None:
        """Refuse the first key of ``mapping`` (in file order) not in ``allowed``."""
        known = set(allowed)
        for key in mapping:
            if key not in known:
                raise self.key_error(mapping, key, where, known)


def _marking_loader(base: type[yaml.SafeLoader]) -> type[yaml.SafeLoader]:
    class _Marking(base):  # type: ignore[valid-type,misc]
        """Remembers the object built for every node; refuses duplicate keys."""

        def __init__(self, stream: str | bytes) -> None:
            super().__init__(stream)
            self.built: list[tuple[Node, object]] = []

        def construct_object(self, node: Node, deep: bool = False) -> Any:
            obj = super().construct_object(node, deep=deep)
            self.built.append((node, obj))
            return obj

        def construct_mapping(self, node: MappingNode, deep: bool = False) -> Any:
            seen: dict[tuple[str, str], Node] = {}
            for key_node, _ in node.value:
                if not isinstance(key_node, ScalarNode) or key_node.tag == _MERGE_TAG:
                    continue
                ident = (key_node.tag, key_node.value)
                if ident in seen:
                    first = seen[ident].start_mark
                    raise yaml.constructor.ConstructorError(
                        None,
                        None,
                        f"duplicate key {key_node.value!r} (first at line {first.line + 1}, "
                        f"column {first.column + 1})",
                        key_node.start_mark,
                    )
                seen[ident] = key_node
            return super().construct_mapping(node, deep=deep)

    return _Marking


def _marks_of(built: list[tuple[Node, object]]) -> dict[int, _Marks]:
    objects: dict[int, object] = {id(node): obj for node, obj in built}
    marks: dict[int, _Marks] = {}
    for node, obj in built:
        if id(obj) in marks:
            continue
        if isinstance(node, MappingNode) and isinstance(obj, Mapping):
            keys: dict[object, tuple[yaml.Mark, yaml.Mark]] = {}
            for key_node, value_node in node.value:
                key = objects.get(id(key_node), key_node.value)
                try:
                    keys.setdefault(key, (key_node.start_mark, value_node.start_mark))
                except TypeError:  # an unhashable key (refused later by the schema)
                    continue
            marks[id(obj)] = _Marks(obj, node.start_mark, keys, [])
        elif isinstance(node, SequenceNode) and isinstance(obj, list):
            items = [item.start_mark for item in node.value]
            marks[id(obj)] = _Marks(obj, node.start_mark, {}, items)
    return marks


def load_yaml(
    text: str | bytes, source: str, *, loader: type[yaml.SafeLoader] = SAFE_LOADER
) -> YamlDocument:
    """Parse one YAML document, keeping positions; DocumentError naming ``source``, the
    line and the column for invalid YAML (and for duplicate keys)."""
    marking = _marking_loader(loader)
    parser: Any = None
    try:
        parser = marking(text)  # a SafeLoader subclass: safe
        data = parser.get_single_data()
    except yaml.reader.ReaderError as exc:
        raise DocumentError(
            f"invalid YAML: {exc.reason} (character #x{exc.character:04x})",
            location=_text_location(text, source, exc.position),
        ) from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        problem = exc.problem or exc.context or "invalid YAML"
        if exc.context and exc.problem and exc.context not in problem:
            where = exc.context_mark
            if where is not None and mark is not None and where.line != mark.line:
                problem = (
                    f"{problem} ({exc.context} started at line {where.line + 1}, "
                    f"column {where.column + 1})"
                )
            else:
                problem = f"{problem} ({exc.context})"
        raise DocumentError(f"invalid YAML: {problem}", location=_location(source, mark)) from None
    except yaml.YAMLError as exc:
        raise DocumentError(f"invalid YAML: {exc}", location=Location(source)) from None
    except RecursionError:
        raise DocumentError("invalid YAML: nested too deeply", location=Location(source)) from None
    except (ValueError, TypeError, OverflowError) as exc:
        # SafeConstructor lets some bad explicit tags through (e.g. "!!int abc").
        raise DocumentError(f"invalid YAML value: {exc}", location=Location(source)) from None
    finally:
        if parser is not None:
            parser.dispose()
    return YamlDocument(data, source, _marks_of(parser.built))


def _text_location(text: str | bytes, source: str, position: int) -> Location:
    """The line and column of a character (a byte, for undecodable bytes) offset."""
    if isinstance(text, bytes):
        text = text.decode("utf-8", "replace")
    before = text[:position]
    line = before.count("\n") + 1
    return Location(source, line, position - (before.rfind("\n") + 1) + 1)


# -- XML ---------------------------------------------------------------------------------------

_XML_NS = "http://www.w3.org/XML/1998/namespace"  # bound to ``xml:`` without a declaration
_TAG = re.compile(rb"<[^\s/>]+")
_ATTRIBUTE = re.compile(rb"""\s+([^\s=/>]+)\s*=\s*("[^"]*"|'[^']*')""")


class XmlPositions:
    """Where each element of a parsed XML document starts (expat's line and column,
    counted in characters), where its attributes are written, and the namespace
    prefixes in scope at it.

    :meth:`parse` refuses DTDs (so entity declarations and external entities never
    reach expat) and raises defusedxml's and :class:`xml.etree.ElementTree.ParseError`
    as they are: callers word them."""

    def __init__(self, source: str) -> None:
        self.source = source
        self._raw: bytes | None = None  # UTF-8 bytes of the document, when known
        self._starts: dict[int, tuple[int, int, int]] = {}
        self._scopes: dict[int, dict[str, str]] = {}
        self._keep: list[ET.Element] = []  # ids stay unique while the positions live

    def parse(self, text: str | bytes) -> ET.Element:
        """Parse ``text`` (DTDs refused), recording every element's position."""
        if isinstance(text, str):
            self._raw = text.encode("utf-8", "surrogatepass")
        else:
            self._raw = None if text.startswith((b"\xff\xfe", b"\xfe\xff")) else text
        builder = _PositionedBuilder(self)
        parser = DefusedET.DefusedXMLParser(target=builder, forbid_dtd=True)
        builder.parser = parser.parser
        parser.feed(text)
        root: ET.Element = parser.close()
        return root

    def _started(
        self, elem: ET.Element, line: int, column: int, offset: int, scope: dict[str, str]
    ) -> None:
        self._keep.append(elem)
        self._starts[id(elem)] = (line, column, offset)
        self._scopes[id(elem)] = scope

    def namespaces(self, elem: ET.Element) -> dict[str, str]:
        """The prefixes in scope at ``elem`` (``""``: the default namespace)."""
        return self._scopes.get(id(elem), {})

    def _at(self, offset: int, line: int, column: int) -> Location:
        """The location of a byte offset, its column counted in characters (expat's
        columns count bytes); expat's line and column when the bytes are not known."""
        if self._raw is None or offset < 0:
            return Location(self.source, line, column + 1)
        start = self._raw.rfind(b"\n", 0, offset) + 1
        chars = len(self._raw[start:offset].decode("utf-8", "replace"))
        return Location(self.source, self._raw.count(b"\n", 0, offset) + 1, chars + 1)

    def element(self, elem: ET.Element) -> Location:
        """Where ``elem``'s start tag is (the document when unknown)."""
        start = self._starts.get(id(elem))
        if start is None:
            return Location(self.source)
        line, column, offset = start
        return self._at(offset, line, column)

    def attribute(self, elem: ET.Element, name: str) -> Location:
        """Where the attribute ``name`` (a Clark name) of ``elem`` is written (the
        element's start when it cannot be told)."""
        start = self._starts.get(id(elem))
        if start is None or self._raw is None:
            return self.element(elem)
        line, column, offset = start
        scope = self.namespaces(elem)
        tag = _TAG.match(self._raw, offset)
        pos = tag.end() if tag is not None else len(self._raw)
        while (m := _ATTRIBUTE.match(self._raw, pos)) is not None:
            written = m.group(1).decode("utf-8", "replace")
            prefix, colon, local = written.partition(":")
            uri = scope.get(prefix, _XML_NS if prefix == "xml" else prefix)
            clark = f"{{{uri}}}{local}" if colon else written
            if clark == name:
                return self._at(m.start(1), line, column)
            pos = m.end()
        return self.element(elem)


class _PositionedBuilder(ET.TreeBuilder):
    """A TreeBuilder that tells its :class:`XmlPositions` where each element starts
    and which namespace prefixes are in scope there."""

    def __init__(self, positions: XmlPositions) -> None:
        super().__init__()
        self._positions = positions
        self.parser: Any = None  # the expat parser, set once it exists
        self._scope: list[tuple[str, str]] = []
        self._marks: list[int] = []
        self._pending = 0

    def start_ns(self, prefix: str, uri: str) -> None:
        self._scope.append((prefix, uri))
        self._pending += 1

    def start(self, tag: str, attrs: dict[str, str]) -> ET.Element:
        elem = super().start(tag, attrs)
        self._marks.append(self._pending)
        self._pending = 0
        p = self.parser
        if p is not None:
            self._positions._started(
                elem,
                p.CurrentLineNumber,
                p.CurrentColumnNumber,
                p.CurrentByteIndex,
                dict(self._scope),
            )
        return elem

    def end(self, tag: str) -> ET.Element:
        count = self._marks.pop() if self._marks else 0
        if count:
            del self._scope[-count:]
        return super().end(tag)


# -- msgspec structs --------------------------------------------------------------------------

_AT = re.compile(r"^(?P<message>.*?)(?: - at `(?:(?P<key>key) in )?(?P<path>\$[^`]*)`)?$", re.S)
_PART = re.compile(r"\.([^.\[]+)|\[(\d+|\.\.\.)\]")
_UNKNOWN = re.compile(r"^Object contains unknown field `(?P<field>.*)`$", re.S)


_ANY = None  # a dict value in msgspec's path: it does not say which key


def _parse_path(path: str) -> list[str | int | None]:
    parts: list[str | int | None] = []
    for m in _PART.finditer(path[1:]):
        if m.group(1) is not None:
            parts.append(m.group(1))
        elif m.group(2) == "...":
            parts.append(_ANY)
        else:
            parts.append(int(m.group(2)))
    return parts


def _resolve(node: object, parts: Sequence[str | int | None], key: str | None) -> list[str | int]:
    """``parts`` as far as they resolve in ``node``; a dict wildcard is resolved only for
    an unknown field ``key``: to the first entry whose value, at the rest of the path,
    holds ``key`` (a wrong type stops at the dict rather than guess)."""
    out: list[str | int] = []
    for i, part in enumerate(parts):
        if part is _ANY:
            if key is None or not isinstance(node, Mapping):
                return out
            for name, value in node.items():
                rest = _resolve(value, parts[i + 1 :], key)
                if len(rest) == len(parts) - i - 1:
                    reached = _walk(value, rest)
                    if isinstance(reached, Mapping) and key in reached:
                        return [*out, name, *rest]
            return out
        found = (isinstance(node, Mapping) and part in node) or (
            isinstance(node, list) and isinstance(part, int) and 0 <= part < len(node)
        )
        if not found:
            return out
        node = node[part]  # type: ignore[index]
        out.append(part)
    return out


def _walk(node: object, path: Sequence[str | int]) -> object:
    for part in path:
        node = node[part]  # type: ignore[index]  # a resolved path
    return node


def _struct_fields(info: msgspec.inspect.Type, path: Sequence[str | int]) -> list[str]:
    """The field names of the struct reached by ``path`` from ``info``."""
    for part in [*path, None]:
        while isinstance(info, msgspec.inspect.UnionType):
            structs = [
                t
                for t in info.types
                if isinstance(
                    t,
                    msgspec.inspect.StructType
                    | msgspec.inspect.ListType
                    | msgspec.inspect.DictType,
                )
            ]
            if not structs:
                return []
            info = structs[0]
        if part is None:
            break
        if isinstance(info, msgspec.inspect.StructType) and isinstance(part, str):
            match = [f.type for f in info.fields if f.encode_name == part]
            if not match:
                return []
            info = match[0]
        elif isinstance(info, msgspec.inspect.ListType | msgspec.inspect.DictType):
            info = info.item_type if isinstance(info, msgspec.inspect.ListType) else info.value_type
        else:
            return []
    if isinstance(info, msgspec.inspect.StructType):
        return [f.encode_name for f in info.fields]
    return []


def _dotted(root: str, path: Sequence[str | int]) -> str:
    out = root
    for part in path:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out


def convert(doc: YamlDocument, data: object, type: type[_T], root: str) -> _T:
    """``msgspec.convert(data, type)`` (``data`` is ``doc.data`` or a part of it reached
    through ``doc``); a refusal is a DocumentError at the offending key or value, named
    from ``root`` (e.g. ``rig.components[0].hal_id``), with "did you mean" for unknown
    fields."""
    try:
        return msgspec.convert(data, type)
    except msgspec.ValidationError as exc:
        m = _AT.match(str(exc))
        assert m is not None  # the pattern matches any text
        message = m.group("message")
        unknown = _UNKNOWN.match(message)
        key = unknown.group("field") if unknown is not None else None
        path = _resolve(data, _parse_path(m.group("path") or "$"), key)
        container, location = doc.follow(path, data)
        where = _dotted(root, path)
        if key is not None:
            allowed = _struct_fields(msgspec.inspect.type_info(type), path)
            raise DocumentError(
                unknown_key_message(key, where, allowed),
                path=where,
                location=doc.key(container, key),
            ) from None
        if m.group("key"):
            message = f"{message} for a key"
        message = message.replace("`", "'")
        raise DocumentError(f"{where}: {message}", path=where, location=location) from None
