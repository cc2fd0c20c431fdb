"""A lockstep MuJoCo simulation does not step while work is in flight on a worker thread.

The simulation steps physics whenever the event loop is idle (``openel_async.clock.wait_idle``);
a task awaiting a bare ``anyio.to_thread.run_sync`` left the loop idle, so the physics (and
every timer on ``sim.clock``) ran at full speed for as long as the thread worked.  Bounded by
``anyio.fail_after``; the threads' waits by their own timeouts.
"""

from __future__ import annotations

import threading

import anyio

from openel_async import EventTimer
from openel_async.clock import external_work, run_in_thread
from openel_mujoco import MujocoSim

HOLD_S = 0.1


async def _ticker(sim: MujocoSim, ticked: threading.Event) -> None:
    for _ in range(10):
        await sim.clock.sleep(0.001)
    ticked.set()


async def test_bare_worker_thread_lets_the_physics_run() -> None:
    """The hazard: the thread is released by ticks of simulated time that pass meanwhile."""
    sim = MujocoSim("arm2")
    ticked = threading.Event()
    with anyio.fail_after(10):
        async with sim, anyio.create_task_group() as tg:
            tg.start_soon(_ticker, sim, ticked)
            await anyio.lowlevel.checkpoint()
            steps = sim.steps
            assert await anyio.to_thread.run_sync(ticked.wait, 5.0)
            assert sim.steps - steps >= 10


async def test_run_in_thread_freezes_the_physics() -> None:
    sim = MujocoSim("arm2")
    ticked = threading.Event()
    with anyio.fail_after(10):
        async with sim, anyio.create_task_group() as tg:
            tg.start_soon(_ticker, sim, ticked)
            await anyio.lowlevel.checkpoint()
            steps, now = sim.steps, sim.clock.now_ns()
            assert not await run_in_thread(ticked.wait, HOLD_S)
            assert (sim.steps, sim.clock.now_ns()) == (steps, now)
            with anyio.fail_after(5):  # released: the physics runs again
                await sim.clock.sleep(0.02)
            assert ticked.is_set()


async def test_no_timer_ticks_while_held() -> None:
    """An EventTimer on sim.clock (inline ticks between physics steps) stays silent during
    the call: no burst of ticks for work that takes no simulated time."""
    sim = MujocoSim("arm2")
    ticks: list[int] = []

    class Count:
        def notify_timer(self, timer: EventTimer) -> None:
            ticks.append(sim.clock.now_ns())

    with anyio.fail_after(10):
        async with sim, EventTimer(1.0, clock=sim.clock) as timer:
            timer.add_observer(Count())
            timer.start_timer()
            await sim.sleep(0.005)
            seen = len(ticks)
            with external_work("configuring"):
                await anyio.to_thread.run_sync(threading.Event().wait, HOLD_S)
                assert len(ticks) == seen
            await sim.sleep(0.005)
            timer.stop_timer()
    assert len(ticks) > seen


async def test_a_held_thread_calling_back_into_the_loop_completes() -> None:
    """A thread that needs the loop (from_thread) gets it while the physics waits."""
    sim = MujocoSim("arm2")

    def read_time() -> int:
        return anyio.from_thread.run_sync(sim.clock.now_ns)

    with anyio.fail_after(10):
        async with sim:
            await sim.sleep(0.003)
            steps = sim.steps
            assert await run_in_thread(read_time) == 3_000_000
            assert sim.steps == steps
