"""VirtualClock: simulated time run at CPU speed, against the same timer on real time."""

from __future__ import annotations

import gc
import time

import anyio

from benchmarks.harness import BenchResult, Row, ratio_of
from openel_async import EventTimer, MonotonicClock, ObserverQueue, VirtualClock
from openel_async.clock import Clock

NAME = "virtual_clock"
PERIOD_MS = 1
VIRTUAL_S = 10.0
REAL_S = 1.0
QUICK_REAL_S = 0.3
TARGET_WALL_S = 1.0


async def _ticks(clock: Clock, seconds: float) -> tuple[int, float]:
    """Run a 1 kHz EventTimer with three observers for ``seconds`` of ``clock`` time."""
    target = round(seconds * 1000 / PERIOD_MS)
    counted = 0

    def plain(timer: EventTimer) -> None:
        nonlocal counted
        counted += 1

    class Async:
        async def notify_timer(self, timer: EventTimer) -> None:
            await anyio.lowlevel.checkpoint()

    queue = ObserverQueue(maxsize=4096)
    start = time.perf_counter()
    async with EventTimer(PERIOD_MS, clock=clock) as timer:
        timer.add_observer(plain)
        timer.add_observer(queue)
        timer.add_observer(Async())
        timer.start_timer()
        while counted < target:
            await queue.get()  # the consumer of the queue observer
        timer.stop_timer()
    return counted, time.perf_counter() - start


async def _virtual() -> tuple[int, float]:
    clock = VirtualClock()
    async with clock.autojump():
        return await _ticks(clock, VIRTUAL_S)


async def _real(seconds: float) -> tuple[int, float]:
    return await _ticks(MonotonicClock(), seconds)


def run(quick: bool) -> BenchResult:
    gc.collect()
    ticks, wall = anyio.run(_virtual, backend="asyncio")
    real_s = QUICK_REAL_S if quick else REAL_S
    gc.collect()
    real_ticks, real_wall = anyio.run(_real, real_s, backend="asyncio")
    per_tick = wall / ticks * 1e6
    real_per_tick = real_wall / real_ticks * 1e6
    rows = (
        Row(
            f"wall time for {VIRTUAL_S:.0f} s of virtual time",
            wall,
            "s",
            baseline=real_per_tick * ticks / 1e6,
            baseline_label=f"the same ticks on the real clock ({real_ticks} measured)",
            ratio=ratio_of(real_per_tick * ticks / 1e6, wall),
            ratio_label="real/virtual",
            target=f"< {TARGET_WALL_S:.0f} s",
            passed=wall < TARGET_WALL_S and ticks == round(VIRTUAL_S * 1000 / PERIOD_MS),
            digits=3,
        ),
        Row(
            "wall time per tick",
            per_tick,
            "µs",
            baseline=real_per_tick,
            baseline_label="real clock (one period)",
            ratio=ratio_of(real_per_tick, per_tick),
            ratio_label="real/virtual",
            digits=1,
        ),
        Row("ticks delivered", ticks, target=f"{round(VIRTUAL_S * 1000 / PERIOD_MS)}", digits=0),
    )
    return BenchResult(
        name=NAME,
        title="VirtualClock: 10 s of a 1 kHz EventTimer with observers, at CPU speed",
        rows=rows,
        description=DESCRIPTION,
        notes=(
            f"The baseline runs the same timer and observers on MonotonicClock for "
            f"{real_s} s in the same run; its per-tick wall time (one period) is scaled to "
            f"the virtual run's {ticks} ticks.",
        ),
        params={"period": f"{PERIOD_MS} ms", "virtual span": f"{VIRTUAL_S} s", "quick": str(quick)},
    )


DESCRIPTION = """\
An `EventTimer` at 1 kHz on a `VirtualClock` with auto-jump, with three observers (a
plain callable, an `ObserverQueue` drained by the measuring task, and an async
observer), runs until 10,000 ticks were delivered. The figure is the wall time of the
whole run; the baseline is the same workload on the real clock (which takes one
period per tick by definition), measured in the same run.
"""
