"""ObserverQueue: FIFO delivery, drop-oldest overflow with ``missed`` counts, close."""

from __future__ import annotations

from typing import Any

import anyio
import pytest
import structlog.testing

from openel_async.errors import BadParameterError
from openel_async.observers import (
    ErrorNotice,
    EventNotice,
    HALObserver,
    ObserverQueue,
    TimerObserver,
    TimerTick,
    observer_methods,
)

SOURCE: Any = object()


class _FakeTimer:
    """Just what ObserverQueue.notify_timer reads from an EventTimer."""

    def __init__(self) -> None:
        self.last_tick: TimerTick | None = None

    def tick(self, index: int) -> None:
        self.last_tick = TimerTick(self, index, index * 10, index * 10 + 1)  # type: ignore[arg-type]


def test_fifo_order_across_kinds() -> None:
    queue = ObserverQueue(8)
    timer = _FakeTimer()
    queue.notify_event(SOURCE, 1)
    queue.notify_error(SOURCE, 2)
    timer.tick(7)
    queue.notify_timer(timer)  # type: ignore[arg-type]
    queue.notify_event(SOURCE, 3)
    assert len(queue) == 4

    first = queue.get_nowait()
    assert first == EventNotice(SOURCE, 1)
    assert queue.get_nowait() == ErrorNotice(SOURCE, 2)
    tick = queue.get_nowait()
    assert isinstance(tick, TimerTick)
    assert (tick.index, tick.deadline_ns, tick.time_ns, tick.lateness_ns) == (7, 70, 71, 1)
    assert tick.timer is timer
    assert queue.get_nowait() == EventNotice(SOURCE, 3)
    assert len(queue) == 0
    assert queue.delivered == 4
    assert queue.missed_total == 0
    with pytest.raises(anyio.WouldBlock):
        queue.get_nowait()


def test_notify_timer_without_a_tick_is_ignored() -> None:
    queue = ObserverQueue()
    queue.notify_timer(_FakeTimer())  # type: ignore[arg-type]
    assert len(queue) == 0


async def test_get_waits_for_the_next_notice() -> None:
    queue = ObserverQueue()
    got: list[object] = []

    async def consumer() -> None:
        for _ in range(3):
            notice = await queue.get()
            assert isinstance(notice, EventNotice)
            got.append(notice.event_id)

    async with anyio.create_task_group() as tg:
        tg.start_soon(consumer)
        for event_id in (10, 11, 12):
            await anyio.wait_all_tasks_blocked()  # the consumer is waiting
            queue.notify_event(SOURCE, event_id)
    assert got == [10, 11, 12]


async def test_overflow_drops_oldest_and_reports_missed() -> None:
    queue = ObserverQueue(3, name="q3")
    with structlog.testing.capture_logs() as logs:
        for event_id in range(1, 8):  # 7 into 3: 1..4 dropped
            queue.notify_event(SOURCE, event_id)
        assert len(queue) == 3
        assert queue.missed_total == 4

        overflow = [e for e in logs if e["event"] == "observer_queue_overflow"]
        # One line per overflow episode, not one per dropped notice.
        assert overflow == [
            {
                "event": "observer_queue_overflow",
                "log_level": "warning",
                "queue": "q3",
                "maxsize": 3,
            }
        ]

        first = await queue.get()
        assert first == EventNotice(SOURCE, 5, missed=4)
        assert await queue.get() == EventNotice(SOURCE, 6, missed=0)

        missed_lines = [e for e in logs if e["event"] == "observer_queue_missed"]
        assert missed_lines == [
            {"event": "observer_queue_missed", "log_level": "warning", "queue": "q3", "missed": 4}
        ]

        # A second episode: counted and logged afresh, missed_total accumulates.
        queue.notify_event(SOURCE, 8)
        queue.notify_event(SOURCE, 9)
        queue.notify_event(SOURCE, 10)  # holds 7, 8, 9 -> drops 7
        assert [n.event_id for n in queue.drain()] == [8, 9, 10]  # type: ignore[union-attr]
        assert queue.missed_total == 5
        assert len([e for e in logs if e["event"] == "observer_queue_overflow"]) == 2
    assert queue.delivered == 5


def test_missed_is_reported_on_timer_ticks_too() -> None:
    queue = ObserverQueue(1)
    timer = _FakeTimer()
    for index in (1, 2, 3):
        timer.tick(index)
        queue.notify_timer(timer)  # type: ignore[arg-type]
    tick = queue.get_nowait()
    assert isinstance(tick, TimerTick)
    assert (tick.index, tick.missed, tick.missed_ticks) == (3, 2, 0)


def test_a_notice_given_by_the_publisher_is_queued_as_is() -> None:
    """Publishers build one notice per notification and share it among observers."""
    queue = ObserverQueue(1)
    notice = EventNotice(SOURCE, 1)
    queue.notify_event(SOURCE, 1, notice)
    assert queue.get_nowait() is notice
    error = ErrorNotice(SOURCE, 4)
    queue.notify_error(SOURCE, 4, error)
    assert queue.get_nowait() is error
    timer = _FakeTimer()
    timer.tick(1)
    tick = TimerTick(timer, 9, 90, 91)  # type: ignore[arg-type]
    queue.notify_timer(timer, tick)  # type: ignore[arg-type]
    assert queue.get_nowait() is tick  # the tick given, not timer.last_tick


def test_missed_counts_add_up_through_forwarded_notices() -> None:
    """A notice that already reports missed ones keeps them, plus the queue's own drops
    (and those of a dropped notice)."""
    queue = ObserverQueue(1)
    queue.notify_event(SOURCE, 2, EventNotice(SOURCE, 2, missed=3))
    queue.notify_event(SOURCE, 3, EventNotice(SOURCE, 3, missed=2))  # drops 2 (and its 3)
    assert queue.get_nowait() == EventNotice(SOURCE, 3, missed=2 + 1 + 3)
    assert queue.missed_total == 1


def test_drain_returns_everything_oldest_first() -> None:
    queue = ObserverQueue(2)
    for event_id in (1, 2, 3):
        queue.notify_event(SOURCE, event_id)
    drained = queue.drain()
    assert drained == [EventNotice(SOURCE, 2, missed=1), EventNotice(SOURCE, 3)]
    assert queue.drain() == []


async def test_iteration_ends_after_close_once_drained() -> None:
    queue = ObserverQueue()
    for event_id in (1, 2, 3):
        queue.notify_event(SOURCE, event_id)
    queue.close()
    queue.notify_event(SOURCE, 4)  # after close: ignored
    got = [notice async for notice in queue]
    assert got == [EventNotice(SOURCE, 1), EventNotice(SOURCE, 2), EventNotice(SOURCE, 3)]
    with pytest.raises(anyio.EndOfStream):
        await queue.get()


async def test_close_wakes_a_waiting_consumer() -> None:
    queue = ObserverQueue()
    got: list[object] = []
    finished = False

    async def consumer() -> None:
        nonlocal finished
        async for notice in queue:
            got.append(notice)
        finished = True

    async with anyio.create_task_group() as tg:
        tg.start_soon(consumer)
        await anyio.wait_all_tasks_blocked()
        queue.notify_error(SOURCE, 9)
        await anyio.wait_all_tasks_blocked()
        assert got == [ErrorNotice(SOURCE, 9)]
        assert not finished
        queue.close()
    assert finished


async def test_a_cancelled_get_loses_nothing() -> None:
    queue = ObserverQueue()
    async with anyio.create_task_group() as tg:
        tg.start_soon(queue.get)
        await anyio.wait_all_tasks_blocked()
        tg.cancel_scope.cancel()
    queue.notify_event(SOURCE, 1)
    assert await queue.get() == EventNotice(SOURCE, 1)


@pytest.mark.parametrize("maxsize", [0, -1, True, 1.5, "8", None])
def test_maxsize_validation(maxsize: object) -> None:
    with pytest.raises(BadParameterError) as info:
        ObserverQueue(maxsize)  # type: ignore[arg-type]
    assert info.value.parameter == "maxsize"
    assert "maxsize" in str(info.value)


def test_maxsize_one_is_allowed() -> None:
    queue = ObserverQueue(1)
    queue.notify_event(SOURCE, 1)
    queue.notify_event(SOURCE, 2)
    assert queue.drain() == [EventNotice(SOURCE, 2, missed=1)]


def test_implements_both_observer_protocols() -> None:
    queue = ObserverQueue()
    assert isinstance(queue, HALObserver)
    assert isinstance(queue, TimerObserver)
    assert not isinstance(object(), HALObserver)
    assert not isinstance(object(), TimerObserver)
    assert "pending=0" in repr(queue)


def test_observer_methods_picks_the_notify_methods() -> None:
    queue = ObserverQueue()
    methods = observer_methods(queue, ("notify_event", "notify_error"))
    assert set(methods) == {"notify_event", "notify_error"}

    def callback(timer: object) -> None:
        pass

    assert observer_methods(callback, ("notify_timer",)) == {"notify_timer": callback}
    # A bare callable cannot stand for two kinds.
    with pytest.raises(BadParameterError) as info:
        observer_methods(callback, ("notify_event", "notify_error"))
    assert info.value.parameter == "observer"
    with pytest.raises(BadParameterError):
        observer_methods(object(), ("notify_timer",))
