"""Return codes, HALId, Property, device kinds and the component name rule."""

from __future__ import annotations

import pytest

from openel_async import (
    BadParameterError,
    DeviceKind,
    HALError,
    HALId,
    NotConnectedError,
    Property,
    Request,
    ReturnCode,
    component_name,
)
from openel_async.errors import check_code
from openel_async.requests import SET_VALUE_REQUESTS, coerce_request


def test_return_codes_match_openel_and_hal4rt() -> None:
    assert ReturnCode.HAL_OK == 0
    assert ReturnCode.HAL_ERROR == 1
    names = {c.name for c in ReturnCode}
    assert {
        "HAL_NO_CONNECTED",
        "HAL_NO_MEMORY",
        "HAL_NULL_PARAMETER",
        "HAL_NOT_IMPLEMENTED",
        "HAL_BAD_PARAMETER",
    } <= names


def test_exceptions_carry_their_code() -> None:
    with pytest.raises(NotConnectedError) as info:
        check_code(ReturnCode.HAL_NO_CONNECTED)
    assert info.value.code is ReturnCode.HAL_NO_CONNECTED
    with pytest.raises(HALError) as err:
        check_code(1, "boom")
    assert err.value.code is ReturnCode.HAL_ERROR
    check_code(0)
    assert BadParameterError("x", 1, "y").code is ReturnCode.HAL_BAD_PARAMETER


def test_device_kinds_of_the_reference_registry() -> None:
    expected = {
        "MOTOR": 1, "GYRO": 2, "TORQUE": 3, "ACCEL": 4, "COMPASS": 5, "DISTANCE": 6,
        "FORCE": 7, "TEMPERATURE": 8, "HUMIDITY": 9, "CO2": 0xA, "COLOR": 0xB,
        "TOUCH": 0xC, "CURRENT": 0xD, "ROTARY_ANGLE": 0xE,
        "GPS": 0x7F00_0001,  # HAL4RT's GPS, from the extension range (docs/psm.md §4.3)
    }  # fmt: skip
    assert {k.name: k.value for k in DeviceKind} == expected


def test_request_codes() -> None:
    assert [int(r) for r in Request] == [0, 1, 2, 3, 5, 6, 7]
    assert Request.POSITION.actual is Request.POSITION_ACTUAL


@pytest.mark.parametrize("bad", [4, 8, -1, "1", 1.0, True, None])
def test_unknown_request_codes_are_bad_parameters(bad: object) -> None:
    with pytest.raises(BadParameterError) as info:
        coerce_request(bad, SET_VALUE_REQUESTS)
    assert info.value.parameter == "request"
    assert "POSITION=1" in str(info.value)


def test_hal_id_is_validated_per_field() -> None:
    hal_id = HALId(1, 2, 3, 0xFFFF_FFFF)
    assert hal_id.device_kind is DeviceKind.MOTOR
    for index, field in enumerate(("device_kind_id", "vendor_id", "product_id", "instance_id")):
        for bad in (-1, 0x1_0000_0000, 1.5, True):
            args: list[object] = [1, 1, 1, 1]
            args[index] = bad
            with pytest.raises(BadParameterError) as info:
                HALId(*args)  # type: ignore[arg-type]
            assert info.value.parameter == field
    assert HALId(0x99, 0, 0, 0).device_kind is None


def test_property_requires_a_name_and_function_names() -> None:
    hal_id = HALId(1, 0, 0, 0)
    assert Property(hal_id, "MOTOR_1", ("a",)).function_list == ("a",)
    with pytest.raises(BadParameterError, match="device_name"):
        Property(hal_id, "")
    with pytest.raises(BadParameterError, match="function_list"):
        Property(hal_id, "M", ("",))


def test_component_name_rule_of_hal4rt() -> None:
    assert component_name("motor", "Acme", "X100") == "HalMotorAcmeX100"
    for bad_vendor in ("acme", "A", "A" * 17, "Ac me"):
        with pytest.raises(BadParameterError, match="vendor_name"):
            component_name("Motor", bad_vendor, "X")
    with pytest.raises(BadParameterError, match="product_name"):
        component_name("Motor", "Acme", "1x")
