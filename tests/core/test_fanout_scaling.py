"""Fanout cost: registration is O(N) for N observers (counted in executed lines, not
timed), and many async observers each get every notice through the shared wake-up."""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path
from types import FrameType
from typing import Any

import anyio

import openel_async.fanout
import openel_async.observers
from openel_async.fanout import Fanout

HAL_KINDS = ("notify_event", "notify_error")
SOURCE: Any = object()
WATCHED = {
    str(Path(openel_async.fanout.__file__).resolve()),
    str(Path(openel_async.observers.__file__).resolve()),
}


class Plain:
    def notify_event(self, source: object, event_id: int) -> None:
        pass

    def notify_error(self, source: object, error_id: int) -> None:
        pass


def _lines_executed(action: Callable[[], None]) -> int:
    """Lines of fanout.py and observers.py that ``action`` executes (sys.settrace)."""
    count = 0

    def local(frame: FrameType, event: str, arg: object) -> Any:
        nonlocal count
        if event == "line":
            count += 1
        return local

    def tracer(frame: FrameType, event: str, arg: object) -> Any:
        if str(Path(frame.f_code.co_filename).resolve()) in WATCHED:
            return local
        return None

    previous = sys.gettrace()
    sys.settrace(tracer)
    try:
        action()
    finally:
        sys.settrace(previous)
    return count


def _register(n: int) -> Callable[[], None]:
    observers = [Plain() for _ in range(n)]
    fan = Fanout("pub", HAL_KINDS)

    def action() -> None:
        for observer in observers:
            fan.add(observer)
        fan.publish("notify_event", SOURCE, 2)  # rebuilds the delivery tuple once

    return action


def test_registering_n_observers_is_linear() -> None:
    # The old copy-on-write tuple with a scan for duplicates and a rescan of every
    # observer's routes per add executed lines in proportion to N² (ratio ~4 here).
    small = _lines_executed(_register(60))
    large = _lines_executed(_register(120))
    assert small > 0
    assert large <= 2.05 * small, (small, large)


def test_removing_keeps_the_others_and_the_notice_kinds() -> None:
    class TakesNotice(Plain):
        def notify_event(self, source: object, event_id: int, notice: object = None) -> None:
            pass

    fan = Fanout("pub", HAL_KINDS)
    plain, taking = Plain(), TakesNotice()
    fan.add(plain)
    fan.add(taking)
    assert fan.wants_notice == frozenset({"notify_event"})
    fan.remove(taking)
    assert fan.wants_notice == frozenset()
    assert fan.observers == (plain,) and plain in fan and taking not in fan
    fan.add(taking)
    assert fan.observers == (plain, taking)  # registration order


async def test_a_thousand_async_observers_each_get_every_notice_in_order() -> None:
    got: list[list[int]] = [[] for _ in range(1000)]

    class Async:
        def __init__(self, i: int) -> None:
            self.i = i

        async def notify_event(self, source: object, event_id: int) -> None:
            got[self.i].append(event_id)

    class OnlyErrors:
        errors = 0

        async def notify_error(self, source: object, error_id: int) -> None:
            OnlyErrors.errors += 1

    fan = Fanout("pub", HAL_KINDS)
    async with anyio.create_task_group() as tg:
        fan.bind(tg)
        for i in range(1000):
            fan.add(Async(i))
        fan.add(OnlyErrors())  # woken by events too, finds nothing to deliver
        for k in range(5):
            fan.publish("notify_event", SOURCE, k)
            if k == 2:
                await anyio.lowlevel.checkpoint()  # some delivered, some queued
        fan.publish("notify_error", SOURCE, 9)
        await fan.wait_delivered()
        assert all(ids == [0, 1, 2, 3, 4] for ids in got)
        assert OnlyErrors.errors == 1
        stats = fan.stats()
        assert sum(m.delivered for m in stats.mailboxes) == 5001
        assert stats.overflowed == stats.failures == 0
        fan.close()
        fan.bind(None)
