"""EventTimer: ticks its TimerObservers every period (milliseconds, as in the spec).

Deadlines are absolute (start + k x period), so lateness never accumulates into
drift. A tick that wakes a whole period or more late skips the periods it missed
instead of delivering them in a burst; both are counted in :attr:`EventTimer.stats`.
"""

from __future__ import annotations

import math
import weakref
from collections.abc import AsyncIterator
from dataclasses import dataclass
from enum import Enum
from types import TracebackType
from typing import Self

import anyio
import anyio.abc

from openel_async.logs import get_logger

from .clock import (
    NS_PER_MS,
    NS_PER_S,
    Clock,
    InlineScheduler,
    ScheduledCall,
    default_clock,
    realtime_scheduler,
)
from .errors import BadParameterError, StateError
from .fanout import Fanout
from .observers import ObserverQueue, TimerTick
from .stats import LatenessRecorder, LatenessSummary, ObserverStats

log = get_logger(__name__)

EXIT_DRAIN_S = 1.0
"""How long leaving ``async with timer`` waits for async observers (real seconds)."""


class TimerState(Enum):
    STOPPED = "Stopped"
    RUNNING = "Running"

    def __str__(self) -> str:
        return self.value


MAX_PERIOD_NS = 2**62
"""Longest period: about 146 years. Deadlines (clock time + period, in integer ns) must
stay within the signed 64-bit nanoseconds that timerfd and the clocks use."""
MAX_PERIOD_MS = MAX_PERIOD_NS / NS_PER_MS


def period_to_ns(period_ms: object, parameter: str = "period_ms") -> int:
    """Validate a period in milliseconds (int or float) and convert it to integer ns.

    Allowed: finite, > 0, rounding to 1 ns .. :data:`MAX_PERIOD_NS` (1e-6 .. ~4.6e12 ms).
    """
    allowed = (
        f"a finite number of milliseconds from 1e-6 to {MAX_PERIOD_MS:.6g} "
        "(1 ns to 2**62 ns, about 146 years)"
    )
    if isinstance(period_ms, bool) or not isinstance(period_ms, int | float):
        raise BadParameterError(parameter, period_ms, allowed)
    if isinstance(period_ms, float) and not math.isfinite(period_ms):
        raise BadParameterError(parameter, period_ms, allowed)
    if period_ms <= 0 or period_ms * NS_PER_MS > MAX_PERIOD_NS:
        raise BadParameterError(parameter, period_ms, allowed)
    period_ns = round(period_ms * NS_PER_MS)
    if period_ns < 1:
        raise BadParameterError(parameter, period_ms, allowed)
    return period_ns


@dataclass(frozen=True, slots=True)
class TimerStats:
    ticks: int
    """Ticks delivered."""
    late_ticks: int
    """Ticks delivered later than ``late_threshold_ns`` after their deadline."""
    missed_ticks: int
    """Periods skipped because a wake-up came a whole period or more late."""
    lateness: LatenessSummary
    last_lateness_ns: int
    """The last tick's lateness: its delivery time minus its deadline (start + index x period).

    Deadlines sit on an absolute grid, so lateness never accumulates into drift: this is
    the lateness of one tick, not a running total."""

    @property
    def drift_ns(self) -> int:
        """Deprecated alias of ``last_lateness_ns`` (the name promised a drift that an
        absolute-deadline timer does not have)."""
        return self.last_lateness_ns


class EventTimer:
    """The OpenEL EventTimer on anyio.

    Use it as an async context manager (it owns the ticking task), then
    ``start_timer()``; ``async for tick in timer`` iterates ticks.
    """

    def __init__(
        self,
        period_ms: float,
        *,
        clock: Clock | None = None,
        name: str = "timer",
        late_threshold_ms: float | None = None,
    ) -> None:
        self._period_ns = period_to_ns(period_ms)
        self._period_ms = period_ms
        self.clock: Clock = clock or default_clock()
        self.name = name
        self._late_threshold_ns = (
            period_to_ns(late_threshold_ms, "late_threshold_ms")
            if late_threshold_ms is not None
            else None
        )
        self._observers = Fanout(name, ("notify_timer",))
        self._tg: anyio.abc.TaskGroup | None = None
        self._scope: anyio.CancelScope | None = None
        self.state = TimerState.STOPPED
        self._last_tick: TimerTick | None = None
        self._tick_fields: tuple[int, int, int, int] | None = None
        self._lateness = LatenessRecorder()
        # Ticks delivered exactly at their deadline on the inline path (a lockstep clock),
        # not yet written into ``_lateness``: recorded as zeros when the statistics are read
        # or before the next late tick, so every tick is still counted, in order.
        self._on_time = 0
        self._ticks = 0
        self._ticks_before_reset = 0
        self._late = 0
        self._missed = 0
        self._drift = 0
        self._index = 0
        self._last_warning = -NS_PER_S
        self._inline: _InlineTicks | None = None
        self._log = log.bind(timer=name)

    # -- context -------------------------------------------------------------------
    async def __aenter__(self) -> Self:
        if self._tg is not None:
            raise StateError("__aenter__", "entered", ["a timer not yet entered"])
        self._tg = await anyio.create_task_group().__aenter__()
        self._observers.bind(self._tg)
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> bool | None:
        assert self._tg is not None
        if self.state is TimerState.RUNNING:
            self.stop_timer()
        # Let a running notify_timer finish (at most EXIT_DRAIN_S); one cut short by the
        # cancellation below is counted and logged (observer_stats.abandoned).
        await self._observers.drain(EXIT_DRAIN_S)
        tg, self._tg = self._tg, None
        self._observers.bind(None)
        tg.cancel_scope.cancel()
        return await tg.__aexit__(exc_type, exc, tb)

    @property
    def last_tick(self) -> TimerTick | None:
        """The latest tick delivered (None before the first one)."""
        fields = self._tick_fields
        if fields is not None:
            self._last_tick = TimerTick(self, *fields)
            self._tick_fields = None
        return self._last_tick

    @last_tick.setter
    def last_tick(self, tick: TimerTick | None) -> None:
        self._last_tick = tick
        self._tick_fields = None

    @property
    def last_tick_fields(self) -> tuple[int, int, int, int] | None:
        """The latest tick's ``(index, deadline_ns, time_ns, missed_ticks)`` without
        building its :class:`~openel_async.observers.TimerTick` (None before the first):
        for a tool that looks at the timer now and then (a recorder's statistics)."""
        fields = self._tick_fields
        if fields is not None:
            return fields
        tick = self._last_tick
        if tick is None:
            return None
        return (tick.index, tick.deadline_ns, tick.time_ns, tick.missed_ticks)

    # -- spec operations -------------------------------------------------------------
    @property
    def period_ms(self) -> float:
        return self._period_ms

    @property
    def period_ns(self) -> int:
        return self._period_ns

    def start_timer(self) -> None:
        """StartTimer: the first tick comes one period from now."""
        if self._tg is None:
            raise StateError("start_timer", "not entered", ["inside 'async with timer'"])
        if self.state is TimerState.RUNNING:
            raise StateError("start_timer", self.state, [TimerState.STOPPED])
        self.state = TimerState.RUNNING
        self._index = self.last_tick.index if self.last_tick else 0
        clock = self.clock
        if isinstance(clock, InlineScheduler):
            self._inline = _InlineTicks(self, clock)
        elif (scheduler := realtime_scheduler(clock)) is not None:
            # The real clock with timerfd: ticks from the loop's timerfd callback, no task.
            self._inline = _InlineTicks(self, scheduler)
        else:
            self._scope = anyio.CancelScope()
            self._tg.start_soon(self._run, self._scope)
        self._log.info("timer_started", period_ms=self._period_ms)

    def stop_timer(self) -> None:
        """StopTimer: no tick is delivered after this returns.

        Ticks queued for async observers and not yet delivered are discarded (counted in
        :meth:`observer_stats` and reported as ``missed`` with the observer's next tick);
        a notify_timer already running finishes (see :meth:`wait_idle`).
        """
        if self.state is not TimerState.RUNNING:
            raise StateError("stop_timer", self.state, [TimerState.RUNNING])
        self.state = TimerState.STOPPED
        if self._inline is not None:
            self._inline.cancel()
            self._inline = None
        if self._scope is not None:
            self._scope.cancel()
            self._scope = None
        discarded = self._observers.discard_pending()
        self._log.info("timer_stopped", ticks=self._ticks, missed=self._missed, discarded=discarded)

    def set_event_period(self, period_ms: float) -> None:
        """SetEventPeriod: takes effect from the next tick on, even while running."""
        self._period_ns = period_to_ns(period_ms)
        self._period_ms = period_ms

    def add_observer(self, observer: object) -> None:
        """AddObserver: a TimerObserver (plain or async notify_timer), or a callable(timer).

        ``notify_timer(timer, tick)`` (or ``f(timer, tick)``) also gets the
        :class:`TimerTick` being delivered. Refused (BadParameterError naming
        ``observer``): None, a class, an observer already registered, a callable that
        cannot be called with ``(timer)``.
        """
        self._observers.add(observer)

    def remove_observer(self, observer: object) -> None:
        """RemoveObserver."""
        self._observers.remove(observer)

    @property
    def observers(self) -> tuple[object, ...]:
        return self._observers.observers

    @property
    def observer_stats(self) -> ObserverStats:
        """Delivery to the observers: ticks published, failures, and every tick dropped
        on the way to an async observer (overflow, StopTimer, exit)."""
        return self._observers.stats()

    async def wait_idle(self) -> None:
        """Wait until async observers have finished handling the ticks delivered to them."""
        await self._observers.wait_delivered()

    # -- ticking ---------------------------------------------------------------------
    async def _run(self, scope: anyio.CancelScope) -> None:
        sleeper = self.clock.sleeper()
        tick = self._tick
        try:
            with scope:
                deadline = self.clock.now_ns() + self._period_ns
                while True:
                    await sleeper.sleep_until(deadline)
                    if scope.cancel_called:
                        # StopTimer ran while this wake-up was already due (woken but
                        # not yet scheduled): anyio does not cancel a task whose wait
                        # has completed, so honour "no tick after stop_timer" here.
                        return
                    deadline = tick(deadline)
        finally:
            sleeper.close()

    def _tick(self, deadline: int) -> int:
        """Deliver the tick due at ``deadline``; returns the next deadline.

        Deadlines are integers advanced by whole periods from the start, so they never
        drift; SetEventPeriod re-anchors at the tick after it was called.
        """
        period = self._period_ns
        now = self.clock.now_ns()
        lateness = now - deadline
        if self._on_time:
            self._record_on_time()
        self._lateness.record(lateness)
        missed = lateness // period if lateness >= period else 0
        if missed:
            deadline += missed * period
            self._missed += missed
            if now - self._last_warning >= NS_PER_S:
                self._last_warning = now
                self._log.warning("timer_missed_ticks", missed=missed, late_us=lateness // 1000)
        if lateness > (self._late_threshold_ns or period // 5):
            self._late += 1
        self._index += 1 + missed
        self._ticks += 1
        self._drift = now - deadline
        observers = self._observers
        if "notify_timer" in observers.wants_notice:
            tick = TimerTick(self, self._index, deadline, now, missed)
            self._last_tick = tick
            self._tick_fields = None
            observers.publish("notify_timer", self, notice=tick)
        else:
            # TimerTick is built when someone reads last_tick: plain observers that do
            # not look at it save its construction on every tick.
            self._tick_fields = (self._index, deadline, now, missed)
            observers.publish("notify_timer", self)
        return deadline + self._period_ns

    def _record_on_time(self) -> None:
        """Write the on-time ticks counted by ``_InlineTicks._fire`` into the lateness
        recorder as zeros (only the last ``window`` of them can stay in its ring)."""
        count, self._on_time = self._on_time, 0
        recorder = self._lateness
        kept = min(count, recorder.window)
        for _ in range(kept):
            recorder.record(0)
        recorder.count += count - kept

    # -- iteration and statistics ----------------------------------------------------
    def __aiter__(self) -> AsyncIterator[TimerTick]:
        return _TickIterator(self)

    @property
    def stats(self) -> TimerStats:
        if self._on_time:
            self._record_on_time()
        return TimerStats(
            ticks=self._ticks,
            late_ticks=self._late,
            missed_ticks=self._missed,
            lateness=self._lateness.summary(),
            last_lateness_ns=self._drift,
        )

    def reset_stats(self) -> None:
        self._lateness.reset()
        self._on_time = 0
        self._ticks_before_reset += self._ticks
        self._ticks = self._late = self._missed = 0

    @property
    def ticks_delivered(self) -> int:
        """Ticks delivered to the observers since the timer was made (``stats.ticks`` counts
        since the last :meth:`reset_stats`): a tool that looks at the timer now and then (a
        recorder) reads how many came in between without observing every tick."""
        return self._ticks_before_reset + self._ticks

    def __repr__(self) -> str:
        return f"EventTimer({self.name!r}, period_ms={self._period_ms}, {self.state})"


class _InlineTicks:
    """Ticks driven by an :class:`InlineScheduler` clock: one periodic callback delivers
    each tick and re-arms itself for the next, with no task of its own."""

    __slots__ = ("_call", "_deadline", "_now_ns", "_timer")

    def __init__(self, timer: EventTimer, clock: InlineScheduler) -> None:
        self._timer = timer
        self._now_ns = clock.now_ns
        self._deadline = clock.now_ns() + timer._period_ns
        self._call: ScheduledCall | None = clock.call_at(self._deadline, self._fire)

    def _fire(self) -> int | None:
        """Deliver the tick due at its deadline (the clock calls it then).  A tick exactly on
        time skips the lateness arithmetic of :meth:`EventTimer._tick` (no miss, not late,
        zero drift) and its zero lateness is recorded in bulk later."""
        timer = self._timer
        deadline = self._deadline
        observers = timer._observers
        if self._now_ns() != deadline or "notify_timer" in observers.wants_notice:
            deadline = timer._tick(deadline)
        else:
            timer._on_time += 1
            index = timer._index = timer._index + 1
            timer._ticks += 1
            timer._drift = 0
            timer._tick_fields = (index, deadline, deadline, 0)
            observers.publish("notify_timer", timer)
            deadline += timer._period_ns
        self._deadline = deadline
        # Re-armed by returning the next deadline, unless an observer stopped (and maybe
        # restarted) the timer during the tick.
        return deadline if timer._inline is self else None

    def cancel(self) -> None:
        if self._call is not None:
            self._call.cancel()
            self._call = None


class _TickIterator:
    """``async for tick in timer``: a private queue, unsubscribed when the loop ends."""

    def __init__(self, timer: EventTimer, maxsize: int = 64) -> None:
        self._queue = ObserverQueue(maxsize, name=f"{timer.name}-iter")
        timer.add_observer(self._queue)
        # Breaking out of ``async for`` drops the iterator: unsubscribe then.
        self._finalizer = weakref.finalize(self, _unsubscribe, timer, self._queue)

    def __aiter__(self) -> _TickIterator:
        return self

    async def __anext__(self) -> TimerTick:
        notice = await self._queue.get()
        assert isinstance(notice, TimerTick)
        return notice


def _unsubscribe(timer: EventTimer, queue: ObserverQueue) -> None:
    if queue in timer._observers:
        timer.remove_observer(queue)
