"""The proven streaming tick: a motion whose whole planned path lies within every device's
limits (ruckig's position extrema, checked once when it is planned) streams its batches
without checking each value again; what can change during the motion is still checked
before every batch (an axis leaving Active: finalized, faulted, disconnected), and a path
that cannot be proven is checked value by value as before."""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from typing import Any, cast

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from ruckig import InputParameter, Ruckig, Synchronization, Trajectory

from openel_async import (
    ActuatorDevice,
    ActuatorLimits,
    BadParameterError,
    ComponentState,
    DeviceFaultError,
    EventTimer,
    Request,
    VirtualClock,
)
from openel_async.device import BatchCommander
from openel_async.motion import (
    AxisFaultError,
    AxisGroup,
    AxisLimits,
    GroupOutcome,
    MotionStoppedError,
    PreemptedError,
)
from openel_async.motion.planner import KinematicState, Planner, trajectory_range
from openel_async.testing import ComponentStack
from openel_sim import SimMotor

from .rigs import LIMITS

MS = 1_000_000


class BatchMotor(SimMotor):
    """A SimMotor commanded through SimMotor's batch path, recording every batched setpoint."""

    def __init__(self, **kwargs: Any) -> None:
        kwargs.setdefault("max_velocity", 20.0)
        kwargs.setdefault("max_acceleration", 1e5)
        super().__init__(**kwargs)
        self.batches: list[tuple[int, float]] = []

    @classmethod
    def batch_commander(cls, devices: Sequence[ActuatorDevice]) -> BatchCommander | None:
        inner = super().batch_commander(devices)
        if inner is None:
            return None
        motors = tuple(cast(BatchMotor, d) for d in devices)

        def command_all(request: Request, values: Sequence[float], /) -> bool:
            if not inner(request, values):
                return False
            for motor, value in zip(motors, values, strict=True):
                motor.batches.append((motor._now(), value))
            return True

        return command_all


async def _group(
    hal_components: ComponentStack, clock: VirtualClock, motors: list[BatchMotor]
) -> tuple[AxisGroup, list[Any], EventTimer]:
    actuators = [
        await hal_components.actuator(m, device_name=f"joint{i}") for i, m in enumerate(motors)
    ]
    timer = EventTimer(1, clock=clock)
    return AxisGroup(actuators, timer=timer, limits=LIMITS), actuators, timer


def _proven(group: AxisGroup) -> bool:
    """Whether the running motion streams through the proven tick."""
    return group._fast is not None and group._fast_motion is group.current


async def test_a_proven_move_sends_the_plan_and_completes_only_the_final_target(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    motors = [BatchMotor() for _ in range(3)]
    group, actuators, timer = await _group(hal_components, virtual_clock, motors)
    async with timer, group:
        motion = await group.move_to([0.5, -0.25, 1.0])
        assert _proven(group)
        await motion
        assert motion.outcome is GroupOutcome.SUCCEEDED
        plan = motion._plan
        for i, motor in enumerate(motors):
            # One setpoint per tick, each the plan's position at that tick, the last exact.
            times = [t for t, _ in motor.batches]
            assert times == sorted(set(times)) and len(times) > 100
            assert [v for _, v in motor.batches] == [plan.positions(t)[i] for t in times]
            assert motor.batches[-1][1] == [0.5, -0.25, 1.0][i]
        for actuator, target in zip(actuators, [0.5, -0.25, 1.0], strict=True):
            latest = actuator.motion
            assert latest is not None and latest.target == target
        samples = group.log.snapshot()
        sent = [v for _, v in motors[2].batches]
        assert list(samples.commanded[: len(sent), 2]) == sent


async def test_an_axis_finalized_mid_proven_move_stops_the_next_batch(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    motors = [BatchMotor() for _ in range(3)]
    group, actuators, timer = await _group(hal_components, virtual_clock, motors)
    async with timer, group:
        motion = await group.move_to([1.0, 1.0, 1.0])
        assert _proven(group)
        await virtual_clock.sleep(0.2)
        sent = [len(m.batches) for m in motors]
        await actuators[1].finalize()
        with pytest.raises(AxisFaultError) as info:
            await motion
        assert info.value.axis == 1 and "Finalized" in str(info.value)
        await virtual_clock.sleep(0.05)
        # Not one batch after the axis left Active.
        assert [len(m.batches) for m in motors] == sent


async def test_a_fault_mid_proven_move_stops_the_next_batch(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    motors = [BatchMotor() for _ in range(3)]
    group, actuators, timer = await _group(hal_components, virtual_clock, motors)
    async with timer, group:
        motion = await group.move_to([1.0, -1.0, 0.5])
        assert _proven(group)
        await virtual_clock.sleep(0.3)
        sent = [len(m.batches) for m in motors]
        motors[2].inject_fault(reason="overcurrent")
        with pytest.raises(AxisFaultError) as info:
            await motion
        assert info.value.axis == 2 and isinstance(info.value.cause, DeviceFaultError)
        assert "overcurrent" in str(info.value)
        assert actuators[2].state is ComponentState.ERROR
        await virtual_clock.sleep(0.05)
        assert [len(m.batches) for m in motors] == sent
        # Re-initialized, the group moves again, proven.
        await actuators[2].re_init()
        again = await group.move_to([0.0, 0.0, 0.0])
        assert _proven(group)
        await again
        assert again.outcome is GroupOutcome.SUCCEEDED


async def test_a_link_fault_mid_proven_move_names_the_axis_and_the_rest_hold(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    motors = [BatchMotor() for _ in range(3)]
    group, actuators, timer = await _group(hal_components, virtual_clock, motors)
    async with timer, group:
        motion = await group.move_to([0.4, 0.4, 0.4])
        assert _proven(group)
        await virtual_clock.sleep(0.1)
        motors[1].connected = False  # the batch declines; command_nowait raises
        with pytest.raises(AxisFaultError) as info:
            await motion
        assert info.value.axis == 1 and actuators[1].state is ComponentState.ERROR
        commands = [m.commands for m in motors]
        await virtual_clock.sleep(0.05)
        assert [m.commands for m in motors] == commands


async def test_preemption_and_stop_on_the_proven_path_have_no_jump(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    motors = [BatchMotor() for _ in range(2)]
    group, _, timer = await _group(hal_components, virtual_clock, motors)
    async with timer, group:
        first = await group.move_to([1.0, 1.0])
        await virtual_clock.sleep(0.3)
        second = await group.move_to([-0.5, 0.2])
        assert _proven(group)
        with pytest.raises(PreemptedError):
            await first
        await virtual_clock.sleep(0.2)
        await group.stop()
        with pytest.raises(MotionStoppedError):
            await second
    values = [v for _, v in motors[0].batches]
    steps = [abs(b - a) for a, b in itertools.pairwise(values)]
    assert max(steps) < LIMITS.max_velocity * 1e-3 * 1.01


async def test_a_path_touching_a_limit_is_checked_value_by_value(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    motors = [BatchMotor(position_limits=(-1.0, 1.0)) for _ in range(2)]
    group, _, timer = await _group(hal_components, virtual_clock, motors)
    async with timer, group:
        inside = await group.move_to([0.5, -0.5])
        assert _proven(group)
        await inside
        motion = await group.move_to([1.0, 0.5])  # ends on the limit: not proven
        assert not _proven(group)
        await motion
        assert motion.outcome is GroupOutcome.SUCCEEDED
        assert motors[0].batches[-1][1] == 1.0


async def test_limits_widened_after_the_group_was_built_are_used_for_the_proof(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    """The bank re-reads its devices' limits when any were set: a path beyond those it was
    built with, within the devices' current ones, is proven."""
    motors = [BatchMotor(position_limits=(-1.0, 1.0)) for _ in range(2)]
    group, _, timer = await _group(hal_components, virtual_clock, motors)
    async with timer, group:
        for motor in motors:
            motor.limits = ActuatorLimits((-3.0, 3.0), 20.0, 2.0)
        motion = await group.move_to([2.0, 0.5])
        assert _proven(group)
        await motion
        assert motion.outcome is GroupOutcome.SUCCEEDED
        assert motors[0].batches[-1][1] == 2.0


async def test_limits_narrowed_mid_proven_move_stop_the_next_batch(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    """The proof is made again when a device's limits are set mid-move: the first batch
    outside the new limits is refused as on the general path (AxisFaultError naming the
    axis, caused by the bank's BadParameterError), nothing sent; within them it streams."""
    motors = [BatchMotor(position_limits=(-3.0, 3.0)) for _ in range(2)]
    group, actuators, timer = await _group(hal_components, virtual_clock, motors)
    async with timer, group:
        motion = await group.move_to([2.0, 0.5])
        assert _proven(group)
        while group.commanded[0] < 0.5:
            await virtual_clock.sleep(0.01)
        # Narrowed but still around the path: the move goes on, proven again.
        for motor in motors:
            motor.limits = ActuatorLimits((-2.5, 2.5), 20.0, 2.0)
        while group.commanded[0] < 0.8:
            await virtual_clock.sleep(0.01)
        assert not motion.done()
        # Narrowed across the path: the next batch outside is refused.
        motors[0].limits = ActuatorLimits((-1.0, 1.0), 20.0, 2.0)
        with pytest.raises(AxisFaultError) as info:
            await motion
        cause = info.value.cause
        assert info.value.axis == 0 and isinstance(cause, BadParameterError)
        assert cause.parameter == "values[0]" and "[-1.0, 1.0]" in cause.allowed
        last = [m.batches[-1][1] for m in motors]
        assert 0.9 < last[0] <= 1.0 and list(group.commanded) == last
        assert [a.get_value_nowait(Request.POSITION) for a in actuators] == last
        sent = [(len(m.batches), m.commands) for m in motors]
        await virtual_clock.sleep(0.05)
        assert [(len(m.batches), m.commands) for m in motors] == sent
        # Widened again: the same target is reached, proven.
        motors[0].limits = ActuatorLimits((-3.0, 3.0), 20.0, 2.0)
        again = await group.move_to([2.0, 0.5])
        assert _proven(group)
        await again
        assert again.outcome is GroupOutcome.SUCCEEDED
        assert [m.batches[-1][1] for m in motors] == [2.0, 0.5]


async def test_the_bank_refuses_bounds_it_cannot_prove(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    motors = [BatchMotor(position_limits=(-1.0, 1.0)) for _ in range(2)]
    group, _, _ = await _group(hal_components, virtual_clock, motors)
    bank = group._bank
    assert bank.position_stream([-0.5, -0.5], [0.5, 0.5]) is not None
    assert bank.position_stream([-0.5, -0.5], [0.5, 1.0 + 1e-12]) is None  # outside
    assert bank.position_stream([-math.inf, -0.5], [0.5, 0.5]) is None  # not finite
    assert bank.position_stream([math.nan, -0.5], [0.5, 0.5]) is None
    assert bank.position_stream([-0.5], [0.5]) is None  # one bound per actuator
    motors[1].limits = ActuatorLimits((-0.4, 0.4), 20.0, 2.0)  # the device's own, now
    assert bank.position_stream([-0.5, -0.5], [0.5, 0.5]) is None


_LIMITS = st.builds(
    AxisLimits,
    max_velocity=st.floats(0.2, 5.0),
    max_acceleration=st.floats(1.0, 20.0),
    max_jerk=st.floats(10.0, 200.0),
)


@settings(max_examples=80, deadline=None)
@given(
    start=st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3),
    velocity=st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3),
    targets=st.lists(st.floats(-2.0, 2.0), min_size=3, max_size=3),
    via=st.lists(st.floats(-2.0, 2.0), min_size=3, max_size=3),
    limits=_LIMITS,
    kind=st.sampled_from(["move", "brake", "waypoints"]),
)
def test_every_sampled_position_lies_within_the_plan_bounds(
    start: list[float],
    velocity: list[float],
    targets: list[float],
    via: list[float],
    limits: AxisLimits,
    kind: str,
) -> None:
    planner = Planner(3, [(-50.0, 50.0)] * 3, [10.0] * 3)
    velocity = [min(abs(v), limits.max_velocity) * math.copysign(1.0, v) for v in velocity]
    state = KinematicState(start, velocity, [0.0] * 3)
    per_axis = [limits] * 3
    if kind == "move":
        plan = planner.move(0, state, targets, per_axis)
    elif kind == "brake":
        plan = planner.brake(0, state, per_axis)
    else:
        plan = planner.waypoints(0, state, [(via, None), (targets, None)], per_axis)
    lows, highs = plan.position_bounds()
    sample = plan.sampler()
    step = 1_000_000  # 1 ms
    for t in range(0, plan.end_ns + 2 * step, step):
        positions = sample(t) if t < plan.end_ns else plan.positions(t)
        assert positions == plan.positions(t)
        for low, value, high in zip(lows, positions, highs, strict=True):
            assert type(value) is float and low <= value <= high


def test_an_overshoot_ruckigs_extrema_miss_is_found() -> None:
    """From 1 rad/s towards +, back to the start: the axis brakes through a phase of
    constant acceleration and turns at 0.5496; ruckig's ``position_extrema`` says 0.3427
    (it skips velocity zeros where the jerk is 0, ruckig issue #215)."""
    planner = Planner(3, [(-0.5, 0.5)] * 3, [10.0] * 3)
    limits = [AxisLimits(max_velocity=1.0, max_acceleration=1.0, max_jerk=10.0)] * 3
    state = KinematicState([0.0] * 3, [0.0, 0.0, 1.0], [0.0] * 3)
    with pytest.raises(BadParameterError, match="axis 2 within its position limits"):
        planner.move(0, state, [0.0] * 3, limits)
    wide = Planner(3, [(-5.0, 5.0)] * 3, [10.0] * 3)
    plan = wide.move(0, state, [0.0] * 3, limits)
    inp = InputParameter(3)
    inp.current_position, inp.current_velocity = [0.0] * 3, [0.0, 0.0, 1.0]
    inp.current_acceleration = inp.target_position = [0.0] * 3
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = [1.0] * 3, [1.0] * 3, [10.0] * 3
    inp.synchronization = Synchronization.Phase
    trajectory = Trajectory(3)
    Ruckig(3).calculate(inp, trajectory)
    assert trajectory.duration == pytest.approx(plan.duration)
    assert trajectory.position_extrema[2].max < 0.35  # ruckig's answer
    _, highs = trajectory_range(trajectory)
    reached = max(plan.positions(t)[2] for t in range(0, plan.end_ns, 100_000))
    assert reached == pytest.approx(0.5496, abs=1e-4)
    assert reached <= highs[2] <= reached + 1e-6
