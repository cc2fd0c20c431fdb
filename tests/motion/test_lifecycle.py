"""The group's context: no orphan tasks, timer ownership, states; the trajectory log."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from openel_async import EventTimer, StateError, TimerState, VirtualClock
from openel_async.motion import (
    AxisGroup,
    GroupOutcome,
    MotionStoppedError,
    TrajectoryLog,
)
from openel_async.testing import ComponentStack

from .rigs import LIMITS, RecordingMotor, RigFactory


def state_of(timer: EventTimer) -> TimerState:
    return timer.state


async def test_leaving_the_context_holds_and_leaves_no_task(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    actuators = [await hal_components.actuator(RecordingMotor()) for _ in range(2)]
    async with EventTimer(1, clock=virtual_clock) as timer:
        before = len(asyncio.all_tasks())
        async with AxisGroup(actuators, timer=timer, limits=LIMITS) as group:
            assert state_of(timer) is TimerState.RUNNING  # started by the group
            assert group in timer.observers
            motion = await group.move_to([1.0, 1.0])
            await virtual_clock.sleep(0.2)
        assert motion.outcome is GroupOutcome.STOPPED
        with pytest.raises(MotionStoppedError, match="closed"):
            await motion
        assert state_of(timer) is TimerState.STOPPED  # stopped again: the group started it
        assert group not in timer.observers
        await asyncio.sleep(0)
        assert len(asyncio.all_tasks()) == before
        with pytest.raises(StateError, match="closed"):
            await group.move_to([0.0, 0.0])
        with pytest.raises(StateError):
            await group.__aenter__()


async def test_a_running_timer_is_left_running(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    actuators = [await hal_components.actuator(RecordingMotor())]
    async with EventTimer(1, clock=virtual_clock) as timer:
        timer.start_timer()
        async with AxisGroup(actuators, timer=timer, limits=LIMITS) as group:
            await (await group.move_to([0.1]))
        assert timer.state is TimerState.RUNNING


async def test_not_entered_and_stopped_timer_are_state_errors(
    make_rig: RigFactory, hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    actuator = await hal_components.actuator(RecordingMotor())
    group = AxisGroup([actuator], timer=EventTimer(1, clock=virtual_clock), limits=LIMITS)
    with pytest.raises(StateError, match="not entered"):
        await group.move_to([0.1])
    rig = await make_rig(axes=1)
    rig.timer.stop_timer()
    with pytest.raises(StateError, match="timer Running"):
        await rig.group.move_to([0.1])


async def test_an_error_in_the_body_propagates_as_is(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    actuators = [await hal_components.actuator(RecordingMotor())]
    timer = EventTimer(1, clock=virtual_clock)
    async with timer:
        with pytest.raises(KeyError):
            async with AxisGroup(actuators, timer=timer, limits=LIMITS) as group:
                await group.move_to([0.5])
                raise KeyError("boom")
        assert group not in timer.observers


async def test_the_log_records_commanded_and_actual_positions(make_rig: RigFactory) -> None:
    rig = await make_rig(axes=2, log_actual=True)
    motion = await rig.group.move_to([0.4, -0.2])
    await motion
    samples = rig.group.log.snapshot()
    n = len(samples)
    assert n == rig.group.stats.ticks
    assert samples.commanded.shape == samples.velocity.shape == (n, 2)
    assert samples.actual is not None and samples.actual.shape == (n, 2)
    assert np.all(np.diff(samples.time_ns) == 1_000_000)
    assert samples.time_s[0] == 0.0 and samples.time_s[-1] == pytest.approx((n - 1) * 1e-3)
    # Actual is read before the tick's setpoints: it follows the previous row's command.
    assert np.max(np.abs(samples.actual[1:] - samples.commanded[:-1])) < 1e-9
    assert np.all(samples.motion_id == motion.id)
    assert samples.commanded[-1] == pytest.approx([0.4, -0.2])


async def test_without_actual_positions_the_log_has_none(make_rig: RigFactory) -> None:
    rig = await make_rig(axes=1)
    await (await rig.group.move_to([0.1]))
    assert rig.group.log.snapshot().actual is None


def test_the_log_is_a_ring_of_the_latest_rows() -> None:
    log = TrajectoryLog(2, capacity=5, actual=True)
    for i in range(8):
        log.append(i, 1, [i, -i], [0, 0], [0, 0], [i + 0.5, 0])
    samples = log.snapshot()
    assert list(samples.time_ns) == [3, 4, 5, 6, 7]
    assert list(samples.commanded[:, 1]) == [-3, -4, -5, -6, -7]
    assert samples.actual is not None and list(samples.actual[:, 0]) == [3.5, 4.5, 5.5, 6.5, 7.5]
    assert log.total == 8 and len(log) == 5
    log.clear()
    assert len(log.snapshot()) == 0


def test_a_disabled_log_keeps_nothing() -> None:
    log = TrajectoryLog(3, capacity=0)
    log.append(1, 1, [0, 0, 0], [0, 0, 0], [0, 0, 0])
    assert len(log) == 0 and len(log.snapshot()) == 0


async def test_entering_a_group_makes_its_log_in_a_worker_thread(
    hal_components: ComponentStack, virtual_clock: VirtualClock, monkeypatch: pytest.MonkeyPatch
) -> None:
    """numpy's first import takes 0.1-1 s: not in the event loop, where it would stall the
    drives' heartbeats and watchdogs (a CiA 402 drive with a 100 ms heartbeat faults)."""
    import threading

    threads: list[threading.Thread] = []
    allocate = TrajectoryLog.allocate

    def recording_allocate(log: TrajectoryLog) -> None:
        threads.append(threading.current_thread())
        allocate(log)

    monkeypatch.setattr(TrajectoryLog, "allocate", recording_allocate)
    actuators = [await hal_components.actuator(RecordingMotor()) for _ in range(2)]
    async with EventTimer(1, clock=virtual_clock) as timer:
        group = AxisGroup(actuators, timer=timer, limits=LIMITS)
        assert not group.log.allocated  # nothing of numpy made by the constructor
        async with group:
            assert group.log.allocated
            assert threads and threads[0] is not threading.main_thread()
            await (await group.move_to([0.2, 0.1]))
        assert len(group.log.snapshot()) > 0
