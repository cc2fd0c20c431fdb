"""Fanout: isolation of failing and slow observers, order, overflow, re-entrancy."""

from __future__ import annotations

from typing import Any

import anyio
import pytest
import structlog.testing

from openel_async.clock import NS_PER_MS, NS_PER_S, VirtualClock
from openel_async.errors import BadParameterError
from openel_async.fanout import Fanout
from openel_async.observers import ObserverQueue

HAL_KINDS = ("notify_event", "notify_error")
SOURCE: Any = object()


class Recorder:
    """A plain HALObserver that records (kind, id) and, with a clock, the time."""

    def __init__(self, clock: VirtualClock | None = None) -> None:
        self.clock = clock
        self.got: list[tuple[str, int]] = []
        self.times: list[int] = []

    def _add(self, kind: str, ident: int) -> None:
        self.got.append((kind, ident))
        if self.clock is not None:
            self.times.append(self.clock.now_ns())

    def notify_event(self, source: object, event_id: int) -> None:
        self._add("event", event_id)

    def notify_error(self, source: object, error_id: int) -> None:
        self._add("error", error_id)


class AsyncRecorder(Recorder):
    """The same with async methods, optionally sleeping on the clock before recording."""

    def __init__(self, clock: VirtualClock | None = None, delay_s: float = 0.0) -> None:
        super().__init__(clock)
        self.delay_s = delay_s

    async def notify_event(self, source: object, event_id: int) -> None:  # type: ignore[override]
        if self.delay_s:
            assert self.clock is not None
            await self.clock.sleep(self.delay_s)
        self._add("event", event_id)

    async def notify_error(self, source: object, error_id: int) -> None:  # type: ignore[override]
        if self.delay_s:
            assert self.clock is not None
            await self.clock.sleep(self.delay_s)
        self._add("error", error_id)


class Raising:
    def __init__(self) -> None:
        self.calls = 0

    def notify_event(self, source: object, event_id: int) -> None:
        self.calls += 1
        raise RuntimeError(f"observer broke on {event_id}")

    def notify_error(self, source: object, error_id: int) -> None:
        self.calls += 1
        raise RuntimeError("observer broke")


class AsyncRaising:
    def __init__(self) -> None:
        self.calls = 0

    async def notify_event(self, source: object, event_id: int) -> None:
        self.calls += 1
        raise RuntimeError(f"async observer broke on {event_id}")

    async def notify_error(self, source: object, error_id: int) -> None:
        self.calls += 1


# -- failures ------------------------------------------------------------------------------


def test_raising_sync_observer_does_not_stop_delivery_and_is_logged() -> None:
    fan = Fanout("pub", HAL_KINDS)
    before, bad, after = Recorder(), Raising(), Recorder()
    for observer in (before, bad, after):
        fan.add(observer)

    with structlog.testing.capture_logs() as logs:
        fan.publish("notify_event", SOURCE, 1)
        fan.publish("notify_error", SOURCE, 2)
        fan.publish("notify_event", SOURCE, 3)

    expected = [("event", 1), ("error", 2), ("event", 3)]
    assert before.got == expected
    assert after.got == expected
    assert bad.calls == 3
    assert fan.failures == 3
    failed = [e for e in logs if e["event"] == "observer_failed"]
    assert len(failed) == 3
    assert all(e["log_level"] == "error" and e["owner"] == "pub" for e in failed)
    assert all(e.get("exc_info") for e in failed)
    assert all("Raising" in e["observer"] for e in failed)


async def test_raising_async_observer_does_not_stop_its_mailbox() -> None:
    fan = Fanout("pub", HAL_KINDS)
    bad, good = AsyncRaising(), AsyncRecorder()
    fan.add(bad)
    fan.add(good)
    with structlog.testing.capture_logs() as logs:
        async with anyio.create_task_group() as tg:
            fan.bind(tg)
            for event_id in range(3):
                fan.publish("notify_event", SOURCE, event_id)
            fan.publish("notify_error", SOURCE, 9)
            await fan.wait_delivered()
            fan.close()

    assert bad.calls == 4  # every notice reached it despite the raises
    assert good.got == [("event", 0), ("event", 1), ("event", 2), ("error", 9)]
    assert len([e for e in logs if e["event"] == "observer_failed"]) == 3
    assert fan.failures == 3


# -- slow observers --------------------------------------------------------------------------


async def test_slow_async_observer_delays_neither_publisher_nor_others() -> None:
    clock = VirtualClock()
    fan = Fanout("pub", HAL_KINDS)
    fast_sync = Recorder(clock)
    fast_async = AsyncRecorder(clock)
    slow = AsyncRecorder(clock, delay_s=1.0)  # 1 s per notice; we publish every 10 ms
    for observer in (slow, fast_sync, fast_async):
        fan.add(observer)

    publish_times = [k * 10 * NS_PER_MS for k in range(1, 6)]
    async with anyio.create_task_group() as tg, clock.autojump():
        fan.bind(tg)
        for k, t in enumerate(publish_times):
            await clock.sleep_until(t)
            fan.publish("notify_event", SOURCE, k)
            assert clock.now_ns() == t  # publish returned at once
        # Every fast observer got every notice at its publish time, before the slow
        # observer was done with even the first one.
        assert slow.got == []
        await fan.wait_delivered()
        fan.close()

    ids = [("event", k) for k in range(5)]
    assert fast_sync.got == ids
    assert fast_sync.times == publish_times
    assert fast_async.got == ids
    assert fast_async.times == publish_times
    # The slow observer worked through its mailbox in order, one second each.
    assert slow.got == ids
    assert slow.times == [publish_times[0] + (k + 1) * NS_PER_S for k in range(5)]


async def test_per_observer_order_is_kept_across_kinds() -> None:
    clock = VirtualClock()
    fan = Fanout("pub", HAL_KINDS)
    mixed_delays = [AsyncRecorder(clock, delay_s=d) for d in (0.0, 0.003, 0.001)]
    sync = Recorder()
    for observer in (*mixed_delays, sync):
        fan.add(observer)
    sent = [("event" if k % 3 else "error", k) for k in range(50)]
    async with anyio.create_task_group() as tg, clock.autojump():
        fan.bind(tg)
        for kind, ident in sent:
            fan.publish(f"notify_{kind}", SOURCE, ident)
            if ident % 7 == 0:
                await clock.sleep(0.002)
        await fan.wait_delivered()
        fan.close()
    for observer in (*mixed_delays, sync):
        assert observer.got == sent


class MixedObserver:
    """Sync notify_event, async notify_error: both go through one mailbox, in order."""

    def __init__(self) -> None:
        self.got: list[tuple[str, int]] = []

    def notify_event(self, source: object, event_id: int) -> None:
        self.got.append(("event", event_id))

    async def notify_error(self, source: object, error_id: int) -> None:
        await anyio.lowlevel.checkpoint()
        self.got.append(("error", error_id))


async def test_observer_with_mixed_sync_and_async_methods_keeps_order() -> None:
    fan = Fanout("pub", HAL_KINDS)
    observer = MixedObserver()
    fan.add(observer)
    async with anyio.create_task_group() as tg:
        fan.bind(tg)
        fan.publish("notify_error", SOURCE, 1)
        fan.publish("notify_event", SOURCE, 2)
        fan.publish("notify_error", SOURCE, 3)
        assert observer.got == []  # queued, not inline
        await fan.wait_delivered()
        fan.close()
    assert observer.got == [("error", 1), ("event", 2), ("error", 3)]


# -- overflow ---------------------------------------------------------------------------------


async def test_mailbox_overflow_drops_oldest_counted_and_logged() -> None:
    fan = Fanout("pub", HAL_KINDS, mailbox_size=2)
    observer = AsyncRecorder()
    fan.add(observer)
    with structlog.testing.capture_logs() as logs:
        for event_id in range(5):  # no task group yet: nothing is consumed
            fan.publish("notify_event", SOURCE, event_id)
    assert fan.stats().overflowed == 3
    overflow = [e for e in logs if e["event"] == "observer_mailbox_overflow"]
    assert len(overflow) == 1  # logged when the episode starts
    assert overflow[0]["log_level"] == "warning"
    assert overflow[0]["owner"] == "pub"
    assert overflow[0]["overflowed_total"] == 1
    assert "AsyncRecorder" in overflow[0]["observer"]

    async with anyio.create_task_group() as tg:
        fan.bind(tg)
        await fan.wait_delivered()
        fan.close()
    assert observer.got == [("event", 3), ("event", 4)]  # the newest survive


async def test_mailbox_overflow_logs_once_per_episode() -> None:
    """A stuck observer must not flood the log from the publisher's (hot) path."""
    fan = Fanout("pub", HAL_KINDS, mailbox_size=4)
    stuck = anyio.Event()
    got: list[int] = []

    async def blocked(source: object, event_id: int) -> None:
        got.append(event_id)
        await stuck.wait()

    class Stuck:
        notify_event = staticmethod(blocked)

    fan.add(Stuck())
    with structlog.testing.capture_logs() as logs:
        async with anyio.create_task_group() as tg:
            fan.bind(tg)
            fan.publish("notify_event", SOURCE, 0)
            await anyio.wait_all_tasks_blocked()  # the observer is stuck on notice 0
            for event_id in range(1, 1001):
                fan.publish("notify_event", SOURCE, event_id)
            assert fan.stats().overflowed == 996
            assert len([e for e in logs if e["event"] == "observer_mailbox_overflow"]) == 1
            stuck.set()
            await fan.wait_delivered()
            fan.close()
    assert got == [0, 997, 998, 999, 1000]


# -- re-entrancy --------------------------------------------------------------------------------


def test_observer_removing_itself_during_publish_is_safe() -> None:
    fan = Fanout("pub", HAL_KINDS)
    log: list[str] = []

    class Quitter:
        def notify_event(self, source: object, event_id: int) -> None:
            log.append(f"quitter {event_id}")
            fan.remove(self)

    first, quitter, last = Recorder(), Quitter(), Recorder()
    for observer in (first, quitter, last):
        fan.add(observer)
    fan.publish("notify_event", SOURCE, 1)
    fan.publish("notify_event", SOURCE, 2)
    assert log == ["quitter 1"]
    assert first.got == last.got == [("event", 1), ("event", 2)]
    assert quitter not in fan
    assert len(fan) == 2


def test_observer_adding_another_during_publish_is_safe() -> None:
    fan = Fanout("pub", HAL_KINDS)
    newcomer = Recorder()

    class Recruiter(Recorder):
        def notify_event(self, source: object, event_id: int) -> None:
            super().notify_event(source, event_id)
            if newcomer not in fan:
                fan.add(newcomer)

    recruiter, tail = Recruiter(), Recorder()
    fan.add(recruiter)
    fan.add(tail)
    fan.publish("notify_event", SOURCE, 1)
    # The in-flight notice goes to the observers registered when it was published.
    assert newcomer.got == []
    assert tail.got == [("event", 1)]
    fan.publish("notify_event", SOURCE, 2)
    assert newcomer.got == [("event", 2)]
    assert recruiter.got == tail.got == [("event", 1), ("event", 2)]
    assert fan.observers == (recruiter, tail, newcomer)


def test_observer_removing_another_during_publish() -> None:
    fan = Fanout("pub", HAL_KINDS)
    victim = Recorder()

    class Remover(Recorder):
        def notify_event(self, source: object, event_id: int) -> None:
            super().notify_event(source, event_id)
            if victim in fan:
                fan.remove(victim)

    remover = Remover()
    fan.add(remover)
    fan.add(victim)
    fan.publish("notify_event", SOURCE, 1)
    # Copy-on-write: the notice being delivered still reaches the removed observer...
    assert victim.got == [("event", 1)]
    fan.publish("notify_event", SOURCE, 2)
    # ...but nothing published after the removal does.
    assert victim.got == [("event", 1)]
    assert remover.got == [("event", 1), ("event", 2)]


async def test_async_observer_removing_itself_gets_what_was_queued_before() -> None:
    fan = Fanout("pub", HAL_KINDS)
    got: list[int] = []

    class AsyncQuitter:
        async def notify_event(self, source: object, event_id: int) -> None:
            got.append(event_id)
            if self in fan:
                fan.remove(self)

    fan.add(AsyncQuitter())
    async with anyio.create_task_group() as tg:
        fan.bind(tg)
        for event_id in (1, 2, 3):  # all queued before the first delivery
            fan.publish("notify_event", SOURCE, event_id)
        await anyio.wait_all_tasks_blocked()
        fan.publish("notify_event", SOURCE, 4)  # after the removal
        await anyio.wait_all_tasks_blocked()
        # No fan.close(): the removed observer's task ended by itself, or this
        # task group would never exit.
    assert got == [1, 2, 3]
    assert len(fan) == 0


async def test_removed_async_observer_task_ends() -> None:
    fan = Fanout("pub", HAL_KINDS)
    observer = AsyncRecorder()
    fan.add(observer)
    async with anyio.create_task_group() as tg:
        fan.bind(tg)
        fan.publish("notify_event", SOURCE, 1)
        fan.remove(observer)
        fan.publish("notify_event", SOURCE, 2)
    assert observer.got == [("event", 1)]


async def test_fanout_can_be_rebound_after_close() -> None:
    """An owner that is entered again (a second ``async with``) keeps its async observers."""
    fan = Fanout("pub", HAL_KINDS)
    observer = AsyncRecorder()
    fan.add(observer)
    for round_ in range(2):
        # fail_after only turns a hang (the bug this guards against) into a failure.
        with anyio.fail_after(10):
            async with anyio.create_task_group() as tg:
                fan.bind(tg)
                await anyio.wait_all_tasks_blocked()  # the mailbox task is up and waiting
                fan.publish("notify_event", SOURCE, round_)
                await fan.wait_delivered()
                fan.close()
        fan.bind(None)
    assert observer.got == [("event", 0), ("event", 1)]


# -- registration ---------------------------------------------------------------------------


def test_duplicate_add_and_unknown_remove_raise() -> None:
    fan = Fanout("pub", HAL_KINDS)
    observer = Recorder()
    fan.add(observer)
    with pytest.raises(BadParameterError) as info:
        fan.add(observer)
    assert info.value.parameter == "observer"
    assert len(fan) == 1

    with pytest.raises(BadParameterError) as info:
        fan.remove(Recorder())
    assert info.value.parameter == "observer"

    fan.remove(observer)
    with pytest.raises(BadParameterError):
        fan.remove(observer)
    assert len(fan) == 0


@pytest.mark.parametrize("bad", [None, object(), 42])
def test_add_rejects_non_observers(bad: object) -> None:
    fan = Fanout("pub", HAL_KINDS)
    with pytest.raises(BadParameterError) as info:
        fan.add(bad)
    assert info.value.parameter == "observer"
    assert len(fan) == 0


def test_plain_callable_is_refused_where_two_kinds_are_published() -> None:
    fan = Fanout("pub", HAL_KINDS)
    with pytest.raises(BadParameterError, match="observer"):
        fan.add(lambda source, ident: None)


async def test_objects_and_plain_callables_for_a_single_kind() -> None:
    fan = Fanout("timer", ("notify_timer",))
    got: dict[str, list[object]] = {}

    def record(name: str, value: object) -> None:
        got.setdefault(name, []).append(value)

    def plain_function(timer: object) -> None:
        record("function", timer)

    async def async_function(timer: object) -> None:
        await anyio.lowlevel.checkpoint()
        record("async function", timer)

    class SyncObserver:
        def notify_timer(self, timer: object) -> None:
            record("sync object", timer)

    class AsyncObserver:
        async def notify_timer(self, timer: object) -> None:
            record("async object", timer)

    class AsyncCallable:
        async def __call__(self, timer: object) -> None:
            record("async callable", timer)

    class SyncCallable:
        def __call__(self, timer: object) -> None:
            record("sync callable", timer)

    queue = ObserverQueue()
    observers: list[object] = [
        plain_function,
        async_function,
        SyncObserver(),
        AsyncObserver(),
        AsyncCallable(),
        SyncCallable(),
        lambda timer: record("lambda", timer),
    ]
    for observer in observers:
        fan.add(observer)
    fan.add(queue)  # has notify_timer: used as an object, not called

    tokens = [object(), object()]
    async with anyio.create_task_group() as tg:
        fan.bind(tg)
        for token in tokens:
            fan.publish("notify_timer", token)
        await fan.wait_delivered()
        fan.close()

    assert got == {
        name: tokens
        for name in (
            "function",
            "async function",
            "sync object",
            "async object",
            "async callable",
            "sync callable",
            "lambda",
        )
    }
    assert len(queue) == 0  # notify_timer of a queue reads timer.last_tick: none here


def test_kinds_an_observer_lacks_are_skipped() -> None:
    fan = Fanout("pub", HAL_KINDS)

    class EventsOnly:
        def __init__(self) -> None:
            self.got: list[int] = []

        def notify_event(self, source: object, event_id: int) -> None:
            self.got.append(event_id)

    observer = EventsOnly()
    fan.add(observer)
    fan.publish("notify_error", SOURCE, 1)
    fan.publish("notify_event", SOURCE, 2)
    assert observer.got == [2]
    assert fan.failures == 0


def test_bound_methods_compare_by_instance_and_function() -> None:
    fan = Fanout("timer", ("notify_timer",))

    class Controller:
        def __init__(self) -> None:
            self.ticks = 0

        def on_tick(self, timer: object) -> None:
            self.ticks += 1

    a, b = Controller(), Controller()
    fan.add(a.on_tick)
    # A fresh bound-method object of the same instance and function is the same observer.
    assert a.on_tick is not a.on_tick
    assert a.on_tick in fan
    assert b.on_tick not in fan
    with pytest.raises(BadParameterError):
        fan.add(a.on_tick)

    fan.add(b.on_tick)  # same function, other instance: a different observer
    assert len(fan) == 2
    fan.publish("notify_timer", object())
    assert (a.ticks, b.ticks) == (1, 1)

    fan.remove(a.on_tick)
    assert a.on_tick not in fan
    assert b.on_tick in fan
    fan.publish("notify_timer", object())
    assert (a.ticks, b.ticks) == (1, 2)
    with pytest.raises(BadParameterError):
        fan.remove(a.on_tick)


def test_equal_but_distinct_objects_are_distinct_observers() -> None:
    class AlwaysEqual(Recorder):
        def __eq__(self, other: object) -> bool:
            return True

        __hash__ = None  # type: ignore[assignment]

    fan = Fanout("pub", HAL_KINDS)
    first, second = AlwaysEqual(), AlwaysEqual()
    fan.add(first)
    fan.add(second)  # identity, not ==
    fan.remove(second)
    assert fan.observers == (first,)


async def test_async_observer_ahead_of_a_plain_one_runs_before_the_task_it_wakes() -> None:
    """Delivery keeps registration order across mailboxes: a task that a plain observer
    wakes must not run before an async observer registered ahead of it has started on the
    same notice (the shared wake-up used to be set only after the plain observers ran)."""
    fan = Fanout("pub", HAL_KINDS)
    order: list[str] = []
    woken = anyio.Event()

    class Async:
        async def notify_event(self, source: object, event_id: int) -> None:
            order.append("async observer")

        async def notify_error(self, source: object, error_id: int) -> None:
            pass

    class Plain:
        def notify_event(self, source: object, event_id: int) -> None:
            woken.set()

        def notify_error(self, source: object, error_id: int) -> None:
            pass

    fan.add(Async())
    fan.add(Plain())

    async def waiter() -> None:
        await woken.wait()
        order.append("woken task")

    async with anyio.create_task_group() as tg:
        fan.bind(tg)
        tg.start_soon(waiter)
        for _ in range(3):
            await anyio.lowlevel.checkpoint()
        fan.publish("notify_event", SOURCE, 1)
        await fan.wait_delivered()
        await woken.wait()
        for _ in range(3):
            await anyio.lowlevel.checkpoint()
        fan.close()
    assert order == ["async observer", "woken task"]


def test_many_observers_registered_between_notifications_all_get_them_in_order() -> None:
    """Registration extends the delivery tuples of a few observers at once and leaves those
    of many to be rebuilt; either way every observer hears every later notification, in
    registration order, and ``direct`` (the components' inline path) agrees."""
    fan = Fanout("pub", HAL_KINDS)
    order: list[int] = []

    class Numbered:
        def __init__(self, number: int) -> None:
            self.number = number

        def notify_event(self, source: object, event_id: int) -> None:
            order.append(self.number)

    observers = [Numbered(i) for i in range(80)]
    for observer in observers[:10]:
        fan.add(observer)
    fan.publish("notify_event", SOURCE, 1)
    assert order == list(range(10))
    for observer in observers[10:]:  # past the append limit
        fan.add(observer)
    order.clear()
    fan.publish("notify_event", SOURCE, 2)
    assert order == list(range(80))
    direct = fan.direct.get("notify_event")
    assert direct is not None and len(direct[0]) == 80 and direct[1] is False
