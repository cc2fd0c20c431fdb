"""Periodic contexts: rate changes, overruns and skipped cycles, lifecycle calls that
do not wait behind another component's long on_execute, lifecycle timeouts."""

from __future__ import annotations

import pytest

from openel_async import VirtualClock
from openel_async.rtc import (
    CallbackFailedError,
    LifeCycleState,
    PeriodicExecutionContext,
    RTCTimeoutError,
)

from .helpers import MS, Journal, ModalRecorder, Recorder

S = LifeCycleState


async def until(clock: VirtualClock, ms: float) -> None:
    await clock.sleep_until(round(ms * MS))


def times_ms(journal: Journal, component: str, callback: str) -> list[float]:
    return [c.time_ns / MS for c in journal.of(component, callback)]


async def test_rate_change(virtual_clock: VirtualClock, journal: Journal) -> None:
    a, b = Recorder("A", journal, virtual_clock), Recorder("B", journal, virtual_clock)
    async with PeriodicExecutionContext(100, clock=virtual_clock) as ec:
        for comp in (a, b):
            await comp.initialize()
            await ec.add_component(comp)
        await ec.start()
        await ec.activate_component(a)
        await until(virtual_clock, 15)
        await ec.set_rate(50)
        assert ec.get_rate() == 50.0
        assert ec.period_ns == 20 * MS
        # every participant is told, whatever its state, at the call
        assert times_ms(journal, "A", "on_rate_changed") == [15.0]
        assert times_ms(journal, "B", "on_rate_changed") == [15.0]
        await until(virtual_clock, 85)
        # The tick already due at 20 ms comes; the new period counts from it.
        assert times_ms(journal, "A", "on_execute") == [10, 20, 40, 60, 80]
        await ec.set_rate(1000.0)
        await until(virtual_clock, 103.5)
        assert times_ms(journal, "A", "on_execute")[-4:] == [100, 101, 102, 103]
        assert ec.stats.overruns == 0


async def test_overruns_and_skipped_cycles(virtual_clock: VirtualClock, journal: Journal) -> None:
    a = Recorder("A", journal, virtual_clock)
    await a.initialize()
    async with PeriodicExecutionContext(100, clock=virtual_clock) as ec:
        await ec.add_component(a)
        await ec.start()
        await ec.activate_component(a)
        await until(virtual_clock, 5)
        a.delays["on_execute"] = 15 * MS  # cycle at 10 ms runs until 25 ms
        await until(virtual_clock, 11)
        del a.delays["on_execute"]
        await until(virtual_clock, 35)
        # The tick of 20 ms waited for the long cycle: run late at 25 ms, then on time.
        assert times_ms(journal, "A", "on_execute") == [10, 25, 30]
        stats = ec.stats
        assert (stats.cycles, stats.overruns, stats.skipped) == (3, 1, 0)
        assert stats.lateness.max_ns == 5 * MS
        assert stats.execution.max_ns == 15 * MS
        # A cycle of 2.5 periods: one of the two ticks it spans is skipped.
        a.delays["on_execute"] = 25 * MS  # cycle at 40 ms runs until 65 ms
        await until(virtual_clock, 41)
        del a.delays["on_execute"]
        await until(virtual_clock, 75)
        assert times_ms(journal, "A", "on_execute")[-3:] == [40, 65, 70]
        stats = ec.stats
        assert (stats.overruns, stats.skipped) == (2, 1)
        assert stats.last_lateness_ns == 0  # the last cycle started on time
        assert stats.timer_missed == 0
        ec.reset_stats()
        assert ec.stats.cycles == 0


async def test_a_slow_component_does_not_stall_lifecycle_calls_on_others(
    virtual_clock: VirtualClock, journal: Journal
) -> None:
    slow, other = (
        Recorder("slow", journal, virtual_clock),
        ModalRecorder("B", journal, virtual_clock),
    )
    for comp in (slow, other):
        await comp.initialize()
    async with PeriodicExecutionContext(100, clock=virtual_clock, lifecycle_timeout=1.0) as ec:
        await ec.add_component(slow)
        await ec.start()
        await ec.activate_component(slow)
        slow.delays["on_execute"] = 50 * MS  # the cycle at 10 ms runs until 60 ms
        await until(virtual_clock, 15)
        t0 = virtual_clock.now_ns()
        # Every lifecycle call on another component completes at once.
        await ec.add_component(other)
        await ec.activate_component(other)
        assert ec.get_component_state(other) is S.ACTIVE
        await other.set_mode("safe", immediate=True)
        assert other.get_current_mode_in_context(ec) == "safe"
        await ec.deactivate_component(other)
        other.fail["on_activated"] = RuntimeError("x")
        with pytest.raises(CallbackFailedError):
            await ec.activate_component(other)
        del other.fail["on_activated"]
        await ec.reset_component(other)
        await ec.remove_component(other)
        assert virtual_clock.now_ns() == t0
        assert ec.get_component_state(slow) is S.ACTIVE  # queries never wait
        # A call on the slow component itself waits for its on_execute only.
        await ec.deactivate_component(slow)
        assert virtual_clock.now_ns() == 60 * MS
        await until(virtual_clock, 61)
        assert ec.stats.overruns == 1


async def test_lifecycle_timeout_on_a_busy_component(
    virtual_clock: VirtualClock, journal: Journal
) -> None:
    slow = Recorder("slow", journal, virtual_clock)
    await slow.initialize()
    async with PeriodicExecutionContext(100, clock=virtual_clock, lifecycle_timeout=0.02) as ec:
        await ec.add_component(slow)
        await ec.start()
        await ec.activate_component(slow)
        slow.delays["on_execute"] = 50 * MS
        await until(virtual_clock, 15)
        with pytest.raises(RTCTimeoutError) as info:
            await ec.deactivate_component(slow)
        assert "deactivate_component(slow) did not finish within 0.02 s" in str(info.value)
        assert virtual_clock.now_ns() == 35 * MS
        # Only the wait timed out; on_deactivated never ran, so the state is unchanged.
        assert ec.get_component_state(slow) is S.ACTIVE
        assert journal.of("slow", "on_deactivated") == []
        del slow.delays["on_execute"]
        await until(virtual_clock, 61)
        await ec.deactivate_component(slow)
        assert ec.get_component_state(slow) is S.INACTIVE


async def test_a_callback_cut_off_by_the_timeout_leaves_the_component_in_error(
    virtual_clock: VirtualClock, journal: Journal
) -> None:
    a = Recorder("A", journal, virtual_clock)
    await a.initialize()
    async with PeriodicExecutionContext(100, clock=virtual_clock, lifecycle_timeout=0.1) as ec:
        await ec.add_component(a)
        a.delays["on_activated"] = 10_000 * MS  # hangs
        with pytest.raises(RTCTimeoutError):
            await ec.activate_component(a)
        assert virtual_clock.now_ns() == 100 * MS
        assert ec.get_component_state(a) is S.ERROR
        assert journal.names("A")[-2:] == ["on_activated", "on_aborting"]
        await ec.start()  # the context goes on
        await until(virtual_clock, 125)
        assert journal.names("A")[-2:] == ["on_error", "on_error"]


async def test_no_timeout_when_disabled(virtual_clock: VirtualClock, journal: Journal) -> None:
    a = Recorder("A", journal, virtual_clock)
    await a.initialize()
    async with PeriodicExecutionContext(100, clock=virtual_clock, lifecycle_timeout=None) as ec:
        await ec.add_component(a)
        a.delays["on_activated"] = 30_000 * MS
        await ec.activate_component(a)
        assert virtual_clock.now_ns() == 30_000 * MS
        assert ec.get_component_state(a) is S.ACTIVE


async def test_stats_on_the_virtual_clock(virtual_clock: VirtualClock, journal: Journal) -> None:
    comps = [Recorder(f"C{i}", journal, virtual_clock) for i in range(10)]
    async with PeriodicExecutionContext(1000, clock=virtual_clock) as ec:
        for comp in comps:
            await comp.initialize()
            await ec.add_component(comp)
            await ec.activate_component(comp)
        await ec.start()
        await until(virtual_clock, 1000.5)
        stats = ec.stats
        assert stats.cycles == 1000
        assert (stats.overruns, stats.skipped, stats.timer_missed, stats.last_lateness_ns) == (
            0,
            0,
            0,
            0,
        )
        assert stats.lateness.max_ns == 0
        assert len(journal.of("C9", "on_state_update")) == 1000
