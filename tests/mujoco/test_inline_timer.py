"""EventTimer ticking inline on a lockstep MujocoSim (``LockstepClock.call_at``).

The ticks run synchronously inside the simulation loop, between two physics steps: a setpoint
written in tick k drives the very next ``mj_step``, which a raw MuJoCo run stepping the same
control sequence reproduces bit for bit.  Also: tick times on the grid, stop/restart and
SetEventPeriod from inside and outside observers, async observers, raising observers and
callbacks, ``call_at`` itself, and run-to-run determinism.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable
from contextlib import AsyncExitStack
from dataclasses import dataclass, field

import anyio
import anyio.lowlevel
import mujoco
import numpy as np
import pytest
import structlog.testing

from openel_async import (
    ActuatorBank,
    EventTimer,
    ObserverQueue,
    Request,
    SensorBank,
    TimerState,
)
from openel_async.clock import InlineScheduler, ScheduledCall, VirtualClock
from openel_async.observers import TimerTick
from openel_async.requests import EventId
from openel_mujoco import LockstepClock, MujocoSim
from openel_mujoco.models import MODELS_DIR

from .conftest import Rig, start_rig

MS = 1_000_000
JOINTS = ("shoulder", "elbow")
SENSORS = ("shoulder_pos_sensor", "elbow_vel_sensor", "imu_gyro")


async def _timer(stack: AsyncExitStack, sim: MujocoSim, period_ms: float) -> EventTimer:
    return await stack.enter_async_context(EventTimer(period_ms, clock=sim.clock, name="ctl"))


@dataclass
class TickLog:
    """A plain TimerObserver recording each tick with the simulation's state at delivery."""

    sim: MujocoSim
    until: int | None = None
    stop_at_until: bool = True
    ticks: list[TimerTick] = field(default_factory=list)
    now: list[int] = field(default_factory=list)
    steps: list[int] = field(default_factory=list)
    done: anyio.Event = field(default_factory=anyio.Event)

    def notify_timer(self, timer: EventTimer) -> None:
        tick = timer.last_tick
        assert tick is not None
        self.ticks.append(tick)
        self.now.append(self.sim.clock.now_ns())
        self.steps.append(self.sim.steps)
        if self.until is not None and len(self.ticks) >= self.until:
            if self.stop_at_until and timer.state is TimerState.RUNNING:
                timer.stop_timer()
            self.done.set()

    @property
    def times(self) -> list[int]:
        return [t.time_ns for t in self.ticks]

    @property
    def indexes(self) -> list[int]:
        return [t.index for t in self.ticks]


# -- ticking on the simulation's grid -------------------------------------------------------


async def test_ticks_exactly_every_period_of_simulated_time(stack: AsyncExitStack) -> None:
    sim = MujocoSim("arm2")
    await stack.enter_async_context(sim)
    timer = await _timer(stack, sim, 2.0)
    log = TickLog(sim, until=50)
    timer.add_observer(log)
    assert sim.clock.now_ns() == 0
    timer.start_timer()
    with anyio.fail_after(10):
        await log.done.wait()
    expected = [2 * MS * k for k in range(1, 51)]
    assert log.times == log.now == expected
    assert [t.deadline_ns for t in log.ticks] == expected
    assert log.indexes == list(range(1, 51))
    assert log.steps == [2 * k for k in range(1, 51)]  # two physics steps per tick
    assert all(t.missed_ticks == 0 and t.lateness_ns == 0 for t in log.ticks)
    assert timer.state is TimerState.STOPPED
    stats = timer.stats
    assert (stats.ticks, stats.late_ticks, stats.missed_ticks, stats.last_lateness_ns) == (
        50,
        0,
        0,
        0,
    )
    assert stats.lateness.max_ns == 0
    last = timer.last_tick
    assert last is not None and (last.index, last.time_ns) == (50, 100 * MS)


async def test_ticks_run_inside_the_simulation_loop_without_a_task(
    stack: AsyncExitStack,
) -> None:
    sim = MujocoSim("arm2")
    await stack.enter_async_context(sim)
    timer = await _timer(stack, sim, 1.0)
    assert isinstance(sim.clock, InlineScheduler)
    step_tasks: set[asyncio.Task[object] | None] = set()
    tick_tasks: set[asyncio.Task[object] | None] = set()
    sim.add_step_hook(lambda: step_tasks.add(asyncio.current_task()))
    log = TickLog(sim, until=20)
    timer.add_observer(log)
    timer.add_observer(lambda _: tick_tasks.add(asyncio.current_task()))
    tasks = asyncio.all_tasks()
    timer.start_timer()
    assert asyncio.all_tasks() == tasks  # no ticking task
    with anyio.fail_after(10):
        await log.done.wait()
    assert len(tick_tasks) == 1 and tick_tasks == step_tasks  # the simulation loop's task
    assert asyncio.current_task() not in tick_tasks


async def test_last_tick_is_right_when_read_only_now_and_then(stack: AsyncExitStack) -> None:
    sim = MujocoSim("arm2")
    await stack.enter_async_context(sim)
    timer = await _timer(stack, sim, 3.0)
    count = 0
    sampled: list[tuple[int, int, int]] = []
    done = anyio.Event()

    def counter(timer: EventTimer) -> None:  # never looks at last_tick ...
        nonlocal count
        count += 1
        if count % 7 == 0:  # ... except now and then
            tick = timer.last_tick
            assert tick is not None
            sampled.append((tick.index, tick.deadline_ns, tick.time_ns))
        if count == 20:
            done.set()

    timer.add_observer(counter)
    assert timer.last_tick is None
    timer.start_timer()
    with anyio.fail_after(10):
        await done.wait()
    timer.stop_timer()
    assert sampled == [(k, 3 * MS * k, 3 * MS * k) for k in (7, 14)]
    last = timer.last_tick
    assert last is not None and last is timer.last_tick  # built once
    assert (last.index, last.deadline_ns, last.time_ns, last.timer) == (20, 60 * MS, 60 * MS, timer)


async def test_periods_that_are_not_a_multiple_of_the_time_step(stack: AsyncExitStack) -> None:
    sim = MujocoSim("arm2")
    await stack.enter_async_context(sim)
    timer = await _timer(stack, sim, 1.5)
    log = TickLog(sim, until=6)
    timer.add_observer(log)
    timer.start_timer()
    with anyio.fail_after(10):
        await log.done.wait()
    # a deadline between two steps is served at the first step at or after it, on a grid
    # that does not drift
    assert [t.deadline_ns for t in log.ticks] == [1_500_000 * k for k in range(1, 7)]
    assert log.times == [2 * MS, 3 * MS, 5 * MS, 6 * MS, 8 * MS, 9 * MS]
    assert [t.lateness_ns for t in log.ticks] == [500_000, 0] * 3
    assert log.indexes == list(range(1, 7))
    assert timer.stats.missed_ticks == 0


# -- the control step between two physics steps ------------------------------------------------

PERIOD_STEPS = 4
TICKS = 60


def _setpoints(k: int) -> list[float]:
    return [0.9 * math.sin(0.07 * k), -0.6 * math.sin(0.11 * k + 0.3)]


@dataclass
class RawRun:
    qpos: np.ndarray
    positions: list[list[float]]
    sensors: list[tuple[float, ...]]


def _raw_run(delay_steps: int = 0) -> RawRun:
    """Plain MuJoCo: the setpoints of tick k written after step k x PERIOD_STEPS (+ delay)."""
    model = mujoco.MjModel.from_xml_path(str(MODELS_DIR / "arm2.xml"))
    data = mujoco.MjData(model)
    mujoco.mj_resetData(model, data)
    mujoco.mj_forward(model, data)
    acts = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, f"{j}_pos") for j in JOINTS]
    joints = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in JOINTS]
    spans = []
    for name in SENSORS:
        sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, name)
        adr = int(model.sensor_adr[sid])
        spans.append((adr, adr + int(model.sensor_dim[sid])))
    positions: list[list[float]] = []
    sensors: list[tuple[float, ...]] = []
    pending: dict[int, list[float]] = {}
    for step in range(1, TICKS * PERIOD_STEPS + 1):
        mujoco.mj_step(model, data)
        if step in pending:
            for act, value in zip(acts, pending.pop(step), strict=True):
                data.ctrl[act] = value
        if step % PERIOD_STEPS == 0:
            k = step // PERIOD_STEPS
            positions.append([float(data.qpos[model.jnt_qposadr[j]]) for j in joints])
            sensors.extend(tuple(data.sensordata[a:b].tolist()) for a, b in spans)
            if delay_steps:
                pending[step + delay_steps] = _setpoints(k)
            else:
                for act, value in zip(acts, _setpoints(k), strict=True):
                    data.ctrl[act] = value
    return RawRun(data.qpos.copy(), positions, sensors)


async def test_setpoints_of_tick_k_drive_the_next_physics_step(stack: AsyncExitStack) -> None:
    sim = MujocoSim("arm2")
    rig = await start_rig(stack, sim, JOINTS, SENSORS)
    joints = ActuatorBank(rig.actuators[j] for j in JOINTS)
    sensors = SensorBank(rig.sensors[s] for s in SENSORS)
    timer = await _timer(stack, sim, float(PERIOD_STEPS))
    positions: list[list[float]] = []
    readings: list[tuple[float, ...]] = []
    steps: list[int] = []
    qpos: list[np.ndarray] = []
    done = anyio.Event()

    def control(timer: EventTimer) -> None:
        tick = timer.last_tick
        assert tick is not None
        steps.append(sim.steps)
        positions.append(list(joints.get_values_nowait()))  # the state after the last step
        readings.extend(sensors.get_values_nowait())
        joints.set_values_nowait(_setpoints(tick.index))  # for the next step
        if tick.index == TICKS:
            timer.stop_timer()
            qpos.append(sim.data.qpos.copy())
            done.set()

    timer.add_observer(control)
    assert sim.steps == 0
    timer.start_timer()
    with anyio.fail_after(10):
        await done.wait()
    assert steps == [PERIOD_STEPS * k for k in range(1, TICKS + 1)]
    raw = _raw_run()
    assert qpos[0].tobytes() == raw.qpos.tobytes()  # bit-identical physics
    assert positions == raw.positions
    assert readings == raw.sensors
    # ... and the comparison can tell: a setpoint applied one step later changes the physics
    late = _raw_run(delay_steps=1)
    assert late.qpos.tobytes() != raw.qpos.tobytes()
    assert np.ptp(np.array(raw.positions)[:, 0]) > 0.3  # the arm really moved


# -- stop, restart, period changes ---------------------------------------------------------------


async def test_stop_inside_an_observer_delivers_no_further_tick(stack: AsyncExitStack) -> None:
    sim = MujocoSim("arm2")
    await stack.enter_async_context(sim)
    timer = await _timer(stack, sim, 1.0)
    log = TickLog(sim, until=5)
    other = TickLog(sim, stop_at_until=False)
    timer.add_observer(log)
    timer.add_observer(other)  # the tick that stops the timer still reaches every observer
    timer.start_timer()
    with anyio.fail_after(10):
        await log.done.wait()
        await sim.sleep(0.02)
    assert log.times == other.times == [MS * k for k in range(1, 6)]
    assert timer.state is TimerState.STOPPED
    last = timer.last_tick
    assert last is not None and last.index == 5
    assert sim.steps >= 25  # the physics went on


async def test_restart_after_stop(stack: AsyncExitStack) -> None:
    sim = MujocoSim("arm2")
    await stack.enter_async_context(sim)
    timer = await _timer(stack, sim, 2.0)
    log = TickLog(sim)
    timer.add_observer(log)
    timer.start_timer()
    with anyio.fail_after(10):
        await sim.clock.sleep_until(7 * MS)
        timer.stop_timer()
        await sim.clock.sleep_until(20 * MS)
        assert log.times == [2 * MS, 4 * MS, 6 * MS]
        timer.start_timer()  # at 20 ms: the first tick one period later
        await sim.clock.sleep_until(26 * MS)  # a tick is due now too: it comes first
        assert log.times[-1] == 26 * MS
        timer.stop_timer()
        await sim.clock.sleep_until(40 * MS)
    assert log.times == [2 * MS, 4 * MS, 6 * MS, 22 * MS, 24 * MS, 26 * MS]
    assert log.indexes == [1, 2, 3, 4, 5, 6]  # indexes count on across the restart
    assert log.now == log.times


async def test_stop_and_restart_inside_an_observer_leaves_one_schedule(
    stack: AsyncExitStack,
) -> None:
    sim = MujocoSim("arm2")
    await stack.enter_async_context(sim)
    timer = await _timer(stack, sim, 2.0)
    log = TickLog(sim, until=6)

    def restart(timer: EventTimer) -> None:
        tick = timer.last_tick
        assert tick is not None
        if tick.index == 2:
            timer.stop_timer()
            timer.set_event_period(3.0)
            timer.start_timer()

    timer.add_observer(restart)
    timer.add_observer(log)
    timer.start_timer()
    with anyio.fail_after(10):
        await log.done.wait()
        await sim.sleep(0.01)
    # the old schedule (a tick at 6 ms) is gone: only the new one ticks
    assert log.times == [2 * MS, 4 * MS, 7 * MS, 10 * MS, 13 * MS, 16 * MS]
    assert log.indexes == list(range(1, 7))


async def test_set_event_period_from_an_observer_and_between_ticks(
    stack: AsyncExitStack,
) -> None:
    sim = MujocoSim("arm2")
    await stack.enter_async_context(sim)
    timer = await _timer(stack, sim, 1.0)
    log = TickLog(sim)

    def slow_down(timer: EventTimer) -> None:
        tick = timer.last_tick
        assert tick is not None
        if tick.index == 3:
            timer.set_event_period(5)  # from the next interval on

    timer.add_observer(slow_down)
    timer.add_observer(log)
    timer.start_timer()
    with anyio.fail_after(10):
        await sim.clock.sleep_until(20 * MS)
        assert log.times == [1 * MS, 2 * MS, 3 * MS, 8 * MS, 13 * MS, 18 * MS]
        # between ticks: the pending tick (23 ms) keeps its deadline, the new period
        # counts from there
        timer.set_event_period(2)
        assert timer.period_ns == 2 * MS
        await sim.clock.sleep_until(30 * MS)
        timer.stop_timer()
    assert log.times[6:] == [23 * MS, 25 * MS, 27 * MS, 29 * MS]
    assert log.now == log.times == [t.deadline_ns for t in log.ticks]
    assert log.indexes == list(range(1, 11))
    assert timer.stats.last_lateness_ns == 0 and timer.stats.missed_ticks == 0


async def test_leaving_the_timer_context_stops_the_inline_ticks(stack: AsyncExitStack) -> None:
    sim = MujocoSim("arm2")
    await stack.enter_async_context(sim)
    log = TickLog(sim)
    with anyio.fail_after(10):
        async with EventTimer(1.0, clock=sim.clock) as timer:
            timer.add_observer(log)
            timer.start_timer()
            await sim.clock.sleep_until(3 * MS)
        assert timer.state is TimerState.STOPPED
        await sim.clock.sleep_until(10 * MS)
    assert log.times == [1 * MS, 2 * MS, 3 * MS]


# -- observers ----------------------------------------------------------------------------------


async def test_async_observers_get_every_tick(stack: AsyncExitStack) -> None:
    sim = MujocoSim("arm2")
    await stack.enter_async_context(sim)
    timer = await _timer(stack, sim, 1.0)
    seen: list[tuple[int, int]] = []
    queue = ObserverQueue()

    async def on_tick(timer: EventTimer) -> None:
        await anyio.lowlevel.checkpoint()
        tick = timer.last_tick
        assert tick is not None
        seen.append((tick.index, sim.clock.now_ns()))

    iterated: list[int] = []

    async def iterate() -> None:
        async for tick in timer:
            iterated.append(tick.index)
            if tick.index == 30:
                break

    # (stop_timer inside a tick would discard that tick for async observers, by design)
    log = TickLog(sim, until=30, stop_at_until=False)
    timer.add_observer(on_tick)
    timer.add_observer(queue)
    timer.add_observer(log)
    with anyio.fail_after(10):
        async with anyio.create_task_group() as tg:
            tg.start_soon(iterate)
            await anyio.lowlevel.checkpoint()  # the iterator subscribes
            timer.start_timer()
            await log.done.wait()
            # woken tasks run before the next physics step: still at the 30th tick
            assert sim.clock.now_ns() == 30 * MS
            timer.stop_timer()
        await timer.wait_idle()
        await sim.sleep(0.01)
    assert log.indexes == list(range(1, 31))
    # every tick, at its own simulated time: the loop lets woken tasks run before stepping on
    assert seen == [(k, k * MS) for k in range(1, 31)]
    assert iterated == list(range(1, 31))
    drained = queue.drain()
    assert [t.index for t in drained if isinstance(t, TimerTick)] == list(range(1, 31))


async def test_raising_observers_do_not_stop_the_timer_or_the_physics(
    stack: AsyncExitStack,
) -> None:
    sim = MujocoSim("arm2")
    rig = await start_rig(stack, sim, ("shoulder",))
    shoulder = rig.actuators["shoulder"]
    timer = await _timer(stack, sim, 1.0)

    def broken(timer: EventTimer) -> None:
        raise RuntimeError("broken sync observer")

    async def broken_async(timer: EventTimer) -> None:
        raise RuntimeError("broken async observer")

    def control(timer: EventTimer) -> None:
        tick = timer.last_tick
        assert tick is not None
        if tick.index == 1:
            shoulder.set_value_nowait(0.5)

    log = TickLog(sim, until=400, stop_at_until=False)
    for observer in (broken, broken_async, control, log):
        timer.add_observer(observer)
    with structlog.testing.capture_logs() as logs, anyio.fail_after(10):
        timer.start_timer()
        await log.done.wait()
        await timer.wait_idle()
        timer.stop_timer()
    assert log.times == [MS * k for k in range(1, 401)]
    assert sim.steps == 400 and sim.fault is None
    # the observer after the broken ones still drove the arm to its target
    assert shoulder.get_value_nowait(Request.POSITION_ACTUAL) == pytest.approx(0.5, abs=2e-3)
    assert rig.events.count("event", EventId.COMPLETED, source=shoulder) == 1
    failures = [e["observer"] for e in logs if e["event"] == "observer_failed"]
    # every call of both broken observers, each logged
    assert sum("broken_async" in f for f in failures) == 400
    assert sum("broken_async" not in f for f in failures) == 400


# -- LockstepClock.call_at ----------------------------------------------------------------------


def test_call_at_runs_callbacks_as_the_simulation_steps() -> None:
    sim = MujocoSim("arm2")
    clock = sim.lockstep_clock
    assert clock is not None and clock is sim.clock
    assert isinstance(clock, InlineScheduler)
    assert not isinstance(VirtualClock(), InlineScheduler)
    calls: list[tuple[str, int, int]] = []

    def note(name: str) -> Callable[[], None]:
        return lambda: calls.append((name, clock.now_ns(), sim.steps))

    handle = clock.call_at(3 * MS, note("a"))
    assert isinstance(handle, ScheduledCall)
    clock.call_at(3 * MS, note("b"))  # same deadline: in the order they were scheduled
    clock.call_at(1_500_000, note("between"))  # served at the first step at or after it
    cancelled = clock.call_at(2 * MS, note("cancelled"))
    cancelled.cancel()
    assert sim.step(1) == 1 and calls == []
    assert clock.next_deadline() == 1_500_000
    assert sim.step(4) == 4
    assert calls == [("between", 2 * MS, 2), ("a", 3 * MS, 3), ("b", 3 * MS, 3)]
    handle.cancel()  # after it ran: nothing happens
    # a deadline already reached is served at the next step, never at once
    clock.call_at(0, note("past"))
    clock.call_at(clock.now_ns(), note("now"))
    assert calls[-1][0] == "b"
    sim.step(1)
    assert calls[-2:] == [("past", 6 * MS, 6), ("now", 6 * MS, 6)]
    assert clock.next_deadline() is None and clock.wakeups == 0  # callbacks wake no sleeper


def test_call_at_from_a_callback_is_served_at_a_later_step() -> None:
    sim = MujocoSim("arm2")
    clock = sim.clock
    assert isinstance(clock, LockstepClock)
    calls: list[int] = []

    def again() -> None:
        calls.append(clock.now_ns())
        if len(calls) < 3:
            clock.call_at(clock.now_ns(), again)  # due already: next step

    clock.call_at(2 * MS, again)
    sim.step(10)
    assert calls == [2 * MS, 3 * MS, 4 * MS]


def test_a_callback_returning_a_deadline_is_called_again_under_the_same_handle() -> None:
    sim = MujocoSim("arm2")
    clock = sim.clock
    assert isinstance(clock, LockstepClock)
    calls: list[int] = []

    def periodic() -> int | None:
        calls.append(clock.now_ns())
        if len(calls) == 2:
            return 0  # a deadline already past: served at the next step
        return clock.now_ns() + 3 * MS

    handle = clock.call_at(2 * MS, periodic)
    sim.step(12)
    assert calls == [2 * MS, 5 * MS, 6 * MS, 9 * MS, 12 * MS]
    assert not handle.done() and clock.next_deadline() == 15 * MS
    handle.cancel()  # stops the re-arming: the pending entry is dropped
    assert clock.next_deadline() is None
    sim.step(10)
    assert calls[-1] == 12 * MS

    # cancelled from inside its own call, or returning None or a non-int: not called again
    def cancels_itself() -> int:
        calls.append(-1)
        own.cancel()
        return clock.now_ns() + MS

    own = clock.call_at(clock.now_ns() + MS, cancels_itself)
    once = clock.call_at(clock.now_ns() + MS, lambda: calls.append(-2))
    sim.step(5)
    assert calls[-2:] == [-1, -2] and own.done() and once.done()
    assert clock.next_deadline() is None


def test_a_periodic_callback_that_raises_is_not_rearmed() -> None:
    sim = MujocoSim("arm2")
    clock = sim.clock
    assert isinstance(clock, LockstepClock)
    calls: list[int] = []

    def flaky() -> int:
        calls.append(clock.now_ns())
        if len(calls) == 2:
            raise RuntimeError("flaky")
        return clock.now_ns() + MS

    handle = clock.call_at(MS, flaky)
    with structlog.testing.capture_logs() as logs:
        sim.step(6)
    assert calls == [MS, 2 * MS] and handle.done()
    assert [e["event"] for e in logs if e["log_level"] == "error"] == ["clock_callback_failed"]


def test_a_raising_callback_is_logged_and_the_simulation_goes_on() -> None:
    sim = MujocoSim("arm2")
    clock = sim.clock
    assert isinstance(clock, LockstepClock)
    calls: list[int] = []

    def broken() -> None:
        raise RuntimeError("broken callback")

    clock.call_at(2 * MS, broken)
    clock.call_at(2 * MS, lambda: calls.append(clock.now_ns()))  # same step, after it
    clock.call_at(4 * MS, lambda: calls.append(clock.now_ns()))
    with structlog.testing.capture_logs() as logs:
        assert sim.step(6) == 6
    assert calls == [2 * MS, 4 * MS]
    assert sim.fault is None and sim.time_ns == 6 * MS
    failed = [e for e in logs if e["event"] == "clock_callback_failed"]
    assert len(failed) == 1
    assert failed[0]["log_level"] == "error" and failed[0].get("exc_info")
    assert "broken" in failed[0]["callback"]


async def test_call_at_runs_before_tasks_woken_at_the_same_time(stack: AsyncExitStack) -> None:
    sim = MujocoSim("arm2")
    await stack.enter_async_context(sim)
    clock = sim.clock
    assert isinstance(clock, LockstepClock)
    order: list[tuple[str, int, int]] = []

    async def sleeper() -> None:
        await clock.sleep_until(5 * MS)
        order.append(("task", clock.now_ns(), sim.steps))

    def broken() -> None:
        raise RuntimeError("broken callback")

    with anyio.fail_after(10), structlog.testing.capture_logs() as logs:
        async with anyio.create_task_group() as tg:
            tg.start_soon(sleeper)
            await anyio.lowlevel.checkpoint()
            clock.call_at(5 * MS, lambda: order.append(("callback", clock.now_ns(), sim.steps)))
            clock.call_at(3 * MS, broken)
            dropped = clock.call_at(4 * MS, lambda: order.append(("dropped", 0, 0)))
            dropped.cancel()
        await clock.sleep(0.005)
    assert order == [("callback", 5 * MS, 5), ("task", 5 * MS, 5)]
    assert [e["event"] for e in logs if e["log_level"] == "error"] == ["clock_callback_failed"]
    assert sim.fault is None and sim.steps >= 10  # the loop went on after the broken callback


# -- determinism ---------------------------------------------------------------------------------


@dataclass
class Trace:
    qpos: bytes
    ticks: list[tuple[int, int, int]]
    readings: list[tuple[float, ...]]
    async_seen: list[tuple[int, int]]
    events: list[tuple[str, int, int]]


async def _controlled_run() -> Trace:
    sim = MujocoSim("arm2")
    async with AsyncExitStack() as stack:
        rig: Rig = await start_rig(stack, sim, JOINTS, SENSORS)
        joints = ActuatorBank(rig.actuators[j] for j in JOINTS)
        sensors = SensorBank(rig.sensors[s] for s in SENSORS)
        timer = await _timer(stack, sim, 2.0)
        ticks: list[tuple[int, int, int]] = []
        readings: list[tuple[float, ...]] = []
        async_seen: list[tuple[int, int]] = []
        done = anyio.Event()

        def control(timer: EventTimer) -> None:
            tick = timer.last_tick
            assert tick is not None
            ticks.append((tick.index, tick.time_ns, sim.steps))
            readings.extend(sensors.get_values_nowait())
            k = tick.index
            if k < 150:
                joints.set_values_nowait(_setpoints(k))
            elif k == 150:
                joints.set_values_nowait([0.3, -0.2])  # a final target: COMPLETED events
                timer.set_event_period(5)
            if k == 250:
                timer.stop_timer()
                done.set()

        async def watch(timer: EventTimer) -> None:
            tick = timer.last_tick
            assert tick is not None
            async_seen.append((tick.index, sim.clock.now_ns()))

        timer.add_observer(control)
        timer.add_observer(watch)
        timer.start_timer()
        with anyio.fail_after(20):
            await done.wait()
            await timer.wait_idle()
        qpos = sim.data.qpos.tobytes()
        events = [(r.kind, r.id, r.time_ns) for r in rig.events.records]
    return Trace(qpos, ticks, readings, async_seen, events)


async def test_two_runs_are_identical() -> None:
    first = await _controlled_run()
    second = await _controlled_run()
    assert first == second
    assert len(first.ticks) == 250 and len(first.async_seen) == 250
    assert first.ticks[149][1] == 300 * MS and first.ticks[150][1] == 305 * MS
    assert [ident for _, ident, _ in first.events].count(EventId.COMPLETED) == 2


# -- inline ticks while the simulation is faulted --------------------------------------------


async def test_inline_timer_and_sleepers_go_on_while_the_simulation_is_faulted(
    stack: AsyncExitStack,
) -> None:
    sim = MujocoSim("arm2")
    rig = await start_rig(stack, sim, ("shoulder",))
    timer = await _timer(stack, sim, 1.0)
    log = TickLog(sim)
    timer.add_observer(log)
    timer.start_timer()
    with anyio.fail_after(10):
        await sim.clock.sleep_until(5 * MS)
        sim.data.qvel[0] = np.nan  # the next step faults the simulation
        await rig.events.wait_for("error")
    assert sim.fault is not None
    faulted_at = sim.clock.now_ns()
    # a healthy clock serves this in milliseconds of real time, jumping from deadline to
    # deadline as VirtualClock.autojump does
    with anyio.fail_after(2):
        await sim.clock.sleep_until(faulted_at + 10 * MS)
    assert log.times[-1] == faulted_at + 10 * MS


class _HandDriven:
    """An InlineScheduler whose single callback the test fires, on time or late."""

    def __init__(self) -> None:
        self.now = 0
        self.deadline: int | None = None
        self.callback: Callable[[], int | None] | None = None

    def now_ns(self) -> int:
        return self.now

    async def sleep_until(self, deadline_ns: int) -> None:
        raise AssertionError("an inline timer does not sleep")

    def sleeper(self) -> object:
        raise AssertionError("an inline timer does not sleep")

    def call_at(self, deadline_ns: int, callback: Callable[[], int | None]) -> ScheduledCall:
        self.deadline, self.callback = deadline_ns, callback
        clock = self

        class _Handle:
            def cancel(self) -> None:
                clock.callback = None

        return _Handle()

    def fire(self, late_ns: int = 0) -> None:
        assert self.deadline is not None and self.callback is not None
        self.now = self.deadline + late_ns
        self.deadline = self.callback()


async def test_on_time_and_late_inline_ticks_are_all_in_the_statistics() -> None:
    """On-time inline ticks skip the lateness arithmetic and are recorded in bulk: the
    statistics still count every tick, with each late tick's lateness among them."""
    clock = _HandDriven()
    assert isinstance(clock, InlineScheduler)
    async with EventTimer(1.0, clock=clock, name="hand") as timer:  # type: ignore[arg-type]
        indexes: list[int] = []

        class Plain:
            def notify_timer(self, t: EventTimer) -> None:
                tick = t.last_tick
                assert tick is not None
                indexes.append(tick.index)

        timer.add_observer(Plain())
        timer.start_timer()
        for _ in range(7):
            clock.fire()
        clock.fire(300_000)  # late (> period / 5) but within the period
        for _ in range(4):
            clock.fire()
        stats = timer.stats
        assert (stats.ticks, stats.late_ticks, stats.missed_ticks) == (12, 1, 0)
        assert stats.lateness.count == 12
        assert stats.lateness.max_ns == 300_000
        assert stats.lateness.mean_ns == pytest.approx(300_000 / 12)
        assert stats.last_lateness_ns == 0
        assert indexes == list(range(1, 13))
        clock.fire(2_500_000)  # two periods missed
        assert timer.stats.missed_ticks == 2 and timer.stats.lateness.count == 13
        timer.reset_stats()
        for _ in range(3):
            clock.fire()
        stats = timer.stats
        assert (stats.ticks, stats.lateness.count, stats.lateness.max_ns) == (3, 3, 0)
        timer.stop_timer()
