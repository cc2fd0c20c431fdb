"""Fuzzers for the profile parsers (XML, YAML) and the constraint parser: whatever the
input, they return or raise their one documented error (ProfileError /
ConstraintSyntaxError), never anything else.  Inputs start from the real profiles and
are damaged at random; example counts are bounded so CI stays fast."""

from __future__ import annotations

import contextlib
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from openel_async.rtc.constraints import (
    ConstraintFormatError,
    ConstraintSyntaxError,
    format_constraint,
    parse_constraint,
)
from openel_async.rtc.profile import ProfileError, dumps_xml, dumps_yaml, loads_xml, loads_yaml

REAL = Path(__file__).parent / "data" / "real"
XML_SEEDS = [p.read_bytes() for p in sorted(REAL.glob("*.xml"))]
YAML_SEEDS = [p.read_text() for p in sorted(REAL.glob("*.yaml"))] + [
    p.read_text() for p in sorted((REAL / "constraints").glob("*.yaml"))
]
FUZZ = settings(
    max_examples=100,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
FIELD_FUZZ = settings(FUZZ, max_examples=100)

# Pieces that hit the interesting paths: numbers (long ones too), operators, names.
NASTY = st.sampled_from(
    [
        "9" * 5000,
        "-" + "1" * 4400,
        "1e999",
        "nan",
        "<",
        ">",
        "=>",
        "x",
        ",",
        ":",
        "{",
        "}",
        "(",
        ")",
        "&amp;",
        "<!DOCTYPE a>",
        "\x00",
        "\u65e5",
        '"',
        "'",
        "*a",
        "&a ",
        "!!python/object:os.system",
        "  ",
        "\n",
        "EventPort",
        "rtcExt::properties",
        "fractionalSecond: 0.5",
        "timezone: 99999",
    ]
)


def _mutate(seed: str, cuts: list[tuple[int, int, str]]) -> str:
    text = seed
    for start, length, piece in cuts:
        at = start % (len(text) + 1)
        text = text[:at] + piece + text[at + length :]
    return text


EDITS = st.lists(
    st.tuples(
        st.integers(0, 20_000),
        st.integers(0, 12),
        st.one_of(NASTY, st.text(max_size=6)),
    ),
    min_size=1,
    max_size=4,
)


def _round_trips(load: object, text: str | bytes) -> None:
    """Load; when it loads, both writers work and reload to the same model."""
    assert callable(load)
    try:
        profile = load(text)
    except ProfileError:
        return
    for dump, reload in ((dumps_yaml, loads_yaml), (dumps_xml, loads_xml)):
        try:
            written = dump(profile)
        except ProfileError:
            continue  # e.g. an unknown YAML key that is no XML name: refused, named
        assert reload(written) == profile


@FUZZ
@given(seed=st.sampled_from(XML_SEEDS), edits=EDITS)
def test_xml_profile_parser_fuzz(seed: bytes, edits: list[tuple[int, int, str]]) -> None:
    text = _mutate(seed.decode("utf-8"), edits)
    _round_trips(loads_xml, text.encode("utf-8", "surrogatepass"))


@FUZZ
@given(seed=st.sampled_from(YAML_SEEDS), edits=EDITS)
def test_yaml_profile_parser_fuzz(seed: str, edits: list[tuple[int, int, str]]) -> None:
    _round_trips(loads_yaml, _mutate(seed, edits))


def _leaves(node: Any, path: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    if isinstance(node, dict):
        return [p for k, v in node.items() for p in _leaves(v, (*path, k))] + [path]
    if isinstance(node, list):
        return [p for i, v in enumerate(node) for p in _leaves(v, (*path, i))]
    return [path]


VALUES = st.one_of(NASTY, st.text(max_size=8), st.integers().map(str))


@FIELD_FUZZ
@given(seed=st.sampled_from(YAML_SEEDS), data=st.data())
def test_yaml_profile_fields_fuzz(seed: str, data: st.DataObject) -> None:
    """Replace field values (and add keys) of a real YAML profile."""
    doc = yaml.load(seed, Loader=yaml.BaseLoader)  # every scalar a string
    for _ in range(data.draw(st.integers(1, 3))):
        where = data.draw(st.sampled_from(_leaves(doc)))
        if not where:
            continue
        parent = doc
        for step in where[:-1]:
            parent = parent[step]
        if isinstance(parent[where[-1]], dict) and data.draw(st.booleans()):
            parent[where[-1]][data.draw(VALUES)] = data.draw(VALUES)
        else:
            parent[where[-1]] = data.draw(VALUES)
    _round_trips(loads_yaml, yaml.safe_dump(doc, allow_unicode=True))


@FIELD_FUZZ
@given(seed=st.sampled_from(XML_SEEDS), data=st.data())
def test_xml_profile_attributes_fuzz(seed: bytes, data: st.DataObject) -> None:
    """Replace attribute values (and add attributes) of a real XML profile."""
    root = ET.fromstring(seed)
    elements = list(root.iter())
    for _ in range(data.draw(st.integers(1, 3))):
        elem = data.draw(st.sampled_from(elements))
        names = list(elem.attrib)
        value = data.draw(VALUES).replace("\x00", "")
        if names and data.draw(st.booleans()):
            elem.set(data.draw(st.sampled_from(names)), value)
        else:
            elem.set(
                data.draw(
                    st.sampled_from(
                        [
                            "{http://www.openrtp.org/namespaces/rtc}maxInstances",
                            "{http://www.openrtp.org/namespaces/rtc}executionRate",
                            "{http://www.openrtp.org/namespaces/rtc}updateDate",
                            "{http://www.openrtp.org/namespaces/rtc_ext}position",
                            "{http://www.openrtp.org/namespaces/rtc}portType",
                        ]
                    )
                ),
                value,
            )
    _round_trips(loads_xml, ET.tostring(root))


@FUZZ
@given(data=st.binary(max_size=300))
def test_xml_profile_parser_on_raw_bytes(data: bytes) -> None:
    for prefix in (b"", b'<?xml version="1.0" encoding="Shift_JIS"?>'):
        with contextlib.suppress(ProfileError):
            loads_xml(prefix + data)


CONSTRAINT_TEXT = st.lists(
    st.one_of(
        st.sampled_from(
            ["x", "<", "<=", ">", ">=", "=>", ",", "(", ")", "{", "}", ":", " ", "-", ".", "e"]
        ),
        st.sampled_from(["0", "1", "100", "9" * 4500, "1.5", "abc", "el1"]),
    ),
    max_size=14,
).map("".join)


@FUZZ
@given(CONSTRAINT_TEXT)
def test_constraint_parser_fuzz(text: str) -> None:
    try:
        tree = parse_constraint(text)
    except ConstraintSyntaxError as e:
        assert len(str(e)) < 600
        return
    for value in (0, 150, -1.5, 1e308, "abc", [1, 2], {"el1": 100}):
        tree.check(value)  # never raises
    try:
        canonical = format_constraint(tree)
    except ConstraintFormatError:
        return
    assert parse_constraint(canonical) == tree
