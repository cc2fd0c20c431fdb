"""The order of callbacks: lifecycle, cycles (two passes), errors and recovery.

The tables follow the spec and the choices documented in docs/rtc.md: a failure while
Active moves the component to Error with on_aborting once (no on_deactivated, unlike
OpenRTM-aist); on_error then runs instead of on_execute and on_state_update every
cycle until reset_component succeeds.
"""

from __future__ import annotations

from collections.abc import AsyncIterator

import pytest

from openel_async import VirtualClock
from openel_async.rtc import (
    CallbackFailedError,
    CallbackResult,
    EventDrivenExecutionContext,
    LifeCycleState,
    PeriodicExecutionContext,
    PreconditionNotMetError,
    ReturnCode_t,
    RTObject,
)

from .helpers import MS, Failure, Journal, Recorder

RC = ReturnCode_t
S = LifeCycleState
FAILURES: list[Failure] = [RC.RTC_ERROR, RC.OUT_OF_RESOURCES, RuntimeError("boom")]


async def until(clock: VirtualClock, ms: float) -> None:
    await clock.sleep_until(round(ms * MS))


@pytest.fixture
async def ec(virtual_clock: VirtualClock) -> AsyncIterator[PeriodicExecutionContext]:
    """100 Hz: cycles at 10, 20, 30 ... ms after start (started at t = 0)."""
    async with PeriodicExecutionContext(100.0, clock=virtual_clock, name="ec") as context:
        yield context


async def joined(ec: PeriodicExecutionContext, *comps: RTObject) -> None:
    for comp in comps:
        await comp.initialize()
        await ec.add_component(comp)


async def test_full_lifecycle(
    virtual_clock: VirtualClock, journal: Journal, ec: PeriodicExecutionContext
) -> None:
    a = Recorder("A", journal, virtual_clock)
    await joined(ec, a)
    await ec.start()
    await ec.activate_component(a)
    await until(virtual_clock, 25)
    await ec.deactivate_component(a)
    await until(virtual_clock, 45)  # inactive: nothing runs
    await ec.stop()
    await ec.remove_component(a)
    await a.finalize()
    assert journal.names("A") == [
        "on_initialize",
        "on_startup",
        "on_activated",
        "on_execute",
        "on_state_update",
        "on_execute",
        "on_state_update",
        "on_deactivated",
        "on_shutdown",
        "on_finalize",
    ]
    assert [c.time_ns // MS for c in journal.of("A", "on_execute")] == [10, 20]
    assert {c.handle for c in journal.calls if c.handle is not None} == {1000}
    assert ec.stats.cycles == 4


async def test_two_passes_in_participant_order(
    virtual_clock: VirtualClock, journal: Journal, ec: PeriodicExecutionContext
) -> None:
    comps = [Recorder(name, journal, virtual_clock) for name in ("A", "B", "C")]
    await joined(ec, *comps)
    for comp in comps:
        await ec.activate_component(comp)
    mark = journal.mark()
    await ec.start()
    await until(virtual_clock, 15)
    assert journal.names(since=mark) == [
        "A.on_startup",
        "B.on_startup",
        "C.on_startup",
        "A.on_execute",
        "B.on_execute",
        "C.on_execute",
        "A.on_state_update",
        "B.on_state_update",
        "C.on_state_update",
    ]


@pytest.mark.parametrize("failure", FAILURES, ids=["RTC_ERROR", "OUT_OF_RESOURCES", "raise"])
async def test_failing_on_execute(
    virtual_clock: VirtualClock, journal: Journal, ec: PeriodicExecutionContext, failure: Failure
) -> None:
    a, b = Recorder("A", journal, virtual_clock), Recorder("B", journal, virtual_clock)
    await joined(ec, a, b)
    await ec.start()
    await ec.activate_component(a)
    await ec.activate_component(b)
    await until(virtual_clock, 15)
    a.fail["on_execute"] = failure
    mark = journal.mark()
    await until(virtual_clock, 45)  # cycles at 20 (fails), 30, 40
    assert journal.names(since=mark) == [
        "A.on_execute",
        "A.on_deactivated",  # leaving Active, at once
        "A.on_aborting",  # once; no on_state_update in the failing cycle
        "B.on_execute",
        "B.on_state_update",
        "A.on_error",  # instead of on_execute and on_state_update
        "B.on_execute",
        "B.on_state_update",
        "A.on_error",
        "B.on_execute",
        "B.on_state_update",
    ]
    assert ec.get_component_state(a) is S.ERROR
    assert ec.get_component_state(b) is S.ACTIVE
    # Recovery: on_reset -> Inactive (nothing runs), then activate again.
    del a.fail["on_execute"]
    mark = journal.mark()
    await ec.reset_component(a)
    assert ec.get_component_state(a) is S.INACTIVE
    await until(virtual_clock, 55)
    await ec.activate_component(a)
    await until(virtual_clock, 65)
    assert journal.names("A", since=mark) == [
        "on_reset",
        "on_activated",
        "on_execute",
        "on_state_update",
    ]


@pytest.mark.parametrize("failure", FAILURES, ids=["RTC_ERROR", "OUT_OF_RESOURCES", "raise"])
async def test_failing_on_state_update(
    virtual_clock: VirtualClock, journal: Journal, ec: PeriodicExecutionContext, failure: Failure
) -> None:
    a = Recorder("A", journal, virtual_clock)
    await joined(ec, a)
    await ec.start()
    await ec.activate_component(a)
    a.fail["on_state_update"] = failure
    await until(virtual_clock, 25)
    assert journal.names("A")[-6:] == [
        "on_activated",
        "on_execute",
        "on_state_update",
        "on_deactivated",
        "on_aborting",
        "on_error",
    ]


async def test_failing_on_activated(
    virtual_clock: VirtualClock, journal: Journal, ec: PeriodicExecutionContext
) -> None:
    a = Recorder("A", journal, virtual_clock)
    await joined(ec, a)
    await ec.start()
    a.fail["on_activated"] = RC.BAD_PARAMETER
    with pytest.raises(CallbackFailedError) as info:
        await ec.activate_component(a)
    assert info.value.code is RC.RTC_ERROR
    assert info.value.callback_code is RC.BAD_PARAMETER
    assert ec.get_component_state(a) is S.ERROR
    await until(virtual_clock, 15)
    assert journal.names("A")[-3:] == ["on_activated", "on_aborting", "on_error"]


async def test_failing_on_deactivated(
    virtual_clock: VirtualClock, journal: Journal, ec: PeriodicExecutionContext
) -> None:
    a = Recorder("A", journal, virtual_clock)
    await joined(ec, a)
    await ec.activate_component(a)
    a.fail["on_deactivated"] = RuntimeError("brake failed")
    with pytest.raises(CallbackFailedError) as info:
        await ec.deactivate_component(a)
    assert isinstance(info.value.__cause__, RuntimeError)
    assert ec.get_component_state(a) is S.ERROR
    assert journal.names("A")[-2:] == ["on_deactivated", "on_aborting"]


async def test_failing_on_reset_stays_in_error(
    virtual_clock: VirtualClock, journal: Journal, ec: PeriodicExecutionContext
) -> None:
    a = Recorder("A", journal, virtual_clock)
    await joined(ec, a)
    await ec.start()
    a.fail["on_activated"] = RC.RTC_ERROR
    with pytest.raises(CallbackFailedError):
        await ec.activate_component(a)
    a.fail["on_reset"] = RC.RTC_ERROR
    a.fail["on_error"] = RC.RTC_ERROR  # failing on_error changes nothing either
    a.fail["on_aborting"] = RuntimeError("ignored")
    mark = journal.mark()
    with pytest.raises(CallbackFailedError):
        await ec.reset_component(a)
    await until(virtual_clock, 25)
    assert ec.get_component_state(a) is S.ERROR
    assert journal.names("A", since=mark) == ["on_reset", "on_error", "on_error"]


async def test_failing_on_aborting_still_enters_error(
    virtual_clock: VirtualClock, journal: Journal, ec: PeriodicExecutionContext
) -> None:
    a = Recorder("A", journal, virtual_clock)
    await joined(ec, a)
    a.fail["on_aborting"] = RC.RTC_ERROR
    a.fail["on_activated"] = RC.RTC_ERROR
    with pytest.raises(CallbackFailedError):
        await ec.activate_component(a)
    assert ec.get_component_state(a) is S.ERROR


async def test_failing_context_wide_callbacks_move_only_that_component_to_error(
    virtual_clock: VirtualClock, journal: Journal, ec: PeriodicExecutionContext
) -> None:
    a, b = Recorder("A", journal, virtual_clock), Recorder("B", journal, virtual_clock)
    await joined(ec, a, b)
    a.fail["on_startup"] = RC.RTC_ERROR
    await ec.start()  # the context starts all the same
    assert ec.is_running()
    assert ec.get_component_state(a) is S.ERROR
    assert ec.get_component_state(b) is S.INACTIVE
    await ec.activate_component(b)
    b.fail["on_rate_changed"] = RuntimeError("cannot run at 50 Hz")
    await ec.set_rate(50)
    assert ec.get_rate() == 50.0
    assert ec.get_component_state(b) is S.ERROR
    assert journal.names("B")[-3:] == ["on_rate_changed", "on_deactivated", "on_aborting"]
    b.fail["on_shutdown"] = RC.RTC_ERROR
    await ec.stop()
    assert not ec.is_running()


async def test_errors_are_per_context(virtual_clock: VirtualClock, journal: Journal) -> None:
    a = Recorder("A", journal, virtual_clock)
    await a.initialize()
    async with (
        PeriodicExecutionContext(100, clock=virtual_clock) as fast,
        PeriodicExecutionContext(10, clock=virtual_clock) as slow,
    ):
        for ec in (fast, slow):
            await ec.add_component(a)
            await ec.start()
            await ec.activate_component(a)
        fast_handle = a.get_context_handle(fast)

        async def fail_in_fast(exec_handle: int) -> CallbackResult:
            return RC.RTC_ERROR if exec_handle == fast_handle else None

        a.on_execute = fail_in_fast  # type: ignore[method-assign]
        await until(virtual_clock, 150)
        assert fast.get_component_state(a) is S.ERROR
        assert slow.get_component_state(a) is S.ACTIVE
        await a.exit()


async def test_stop_waits_for_the_running_cycle_and_no_cycle_follows(
    virtual_clock: VirtualClock, journal: Journal, ec: PeriodicExecutionContext
) -> None:
    a, b = Recorder("A", journal, virtual_clock), Recorder("B", journal, virtual_clock)
    await joined(ec, a, b)
    await ec.start()
    await ec.activate_component(a)
    await ec.activate_component(b)
    a.delays["on_execute"] = 7 * MS  # cycle at 10 ms: A runs 10..17
    await until(virtual_clock, 12)
    mark = journal.mark()
    await ec.stop()
    assert virtual_clock.now_ns() == 17 * MS  # A's on_shutdown waited for its on_execute
    await until(virtual_clock, 50)
    assert sorted(journal.names(since=mark)) == ["A.on_shutdown", "B.on_shutdown"]
    assert journal.of("B", "on_shutdown")[0].time_ns == 12 * MS  # B did not wait for A
    assert ec.get_component_state(a) is S.ACTIVE  # states survive stop
    del a.delays["on_execute"]
    mark = journal.mark()
    await ec.start()
    await until(virtual_clock, 65)
    assert journal.names("A", since=mark) == ["on_startup", "on_execute", "on_state_update"]


async def test_a_component_cannot_wait_for_itself(
    virtual_clock: VirtualClock, journal: Journal, ec: PeriodicExecutionContext
) -> None:
    errors: list[BaseException] = []

    class SelfStopper(Recorder):
        async def on_execute(self, exec_handle: int) -> CallbackResult:
            try:
                await self.get_context(exec_handle).deactivate_component(self)
            except PreconditionNotMetError as exc:
                errors.append(exc)
                raise
            return None

    a = SelfStopper("A", journal, virtual_clock)
    await joined(ec, a)
    await ec.start()
    await ec.activate_component(a)
    await until(virtual_clock, 15)  # no deadlock: the call is refused at once
    assert len(errors) == 1
    assert "inside a callback of A" in str(errors[0])
    assert ec.get_component_state(a) is S.ERROR
    assert virtual_clock.now_ns() == 15 * MS


async def test_removed_component_gets_no_more_callbacks(
    virtual_clock: VirtualClock, journal: Journal, ec: PeriodicExecutionContext
) -> None:
    a = Recorder("A", journal, virtual_clock)
    await joined(ec, a)
    await ec.start()
    await ec.activate_component(a)
    await until(virtual_clock, 15)
    await ec.deactivate_component(a)
    await ec.remove_component(a)
    mark = journal.mark()
    await until(virtual_clock, 45)
    assert journal.names(since=mark) == []


async def test_event_driven_cycles(virtual_clock: VirtualClock, journal: Journal) -> None:
    a = Recorder("A", journal, virtual_clock)
    await a.initialize()
    async with EventDrivenExecutionContext(clock=virtual_clock) as ec:
        await ec.add_component(a)
        await ec.start()
        await ec.activate_component(a)
        await until(virtual_clock, 100)
        assert journal.of("A", "on_execute") == []  # nothing without a trigger
        await ec.trigger_and_wait()
        assert journal.names("A")[-2:] == ["on_execute", "on_state_update"]
        # Triggers during a cycle merge into one next cycle.
        a.delays["on_execute"] = 5 * MS
        ec.trigger()
        await until(virtual_clock, 101)
        ec.trigger()
        ec.trigger()
        ec.trigger()
        await until(virtual_clock, 120)
        assert len(journal.of("A", "on_execute")) == 3
        assert ec.stats.skipped == 2
        assert ec.stats.overruns == 0  # no period, no overrun
        await ec.stop()
        with pytest.raises(PreconditionNotMetError):
            await ec.trigger_and_wait()
