"""A Recorder entered and exited inside a running lockstep simulation: no physics step
passes while its writer process starts or stops (each is a call on a worker thread, under
``external_work``; with a bare ``anyio.to_thread.run_sync`` the simulation stepped at full
speed meanwhile, a burst of simulated time for work that takes none)."""

from __future__ import annotations

import itertools
from pathlib import Path

import anyio
import pytest
import structlog

from openel_async.recording import Recorder

from .schema_check import check_recording

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


async def test_on_a_lockstep_clock_the_tap_paces_itself(tmp_path: Path) -> None:
    """On an InlineScheduler clock the tap does not observe the timer (no call per tick):
    its own callback on the clock takes the timer's statistics (every tick counted, from
    the timer) and the joint-state samples at their period, between physics steps."""
    from openel_async import Actuator, ActuatorBank, EventTimer
    from openel_mujoco import MujocoSim

    path = tmp_path / "p.mcap"
    sim = MujocoSim("arm2", pacing="lockstep")
    recorder = Recorder(path, joint_period_ms=10)
    done = anyio.Event()
    with anyio.fail_after(30):
        async with recorder, sim:
            axes = [Actuator(sim.actuator(j), clock=sim.clock) for j in ("shoulder", "elbow")]
            timer = EventTimer(2, clock=sim.clock, name="loop")
            for axis in axes:
                recorder.observe(axis)
            recorder.observe_timer(timer)
            async with axes[0], axes[1], timer:
                bank = ActuatorBank(axes)
                ticks = 0

                def on_tick(t: EventTimer) -> None:
                    nonlocal ticks
                    ticks += 1
                    bank.set_values_nowait([0.001 * ticks, -0.001 * ticks])
                    if ticks == 500:
                        t.stop_timer()
                        done.set()

                timer.add_observer(on_tick)
                assert timer.observers == (on_tick,)  # the tap is not among them
                timer.start_timer()
                await done.wait()
                delivered = timer.ticks_delivered
                logged_at = sim.clock.now_ns()
                structlog.get_logger("test_lockstep").warning("lockstep_line")
    from openel_async.recording import read_recording

    assert check_recording(path) > 0  # every message fits its schema
    rec = read_recording(path)
    # /log on the simulation's clock (shifted to the wall clock, as every other channel)
    (line,) = [
        m for m in rec.messages if m.topic == "/log" and m.data["message"] == "lockstep_line"
    ]
    (sample,) = [m for m in rec.messages if m.topic == "/joint_states"][-1:]
    assert line.log_time_ns == sample.log_time_ns - sample.data["time_ns"] + logged_at
    stats = rec.topic("/timer/loop")
    assert sum(m["ticks"] for m in stats) == delivered == 500
    assert all(m["missed_ticks"] == 0 for m in stats)
    samples = rec.topic("/joint_states")
    assert 95 <= len(samples) <= 110  # 1 s of simulated time at 10 ms
    gaps = {b["time_ns"] - a["time_ns"] for a, b in itertools.pairwise(samples)}
    assert gaps == {10_000_000}
    (topic,) = [t for t in rec.counts() if t.startswith("/hal/") and "Shoulder" in t]
    commands = [m for m in rec.topic(topic) if m["kind"] == "command"]
    assert len(commands) == 500
    last = samples[-1]
    before = [m["value"] for m in commands if m["time_ns"] < last["time_ns"]]
    assert last["joints"][0]["commanded"] == before[-1]
