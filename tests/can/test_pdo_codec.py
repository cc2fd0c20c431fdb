"""PdoCodec (the compiled PDO codec of the set-point path) against pack_pdo/unpack_pdo."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from openel_can import canopen as co

_ENTRY = st.builds(
    co.PdoMapEntry,
    index=st.integers(0x2000, 0x6FFF),
    subindex=st.integers(0, 255),
    bit_length=st.sampled_from((1, 4, 8, 8, 16, 16, 24, 32, 32)),
    signed=st.booleans(),
)
_MAPPING = st.lists(_ENTRY, min_size=1, max_size=8).filter(
    lambda m: sum(e.bit_length for e in m) <= 64
)


def _value(entry: co.PdoMapEntry) -> st.SearchStrategy[int]:
    bits = entry.bit_length
    if entry.signed:  # one beyond each end too: out of range must fail alike
        return st.integers(-(1 << (bits - 1)) - 1, 1 << (bits - 1))
    return st.integers(-1, 1 << bits)


@st.composite
def _mapping_and_values(draw: st.DrawFn) -> tuple[list[co.PdoMapEntry], list[int]]:
    mapping = draw(_MAPPING)
    return mapping, [draw(_value(entry)) for entry in mapping]


@settings(max_examples=100, deadline=None)
@given(_mapping_and_values())
def test_pack_matches_pack_pdo(case: tuple[list[co.PdoMapEntry], list[int]]) -> None:
    mapping, values = case
    codec = co.PdoCodec(mapping)
    try:
        expected = co.pack_pdo(mapping, values)
    except ValueError as exc:
        with pytest.raises(ValueError, match="does not fit") as caught:
            codec.pack(values)
        assert str(caught.value) == str(exc)
        return
    assert codec.pack(values) == expected


@settings(max_examples=100, deadline=None)
@given(_MAPPING, st.binary(max_size=10))
def test_unpack_matches_unpack_pdo(mapping: list[co.PdoMapEntry], data: bytes) -> None:
    codec = co.PdoCodec(mapping)
    try:
        expected = co.unpack_pdo(mapping, data)
    except co.CanOpenDecodeError:
        with pytest.raises(co.CanOpenDecodeError):
            codec.unpack(data)
        return
    assert list(codec.unpack(data)) == expected
    assert list(codec.unpack(bytearray(data))) == expected


def test_wrong_value_count_is_refused() -> None:
    codec = co.PdoCodec((co.PdoMapEntry(0x6040, 0, 16), co.PdoMapEntry(0x607A, 0, 32, True)))
    with pytest.raises(ValueError, match="2 mapping entries"):
        codec.pack((1,))
    assert codec.pack((0x3F, -2)) == bytes.fromhex("3f00feffffff")
