"""Modes (MultiModeObject): pending until the next cycle, immediate changes,
on_mode_changed before on_execute, several contexts and stabilization."""

from __future__ import annotations

from collections.abc import AsyncIterator

import pytest

from openel_async import VirtualClock
from openel_async.rtc import (
    CallbackFailedError,
    CallbackResult,
    EventDrivenExecutionContext,
    LifeCycleState,
    MultiModeObject,
    PeriodicExecutionContext,
    ReturnCode_t,
)

from .helpers import MS, Journal, ModalRecorder


async def until(clock: VirtualClock, ms: float) -> None:
    await clock.sleep_until(round(ms * MS))


@pytest.fixture
async def ec(virtual_clock: VirtualClock) -> AsyncIterator[PeriodicExecutionContext]:
    """100 Hz, cycles at 10, 20, 30 ... ms."""
    async with PeriodicExecutionContext(100.0, clock=virtual_clock, name="ec") as context:
        yield context


@pytest.fixture
async def b(
    virtual_clock: VirtualClock, journal: Journal, ec: PeriodicExecutionContext
) -> ModalRecorder:
    """Active in the running context ``ec``."""
    comp = ModalRecorder("B", journal, virtual_clock)
    await comp.initialize()
    await ec.add_component(comp)
    await ec.start()
    await ec.activate_component(comp)
    return comp


def modes_seen(journal: Journal, since: int) -> list[tuple[str, str | None]]:
    return [(c.callback, c.mode) for c in journal.calls[since:] if c.component == "B"]


async def test_a_mode_is_pending_until_the_next_cycle(
    virtual_clock: VirtualClock, journal: Journal, ec: PeriodicExecutionContext, b: ModalRecorder
) -> None:
    assert b.get_default_mode() == b.get_current_mode() == "normal"
    await until(virtual_clock, 15)
    mark = journal.mark()
    await b.set_mode("safe")
    assert b.get_pending_mode() == "safe"
    assert b.get_pending_mode_in_context(ec) == "safe"
    assert b.get_current_mode() == "normal"
    assert b.get_current_mode_in_context(ec) == "normal"
    assert journal.names(since=mark) == []  # nothing runs before the cycle
    await until(virtual_clock, 25)
    assert modes_seen(journal, mark) == [
        ("on_mode_changed", "safe"),  # first thing of the cycle at 20 ms
        ("on_execute", "safe"),
        ("on_state_update", "safe"),
    ]
    assert journal.of("B", "on_mode_changed")[0].time_ns == 20 * MS
    assert b.get_pending_mode() is None
    assert b.get_pending_mode_in_context(ec) is None
    assert b.get_current_mode() == b.get_current_mode_in_context(ec) == "safe"


async def test_requesting_the_current_mode_again_cancels_the_change(
    virtual_clock: VirtualClock, journal: Journal, ec: PeriodicExecutionContext, b: ModalRecorder
) -> None:
    await until(virtual_clock, 15)
    await b.set_mode("safe")
    await b.set_mode("normal")
    assert b.get_pending_mode() is None
    await until(virtual_clock, 25)
    assert journal.of("B", "on_mode_changed") == []


async def test_immediate_mode_change(
    virtual_clock: VirtualClock, journal: Journal, ec: PeriodicExecutionContext, b: ModalRecorder
) -> None:
    await until(virtual_clock, 15)
    mark = journal.mark()
    await b.set_mode("safe", immediate=True)
    assert virtual_clock.now_ns() == 15 * MS
    assert modes_seen(journal, mark) == [("on_mode_changed", "safe")]
    assert b.get_current_mode() == b.get_current_mode_in_context(ec) == "safe"
    assert b.get_pending_mode() is None
    await until(virtual_clock, 25)
    assert modes_seen(journal, mark)[1:] == [("on_execute", "safe"), ("on_state_update", "safe")]


async def test_immediate_change_waits_for_the_running_callback(
    virtual_clock: VirtualClock, journal: Journal, ec: PeriodicExecutionContext, b: ModalRecorder
) -> None:
    b.delays["on_execute"] = 4 * MS  # the cycle at 10 ms runs on_execute 10..14
    await until(virtual_clock, 12)
    mark = journal.mark()
    await b.set_mode("safe", immediate=True)
    assert virtual_clock.now_ns() == 14 * MS
    assert modes_seen(journal, mark) == [
        ("on_mode_changed", "safe"),  # after on_execute returned, before on_state_update
        ("on_state_update", "safe"),
    ]


async def test_immediate_change_from_the_components_own_callback(
    virtual_clock: VirtualClock, journal: Journal, ec: PeriodicExecutionContext
) -> None:
    class Emergency(ModalRecorder):
        async def on_execute(self, exec_handle: int) -> CallbackResult:
            await self._record("on_execute", exec_handle)
            if self.mode_of(exec_handle) == "normal":
                await self.set_mode("safe", immediate=True)
                assert self.mode_of(exec_handle) == "safe"  # taken at once
            return None

    comp = Emergency("B", journal, virtual_clock)
    await comp.initialize()
    await ec.add_component(comp)
    await ec.start()
    await ec.activate_component(comp)
    await until(virtual_clock, 25)
    assert modes_seen(journal, 0)[-5:] == [
        ("on_execute", "normal"),
        ("on_mode_changed", "safe"),  # right after the calling callback returned
        ("on_state_update", "safe"),
        ("on_execute", "safe"),
        ("on_state_update", "safe"),
    ]
    assert comp.get_current_mode() == "safe"


async def test_inactive_and_error_components_take_modes_too(
    virtual_clock: VirtualClock, journal: Journal, ec: PeriodicExecutionContext, b: ModalRecorder
) -> None:
    await ec.deactivate_component(b)
    await b.set_mode("safe")
    mark = journal.mark()
    await until(virtual_clock, 15)
    assert modes_seen(journal, mark) == [("on_mode_changed", "safe")]  # no on_execute
    b.fail["on_reset"] = ReturnCode_t.RTC_ERROR
    b.fail["on_activated"] = ReturnCode_t.RTC_ERROR
    with pytest.raises(CallbackFailedError):
        await ec.activate_component(b)
    assert ec.get_component_state(b) is LifeCycleState.ERROR
    await b.set_mode("fast")
    mark = journal.mark()
    await until(virtual_clock, 25)
    assert modes_seen(journal, mark) == [("on_mode_changed", "fast"), ("on_error", "fast")]


async def test_failing_on_mode_changed_moves_an_active_component_to_error(
    virtual_clock: VirtualClock, journal: Journal, ec: PeriodicExecutionContext, b: ModalRecorder
) -> None:
    b.fail["on_mode_changed"] = RuntimeError("cannot switch")
    await b.set_mode("safe")
    await until(virtual_clock, 15)
    # Error entered at the start of the cycle: on_error runs in that same cycle.
    assert journal.names("B")[-4:] == [
        "on_mode_changed",
        "on_deactivated",
        "on_aborting",
        "on_error",
    ]
    assert ec.get_component_state(b) is LifeCycleState.ERROR
    assert b.get_current_mode() == "safe"  # the mode was taken all the same


async def test_several_contexts(virtual_clock: VirtualClock, journal: Journal) -> None:
    b = ModalRecorder("B", journal, virtual_clock)
    await b.initialize()
    async with (
        PeriodicExecutionContext(100, clock=virtual_clock, name="periodic") as periodic,
        EventDrivenExecutionContext(clock=virtual_clock, name="events") as events,
    ):
        for ec in (periodic, events):
            await ec.add_component(b)
            await ec.activate_component(b)
        await periodic.start()
        await until(virtual_clock, 15)
        await b.set_mode("safe")
        await until(virtual_clock, 25)
        # The periodic context took it at 20 ms; the stopped event context has not.
        assert b.get_current_mode_in_context(periodic) == "safe"
        assert b.get_pending_mode_in_context(periodic) is None
        assert b.get_current_mode_in_context(events) == "normal"
        assert b.get_pending_mode_in_context(events) == "safe"
        assert b.get_pending_mode() == "safe"
        assert b.get_current_mode() == "normal"  # not stabilized
        await events.start()
        await until(virtual_clock, 45)
        assert b.get_pending_mode() == "safe"  # no cycle without a trigger
        await events.trigger_and_wait()
        assert b.get_current_mode_in_context(events) == "safe"
        assert b.get_pending_mode() is None
        assert b.get_current_mode() == "safe"
        handles = [c.handle or 0 for c in journal.of("B", "on_mode_changed")]
        assert handles == [b.get_context_handle(periodic), b.get_context_handle(events)]
        # Immediate: every context at once, stopped ones included.
        await events.stop()
        mark = journal.mark()
        await b.set_mode("fast", immediate=True)
        assert b.get_current_mode() == "fast"
        assert b.get_current_mode_in_context(events) == "fast"
        assert sorted(c.handle or 0 for c in journal.calls[mark:]) == sorted(handles)
        await b.exit()


async def test_leaving_and_joining_contexts(virtual_clock: VirtualClock, journal: Journal) -> None:
    b = ModalRecorder("B", journal, virtual_clock)
    await b.set_mode("safe")  # no context: stabilizes at once
    assert b.get_current_mode() == "safe" and b.get_pending_mode() is None
    await b.initialize()
    async with (
        EventDrivenExecutionContext(clock=virtual_clock) as one,
        EventDrivenExecutionContext(clock=virtual_clock) as two,
    ):
        await one.add_component(b)
        await two.add_component(b)
        await one.start()
        await b.set_mode("normal")
        await one.trigger_and_wait()
        assert b.get_pending_mode() == "normal"  # ``two`` has not taken it
        await two.remove_component(b)  # the lagging context leaves: stabilized
        assert b.get_pending_mode() is None
        assert b.get_current_mode() == "normal"
        await b.set_mode("fast")
        await two.add_component(b)  # a new context starts in the requested mode
        assert b.get_current_mode_in_context(two) == "fast"
        assert b.get_pending_mode_in_context(two) is None
        assert b.get_pending_mode_in_context(one) == "fast"
        await b.exit()


def test_modes_declared_by_the_class() -> None:
    class Arm(MultiModeObject):
        modes = ("idle", "move", "stop")
        default_mode = "stop"

    arm = Arm()
    assert arm.get_modes() == ("idle", "move", "stop")
    assert arm.get_default_mode() == arm.get_current_mode() == "stop"
    other = Arm(modes=("a", "b"))
    assert other.get_default_mode() == "a"  # the class default is not one of these
