"""A lockstep simulation beside an auto-jumping VirtualClock in one event loop.

Both wait for the loop to be idle through the loop's one idle detector
(``openel_async.clock.wait_idle``), so they take turns; with separate busy settle loops
each kept the other runnable forever. Bounded by ``anyio.fail_after`` on real time, so a
regression fails instead of hanging.
"""

from __future__ import annotations

import anyio

from openel_async import VirtualClock
from openel_mujoco import MujocoSim


async def test_lockstep_sim_beside_the_virtual_clock_fixture(virtual_clock: VirtualClock) -> None:
    sim = MujocoSim("arm2")
    log: list[tuple[str, int]] = []

    async def on_sim() -> None:
        for _ in range(3):
            await sim.clock.sleep_until(sim.clock.now_ns() + 10_000_000)  # 10 ms of physics
            log.append(("sim", sim.clock.now_ns()))

    async def on_virtual() -> None:
        for _ in range(3):
            await virtual_clock.sleep(1.0)
            log.append(("virtual", virtual_clock.now_ns()))

    with anyio.fail_after(5):
        async with sim, anyio.create_task_group() as tg:
            tg.start_soon(on_sim)
            tg.start_soon(on_virtual)
    assert [t for n, t in log if n == "sim"] == [10_000_000, 20_000_000, 30_000_000]
    assert [t for n, t in log if n == "virtual"] == [10**9, 2 * 10**9, 3 * 10**9]
    assert sim.steps >= 30


async def test_manual_virtual_clock_advanced_beside_a_lockstep_sim() -> None:
    sim = MujocoSim("arm2")
    manual = VirtualClock()
    woken: list[int] = []

    async def sleeper() -> None:
        await manual.sleep_until(5)
        woken.append(manual.now_ns())

    with anyio.fail_after(5):
        async with sim, anyio.create_task_group() as tg:
            tg.start_soon(sleeper)
            await sim.sleep(0.01)  # the simulation runs ...
            await manual.advance(10)  # ... and the manual clock moves when told
    assert woken == [5] and manual.now_ns() == 10
