"""ExtTrigExecutionContext: one cycle per tick(), returned after it, and nothing else
(OpenRTM-aist's ExtTrigExecutionContext; issue 21, point 17)."""

from __future__ import annotations

import math

import anyio
import pytest

from openel_async import VirtualClock
from openel_async.rtc import (
    CallbackFailedError,
    ExecutionKind,
    ExtTrigExecutionContext,
    LifeCycleState,
    PreconditionNotMetError,
    ReturnCode_t,
    RTCBadParameterError,
    RTCTimeoutError,
)

from .helpers import MS, Journal, Recorder

S = LifeCycleState


async def test_n_ticks_run_exactly_n_cycles_and_nothing_runs_without_one(
    virtual_clock: VirtualClock, journal: Journal
) -> None:
    a = Recorder("A", journal, virtual_clock)
    b = Recorder("B", journal, virtual_clock)
    async with ExtTrigExecutionContext(1000.0, clock=virtual_clock, owner=a) as ec:
        for comp in (a, b):
            await comp.initialize()
            await ec.add_component(comp)
        await ec.start()
        await ec.activate_component(a)
        await ec.activate_component(b)
        # No tick, no cycle: a minute of simulated time passes without one.
        await virtual_clock.sleep(60.0)
        assert journal.of("A", "on_execute") == []
        for n in range(1, 6):
            await ec.tick()
            # tick() returns after its cycle: both passes of every participant are done.
            assert len(journal.of("A", "on_execute")) == len(journal.of("B", "on_execute")) == n
            assert len(journal.of("B", "on_state_update")) == n
            assert journal.names()[-4:] == [
                "A.on_execute",
                "B.on_execute",
                "A.on_state_update",
                "B.on_state_update",
            ]
        await virtual_clock.sleep(60.0)
        assert ec.stats.cycles == ec.ticks == 5
        assert ec.stats.skipped == ec.stats.overruns == 0
        assert len(journal.of("A", "on_execute")) == 5


async def test_concurrent_ticks_are_not_merged(
    virtual_clock: VirtualClock, journal: Journal
) -> None:
    a = Recorder("A", journal, virtual_clock)
    a.delays["on_execute"] = 5 * MS  # each cycle takes 5 ms
    async with ExtTrigExecutionContext(clock=virtual_clock) as ec:
        await a.initialize()
        await ec.add_component(a)
        await ec.start()
        await ec.activate_component(a)
        start = virtual_clock.now_ns()
        async with anyio.create_task_group() as tg:
            for _ in range(4):
                tg.start_soon(ec.tick)
        assert len(journal.of("A", "on_execute")) == ec.stats.cycles == 4
        assert ec.stats.skipped == 0
        # one after the other: 4 x 5 ms
        assert virtual_clock.now_ns() - start == 20 * MS


async def test_kind_rate_and_constructor_checks(virtual_clock: VirtualClock) -> None:
    ec = ExtTrigExecutionContext(250, clock=virtual_clock)
    # As in OpenRTM-aist: PERIODIC with a nominal rate (nothing ticks at it).
    assert ec.get_kind() is ExecutionKind.PERIODIC
    assert ec.get_rate() == 250.0
    assert ec.period_ns is None
    for bad in (0, -1.0, math.nan, "100", True, None, 2e9):
        with pytest.raises(RTCBadParameterError) as info:
            ExtTrigExecutionContext(bad, clock=virtual_clock)  # type: ignore[arg-type]
        assert info.value.parameter == "rate"


async def test_lifecycle_goes_through_the_context(
    virtual_clock: VirtualClock, journal: Journal
) -> None:
    a = Recorder("A", journal, virtual_clock)
    async with ExtTrigExecutionContext(clock=virtual_clock) as ec:
        with pytest.raises(PreconditionNotMetError):
            await ec.tick()  # stopped
        await a.initialize()
        await ec.add_component(a)
        await ec.start()
        await ec.tick()  # Inactive: nothing runs
        assert journal.of("A", "on_execute") == []
        await ec.activate_component(a)  # at once, without a tick, no on_execute
        assert ec.get_component_state(a) is S.ACTIVE
        assert journal.names("A")[-1] == "on_activated"
        await ec.tick()
        await ec.deactivate_component(a)
        await ec.tick()
        assert len(journal.of("A", "on_execute")) == 1
        assert ec.get_component_state(a) is S.INACTIVE
        # on_set_rate: the nominal rate changes, on_rate_changed runs
        await ec.set_rate(50.0)
        assert ec.get_rate() == 50.0
        assert journal.names("A")[-1] == "on_rate_changed"
        # a failing on_execute: Error, then on_error on each tick, reset back
        await ec.activate_component(a)
        a.fail["on_execute"] = ReturnCode_t.RTC_ERROR
        await ec.tick()
        assert ec.get_component_state(a) is S.ERROR
        mark = journal.mark()
        await ec.tick()
        await ec.tick()
        assert journal.names("A", since=mark) == ["on_error", "on_error"]
        del a.fail["on_execute"]
        await ec.reset_component(a)
        assert ec.get_component_state(a) is S.INACTIVE
        a.fail["on_activated"] = ReturnCode_t.RTC_ERROR
        with pytest.raises(CallbackFailedError):
            await ec.activate_component(a)
        assert ec.get_component_state(a) is S.ERROR
        await ec.stop()
        with pytest.raises(PreconditionNotMetError):
            await ec.tick()
        assert journal.names("A")[-1] == "on_shutdown"


async def test_a_participant_cannot_tick_its_own_context(
    virtual_clock: VirtualClock, journal: Journal
) -> None:
    errors: list[BaseException] = []

    class Ticker(Recorder):
        async def on_execute(self, exec_handle: int) -> None:
            ec = self.get_context(exec_handle)
            assert isinstance(ec, ExtTrigExecutionContext)
            try:
                await ec.tick()
            except PreconditionNotMetError as exc:
                errors.append(exc)

    a = Ticker("A", journal, virtual_clock)
    async with ExtTrigExecutionContext(clock=virtual_clock, owner=a) as ec:
        await a.initialize()
        await ec.add_component(a)
        await ec.start()
        await ec.activate_component(a)
        await ec.tick()
    assert len(errors) == 1
    assert "inside a callback of A" in str(errors[0])


async def test_a_cancelled_tick_still_runs_its_cycle_and_a_stop_ends_a_wait(
    virtual_clock: VirtualClock, journal: Journal
) -> None:
    a = Recorder("A", journal, virtual_clock)
    a.delays["on_execute"] = 10 * MS
    async with ExtTrigExecutionContext(clock=virtual_clock, lifecycle_timeout=None) as ec:
        await a.initialize()
        await ec.add_component(a)
        await ec.start()
        await ec.activate_component(a)
        with anyio.CancelScope() as scope:
            async with anyio.create_task_group() as tg:
                tg.start_soon(ec.tick)
                await virtual_clock.sleep(0.001)
                scope.cancel()
        assert ec.stats.cycles == 0  # its cycle still runs
        await ec.tick()  # waits for the cancelled tick's cycle, then runs its own
        assert ec.stats.cycles == 2
        # stop() while a tick waits: the tick returns, its cycle cut short
        async with anyio.create_task_group() as tg:
            tg.start_soon(ec.tick)
            await virtual_clock.sleep(0.001)
            await ec.stop()
        assert not ec.is_running()


async def test_a_tick_wait_is_bounded_by_the_lifecycle_timeout(
    virtual_clock: VirtualClock, journal: Journal
) -> None:
    a = Recorder("A", journal, virtual_clock)
    a.delays["on_execute"] = 5_000 * MS
    async with ExtTrigExecutionContext(clock=virtual_clock, lifecycle_timeout=1.0) as ec:
        await a.initialize()
        await ec.add_component(a)
        await ec.start()
        await ec.activate_component(a)
        with pytest.raises(RTCTimeoutError, match="tick"):
            await ec.tick()
