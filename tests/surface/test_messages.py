"""The message model, the XML PSM (validated against the shipped XSD) and the compact codec."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import xmlschema
from hypothesis import given, settings
from hypothesis import strategies as st

from openel_async import BadParameterError
from openel_async.surface import compact, xml_psm
from openel_async.surface.messages import (
    ArgumentList,
    CommandMessage,
    DataType,
    Device,
    Message,
    Parameter,
    ResultList,
)

SAMPLES = Path(__file__).parent / "samples"
XSD = Path(xml_psm.__file__).with_name(xml_psm.SCHEMA_FILE)

# XML 1.0 characters (surrogates excluded); \r included: it must survive the parser.
xml_text = st.text(
    st.characters(
        codec="utf-8",
        exclude_categories=("Cs",),
        exclude_characters="".join(chr(c) for c in range(32) if c not in (9, 10, 13))
        + "\ufffe\uffff",
    ),
    max_size=20,
)
ints = st.integers(-(2**63), 2**63 - 1)
floats = st.floats(allow_nan=True, allow_infinity=True)
values = st.one_of(
    st.tuples(st.just(DataType.INT), ints),
    st.tuples(st.just(DataType.FLOAT), floats),
    st.tuples(st.just(DataType.STRING), xml_text),
    st.tuples(st.just(DataType.BOOL), st.booleans()),
    st.tuples(st.just(DataType.BYTES), st.binary(max_size=20)),
    st.tuples(st.just(DataType.INT_LIST), st.lists(ints, max_size=4).map(tuple)),
    st.tuples(st.just(DataType.FLOAT_LIST), st.lists(floats, max_size=4).map(tuple)),
    st.tuples(st.just(DataType.STRING_LIST), st.lists(xml_text, max_size=4).map(tuple)),
    st.tuples(st.just(DataType.BOOL_LIST), st.lists(st.booleans(), max_size=4).map(tuple)),
)
parameters = st.builds(lambda tv, name: Parameter(int(tv[0]), name, tv[1]), values, xml_text)
parameter_lists = st.lists(parameters, min_size=1, max_size=4).map(tuple)
commands = st.builds(
    CommandMessage,
    xml_text,
    xml_text,
    st.none() | parameter_lists.map(ArgumentList),
    st.none() | parameter_lists.map(ResultList),
)
devices = st.builds(Device, xml_text, st.lists(commands, min_size=1, max_size=3).map(tuple))
messages: st.SearchStrategy[Message] = st.one_of(
    devices,
    commands,
    parameter_lists.map(ArgumentList),
    parameter_lists.map(ResultList),
    parameters,
)


def same(a: object, b: object) -> bool:
    """Equality where NaN equals NaN (and -0.0 differs from 0.0)."""
    if isinstance(a, float) and isinstance(b, float):
        return (math.isnan(a) and math.isnan(b)) or (
            a == b and math.copysign(1, a) == math.copysign(1, b)
        )
    if isinstance(a, tuple) and isinstance(b, tuple):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
    if type(a) is not type(b):
        return False
    if hasattr(a, "__struct_fields__"):
        return all(same(getattr(a, f), getattr(b, f)) for f in a.__struct_fields__)  # type: ignore[attr-defined]
    return a == b


@settings(max_examples=100, deadline=None)
@given(messages)
def test_xml_round_trip_is_exact_and_valid(message: Message) -> None:
    data = xml_psm.to_xml(message)
    assert xml_psm.schema().is_valid(data.decode("utf-8"))
    back = xml_psm.from_xml(data)
    assert same(back, message)
    assert xml_psm.to_xml(back) == data


@settings(max_examples=100, deadline=None)
@given(messages)
def test_compact_round_trip_is_exact(message: Message) -> None:
    back = compact.decode(compact.encode(message), type(message))
    assert same(back, message)


@pytest.mark.parametrize("sample", sorted(SAMPLES.glob("*.xml")), ids=lambda p: p.name)
def test_samples_are_valid_and_round_trip(sample: Path) -> None:
    # Validated by path, as any xmlschema user would, then through our reader.
    xmlschema.XMLSchema(str(XSD)).validate(str(sample))
    message = xml_psm.from_xml(sample.read_bytes())
    again = xml_psm.from_xml(xml_psm.to_xml(message))
    assert same(again, message)
    assert same(compact.decode(compact.encode(message), type(message)), message)


def test_sample_values_decode_to_python_types() -> None:
    device = xml_psm.device_from_xml((SAMPLES / "get_position_result.xml").read_bytes())
    command = device.commands[0]
    assert command.results is not None
    assert command.results.as_dict() == {"return_code": 0, "position": -0.25}
    args = xml_psm.from_xml((SAMPLES / "argument_list.xml").read_bytes())
    assert isinstance(args, ArgumentList)
    floats_ = args.parameters[0].value
    assert floats_[:3] == (1.0, -2.5, math.inf) and math.isnan(floats_[3])
    assert args.parameters[1].value == ("rad", "rad/s")


def test_schema_fixes_are_noted_in_the_shipped_xsd() -> None:
    text = xml_psm.schema_text()
    assert "FIX 1" in text and "FIX 2" in text
    assert (
        '<xs:element name="parameters" type="Parameter" minOccurs="1" maxOccurs="unbounded"/>'
        in text
    )


@pytest.mark.parametrize(
    ("data", "fragment"),
    [
        (b'<?xml version="1.0"?><!DOCTYPE d [<!ENTITY a "b">]><Device/>', "without DTD"),
        (b"<Device><device_kind>M</device_kind></Device>", "valid against the HAL4RT schema"),
        (b"<Device><device_kind>M</device_kind>", "well-formed"),
        (b"<Foo/>", "root element"),
        (b"<a>" * 20 + b"</a>" * 20, "levels"),
        (
            b"<Parameter><data_type_id>99</data_type_id><name>a</name><value>1</value></Parameter>",
            "data_type_id=99",
        ),
        (
            b"<Parameter><data_type_id>1</data_type_id><name>a</name><value>1.5</value></Parameter>",
            "decimal integer",
        ),
        (
            b"<Parameter><data_type_id>2</data_type_id><name>a</name><value>1_0</value></Parameter>",
            "xs:double",
        ),
        (
            b"<Parameter><data_type_id>1</data_type_id><name>a</name><value>99999999999999999999</value></Parameter>",
            "64-bit",
        ),
        (
            b"<Parameter><data_type_id>5</data_type_id><name>a</name><value>@@</value></Parameter>",
            "base64",
        ),
        (
            b"<Parameter><data_type_id>x</data_type_id><name>a</name><value>1</value></Parameter>",
            "schema",
        ),
    ],
)
def test_bad_xml_is_refused_with_bad_parameter(data: bytes, fragment: str) -> None:
    with pytest.raises(BadParameterError) as info:
        xml_psm.from_xml(data)
    assert fragment in str(info.value)


def test_oversized_messages_are_refused_before_parsing() -> None:
    big = b"<ResultList>" + b" " * 100 + b"</ResultList>"
    with pytest.raises(BadParameterError, match="at most 50 bytes"):
        xml_psm.from_xml(big, max_bytes=50)
    with pytest.raises(BadParameterError, match="at most 10 bytes"):
        compact.decode(b"\x00" * 11, Device, max_bytes=10)


def test_billion_laughs_is_refused() -> None:
    bomb = (
        b'<?xml version="1.0"?><!DOCTYPE lolz [<!ENTITY lol "lol">'
        b'<!ENTITY lol2 "&lol;&lol;&lol;&lol;">]><Parameter><data_type_id>3</data_type_id>'
        b"<name>a</name><value>&lol2;</value></Parameter>"
    )
    with pytest.raises(BadParameterError):
        xml_psm.from_xml(bomb)


def test_model_refuses_wrong_types_and_non_xml_text() -> None:
    with pytest.raises(BadParameterError, match="a float"):
        Parameter(DataType.FLOAT, "x", 1)
    with pytest.raises(BadParameterError, match="an int"):
        Parameter(DataType.INT, "x", True)
    with pytest.raises(BadParameterError, match="U\\+0000"):
        Parameter(DataType.STRING, "x", "a\x00")
    with pytest.raises(BadParameterError, match="one or more"):
        ArgumentList(())
    with pytest.raises(BadParameterError, match="one or more CommandMessages"):
        Device("Motor", ())
    with pytest.raises(BadParameterError, match="compact Device"):
        compact.decode(compact.encode(["Motor", [["F", "", None, [[[1, "x", "nope"]]]]]]), Device)


def test_parameter_of_infers_the_data_type() -> None:
    assert Parameter.of("a", 1).data_type_id == DataType.INT
    assert Parameter.of("a", [1.0, 2.0]).value == (1.0, 2.0)
    assert Parameter.of("a", ["x"]).data_type_id == DataType.STRING_LIST
    assert Parameter.of("a", b"\x01").data_type_id == DataType.BYTES
