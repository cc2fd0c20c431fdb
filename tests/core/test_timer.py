"""EventTimer on the virtual clock: exact tick times, period changes, state errors,
missed-tick handling, lateness statistics and drift."""

from __future__ import annotations

import itertools
import math
import random
from collections.abc import Iterable, Iterator
from typing import Any

import anyio
import pytest
import structlog.testing

from openel_async.clock import NS_PER_MS, NS_PER_S, Clock, MonotonicClock, Sleeper, VirtualClock
from openel_async.errors import BadParameterError, StateError
from openel_async.observers import ObserverQueue, TimerObserver, TimerTick
from openel_async.stats import LatenessRecorder, LatenessSummary, percentile
from openel_async.timer import EventTimer, TimerState, TimerStats, period_to_ns

# -- helpers ------------------------------------------------------------------------------


class TickLog:
    """A sync TimerObserver keeping every tick and the clock time it arrived at."""

    def __init__(self, clock: Clock, until: int | None = None) -> None:
        self.clock = clock
        self.ticks: list[TimerTick] = []
        self.arrivals: list[int] = []
        self.until = until
        self.done = anyio.Event()

    def notify_timer(self, timer: EventTimer) -> None:
        assert timer.last_tick is not None
        self.ticks.append(timer.last_tick)
        self.arrivals.append(self.clock.now_ns())
        if self.until is not None and len(self.ticks) >= self.until:
            self.done.set()

    @property
    def times(self) -> list[int]:
        return [t.time_ns for t in self.ticks]

    @property
    def indexes(self) -> list[int]:
        return [t.index for t in self.ticks]


class LateClock:
    """A Clock on a VirtualClock whose sleepers wake late by scripted amounts (ns).

    Each ``sleeper().sleep_until`` takes the next lateness from the script (0 once it
    runs out), as a real timer would under load.
    """

    def __init__(self, inner: VirtualClock, lateness: Iterable[int]) -> None:
        self.inner = inner
        self._lateness: Iterator[int] = iter(lateness)
        self.sleepers_closed = 0

    def now_ns(self) -> int:
        return self.inner.now_ns()

    async def sleep_until(self, deadline_ns: int) -> None:
        await self.inner.sleep_until(deadline_ns)

    def sleeper(self) -> Sleeper:
        return _LateSleeper(self)


class _LateSleeper:
    def __init__(self, clock: LateClock) -> None:
        self._clock = clock

    async def sleep_until(self, deadline_ns: int) -> None:
        late = next(self._clock._lateness, 0)
        await self._clock.inner.sleep_until(deadline_ns + late)

    def close(self) -> None:
        self._clock.sleepers_closed += 1


def _grid(start: int, period: int, count: int, first: int = 1) -> list[int]:
    return [start + k * period for k in range(first, first + count)]


# -- ticking on the grid ---------------------------------------------------------------------


async def test_ticks_arrive_exactly_on_the_grid(virtual_clock: VirtualClock) -> None:
    await virtual_clock.sleep(0.123)  # start off a round number
    start = virtual_clock.now_ns()
    async with EventTimer(10, clock=virtual_clock, name="t10") as timer:
        ticks = TickLog(virtual_clock, until=20)
        timer.add_observer(ticks)
        timer.start_timer()
        assert timer.state is TimerState.RUNNING
        await ticks.done.wait()
        timer.stop_timer()
        assert timer.state is TimerState.STOPPED

    expected = _grid(start, 10 * NS_PER_MS, 20)
    assert ticks.times == expected
    assert ticks.arrivals == expected
    assert [t.deadline_ns for t in ticks.ticks] == expected
    assert ticks.indexes == list(range(1, 21))
    assert all(t.missed_ticks == 0 and t.lateness_ns == 0 and t.timer is timer for t in ticks.ticks)
    stats = timer.stats
    assert (stats.ticks, stats.late_ticks, stats.missed_ticks, stats.last_lateness_ns) == (
        20,
        0,
        0,
        0,
    )
    assert stats.lateness.count == 20
    assert stats.lateness.max_ns == stats.lateness.p99_ns == stats.lateness.p50_ns == 0


class _Peek:
    """A plain TimerObserver that does not take the tick notice (no TimerTick is built)
    and reads ``last_tick_fields`` at each tick."""

    def __init__(self) -> None:
        self.fields: list[tuple[int, int, int, int] | None] = []

    def notify_timer(self, timer: EventTimer) -> None:
        self.fields.append(timer.last_tick_fields)


async def test_last_tick_fields_match_last_tick(virtual_clock: VirtualClock) -> None:
    """``last_tick_fields`` gives the latest tick's (index, deadline, time, missed) without
    building its TimerTick, and agrees with ``last_tick`` once that is built."""
    async with EventTimer(5, clock=virtual_clock, name="peek") as timer:
        assert timer.last_tick_fields is None
        peek = _Peek()
        timer.add_observer(peek)
        timer.start_timer()
        await virtual_clock.sleep(0.0201)
        timer.stop_timer()
    start = peek.fields[0]
    assert start is not None
    assert [f[0] for f in peek.fields if f is not None] == [1, 2, 3, 4]
    assert all(f is not None and f[1] == f[2] and f[3] == 0 for f in peek.fields)
    tick = timer.last_tick  # built now, from the same fields
    assert tick is not None
    fields = (tick.index, tick.deadline_ns, tick.time_ns, tick.missed_ticks)
    assert timer.last_tick_fields == fields == peek.fields[-1]


@pytest.mark.parametrize(
    ("period_ms", "period_ns"),
    [
        (1, 1_000_000),
        (0.5, 500_000),
        (2.25, 2_250_000),
        (1 / 3, 333_333),
        (1e-6, 1),
        (250, 250 * NS_PER_MS),
    ],
)
async def test_int_and_float_periods(
    virtual_clock: VirtualClock, period_ms: float, period_ns: int
) -> None:
    start = virtual_clock.now_ns()
    async with EventTimer(period_ms, clock=virtual_clock) as timer:
        assert timer.period_ns == period_ns
        assert timer.period_ms == period_ms
        ticks = TickLog(virtual_clock, until=7)
        timer.add_observer(ticks)
        timer.start_timer()
        await ticks.done.wait()
    assert ticks.times == _grid(start, period_ns, 7)


def test_period_to_ns_rounds_to_the_nearest_nanosecond() -> None:
    assert period_to_ns(1) == NS_PER_MS
    assert period_to_ns(0.0000015) == 2
    assert period_to_ns(2**40) == 2**40 * NS_PER_MS


# -- period validation ------------------------------------------------------------------------

BAD_PERIODS: list[object] = [
    0,
    0.0,
    -1,
    -0.5,
    math.nan,
    math.inf,
    -math.inf,
    True,
    False,
    "10",
    None,
    [10],
    1e-7,  # below one nanosecond
]


@pytest.mark.parametrize("period", BAD_PERIODS)
def test_bad_period_at_construction(period: object) -> None:
    with pytest.raises(BadParameterError) as info:
        EventTimer(period)  # type: ignore[arg-type]
    assert info.value.parameter == "period_ms"
    assert "period_ms" in str(info.value)


@pytest.mark.parametrize("period", BAD_PERIODS)
async def test_bad_period_in_set_event_period_keeps_the_old_one(
    virtual_clock: VirtualClock, period: object
) -> None:
    async with EventTimer(5, clock=virtual_clock) as timer:
        timer.start_timer()
        with pytest.raises(BadParameterError) as info:
            timer.set_event_period(period)  # type: ignore[arg-type]
        assert info.value.parameter == "period_ms"
        assert (timer.period_ms, timer.period_ns) == (5, 5 * NS_PER_MS)
        assert timer.state is TimerState.RUNNING


@pytest.mark.parametrize("threshold", [0, -1, math.nan, "1", True])
def test_bad_late_threshold_names_its_parameter(threshold: object) -> None:
    with pytest.raises(BadParameterError) as info:
        EventTimer(10, late_threshold_ms=threshold)  # type: ignore[arg-type]
    assert info.value.parameter == "late_threshold_ms"


# -- SetEventPeriod --------------------------------------------------------------------------


async def test_set_event_period_while_running_applies_from_the_next_tick(
    virtual_clock: VirtualClock,
) -> None:
    ms = NS_PER_MS
    async with EventTimer(10, clock=virtual_clock) as timer:
        ticks = TickLog(virtual_clock)
        timer.add_observer(ticks)
        timer.start_timer()
        await virtual_clock.sleep_until(25 * ms)
        assert ticks.times == [10 * ms, 20 * ms]
        # Between ticks: the pending tick (30 ms) keeps its deadline; the new period
        # counts from there.
        timer.set_event_period(4)
        assert timer.period_ns == 4 * ms
        await virtual_clock.sleep_until(43 * ms)
        assert ticks.times == [10 * ms, 20 * ms, 30 * ms, 34 * ms, 38 * ms, 42 * ms]
        # Longer again, with a float period.
        timer.set_event_period(7.5)
        await virtual_clock.sleep_until(62 * ms)
        timer.stop_timer()
    assert ticks.times[6:] == [46 * ms, 53_500_000, 61 * ms]
    # Indexes keep counting ticks; deadlines stay on the (re-anchored) grid.
    assert ticks.indexes == list(range(1, 10))
    assert [t.deadline_ns for t in ticks.ticks] == ticks.times
    assert timer.stats.missed_ticks == 0
    assert timer.stats.last_lateness_ns == 0


async def test_set_event_period_from_an_observer_applies_to_the_next_interval(
    virtual_clock: VirtualClock,
) -> None:
    ms = NS_PER_MS
    async with EventTimer(10, clock=virtual_clock) as timer:
        ticks = TickLog(virtual_clock, until=5)

        def speed_up(t: EventTimer) -> None:
            assert t.last_tick is not None
            if t.last_tick.index == 2:
                t.set_event_period(3)

        timer.add_observer(speed_up)
        timer.add_observer(ticks)
        timer.start_timer()
        await ticks.done.wait()
    assert ticks.times == [10 * ms, 20 * ms, 23 * ms, 26 * ms, 29 * ms]


async def test_set_event_period_while_stopped(virtual_clock: VirtualClock) -> None:
    async with EventTimer(10, clock=virtual_clock) as timer:
        timer.set_event_period(2)
        ticks = TickLog(virtual_clock, until=3)
        timer.add_observer(ticks)
        start = virtual_clock.now_ns()
        timer.start_timer()
        await ticks.done.wait()
    assert ticks.times == _grid(start, 2 * NS_PER_MS, 3)


# -- states --------------------------------------------------------------------------------------


async def test_start_twice_and_stop_when_stopped_raise_state_errors(
    virtual_clock: VirtualClock,
) -> None:
    async with EventTimer(1, clock=virtual_clock) as timer:
        with pytest.raises(StateError) as info:
            timer.stop_timer()
        assert info.value.state is TimerState.STOPPED
        assert "Stopped" in str(info.value)
        assert info.value.operation == "stop_timer"

        timer.start_timer()
        with pytest.raises(StateError) as info:
            timer.start_timer()
        assert info.value.state is TimerState.RUNNING
        assert "Running" in str(info.value)
        assert info.value.operation == "start_timer"
        assert timer.state is TimerState.RUNNING

        timer.stop_timer()
        with pytest.raises(StateError):
            timer.stop_timer()


async def test_start_outside_async_with_raises(virtual_clock: VirtualClock) -> None:
    timer = EventTimer(1, clock=virtual_clock)
    with pytest.raises(StateError) as info:
        timer.start_timer()
    assert "not entered" in str(info.value)
    assert timer.state is TimerState.STOPPED

    async with timer:
        timer.start_timer()
    # Leaving the block stops the timer; it cannot be started outside it.
    assert timer.state is TimerState.STOPPED
    with pytest.raises(StateError):
        timer.start_timer()


async def test_entering_twice_at_once_raises(virtual_clock: VirtualClock) -> None:
    async with EventTimer(1, clock=virtual_clock) as timer:
        with pytest.raises(StateError):
            await timer.__aenter__()


async def test_stop_timer_delivers_no_further_ticks(virtual_clock: VirtualClock) -> None:
    ms = NS_PER_MS
    async with EventTimer(10, clock=virtual_clock) as timer:
        ticks = TickLog(virtual_clock)
        timer.add_observer(ticks)
        timer.start_timer()
        await virtual_clock.sleep_until(35 * ms)
        timer.stop_timer()
        await virtual_clock.sleep_until(200 * ms)
    assert ticks.times == [10 * ms, 20 * ms, 30 * ms]
    assert timer.stats.ticks == 3


async def test_stop_timer_at_a_tick_deadline_delivers_no_tick(virtual_clock: VirtualClock) -> None:
    """StopTimer called by a task woken at the same instant as the timer wins.

    This task sleeps until 10 ms before the timer's task registers the same deadline,
    so it is woken first; the timer's wake-up is then already due when it stops.
    """
    async with EventTimer(10, clock=virtual_clock) as timer:
        ticks = TickLog(virtual_clock)
        timer.add_observer(ticks)
        timer.start_timer()
        await virtual_clock.sleep_until(10 * NS_PER_MS)
        timer.stop_timer()
        await virtual_clock.sleep_until(100 * NS_PER_MS)
    assert ticks.times == []
    assert timer.stats.ticks == 0


async def test_stop_from_inside_an_observer(virtual_clock: VirtualClock) -> None:
    async with EventTimer(1, clock=virtual_clock) as timer:
        ticks = TickLog(virtual_clock)

        def stop_at_three(t: EventTimer) -> None:
            assert t.last_tick is not None
            if t.last_tick.index == 3:
                t.stop_timer()

        timer.add_observer(stop_at_three)
        timer.add_observer(ticks)
        timer.start_timer()
        await virtual_clock.sleep(0.050)
    # The tick being delivered still reaches every observer; none comes after.
    assert ticks.indexes == [1, 2, 3]
    assert timer.state is TimerState.STOPPED


async def test_restart_counts_on_and_ticks_from_the_restart(virtual_clock: VirtualClock) -> None:
    ms = NS_PER_MS
    async with EventTimer(10, clock=virtual_clock) as timer:
        ticks = TickLog(virtual_clock)
        timer.add_observer(ticks)
        timer.start_timer()
        await virtual_clock.sleep_until(25 * ms)
        timer.stop_timer()
        await virtual_clock.sleep_until(37 * ms)
        timer.start_timer()
        await virtual_clock.sleep_until(60 * ms)
        timer.stop_timer()
    assert ticks.times == [10 * ms, 20 * ms, 47 * ms, 57 * ms]
    assert ticks.indexes == [1, 2, 3, 4]


async def test_timer_can_be_entered_again(virtual_clock: VirtualClock) -> None:
    timer = EventTimer(5, clock=virtual_clock)
    sync_ticks = TickLog(virtual_clock)
    async_times: list[int] = []

    async def async_observer(t: EventTimer) -> None:
        async_times.append(virtual_clock.now_ns())

    timer.add_observer(sync_ticks)
    timer.add_observer(async_observer)
    for _ in range(2):
        async with timer:
            timer.start_timer()
            await virtual_clock.sleep(0.012)
    assert len(sync_ticks.ticks) == 4
    assert async_times == sync_ticks.times


# -- iteration -----------------------------------------------------------------------------------


async def test_async_for_yields_ticks_and_unsubscribes_on_break(
    virtual_clock: VirtualClock,
) -> None:
    start = virtual_clock.now_ns()
    async with EventTimer(2, clock=virtual_clock) as timer:
        timer.start_timer()
        got: list[TimerTick] = []
        async for tick in timer:
            assert isinstance(tick, TimerTick)
            got.append(tick)
            if len(got) == 5:
                break
        assert timer.observers == ()  # the loop's private queue is gone

        # A second loop starts with the ticks after it subscribed.
        async for tick in timer:
            later = tick
            break
        assert timer.observers == ()
    assert [t.index for t in got] == [1, 2, 3, 4, 5]
    assert [t.time_ns for t in got] == _grid(start, 2 * NS_PER_MS, 5)
    assert all(t.timer is timer and t.lateness_ns == 0 for t in got)
    assert later.index == 6


async def test_async_for_alongside_other_observers(virtual_clock: VirtualClock) -> None:
    async with EventTimer(1, clock=virtual_clock) as timer:
        ticks = TickLog(virtual_clock)
        timer.add_observer(ticks)
        timer.start_timer()
        indexes = []
        async for tick in timer:
            indexes.append(tick.index)
            if tick.index == 4:
                break
        assert timer.observers == (ticks,)
    assert indexes == [1, 2, 3, 4]


# -- observers ----------------------------------------------------------------------------------


async def test_sync_and_async_observers_are_all_notified(virtual_clock: VirtualClock) -> None:
    arrivals: dict[str, list[tuple[int, int]]] = {}

    def note(name: str, timer: EventTimer) -> None:
        assert timer.last_tick is not None
        arrivals.setdefault(name, []).append((timer.last_tick.index, virtual_clock.now_ns()))

    def sync_function(timer: EventTimer) -> None:
        note("sync function", timer)

    async def async_function(timer: EventTimer) -> None:
        note("async function", timer)

    class SyncObserver:
        def notify_timer(self, timer: EventTimer) -> None:
            note("sync object", timer)

    class AsyncObserver:
        async def notify_timer(self, timer: EventTimer) -> None:
            await anyio.lowlevel.checkpoint()
            note("async object", timer)

    queue = ObserverQueue()
    observers: list[Any] = [sync_function, async_function, SyncObserver(), AsyncObserver(), queue]
    assert isinstance(observers[2], TimerObserver)
    assert isinstance(observers[3], TimerObserver)
    start = virtual_clock.now_ns()
    async with EventTimer(3, clock=virtual_clock) as timer:
        for observer in observers:
            timer.add_observer(observer)
        assert timer.observers == tuple(observers)
        timer.start_timer()
        await virtual_clock.sleep(0.0155)
        timer.stop_timer()
        timer.remove_observer(async_function)
        assert async_function not in timer.observers

    expected = list(zip(range(1, 6), _grid(start, 3 * NS_PER_MS, 5), strict=True))
    assert set(arrivals) == {"sync function", "async function", "sync object", "async object"}
    for name, got in arrivals.items():
        assert got == expected, name  # async observers too, at the tick's virtual time
    assert [t.index for t in queue.drain()] == [1, 2, 3, 4, 5]  # type: ignore[union-attr]


async def test_raising_observers_do_not_stop_the_timer(virtual_clock: VirtualClock) -> None:
    def broken(timer: EventTimer) -> None:
        raise RuntimeError("broken sync observer")

    async def broken_async(timer: EventTimer) -> None:
        raise RuntimeError("broken async observer")

    with structlog.testing.capture_logs() as logs:
        async with EventTimer(1, clock=virtual_clock) as timer:
            ticks = TickLog(virtual_clock, until=5)
            timer.add_observer(broken)
            timer.add_observer(broken_async)
            timer.add_observer(ticks)
            timer.start_timer()
            await ticks.done.wait()
            assert timer.state is TimerState.RUNNING
    assert ticks.indexes == [1, 2, 3, 4, 5]
    failures = [e for e in logs if e["event"] == "observer_failed"]
    assert len(failures) >= 9  # 5 sync + the async ones delivered before exit


async def test_observer_registration_errors(virtual_clock: VirtualClock) -> None:
    async with EventTimer(1, clock=virtual_clock) as timer:
        ticks = TickLog(virtual_clock)
        timer.add_observer(ticks)
        with pytest.raises(BadParameterError):
            timer.add_observer(ticks)
        with pytest.raises(BadParameterError):
            timer.remove_observer(TickLog(virtual_clock))
        with pytest.raises(BadParameterError):
            timer.add_observer(None)
        with pytest.raises(BadParameterError):
            timer.add_observer(object())
        timer.remove_observer(ticks)
        assert timer.observers == ()


# -- missed ticks, lateness, drift ------------------------------------------------------------------


async def test_late_wake_skips_missed_periods_without_a_burst(virtual_clock: VirtualClock) -> None:
    ms = NS_PER_MS
    # The second wake comes 3.5 periods late, everything else on time.
    clock = LateClock(virtual_clock, [0, 35 * ms])
    assert isinstance(clock, Clock)
    with structlog.testing.capture_logs() as logs:
        async with EventTimer(10, clock=clock, name="late") as timer:
            ticks = TickLog(clock, until=5)
            timer.add_observer(ticks)
            timer.start_timer()
            await ticks.done.wait()
            timer.stop_timer()
    assert clock.sleepers_closed == 1

    assert ticks.times == [10 * ms, 55 * ms, 60 * ms, 70 * ms, 80 * ms]
    # The late tick is stamped with the grid point it stands for (50 ms)...
    assert [t.deadline_ns for t in ticks.ticks] == [10 * ms, 50 * ms, 60 * ms, 70 * ms, 80 * ms]
    # ...its index jumps over the three skipped periods (20, 30, 40 ms)...
    assert ticks.indexes == [1, 5, 6, 7, 8]
    assert [t.missed_ticks for t in ticks.ticks] == [0, 3, 0, 0, 0]
    assert ticks.ticks[1].lateness_ns == 5 * ms
    # ...and the next tick is back on the grid (60 ms), not a burst of catch-up ticks.
    stats = timer.stats
    assert stats.ticks == 5
    assert stats.missed_ticks == 3
    assert stats.late_ticks == 1
    assert stats.lateness.max_ns == 35 * ms
    assert stats.last_lateness_ns == 0
    warnings = [e for e in logs if e["event"] == "timer_missed_ticks"]
    assert len(warnings) == 1
    assert warnings[0]["missed"] == 3


async def test_lateness_below_one_period_is_not_a_miss(virtual_clock: VirtualClock) -> None:
    period = 10 * NS_PER_MS
    clock = LateClock(virtual_clock, [period - 1, 0, period, 0])
    async with EventTimer(10, clock=clock) as timer:
        ticks = TickLog(clock, until=4)
        timer.add_observer(ticks)
        timer.start_timer()
        await ticks.done.wait()
    assert ticks.times == [2 * period - 1, 2 * period, 4 * period, 5 * period]
    assert ticks.indexes == [1, 2, 4, 5]
    assert [t.missed_ticks for t in ticks.ticks] == [0, 0, 1, 0]
    assert timer.stats.missed_ticks == 1


async def test_lateness_statistics_reflect_the_scripted_lateness(
    virtual_clock: VirtualClock,
) -> None:
    us = 1_000
    lateness = [i * 10 * us for i in range(100)]  # 0 .. 990 µs, all below the 2 ms period
    random.Random(7).shuffle(lateness)
    lateness += [0] * 5
    clock = LateClock(virtual_clock, lateness)
    async with EventTimer(2, clock=clock, late_threshold_ms=0.5) as timer:
        ticks = TickLog(clock, until=100)
        timer.add_observer(ticks)
        timer.start_timer()
        await ticks.done.wait()
        timer.stop_timer()
    stats = timer.stats
    assert [t.lateness_ns for t in ticks.ticks] == lateness[:100]
    assert stats.ticks == 100
    assert stats.missed_ticks == 0
    assert stats.lateness.count == 100
    # Nearest-rank percentiles of 0, 10, ..., 990 µs.
    assert stats.lateness.p50_ns == 490 * us
    assert stats.lateness.p99_ns == 980 * us
    assert stats.lateness.max_ns == 990 * us
    assert stats.lateness.mean_ns == pytest.approx(495 * us)
    # late_threshold 0.5 ms: 510, 520, ..., 990 µs are late.
    assert stats.late_ticks == 49
    assert stats.last_lateness_ns == ticks.ticks[-1].lateness_ns

    timer.reset_stats()
    cleared = timer.stats
    assert (cleared.ticks, cleared.late_ticks, cleared.missed_ticks) == (0, 0, 0)
    assert cleared.lateness.count == 0
    assert cleared.lateness.max_ns == 0


async def test_default_late_threshold_is_a_fifth_of_the_period(
    virtual_clock: VirtualClock,
) -> None:
    period = 10 * NS_PER_MS
    clock = LateClock(virtual_clock, [period // 5, period // 5 + 1, 0])
    async with EventTimer(10, clock=clock) as timer:
        ticks = TickLog(clock, until=3)
        timer.add_observer(ticks)
        timer.start_timer()
        await ticks.done.wait()
    assert timer.stats.late_ticks == 1


async def test_drift_does_not_accumulate_over_1000_jittery_ticks(
    virtual_clock: VirtualClock,
) -> None:
    period = NS_PER_MS
    rng = random.Random(2024)
    # Mostly sub-period jitter, with an occasional wake-up several periods late.
    jitter = [
        rng.randrange(0, 4 * period) if rng.random() < 0.02 else rng.randrange(0, period * 9 // 10)
        for _ in range(1000)
    ]
    clock = LateClock(virtual_clock, jitter)
    start = virtual_clock.now_ns()
    async with EventTimer(1, clock=clock) as timer:
        ticks = TickLog(clock, until=1000)
        timer.add_observer(ticks)
        timer.start_timer()
        await ticks.done.wait()
        timer.stop_timer()

    stats = timer.stats
    assert stats.ticks == 1000
    # Every tick stands for a grid point: deadline = start + index x period, exactly.
    for tick in ticks.ticks:
        assert tick.deadline_ns == start + tick.index * period
        assert 0 <= tick.lateness_ns < period
    # Indexes count delivered plus skipped periods; no period is lost or repeated.
    assert ticks.indexes[-1] == stats.ticks + stats.missed_ticks
    assert all(b > a for a, b in itertools.pairwise(ticks.indexes))
    assert stats.missed_ticks == sum(t.missed_ticks for t in ticks.ticks)
    assert stats.missed_ticks > 0
    assert 0 <= stats.last_lateness_ns < period
    assert stats.lateness.max_ns == max(jitter)


# -- throughput of virtual time -----------------------------------------------------------------------


async def test_ten_virtual_seconds_at_1khz_with_three_observers(
    virtual_clock: VirtualClock,
) -> None:
    counts = {"sync": 0, "async": 0}

    def sync_observer(timer: EventTimer) -> None:
        counts["sync"] += 1

    async def async_observer(timer: EventTimer) -> None:
        counts["async"] += 1

    queue = ObserverQueue(20_000)
    start = virtual_clock.now_ns()
    async with EventTimer(1, clock=virtual_clock) as timer:
        timer.add_observer(sync_observer)
        timer.add_observer(async_observer)
        timer.add_observer(queue)
        timer.start_timer()
        await virtual_clock.sleep_until(start + 10 * NS_PER_S + NS_PER_MS // 2)
        timer.stop_timer()
        await virtual_clock.sleep(1.0)
    assert counts == {"sync": 10_000, "async": 10_000}
    ticks = queue.drain()
    assert len(ticks) == 10_000
    assert ticks[-1].time_ns == start + 10 * NS_PER_S  # type: ignore[union-attr]
    assert timer.stats.ticks == 10_000
    assert timer.stats.missed_ticks == 0
    assert queue.missed_total == 0


# -- lateness statistics ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("values", "q", "expected"),
    [
        ([], 50, 0),
        ([7], 50, 7),
        ([7], 99, 7),
        ([1, 2, 3, 4, 5], 50, 3),  # the median, not the 2nd value
        ([1, 2, 3, 4], 50, 2),
        (list(range(1, 101)), 50, 50),
        (list(range(1, 101)), 99, 99),
        (list(range(1, 151)), 99, 149),  # ceil(148.5) = 149
        (list(range(1, 1001)), 99, 990),
        (list(range(1, 11)), 0, 1),
        (list(range(1, 11)), 100, 10),
    ],
)
def test_percentile_is_nearest_rank(values: list[int], q: float, expected: int) -> None:
    assert percentile(values, q) == expected


def test_lateness_recorder_keeps_a_window_but_counts_everything() -> None:
    recorder = LatenessRecorder(window=4)
    for value in [5, 1, 9, 3, 7, 2, 8, 4, 6, 10]:
        recorder.record(value)
    summary = recorder.summary()
    assert summary.count == 10
    assert summary.max_ns == 10  # over every sample
    # The window holds the last four: 8, 4, 6, 10.
    assert summary.p50_ns == 6
    assert summary.p99_ns == 10
    assert summary.mean_ns == 7.0
    assert summary.as_us() == {"p50_us": 0.006, "p99_us": 0.01, "max_us": 0.01, "mean_us": 0.007}
    recorder.reset()
    assert recorder.summary() == LatenessSummary(0, 0, 0, 0, 0.0)


# -- on the real clock ---------------------------------------------------------------------------------


@pytest.mark.parametrize("use_timerfd", [True, False])
async def test_real_clock_ticks_never_come_before_their_deadline(use_timerfd: bool) -> None:
    """Behaviour only (no timing bounds): each tick at or after its grid deadline."""
    clock = MonotonicClock(use_timerfd=use_timerfd)
    async with EventTimer(0.5, clock=clock) as timer:
        ticks = TickLog(clock, until=8)
        timer.add_observer(ticks)
        timer.start_timer()
        with anyio.fail_after(30):  # guards against a hang only
            await ticks.done.wait()
        timer.stop_timer()
    period = timer.period_ns
    for tick, arrival in zip(ticks.ticks, ticks.arrivals, strict=True):
        assert arrival >= tick.time_ns >= tick.deadline_ns
        assert tick.lateness_ns < period  # later wake-ups are re-stamped on the grid
    for a, b in itertools.pairwise(ticks.ticks):
        assert b.index > a.index
        assert b.deadline_ns - a.deadline_ns == (b.index - a.index) * period
    assert timer.stats.ticks == 8


async def test_stats_name_the_last_ticks_lateness_and_keep_drift_ns_as_its_alias() -> None:
    """TimerStats reported the last tick's lateness under the name drift_ns (issue 10 #8):
    it is now last_lateness_ns, and drift_ns is an alias of it."""
    clock = VirtualClock()
    async with clock.autojump(), EventTimer(10, clock=clock) as timer:
        timer.start_timer()
        await clock.sleep(0.055)
        timer.stop_timer()
    stats = timer.stats
    assert stats.ticks >= 5
    assert stats.last_lateness_ns == 0
    assert stats.drift_ns == stats.last_lateness_ns
    assert "last_lateness_ns" in TimerStats.__dataclass_fields__
