"""A Recorder entered and exited inside a running lockstep simulation: no physics step
passes while its writer process starts or stops (each is a call on a worker thread, under
``external_work``; with a bare ``anyio.to_thread.run_sync`` the simulation stepped at full
speed meanwhile, a burst of simulated time for work that takes none)."""

from __future__ import annotations

from pathlib import Path

import anyio
import pytest

from openel_async.recording import Recorder

pytest.importorskip("mujoco")


async def _ticker(sim: object, stop: anyio.Event) -> None:
    clock = sim.clock  # type: ignore[attr-defined]
    while not stop.is_set():
        await clock.sleep(0.001)


async def test_recorder_start_and_stop_take_no_simulated_time(tmp_path: Path) -> None:
    from openel_mujoco import MujocoSim

    sim = MujocoSim("arm2", pacing="lockstep")
    stop = anyio.Event()
    with anyio.fail_after(30):
        async with sim, anyio.create_task_group() as tg:
            tg.start_soon(_ticker, sim, stop)  # something always waits for simulated time
            await sim.sleep(0.01)
            steps, now = sim.steps, sim.clock.now_ns()
            recorder = Recorder(tmp_path / "l.mcap")
            await recorder.__aenter__()  # the writer process starts
            entered = sim.steps, sim.clock.now_ns()
            await recorder.__aexit__(None, None, None)  # and stops
            exited = sim.steps, sim.clock.now_ns()
            stop.set()
    assert entered == (steps, now)
    assert exited == (steps, now)
    assert recorder.final_stats is not None and recorder.final_stats.dropped == 0
