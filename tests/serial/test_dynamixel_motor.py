"""Dynamixel servos through the HAL4RT Motor API: control modes on Operating Mode (11) and
Torque Enable (64), tm_acc on the servo's own Profile Acceleration (108), the device
characteristics profile and the registry, bad input, and dynamixel-sdk reading back what
the driver wrote.

Driver tests run over a pty in real time: every wait is bounded (``fail_after``). The
simulated servo's ramp is also checked on a virtual clock, without a pty.
"""

from __future__ import annotations

import json
import math
from collections.abc import AsyncIterator
from contextlib import AsyncExitStack
from typing import Any

import anyio
import dynamixel_sdk as sdk
import pytest

from openel_async import (
    BadParameterError,
    DeviceKind,
    HALError,
    HALId,
    Motor,
    MotorControlMode,
    NotImplementedHALError,
    VirtualClock,
)
from openel_async.cli import main
from openel_async.device import VelocityRamp
from openel_async.device_profile import profile_of
from openel_async.device_registry import DeviceRegistry
from openel_serial import (
    DynamixelPort,
    DynamixelServo,
    DynamixelXL430W250,
    DynamixelXM430W350,
)
from openel_serial import dynamixel as dx
from openel_serial.peers import SimDynamixelBus, SimServo
from openel_serial.servo import (
    MAX_PROFILE_ACCELERATION,
    ROBOTIS_VENDOR_ID,
    profile_acceleration_for,
)

from .conftest import BAUD, WAIT_S, make_servo

pytestmark = pytest.mark.timeout(20)

X = dx.XSeries
TICK = 2 * math.pi / 4096
ACC_UNIT = dx.acceleration_to_rad_s2(1)  # rad/s^2 per Profile Acceleration unit
VEL_UNIT = dx.velocity_to_rad_s(1)


def writes_since(bus: SimDynamixelBus, start: int) -> list[tuple[int, bytes]]:
    return [(m.address, m.data) for m in bus.instructions[start:] if isinstance(m, dx.Write)]


async def motor(stack: AsyncExitStack, port: DynamixelPort, dxl_id: int = 1, **kw: Any) -> Motor:
    cls = kw.pop("cls", DynamixelXM430W350)
    return await stack.enter_async_context(Motor(cls(port, dxl_id, **kw)))


# -- control modes ------------------------------------------------------------------------------


async def test_modes_map_to_operating_mode_and_torque_enable(
    bus: SimDynamixelBus, port: DynamixelPort
) -> None:
    async with AsyncExitStack() as stack:
        m = await motor(stack, port, torque_constant=1.5)
        assert m.get_control_mode() is MotorControlMode.READY_TO_CONTROL
        servo = bus[1]

        start = len(bus.instructions)
        position = await m.set_position(0.4)
        assert (servo.mode, servo.torque_enabled) == (dx.OperatingMode.POSITION, True)
        assert servo.get_raw(X.GOAL_POSITION) == dx.rad_to_ticks(0.4)
        assert writes_since(bus, start) == [(116, X.GOAL_POSITION.encode(dx.rad_to_ticks(0.4)))]
        assert m.get_control_mode() is MotorControlMode.POSITION
        with anyio.fail_after(WAIT_S):
            await position
        assert await m.get_position() == pytest.approx(0.4, abs=4 * TICK)

        start = len(bus.instructions)
        speed = await m.set_speed(2.0)  # tm_acc 0: the servo's configured acceleration
        assert (servo.mode, servo.torque_enabled) == (dx.OperatingMode.VELOCITY, True)
        assert writes_since(bus, start) == [
            (64, b"\x00"),  # torque off before the mode (EEPROM) write
            (11, bytes([dx.OperatingMode.VELOCITY])),
            (108, X.PROFILE_ACCELERATION.encode(400)),  # reset by the mode change: restored
            (104, X.GOAL_VELOCITY.encode(dx.rad_s_to_velocity(2.0))),
            (64, b"\x01"),
        ]
        assert m.get_control_mode() is MotorControlMode.SPEED
        with anyio.fail_after(WAIT_S):
            await speed
        assert await m.get_speed() == pytest.approx(2.0, abs=0.05 + VEL_UNIT)

        torque = await m.set_torque(0.3)  # Goal Current = 0.3 Nm / 1.5 Nm/A / 2.69 mA
        assert servo.mode == dx.OperatingMode.CURRENT
        assert servo.get_raw(X.GOAL_CURRENT) == round(0.3 / 1.5 / dx.CURRENT_UNIT_A)
        assert m.get_control_mode() is MotorControlMode.TORQUE
        with anyio.fail_after(WAIT_S):
            await torque
        assert await m.get_torque() == pytest.approx(0.3, abs=1.5 * dx.CURRENT_UNIT_A)

        await m.set_control_mode(MotorControlMode.READY_TO_CONTROL)
        assert not servo.torque_enabled
        assert m.get_control_mode() is MotorControlMode.READY_TO_CONTROL

        # SetControlMode(POSITION) holds the actual position: no jump, torque back on.
        hold = await m.set_control_mode(MotorControlMode.POSITION)
        assert (servo.mode, servo.torque_enabled) == (dx.OperatingMode.POSITION, True)
        assert servo.get_raw(X.GOAL_POSITION) == dx.rad_to_ticks(hold.target)
        with anyio.fail_after(WAIT_S):
            await hold
        assert await m.get_position() == pytest.approx(hold.target, abs=4 * TICK)


async def test_extended_position_mode_and_scale_factor(bus: SimDynamixelBus) -> None:
    async with (
        DynamixelPort(bus.path, baudrate=BAUD, return_delay=0.0, poll_period=0.005) as port,
        Motor(
            DynamixelXM430W350(port, 1, position_mode=dx.OperatingMode.EXTENDED_POSITION),
            scale_factor=360,
        ) as m,
    ):
        assert bus[1].mode == dx.OperatingMode.EXTENDED_POSITION
        # The mode change at init reset the profile: the driver wrote it again.
        assert bus[1].get_raw(X.PROFILE_ACCELERATION) == 400
        assert bus[1].get_raw(X.PROFILE_VELOCITY) == 400
        move = await m.set_position(450.0)  # degrees: beyond one turn
        assert bus[1].get_raw(X.GOAL_POSITION) == dx.rad_to_ticks(math.radians(450.0))
        with anyio.fail_after(WAIT_S):
            await move
        assert await m.get_position() == pytest.approx(450.0, abs=4 * 360 / 4096)


# -- tm_acc: the servo's Profile Acceleration ---------------------------------------------------


def test_profile_acceleration_from_the_ramp() -> None:
    ramp = VelocityRamp(start=0.0, target=6.0, duration_s=0.3)  # 20 rad/s^2
    assert profile_acceleration_for(ramp) == round(20.0 / ACC_UNIT) == 53
    # 214.577 rev/min^2 per unit = 0.374508 rad/s^2 (e-manual, X series).
    assert abs(ACC_UNIT - 214.577 * 2 * math.pi / 3600) < 1e-12
    assert profile_acceleration_for(VelocityRamp(2.0, -2.0, 4.0)) == round(1.0 / ACC_UNIT)
    assert profile_acceleration_for(VelocityRamp(0.0, 1e-4, 10.0)) == 1  # never 0 (unlimited)
    fastest = MAX_PROFILE_ACCELERATION * ACC_UNIT
    assert profile_acceleration_for(VelocityRamp(0.0, fastest, 1.0)) == MAX_PROFILE_ACCELERATION
    assert profile_acceleration_for(VelocityRamp(0.0, 2 * fastest, 1.0)) == 0


async def test_simulated_servo_ramps_at_profile_acceleration_on_a_virtual_clock() -> None:
    clock = VirtualClock()
    servo = SimServo(1, velocity_limit=600, clock=clock)
    for item, value in (
        (X.OPERATING_MODE, dx.OperatingMode.VELOCITY),
        (X.TORQUE_ENABLE, 1),
        (X.PROFILE_ACCELERATION, 53),  # 19.85 rad/s^2
        (X.GOAL_VELOCITY, dx.rad_s_to_velocity(6.0)),
    ):
        status = servo.handle(item.write(1, value))
        assert status is not None and status.error == 0
    t0 = clock.now_ns()
    rate = 53 * ACC_UNIT
    goal = dx.velocity_to_rad_s(dx.rad_s_to_velocity(6.0))
    assert servo.arrival_ns() - t0 == pytest.approx(goal / rate * 1e9, rel=1e-6)
    await clock.advance(150_000_000)
    _, velocity_ticks = servo.state()
    assert velocity_ticks * TICK == pytest.approx(rate * 0.15, rel=1e-6)
    await clock.advance(200_000_000)
    assert servo.state()[1] * TICK == pytest.approx(goal, rel=1e-9)


async def test_set_speed_with_tm_acc_uses_profile_acceleration(
    bus: SimDynamixelBus, port: DynamixelPort
) -> None:
    async with AsyncExitStack() as stack:
        m = await motor(stack, port)
        assert m.device.velocity_ramp
        servo = bus[1]
        start = len(bus.instructions)
        ramp = await m.set_speed(6.0, tm_acc=0.3)
        assert not m.ramping  # the servo ramps, the framework streams nothing
        units = round(6.0 / 0.3 / ACC_UNIT)
        assert writes_since(bus, start) == [
            (64, b"\x00"),
            (11, bytes([dx.OperatingMode.VELOCITY])),
            (108, X.PROFILE_ACCELERATION.encode(units)),  # before the goal: it shapes it
            (104, X.GOAL_VELOCITY.encode(dx.rad_s_to_velocity(6.0))),
            (64, b"\x01"),
        ]
        # The simulated servo plans the ramp over tm_acc (Goal Velocity quantised).
        # Within half a Profile Acceleration unit of the rate: 53 units for 20 rad/s^2.
        planned_s = (servo.arrival_ns() - servo.clock.now_ns()) / 1e9
        assert planned_s == pytest.approx(0.3, rel=0.5 / units + 0.05)
        assert m.get_control_mode() is MotorControlMode.SPEED
        with anyio.fail_after(WAIT_S):
            await ramp
        assert ramp.reached_ns is not None
        elapsed = (ramp.reached_ns - ramp.issued_ns) / 1e9
        # Completion comes at the end of the ramp (velocity within 0.05 rad/s), not before.
        assert elapsed >= 0.3 * (1 - 0.05 / 6.0) - 0.02
        assert await m.get_speed() == pytest.approx(6.0, abs=0.05 + VEL_UNIT)

        # A later command without tm_acc restores the configured acceleration.
        start = len(bus.instructions)
        await m.set_speed(1.0)
        assert writes_since(bus, start) == [
            (108, X.PROFILE_ACCELERATION.encode(400)),
            (104, X.GOAL_VELOCITY.encode(dx.rad_s_to_velocity(1.0))),
        ]


async def test_time_based_profile_falls_back_to_the_framework_ramp() -> None:
    servo = make_servo(1)
    servo.table[X.DRIVE_MODE.address] = 0x04  # time-based profile: 108 would be a time
    async with (
        SimDynamixelBus([servo]) as bus,
        DynamixelPort(bus.path, baudrate=BAUD, return_delay=0.0, poll_period=0.005) as port,
        Motor(DynamixelXM430W350(port, 1)) as m,
    ):
        assert not m.device.velocity_ramp
        ramp = await m.set_speed(3.0, tm_acc=0.1)
        assert m.ramping  # streamed by the framework
        with anyio.fail_after(WAIT_S):
            await ramp
        written = [
            X.GOAL_VELOCITY.decode(m_.data)
            for m_ in bus.instructions
            if isinstance(m_, dx.Write) and m_.address == X.GOAL_VELOCITY.address
        ]
        assert len(written) > 3 and written[-1] == dx.rad_s_to_velocity(3.0)
        assert bus[1].get_raw(X.PROFILE_ACCELERATION) == 400  # never touched by the ramp


# -- bad input ----------------------------------------------------------------------------------


async def test_bad_input_names_the_parameter_and_sends_nothing(
    bus: SimDynamixelBus, port: DynamixelPort
) -> None:
    async with AsyncExitStack() as stack:
        m = await motor(stack, port)
        before = (bus[1].mode, bus[1].get_raw(X.PROFILE_ACCELERATION))
        start = len(bus.instructions)
        cases: list[tuple[str, Any]] = [
            ("speed", m.set_speed(math.nan, 0.2)),
            ("tm_acc", m.set_speed(1.0, -0.1)),
            ("tm_acc", m.set_speed(1.0, math.inf)),
            ("speed", m.set_speed(100.0, 0.2)),  # above Velocity Limit (600 units)
            ("position", m.set_position(math.inf)),
            ("position", m.set_position(10.0)),  # outside Min/Max Position Limit
            ("mode", m.set_control_mode(16)),  # PWM has no HAL4RT mode
        ]
        for parameter, call in cases:
            with pytest.raises(BadParameterError) as excinfo:
                await call
            assert excinfo.value.parameter == parameter
        with pytest.raises(NotImplementedHALError, match="TORQUE"):
            await m.set_torque(0.1)  # no torque_constant: torque mode refused
        assert writes_since(bus, start) == []
        assert (bus[1].mode, bus[1].get_raw(X.PROFILE_ACCELERATION)) == before
        assert m.get_control_mode() is MotorControlMode.READY_TO_CONTROL


async def test_xl430_has_no_current_control(port: DynamixelPort) -> None:
    with pytest.raises(BadParameterError) as excinfo:
        DynamixelXL430W250(port, 1, torque_constant=1.0)
    assert excinfo.value.parameter == "torque_constant"
    assert DynamixelXL430W250(port, 1).supported_requests == {
        *DynamixelServo(port, 1).supported_requests
    }


async def test_model_class_refuses_another_model() -> None:
    async with (
        SimDynamixelBus([make_servo(1, model_number=1020)]) as bus,
        DynamixelPort(bus.path, baudrate=BAUD, return_delay=0.0) as port,
    ):
        with pytest.raises(HALError, match="model 1020, not the XL430W250"):
            async with Motor(DynamixelXL430W250(port, 1)):
                pass


# -- identity, profile, registry ----------------------------------------------------------------


def test_profile_carries_vendor_product_and_the_device_ramp() -> None:
    profile = profile_of(DynamixelXM430W350)
    assert (profile.kind_id, profile.vendor_id, profile.product_id) == (
        DeviceKind.MOTOR,
        ROBOTIS_VENDOR_ID,
        1020,
    )
    assert profile.component_name == "HalMotorRobotisXM430W350"
    assert profile.attributes["velocity_ramp"] is True
    assert profile.command("SetSpeed").parameters[1].name == "tmAcc"
    assert profile.command("reboot").id == 0x1000
    assert profile_of(DynamixelXL430W250).product_id == 1060
    json.dumps(profile.to_dict())  # plain JSON data


async def test_registry_creates_the_model_from_a_hal_id(bus: SimDynamixelBus) -> None:
    registry = DeviceRegistry.from_drivers()
    entry = registry.lookup(DeviceKind.MOTOR, ROBOTIS_VENDOR_ID, 1020)
    assert entry.device_class is DynamixelXM430W350 and entry.driver == "serial"
    assert registry.lookup(DeviceKind.MOTOR, ROBOTIS_VENDOR_ID, 1060).device_class is (
        DynamixelXL430W250
    )
    # The generic class (any model) has product id 0 and is not registered.
    assert any(label == "serial.dynamixel" for label, _ in registry.skipped)
    async with DynamixelPort(bus.path, baudrate=BAUD, return_delay=0.0) as port:
        component = registry.create(HALId(DeviceKind.MOTOR, ROBOTIS_VENDOR_ID, 1020, 7), port, 2)
        assert isinstance(component, Motor)
        async with component as m:
            assert m.hal_id.instance_id == 7 and m.profile_id == DeviceKind.MOTOR
            move = await m.set_position(-0.2)
            with anyio.fail_after(WAIT_S):
                await move
            assert bus[2].get_raw(X.GOAL_POSITION) == dx.rad_to_ticks(-0.2)


def test_cli_devices_profile_lists_the_dynamixel_models(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["devices", "--profile"]) == 0
    document = json.loads(capsys.readouterr().out)
    xm = document["devices"]["serial.dynamixel_xm430_w350"]
    assert (xm["vendor_id"], xm["product_id"], xm["vendor_name"]) == (
        ROBOTIS_VENDOR_ID,
        1020,
        "Robotis",
    )
    assert document["devices"]["serial.dynamixel_xl430_w250"]["product_id"] == 1060
    assert "serial.dynamixel" in document["not_registered"]


# -- interop: dynamixel-sdk reads back what the driver wrote ------------------------------------


@pytest.fixture
async def lone_bus() -> AsyncIterator[SimDynamixelBus]:
    async with SimDynamixelBus([make_servo(1)]) as sim:
        yield sim


async def test_sdk_reads_back_operating_mode_and_profile_acceleration(
    lone_bus: SimDynamixelBus,
) -> None:
    async with (
        DynamixelPort(lone_bus.path, baudrate=BAUD, return_delay=0.0, poll_period=0.005) as port,
        Motor(DynamixelXM430W350(port, 1)) as m,
    ):
        ramp = await m.set_speed(-4.0, tm_acc=0.5)  # 8 rad/s^2
        with anyio.fail_after(WAIT_S):
            await ramp
    # Our driver has closed the port (torque left on): ROBOTIS' SDK opens the same tty.
    handler = sdk.PortHandler(lone_bus.path)
    packets = sdk.PacketHandler(2.0)

    def read_back() -> tuple[tuple[int, int, int], tuple[int, int, int], tuple[int, int, int]]:
        assert handler.openPort() and handler.setBaudRate(BAUD)
        try:
            return (
                packets.read1ByteTxRx(handler, 1, X.OPERATING_MODE.address),
                packets.read4ByteTxRx(handler, 1, X.PROFILE_ACCELERATION.address),
                packets.read4ByteTxRx(handler, 1, X.GOAL_VELOCITY.address),
            )
        finally:
            handler.closePort()

    with anyio.fail_after(WAIT_S):
        mode, acceleration, goal = await anyio.to_thread.run_sync(read_back)
    assert mode == (dx.OperatingMode.VELOCITY, sdk.COMM_SUCCESS, 0)
    assert acceleration == (round(8.0 / ACC_UNIT), sdk.COMM_SUCCESS, 0)
    # read4ByteTxRx returns the unsigned 32-bit value: -4 rad/s in two's complement.
    assert goal[0] == dx.rad_s_to_velocity(-4.0) & 0xFFFFFFFF
