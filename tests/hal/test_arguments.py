"""Bad arguments are BadParameterError naming the parameter, never another exception."""

from __future__ import annotations

import math

import pytest

from openel_async import (
    Actuator,
    ActuatorBank,
    BadParameterError,
    ComponentState,
    DeviceKind,
    HALId,
    Request,
    Sensor,
    VirtualClock,
)
from openel_async.testing import ComponentStack
from openel_sim import SimEncoder, SimMotor, SimTemperature


@pytest.mark.parametrize(
    ("kwargs", "parameter"),
    [
        ({"hal_id": (1, 2, 3, 4)}, "hal_id"),
        ({"hal_id": 7}, "hal_id"),
        ({"clock": object()}, "clock"),
        ({"clock": 0}, "clock"),
        ({"auto_init": "yes"}, "auto_init"),
        ({"auto_init": None}, "auto_init"),
        ({"open_timeout": 0}, "open_timeout"),
        ({"open_timeout": -1.0}, "open_timeout"),
        ({"open_timeout": math.nan}, "open_timeout"),
        ({"open_timeout": math.inf}, "open_timeout"),
        ({"open_timeout": True}, "open_timeout"),
        ({"open_timeout": "10"}, "open_timeout"),
        ({"function_list": "inject_fault"}, "function_list"),
        ({"function_list": 3}, "function_list"),
        ({"function_list": ("ok", "")}, "function_list"),
        ({"device_name": ""}, "device_name"),
        ({"device_name": 5}, "device_name"),
        ({"completion": object()}, "completion"),
    ],
)
def test_actuator_constructor_arguments(kwargs: dict[str, object], parameter: str) -> None:
    with pytest.raises(BadParameterError) as info:
        Actuator(SimMotor(), **kwargs)  # type: ignore[arg-type]
    assert info.value.parameter == parameter


@pytest.mark.parametrize(
    ("component", "device"),
    [
        (Actuator, None),
        (Actuator, "SimMotor"),
        (Actuator, SimEncoder(SimMotor())),  # a sensor device
        (Sensor, None),
        (Sensor, SimMotor()),  # an actuator device (was accepted)
        (Sensor, SimMotor),  # the class, not an instance
    ],
)
def test_the_device_must_be_of_the_component_kind(component: type, device: object) -> None:
    with pytest.raises(BadParameterError, match="device=") as info:
        component(device)
    assert info.value.parameter == "device"
    expected = "ActuatorDevice" if component is Actuator else "SensorDevice"
    assert expected in info.value.allowed


def test_sensor_constructor_arguments() -> None:
    with pytest.raises(BadParameterError) as info:
        Sensor(SimTemperature(), hal_id=(8, 0, 0, 1))  # type: ignore[arg-type]
    assert info.value.parameter == "hal_id"
    with pytest.raises(BadParameterError) as info:
        Sensor(SimTemperature(), clock=VirtualClock)  # type: ignore[arg-type]
    assert info.value.parameter == "clock"


def test_good_arguments_are_kept() -> None:
    clock = VirtualClock()
    hal_id = HALId(DeviceKind.MOTOR, 1, 2, 3)
    motor = Actuator(
        SimMotor(),
        hal_id=hal_id,
        clock=clock,
        auto_init=False,
        open_timeout=2,
        function_list=["a", "b"],
    )
    assert motor.hal_id is hal_id and motor.clock is clock and motor.open_timeout == 2
    assert motor.property.function_list == ("a", "b")


# -- values out of any range: BadParameterError, not OverflowError or TypeError ----------


async def test_set_value_of_a_huge_int(sim_actuator: Actuator) -> None:
    with pytest.raises(BadParameterError) as fast:
        sim_actuator.set_value_nowait(10**400, Request.VELOCITY)
    with pytest.raises(BadParameterError) as slow:
        await sim_actuator.set_value(-(10**400), Request.VELOCITY)
    for info in (fast, slow):
        assert info.value.parameter == "value" and "finite" in info.value.allowed
    assert sim_actuator.motion is None and sim_actuator.state is ComponentState.ACTIVE


@pytest.mark.parametrize("values", [None, 5, 0.5, iter([0.1, 0.2]), {"a": 0.1}])
async def test_bank_values_that_are_not_a_sequence(
    hal_components: ComponentStack, values: object
) -> None:
    actuators = [await hal_components.actuator(SimMotor()) for _ in range(2)]
    bank = ActuatorBank(actuators)
    with pytest.raises(BadParameterError) as info:
        bank.set_values_nowait(values)  # type: ignore[arg-type]
    assert info.value.parameter == "values" and "a sequence of 2 values" in info.value.allowed
    with pytest.raises(BadParameterError):
        await bank.set_values(values)  # type: ignore[arg-type]
    assert bank.motions == (None, None)


async def test_bank_value_that_is_a_huge_int(hal_components: ComponentStack) -> None:
    bank = ActuatorBank([await hal_components.actuator(SimMotor()) for _ in range(2)])
    with pytest.raises(BadParameterError) as info:
        bank.set_values_nowait([0.5, -(10**400)], Request.TORQUE)
    assert info.value.parameter == "values[1]"
    assert bank.motions == (None, None)
