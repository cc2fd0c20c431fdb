"""AxisGroup.move_to: synchronized start and arrival, kinematic limits of the streamed
setpoints, fixed durations, start state, and any Actuator (not only SimMotor)."""

from __future__ import annotations

import numpy as np
import pytest

from openel_async import (
    Actuator,
    ActuatorDevice,
    ActuatorLimits,
    DeviceContext,
    EventTimer,
    Request,
    VirtualClock,
)
from openel_async.motion import AxisGroup, AxisLimits, GroupOutcome, Tolerances
from openel_async.testing import ComponentStack

from .rigs import DT, LIMITS, RigFactory, differences

TARGETS = [2.5, 0.01, -1.2]
PER_AXIS = [
    AxisLimits(1.5, 8.0, 80.0),
    AxisLimits(0.5, 2.0, 10.0),
    AxisLimits(3.0, 20.0, 300.0),
]


def moving_rows(velocity: np.ndarray) -> list[tuple[int, int]]:
    """Per axis, the first and last row at which it moves (|v| above 1e-5 of its peak)."""
    out = []
    for axis in range(velocity.shape[1]):
        speed = np.abs(velocity[:, axis])
        rows = np.nonzero(speed > 1e-5 * speed.max())[0]
        out.append((int(rows[0]), int(rows[-1])))
    return out


def arrival_ticks(samples: np.ndarray, start: list[float], targets: list[float]) -> list[int]:
    """Per axis, the first row from which the axis stays within 0.1 % of its distance."""
    out = []
    for axis, (p0, p1) in enumerate(zip(start, targets, strict=True)):
        remaining = np.abs(samples[:, axis] - p1) / abs(p1 - p0)
        outside = np.nonzero(remaining > 1e-3)[0]
        out.append(int(outside[-1]) + 1 if outside.size else 0)
    return out


@pytest.mark.parametrize("synchronization", ["phase", "time"])
async def test_axes_start_and_arrive_together_for_very_different_distances(
    make_rig: RigFactory, synchronization: str
) -> None:
    rig = await make_rig(limits=PER_AXIS, synchronization=synchronization, log_actual=True)
    motion = await rig.group.move_to(TARGETS)
    assert not motion.done()  # returned at once
    await motion
    assert motion.outcome is GroupOutcome.SUCCEEDED
    samples = rig.group.log.snapshot().of_motion(motion.id)
    # Commanded: every axis starts and stops moving at the same tick (± 1).
    first, last = zip(*moving_rows(samples.velocity), strict=True)
    assert max(first) - min(first) <= 1, first
    assert max(last) - min(last) <= 1, last
    # Every axis' last setpoint is its exact target, sent at the same tick.
    ends = [int(np.nonzero(samples.commanded[:, i] != TARGETS[i])[0][-1]) + 1 for i in range(3)]
    assert len(set(ends)) == 1
    assert samples.time_ns[ends[0]] == motion.planned_end_ns or (
        0 <= samples.time_ns[ends[0]] - motion.planned_end_ns < DT * 1e9
    )
    # Actual: the motors track within a tick, so they stop within a tick of each other.
    assert samples.actual is not None
    actual_velocity = np.diff(samples.actual, axis=0) / DT
    _, actual_last = zip(*moving_rows(actual_velocity), strict=True)
    assert max(actual_last) - min(actual_last) <= 1, actual_last
    if synchronization == "phase":  # scaled copies: also the same fraction of the path
        arrivals = arrival_ticks(samples.commanded, [0.0] * 3, TARGETS)
        assert max(arrivals) - min(arrivals) <= 1, arrivals
    for actuator, target in zip(rig.actuators, TARGETS, strict=True):
        assert await actuator.get_value(Request.POSITION_ACTUAL) == pytest.approx(target, abs=1e-3)


async def test_phase_synchronization_moves_in_a_straight_line(make_rig: RigFactory) -> None:
    rig = await make_rig(limits=PER_AXIS)
    motion = await rig.group.move_to(TARGETS)
    await motion
    commanded = rig.group.log.snapshot().of_motion(motion.id).commanded
    fraction = commanded / np.array(TARGETS)
    # From rest to rest, every axis is a scaled copy of the slowest one.
    assert np.max(np.ptp(fraction, axis=1)) < 1e-9


async def test_streamed_setpoints_respect_velocity_acceleration_and_jerk(
    make_rig: RigFactory,
) -> None:
    rig = await make_rig(limits=PER_AXIS, synchronization="time")
    await (await rig.group.move_to(TARGETS))
    await (await rig.group.move_to([-1.0, 0.8, 0.4]))
    peaks = []
    for motor, lim in zip(rig.motors, PER_AXIS, strict=True):
        values = motor.on_grid(round(DT * 1e9))  # what the motor is told at each tick
        v, a, j = differences(values, DT)
        slack = 1 + 1e-6
        assert np.max(np.abs(v)) <= lim.max_velocity * slack
        assert np.max(np.abs(a)) <= lim.max_acceleration * slack + 1e-6
        assert np.max(np.abs(j)) <= lim.max_jerk * slack + 1e-3
        peaks.append((np.max(np.abs(v)), np.max(np.abs(a))))
    # Axis 0 sets the pace (longest moves): the limits are used, not just respected.
    assert peaks[0][0] > 0.99 * PER_AXIS[0].max_velocity
    assert peaks[0][1] > 0.95 * PER_AXIS[0].max_acceleration


async def test_device_velocity_limit_caps_the_trajectory(make_rig: RigFactory) -> None:
    from .rigs import RecordingMotor

    motors = [RecordingMotor(max_velocity=0.4), RecordingMotor()]
    rig = await make_rig(motors=motors, limits=LIMITS)
    await (await rig.group.move_to([1.0, 1.0]))
    v, _, _ = differences(motors[0].on_grid(round(DT * 1e9)), DT)
    assert np.max(np.abs(v)) <= 0.4 * (1 + 1e-6)


async def test_move_with_a_duration_arrives_exactly_then(make_rig: RigFactory) -> None:
    rig = await make_rig()
    motion = await rig.group.move_to([0.5, -0.5, 0.2], duration=1.5)
    assert motion.duration == pytest.approx(1.5)
    await motion
    samples = rig.group.log.snapshot().of_motion(motion.id)
    at_end = samples.time_ns - motion.start_ns == 1_500_000_000
    assert samples.commanded[at_end][0] == pytest.approx([0.5, -0.5, 0.2], abs=1e-9)
    before = samples.time_ns - motion.start_ns == 1_400_000_000
    assert np.all(np.abs(samples.commanded[before][0] - [0.5, -0.5, 0.2]) > 1e-6)


async def test_a_move_starts_from_where_the_actuators_were_commanded(
    make_rig: RigFactory,
) -> None:
    rig = await make_rig(axes=2)
    await (await rig.actuators[0].set_value(0.7))  # moved outside the group
    assert rig.group.commanded == (0.0, 0.0)
    motion = await rig.group.move_to([0.7, 0.3])
    assert rig.group.commanded == (0.7, 0.0)
    await motion
    first = rig.group.log.snapshot().of_motion(motion.id).commanded
    assert first[0] == pytest.approx([0.7, 0.0], abs=1e-6)
    assert np.all(first[:, 0] == 0.7)  # the axis already there does not move


async def test_successive_moves_reuse_the_group_and_count_ticks(make_rig: RigFactory) -> None:
    rig = await make_rig(axes=2)
    for target in ([0.3, -0.3], [0.0, 0.0], [0.1, 0.2]):
        motion = await rig.group.move_to(target)
        await motion
        assert rig.group.commanded == tuple(target)
    assert not rig.group.moving and rig.group.current is None
    stats = rig.group.stats
    assert stats.ticks > 0 and stats.skipped_ticks == 0
    assert stats.tick_cost.count == stats.ticks


class MemoryServo(ActuatorDevice):
    """A device that is wherever it was last told to be; no completion reports."""

    limits = ActuatorLimits(position=(-1.0, 1.0))

    def __init__(self) -> None:
        self.position = 0.0

    async def open(self, ctx: DeviceContext) -> None:
        self.ctx = ctx

    async def command(self, request: Request, value: float) -> None:
        self.position = value

    async def read(self, request: Request) -> float:
        return self.position


async def test_works_with_any_actuator_device(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    actuators = [await hal_components.actuator(MemoryServo()) for _ in range(4)]
    async with (
        EventTimer(2, clock=virtual_clock) as timer,
        AxisGroup(
            actuators,
            timer=timer,
            limits=LIMITS,
            tolerances=Tolerances(goal=1e-9, path=0.01),
        ) as group,
    ):
        motion = await group.move_to([0.9, -0.9, 0.1, 0.0])
        await motion
        assert [a.device.position for a in actuators] == [0.9, -0.9, 0.1, 0.0]  # type: ignore[attr-defined]
    assert isinstance(actuators[0], Actuator)
