"""Call-to-return time of ``await Actuator.set_value`` against the bare driver call.

One ``Actuator(SimMotor())`` on the real clock is reused for every call. Targets
alternate between two positions within the limits, so every call is a real new move
(the previous Motion is superseded). Each await is timed alone with
``time.perf_counter_ns``; framework and driver-alone calls run in interleaved blocks so
that load changes on the machine hit both alike.
"""

from __future__ import annotations

import asyncio
import gc
import time
from dataclasses import dataclass

import anyio
import anyio.lowlevel

from openel_async import (
    Actuator,
    ActuatorDevice,
    ActuatorLimits,
    ComponentState,
    DeviceInfo,
    DeviceKind,
    MonotonicClock,
    Request,
)
from openel_async.stats import percentile
from openel_sim import SimMotor

from .harness import COMMAND, BenchResult, Row, median, ratio_of

NAME = "set_value"
CALLS = 20_000
QUICK_CALLS = 5_000
BLOCKS = 10
QUICK_BLOCKS = 5
WARMUP = 1_000
TARGETS = (0.5, -0.5)
MEDIAN_TARGET_US = 20.0
QUEUE_TARGET = 1.2
"""Largest ours/asyncio.Queue.put ratio of the median call (issue 27)."""


class StoreDrive(ActuatorDevice):
    """A driver that takes a command by storing it (no I/O, no simulation): what is left of
    ``set_value`` is the framework's own work, compared with putting the target on a queue."""

    info = DeviceInfo(kind=DeviceKind.MOTOR, vendor_name="Bench", product_name="StoreDrive")
    limits = ActuatorLimits(position=(-10.0, 10.0))
    reports_completion = True  # no completion-detection task

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


@dataclass(frozen=True, slots=True)
class Timings:
    framework_ns: list[list[int]]
    """Per block (round), each call's time."""
    driver_ns: list[list[int]]
    store_ns: list[list[int]]
    """set_value on the StoreDrive."""
    queue_ns: list[list[int]]
    """await asyncio.Queue.put."""


def _median_us(rounds: list[list[int]]) -> float:
    return median([percentile(sorted(r), 50) for r in rounds]) / 1e3


def _all(rounds: list[list[int]]) -> list[int]:
    return sorted(v for r in rounds for v in r)


async def measure(calls: int, blocks: int) -> Timings:
    framework: list[list[int]] = []
    driver: list[list[int]] = []
    store: list[list[int]] = []
    queued: list[list[int]] = []
    clock = MonotonicClock()
    per_block = calls // blocks
    queue: asyncio.Queue[float] = asyncio.Queue()

    async def consume() -> None:
        while True:
            await queue.get()

    async with (
        Actuator(SimMotor(), clock=clock) as actuator,
        Actuator(StoreDrive(), clock=clock) as stored,
        anyio.create_task_group() as tg,
    ):
        assert actuator.state is ComponentState.ACTIVE
        tg.start_soon(consume)
        device = actuator.device
        perf = time.perf_counter_ns
        position = Request.POSITION

        async def framework_block(n: int, out: list[int] | None, on: Actuator) -> None:
            for i in range(n):
                target = TARGETS[i & 1]
                t0 = perf()
                await on.set_value(target, position)
                t1 = perf()
                if out is not None:
                    out.append(t1 - t0)
                # Let the motor's watcher task re-plan (as between commands of a real
                # control loop); outside the timed region.
                await anyio.lowlevel.checkpoint()

        async def driver_block(n: int, out: list[int] | None) -> None:
            for i in range(n):
                target = TARGETS[i & 1]
                t0 = perf()
                await device.command(position, target)
                t1 = perf()
                if out is not None:
                    out.append(t1 - t0)
                await anyio.lowlevel.checkpoint()

        async def queue_block(n: int, out: list[int] | None) -> None:
            for i in range(n):
                target = TARGETS[i & 1]
                t0 = perf()
                await queue.put(target)
                t1 = perf()
                if out is not None:
                    out.append(t1 - t0)
                await anyio.lowlevel.checkpoint()  # the consumer takes it

        await framework_block(WARMUP, None, actuator)
        await driver_block(WARMUP, None)
        await framework_block(WARMUP, None, stored)
        await queue_block(WARMUP, None)
        for _ in range(blocks):
            for out, block in (
                (driver, driver_block),
                (queued, queue_block),
            ):
                out.append([])
                await block(per_block, out[-1])
            framework.append([])
            await framework_block(per_block, framework[-1], actuator)
            store.append([])
            await framework_block(per_block, store[-1], stored)
        for component in (actuator, stored):
            if component.state is not ComponentState.ACTIVE:
                raise AssertionError(
                    f"{component.device_name} left Active during the benchmark: {component.state}"
                )
        tg.cancel_scope.cancel()
    return Timings(framework, driver, store, queued)


def run(quick: bool) -> BenchResult:
    calls = QUICK_CALLS if quick else CALLS
    blocks = QUICK_BLOCKS if quick else BLOCKS
    gc.collect()
    timings = anyio.run(measure, calls, blocks, backend="asyncio")
    ours = _all(timings.framework_ns)
    base = _all(timings.driver_ns)
    us = 1e3
    med, med_base = _median_us(timings.framework_ns), _median_us(timings.driver_ns)
    med_store, med_queue = _median_us(timings.store_ns), _median_us(timings.queue_ns)
    # The target's ratio: the median of the rounds' own ratios (each round's store block
    # over the queue block of the same round): the machine's speed shifts between rounds
    # (per-round medians of either side move between ~1.5 and ~3.7 µs), and a ratio of the
    # two sides' medians can pair a fast state of one with a slow state of the other.
    round_ratios = [
        percentile(sorted(s), 50) / percentile(sorted(q), 50)
        for s, q in zip(timings.store_ns, timings.queue_ns, strict=True)
    ]
    queue_ratio = median(round_ratios)
    p99, p99_base = percentile(ours, 99) / us, percentile(base, 99) / us
    mean, mean_base = sum(ours) / len(ours) / us, sum(base) / len(base) / us
    rows = (
        Row(
            "median call-to-return, storing driver",
            med_store,
            "µs",
            baseline=med_queue,
            baseline_label="await asyncio.Queue.put",
            ratio=queue_ratio,
            ratio_label="ours/Queue.put, median of rounds' ratios",
            target=f"<= {QUEUE_TARGET:g}x Queue.put",
            passed=queue_ratio <= QUEUE_TARGET,
            digits=2,
        ),
        Row(
            "median call-to-return, SimMotor",
            med,
            "µs",
            baseline=med_base,
            baseline_label="driver alone",
            ratio=ratio_of(med, med_base),
            ratio_label="ours/driver",
            target=f"<= {MEDIAN_TARGET_US:.0f} µs",
            passed=med <= MEDIAN_TARGET_US,
            digits=2,
        ),
        Row(
            "p99 call-to-return, SimMotor",
            p99,
            "µs",
            baseline=p99_base,
            baseline_label="driver alone",
            ratio=ratio_of(p99, p99_base),
            ratio_label="ours/driver",
            digits=2,
        ),
        Row(
            "mean call-to-return, SimMotor",
            mean,
            "µs",
            baseline=mean_base,
            baseline_label="driver alone",
            ratio=ratio_of(mean, mean_base),
            ratio_label="ours/driver",
            digits=2,
        ),
        Row(
            "max call-to-return, SimMotor",
            ours[-1] / us,
            "µs",
            baseline=base[-1] / us,
            baseline_label="driver alone",
            digits=1,
        ),
    )
    notes: tuple[str, ...] = (
        f"Framework overhead at the median: {med - med_base:.2f} µs per call on SimMotor "
        f"(`set_value` minus the bare `SimMotor.command`), {med_store - med_queue:.2f} µs "
        "over `Queue.put` on the storing driver.",
        f"{per_block_count(calls, blocks)} timed calls of each kind per round, {blocks} "
        f"interleaved rounds after {WARMUP} warm-up calls of each kind; medians are the "
        "median of the rounds' medians.",
        "Storing driver over Queue.put, per round: "
        + ", ".join(f"{r:.2f}" for r in round_ratios)
        + " (the target's ratio is their median).",
    )
    if queue_ratio > QUEUE_TARGET or med > MEDIAN_TARGET_US:
        notes += (f"Target missed: where the time goes: `{COMMAND} {NAME} --profile`.",)
    return BenchResult(
        name=NAME,
        title="Actuator.set_value call-to-return vs asyncio.Queue.put and the driver alone",
        rows=rows,
        description=DESCRIPTION,
        notes=notes,
        params={
            "calls": str(calls),
            "rounds": str(blocks),
            "targets": f"{TARGETS} rad, alternating",
        },
    )


def per_block_count(calls: int, blocks: int) -> int:
    return calls // blocks


DESCRIPTION = """\
**Against `asyncio.Queue.put`** (the target row): `await actuator.set_value(x)` on an
`Actuator` over a driver that stores the command (`StoreDrive`: `command_nowait` stores the
value, the driver reports completion, so no detection task runs), against
`await queue.put(x)` on an unbounded `asyncio.Queue` drained by a consumer task: handing a
target to whatever acts on it, the way a plain asyncio program would. Each call is timed
alone; every call is followed by one checkpoint outside the timed region.

**Against the driver alone**: `await actuator.set_value(x, Request.POSITION)` on one `Actuator(SimMotor())` on the real
clock, reused for every call, with targets alternating between two positions within the
limits (each call supersedes the previous Motion). Each await is timed alone with
`time.perf_counter_ns`. Baseline: the bare driver call `await device.command(Request.POSITION, x)`
on the same SimMotor, timed the same way; the two kinds of calls run in interleaved
blocks, each call followed (outside the timed region) by one checkpoint so the motor's
watcher task re-plans as it would between the commands of a control loop. The ratio is
ours/driver: how many times the driver alone the whole call costs.

Issue 27 (storing driver, target <= 1.2x `Queue.put`, 1.29x and 1.09x in the runs before):
the call is `set_value` -> `_set_now` (state, request, finiteness and limit checks, the
sequence, the driver's `command_nowait`, the new `Motion`, the superseded one finished).
Cut in this pass: `MonotonicClock.now_ns` is `time.monotonic_ns` itself (a C call, no
Python frame), and the superseded Motion nobody awaits is finished inline (no `_finish`
call). What is left is four Python calls (`set_value`, `_set_now`, the driver's
`command_nowait`, `Motion.__init__`) against `Queue.put`'s seven (`put`, `full` twice,
`put_nowait`, `_put`, `Event.clear`, `_wakeup_next`), each of ours doing more; quick runs
after: 0.98x, 1.01x, 1.05x. The remaining difference between runs is the machine (a median of 2 µs moves by
10-20 % with the load of the shared 2-core VM). The target's ratio is the median of the
rounds' own ratios (each round's storing-driver block over its own `Queue.put` block): in
the first two full runs after issue 27's last pass the ratio of the two sides' medians was
1.58x and 1.27x while single runs gave 0.85-1.07x; the per-round medians of both sides
move between ~1.5 and ~3.7 µs as the machine's state shifts (three runs of this benchmark:
per-round ratios 0.71-1.10 but for one round at 1.60, medians 1.00-1.02, against
ratios of medians 0.97-1.04), and a ratio of medians can pair one side's fast rounds with
the other's slow ones."""
