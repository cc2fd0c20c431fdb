"""EventTimer on the real clock with timerfd: ticks come from the loop's timerfd callback
(:func:`openel_async.clock.realtime_scheduler`), no task; stop_timer unregisters it."""

from __future__ import annotations

import asyncio

import anyio
import pytest

from openel_async import EventTimer, timerfd
from openel_async.clock import MonotonicClock, default_clock, realtime_scheduler

pytestmark = pytest.mark.skipif(not timerfd.available(), reason="Linux timerfd")


class _Count:
    def __init__(self, until: int) -> None:
        self.ticks = 0
        self.until = until
        self.tasks: list[asyncio.Task[object] | None] = []
        self.done = anyio.Event()

    def notify_timer(self, timer: EventTimer) -> None:
        self.ticks += 1
        self.tasks.append(asyncio.current_task())
        if self.ticks >= self.until:
            self.done.set()


async def test_real_time_ticks_come_from_the_timerfd_callback_and_stop_unregisters() -> None:
    assert realtime_scheduler(default_clock()) is not None
    assert realtime_scheduler(MonotonicClock(use_timerfd=False)) is None
    loop = asyncio.get_running_loop()
    async with EventTimer(1.0, name="fd") as timer:
        count = _Count(5)
        timer.add_observer(count)
        timer.start_timer()
        with anyio.fail_after(5):
            await count.done.wait()
        assert count.tasks == [None] * len(count.tasks)  # a loop callback, not a task
        readers = len(loop._selector.get_map())  # type: ignore[attr-defined]
        timer.stop_timer()
        ticks = count.ticks
        assert len(loop._selector.get_map()) == readers - 1  # type: ignore[attr-defined]
        await anyio.sleep(0.01)
        assert count.ticks == ticks  # no tick after stop_timer
        assert timer.stats.ticks == ticks
        timer.start_timer()  # and again
        count.until, count.done = ticks + 3, anyio.Event()
        with anyio.fail_after(5):
            await count.done.wait()
