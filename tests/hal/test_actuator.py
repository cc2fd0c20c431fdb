"""Actuator.set_value/get_value: completion, supersession, bad input, faults, modes."""

from __future__ import annotations

import math

import anyio
import pytest

from openel_async import (
    Actuator,
    ActuatorDevice,
    ActuatorLimits,
    BadParameterError,
    CompletionPolicy,
    ComponentState,
    DeviceContext,
    DeviceFaultError,
    EventId,
    MotionCancelledError,
    NotImplementedHALError,
    Outcome,
    Request,
    ReturnCode,
    SupersededError,
    VirtualClock,
)
from openel_async.testing import ComponentStack, EventRecorder
from openel_sim import SimMotor

COMPLETED = EventId.COMPLETED


async def test_set_value_returns_at_once_and_completes_on_arrival(
    sim_actuator: Actuator, hal_events: EventRecorder, virtual_clock: VirtualClock
) -> None:
    start = virtual_clock.now_ns()
    motion = await sim_actuator.set_value(1.0, Request.POSITION)
    assert virtual_clock.now_ns() == start  # no simulated time passed: it did not wait
    assert motion.outcome is Outcome.PENDING
    record = await hal_events.wait_for("event", COMPLETED)
    # 1 rad at 2 rad/s, 10 rad/s^2: 0.2 s ramp up, 0.3 s cruise, 0.2 s ramp down.
    assert record.time_ns - start == 700_000_000
    await motion
    assert motion.outcome is Outcome.REACHED and motion.reached_ns == record.time_ns
    assert await sim_actuator.get_value(Request.POSITION_ACTUAL) == pytest.approx(1.0)
    assert await sim_actuator.get_value(Request.POSITION) == 1.0


async def test_completed_only_for_the_final_target(
    sim_actuator: Actuator, hal_events: EventRecorder, virtual_clock: VirtualClock
) -> None:
    first = await sim_actuator.set_value(1.0)
    await virtual_clock.sleep(0.1)
    second = await sim_actuator.set_value(-0.5)
    third = await sim_actuator.set_value(0.25)
    with pytest.raises(SupersededError):
        await first
    with pytest.raises(SupersededError):
        await second
    await third
    await virtual_clock.sleep(5)
    assert hal_events.count("event", COMPLETED) == 1
    assert first.outcome is second.outcome is Outcome.SUPERSEDED
    assert await sim_actuator.get_value(Request.POSITION_ACTUAL) == pytest.approx(0.25)


async def test_each_reached_target_completes_exactly_once(
    sim_actuator: Actuator, hal_events: EventRecorder, virtual_clock: VirtualClock
) -> None:
    for target in (0.3, -0.3, 0.0):
        await (await sim_actuator.set_value(target))
    await virtual_clock.sleep(2)
    assert hal_events.count("event", COMPLETED, source=sim_actuator) == 3
    assert sim_actuator.completed_count == 3


async def test_concurrent_waiters_on_one_motion(sim_actuator: Actuator) -> None:
    motion = await sim_actuator.set_value(0.4)
    done: list[int] = []

    async def waiter(i: int) -> None:
        await motion
        done.append(i)

    async with anyio.create_task_group() as tg:
        for i in range(3):
            tg.start_soon(waiter, i)
    assert sorted(done) == [0, 1, 2]


@pytest.mark.parametrize(
    ("value", "request_code", "parameter"),
    [
        (math.nan, Request.POSITION, "value"),
        (math.inf, Request.POSITION, "value"),
        (-math.inf, Request.VELOCITY, "value"),
        ("1.0", Request.POSITION, "value"),
        (None, Request.POSITION, "value"),
        (4.0, Request.POSITION, "value"),  # beyond the +-pi position limits
        (2.5, Request.VELOCITY, "value"),  # beyond 2 rad/s
        (-3.0, Request.TORQUE, "value"),  # beyond 2 Nm
        (0.1, 4, "request"),
        (0.1, Request.POSITION_ACTUAL, "request"),
        (0.1, "POSITION", "request"),
    ],
)
async def test_bad_input_is_refused_and_changes_nothing(
    sim_actuator: Actuator,
    hal_events: EventRecorder,
    value: object,
    request_code: object,
    parameter: str,
) -> None:
    motion = await sim_actuator.set_value(0.5)
    with pytest.raises(BadParameterError) as info:
        await sim_actuator.set_value(value, request_code)  # type: ignore[arg-type]
    assert info.value.parameter == parameter
    assert info.value.code is ReturnCode.HAL_BAD_PARAMETER
    assert sim_actuator.state is ComponentState.ACTIVE
    assert sim_actuator.motion is motion  # the running command was not replaced
    await motion  # ...and its completion is not lost
    assert (await hal_events.wait_for("event", COMPLETED)).source is sim_actuator


async def test_get_value_request_codes(sim_actuator: Actuator) -> None:
    assert await sim_actuator.get_value(Request.POSITION) == 0.0  # before any command
    await sim_actuator.set_value(1.5, Request.VELOCITY)
    assert await sim_actuator.get_value(2) == 1.5
    assert await sim_actuator.get_value(Request.VELOCITY_ACTUAL) == 0.0
    for bad in (0, 4, 8, "x"):
        with pytest.raises(BadParameterError, match="request"):
            await sim_actuator.get_value(bad)  # type: ignore[arg-type]


async def test_velocity_mode_completes_when_the_velocity_is_reached(
    sim_actuator: Actuator, virtual_clock: VirtualClock
) -> None:
    start = virtual_clock.now_ns()
    await (await sim_actuator.set_value(1.0, Request.VELOCITY))
    assert virtual_clock.now_ns() - start == 100_000_000  # 1 rad/s at 10 rad/s^2
    assert await sim_actuator.get_value(Request.VELOCITY_ACTUAL) == pytest.approx(1.0)


async def test_velocity_mode_stops_at_the_position_limit_with_an_event(
    sim_actuator: Actuator, hal_events: EventRecorder, virtual_clock: VirtualClock
) -> None:
    await (await sim_actuator.set_value(2.0, Request.VELOCITY))
    record = await hal_events.wait_for("event", EventId.LIMIT_REACHED)
    # 0.2 s ramp covers 0.2 rad; the remaining pi - 0.2 rad at 2 rad/s.
    assert record.time_ns == pytest.approx(200_000_000 + (math.pi - 0.2) / 2.0 * 1e9, abs=2)
    assert await sim_actuator.get_value(Request.POSITION_ACTUAL) == pytest.approx(math.pi)
    assert await sim_actuator.get_value(Request.VELOCITY_ACTUAL) == 0.0


async def test_torque_mode_accelerates_the_rotor(
    sim_actuator: Actuator, virtual_clock: VirtualClock
) -> None:
    await (await sim_actuator.set_value(0.1, Request.TORQUE))
    assert await sim_actuator.get_value(Request.TORQUE_ACTUAL) == pytest.approx(0.1)
    await virtual_clock.sleep(0.1)
    # a = tau / J = 10 rad/s^2
    assert await sim_actuator.get_value(Request.VELOCITY_ACTUAL) == pytest.approx(1.0, rel=0.03)


async def test_no_excite_coasts_to_rest_and_completes_at_once(
    sim_actuator: Actuator, hal_events: EventRecorder, virtual_clock: VirtualClock
) -> None:
    moving = await sim_actuator.set_value(2.0, Request.VELOCITY)
    await moving
    stop = await sim_actuator.set_value(0.0, Request.NO_EXCITE)
    assert stop.outcome is Outcome.REACHED
    assert hal_events.count("event", COMPLETED) == 2
    await virtual_clock.sleep(1.0)
    assert await sim_actuator.get_value(Request.VELOCITY_ACTUAL) == 0.0


async def test_stuck_motor_never_completes(
    sim_actuator: Actuator, sim_motor: SimMotor, virtual_clock: VirtualClock
) -> None:
    sim_motor.set_stuck()
    motion = await sim_actuator.set_value(1.0)
    await virtual_clock.sleep(60)
    assert motion.outcome is Outcome.PENDING
    assert await sim_actuator.get_value(Request.POSITION_ACTUAL) == 0.0


async def test_fault_fails_the_pending_motion(
    sim_actuator: Actuator,
    sim_motor: SimMotor,
    hal_events: EventRecorder,
    virtual_clock: VirtualClock,
) -> None:
    motion = await sim_actuator.set_value(1.0)
    await virtual_clock.sleep(0.1)
    sim_motor.inject_fault(error_id=9)
    with pytest.raises(DeviceFaultError) as info:
        await motion
    assert info.value.error_id == 9
    assert hal_events.count("error", 9) == 1
    assert hal_events.count("event", COMPLETED) == 0
    await sim_actuator.re_init()
    await (await sim_actuator.set_value(0.0))


async def test_finalize_cancels_the_pending_motion(sim_actuator: Actuator) -> None:
    motion = await sim_actuator.set_value(1.0)
    await sim_actuator.finalize()
    with pytest.raises(MotionCancelledError):
        await motion


async def test_unsupported_mode_is_not_implemented(hal_components: ComponentStack) -> None:
    class PositionOnly(SimMotor):
        supported_requests = frozenset({Request.POSITION})

    motor = await hal_components.actuator(PositionOnly())
    with pytest.raises(NotImplementedHALError) as info:
        await motor.set_value(0.1, Request.VELOCITY)
    assert info.value.code is ReturnCode.HAL_NOT_IMPLEMENTED


class LagMotor(ActuatorDevice):
    """A first-order lag that cannot report completion: the framework must detect it."""

    limits = ActuatorLimits((-10.0, 10.0), 5.0, 1.0)
    supported_requests = frozenset({Request.POSITION})

    def __init__(self, time_constant: float = 0.05, offset: float = 0.0) -> None:
        self.tau = time_constant
        self.offset = offset
        self.target = 0.0
        self.start = 0.0
        self.since = 0
        self.clock: VirtualClock | None = None

    async def open(self, ctx: DeviceContext) -> None:
        assert isinstance(ctx.clock, VirtualClock)
        self.clock = ctx.clock

    def position(self) -> float:
        assert self.clock is not None
        dt = (self.clock.now_ns() - self.since) / 1e9
        return self.target + (self.start - self.target) * math.exp(-dt / self.tau) + self.offset

    async def command(self, request: Request, value: float) -> None:
        assert self.clock is not None
        self.start, self.target, self.since = (
            self.position() - self.offset,
            value,
            self.clock.now_ns(),
        )

    async def read(self, request: Request) -> float:
        return self.position() if request is Request.POSITION_ACTUAL else 0.0


async def test_completion_by_tolerance_and_settle_time(
    hal_components: ComponentStack, hal_events: EventRecorder, virtual_clock: VirtualClock
) -> None:
    policy = CompletionPolicy(position_tolerance=1e-3, settle_ns=50_000_000, poll_ns=1_000_000)
    motor = await hal_components.actuator(LagMotor(), completion=policy)
    motor.add_observer(hal_events)
    start = virtual_clock.now_ns()
    await (await motor.set_value(1.0))
    # Within 1e-3 of 1.0 once exp(-t/0.05) <= 1e-3: t = 0.05 ln(1000) = 345.4 ms,
    # first seen at the next 1 ms poll, then held for the 50 ms settle time.
    elapsed = virtual_clock.now_ns() - start
    assert 395_000_000 <= elapsed <= 397_000_000
    assert hal_events.count("event", COMPLETED) == 1


async def test_tolerance_detection_never_completes_outside_tolerance(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    motor = await hal_components.actuator(LagMotor(offset=0.01))
    motion = await motor.set_value(1.0)
    await virtual_clock.sleep(10)
    assert motion.outcome is Outcome.PENDING


class CountingLag(LagMotor):
    def __init__(self) -> None:
        super().__init__()
        self.reads = 0
        self.fail_with: Exception | None = None

    async def read(self, request: Request) -> float:
        self.reads += 1
        if self.fail_with is not None:
            raise self.fail_with
        return await super().read(request)


async def test_one_completion_detector_survives_fault_cycles(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    from openel_async import ErrorId

    device = CountingLag()
    policy = CompletionPolicy(settle_ns=10**9, poll_ns=1_000_000)
    motor = await hal_components.actuator(device, completion=policy)
    for _ in range(3):
        await motor.set_value(1.0)
        await virtual_clock.sleep(0.01)
        motor._fault(ErrorId.DEVICE_ERROR, "test fault")
        await motor.re_init()
    await motor.set_value(2.0)
    await virtual_clock.sleep(0.001)
    before = device.reads
    await virtual_clock.sleep(0.1)
    assert device.reads - before == 100  # one poll per ms: a single detector polls


async def test_a_driver_bug_in_the_detector_faults_instead_of_tearing_down(
    hal_components: ComponentStack, hal_events: EventRecorder, virtual_clock: VirtualClock
) -> None:
    from openel_async import ErrorId

    device = CountingLag()
    motor = await hal_components.actuator(device)
    motor.add_observer(hal_events)
    device.fail_with = ValueError("driver bug")
    motion = await motor.set_value(1.0)
    with pytest.raises(DeviceFaultError, match="driver bug"):
        await motion
    assert motor.state is ComponentState.ERROR
    assert hal_events.count("error", ErrorId.DEVICE_ERROR) == 1
    device.fail_with = None
    await motor.re_init()
    await (await motor.set_value(0.5))


async def test_no_notification_after_finalize(
    sim_actuator: Actuator, hal_events: EventRecorder, virtual_clock: VirtualClock
) -> None:
    await sim_actuator.set_value(2.0, Request.VELOCITY)  # would hit the limit at ~1.67 s
    await virtual_clock.sleep(0.5)
    await sim_actuator.finalize()
    hal_events.clear()
    await virtual_clock.sleep(5)
    assert hal_events.records == []


def test_check_code_raises_the_matching_exception() -> None:
    from openel_async.errors import check_code

    with pytest.raises(BadParameterError):
        check_code(ReturnCode.HAL_BAD_PARAMETER, "bad")
    with pytest.raises(NotImplementedHALError):
        check_code(ReturnCode.HAL_NOT_IMPLEMENTED)
