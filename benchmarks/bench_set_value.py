"""Call-to-return time of ``await Actuator.set_value`` against the bare driver call.

One ``Actuator(SimMotor())`` on the real clock is reused for every call. Targets
alternate between two positions within the limits, so every call is a real new move
(the previous Motion is superseded). Each await is timed alone with
``time.perf_counter_ns``; framework and driver-alone calls run in interleaved blocks so
that load changes on the machine hit both alike.
"""

from __future__ import annotations

import gc
import time
from dataclasses import dataclass

import anyio
import anyio.lowlevel

from openel_async import Actuator, ComponentState, MonotonicClock, Request
from openel_async.stats import percentile
from openel_sim import SimMotor

from .harness import COMMAND, BenchResult, Row, ratio_of

NAME = "set_value"
CALLS = 20_000
QUICK_CALLS = 4_000
BLOCKS = 10
WARMUP = 1_000
TARGETS = (0.5, -0.5)
MEDIAN_TARGET_US = 20.0


@dataclass(frozen=True, slots=True)
class Timings:
    framework_ns: list[int]
    driver_ns: list[int]


async def measure(calls: int) -> Timings:
    framework: list[int] = []
    driver: list[int] = []
    clock = MonotonicClock()
    per_block = calls // BLOCKS
    async with Actuator(SimMotor(), clock=clock) as actuator:
        assert actuator.state is ComponentState.ACTIVE
        device = actuator.device
        perf = time.perf_counter_ns
        position = Request.POSITION

        async def framework_block(n: int, out: list[int] | None) -> None:
            for i in range(n):
                target = TARGETS[i & 1]
                t0 = perf()
                await actuator.set_value(target, position)
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

        await framework_block(WARMUP, None)
        await driver_block(WARMUP, None)
        for _ in range(BLOCKS):
            await driver_block(per_block, driver)
            await framework_block(per_block, framework)
        if actuator.state is not ComponentState.ACTIVE:
            raise AssertionError(f"actuator left Active during the benchmark: {actuator.state}")
    return Timings(framework, driver)


def run(quick: bool) -> BenchResult:
    calls = QUICK_CALLS if quick else CALLS
    gc.collect()
    timings = anyio.run(measure, calls, backend="asyncio")
    ours = sorted(timings.framework_ns)
    base = sorted(timings.driver_ns)
    us = 1e3
    med, med_base = percentile(ours, 50) / us, percentile(base, 50) / us
    p99, p99_base = percentile(ours, 99) / us, percentile(base, 99) / us
    mean, mean_base = sum(ours) / len(ours) / us, sum(base) / len(base) / us
    rows = (
        Row(
            "median call-to-return",
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
            "p99 call-to-return",
            p99,
            "µs",
            baseline=p99_base,
            baseline_label="driver alone",
            ratio=ratio_of(p99, p99_base),
            ratio_label="ours/driver",
            digits=2,
        ),
        Row(
            "mean call-to-return",
            mean,
            "µs",
            baseline=mean_base,
            baseline_label="driver alone",
            ratio=ratio_of(mean, mean_base),
            ratio_label="ours/driver",
            digits=2,
        ),
        Row(
            "max call-to-return",
            ours[-1] / us,
            "µs",
            baseline=base[-1] / us,
            baseline_label="driver alone",
            digits=1,
        ),
    )
    notes: tuple[str, ...] = (
        f"Framework overhead at the median: {med - med_base:.2f} µs per call "
        f"(`set_value` minus the bare `SimMotor.command`).",
        f"{len(ours)} timed calls each, in {BLOCKS} interleaved blocks after {WARMUP} "
        "warm-up calls of each kind.",
    )
    if med > MEDIAN_TARGET_US:
        notes += (
            f"Target missed: the driver alone takes {med_base:.1f} µs at the median "
            f"({med_base / MEDIAN_TARGET_US:.0%} of the {MEDIAN_TARGET_US:.0f} µs budget) "
            f"and the framework adds {med - med_base:.1f} µs on top. Where the time goes: "
            f"`{COMMAND} {NAME} --profile`.",
        )
    return BenchResult(
        name=NAME,
        title="Actuator.set_value call-to-return vs the driver alone",
        rows=rows,
        description=DESCRIPTION,
        notes=notes,
        params={"calls": str(calls), "targets": f"{TARGETS} rad, alternating"},
    )


DESCRIPTION = """\
`await actuator.set_value(x, Request.POSITION)` on one `Actuator(SimMotor())` on the real
clock, reused for every call, with targets alternating between two positions within the
limits (each call supersedes the previous Motion). Each await is timed alone with
`time.perf_counter_ns`. Baseline: the bare driver call `await device.command(Request.POSITION, x)`
on the same SimMotor, timed the same way; the two kinds of calls run in interleaved
blocks, each call followed (outside the timed region) by one checkpoint so the motor's
watcher task re-plans as it would between the commands of a control loop. The ratio is
ours/driver: how many times the driver alone the whole call costs."""
