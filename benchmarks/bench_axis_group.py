"""Per-tick cost of an AxisGroup against ruckig called directly, for 6, 64 and 256 axes.

Peer (what a user would write instead of the group): the same move planned with
``ruckig.Ruckig(N).calculate`` from the same inputs (start state, targets, limits,
phase synchronization), then at every tick ``Trajectory.at_time(t)`` and the N
positions stored into a list one by one (the setpoints a loop would hand to N devices).

Ours: an ``AxisGroup`` over N ``Actuator``s on an in-memory driver (``command`` /
``command_nowait`` store the value, ``read`` returns it; completion reported by the
driver, so no detection task runs) running the same move on an ``EventTimer(1 ms)``
over a ``VirtualClock``. The group times each tick itself (``AxisGroup.tick_costs_ns``:
sampling the plan, the trajectory-log row, validating and streaming the batch of N
setpoints). Rounds alternate ours and the peer; the figures are medians over every
tick of every round.

A last, real-clock run drives 64 axes at 1 kHz on a ``MonotonicClock`` for a few
seconds and reports the process CPU time per wall second (timer, event loop and group
together) and the ticks the timer or the group had to skip.
"""

from __future__ import annotations

import gc
import random
import time
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass
from typing import cast

import anyio
from ruckig import InputParameter, Ruckig, Synchronization, Trajectory

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
from openel_async.clock import Clock
from openel_async.component import STATE_CHANGES
from openel_async.device import LIMITS_CHANGES, AsyncBatchCommander, BatchCommander
from openel_async.motion import AxisGroup, AxisLimits, Tolerances
from openel_async.stats import percentile

from .harness import COMMAND, BenchResult, Row, median, ratio_of

NAME = "axis_group"
SIZES = (6, 64, 256)
TARGETS = {6: 1.5, 64: 1.3}
"""Axes -> the largest ours/peer ratio of the median tick allowed (issue 27)."""
ASYNC_TARGETS = {64: 4.0}
"""Axes -> the same over drivers without a synchronous path (issue 27)."""
REAL_AXES = 64
PERIOD_MS = 1
TICKS = 2_000
QUICK_TICKS = 300
ROUNDS = 5
QUICK_ROUNDS = 5
REAL_SECONDS = 4.0
QUICK_REAL_SECONDS = 1.5
LIMITS = AxisLimits(max_velocity=1.0, max_acceleration=5.0, max_jerk=50.0)
POSITION = Request.POSITION


class MemoryDrive(ActuatorDevice):
    """A driver that is wherever it was last told to be (a simulation: no I/O)."""

    info = DeviceInfo(kind=DeviceKind.MOTOR, vendor_name="Bench", product_name="MemoryDrive")
    limits = ActuatorLimits(position=(-10.0, 10.0))
    reports_completion = True  # no completion-detection task: only the group runs

    def __init__(self) -> None:
        self.position = 0.0

    async def command(self, request: Request, value: float) -> None:
        self.position = value

    def command_nowait(self, request: Request, value: float) -> None:
        self.position = value

    async def read(self, request: Request) -> float:
        return self.position

    def read_nowait(self, request: Request) -> float:
        return self.position

    @classmethod
    def batch_commander(cls, devices: Sequence[ActuatorDevice]) -> BatchCommander | None:
        """Every drive told its value in one call, as a driver with a batch path does."""
        drives = tuple(cast(MemoryDrive, d) for d in devices)

        def command_all(request: Request, values: Sequence[float]) -> bool:
            for drive, value in zip(drives, values, strict=True):
                drive.position = value
            return True

        return command_all


class AsyncEachDrive(MemoryDrive):
    """The same without a synchronous path and without a batch command: one awaited
    ``command`` per axis and tick."""

    info = DeviceInfo(kind=DeviceKind.MOTOR, vendor_name="Bench", product_name="AsyncEach")

    async def command(self, request: Request, value: float) -> None:
        self.position = value


class AsyncMemoryDrive(AsyncEachDrive):
    """Without a synchronous path, with an awaited batch command: what a bus driver with
    one write for every drive (a SYNC WRITE, a CAN SYNC cycle) looks like to the group."""

    info = DeviceInfo(kind=DeviceKind.MOTOR, vendor_name="Bench", product_name="AsyncMemory")

    @classmethod
    def async_batch_commander(cls, devices: Sequence[ActuatorDevice]) -> AsyncBatchCommander:
        drives = tuple(cast(MemoryDrive, d) for d in devices)

        async def command_all(request: Request, values: Sequence[float], /) -> bool:
            for drive, value in zip(drives, values, strict=True):
                drive.position = value
            return True

        return command_all


@dataclass(frozen=True, slots=True)
class SizeResult:
    axes: int
    ours_ns: list[list[int]]
    """Per round, the group's tick costs."""
    peer_ns: list[list[int]]
    checked_ns: list[list[int]]
    """Group tick with a path tolerance (reads POSITION_ACTUAL every tick)."""
    async_ns: list[list[int]]
    """Group tick over drivers without a synchronous command path (an awaited batch)."""
    each_ns: list[list[int]]
    """The same, one awaited command per axis."""
    floor_ns: list[list[int]]
    """The least a tick of the group's shape costs in Python (:func:`floor_ticks`)."""
    floor_loop_ns: list[list[int]]
    """The same tick called by the group's EventTimer (:func:`floor_loop_ticks`)."""
    fused_loop_ns: list[list[int]]
    """The floor with the group's per-tick work fused in, called the same way (:func:`_fused_tick`)."""

    @staticmethod
    def median_us(rounds: list[list[int]]) -> float:
        """The median over the rounds of each round's median tick."""
        return median([percentile(sorted(r), 50) for r in rounds]) / 1e3

    @staticmethod
    def p99_us(rounds: list[list[int]]) -> float:
        return percentile(sorted(v for r in rounds for v in r), 99) / 1e3

    @staticmethod
    def ticks(rounds: list[list[int]]) -> int:
        return sum(len(r) for r in rounds)


def _targets(axes: int, rng: random.Random, sign: float) -> list[float]:
    # Distances from 0.2 to 1.8: the move takes about 2 s at the limits.
    return [sign * rng.uniform(0.2, 1.8) for _ in range(axes)]


async def _move_ticks(group: AxisGroup, targets: list[float], ticks: int) -> list[int]:
    """Run one move (held after ``ticks`` ticks if longer) and return its tick costs."""
    group.reset_stats()
    motion = await group.move_to(targets)
    clock = group.timer.clock
    end = motion.start_ns + ticks * PERIOD_MS * 1_000_000
    while not motion.done() and clock.now_ns() < end:
        await clock.sleep_until(min(end, motion.planned_end_ns + 5_000_000))
    if not motion.done():
        group.hold()
    return group.tick_costs_ns()


def _trajectory(start: list[float], targets: list[float]) -> Trajectory:
    """ruckig's plan of the group's move (the same inputs)."""
    n = len(start)
    inp = InputParameter(n)
    inp.current_position = start
    inp.current_velocity = [0.0] * n
    inp.current_acceleration = [0.0] * n
    inp.target_position = targets
    inp.max_velocity = [LIMITS.max_velocity] * n
    inp.max_acceleration = [LIMITS.max_acceleration] * n
    inp.max_jerk = [LIMITS.max_jerk] * n
    inp.synchronization = Synchronization.Phase
    trajectory = Trajectory(n)
    Ruckig(n).calculate(inp, trajectory)
    return trajectory


def _floor_tick(start: list[float], targets: list[float]) -> tuple[Callable[[float], None], int]:
    """The floor's tick function (see :func:`floor_ticks`) and its number of ticks."""
    trajectory = _trajectory(start, targets)
    drives = [MemoryDrive() for _ in start]
    at_time = trajectory.at_time
    kept: list[list[float]] = [[]]

    def tick(t_s: float) -> None:
        position, _, _ = at_time(t_s)
        for drive, value in zip(drives, position):  # noqa: B905 (as the drive's batch)
            drive.position = value
        kept[0] = position

    return tick, int(trajectory.duration / (PERIOD_MS / 1000)) + 1


class _FusedState:
    """What the fused floor keeps between ticks (see :func:`_fused_tick`)."""

    __slots__ = ("active_at", "built", "commanded", "count", "limits_at", "stamp", "targets")

    def __init__(self, axes: int) -> None:
        self.count = 0
        self.active_at = STATE_CHANGES.value
        self.limits_at = LIMITS_CHANGES.value
        self.targets = [0.0] * axes
        self.stamp = 0
        self.built: list[object] = []
        self.commanded: list[float] = []


def _fused_tick(
    start: list[float], targets: list[float], clock: Clock
) -> tuple[Callable[[float], None], int]:
    """The floor with the per-tick work the group must do, fused into one function by hand
    (no layer between the group, the bank and the stream bookkeeping): ruckig's ``at_time``,
    the trajectory-log row (a tuple into a preallocated ring), the limits-changed and
    Active checks (two counter compares), the command stamp (the clock's ``now_ns``), one
    call of the drive's batch command (N stores, as ``MemoryDrive.batch_commander``), the
    stream's record of the batch (the targets copied, the stamp, the Motions built since
    the last batch) and the commanded setpoints kept.  What any implementation of the
    group's features costs in Python at the least: a lower bound for the group's tick."""
    trajectory = _trajectory(start, targets)
    drives = [MemoryDrive() for _ in start]
    batch = MemoryDrive.batch_commander(drives)
    assert batch is not None
    at_time = trajectory.at_time
    capacity = 10_000
    planned: list[tuple[int, int, object] | None] = [None] * capacity
    state = _FusedState(len(start))
    now_ns = clock.now_ns
    plan = object()

    def tick(t_s: float) -> None:
        position: list[float] = at_time(t_s)[0]
        count = state.count
        state.count = count + 1
        planned[count % capacity] = (count, 1, plan)
        if state.limits_at != LIMITS_CHANGES.value or state.active_at != STATE_CHANGES.value:
            raise RuntimeError("the bench changed a device's limits or state mid-move")
        stamp = now_ns()
        batch(POSITION, position)
        state.targets[:] = position
        state.stamp = stamp
        if state.built:
            raise RuntimeError("no Motion is built during the bench's moves")
        state.commanded = position

    return tick, int(trajectory.duration / (PERIOD_MS / 1000)) + 1


def floor_ticks(start: list[float], targets: list[float], ticks: int) -> list[int]:
    """The least a tick of the group's shape can do in Python: one call into a tick
    function, ruckig's ``at_time``, the N setpoints stored into N drive objects (where the
    peer stores them into one list) and the setpoints kept; no check, stamp or log."""
    tick, count = _floor_tick(start, targets)
    perf = time.perf_counter_ns
    costs: list[int] = []
    period_s = PERIOD_MS / 1000
    last = min(ticks, count)
    for k in range(1, last + 1):
        t0 = perf()
        tick(k * period_s)
        costs.append(perf() - t0)
    return costs


async def floor_loop_ticks(
    timer: EventTimer, start: list[float], targets: list[float], ticks: int, fused: bool = False
) -> list[int]:
    """:func:`floor_ticks` in the group's conditions: the same tick function called by a
    plain observer of the group's own EventTimer, between event-loop passes (as the group's
    tick is), timed the same way; what the loop around a tick costs the tick itself (cold
    caches), which the peer's back-to-back loop never pays.  ``fused``: the tick of
    :func:`_fused_tick` (the floor plus the group's per-tick work, fused by hand)."""
    tick, count = _fused_tick(start, targets, timer.clock) if fused else _floor_tick(start, targets)
    last = min(ticks, count)
    perf = time.perf_counter_ns
    costs: list[int] = []
    period_s = PERIOD_MS / 1000
    done = anyio.Event()

    def observe(_timer: EventTimer) -> None:
        k = len(costs) + 1
        if k > last:
            done.set()
            return
        t0 = perf()
        tick(k * period_s)
        costs.append(perf() - t0)

    timer.add_observer(observe)
    try:
        await done.wait()
    finally:
        timer.remove_observer(observe)
    return costs


def peer_ticks(start: list[float], targets: list[float], ticks: int) -> list[int]:
    """The peer: ruckig called directly with the group's inputs, setpoints stored in a list."""
    n = len(start)
    trajectory = _trajectory(start, targets)
    setpoints = [0.0] * n
    at_time = trajectory.at_time
    perf = time.perf_counter_ns
    costs: list[int] = []
    period_s = PERIOD_MS / 1000
    last = min(ticks, int(trajectory.duration / period_s) + 1)
    for k in range(1, last + 1):
        t0 = perf()
        position, _, _ = at_time(k * period_s)
        for i in range(n):
            setpoints[i] = position[i]
        costs.append(perf() - t0)
    assert setpoints[0] == position[0]
    return costs


async def _with_group(
    drive: type[MemoryDrive],
    axes: int,
    body: Callable[[AxisGroup], Awaitable[None]],
    clock: Clock | None = None,
) -> None:
    """``body(group)`` with a group of ``axes`` actuators on ``drive`` over its own timer,
    on ``clock`` (None: a new VirtualClock in auto-jump)."""
    if clock is None:
        virtual = VirtualClock()
        async with virtual.autojump():
            await _with_group(drive, axes, body, virtual)
        return
    actuators = [Actuator(drive(), clock=clock) for _ in range(axes)]
    for actuator in actuators:
        await actuator.__aenter__()
    try:
        async with (
            EventTimer(PERIOD_MS, clock=clock) as timer,
            AxisGroup(actuators, timer=timer, limits=LIMITS, log_capacity=10_000) as group,
        ):
            await body(group)
    finally:
        for actuator in reversed(actuators):
            await actuator.__aexit__(None, None, None)


async def measure_size(axes: int, ticks: int, rounds: int) -> SizeResult:
    """``rounds`` rounds, each: a move of the group over synchronous drivers, the peer on
    the same inputs, a move with a path check, and a move of a second group over drivers
    without a synchronous path (both groups open side by side, so the rounds interleave)."""
    rng = random.Random(axes)
    ours: list[list[int]] = []
    peer: list[list[int]] = []
    checked: list[list[int]] = []
    slow: list[list[int]] = []
    each: list[list[int]] = []
    floor: list[list[int]] = []
    floor_loop: list[list[int]] = []
    fused_loop: list[list[int]] = []

    async def body(group: AxisGroup, slow_group: AxisGroup, each_group: AxisGroup) -> None:
        sign = 1.0
        for _ in range(rounds):  # alternate ours and the peer, same inputs
            gc.collect()
            start = [await a.get_value(POSITION) for a in group.axes]
            targets = _targets(axes, rng, sign)
            ours.append(await _move_ticks(group, targets, ticks))
            gc.collect()
            peer.append(peer_ticks(start, targets, ticks))
            gc.collect()
            floor.append(floor_ticks(start, targets, ticks))
            gc.collect()
            floor_loop.append(await floor_loop_ticks(group.timer, start, targets, ticks))
            gc.collect()
            fused_loop.append(await floor_loop_ticks(group.timer, start, targets, ticks, True))
            # Back with a path check: every axis' POSITION_ACTUAL read every tick.
            group.tolerances = Tolerances(goal=1e-3, path=0.1)
            checked.append(await _move_ticks(group, _targets(axes, rng, -sign), ticks))
            group.tolerances = Tolerances()
            gc.collect()
            slow.append(await _move_ticks(slow_group, _targets(axes, rng, sign), ticks))
            gc.collect()
            each.append(await _move_ticks(each_group, _targets(axes, rng, sign), ticks))
            sign = -sign

    async def outer(group: AxisGroup) -> None:
        clock = group.timer.clock

        async def inner(slow_group: AxisGroup) -> None:
            async def innermost(each_group: AxisGroup) -> None:
                await body(group, slow_group, each_group)

            await _with_group(AsyncEachDrive, axes, innermost, clock=clock)

        await _with_group(AsyncMemoryDrive, axes, inner, clock=clock)

    await _with_group(MemoryDrive, axes, outer)
    return SizeResult(axes, ours, peer, checked, slow, each, floor, floor_loop, fused_loop)


@dataclass(frozen=True, slots=True)
class RealRun:
    seconds: float
    cpu_seconds: float
    ticks: int
    timer_missed: int
    group_skipped: int
    tick_median_us: float
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
        tick_median_us=stats.tick_cost.p50_ns / 1e3,
        tick_p99_us=stats.tick_cost.p99_ns / 1e3,
    )


def run(quick: bool) -> BenchResult:
    ticks = QUICK_TICKS if quick else TICKS
    rounds = QUICK_ROUNDS if quick else ROUNDS
    results = [anyio.run(measure_size, n, ticks, rounds, backend="asyncio") for n in SIZES]
    real_s = QUICK_REAL_SECONDS if quick else REAL_SECONDS
    real_runs = []
    for _ in range(rounds):  # the real-clock run in rounds too: its row is their median
        gc.collect()
        real_runs.append(anyio.run(measure_real, REAL_AXES, real_s / rounds, backend="asyncio"))
    real = RealRun(
        seconds=sum(r.seconds for r in real_runs),
        cpu_seconds=sum(r.cpu_seconds for r in real_runs),
        ticks=sum(r.ticks for r in real_runs),
        timer_missed=sum(r.timer_missed for r in real_runs),
        group_skipped=sum(r.group_skipped for r in real_runs),
        tick_median_us=median([r.tick_median_us for r in real_runs]),
        tick_p99_us=max(r.tick_p99_us for r in real_runs),
    )
    real_cores = median([r.cores for r in real_runs])
    rows: list[Row] = []
    notes: list[str] = []
    for r in results:
        ours, peer = r.median_us(r.ours_ns), r.median_us(r.peer_ns)
        ratio = ratio_of(ours, peer)
        limit = TARGETS.get(r.axes)
        rows.append(
            Row(
                f"tick, {r.axes} axes (median)",
                ours,
                "µs",
                baseline=peer,
                baseline_label="ruckig at_time + stores",
                ratio=ratio,
                ratio_label="ours/ruckig",
                target=f"<= {limit:g}x ruckig" if limit is not None else "",
                passed=ratio <= limit if limit is not None else None,
                digits=2,
            )
        )
    floors: tuple[tuple[str, Callable[[SizeResult], list[list[int]]]], ...] = (
        ("floor: one call, at_time, {n} stores into {n} drives (median)", lambda r: r.floor_ns),
        ("floor called by the group's EventTimer, {n} axes (median)", lambda r: r.floor_loop_ns),
        (
            "floor with the group's per-tick work, fused, called by its EventTimer, {n} axes (median)",
            lambda r: r.fused_loop_ns,
        ),
    )
    for label, costs in floors:
        for r in results:
            floor, peer = r.median_us(costs(r)), r.median_us(r.peer_ns)
            rows.append(
                Row(
                    label.format(n=r.axes),
                    floor,
                    "µs",
                    baseline=peer,
                    baseline_label="ruckig at_time + stores",
                    ratio=ratio_of(floor, peer),
                    ratio_label="floor/ruckig",
                    digits=2,
                )
            )
    for r in results:
        rows.append(
            Row(
                f"tick, {r.axes} axes (p99)",
                r.p99_us(r.ours_ns),
                "µs",
                baseline=r.p99_us(r.peer_ns),
                baseline_label="ruckig at_time + stores",
                ratio=ratio_of(r.p99_us(r.ours_ns), r.p99_us(r.peer_ns)),
                ratio_label="ours/ruckig",
                digits=2,
            )
        )
    for r in results:
        checked, peer = r.median_us(r.checked_ns), r.median_us(r.peer_ns)
        rows.append(
            Row(
                f"tick with path check, {r.axes} axes (median)",
                checked,
                "µs",
                baseline=peer,
                baseline_label="ruckig at_time + stores",
                ratio=ratio_of(checked, peer),
                ratio_label="ours/ruckig",
                digits=2,
            )
        )
    for r in results:
        slow, peer = r.median_us(r.async_ns), r.median_us(r.peer_ns)
        ratio = ratio_of(slow, peer)
        limit = ASYNC_TARGETS.get(r.axes)
        rows.append(
            Row(
                f"tick over async-only drivers, awaited batch, {r.axes} axes (median)",
                slow,
                "µs",
                baseline=peer,
                baseline_label="ruckig at_time + stores",
                ratio=ratio,
                ratio_label="ours/ruckig",
                target=f"<= {limit:g}x ruckig" if limit is not None else "",
                passed=ratio <= limit if limit is not None else None,
                digits=2,
            )
        )
    for r in results:
        each, peer = r.median_us(r.each_ns), r.median_us(r.peer_ns)
        rows.append(
            Row(
                f"tick over async-only drivers, one command per axis, {r.axes} axes (median)",
                each,
                "µs",
                baseline=peer,
                baseline_label="ruckig at_time + stores",
                ratio=ratio_of(each, peer),
                ratio_label="ours/ruckig",
                digits=2,
            )
        )
    rows.append(
        Row(
            f"real clock, {REAL_AXES} axes at 1 kHz: CPU per wall second",
            real_cores,
            "cores",
            target="< 0.5 core",
            passed=real_cores < 0.5,
            digits=3,
        )
    )
    notes.append(
        f"Real clock ({rounds} rounds; CPU per wall second: the median of the rounds'): "
        f"{real.ticks} ticks in {real.seconds:.1f} s, {real.cpu_seconds:.2f} s "
        f"of CPU; the timer skipped {real.timer_missed} period(s), the group "
        f"{real.group_skipped} tick(s); group tick median {real.tick_median_us:.1f} µs, "
        f"largest round p99 {real.tick_p99_us:.0f} µs."
    )
    for r in results:
        notes.append(
            f"{r.axes} axes: {r.ticks(r.ours_ns):,} group ticks and {r.ticks(r.peer_ns):,} peer "
            f"ticks over {rounds} interleaved rounds (figures: the median of the rounds' "
            f"medians); per axis and tick {r.median_us(r.ours_ns) / r.axes * 1e3:.0f} ns "
            f"in the group, {r.median_us(r.peer_ns) / r.axes * 1e3:.0f} ns in the peer."
        )
    notes.append(
        "p99 includes the machine's noise (other processes preempting a tick, garbage "
        "collections); the medians compare the group and the peer best."
    )
    if not all(row.passed is not False for row in rows):
        notes.append(f"Target missed: see where the time goes with `{COMMAND} {NAME} --profile`.")
    return BenchResult(
        name=NAME,
        title="AxisGroup tick vs ruckig called directly (same inputs, setpoints stored in a list)",
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
**Peer: ruckig called directly**, what one would write without the group: the same move
planned with `Ruckig(N).calculate` from the same inputs (start positions at rest,
targets, limits v 1, a 5, j 50, phase synchronization), then at every 1 ms tick
`position, _, _ = trajectory.at_time(t)` and the N positions stored one by one into a
list (`setpoints[i] = position[i]`), timed with `perf_counter_ns` around those two steps.

**Ours**: an `AxisGroup` over N `Actuator`s on an in-memory driver with a synchronous
path (`command_nowait` stores the value, as a simulation does; the driver reports
completion, so no detection task runs) runs the same move on an `EventTimer(1 ms)` over
a `VirtualClock`; the group times each tick itself (`AxisGroup.tick_costs_ns()`):
sampling the plan (ruckig `at_time` plus the end-error blend), the trajectory-log row,
and one validated batch of N setpoints. The batch is validated by proof: when the move
is planned, the exact position range of the whole trajectory (every phase's ends and
velocity zeros, `planner.trajectory_range`) is checked once against every device's limits
(those the bank read when it was built and the current ones); the tick then sends through
`ActuatorBank.position_stream`, which still checks every axis Active before each batch
(`component.STATE_CHANGES`); a path that cannot be proven (e.g. one ending on a limit) is
checked value by value through `set_values_nowait` as before. The drive offers a batch
command (`MemoryDrive.batch_commander`: one call storing every drive's value, as
`SimMotor`'s and `MujocoJoint`'s do), so the bank records the tick's targets once
(`StreamBatch`) and each actuator settles its sequence, commanded value and `Motion` from
them only when something reads them; no `Motion` per axis and tick.
Neither side includes the timer waking the task.

Rounds alternate ours and the peer; figures are medians over every tick of every round.
Informational rows: the group with a path tolerance (every axis' `POSITION_ACTUAL` read
every tick), the group over drivers without a synchronous path (one awaited `command`
per axis, as on a bus), and a real-clock run (64 axes at 1 kHz on `MonotonicClock`: CPU
of the whole process per wall second).

**Profile (cProfile, 64 axes, 2,000 ticks, tottime).** When the issue was filed (one
`await actuator.set_value()` per axis and tick, a `Motion` built and superseded each
time): 15x / 26x the peer at 6 / 64 axes; 3.7 M calls, 4.6 s; `Actuator._accept` 0.82 s,
`_send_now` 0.49, `_check_target` 0.31, `set_value` 0.31, `_validate` 0.30. One bank
batch per tick, device by device (`stream_targets`): 7.07x / 5.75x, `stream_targets`
(sequence, `_sync_send`, `command_nowait`, the lazy-Motion tuple, the commanded value,
the listener, per axis) 0.091 s of 0.27 s profiled. Then (the drive's batch command, the
bookkeeping per batch): `stream_targets` gone from the profile; left per tick were the
limit check (`ActuatorBank._in_limits`), the drive's batch (64 stores), `Plan.positions`
(ruckig `at_time`) and the event loop around the tick; the limit check is now made once
per motion (below).

**Where the time goes (6 axes, warm micro-timing of the parts with `timeit`).** Before
this pass (tick 2.06 µs against the peer's 0.52 in the last full run, 3.96x):
`Plan.positions` 0.39 (ruckig `at_time` 0.33), the log row 0.14, `set_values_nowait`
~1.1-1.2 µs (per-value checks: the type tuple, `sum` for finiteness, `min`/`max` against
the range ~0.42; the drive's batch 0.30; `StreamBatch.accept` 0.09; the Active check),
plus the calls between them. Now one closure per motion (`AxisGroup._proven_tick`) runs
the tick: the plan's sampler 0.31 (ruckig `at_time` 0.26), the log row 0.07, the proven
send 0.51 (the Active check against `STATE_CHANGES`, the clock stamp, the drive's batch,
`StreamBatch.accept`) where `set_values_nowait` on the same batch takes 1.17; the whole
closure ~1.1 µs warm. What is left is ruckig's `at_time` (it builds three lists: position,
velocity, acceleration), the drive's own batch and `accept` (pure Python, per batch), and
about five Python calls; in the benchmark the tick runs between event-loop passes (colder
caches) while the peer runs 2,000 ticks back to back. What would remove more: a
position-only `at_time` in ruckig's Python binding, the drive's batch and the stream
bookkeeping in compiled code. Not done on purpose: a per-tick check that no device's
`limits` object was replaced (0.3 µs at 6 axes, 1.4 µs at 64, measured): a bank reads its
devices' limits when it is built (docs/psm.md), and the proof covers those limits, so a
proven batch is exactly one the per-value check would have passed.

**Issue 27 (targets 1.5x / 1.3x, async-only 64 axes 4x).** Profiled (cProfile), a new
`anyio.Event()` per tick for the streaming task's wake-up took 25-30 % of the tick
(`current_async_library`, asyncio's `_get_loop`), plus a task switch and a `TimerTick`
per tick. Now a tick that needs no await runs inside `notify_timer` (the timer's
notification: no task switch, no `TimerTick` built, the deadline read from
`EventTimer.last_tick_fields`), and the streaming task, kept for ticks that await a
driver, waits on a reused `Wakeup`. Over async-only drivers the tick paid a `_send`
coroutine and a `Motion` per axis (`Actuator._accept`: 70 % of the tick); now one
coroutine sends the batch (`actuator.send_targets`: one awaited `command` per axis,
lazy Motions, one clock reading per batch): 16x -> ~6-7x the peer at 64 axes on a loaded
machine. Warm micro-timing of the parts (thread time, min of 30 rounds, loaded machine,
6 / 64 axes): peer 867 / 5,358 ns; `at_time` alone 502 / 3,683; the group's tick 2,397 /
7,671: the sampler 641 / 3,697, the log row 152 / 155, the proven send 1,150 / 2,852 (the
drive's batch alone 682 / 2,219: N attribute stores on N drive objects, where the peer
stores into one list; `StreamBatch.accept` 182 / 283). Over async-only drivers, per axis:
the bare awaited `command` 153-234 ns, `send_targets` 347-599 ns (sequence, the lazy
Motion's tuple, the commanded value, the checks that a command was not overtaken during
its await). At 6 axes the framework's own part of a tick (sampler wrapper, log row, the
Active and limits checks, the stamp, `accept`, the tick closure: ~1 µs warm) is already
more than 0.5x the peer, so 1.5x is out of reach in pure Python without dropping per-tick
checks; compiling the tick (mypyc on `motion/group.py`, `banks.py`, `actuator.py`) or a
position-only `at_time` in ruckig's binding are what is left. Over async-only drivers the
awaited commands alone are ~1.7x the peer at 64 axes; an asynchronous batch hook on the
driver removes the per-axis coroutine and bookkeeping (done: below).

**Async-only drivers: an awaited batch.** A driver without a synchronous path may offer
`ActuatorDevice.async_batch_commander` (a bus's one write for every drive: a SYNC WRITE,
one CAN SYNC cycle); the group's bank then awaits one batch per tick and records it in its
`StreamBatch` (lazy Motions, as the synchronous batch), instead of one awaited `command`,
sequence and Motion tuple per axis. The target row runs over such a drive
(`AsyncMemoryDrive`); the informational row "one command per axis" over the same drive
without it (`AsyncEachDrive`). At 64 axes (loaded 2-core machine, quick runs): 4.6x the
peer before, 2.8-3.5x with the awaited batch (one command per axis: ~7x). Issue 27,
fourth pass (the row was 4.07x in one full run): the awaited tick now takes the proof too
(`ActuatorBank.position_stream_awaited`: the path's range proven once per motion, every
axis still checked Active before each batch, the proof made again when a device's limits
are set), so a tick is the sampler, the log row and one awaited device batch, without the
per-value check (the generated range check of 64 values) and two coroutine layers
(`set_values`, the per-call checks): 25 -> 11 µs per tick at 64 axes in an isolated loop
(6 moves of 2,000 ticks, load 2.4), 3.0x the peer in a quick run of this benchmark.

**The floor in the group's conditions.** The peer and the floor run their ticks back to
back in a tight loop; the group's tick runs from its `EventTimer`, between event-loop passes
(colder caches). The row "floor called by the group's EventTimer" times the same floor
tick called by a plain observer of the group's own timer in the same rounds
(`floor_loop_ticks`): what the loop around a tick costs the tick itself, before any of the
group's work. In the first quick runs with it (load 2-3): 1.13x the peer at 6 axes and
1.16x at 64, against 2.75x and 1.56x for the group's tick in the same run.

**The group's work at its least (issue 27: 64 axes <= 1.3x).** The row "floor with the
group's per-tick work, fused" times, in the same rounds and called the same way, the floor
tick plus what a tick of the group must do, written by hand as one function with no layer
between the group, the bank and the stream (`_fused_tick`): the trajectory-log row (a tuple
into a preallocated ring), the limits-changed and Active checks (two counter compares), the
command's stamp (the clock's `now_ns`), one call of the drive's batch command, the stream's
record of the batch (the targets copied, the stamp, the Motions built since the last batch)
and the commanded setpoints kept. It is the least any implementation of the group's
features (a trajectory log, commands refused to an axis no longer Active, a proof that
follows a device's limits, command times, `Motion`s on demand) can cost per tick in Python:
a lower bound of the group's tick, not a variant of it. Measured (quick runs, load 2-3 with
other work on this 2-core machine): 1.57-1.62x the peer at 64 axes (the group's tick
1.79-2.00x in the same runs) and 2.2-3.6x at 6 axes (the group's 2.8-4.0x); in-loop, a log
row, two compares, a clock call and a batch record cost ~2-3 µs, several times what they
cost warm. So neither target can be met by the group's tick in pure Python: 1.3x at 64 axes
is below the fused lower bound, and what is left between the group's tick and that bound
(0.2-0.4x the peer) is the layering (the plan's sampler, the bank's sender and the stream
as separate calls). The compiled path was measured for this tick (below: no gain, the cost
is calls across objects); **decision**: the rows stay marked missed with this bound beside
them in every run. In the two full runs after it (12:01 and 12:28 UTC): the fused bound 1.94x and 1.45x
the peer at 64 axes (the group's tick 1.95x and 2.04x), 2.48x and 2.53x at 6 axes (the
group's 3.14x and 3.88x).

**The floor, and the compiled path (issue 27: 6 axes <= 1.5x).** The row "floor" times the
least a tick of the group's shape can do in Python (`floor_ticks`): one call into a tick
function, ruckig's `at_time`, N stores into N drive objects, the setpoints kept; no Active
check, no stamp, no log row, no end-error blend. Measured beside the peer in the same
rounds (5 rounds of 2,000 ticks, 2-core machine at load 1.6-2.5, four runs): the floor is
1.17-1.32x the peer at 6 axes and 1.11-1.18x at 64; the group's tick 3.1-4.3x at 6 axes
and 1.7-2.1x at 64 in the same runs. So at 6 axes the 1.5x target leaves ~0.2-0.4x of the
peer (~0.3-0.6 µs: two to four Python calls) for everything the group does beyond the
floor -- the Active check, the clock stamp, the log row, `StreamBatch.accept`, the sampler's
end-error blend -- which cannot fit: the target is out of reach in pure Python without
dropping per-tick checks. Compiled with mypyc (mypy 1.x's `mypyc` through
`uv run --with setuptools`, gcc present here) in a scratch build of `motion/planner.py`,
`streaming.py`, `banks.py` and `motion/group.py` (55 s to build; `motion/log.py` does not
import once compiled: its dataclass annotations name `TYPE_CHECKING`-only aliases), the
6-axis tick stayed where it was (3.6-3.9x against 3.1-4.3x interpreted, same load; 64 axes
1.1-2.0x, within the noise): the tick's cost is calls across objects mypyc cannot type
natively (the `Actuator`s, the drive, ruckig's binding, the lists `at_time` builds), not
the interpreted bytecode of these modules. The compiled build also changed behaviour:
`sum(values)` over a `Sequence[float]` in `ActuatorBank.set_values_nowait` raised
`TypeError: int object expected; got float` (mypyc typed the sum as int), so every path
would need tests run against both builds. Its cost: a C compiler for a source install,
wheels per platform and Python version (cibuildwheel: CPython 3.11-3.13 x Linux
x86_64/aarch64, macOS, Windows), and a build hook that falls back to pure Python so that
`uv sync --locked` with `UV_PYTHON_DOWNLOADS=never` still works on a machine without a
compiler. **Decision: no compiled extension** -- the data shows no gain on this path for
that cost. What would move the 6-axis row: a position-only `at_time` in ruckig's binding
(it builds three lists per call), or a tick that skips the checks (not done: a proven
batch must stay exactly one the per-value check would pass, with every axis Active).

The proof does not use ruckig's `Trajectory.position_extrema`: the community edition
skips velocity zeros in constant-acceleration phases and can miss an overshoot entirely
(ruckig issue #215; e.g. from 1 rad/s back to the start under a 1, j 10 it reports a
maximum of 0.343 where the axis turns at 0.550). `Planner` now checks overshoots with the
exact range too, so such a motion is refused when planned instead of aborting mid-move.
"""
