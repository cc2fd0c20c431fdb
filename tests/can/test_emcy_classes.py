"""Issue 23 point 5: EMCY codes decode with their CiA 301 / CiA 402 classes."""

from __future__ import annotations

import doctest

from hypothesis import given
from hypothesis import strategies as st

import openel_can.emcy
from openel_can.canopen import EmcyCode
from openel_can.emcy import EMCY_CODES, describe_emcy, emcy_class


def test_the_classes_of_cia_301_table_21() -> None:
    assert emcy_class(0x0000) == "no error"
    assert emcy_class(0x1000) == "generic error"
    assert emcy_class(0x2310) == "current, device output side"
    assert emcy_class(0x3210) == "voltage inside the device"
    assert emcy_class(0x4210) == "device temperature"
    assert emcy_class(0x5000) == "device hardware"
    assert emcy_class(0x6100) == "internal software"
    assert emcy_class(0x7000) == "additional modules"
    assert emcy_class(0x8110) == "monitoring: communication"
    assert emcy_class(0x8210) == "monitoring: protocol error"
    assert emcy_class(0x8611) == "monitoring: control"
    assert emcy_class(0x9000) == "external error"
    assert emcy_class(0xF000) == "additional functions"
    assert emcy_class(0xFF42) == "device specific"
    assert emcy_class(0x2F00) == "current"  # an unnamed sub-class: its nibble's class
    assert emcy_class(0xA000) == "reserved"


def test_descriptions() -> None:
    assert describe_emcy(0x8611) == "0x8611 following error (monitoring: control)"
    assert describe_emcy(0x8130) == (
        "0x8130 life guard or heartbeat error (monitoring: communication)"
    )
    assert describe_emcy(0x1000) == "0x1000 generic error"
    assert describe_emcy(0x2345) == "0x2345 current, device output side"
    assert doctest.testmod(openel_can.emcy).failed == 0


def test_every_named_code_of_the_codec_has_a_description() -> None:
    for code in EmcyCode:
        assert code.value in EMCY_CODES, code


@given(st.integers(0, 0xFFFF))
def test_every_code_is_described_with_its_class(code: int) -> None:
    text = describe_emcy(code)
    assert text.startswith(f"{code:#06x} ")
    assert emcy_class(code) in text
