"""The MuJoCo device layer: lockstep overhead against raw MuJoCo, and real-time pacing.

**Lockstep overhead.** The 6-DoF arm (``arm6``) with 6 ``Actuator`` components (one per
joint, POSITION) and 6 ``Sensor`` components (``imu_acc``, ``imu_gyro``, ``wrist_force``,
``wrist_torque``, ``tool_pos``, ``pad_touch``: 16 values), all on ``sim.clock``.  An
``EventTimer`` at the physics rate (1 ms) on the simulation clock drives the control step, a
plain TimerObserver that the lockstep clock calls inline between physics steps: it writes the
6 joint targets through an ``ActuatorBank`` (``set_values_nowait``) and reads the 6 sensors
through a ``SensorBank`` (``get_values_nowait``).  Peer, same run, same number of steps: the
loop a MuJoCo user writes with numpy (*raw numpy*: ``mj_step``, one fancy-index store of the
6 targets into ``ctrl``, one fancy-index gather of the 16 ``sensordata`` values); *raw* is
the same loop written element by element (6 ``ctrl`` writes, 6 ``sensordata`` slices as
floats).  All apply the same targets at the same steps, so they end in bit-identical states
(checked).  More variants split the overhead between the driver and the framework and show
the other ways to write the step:

- *mj_step alone*: the raw loop without the control work;
- *sim loop*: the lockstep simulation alone with the 12 components attached, no control
  (driver: stepping loop, completion/limit/saturation monitors, instability check, clock);
- *+ timer*: plus the EventTimer and a plain observer that does nothing (framework: the
  inline tick and its fan-out);
- *+ device calls*: the observer calls the devices one by one (``MujocoJoint.command_nowait``,
  ``MujocoSensor.read_nowait``; driver);
- *full*: through the banks (framework components), as described above;
- *full, per call*: ``Actuator.set_value_nowait``/``Sensor.get_value_nowait`` per component;
- *full, async*: an async observer (mailbox, task switch per tick) awaiting ``set_value`` and
  ``get_value`` per component.

Recorded runs before the passes of docs/mujoco.md, section 9, per control step: full 13.0 µs
against raw numpy 6.7 µs (1.94x; sim loop 7.7, + timer 8.5, + device calls 12.1 µs); after
the SensorBank batch reader, the ActuatorBank's inline tick for per-joint ranges, the
generated joint monitor over memoryviews and the inline clock advance, 11.6 against 7.0 µs
(1.67x; sim loop 7.3, + timer 8.1, + device calls 11.5 µs).  The latest pass generates the
joints' batch per plan (one command-state attribute per joint), steps the physics inline in
the lockstep loop and reads the sensors' span of ``sensordata`` with one ``struct`` unpack.
Issue 27's profile put ~37 % of the bank calls in ``ActuatorBank.set_values_nowait``'s checks
(the type tuple 14 %, min/max 11 %, the finiteness sum 5 %): a POSITION batch is now checked
by one straight-line function generated per bank (per value one type test and one chained
comparison with its device's finite limits, which NaN and infinities fail), about 0.4 µs
less per call on this arm.  (Vectorising with numpy does not pay at this size: one ufunc
call or reduction on 6 values costs 0.5-1.5 µs, more than the whole Python check.)

Each variant runs ROUNDS times, interleaved; the median time per step is reported (many short
rounds rather than a few long ones, so that a burst of load on a shared machine spoils a
minority of the rounds of every variant alike).  Times are CPU time of the thread running
the loop (``time.thread_time_ns``): every variant is CPU-bound and single-threaded, and CPU
time is not inflated when a shared machine deschedules the process.

**Real-time pacing.** The same arm and control step with ``pacing="realtime"`` on the real
``MonotonicClock`` for DURATION_S (in CHUNKS chunks): real-time factor (simulated / real time),
lateness of the simulation loop's wake-ups after each physics-step deadline, and lateness of
the control EventTimer's ticks.  Baseline, same run and duration, chunks alternating with
ours: a bare deadline loop on the same kind of sleeper (a timerfd) stepping raw MuJoCo with
the raw control work.

**The limit and the decision (issue 27, <= 1.3x).** Each run's split rows bound the ratio
from below, before any value is written or read. The stepping loop with the components
attached ("sim loop") and the timer's inline tick with an observer that does nothing
("+ timer") already take 1.56x and 1.98x the raw numpy loop in the run recorded below: the
completion, limit and saturation monitors after every physics step, and the tick's fan-out.

The monitors are the safety of a simulated drive (a joint at a limit or saturated is faulted
or reported; completion is what posts COMPLETED). They are already one generated
straight-line function per plan over memoryviews. mypyc does not apply to code generated at
run time, and numpy costs more at this size: 0.5-1.5 µs per ufunc over 6 values. Only a C
extension could take the monitors and the tick out of the interpreter. Even if both cost
nothing, the ratio would be about 1.0x plus the control work's share (full minus "+ timer",
0.25x in that run): 1.25x, at the edge of the target. A real extension would still pay a
Python call per step.

The compiled path was measured on the AxisGroup's tick (the axis_group section: mypyc, no
gain on calls across objects). It would cost a C build, wheels for every platform, and tests
run against both builds.

**Decision:** no compiled extension for the simulation loop. The row stays marked missed,
with its bound measured in every run (the split rows).
"""

from __future__ import annotations

import gc
import math
import statistics
import time
from collections.abc import Callable, Coroutine
from contextlib import AsyncExitStack
from dataclasses import dataclass
from typing import Any

import anyio
import mujoco
import numpy as np

from openel_async import (
    Actuator,
    ActuatorBank,
    EventTimer,
    MonotonicClock,
    Request,
    Sensor,
    SensorBank,
)
from openel_async.stats import LatenessRecorder, LatenessSummary
from openel_mujoco import MujocoSim

from .harness import BenchResult, Row, ratio_of

NAME = "mujoco"
MODEL = "arm6"
KEYFRAME = "home"
JOINTS = (
    "base_yaw",
    "shoulder_pitch",
    "elbow_pitch",
    "wrist_roll",
    "wrist_pitch",
    "flange_roll",
)
SENSORS = ("imu_acc", "imu_gyro", "wrist_force", "wrist_torque", "tool_pos", "pad_touch")
STEPS = 5_000
QUICK_STEPS = 2_000
ROUNDS = 9
QUICK_ROUNDS = 2
DURATION_S = 10.0
QUICK_DURATION_S = 2.0
CHUNKS = 5
QUICK_CHUNKS = 2
PERIOD_MS = 1.0
OVERHEAD_TARGET = 1.3
"""Ours (full) / the raw numpy loop, time per control step, at most (issue 27)."""
RTF_TOLERANCE = 0.01
LATENESS_TARGET_US = 1000.0

VARIANTS = (
    "mj_step only",
    "raw numpy",
    "raw",
    "sim loop",
    "+ timer",
    "+ device calls",
    "full",
    "full, per call",
    "full, async",
)

# Lockstep runs are CPU-bound in the main thread: their cost is measured in the thread's CPU
# time, which a busy shared machine does not inflate the way it inflates wall time.
_cpu_ns = time.thread_time_ns


def targets(steps: int) -> list[list[float]]:
    """Slow sine sweeps, one phase per joint, well inside every joint range."""
    return [
        [0.3 * math.sin(2 * math.pi * 0.5 * k / 1000 + j) for j in range(len(JOINTS))]
        for k in range(steps + 1)
    ]


# -- raw MuJoCo ---------------------------------------------------------------------------------


@dataclass
class RawRig:
    model: mujoco.MjModel
    data: mujoco.MjData
    acts: list[int]
    slices: list[tuple[int, int]]

    @classmethod
    def make(cls) -> RawRig:
        sim = MujocoSim(MODEL, keyframe=KEYFRAME)  # same model, options and initial state
        m, d = sim.model, sim.data
        acts = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, j + "_pos") for j in JOINTS]
        slices = []
        for name in SENSORS:
            sid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SENSOR, name)
            start = int(m.sensor_adr[sid])
            slices.append((start, start + int(m.sensor_dim[sid])))
        return cls(m, d, acts, slices)

    def control(self, target: list[float]) -> float:
        ctrl, sd = self.data.ctrl, self.data.sensordata
        for act, value in zip(self.acts, target, strict=True):
            ctrl[act] = value
        total = 0.0
        for a, b in self.slices:
            total += sum(sd[a:b].tolist())
        return total


def raw_numpy_loop(steps: int, table: list[list[float]]) -> tuple[float, np.ndarray]:
    """The loop a MuJoCo user writes with numpy: one fancy-index store of the 6 position
    targets into ``ctrl``, ``mj_step``, one fancy-index gather of the 16 sensor values."""
    rig = RawRig.make()
    m, d = rig.model, rig.data
    acts = np.array(rig.acts)
    sensor_index = np.concatenate([np.arange(a, b) for a, b in rig.slices])
    rows = np.array(table)  # the targets as the numpy user holds them
    ctrl, sd = d.ctrl, d.sensordata
    step = mujoco.mj_step
    readings = None
    t0 = _cpu_ns()
    for k in range(steps):
        step(m, d)
        ctrl[acts] = rows[k]
        readings = sd[sensor_index]
    elapsed = _cpu_ns() - t0
    assert readings is not None and readings.shape == (sensor_index.size,)
    return elapsed / steps, np.array(d.qpos)


def raw_loop(
    steps: int, table: list[list[float]], control: bool = True
) -> tuple[float, np.ndarray]:
    rig = RawRig.make()
    m, d = rig.model, rig.data
    step = mujoco.mj_step
    work = rig.control
    t0 = _cpu_ns()
    if control:
        for k in range(steps):
            step(m, d)
            work(table[k])
    else:
        for _ in range(steps):
            step(m, d)
    elapsed = _cpu_ns() - t0
    return elapsed / steps, np.array(d.qpos)


# -- through the framework ------------------------------------------------------------------


async def lockstep_loop(
    variant: str, steps: int, table: list[list[float]]
) -> tuple[float, np.ndarray]:
    sim = MujocoSim(MODEL, keyframe=KEYFRAME)
    async with AsyncExitStack() as stack:
        await stack.enter_async_context(sim)
        actuators = [
            await stack.enter_async_context(Actuator(sim.actuator(j), clock=sim.clock))
            for j in JOINTS
        ]
        sensors = [
            await stack.enter_async_context(Sensor(sim.sensor(s), clock=sim.clock)) for s in SENSORS
        ]
        if variant == "sim loop":
            t0 = _cpu_ns()
            await sim.sleep(steps * sim.timestep_ns / 1e9)
            elapsed = _cpu_ns() - t0
            return elapsed / steps, np.array(sim.data.qpos)

        timer = await stack.enter_async_context(EventTimer(PERIOD_MS, clock=sim.clock))
        done = anyio.Event()
        observer: _Observer | _AsyncObserver
        if variant == "full, async":
            observer = _AsyncObserver(_async_work(actuators, sensors, table), steps, done)
        else:
            observer = _Observer(_control_work(variant, actuators, sensors, table), steps, done)
        timer.add_observer(observer)
        t0 = _cpu_ns()
        timer.start_timer()
        with anyio.fail_after(600):
            await done.wait()
        elapsed = _cpu_ns() - t0
        qpos = np.array(sim.data.qpos)
        if observer.count != steps or sim.steps != steps:
            raise AssertionError(
                f"{variant}: {observer.count} control steps for {sim.steps} physics steps"
            )
        return elapsed / steps, qpos


Work = Callable[[int], None]
AsyncWork = Callable[[int], Coroutine[Any, Any, None]]


def _control_work(
    variant: str, actuators: list[Actuator], sensors: list[Sensor], table: list[list[float]]
) -> Work:
    """The control step of a plain (synchronous) TimerObserver: the non-suspending calls."""
    position = Request.POSITION
    if variant == "+ timer":

        def nothing(k: int) -> None:
            pass

        return nothing
    if variant == "+ device calls":
        joints = [a.device for a in actuators]
        devices = [s.device for s in sensors]

        def direct(k: int) -> None:
            target = table[k]
            for i, joint in enumerate(joints):
                joint.command_nowait(position, target[i])
            for device in devices:
                device.read_nowait()

        return direct

    if variant == "full, per call":

        def per_call(k: int) -> None:
            target = table[k]
            for i, actuator in enumerate(actuators):
                actuator.set_value_nowait(target[i], position)
            for sensor in sensors:
                sensor.get_value_nowait()

        return per_call

    joint_bank = ActuatorBank(actuators)
    sensor_bank = SensorBank(sensors)

    def full(k: int) -> None:
        joint_bank.set_values_nowait(table[k], position)
        sensor_bank.get_values_nowait()

    return full


def _async_work(
    actuators: list[Actuator], sensors: list[Sensor], table: list[list[float]]
) -> AsyncWork:
    """The same control step in an async TimerObserver: ``await`` set_value/get_value."""
    position = Request.POSITION

    async def full(k: int) -> None:
        target = table[k]
        for i, actuator in enumerate(actuators):
            await actuator.set_value(target[i], position)
        for sensor in sensors:
            await sensor.get_value()

    return full


class _Observer:
    """Plain TimerObserver: one control step per tick, stops the timer after ``steps``."""

    def __init__(self, work: Work, steps: int, done: anyio.Event) -> None:
        self.work = work
        self.steps = steps
        self.done = done
        self.count = 0

    def notify_timer(self, timer: EventTimer) -> None:
        if self.count >= self.steps:
            return
        self.work(self.count)
        self.count += 1
        if self.count == self.steps:
            timer.stop_timer()
            self.done.set()


class _AsyncObserver:
    """Async TimerObserver (a mailbox and a task of its own) doing the same."""

    def __init__(self, work: AsyncWork, steps: int, done: anyio.Event) -> None:
        self.work = work
        self.steps = steps
        self.done = done
        self.count = 0

    async def notify_timer(self, timer: EventTimer) -> None:
        if self.count >= self.steps:
            return
        await self.work(self.count)
        self.count += 1
        if self.count == self.steps:
            timer.stop_timer()
            self.done.set()


# -- real time ----------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class RealtimeFigures:
    rtf: float
    loop_lateness: LatenessSummary
    timer_lateness: LatenessSummary | None
    dropped: int
    missed_ticks: int
    ticks: int
    steps: int


async def realtime_run(duration_s: float, table: list[list[float]]) -> RealtimeFigures:
    sim = MujocoSim(MODEL, keyframe=KEYFRAME, pacing="realtime", clock=MonotonicClock())
    async with AsyncExitStack() as stack:
        await stack.enter_async_context(sim)
        actuators = [
            await stack.enter_async_context(Actuator(sim.actuator(j), clock=sim.clock))
            for j in JOINTS
        ]
        sensors = [
            await stack.enter_async_context(Sensor(sim.sensor(s), clock=sim.clock)) for s in SENSORS
        ]
        timer = await stack.enter_async_context(EventTimer(PERIOD_MS, clock=sim.clock))
        steps = round(duration_s * 1000)
        done = anyio.Event()
        observer = _Observer(_control_work("full", actuators, sensors, table), steps, done)
        timer.add_observer(observer)
        await anyio.sleep(0.1)  # warm-up: the loop runs, stats restart below
        sim.reset_stats()
        timer.start_timer()
        with anyio.fail_after(duration_s * 3 + 10):
            await done.wait()
        stats = sim.stats
        assert stats.lateness is not None
        return RealtimeFigures(
            rtf=stats.realtime_factor,
            loop_lateness=stats.lateness,
            timer_lateness=timer.stats.lateness,
            dropped=stats.dropped_steps,
            missed_ticks=timer.stats.missed_ticks,
            ticks=timer.stats.ticks,
            steps=stats.steps,
        )


async def realtime_baseline(duration_s: float, table: list[list[float]]) -> RealtimeFigures:
    """A bare deadline loop on the clock's sleeper: mj_step + the raw control work per 1 ms."""
    rig = RawRig.make()
    m, d = rig.model, rig.data
    clock = MonotonicClock()
    sleeper = clock.sleeper()
    recorder = LatenessRecorder()
    period = 1_000_000
    steps = round(duration_s * 1000)
    try:
        start = clock.now_ns()
        for k in range(1, steps + 1):
            deadline = start + k * period
            await sleeper.sleep_until(deadline)
            recorder.record(clock.now_ns() - deadline)
            mujoco.mj_step(m, d)
            rig.control(table[k - 1])
        elapsed = clock.now_ns() - start
    finally:
        sleeper.close()
    return RealtimeFigures(
        rtf=steps * period / elapsed,
        loop_lateness=recorder.summary(),
        timer_lateness=None,
        dropped=0,
        missed_ticks=0,
        ticks=steps,
        steps=steps,
    )


def _combine(figures: list[RealtimeFigures]) -> RealtimeFigures:
    """Totals over the chunks; p50/p99 are the medians of the chunks' percentiles."""

    def summary(parts: list[LatenessSummary]) -> LatenessSummary:
        count = sum(p.count for p in parts)
        return LatenessSummary(
            count=count,
            p50_ns=round(statistics.median(p.p50_ns for p in parts)),
            p99_ns=round(statistics.median(p.p99_ns for p in parts)),
            max_ns=max(p.max_ns for p in parts),
            mean_ns=sum(p.mean_ns * p.count for p in parts) / count if count else 0.0,
        )

    steps = sum(f.steps for f in figures)
    wall = sum(f.steps / f.rtf for f in figures if f.rtf)
    timers = [f.timer_lateness for f in figures if f.timer_lateness is not None]
    return RealtimeFigures(
        rtf=steps / wall if wall else 0.0,
        loop_lateness=summary([f.loop_lateness for f in figures]),
        timer_lateness=summary(timers) if timers else None,
        dropped=sum(f.dropped for f in figures),
        missed_ticks=sum(f.missed_ticks for f in figures),
        ticks=sum(f.ticks for f in figures),
        steps=steps,
    )


# -- the benchmark -------------------------------------------------------------------------------


def _measure_lockstep(steps: int, rounds: int) -> tuple[dict[str, list[float]], list[str]]:
    table = targets(steps)
    per_step: dict[str, list[float]] = {v: [] for v in VARIANTS}
    notes: list[str] = []
    for _ in range(rounds):
        states: dict[str, np.ndarray] = {}
        for variant in VARIANTS:
            gc.collect()
            if variant == "raw numpy":
                ns, qpos = raw_numpy_loop(steps, table)
            elif variant in ("raw", "mj_step only"):
                ns, qpos = raw_loop(steps, table, control=variant == "raw")
            else:
                ns, qpos = anyio.run(lockstep_loop, variant, steps, table, backend="asyncio")
            per_step[variant].append(ns)
            states[variant] = qpos
        for variant in ("raw numpy", "+ device calls", "full", "full, per call", "full, async"):
            if variant not in states:
                continue
            if states[variant].tobytes() != states["raw"].tobytes():
                raise AssertionError(f"{variant}: final state differs from raw MuJoCo's")
    notes.append(
        "After every round the final `qpos` of the device-call and full runs were checked "
        "bit-identical to raw MuJoCo's: the framework did the same physics."
    )
    return per_step, notes


def run(quick: bool) -> BenchResult:
    steps = QUICK_STEPS if quick else STEPS
    rounds = QUICK_ROUNDS if quick else ROUNDS
    duration_s = QUICK_DURATION_S if quick else DURATION_S

    per_step, notes = _measure_lockstep(steps, rounds)
    med = {v: statistics.median(per_step[v]) / 1e3 for v in VARIANTS}  # µs per step

    chunks = QUICK_CHUNKS if quick else CHUNKS
    chunk_s = duration_s / chunks
    table = targets(round(chunk_s * 1000))
    ours: list[RealtimeFigures] = []
    bares: list[RealtimeFigures] = []
    for _ in range(chunks):  # interleaved, so that load changes hit both alike
        gc.collect()
        ours.append(anyio.run(realtime_run, chunk_s, table, backend="asyncio"))
        gc.collect()
        bares.append(anyio.run(realtime_baseline, chunk_s, table, backend="asyncio"))
    rt, base = _combine(ours), _combine(bares)

    raw = med["raw"]
    peer = med["raw numpy"]
    overhead = ratio_of(med["full"], peer)
    rows: list[Row] = [
        Row(
            "lockstep: time per control step (full)",
            med["full"],
            "µs",
            baseline=peer,
            baseline_label="raw numpy loop (ctrl[acts] = row, mj_step, sensordata[idx])",
            ratio=overhead,
            ratio_label="ours/raw numpy",
            target=f"ratio <= {OVERHEAD_TARGET:.1f}x",
            passed=overhead <= OVERHEAD_TARGET,
            digits=1,
        )
    ]
    rows.append(
        Row(
            "lockstep: mj_step alone",
            med["mj_step only"],
            "µs",
            baseline=raw,
            baseline_label="raw",
            ratio=ratio_of(med["mj_step only"], raw),
            ratio_label="variant/raw",
            digits=1,
        )
    )
    for variant in [v for v in VARIANTS if v not in ("full", "mj_step only", "raw")]:
        rows.append(
            Row(
                f"lockstep: {variant}",
                med[variant],
                "µs",
                baseline=raw,
                baseline_label="raw",
                ratio=ratio_of(med[variant], raw),
                ratio_label="variant/raw",
                digits=1,
            )
        )
    rows.append(
        Row(
            "lockstep: speed (full)",
            1e6 / med["full"] / 1000,
            "x real time",
            baseline=1e6 / raw / 1000,
            baseline_label="raw",
            digits=1,
        )
    )
    rtf_ok = abs(rt.rtf - 1.0) <= RTF_TOLERANCE
    us = 1e3
    rows += [
        Row(
            "realtime: real-time factor",
            rt.rtf,
            "",
            baseline=base.rtf,
            baseline_label="bare deadline loop",
            target=f"1.0 ± {RTF_TOLERANCE:.2f}",
            passed=rtf_ok,
            digits=4,
        ),
        Row(
            "realtime: sim loop lateness p99",
            rt.loop_lateness.p99_ns / us,
            "µs",
            baseline=base.loop_lateness.p99_ns / us,
            baseline_label="bare deadline loop",
            ratio=ratio_of(rt.loop_lateness.p99_ns, base.loop_lateness.p99_ns),
            ratio_label="ours/bare",
            target=f"<= {LATENESS_TARGET_US:.0f} µs",
            passed=rt.loop_lateness.p99_ns / us <= LATENESS_TARGET_US,
        ),
        Row(
            "realtime: sim loop lateness p50",
            rt.loop_lateness.p50_ns / us,
            "µs",
            baseline=base.loop_lateness.p50_ns / us,
            baseline_label="bare deadline loop",
            ratio=ratio_of(rt.loop_lateness.p50_ns, base.loop_lateness.p50_ns),
            ratio_label="ours/bare",
        ),
    ]
    if rt.timer_lateness is not None:
        rows.append(
            Row(
                "realtime: control tick lateness p99",
                rt.timer_lateness.p99_ns / us,
                "µs",
                baseline=base.loop_lateness.p99_ns / us,
                baseline_label="bare deadline loop",
                ratio=ratio_of(rt.timer_lateness.p99_ns, base.loop_lateness.p99_ns),
                ratio_label="ours/bare",
                target=f"<= {LATENESS_TARGET_US:.0f} µs",
                passed=rt.timer_lateness.p99_ns / us <= LATENESS_TARGET_US,
            )
        )
    rows.append(
        Row(
            "realtime: dropped physics steps",
            rt.dropped,
            baseline=0,
            baseline_label="bare",
            digits=0,
        )
    )

    bare = med["mj_step only"]
    control_us = raw - bare
    stepping_us = med["sim loop"] - bare
    notes += [
        f"Overhead per control step over raw MuJoCo: {med['full'] - raw:.1f} µs. Stepping loop, "
        f"monitors and instability check {stepping_us:.1f} µs per physics step over a bare "
        f"mj_step ({bare:.1f} µs); the inline EventTimer tick and its fan-out "
        f"{med['+ timer'] - med['sim loop']:.1f} µs; the control work through the banks "
        f"{med['full'] - med['+ timer']:.1f} µs, where the 12 device calls one by one take "
        f"{med['+ device calls'] - med['+ timer']:.1f} µs and raw MuJoCo's 6 ctrl writes and 6 "
        f"sensordata reads {control_us:.1f} µs. Per component instead of banks: "
        f"{med['full, per call']:.1f} µs per step "
        f"({ratio_of(med['full, per call'], raw):.2f}x); an async observer awaiting each call: "
        f"{med['full, async']:.1f} µs ({ratio_of(med['full, async'], raw):.2f}x).",
        "Per-round µs per step: "
        + "; ".join(f"{v} " + ", ".join(f"{x / 1e3:.1f}" for x in per_step[v]) for v in VARIANTS)
        + ".",
        f"Real time ({chunks} chunks of {chunk_s:g} s, alternating with the bare loop; p50/p99 "
        f"are medians over the chunks): {rt.steps} physics steps, {rt.ticks} control ticks "
        f"({rt.missed_ticks} missed), {rt.dropped} dropped steps; sim loop lateness p50 "
        f"{rt.loop_lateness.p50_ns / us:.0f} µs, p99 {rt.loop_lateness.p99_ns / us:.0f} µs, "
        f"max {rt.loop_lateness.max_ns / us:.0f} µs; bare loop p99 "
        f"{base.loop_lateness.p99_ns / us:.0f} µs, max {base.loop_lateness.max_ns / us:.0f} µs.",
    ]
    if base.loop_lateness.p99_ns / us > LATENESS_TARGET_US:
        notes.append(
            "The bare deadline loop, doing a fraction of the work, misses the lateness target "
            "too: the real-time tails in this run are the machine's wake-up latency under load "
            "(see the load average below), not the simulation's pacing."
        )
    if overhead > OVERHEAD_TARGET:
        notes.append(
            f"The {OVERHEAD_TARGET:.1f}x target is missed: the raw numpy loop spends "
            f"{peer:.1f} µs per step on this arm, so {OVERHEAD_TARGET:.1f}x leaves "
            f"{(OVERHEAD_TARGET - 1) * peer:.1f} µs per control step "
            "for the stepping loop, the timer tick and the control work (see the split above). "
            "Profile of the remaining cost and what would remove it: docs/mujoco.md, "
            "section 9 (joint monitors from a plan and sensor reads cut by one itemgetter "
            "took it from 2.21x to 2.03x; banks skipping per-member Active checks while no "
            "component changed state, the joint batch counting its calls once, inline bank "
            "checks and an inline timer tick without lateness arithmetic to about 1.9x; a "
            "SensorBank batch reader, the ActuatorBank's inline tick for per-joint ranges, a "
            "joint monitor generated per plan over memoryviews, memoryview ctrl writes and the "
            "clock advanced inline by the stepping loop to about 1.7x; a joint batch generated per "
            "plan, the physics step inline in the lockstep loop and a batch reader over one "
            "span of sensordata to about 1.6x; the bank's check generated per bank, about "
            "0.4 µs less per step)."
        )
        notes.append(
            f"What bounds the ratio, measured in this run: the stepping loop with the 12 "
            f"components attached and no control work (sim loop) takes "
            f"{ratio_of(med['sim loop'], peer):.2f}x the raw numpy loop, and with the "
            f"EventTimer ticking a plain observer that does nothing (+ timer) "
            f"{ratio_of(med['+ timer'], peer):.2f}x: the completion, limit and saturation "
            "monitors after every physics step and the timer's inline tick and fan-out, "
            "before any value is written or read. The control work through the banks adds "
            f"{med['full'] - med['+ timer']:.1f} µs against the numpy loop's "
            f"{peer - bare:.1f} µs for its store and gather (the checks, the batch's "
            "bookkeeping for Motions and COMPLETED, the per-sensor tuples and their "
            "finiteness check). Below the target would need the monitors and the timer tick "
            "out of the interpreter (a compiled hot path), not more work removed from it."
        )
    return BenchResult(
        name=NAME,
        title="MuJoCo arm6: lockstep overhead vs raw MuJoCo, real-time pacing",
        rows=tuple(rows),
        description=DESCRIPTION,
        notes=tuple(notes),
        params={
            "model": f"{MODEL} (keyframe {KEYFRAME}), timestep 1 ms",
            "control": "6 Actuators (POSITION) + 6 Sensors (16 values) per 1 ms tick",
            "lockstep steps": f"{steps} x {rounds} rounds",
            "real time": f"{duration_s:g} s ({chunks} x {chunk_s:g} s)",
            "clock": repr(MonotonicClock()),
        },
    )


DESCRIPTION = (
    (__doc__ or "")
    .split("\n", 2)[2]
    .strip()
    .replace("ROUNDS times", f"{ROUNDS} times ({QUICK_ROUNDS} with --quick)")
    .replace(
        "DURATION_S (in CHUNKS chunks)",
        f"{DURATION_S:g} s (in {CHUNKS} chunks; --quick: {QUICK_DURATION_S:g} s)",
    )
)
