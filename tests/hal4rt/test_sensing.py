"""OpenEL §7.4.1.1: one component with Actuator and Sensor characteristics (a pan-tilt
camera head), and §7.4.1.7 through the Motor names (estimate or commanded value, told)."""

from __future__ import annotations

import math

import pytest

from openel_async import (
    ActuatorDevice,
    BadParameterError,
    ComponentState,
    DeviceInfo,
    DeviceKind,
    EventId,
    HALId,
    Request,
    ValueSource,
    VirtualClock,
)
from openel_async.device_profile import profile_of
from openel_async.device_registry import DeviceRegistry
from openel_async.motor import Motor
from openel_async.sensing import SensingMotor
from openel_async.testing import ComponentStack, EventRecorder
from openel_sim import SimPanTiltHead


async def head_of(stack: ComponentStack, device: SimPanTiltHead) -> SensingMotor:
    return await stack.enter(SensingMotor(device, clock=stack.clock, scale_factor=360))


async def test_one_component_is_actuator_and_sensor(
    hal_components: ComponentStack, virtual_clock: VirtualClock, hal_events: EventRecorder
) -> None:
    device = SimPanTiltHead(target=(math.radians(30.0), math.radians(10.0)))
    head = await head_of(hal_components, device)
    head.add_observer(hal_events)
    assert head.profile_id == DeviceKind.MOTOR and head.get_sensor_kind() == DeviceKind.ROTARY_ANGLE
    # The actuator: pan to 30 degrees; completion is event 1 of this component.
    motion = await head.set_position(30.0)
    device.set_tilt(math.radians(10.0))  # the vendor function moves the tilt servo
    await motion
    await virtual_clock.sleep(0.5)
    assert hal_events.count("event", EventId.COMPLETED) == 1  # the tilt's arrival is not
    # The sensor: line of sight and the target's offset in the image, in degrees.
    head.set_unit_of_measurement(["deg"] * 4)
    azimuth, elevation, dx, dy = await head.get_value_of_measurement()
    assert (azimuth, elevation) == pytest.approx((30.0, 10.0))
    assert (dx, dy) == pytest.approx((0.0, 0.0), abs=1e-9)
    timed = await head.get_timed_value()
    assert timed.num == 4 and timed.time_ns == virtual_clock.now_ns()
    assert head.get_value_of_measurement_nowait() == pytest.approx(timed.values)
    assert await head.get_position() == pytest.approx(30.0)  # the actuator's names still work
    assert head.state is ComponentState.ACTIVE


async def test_sensor_settings_have_their_own_names_and_checks(
    hal_components: ComponentStack,
) -> None:
    head = await head_of(hal_components, SimPanTiltHead())
    head.set_measurement_origin([0.0, 0.0, 0.1, 0.0])
    head.set_measurement_scale_factor([1.0, 1.0, 2.0, 1.0])
    assert head.get_measurement_origin() == (0.0, 0.0, 0.1, 0.0)
    assert head.get_measurement_scale_factor() == (1.0, 1.0, 2.0, 1.0)
    assert head.get_scale_factor() == 360.0  # the Motor's own, unchanged
    values = await head.get_value_of_measurement()
    assert values[2] == pytest.approx(2.0 * (0.0 - 0.1))
    with pytest.raises(BadParameterError) as info:
        head.set_unit_of_measurement(["m", "deg", "deg", "deg"])
    assert info.value.parameter == "units[0]"
    with pytest.raises(BadParameterError) as info:
        head.set_measurement_scale_factor([1.0, 0.0, 1.0, 1.0])
    assert info.value.parameter == "values[1]"
    assert head.get_measurement_scale_factor() == (1.0, 1.0, 2.0, 1.0)


async def test_registry_creates_a_sensing_motor_and_profiles_both_sides(
    hal_components: ComponentStack,
) -> None:
    registry = DeviceRegistry()
    registry.register(SimPanTiltHead)
    head = registry.create(
        HALId(DeviceKind.MOTOR, 0x0E1, 0x800, 1), component_options={"clock": hal_components.clock}
    )
    assert type(head) is SensingMotor
    profile = profile_of(SimPanTiltHead)
    names = {c.name: c.method for c in profile.commands}
    assert (
        names["SetOrigin"] == "set_origin" and names["SensorSetOrigin"] == "set_measurement_origin"
    )
    assert names["GetValueOfMeasurement"] == "get_value_of_measurement"
    for command in profile.commands:  # vendor functions (0x1000+) are the device's
        target = SensingMotor if command.id < 0x1000 else SimPanTiltHead
        assert hasattr(target, command.method), command.name
    assert profile.attributes["sensor_units"] == ["rad"] * 4


class NoTorqueSensing(ActuatorDevice):
    """Measures position, estimates velocity, cannot tell torque."""

    info = DeviceInfo(DeviceKind.MOTOR, 0x0E1, 0x7003, "Test", "NoTorque")
    reports_completion = True
    measured_requests = frozenset({Request.POSITION_ACTUAL})
    estimated_requests = frozenset({Request.VELOCITY_ACTUAL})

    def __init__(self) -> None:
        self.position = 0.0

    async def command(self, request: Request, value: float) -> None:
        if request is Request.POSITION:
            self.position = value

    async def read(self, request: Request) -> float:
        assert request is not Request.TORQUE_ACTUAL  # never asked: it cannot tell
        return self.position if request is Request.POSITION_ACTUAL else 0.25


async def test_motor_getters_follow_openel_7_4_1_7(hal_components: ComponentStack) -> None:
    motor = await hal_components.enter(Motor(NoTorqueSensing(), clock=hal_components.clock))
    await motor.set_torque(0.3)
    assert await motor.get_torque() == 0.3  # the commanded value...
    assert motor.value_source(Request.TORQUE_ACTUAL) is ValueSource.COMMANDED  # ...and told so
    assert await motor.get_speed() == pytest.approx(0.25)
    assert motor.value_source(Request.VELOCITY_ACTUAL) is ValueSource.ESTIMATED
    assert motor.value_source(Request.POSITION_ACTUAL) is ValueSource.MEASURED
