"""The YAML form of an RTC Profile (§3.2, §7, sample §9.3).

Loading uses PyYAML's safe loader (libyaml's parser where present; no Python object construction: ``!!python/...``
tags are refused) with one change: plain scalars stay strings and only null is
resolved implicitly, so ``version: 1.10`` or ``defaultValue: 010`` keep their text
instead of becoming the numbers 1.1 and 8; typed fields are converted by the schema.
Aliases are allowed (the spec's sample uses ``&58 LEFT`` / ``*58``) but the document
is walked with a node budget first, so alias bombs and self-referencing aliases are
refused instead of expanded.
"""

from __future__ import annotations

import copy
import re
from collections.abc import Mapping, Sequence
from datetime import datetime

import yaml

from ...positioned import (
    SAFE_DUMPER,
    SAFE_LOADER,
    DocumentError,
    Location,
    YamlDocument,
    did_you_mean,
    load_yaml,
)
from ..constraints import (
    Constraint,
    ConstraintError,
    constraint_from_yaml,
    constraint_to_yaml,
)
from ._codec import Sink, SinkScalar, Source, is_extension_key, read_profile, write_profile
from .errors import MAX_DEPTH, MAX_NODES, ProfileError
from .model import Extra, ExtraValue, Position, RtcProfile, validate_profile

__all__ = ["dumps_yaml", "loads_yaml"]

DOCUMENT = "<document>"
ROOT = "rtcProfile"
_NULL_TAG = "tag:yaml.org,2002:null"
_PLURALS = {"transMethod": "transMethods"}
"""Sequence keys RTCBuilder spells in the plural: their entries are read after those of
the spec's singular key (and written under the singular key)."""


class _ProfileLoader(SAFE_LOADER):  # type: ignore[valid-type,misc]
    """SafeLoader that resolves nothing but null implicitly (see module docstring)."""


_ProfileLoader.yaml_implicit_resolvers = {
    first: [(tag, regexp) for tag, regexp in resolvers if tag == _NULL_TAG]
    for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
}


def _check_budget(data: object) -> None:
    """Count nodes as if aliases were expanded; refuse bombs and cycles early."""
    stack: list[tuple[object, int]] = [(data, 0)]
    seen = 0
    while stack:
        node, depth = stack.pop()
        seen += 1
        if seen > MAX_NODES:
            raise ProfileError(DOCUMENT, f"more than {MAX_NODES} nodes (alias expansion?)")
        if depth > MAX_DEPTH:
            raise ProfileError(DOCUMENT, f"nested deeper than {MAX_DEPTH} levels")
        if isinstance(node, Mapping):
            stack.extend((k, depth + 1) for k in node)
            stack.extend((v, depth + 1) for v in node.values())
        elif isinstance(node, list):
            stack.extend((v, depth + 1) for v in node)


def _load(text: str | bytes, source: str) -> YamlDocument:
    try:
        doc = load_yaml(text, source, loader=_ProfileLoader)
    except DocumentError as e:
        raise ProfileError(DOCUMENT, e.message, location=e.location) from None
    try:
        _check_budget(doc.data)
    except ProfileError as e:
        raise e.at(Location(source)) from None
    return doc


def _mapping(data: object, path: str) -> Mapping[str, object]:
    """``data`` itself (not a copy: positions are looked up by object)."""
    if data is None:
        return {}
    if not isinstance(data, Mapping):
        kind = "a sequence" if isinstance(data, list) else type(data).__name__
        raise ProfileError(path, f"expected a mapping, got {kind}")
    for key in data:
        if not isinstance(key, str):
            raise ProfileError(path, f"keys must be strings, got {key!r}")
    return data


_PATH_PART = re.compile(r"\.([^.\[]+)|\[(\d+)\]")


class _Places:
    """Where the mappings read so far are in the file, by their error path."""

    def __init__(self, doc: YamlDocument) -> None:
        self.doc = doc
        self._mappings: dict[str, Mapping[str, object]] = {}

    def add(self, path: str, mapping: Mapping[str, object]) -> None:
        self._mappings.setdefault(path, mapping)

    def locate(self, path: str) -> Location:
        """The position of the field an error path names (its nearest known parent's
        when the field itself is not written)."""
        best = ""
        for known in self._mappings:
            if len(known) > len(best) and (
                path == known or path.startswith((known + ".", known + "["))
            ):
                best = known
        if not best:
            return Location(self.doc.source)
        mapping = self._mappings[best]
        rest: list[str | int] = [
            m.group(1) if m.group(1) is not None else int(m.group(2))
            for m in _PATH_PART.finditer(path[len(best) :])
        ]
        container = self.doc.follow(rest[:-1], mapping)[0]
        last = rest[-1] if rest else None
        if isinstance(container, Mapping) and last in container:
            return self.doc.key(container, last)  # the field's key
        if isinstance(container, list) and isinstance(last, int) and last < len(container):
            return self.doc.value(container, last)
        return self.doc.where(container)


def _extra_value(value: object, path: str) -> ExtraValue:
    if value is None or isinstance(value, str | bool | int | float):
        return value
    if isinstance(value, list):
        return [_extra_value(v, f"{path}[{i}]") for i, v in enumerate(value)]
    if isinstance(value, Mapping):
        return {k: _extra_value(v, f"{path}.{k}") for k, v in _mapping(value, path).items()}
    raise ProfileError(path, f"unsupported value of type {type(value).__name__}")


class _YamlSource(Source):
    def __init__(self, data: Mapping[str, object], path: str, places: _Places) -> None:
        self._data = data
        self.path = path
        self._used: set[str] = set()
        self._places = places
        places.add(path, data)

    def raw(self, key: str) -> object:
        self._used.add(key)
        return self._data.get(key)

    def child(self, key: str) -> Source | None:
        self._used.add(key)
        if key not in self._data:
            return None
        path = f"{self.path}.{key}"
        return _YamlSource(_mapping(self._data[key], path), path, self._places)

    def children(self, key: str) -> list[Source]:
        alias = _PLURALS.get(key)
        if alias is not None:  # RTCBuilder writes the plural (transMethods): both count
            return self._children(key) + self._children(alias)
        return self._children(key)

    def _children(self, key: str) -> list[Source]:
        self._used.add(key)
        path = f"{self.path}.{key}"
        value = self._data.get(key)
        if value is None:
            return []
        if isinstance(value, Mapping):
            value = [value]  # the spec's sample writes one-entry sequences as the entry
        if not isinstance(value, list):
            raise ProfileError(path, f"expected a sequence, got {type(value).__name__}")
        return [
            _YamlSource(_mapping(item, f"{path}[{i}]"), f"{path}[{i}]", self._places)
            for i, item in enumerate(value)
        ]

    def texts(self, key: str) -> list[object]:
        self._used.add(key)
        value = self._data.get(key)
        if value is None:
            return []
        return value if isinstance(value, list) else [value]

    def constraint(self, key: str) -> Constraint | None:
        self._used.add(key)
        value = self._data.get(key)
        if value is None:
            return None
        try:
            return constraint_from_yaml(value, f"{self.path}.{key}")
        except ConstraintError as e:
            raise ProfileError(e.path or f"{self.path}.{key}", e.message) from None

    def has_ext(self, keys: Sequence[str]) -> bool:
        return any(k in self._data for k in keys)

    def unread(self) -> list[str]:
        return [k for k in self._data if k not in self._used]

    def locate(self, key: str) -> Location | None:
        return self._places.doc.key(self._data, key)

    def extras(self) -> dict[str, ExtraValue]:
        """The extension keys not read; any other unknown key is refused."""
        for key in self._data:
            if key not in self._used and not is_extension_key(key):
                raise ProfileError(
                    self.path,
                    f"unknown key {key!r} ({did_you_mean(key, self._used)}; "
                    "extensions: any prefix::name key)",
                    location=self._places.doc.key(self._data, key),
                )
        return {
            k: _extra_value(v, f"{self.path}.{k}")
            for k, v in self._data.items()
            if k not in self._used
        }


def _plain(value: ExtraValue) -> object:
    """Extras as plain dicts/lists (the safe dumper refuses other Mapping types)."""
    if isinstance(value, Mapping):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, Sequence) and not isinstance(value, str):
        return [_plain(v) for v in value]
    return copy.copy(value)


def _date_value(value: datetime) -> object:
    """The year..second mapping (§3.2.1), with RTCBuilder's ``millisecond`` and
    ``timezone`` (minutes east of UTC) when needed; ISO text for what the mapping
    cannot hold (sub-millisecond times, zones with seconds)."""
    parts = ("year", "month", "day", "hour", "minute", "second")
    out: dict[str, object] = {p: getattr(value, p) for p in parts}
    if value.microsecond:
        if value.microsecond % 1000:
            return value.isoformat()
        out["millisecond"] = value.microsecond // 1000
    offset = value.utcoffset()
    if offset is not None:
        seconds = int(offset.total_seconds())
        if seconds % 60 or offset.microseconds:
            return value.isoformat()
        out["timezone"] = seconds // 60
    return out


class _YamlSink(Sink):
    def __init__(self, data: dict[str, object], path: str) -> None:
        self._data = data
        self._path = path

    def _set(self, key: str, value: object) -> None:
        self._data[key] = value

    def scalar(self, key: str, value: SinkScalar | None) -> None:
        if value is None:
            return
        if isinstance(value, datetime):
            self._set(key, _date_value(value))
        elif isinstance(value, str):
            self._set(key, str(value))  # plain str: the safe dumper refuses StrEnum
        else:
            self._set(key, value)

    def position(self, key: str, value: Position) -> None:
        self._set(key, value.value.upper())  # the YAML schema's enum is upper case

    def child(self, key: str) -> Sink:
        data: dict[str, object] = {}
        self._set(key, data)
        return _YamlSink(data, f"{self._path}.{key}")

    def add(self, key: str) -> Sink:
        items = self._data.setdefault(key, [])
        assert isinstance(items, list)
        data: dict[str, object] = {}
        items.append(data)
        return _YamlSink(data, f"{self._path}.{key}[{len(items) - 1}]")

    def texts(self, key: str, values: Sequence[str]) -> None:
        if values:
            self._set(key, list(values))

    def constraint(self, key: str, value: Constraint | None) -> None:
        if value is not None:
            self._set(key, constraint_to_yaml(value))

    def declare(self, base: str, *, doc: bool, ext: bool) -> None:
        """YAML marks the profiles by the key prefixes alone."""

    def extras(self, extra: Extra) -> None:
        for key, value in extra.items():
            if key in self._data:
                raise ProfileError(f"{self._path}.{key}", "extra key collides with a known field")
            self._data[key] = _plain(value)


def loads_yaml(text: str | bytes, source: str = "<string>") -> RtcProfile:
    """Parse and validate a YAML RTC Profile; raises ProfileError only, located in
    ``source`` (the file name shown in messages) at the line and column of the field."""
    doc = _load(text, source)
    data = doc.data
    if not isinstance(data, Mapping) or ROOT not in data:
        raise ProfileError(
            DOCUMENT, f"expected a mapping with the key {ROOT!r}", location=doc.where(data)
        )
    for key in data:
        if key != ROOT:
            raise ProfileError(
                str(key),
                f"unknown top-level key (allowed: {ROOT})",
                location=doc.key(data, key),
            )
    places = _Places(doc)
    try:
        profile = read_profile(_YamlSource(_mapping(data[ROOT], ROOT), ROOT, places))
        validate_profile(profile)
    except ProfileError as e:
        raise e.at(places.locate(e.path)) from None
    return profile


def dumps_yaml(profile: RtcProfile) -> str:
    """The YAML form of a profile (validated first; raises ProfileError)."""
    validate_profile(profile)
    body: dict[str, object] = {}
    write_profile(profile, _YamlSink(body, ROOT))
    _check_budget({ROOT: body})  # never write what loads_yaml would refuse
    return yaml.dump(
        {ROOT: body},
        Dumper=SAFE_DUMPER,
        sort_keys=False,
        allow_unicode=True,
        explicit_start=True,
        width=100,
    )
