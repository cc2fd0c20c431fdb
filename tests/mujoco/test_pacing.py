"""Real-time pacing: the stepping logic on stand-in clocks (deterministic), then a short
loose check on the real clock."""

from __future__ import annotations

import time
from contextlib import AsyncExitStack

import anyio
import anyio.lowlevel
import pytest

from openel_async import Actuator, EventTimer, MonotonicClock, Request, VirtualClock
from openel_async.clock import Sleeper
from openel_mujoco import MujocoSim

from .conftest import start_rig


class LateClock:
    """A stand-in for the real clock: every wake-up comes ``lateness_ns`` after its deadline.

    Time moves only when a task sleeps, so a run is deterministic however slow the machine.
    """

    def __init__(self, lateness_ns: int) -> None:
        self.lateness_ns = lateness_ns
        self._now = 1_000_000_000

    def now_ns(self) -> int:
        return self._now

    async def sleep_until(self, deadline_ns: int) -> None:
        self._now = max(self._now, deadline_ns + self.lateness_ns)
        await anyio.lowlevel.checkpoint()

    def sleeper(self) -> Sleeper:
        clock = self

        class _Sleeper:
            async def sleep_until(self, deadline_ns: int) -> None:
                await clock.sleep_until(deadline_ns)

            def close(self) -> None:
                pass

        return _Sleeper()


async def _run_until(sim: MujocoSim, steps: int) -> None:
    with anyio.fail_after(20):
        while sim.steps < steps:
            await anyio.lowlevel.checkpoint()


async def test_realtime_pacing_on_a_virtual_clock_is_exact(stack: AsyncExitStack) -> None:
    clock = VirtualClock()
    await stack.enter_async_context(clock.autojump())
    sim = MujocoSim("arm2", pacing="realtime", clock=clock)
    assert sim.clock is clock
    rig = await start_rig(stack, sim, ("shoulder",), ("imu_acc",))
    timer = await stack.enter_async_context(EventTimer(1.0, clock=clock))
    timer.start_timer()
    with anyio.fail_after(10):
        motion = await rig.actuators["shoulder"].set_value(0.8)
        await motion
        await clock.sleep(0.5)
        await anyio.lowlevel.checkpoint()  # the simulation's wake-up at this time runs now
    # one physics step per 1 ms of clock time, never late
    assert sim.time_ns == clock.now_ns()
    stats = sim.stats
    assert stats.realtime_factor == pytest.approx(1.0, abs=1e-3)
    assert stats.lateness is not None and stats.lateness.max_ns == 0
    assert stats.max_catchup == 1 and stats.dropped_steps == 0
    assert timer.stats.lateness.max_ns == 0
    reading = await rig.sensors["imu_acc"].get_timed_value()
    assert reading.time_ns == clock.now_ns() - 1_000_000  # state at the start of the last step
    assert motion.reached_ns is not None and 0.15e9 < motion.reached_ns < 1e9


@pytest.mark.parametrize(
    ("lateness_us", "per_wake"),
    [(400, 1), (2_500, 3), (9_000, 10)],
)
async def test_realtime_steps_every_due_step_after_a_late_wake_up(
    lateness_us: int, per_wake: int
) -> None:
    clock = LateClock(lateness_us * 1000)
    sim = MujocoSim("arm2", pacing="realtime", clock=clock)
    start = clock.now_ns()
    async with sim:
        await _run_until(sim, 300)
        elapsed = clock.now_ns() - start
    stats = sim.stats
    # simulated time keeps up with the clock (to within the steps not yet due)
    assert abs(sim.time_ns - elapsed) <= (per_wake + 1) * sim.timestep_ns
    assert stats.lateness is not None
    assert stats.lateness.p50_ns == stats.lateness.max_ns == lateness_us * 1000
    assert stats.max_catchup == per_wake and stats.dropped_steps == 0
    assert stats.realtime_factor == pytest.approx(1.0, rel=0.05)


async def test_realtime_drops_steps_beyond_max_catchup() -> None:
    clock = LateClock(80_000_000)  # 80 ms late every time
    sim = MujocoSim("arm2", pacing="realtime", clock=clock, max_catchup_steps=50)
    start = clock.now_ns()
    async with sim:
        await _run_until(sim, 500)
        elapsed = clock.now_ns() - start
    stats = sim.stats
    assert stats.max_catchup == 50 and stats.dropped_steps > 0
    assert sim.time_ns < 0.75 * elapsed  # simulated time fell behind instead of blocking
    # 50 of every 81 due steps are taken (the last, interrupted wake-up adds some clock time)
    assert 0.5 < stats.realtime_factor <= 50 / 81 + 1e-9


async def test_realtime_factor_two(stack: AsyncExitStack) -> None:
    clock = VirtualClock()
    await stack.enter_async_context(clock.autojump())
    sim = MujocoSim("arm2", pacing="realtime", clock=clock, realtime_factor=2.0)
    await stack.enter_async_context(sim)
    with anyio.fail_after(10):
        await clock.sleep(0.25)
        await anyio.lowlevel.checkpoint()
    assert sim.time_ns == 500_000_000


async def test_realtime_on_the_real_clock_stays_near_real_time(stack: AsyncExitStack) -> None:
    sim = MujocoSim("arm2", pacing="realtime")
    assert isinstance(sim.clock, MonotonicClock)
    rig = await start_rig(stack, sim, ("elbow",))
    t0, s0 = time.monotonic_ns(), sim.time_ns
    await rig.actuators["elbow"].set_value(0.5, Request.VELOCITY)
    await anyio.sleep(0.5)
    wall, simulated = time.monotonic_ns() - t0, sim.time_ns - s0
    # loose bounds: a shared CI machine may stall the loop for a while
    assert 0.8 * wall <= simulated <= 1.2 * wall
    stats = sim.stats
    assert stats.lateness is not None and stats.lateness.count > 300
    assert isinstance(rig.actuators["elbow"], Actuator)


async def test_pause_stops_lockstep_time(stack: AsyncExitStack) -> None:
    sim = MujocoSim("arm2")
    await stack.enter_async_context(sim)
    await sim.sleep(0.01)
    steps = sim.steps
    async with sim.paused():
        for _ in range(100):
            await anyio.lowlevel.checkpoint()
        await anyio.sleep(0.01)  # real time passes, simulated time does not
        assert sim.steps == steps
    with anyio.fail_after(10):
        await sim.sleep(0.01)
    assert sim.steps == steps + 10


async def test_realtime_fault_waits_and_reset_resumes(stack: AsyncExitStack) -> None:
    clock = VirtualClock()
    await stack.enter_async_context(clock.autojump())
    sim = MujocoSim("arm2", pacing="realtime", clock=clock)
    rig = await start_rig(stack, sim, ("shoulder",))
    with anyio.fail_after(10):
        await clock.sleep(0.1)
        sim.data.qvel[0] = float("nan")
        await rig.events.wait_for("error")
        steps = sim.steps
        await clock.sleep(0.1)  # the clock goes on, the physics does not
        assert sim.steps == steps and sim.fault is not None
        await rig.actuators["shoulder"].re_init()
        assert sim.fault is None and sim.time_ns == 0
        await clock.sleep(0.1)
        await anyio.lowlevel.checkpoint()
    assert sim.time_ns == 100_000_000  # paced again from the reset on
