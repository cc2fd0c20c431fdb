"""Preemption from the commanded state without jumps; stop() and hold()."""

from __future__ import annotations

import anyio
import numpy as np
import pytest

from openel_async import MotionCancelledError, SupersededError
from openel_async.motion import GroupOutcome, MotionStoppedError, PreemptedError

from .rigs import DT, LIMITS, RigFactory, differences

PERIOD_NS = round(DT * 1e9)
SLACK = 1 + 1e-6


def assert_within_limits(values: np.ndarray) -> None:
    v, a, j = differences(values, DT)
    assert np.max(np.abs(v)) <= LIMITS.max_velocity * SLACK
    assert np.max(np.abs(a)) <= LIMITS.max_acceleration * SLACK + 1e-6
    assert np.max(np.abs(j)) <= LIMITS.max_jerk * SLACK + 1e-3


async def test_preemption_continues_from_the_commanded_state_without_jumps(
    make_rig: RigFactory,
) -> None:
    rig = await make_rig()
    first = await rig.group.move_to([1.5, -1.0, 0.8])
    await rig.sleep(0.6)  # at speed
    second = await rig.group.move_to([-0.5, 0.5, 0.0])  # reverses every axis
    with pytest.raises(PreemptedError) as info:
        await first
    assert isinstance(info.value, SupersededError) and info.value.by == second.id
    assert first.outcome is GroupOutcome.PREEMPTED
    await second
    assert second.outcome is GroupOutcome.SUCCEEDED

    log = rig.group.log.snapshot()
    old = log.of_motion(first.id)
    new = log.of_motion(second.id)
    # The new trajectory is rooted at the last tick the old one commanded ...
    assert second.start_ns == old.time_ns[-1]
    assert new.time_ns[0] == second.start_ns + PERIOD_NS
    # ... with its position, velocity and acceleration: the switch is as smooth as
    # any other tick of a jerk-limited trajectory.
    assert np.max(np.abs(old.velocity[-1])) > 0.5  # it really was moving
    dv = np.abs(new.velocity[0] - old.velocity[-1])
    dp = np.abs(new.commanded[0] - old.commanded[-1])
    assert np.all(dv <= LIMITS.max_acceleration * DT * SLACK)
    assert np.all(dp <= LIMITS.max_velocity * DT * SLACK)
    expected = old.commanded[-1] + old.velocity[-1] * DT + old.acceleration[-1] * DT**2 / 2
    assert new.commanded[0] == pytest.approx(expected, abs=LIMITS.max_jerk * DT**3 / 6 + 1e-12)
    # What the motors received, differentiated across the switch.
    for motor in rig.motors:
        assert_within_limits(motor.on_grid(PERIOD_NS))


async def test_back_to_back_requests_before_a_tick_keep_the_start_state(
    make_rig: RigFactory,
) -> None:
    rig = await make_rig(axes=2)
    first = await rig.group.move_to([1.0, 1.0])
    second = await rig.group.move_to([-1.0, 0.5])
    assert second.start_ns == first.start_ns
    with pytest.raises(PreemptedError):
        await first
    await second
    assert not rig.group.log.snapshot().of_motion(first.id)  # never streamed
    for motor in rig.motors:
        assert_within_limits(motor.on_grid(PERIOD_NS))


async def test_preemption_during_the_goal_check_starts_at_rest(make_rig: RigFactory) -> None:
    rig = await make_rig(axes=2, goal_time=0.5)
    rig.motors[1].set_stuck()  # keeps the first motion in its goal check
    first = await rig.group.move_to([0.3, 0.3])
    while not first.settling:
        await rig.sleep(0.01)
    rig.motors[1].set_stuck(False)
    second = await rig.group.move_to([0.0, 0.0])
    with pytest.raises(PreemptedError):
        await first
    await second
    new = rig.group.log.snapshot().of_motion(second.id)
    assert new.commanded[0] == pytest.approx([0.3, 0.3], abs=1e-6)
    assert_within_limits(rig.motors[0].on_grid(PERIOD_NS))


async def test_stop_brakes_to_rest_within_the_limits(make_rig: RigFactory) -> None:
    rig = await make_rig()
    motion = await rig.group.move_to([2.0, -2.0, 1.0])
    await rig.sleep(0.7)
    await rig.group.stop()
    with pytest.raises(MotionStoppedError) as info:
        await motion
    assert isinstance(info.value, MotionCancelledError)
    assert motion.outcome is GroupOutcome.STOPPED
    assert not rig.group.moving
    log = rig.group.log.snapshot()
    brake_id = int(log.motion_id[-1])
    assert brake_id != motion.id
    brake = log.of_motion(brake_id)
    assert np.all(brake.velocity[-1] == 0) and np.all(brake.acceleration[-1] == 0)
    stopped_at = np.array(rig.group.commanded)
    assert np.all(np.abs(stopped_at) < [2.0, 2.0, 1.0])  # short of the targets
    for motor in rig.motors:
        assert_within_limits(motor.on_grid(PERIOD_NS))
    sent = [len(m.setpoints) for m in rig.motors]
    await rig.sleep(0.1)
    assert [len(m.setpoints) for m in rig.motors] == sent


async def test_stop_when_idle_does_nothing(make_rig: RigFactory) -> None:
    rig = await make_rig(axes=1)
    await rig.group.stop()
    assert not rig.group.moving and rig.motors[0].setpoints == []


async def test_a_new_move_preempts_a_stop(make_rig: RigFactory) -> None:
    rig = await make_rig(axes=2)
    await rig.group.move_to([2.0, 2.0])
    await rig.sleep(0.5)
    async with anyio.create_task_group() as tg:
        tg.start_soon(rig.group.stop)
        await rig.sleep(0.05)
        motion = await rig.group.move_to([0.0, 0.0])
    await motion  # stop() returned without error when preempted
    for motor in rig.motors:
        assert_within_limits(motor.on_grid(PERIOD_NS))


async def test_concurrent_stops_share_one_braking(make_rig: RigFactory) -> None:
    rig = await make_rig(axes=2)
    motion = await rig.group.move_to([2.0, 2.0])
    await rig.sleep(0.5)
    async with anyio.create_task_group() as tg:
        tg.start_soon(rig.group.stop)
        await rig.sleep(0.02)
        brake = rig.group.current
        assert brake is not None and brake.kind == "stop"
        await rig.group.stop()  # waits for the same braking
        assert brake.outcome is GroupOutcome.SUCCEEDED
    assert motion.outcome is GroupOutcome.STOPPED
    assert not rig.group.moving


async def test_hold_stops_streaming_at_once(make_rig: RigFactory) -> None:
    rig = await make_rig(axes=2)
    motion = await rig.group.move_to([1.0, 1.0])
    await rig.sleep(0.3)
    rig.group.hold()
    with pytest.raises(MotionStoppedError, match="hold"):
        await motion
    sent = [len(m.setpoints) for m in rig.motors]
    await rig.sleep(0.2)
    assert [len(m.setpoints) for m in rig.motors] == sent
    assert not rig.group.moving
