"""Nothing is lost untold: every notice an async observer does not get is counted, logged
and reported to it; ticks carry their identity; bad observers and periods are refused."""

from __future__ import annotations

import math
from typing import Any

import anyio
import pytest
import structlog.testing

import openel_async.component
import openel_async.timer
from openel_async import (
    Actuator,
    ActuatorDevice,
    DeviceContext,
    DeviceInfo,
    DeviceKind,
    EventTimer,
    MonotonicClock,
    ObserverQueue,
    Request,
    VirtualClock,
)
from openel_async.errors import BadParameterError
from openel_async.observers import ErrorNotice, EventNotice, TimerTick
from openel_async.stats import MailboxStats, ObserverStats
from openel_async.timer import MAX_PERIOD_MS, MAX_PERIOD_NS

MS = 1_000_000
MAILBOX = 1024  # the Fanout's default mailbox size


class EventSource(ActuatorDevice):
    """A driver that only posts events and errors through the context it keeps."""

    info = DeviceInfo(kind=DeviceKind.MOTOR, vendor_name="Test", product_name="EventSource")
    reports_completion = True

    def __init__(self) -> None:
        self.ctx: DeviceContext | None = None

    async def open(self, ctx: DeviceContext) -> None:
        self.ctx = ctx

    async def command(self, request: Request, value: float) -> None:
        pass

    async def read(self, request: Request) -> float:
        return 0.0


class StuckHALObserver:
    """Async HALObserver that takes the notice; stuck on the first until released."""

    def __init__(self) -> None:
        self.release = anyio.Event()
        self.notices: list[EventNotice | ErrorNotice] = []

    async def notify_event(
        self, source: object, event_id: int, notice: EventNotice | None = None
    ) -> None:
        assert notice is not None and notice.event_id == event_id and notice.source is source
        self.notices.append(notice)
        await self.release.wait()

    async def notify_error(
        self, source: object, error_id: int, notice: ErrorNotice | None = None
    ) -> None:
        assert notice is not None and notice.error_id == error_id
        self.notices.append(notice)
        await self.release.wait()


def _post(ctx: DeviceContext, k: int) -> None:
    """Notification k: an event on even k, an error on odd k (ids = k)."""
    if k % 2:
        ctx.post_error(k)
    else:
        ctx.post_event(k)


def _check_conservation(stats: MailboxStats) -> None:
    assert stats.queued == stats.delivered + stats.pending + stats.lost


# -- point 1: a mailbox that overflows tells its observer how much it missed ------------------


async def test_async_hal_observer_is_told_how_many_events_and_errors_it_missed() -> None:
    source = EventSource()
    observer = StuckHALObserver()
    with structlog.testing.capture_logs() as logs:
        async with Actuator(source) as actuator:
            actuator.add_observer(observer)
            assert source.ctx is not None
            _post(source.ctx, 0)
            await anyio.wait_all_tasks_blocked()  # the observer is stuck on notice 0
            for k in range(1, 1100):
                _post(source.ctx, k)
            stats = actuator.observer_stats
            assert (stats.published, stats.overflowed) == (1100, 1100 - 1 - MAILBOX)
            (mailbox,) = stats.mailboxes
            assert mailbox.observer is observer
            assert (mailbox.queued, mailbox.pending, mailbox.overflowed) == (1100, MAILBOX, 75)
            observer.release.set()
        final = actuator.observer_stats

    kinds = [type(n) for n in observer.notices]
    ids = [n.event_id if isinstance(n, EventNotice) else n.error_id for n in observer.notices]
    assert ids == [0, *range(76, 1100)]
    assert kinds == [EventNotice if k % 2 == 0 else ErrorNotice for k in ids]
    # The first notice after the gap says how many came before it and never arrived.
    assert [n.missed for n in observer.notices[:3]] == [0, 75, 0]
    assert len(observer.notices) + sum(n.missed for n in observer.notices) == 1100
    (mailbox,) = final.mailboxes
    assert (mailbox.delivered, mailbox.pending, mailbox.lost, final.abandoned) == (1025, 0, 75, 0)
    _check_conservation(mailbox)
    overflow = [e for e in logs if e["event"] == "observer_mailbox_overflow"]
    missed = [e for e in logs if e["event"] == "observer_missed"]
    assert len(overflow) == 1 and overflow[0]["log_level"] == "warning"
    assert [(e["missed"], e["log_level"]) for e in missed] == [(75, "warning")]


async def test_spec_signature_async_observer_gets_its_losses_logged_and_counted() -> None:
    """An observer without the notice argument still hears of its losses: in the log, with
    the count, when delivery resumes, and in observer_stats."""
    source = EventSource()
    release = anyio.Event()
    got: list[int] = []

    class SpecObserver:
        async def notify_event(self, source: object, event_id: int) -> None:
            got.append(event_id)
            await release.wait()

    with structlog.testing.capture_logs() as logs:
        async with Actuator(source) as actuator:
            actuator.add_observer(SpecObserver())
            assert source.ctx is not None
            for k in range(MAILBOX + 11):  # 1 in flight, MAILBOX queued, 10 dropped
                source.ctx.post_event(k)
                if k == 0:
                    await anyio.wait_all_tasks_blocked()
            release.set()
        stats = actuator.observer_stats
    assert got == [0, *range(11, MAILBOX + 11)]
    assert stats.overflowed == 10 and stats.lost == 10
    assert [e["missed"] for e in logs if e["event"] == "observer_missed"] == [10]


async def test_async_timer_observer_is_told_how_many_ticks_it_missed(
    virtual_clock: VirtualClock,
) -> None:
    release = anyio.Event()
    done = anyio.Event()
    ticks: list[TimerTick] = []

    def counter(timer: EventTimer) -> None:
        tick = timer.last_tick
        assert tick is not None
        if tick.index == 1100:
            release.set()

    async def slow(timer: EventTimer, tick: TimerTick | None = None) -> None:
        assert tick is not None
        ticks.append(tick)
        await release.wait()
        if tick.index == 1100:
            timer.stop_timer()
            done.set()

    async with EventTimer(10, clock=virtual_clock) as timer:
        timer.add_observer(counter)
        timer.add_observer(slow)
        timer.start_timer()
        await done.wait()
        stats = timer.observer_stats
    assert timer.stats.ticks == stats.published == 1100
    assert [t.index for t in ticks] == [1, *range(77, 1101)]
    assert [t.missed for t in ticks[:3]] == [0, 75, 0]
    assert len(ticks) + sum(t.missed for t in ticks) == 1100
    assert (stats.overflowed, stats.discarded, stats.abandoned) == (75, 0, 0)
    _check_conservation(stats.mailboxes[0])


# -- point 2: each notification carries the tick it is about ----------------------------------


async def test_slow_async_timer_observer_knows_which_tick_it_handles(
    virtual_clock: VirtualClock,
) -> None:
    """On a 10 ms timer an observer taking 25 ms per tick runs ever further behind; each
    call still gets its own tick (index, deadline, time, lateness), not the latest one."""
    handled: list[tuple[TimerTick, int]] = []  # (tick given, last_tick index when run)
    done = anyio.Event()
    start = virtual_clock.now_ns()

    class Slow:
        async def notify_timer(self, timer: EventTimer, tick: TimerTick | None = None) -> None:
            assert tick is not None and timer.last_tick is not None
            handled.append((tick, timer.last_tick.index))
            await virtual_clock.sleep(0.025)
            if len(handled) == 20:
                done.set()

    async with EventTimer(10, clock=virtual_clock) as timer:
        timer.add_observer(Slow())
        timer.start_timer()
        await done.wait()
        timer.stop_timer()  # (tick 21, already being handled, finishes)

    ticks = [tick for tick, _ in handled[:20]]
    assert [t.index for t in ticks] == list(range(1, 21))
    assert [t.deadline_ns for t in ticks] == [start + k * 10 * MS for k in range(1, 21)]
    assert all(t.time_ns == t.deadline_ns and t.lateness_ns == 0 for t in ticks)
    assert all(t.missed == t.missed_ticks == 0 and t.timer is timer for t in ticks)
    # What last_tick said while the observer ran: the timer was already far ahead.
    assert handled[19][1] > 40


async def test_tick_argument_is_the_same_object_for_every_observer(
    virtual_clock: VirtualClock,
) -> None:
    """One TimerTick per tick, shared: plain callables and ObserverQueues get it too."""
    seen: dict[str, list[TimerTick]] = {"plain": [], "async": []}
    queue = ObserverQueue()
    done = anyio.Event()

    def plain(timer: EventTimer, tick: TimerTick | None = None) -> None:
        assert tick is not None and tick is timer.last_tick
        seen["plain"].append(tick)

    async def later(timer: EventTimer, tick: TimerTick | None = None) -> None:
        assert tick is not None
        seen["async"].append(tick)
        if tick.index == 3:
            done.set()

    async with EventTimer(1, clock=virtual_clock) as timer:
        for observer in (plain, queue, later):
            timer.add_observer(observer)
        timer.start_timer()
        await done.wait()
        timer.stop_timer()
    queued = queue.drain()
    assert [t.index for t in seen["plain"]] == [1, 2, 3]
    assert all(a is b is c for a, b, c in zip(seen["plain"], seen["async"], queued, strict=True))


# -- point 5: a class (or an uncallable observer) is refused at add time ----------------------


class HALObserverClass:
    def notify_event(self, source: object, event_id: int) -> None:
        pass

    def notify_error(self, source: object, error_id: int) -> None:
        pass


class TimerObserverClass:
    def notify_timer(self, timer: object) -> None:
        pass


async def test_component_refuses_an_observer_class() -> None:
    async with Actuator(EventSource()) as actuator:
        with pytest.raises(BadParameterError) as info:
            actuator.add_observer(HALObserverClass)
        assert info.value.parameter == "observer"
        assert "HALObserverClass()" in str(info.value) and "class" in str(info.value)
        assert actuator.observers == ()
        actuator.add_observer(HALObserverClass())  # an instance is fine


@pytest.mark.parametrize("cls", [TimerObserverClass, HALObserverClass, ObserverQueue])
def test_timer_refuses_an_observer_class(cls: type) -> None:
    timer = EventTimer(10)
    with pytest.raises(BadParameterError) as info:
        timer.add_observer(cls)
    assert info.value.parameter == "observer"
    assert f"{cls.__name__}()" in str(info.value)
    assert timer.observers == ()


class NoArgs:
    def notify_event(self) -> None:
        pass


class KeywordOnly:
    async def notify_error(self, source: object, error_id: int, *, extra: int) -> None:
        pass


async def test_component_refuses_methods_that_cannot_take_the_spec_arguments() -> None:
    async with Actuator(EventSource()) as actuator:
        for bad in (NoArgs(), KeywordOnly()):
            with pytest.raises(BadParameterError) as info:
                actuator.add_observer(bad)
            assert info.value.parameter == "observer"
            assert "(source, event_id)" in str(info.value) or "(source, error_id)" in str(
                info.value
            )
        assert actuator.observers == ()


@pytest.mark.parametrize(
    "bad",
    [lambda: None, lambda timer, tick, more: None, TimerObserverClass().notify_timer.__func__],
)
def test_timer_refuses_callables_that_cannot_take_the_timer(bad: Any) -> None:
    # (The unbound function needs (self, timer): one argument is not enough.)
    timer = EventTimer(10)
    with pytest.raises(BadParameterError) as info:
        timer.add_observer(bad)
    assert info.value.parameter == "observer"
    assert "notify_timer(timer)" in str(info.value)
    assert timer.observers == ()


async def test_observers_that_can_take_the_notice_get_it_others_do_not(
    virtual_clock: VirtualClock,
) -> None:
    got: list[tuple[Any, ...]] = []
    async with EventTimer(10, clock=virtual_clock) as timer:
        timer.add_observer(lambda timer: got.append(("spec", timer)))
        timer.add_observer(lambda *args: got.append(("star", *args)))
        timer.add_observer(lambda timer, tick=None: got.append(("default", timer, tick)))
        timer.start_timer()
        await virtual_clock.sleep(0.015)
        timer.stop_timer()
    tick = timer.last_tick
    assert tick is not None and tick.index == 1
    assert got == [("spec", timer), ("star", timer, tick), ("default", timer, tick)]


# -- point 16: what async observers do not get at exit is counted and reported ----------------


class ForeverStuck:
    def __init__(self) -> None:
        self.started: list[int] = []

    async def notify_event(self, source: object, event_id: int) -> None:
        self.started.append(event_id)
        await anyio.sleep_forever()


async def test_component_exit_counts_and_logs_what_async_observers_never_got(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(openel_async.component, "EXIT_DRAIN_S", 0.01)
    source = EventSource()
    stuck, fine = ForeverStuck(), StuckHALObserver()
    fine.release.set()
    with structlog.testing.capture_logs() as logs:
        async with Actuator(source) as actuator:
            actuator.add_observer(stuck)
            actuator.add_observer(fine)
            assert source.ctx is not None
            for k in range(20):
                source.ctx.post_event(k)
    stats = actuator.observer_stats
    assert stuck.started == [0]
    assert len(fine.notices) == 20
    assert (stats.published, stats.abandoned, stats.lost) == (20, 20, 20)
    stuck_stats, fine_stats = stats.mailboxes
    assert (stuck_stats.queued, stuck_stats.delivered, stuck_stats.abandoned) == (20, 0, 20)
    assert (fine_stats.delivered, fine_stats.lost) == (20, 0)
    for mailbox in stats.mailboxes:
        _check_conservation(mailbox)
    abandoned = [e for e in logs if e["event"] == "observer_notices_abandoned"]
    assert len(abandoned) == 1
    assert abandoned[0]["abandoned"] == 20 and abandoned[0]["log_level"] == "warning"
    assert "ForeverStuck" in abandoned[0]["observer"]


async def test_exit_counts_what_a_removed_async_observer_had_still_to_handle(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A removed observer still gets what was queued before its removal; if the owner
    exits first, that is counted and logged like any other abandoned notice."""
    monkeypatch.setattr(openel_async.component, "EXIT_DRAIN_S", 0.01)
    source = EventSource()
    stuck = ForeverStuck()
    with structlog.testing.capture_logs() as logs:
        async with Actuator(source) as actuator:
            actuator.add_observer(stuck)
            assert source.ctx is not None
            for k in range(5):
                source.ctx.post_event(k)
            await anyio.wait_all_tasks_blocked()  # stuck on notice 0, 1..4 queued
            actuator.remove_observer(stuck)
            source.ctx.post_event(5)  # after the removal: not for it
    assert stuck.started == [0]
    stats = actuator.observer_stats
    assert (stats.published, stats.abandoned, stats.mailboxes) == (6, 5, ())
    abandoned = [e for e in logs if e["event"] == "observer_notices_abandoned"]
    assert [e["abandoned"] for e in abandoned] == [5]


async def test_component_exit_within_the_drain_time_abandons_nothing() -> None:
    source = EventSource()
    observer = StuckHALObserver()
    with structlog.testing.capture_logs() as logs:
        async with Actuator(source) as actuator:
            actuator.add_observer(observer)
            assert source.ctx is not None
            for k in range(20):
                source.ctx.post_event(k)
            observer.release.set()  # the observer finishes during the exit drain
    assert len(observer.notices) == 20
    assert actuator.observer_stats.abandoned == 0
    assert not [e for e in logs if e["event"] == "observer_notices_abandoned"]


async def test_timer_stop_and_exit_count_every_tick_not_delivered(
    virtual_clock: VirtualClock, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(openel_async.timer, "EXIT_DRAIN_S", 0.01)
    release = anyio.Event()
    five = anyio.Event()
    ticks: list[TimerTick] = []

    def counter(timer: EventTimer, tick: TimerTick | None = None) -> None:
        assert tick is not None
        if tick.index == 5:
            five.set()

    async def slow(timer: EventTimer, tick: TimerTick | None = None) -> None:
        assert tick is not None
        ticks.append(tick)
        if tick.index == 1:
            await release.wait()
        else:
            await anyio.sleep_forever()

    with structlog.testing.capture_logs() as logs:
        async with EventTimer(10, clock=virtual_clock) as timer:
            timer.add_observer(counter)
            timer.add_observer(slow)
            timer.start_timer()
            await five.wait()
            timer.stop_timer()  # ticks 2..5 are queued behind tick 1: discarded
            stats = timer.observer_stats
            assert (stats.discarded, stats.mailboxes[0].pending) == (4, 0)
            release.set()
            timer.start_timer()  # continues the index: next tick is 6
            while len(ticks) < 2:
                await virtual_clock.sleep(0.01)
            # Tick 6 tells it the four before it never came; then the observer hangs on
            # it and the exit abandons it, plus whatever ticks queued meanwhile.
    assert [(t.index, t.missed) for t in ticks] == [(1, 0), (6, 4)]
    stats = timer.observer_stats
    (mailbox,) = stats.mailboxes
    assert stats.discarded == 4 and stats.abandoned >= 1
    assert mailbox.delivered == 1
    _check_conservation(mailbox)
    assert mailbox.queued == timer.stats.ticks
    stopped = [e for e in logs if e["event"] == "timer_stopped"]
    assert stopped[0]["discarded"] == 4
    abandoned = [e for e in logs if e["event"] == "observer_notices_abandoned"]
    assert [e["abandoned"] for e in abandoned] == [stats.abandoned]


def test_observer_stats_are_public_and_start_at_zero() -> None:
    stats = EventTimer(10).observer_stats
    assert stats == ObserverStats(0, 0, 0, 0, 0, ())
    assert stats.lost == 0


# -- point 17: periods that cannot be represented are refused ---------------------------------


@pytest.mark.parametrize("period", [1.8e22, 10**400, MAX_PERIOD_MS * 1.000001, 2**62])
def test_unrepresentable_periods_are_refused_with_the_range(period: float) -> None:
    with pytest.raises(BadParameterError) as info:
        EventTimer(period)
    assert info.value.parameter == "period_ms"
    message = str(info.value)
    assert "period_ms" in message
    assert "2**62 ns" in message and f"{MAX_PERIOD_MS:.6g}" in message


async def test_set_event_period_refuses_an_unrepresentable_period(
    virtual_clock: VirtualClock,
) -> None:
    async with EventTimer(5, clock=virtual_clock) as timer:
        timer.start_timer()
        with pytest.raises(BadParameterError) as info:
            timer.set_event_period(1.8e22)
        assert info.value.parameter == "period_ms"
        assert timer.period_ns == 5 * MS
        timer.stop_timer()


async def test_longest_period_runs_on_the_real_clock_without_overflow() -> None:
    """At the largest allowed period the deadline still fits the clock (timerfd's int64
    nanoseconds): the timer arms and waits instead of dying with OverflowError."""
    assert math.isclose(MAX_PERIOD_MS * MS, MAX_PERIOD_NS)
    async with EventTimer(MAX_PERIOD_MS, clock=MonotonicClock()) as timer:
        assert timer.period_ns == MAX_PERIOD_NS
        timer.start_timer()
        await anyio.wait_all_tasks_blocked()  # the ticking task armed its deadline
        assert timer.stats.ticks == 0
        timer.stop_timer()


async def test_events_posted_outside_active_and_error_are_counted_not_lost_untold() -> None:
    """A driver posting after finalize (or before init) reaches no observer by the state
    machine; the notices used to vanish with a debug log only (issue 10 #1/#16)."""
    source = EventSource()
    got: list[int] = []

    class Plain:
        def notify_event(self, source: object, event_id: int) -> None:
            got.append(event_id)

        def notify_error(self, source: object, error_id: int) -> None:
            got.append(-error_id)

    async with Actuator(source) as actuator:
        actuator.add_observer(Plain())
        assert source.ctx is not None
        source.ctx.post_event(7)
        await actuator.finalize()
        source.ctx.post_event(8)
        source.ctx.post_error(9)
        stats = actuator.observer_stats
    assert got == [7]
    assert stats.unpublished == 2
    assert stats.lost == 0
