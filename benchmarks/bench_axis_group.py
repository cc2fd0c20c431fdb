"""Per-tick cost of an AxisGroup (ruckig sampling + streaming setpoints) for 8-256 axes.

The actuators are ``Actuator``s over an in-memory driver (``command`` stores the value,
``read`` returns it, completion reported by the driver so no detection task runs), to
isolate the group's own cost from any driver's. The group runs a real move on an
``EventTimer(1 ms)`` over a ``VirtualClock`` (time jumps from tick to tick, so a run
of 2 simulated seconds takes what its ticks cost), and the group itself times each
tick (``AxisGroup.stats.tick_cost``: sampling the ruckig trajectory, sending one
``set_value`` per axis, logging the row).

Baseline, on the same actuators in the same run: a naive streaming loop that linearly
interpolates every axis in Python and awaits ``set_value`` for each (no ruckig, no
checks, no log), timed per tick the same way. Ruckig alone: the same trajectory's
``Plan.sample`` (``Trajectory.at_time``) timed at the same tick times.

A last, real-clock run drives 64 axes at 1 kHz on a ``MonotonicClock`` for a few
seconds and reports the process CPU time per wall second (timer, event loop and group
together) and the ticks the timer or the group had to skip.
"""

from __future__ import annotations

import gc
import random
import statistics
import time
from dataclasses import dataclass

import anyio
import anyio.lowlevel

from openel_async import (
    Actuator,
    ActuatorDevice,
    ActuatorLimits,
    DeviceInfo,
    DeviceKind,
    EventTimer,
    MonotonicClock,
    Request,
    VirtualClock,
)
from openel_async.motion import AxisGroup, AxisLimits, KinematicState, Planner, Tolerances
from openel_async.stats import percentile

from .harness import COMMAND, BenchResult, Row, ratio_of

NAME = "axis_group"
SIZES = (8, 64, 256)
TARGET_AXES = 64
TARGET_US = 500.0
PERIOD_MS = 1
TICKS = 2_000
QUICK_TICKS = 500
ROUNDS = 3
QUICK_ROUNDS = 1
REAL_SECONDS = 4.0
QUICK_REAL_SECONDS = 1.5
PLANNING_REPEATS = 20
LIMITS = AxisLimits(max_velocity=1.0, max_acceleration=5.0, max_jerk=50.0)
POSITION = Request.POSITION


class MemoryDrive(ActuatorDevice):
    """A driver that is wherever it was last told to be."""

    info = DeviceInfo(kind=DeviceKind.MOTOR, vendor_name="Bench", product_name="MemoryDrive")
    limits = ActuatorLimits(position=(-10.0, 10.0))
    reports_completion = True  # no completion-detection task: only the group runs

    def __init__(self) -> None:
        self.position = 0.0

    async def command(self, request: Request, value: float) -> None:
        self.position = value

    async def read(self, request: Request) -> float:
        return self.position


@dataclass(frozen=True, slots=True)
class SizeResult:
    axes: int
    ours_ns: list[int]
    """Group tick cost, every tick of every round."""
    checked_ns: list[int]
    """Group tick cost with a path tolerance (reads POSITION_ACTUAL every tick)."""
    naive_ns: list[int]
    ruckig_ns: list[int]
    planning_ns: list[int]

    @staticmethod
    def mean_us(values: list[int]) -> float:
        return statistics.fmean(values) / 1e3 if values else float("nan")

    @staticmethod
    def p50_us(values: list[int]) -> float:
        return percentile(sorted(values), 50) / 1e3

    @staticmethod
    def p99_us(values: list[int]) -> float:
        return percentile(sorted(values), 99) / 1e3


def _targets(axes: int, rng: random.Random, sign: float) -> list[float]:
    # Distances from 0.2 to 1.8: the move takes about 2 s at the limits.
    return [sign * rng.uniform(0.2, 1.8) for _ in range(axes)]


async def _move_ticks(group: AxisGroup, targets: list[float], ticks: int) -> list[int]:
    """Run one move (stopped after ``ticks`` ticks if longer) and return its tick costs."""
    group.reset_stats()
    motion = await group.move_to(targets)
    clock = group.timer.clock
    end = motion.start_ns + ticks * PERIOD_MS * 1_000_000
    while not motion.done() and clock.now_ns() < end:
        await clock.sleep_until(min(end, motion.planned_end_ns + 5_000_000))
    if not motion.done():
        group.hold()
    return group.tick_costs_ns()


async def _naive_ticks(actuators: list[Actuator], targets: list[float], ticks: int) -> list[int]:
    perf = time.perf_counter_ns
    start = [await a.get_value(POSITION) for a in actuators]
    costs: list[int] = []
    n = len(actuators)
    for k in range(1, ticks + 1):
        t0 = perf()
        s = k / ticks
        for i in range(n):
            p0 = start[i]
            await actuators[i].set_value(p0 + (targets[i] - p0) * s, POSITION)
        costs.append(perf() - t0)
        await anyio.lowlevel.checkpoint()
    return costs


def _ruckig_alone(
    axes: int, start: list[float], targets: list[float], ticks: int
) -> tuple[list[int], int]:
    perf = time.perf_counter_ns
    planner = Planner(axes, [(-10.0, 10.0)] * axes, [float("inf")] * axes)
    zeros = [0.0] * axes
    state = KinematicState(start, zeros, list(zeros))
    limits = [LIMITS] * axes
    plannings: list[int] = []
    for _ in range(PLANNING_REPEATS):
        t0 = perf()
        plan = planner.move(0, state, targets, limits)
        plannings.append(perf() - t0)
    planning = int(statistics.median(plannings))
    costs: list[int] = []
    period = PERIOD_MS * 1_000_000
    for k in range(1, ticks + 1):
        t0 = perf()
        plan.sample(k * period)
        costs.append(perf() - t0)
    return costs, planning


async def measure_size(axes: int, ticks: int, rounds: int) -> SizeResult:
    rng = random.Random(axes)
    clock = VirtualClock()
    ours: list[int] = []
    checked: list[int] = []
    naive: list[int] = []
    ruckig: list[int] = []
    planning: list[int] = []
    async with clock.autojump():
        actuators = [Actuator(MemoryDrive(), clock=clock) for _ in range(axes)]
        for actuator in actuators:
            await actuator.__aenter__()
        try:
            async with (
                EventTimer(PERIOD_MS, clock=clock) as timer,
                AxisGroup(actuators, timer=timer, limits=LIMITS, log_capacity=10_000) as group,
            ):
                sign = 1.0
                for _ in range(rounds):
                    gc.collect()
                    start = [await a.get_value(POSITION) for a in actuators]
                    targets = _targets(axes, rng, sign)
                    ours += await _move_ticks(group, targets, ticks)
                    costs, plan_ns = _ruckig_alone(axes, start, targets, ticks)
                    ruckig += costs
                    planning.append(plan_ns)
                    back = _targets(axes, rng, -sign)
                    naive += await _naive_ticks(actuators, back, ticks)
                    # With a path check: every axis' POSITION_ACTUAL read every tick.
                    group.tolerances = Tolerances(goal=1e-3, path=0.1)
                    checked += await _move_ticks(group, targets, ticks)
                    group.tolerances = Tolerances()
                    sign = -sign
        finally:
            for actuator in reversed(actuators):
                await actuator.__aexit__(None, None, None)
    return SizeResult(axes, ours, checked, naive, ruckig, planning)


@dataclass(frozen=True, slots=True)
class RealRun:
    seconds: float
    cpu_seconds: float
    ticks: int
    timer_missed: int
    group_skipped: int
    tick_mean_us: float
    tick_p99_us: float

    @property
    def cores(self) -> float:
        return self.cpu_seconds / self.seconds


async def measure_real(axes: int, seconds: float) -> RealRun:
    rng = random.Random(7)
    clock = MonotonicClock()
    actuators = [Actuator(MemoryDrive(), clock=clock) for _ in range(axes)]
    for actuator in actuators:
        await actuator.__aenter__()
    try:
        async with (
            EventTimer(PERIOD_MS, clock=clock, name="bench") as timer,
            AxisGroup(actuators, timer=timer, limits=LIMITS) as group,
        ):
            await anyio.sleep(0.05)
            timer.reset_stats()
            group.reset_stats()
            sign = 1.0
            wall0, cpu0 = time.perf_counter(), time.process_time()
            deadline = wall0 + seconds
            while time.perf_counter() < deadline:
                motion = await group.move_to(_targets(axes, rng, sign))
                with anyio.move_on_after(max(0.0, deadline - time.perf_counter())):
                    await motion
                sign = -sign
            wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
            group.hold()
            stats, timer_stats = group.stats, timer.stats
    finally:
        for actuator in reversed(actuators):
            await actuator.__aexit__(None, None, None)
    return RealRun(
        seconds=wall,
        cpu_seconds=cpu,
        ticks=stats.ticks,
        timer_missed=timer_stats.missed_ticks,
        group_skipped=stats.skipped_ticks,
        tick_mean_us=stats.tick_cost.mean_ns / 1e3,
        tick_p99_us=stats.tick_cost.p99_ns / 1e3,
    )


def run(quick: bool) -> BenchResult:
    ticks = QUICK_TICKS if quick else TICKS
    rounds = QUICK_ROUNDS if quick else ROUNDS
    results = [anyio.run(measure_size, n, ticks, rounds, backend="asyncio") for n in SIZES]
    real = anyio.run(
        measure_real, TARGET_AXES, QUICK_REAL_SECONDS if quick else REAL_SECONDS, backend="asyncio"
    )
    rows: list[Row] = []
    notes: list[str] = []
    target = results[SIZES.index(TARGET_AXES)]
    for r in results:
        mean, naive = r.mean_us(r.ours_ns), r.mean_us(r.naive_ns)
        is_target = r.axes == TARGET_AXES
        rows.append(
            Row(
                f"tick cost, {r.axes} axes (mean)",
                mean,
                "µs",
                baseline=naive,
                baseline_label="naive stream loop",
                ratio=ratio_of(mean, naive),
                ratio_label="ours/naive",
                target=f"< {TARGET_US:.0f} µs" if is_target else "",
                passed=mean < TARGET_US if is_target else None,
            )
        )
    for r in results:
        med, naive = r.p50_us(r.ours_ns), r.p50_us(r.naive_ns)
        rows.append(
            Row(
                f"tick cost, {r.axes} axes (median)",
                med,
                "µs",
                baseline=naive,
                baseline_label="naive stream loop",
                ratio=ratio_of(med, naive),
                ratio_label="ours/naive",
            )
        )
    rows.append(
        Row(
            f"tick cost, {TARGET_AXES} axes (p99)",
            target.p99_us(target.ours_ns),
            "µs",
            baseline=target.p99_us(target.naive_ns),
            baseline_label="naive stream loop",
            ratio=ratio_of(target.p99_us(target.ours_ns), target.p99_us(target.naive_ns)),
            ratio_label="ours/naive",
        )
    )
    for r in results:
        ruck, med = r.p50_us(r.ruckig_ns), r.p50_us(r.ours_ns)
        rows.append(
            Row(
                f"ruckig sampling alone, {r.axes} axes (median)",
                ruck,
                "µs",
                baseline=med,
                baseline_label="group tick",
                ratio=ratio_of(ruck, med),
                ratio_label="share of the tick",
                digits=2,
            )
        )
    checked, unchecked = target.p50_us(target.checked_ns), target.p50_us(target.ours_ns)
    rows.append(
        Row(
            f"tick cost with path check, {TARGET_AXES} axes (median)",
            checked,
            "µs",
            baseline=unchecked,
            baseline_label="no path check",
            ratio=ratio_of(checked, unchecked),
            ratio_label="checked/unchecked",
        )
    )
    for r in results:
        rows.append(
            Row(
                f"planning a move (Planner.move), {r.axes} axes (median)",
                statistics.median(r.planning_ns) / 1e3,
                "µs",
            )
        )
    rows.append(
        Row(
            f"real clock, {TARGET_AXES} axes at 1 kHz: CPU per wall second",
            real.cores,
            "cores",
            target="< 0.5 core",
            passed=real.cores < 0.5,
            digits=3,
        )
    )
    virtual_mean = target.mean_us(target.ours_ns)
    rows.append(
        Row(
            f"real clock, {TARGET_AXES} axes at 1 kHz: tick cost (mean)",
            real.tick_mean_us,
            "µs",
            baseline=virtual_mean,
            baseline_label="virtual clock",
            ratio=ratio_of(real.tick_mean_us, virtual_mean),
            ratio_label="real/virtual",
        )
    )
    per_axis_naive = target.mean_us(target.naive_ns) / TARGET_AXES
    per_axis_ours = target.mean_us(target.ours_ns) / TARGET_AXES
    notes.append(
        f"Per axis and tick at {TARGET_AXES} axes: {per_axis_ours:.2f} µs in the group, "
        f"{per_axis_naive:.2f} µs in the naive loop (almost all of it one "
        "`Actuator.set_value` call); ruckig's sampling is "
        f"{target.mean_us(target.ruckig_ns) / TARGET_AXES:.3f} µs per axis."
    )
    notes.append(
        f"Real clock: {real.ticks} ticks in {real.seconds:.1f} s, {real.cpu_seconds:.2f} s "
        f"of CPU; the timer skipped {real.timer_missed} period(s), the group "
        f"{real.group_skipped} tick(s); tick p99 {real.tick_p99_us:.0f} µs."
    )
    biggest = results[-1]
    budget_axes = int(1000.0 / (biggest.mean_us(biggest.ours_ns) / biggest.axes))
    notes.append(
        f"At {biggest.axes} axes a tick costs {biggest.mean_us(biggest.ours_ns):.0f} µs: "
        f"a 1 ms period (the event loop is one thread) has room for about {budget_axes} "
        "axes at this cost, with nothing else running."
    )
    if real.tick_mean_us > 1.1 * virtual_mean:
        notes.append(
            "Real-clock ticks cost more than the back-to-back ticks of the virtual clock: "
            "between two ticks the loop sleeps and other processes run (see the load "
            "average below), so a tick likely starts with cold caches, or is preempted."
        )
    notes.append(
        "Means and p99 include the machine's noise (other processes preempting a tick, "
        "garbage collections); the medians compare the group and the baseline best."
    )
    if not all(row.passed is not False for row in rows):
        notes.append(f"Target missed: see where the time goes with `{COMMAND} {NAME} --profile`.")
    return BenchResult(
        name=NAME,
        title="AxisGroup tick cost (ruckig + streaming setpoints) vs a naive streaming loop",
        rows=tuple(rows),
        description=DESCRIPTION,
        notes=tuple(notes),
        params={
            "axes": ", ".join(str(n) for n in SIZES),
            "period": f"{PERIOD_MS} ms",
            "ticks per move": str(ticks),
            "rounds": str(rounds),
            "limits": f"v {LIMITS.max_velocity}, a {LIMITS.max_acceleration}, j {LIMITS.max_jerk}",
            "real-clock run": f"{QUICK_REAL_SECONDS if quick else REAL_SECONDS} s",
        },
    )


DESCRIPTION = """\
Per-tick wall time of an `AxisGroup` over N `Actuator`s on an in-memory driver
(`command` stores the value, `read` returns it; the driver reports completion, so no
detection task runs), to isolate the group's own cost from any driver's. Each round
runs a real move (random distances 0.2-1.8, about 2 s at v 1, a 5, j 50) on an
`EventTimer(1 ms)` over a `VirtualClock`, and the group times each tick itself
(`AxisGroup.stats.tick_cost`): sampling the ruckig trajectory, one
`await actuator.set_value(p, POSITION)` per axis, and the trajectory-log row.

- **Baseline (naive stream loop)**, same actuators, same run: per tick, linear
  interpolation of every axis in Python and `await set_value` for each, timed the same
  way; no ruckig, no checks, no log. The ratio ours/naive is what the group costs
  over the bare streaming through the public Actuator API.
- **Ruckig alone**: `Plan.sample` (`Trajectory.at_time`) of the same move at the same
  tick times; its ratio to the group's tick is ruckig's share.
- **With path check**: the same move with a path tolerance, which reads every axis'
  `POSITION_ACTUAL` with `get_value` every tick.
- **Real clock**: 64 axes on `MonotonicClock` at 1 kHz, back-and-forth moves; CPU time
  of the process per wall second (timer, event loop and group) and skipped ticks."""
