"""The parameter values' parser (openel_async.params.parse_value) and the ODrive endpoint
value codec (openel_can.params_odrive): round trips over their whole ranges."""

from __future__ import annotations

import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from openel_async.errors import BadParameterError
from openel_async.params import ParameterInfo, parse_value
from openel_can.odrive_endpoints import Endpoint
from openel_can.params_odrive import decode, encode

INT16 = ParameterInfo("Goal", "1", "int16", "rw", low=-(2**15), high=2**15 - 1)


@settings(max_examples=100, deadline=None)
@given(st.integers(min_value=-(2**17), max_value=2**17), st.sampled_from(["{}", "{:#x}", " {} "]))
def test_an_integer_parses_back_or_is_refused_by_range(value: int, shape: str) -> None:
    text = shape.format(value) if value >= 0 or shape != "{:#x}" else str(value)
    if -(2**15) <= value < 2**15:
        assert parse_value(INT16, text) == value
    else:
        with pytest.raises(BadParameterError, match=r"-32768\.\.32767"):
            parse_value(INT16, text)


@settings(max_examples=100, deadline=None)
@given(st.one_of(st.integers(0, 2**32 - 1).map(lambda v: ("uint32", v)),
                 st.integers(-(2**31), 2**31 - 1).map(lambda v: ("int32", v)),
                 st.floats(width=32, allow_nan=False, allow_infinity=False).map(lambda v: ("float", v)),
                 st.booleans().map(lambda v: ("bool", v))))  # fmt: skip
def test_an_endpoint_value_round_trips_in_four_bytes(typed: tuple[str, object]) -> None:
    kind, value = typed
    endpoint = Endpoint("x", 1, kind)  # type: ignore[arg-type]
    field = encode(endpoint, value)  # type: ignore[arg-type]
    assert len(field) == 4
    assert decode(endpoint, field) == value
    if kind == "float":
        assert field == struct.pack("<f", value)
