"""HAL4RT Motor (§7.4.5.3-7.4.5.4) on the virtual clock: modes, scale factor, origin, tm_acc."""

from __future__ import annotations

import itertools
import math

import pytest

from openel_async import (
    Actuator,
    ActuatorDevice,
    ActuatorLimits,
    BadParameterError,
    ComponentState,
    DeviceInfo,
    DeviceKind,
    EventId,
    Motor,
    MotorControlMode,
    NotImplementedHALError,
    Outcome,
    Request,
    SupersededError,
    VelocityRamp,
    VirtualClock,
)
from openel_async.ramp import streamer_for
from openel_async.testing import ComponentStack, EventRecorder
from openel_sim import SimMotor

M = MotorControlMode


async def motor_of(
    stack: ComponentStack, device: ActuatorDevice | None = None, **kwargs: object
) -> Motor:
    motor = Motor(device or SimMotor(), clock=stack.clock, **kwargs)  # type: ignore[arg-type]
    return await stack.enter(motor)


class SpeedDrive(ActuatorDevice):
    """A drive with no ramp of its own: it is at the commanded velocity at once."""

    info = DeviceInfo(DeviceKind.MOTOR, 0x0E1, 0x7001, "Test", "SpeedDrive")
    reports_completion = True

    def __init__(self, *, linear: bool = False) -> None:
        self.velocity = 0.0
        self.position = 0.0
        self.commands: list[tuple[Request, float]] = []
        self.linear = linear
        self.ctx = None

    async def open(self, ctx):  # type: ignore[no-untyped-def]
        self.ctx = ctx

    async def command(self, request: Request, value: float) -> None:
        self.command_nowait(request, value)

    def command_nowait(self, request: Request, value: float) -> None:
        self.commands.append((request, value))
        if request is Request.VELOCITY:
            self.velocity = value
        elif request is Request.POSITION:
            self.position = value
        assert self.ctx is not None
        self.ctx.target_reached()  # reaches every target at once

    async def read(self, request: Request) -> float:
        return self.read_nowait(request)

    def read_nowait(self, request: Request) -> float:
        return self.velocity if request is Request.VELOCITY_ACTUAL else self.position


class RampDrive(SpeedDrive):
    """A drive with its own ramp generator: records the VelocityRamp it gets."""

    velocity_ramp = True

    def __init__(self) -> None:
        super().__init__()
        self.ramps: list[VelocityRamp] = []

    async def command_velocity_ramp(self, ramp: VelocityRamp) -> None:
        self.ramps.append(ramp)


# -- modes (Fig. 7.10) --------------------------------------------------------------------
async def test_mode_is_wait_before_the_first_command_and_follows_each_set(
    hal_components: ComponentStack,
) -> None:
    motor = await motor_of(hal_components)
    assert motor.get_control_mode() is M.READY_TO_CONTROL
    await motor.set_position(1.0)
    assert motor.get_control_mode() is M.POSITION
    await motor.set_speed(0.5)
    assert motor.get_control_mode() is M.SPEED
    await motor.set_torque(0.1)
    assert motor.get_control_mode() is M.TORQUE
    await motor.set_value(0.0, Request.NO_EXCITE)
    assert motor.get_control_mode() is M.READY_TO_CONTROL
    await motor.set_value(0.2, Request.POSITION)  # the OpenEL name switches the mode too
    assert motor.get_control_mode() is M.POSITION
    assert motor.actuator_kind == DeviceKind.MOTOR and isinstance(motor, Actuator)


async def test_mode_is_wait_again_after_re_init(hal_components: ComponentStack) -> None:
    device = SimMotor()
    motor = await motor_of(hal_components, device)
    await motor.set_speed(1.0)
    device.inject_fault()
    assert motor.state is ComponentState.ERROR
    await motor.re_init()
    assert motor.get_control_mode() is M.READY_TO_CONTROL


async def test_set_control_mode_enters_each_mode_without_a_jump(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    device = SimMotor()
    motor = await motor_of(hal_components, device)
    await (await motor.set_position(1.0))
    motion = await motor.set_control_mode(M.SPEED)
    assert motor.get_control_mode() is M.SPEED
    assert motion.request is Request.VELOCITY and motion.target == pytest.approx(0.0, abs=1e-9)
    motion = await motor.set_control_mode(2)  # the mode in force: nothing changes
    assert motion is motor.motion
    await motor.set_control_mode(M.POSITION)
    assert motor.motion is not None and motor.motion.target == pytest.approx(1.0)
    await motor.set_control_mode(M.READY_TO_CONTROL)
    assert motor.get_control_mode() is M.READY_TO_CONTROL
    assert motor.motion is not None and motor.motion.outcome is Outcome.REACHED


@pytest.mark.parametrize("mode", [4, -1, "POSITION", 1.0, None, True])
async def test_unknown_mode_is_refused_and_nothing_changes(
    hal_components: ComponentStack, mode: object
) -> None:
    motor = await motor_of(hal_components)
    await motor.set_position(0.5)
    before = motor.motion
    with pytest.raises(BadParameterError) as info:
        await motor.set_control_mode(mode)  # type: ignore[arg-type]
    assert info.value.parameter == "mode"
    assert motor.motion is before and motor.get_control_mode() is M.POSITION


async def test_unsupported_mode_is_not_implemented(hal_components: ComponentStack) -> None:
    device = SpeedDrive()
    device.supported_requests = frozenset({Request.NO_EXCITE, Request.VELOCITY})
    motor = await motor_of(hal_components, device)
    with pytest.raises(NotImplementedHALError):
        await motor.set_control_mode(M.TORQUE)
    with pytest.raises(NotImplementedHALError):
        await motor.set_position(1.0)
    assert motor.get_control_mode() is M.READY_TO_CONTROL


# -- scale factor and origin ------------------------------------------------------------
async def test_scale_factor_360_gives_degrees(
    hal_components: ComponentStack, hal_events: EventRecorder
) -> None:
    motor = await motor_of(hal_components, scale_factor=360)
    motor.add_observer(hal_events)
    assert motor.scale_factor == 360.0
    motion = await motor.set_position(90.0)
    assert motion.target == pytest.approx(math.pi / 2)  # the device gets SI
    assert motion.outcome is Outcome.PENDING  # returns at once
    await motion
    assert hal_events.count("event", EventId.COMPLETED) == 1
    assert await motor.get_position() == pytest.approx(90.0)
    assert await motor.get_value(Request.POSITION_ACTUAL) == pytest.approx(math.pi / 2)
    await (await motor.set_speed(-36.0))
    assert await motor.get_speed() == pytest.approx(-36.0)
    assert await motor.get_value(Request.VELOCITY_ACTUAL) == pytest.approx(-math.pi / 5)


async def test_default_scale_factors_rotary_and_linear(hal_components: ComponentStack) -> None:
    rotary = await motor_of(hal_components)
    linear = await motor_of(hal_components, SpeedDrive(linear=True))
    assert rotary.get_scale_factor() == pytest.approx(2 * math.pi)
    assert linear.get_scale_factor() == 1.0
    await linear.set_position(0.25)
    assert linear.device.position == 0.25  # type: ignore[attr-defined]
    linear.set_scale_factor(1000.0)  # millimetres
    assert await linear.get_position() == pytest.approx(250.0)


@pytest.mark.parametrize("bad", [0, 0.0, math.nan, math.inf, "1", None, True])
async def test_bad_scale_factor_is_refused(hal_components: ComponentStack, bad: object) -> None:
    motor = await motor_of(hal_components)
    with pytest.raises(BadParameterError) as info:
        motor.set_scale_factor(bad)  # type: ignore[arg-type]
    assert info.value.parameter == "scale_factor"
    assert motor.scale_factor == pytest.approx(2 * math.pi)
    if bad is not None:  # None is the constructor's "the default"
        with pytest.raises(BadParameterError):
            Motor(SimMotor(), scale_factor=bad)  # type: ignore[arg-type]


async def test_set_origin_offsets_later_positions_and_survives_re_init(
    hal_components: ComponentStack,
) -> None:
    device = SimMotor()
    motor = await motor_of(hal_components, device, scale_factor=360)
    await (await motor.set_position(90.0))
    await motor.set_origin(0.0)  # here is 0
    assert motor.origin == pytest.approx(math.pi / 2)
    assert await motor.get_position() == pytest.approx(0.0)
    motion = await motor.set_position(-45.0)
    assert motion.target == pytest.approx(math.pi / 4)
    await motion
    assert await motor.get_position() == pytest.approx(-45.0)
    await motor.set_origin(math.pi)  # HAL4RT: the position argument is in rad
    assert await motor.get_position() == pytest.approx(180.0)
    device.inject_fault()
    await motor.re_init()
    assert await motor.get_position() == pytest.approx(180.0)


async def test_position_outside_the_limits_is_told_in_motor_units(
    hal_components: ComponentStack,
) -> None:
    motor = await motor_of(hal_components, scale_factor=360)  # limits +-pi rad
    with pytest.raises(BadParameterError, match=r"\[-180.0, 180.0\]") as info:
        await motor.set_position(200.0)
    assert info.value.parameter == "position"
    assert motor.motion is None
    with pytest.raises(BadParameterError) as info:
        await motor.set_position(math.nan)
    assert info.value.parameter == "position"
    with pytest.raises(BadParameterError) as info:
        await motor.set_speed(1000.0)
    assert info.value.parameter == "speed"
    with pytest.raises(BadParameterError) as info:
        await motor.set_torque(50.0)
    assert info.value.parameter == "torque"
    with pytest.raises(BadParameterError) as info:
        await motor.set_origin(math.inf)
    assert info.value.parameter == "position" and motor.origin == 0.0


async def test_get_torque_is_the_actual_torque(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    motor = await motor_of(hal_components)
    await motor.set_torque(0.5)
    await virtual_clock.sleep(0.01)  # past the current loop's rise time
    assert await motor.get_torque() == pytest.approx(0.5)


# -- tm_acc --------------------------------------------------------------------------------
@pytest.mark.parametrize("bad", [-0.1, math.nan, math.inf, -math.inf, "1", None])
async def test_bad_tm_acc_is_refused_and_nothing_changes(
    hal_components: ComponentStack, bad: object
) -> None:
    device = SpeedDrive()
    motor = await motor_of(hal_components, device)
    with pytest.raises(BadParameterError) as info:
        await motor.set_speed(1.0, bad)  # type: ignore[arg-type]
    assert info.value.parameter == "tm_acc"
    assert device.commands == [] and motor.motion is None


async def test_framework_ramp_streams_every_millisecond_and_completes_at_the_end(
    hal_components: ComponentStack, virtual_clock: VirtualClock, hal_events: EventRecorder
) -> None:
    device = SpeedDrive()
    motor = await motor_of(hal_components, device)
    motor.add_observer(hal_events)
    start = virtual_clock.now_ns()
    motion = await motor.set_speed(2.0, 0.1)
    assert motion.outcome is Outcome.PENDING and motor.ramping
    assert device.commands == [(Request.VELOCITY, 0.0)]  # velocity mode at the start speed
    await virtual_clock.sleep(0.0505)  # after the setpoint of 50 ms
    assert await motor.get_speed() == pytest.approx(1.0, rel=1e-9)
    assert motion.outcome is Outcome.PENDING  # every setpoint is "reached": not final
    await motion
    assert motion.reached_ns == start + 100_000_000
    values = [v for _, v in device.commands]
    assert len(values) == 101  # the start and one setpoint per ms
    assert values[-1] == 2.0 / (2 * math.pi) * 2 * math.pi  # SI target
    steps = [b - a for a, b in itertools.pairwise(values)]
    assert all(s == pytest.approx(0.02) for s in steps)
    assert hal_events.count("event", EventId.COMPLETED) == 1
    assert not motor.ramping and motor.get_control_mode() is M.SPEED


async def test_next_command_supersedes_the_ramp(
    hal_components: ComponentStack, virtual_clock: VirtualClock, hal_events: EventRecorder
) -> None:
    device = SpeedDrive()
    motor = await motor_of(hal_components, device)
    motor.add_observer(hal_events)
    ramp = await motor.set_speed(1.0, 1.0)
    await virtual_clock.sleep(0.2)
    sent = len(device.commands)
    motion = await motor.set_position(0.0)
    with pytest.raises(SupersededError):
        await ramp
    await virtual_clock.sleep(0.1)
    assert device.commands[sent:] == [(Request.POSITION, 0.0)]  # no setpoint after it
    assert motion.outcome is Outcome.REACHED and not motor.ramping
    assert hal_events.count("event", EventId.COMPLETED) == 1


async def test_a_ramp_from_a_ramp_starts_at_its_current_setpoint(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    device = SpeedDrive()
    motor = await motor_of(hal_components, device, scale_factor=1.0)
    first = await motor.set_speed(1.0, 1.0)
    await virtual_clock.sleep(0.5)
    second = await motor.set_speed(0.0, 0.5)
    assert first.outcome is Outcome.SUPERSEDED
    assert device.commands[-1] == (Request.VELOCITY, pytest.approx(math.pi))  # 0.5 rev/s
    await second
    assert device.velocity == 0.0


async def test_native_ramp_gets_the_velocity_ramp(hal_components: ComponentStack) -> None:
    device = RampDrive()
    motor = await motor_of(hal_components, device, scale_factor=360)
    motion = await motor.set_speed(90.0, 0.5)
    assert device.ramps == [VelocityRamp(0.0, math.pi / 2, 0.5)]
    assert device.ramps[0].rate == pytest.approx(math.pi)
    assert device.commands == [] and not motor.ramping
    assert motion.request is Request.VELOCITY and motion.target == pytest.approx(math.pi / 2)


async def test_zero_tm_acc_is_a_plain_velocity_command(hal_components: ComponentStack) -> None:
    device = RampDrive()
    motor = await motor_of(hal_components, device)
    await motor.set_speed(1.0, 0.0)
    assert device.ramps == [] and device.commands == [
        (Request.VELOCITY, 1.0 / (2 * math.pi) * 2 * math.pi)
    ]


@pytest.mark.parametrize("native", [True, False])
async def test_sim_motor_reaches_the_speed_in_tm_acc(
    hal_components: ComponentStack, virtual_clock: VirtualClock, native: bool
) -> None:
    motor = await motor_of(hal_components, SimMotor(native_ramp=native), scale_factor=360)
    start = virtual_clock.now_ns()
    motion = await motor.set_speed(60.0, 0.5)  # well under the drive's acceleration limit
    await virtual_clock.sleep(0.25)
    assert await motor.get_speed() == pytest.approx(30.0, abs=0.5)
    await motion
    assert motion.reached_ns is not None
    assert 0.5 <= (motion.reached_ns - start) / 1e9 <= 0.502
    assert await motor.get_speed() == pytest.approx(60.0)


async def test_one_streamer_serves_every_motor_on_a_clock(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    devices = [SpeedDrive() for _ in range(8)]
    motors = [await motor_of(hal_components, d) for d in devices]
    streamer = streamer_for(virtual_clock)
    ticks = streamer.ticks
    motions = [await m.set_speed(1.0, 0.01) for m in motors]
    assert len(streamer) == 8
    for motion in motions:
        await motion
    assert streamer.ticks - ticks == 10  # one wake per ms for all eight
    assert all(len(d.commands) == 11 for d in devices)


async def test_the_ramp_moves_to_another_host_when_its_host_exits(
    virtual_clock: VirtualClock,
) -> None:
    first, second = SpeedDrive(), SpeedDrive()
    async with Motor(second, clock=virtual_clock) as other:
        async with Motor(first, clock=virtual_clock) as host:
            await host.set_speed(1.0, 1.0)  # starts the streamer in host's task group
            motion = await other.set_speed(1.0, 0.2)
            await virtual_clock.sleep(0.05)
        await motion  # streamed on after host exited
        assert second.velocity == 1.0


async def test_finalize_cancels_the_ramp(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    device = SpeedDrive()
    motor = await motor_of(hal_components, device)
    motion = await motor.set_speed(1.0, 1.0)
    await motor.finalize()
    sent = len(device.commands)
    await virtual_clock.sleep(0.1)
    assert motion.outcome is Outcome.CANCELLED and len(device.commands) == sent


async def test_motor_keeps_the_actuator_attribute_budget(hal_components: ComponentStack) -> None:
    motor = await motor_of(hal_components)
    assert len(vars(motor)) <= 29, sorted(vars(motor))


async def test_actuator_with_limits_on_bank_paths_stays_raw(hal_components: ComponentStack) -> None:
    """set_value/get_value and banks stay in the device's SI frame: only HAL4RT names scale."""
    device = SimMotor(position_limits=(-1.0, 1.0))
    device.limits = ActuatorLimits((-1.0, 1.0), 2.0, 2.0)
    motor = await motor_of(hal_components, device, scale_factor=360)
    await (await motor.set_value(0.5, Request.POSITION))
    assert await motor.get_value() == pytest.approx(0.5)
    assert await motor.get_position() == pytest.approx(math.degrees(0.5))
