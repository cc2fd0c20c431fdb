"""The RTC lifecycle (LightweightRTObject) and the return code of every illegal call."""

from __future__ import annotations

import math
from collections.abc import AsyncIterator, Awaitable, Callable
from dataclasses import dataclass

import pytest

from openel_async import VirtualClock
from openel_async.rtc import (
    ECOTHER_OFFSET,
    CallbackFailedError,
    EventDrivenExecutionContext,
    ExecutionKind,
    LifeCycleState,
    MultiModeObject,
    ObjectState,
    PeriodicExecutionContext,
    PreconditionNotMetError,
    ReturnCode_t,
    RTCBadParameterError,
    RTCError,
    RTObject,
    UnsupportedError,
)

from .helpers import Journal, ModalRecorder, Recorder

RC = ReturnCode_t


def state_of(rtc: RTObject) -> ObjectState:
    return rtc.state  # a call: mypy does not carry a narrowed state across an await


@dataclass
class World:
    clock: VirtualClock
    journal: Journal
    a: Recorder
    b: ModalRecorder
    ec: PeriodicExecutionContext
    other: EventDrivenExecutionContext

    async def alive(self, *comps: RTObject) -> None:
        for comp in comps:
            await comp.initialize()

    async def joined(self, comp: RTObject) -> None:
        if comp.state is ObjectState.CREATED:
            await comp.initialize()
        await self.ec.add_component(comp)

    async def active(self, comp: RTObject) -> None:
        await self.joined(comp)
        await self.ec.activate_component(comp)

    async def in_error(self, comp: Recorder) -> None:
        await self.joined(comp)
        comp.fail["on_activated"] = RC.RTC_ERROR
        with pytest.raises(CallbackFailedError):
            await self.ec.activate_component(comp)
        del comp.fail["on_activated"]
        assert self.ec.get_component_state(comp) is LifeCycleState.ERROR


@pytest.fixture
async def world(virtual_clock: VirtualClock, journal: Journal) -> AsyncIterator[World]:
    a = Recorder("A", journal, virtual_clock)
    b = ModalRecorder("B", journal, virtual_clock)
    async with (
        PeriodicExecutionContext(100.0, clock=virtual_clock, owner=a, name="ec") as ec,
        EventDrivenExecutionContext(clock=virtual_clock, name="other") as other,
    ):
        yield World(virtual_clock, journal, a, b, ec, other)


# -- the normal lifecycle ----------------------------------------------------------------


async def test_lifecycle_from_created_to_finalized(world: World) -> None:
    a, ec = world.a, world.ec
    assert a.state is ObjectState.CREATED
    assert a.get_owned_contexts() == (ec,)
    assert a.get_participating_contexts() == ()
    assert not a.is_alive(ec)
    await a.initialize()
    assert state_of(a) is ObjectState.ALIVE
    assert not a.is_alive(ec)  # alive, but not in that context
    await ec.add_component(a)
    assert a.is_alive(ec)
    handle = a.get_context_handle(ec)
    assert handle == 0  # the first context an RTC owns
    assert a.get_context(handle) is ec
    assert a.get_participating_contexts() == (ec,)
    assert ec.get_component_state(a) is LifeCycleState.INACTIVE
    assert ec.participants == (a,)
    await ec.remove_component(a)
    assert a.get_participating_contexts() == ()
    assert len(ec.participants) == 0
    await a.finalize()
    assert state_of(a) is ObjectState.FINALIZED
    assert world.journal.names("A") == ["on_initialize", "on_finalize"]


async def test_handles_of_other_contexts_start_at_the_offset(world: World) -> None:
    await world.alive(world.b)
    await world.ec.add_component(world.b)
    await world.other.add_component(world.b)
    assert world.b.get_context_handle(world.ec) == ECOTHER_OFFSET
    assert world.b.get_context_handle(world.other) == ECOTHER_OFFSET + 1
    assert world.b.get_owned_contexts() == ()
    assert world.ec.owner is world.a and world.other.owner is None


async def test_exit_stops_owned_contexts_deactivates_and_finalizes(world: World) -> None:
    a, b, ec, other = world.a, world.b, world.ec, world.other
    await world.active(a)
    await world.active(b)
    await other.add_component(a)
    await other.start()
    await other.activate_component(a)
    await ec.start()
    mark = world.journal.mark()
    await a.exit()
    assert not ec.is_running()  # a owns ec
    assert other.is_running()  # a does not own other
    assert a.state is ObjectState.FINALIZED
    assert a.get_participating_contexts() == ()
    assert ec.participants == (b,) and other.participants == ()
    assert ec.get_component_state(b) is LifeCycleState.ACTIVE  # others keep their state
    assert world.journal.names("A", since=mark) == [
        "on_shutdown",
        "on_deactivated",
        "on_deactivated",
        "on_finalize",
    ]


async def test_detach_context_is_the_rtc_side_of_remove_component(world: World) -> None:
    await world.joined(world.a)
    handle = world.a.get_context_handle(world.ec)
    world.a.detach_context(handle)
    assert world.ec.participants == ()
    assert world.a.get_participating_contexts() == ()


async def test_a_failing_on_initialize_leaves_the_rtc_created(world: World) -> None:
    world.a.fail["on_initialize"] = RuntimeError("no device")
    with pytest.raises(CallbackFailedError) as info:
        await world.a.initialize()
    assert info.value.code is RC.RTC_ERROR
    assert info.value.callback == "on_initialize"
    assert isinstance(info.value.__cause__, RuntimeError)
    assert world.a.state is ObjectState.CREATED
    del world.a.fail["on_initialize"]
    await world.a.initialize()
    assert state_of(world.a) is ObjectState.ALIVE


async def test_a_failing_on_finalize_still_finalizes(world: World) -> None:
    await world.a.initialize()
    world.a.fail["on_finalize"] = RC.OUT_OF_RESOURCES
    with pytest.raises(CallbackFailedError) as info:
        await world.a.finalize()
    assert info.value.callback_code is RC.OUT_OF_RESOURCES
    assert world.a.state is ObjectState.FINALIZED


async def test_kinds_rates_and_constructor_checks(virtual_clock: VirtualClock) -> None:
    ec = PeriodicExecutionContext(250, clock=virtual_clock)
    assert ec.get_kind() is ExecutionKind.PERIODIC
    assert ec.get_rate() == 250.0
    assert ec.period_ns == 4_000_000
    assert ec.timer.period_ms == 4.0
    ev = EventDrivenExecutionContext(clock=virtual_clock)
    assert ev.get_kind() is ExecutionKind.EVENT_DRIVEN
    assert ev.period_ns is None
    for bad in (0, -1.0, math.nan, math.inf, "100", True, None, 2e9):
        with pytest.raises(RTCBadParameterError) as info:
            PeriodicExecutionContext(bad, clock=virtual_clock)  # type: ignore[arg-type]
        assert info.value.parameter == "rate"
    for timeout in (0, -1, math.nan, "1"):
        with pytest.raises(RTCBadParameterError) as info:
            EventDrivenExecutionContext(lifecycle_timeout=timeout)  # type: ignore[arg-type]
        assert info.value.parameter == "lifecycle_timeout"
    with pytest.raises(RTCBadParameterError):
        EventDrivenExecutionContext(owner="me")  # type: ignore[arg-type]
    with pytest.raises(RTCBadParameterError):
        RTObject(42)  # type: ignore[arg-type]
    with pytest.raises(RTCBadParameterError):
        MultiModeObject(modes=())
    with pytest.raises(RTCBadParameterError):
        MultiModeObject(modes=("a", "a"))
    with pytest.raises(RTCBadParameterError) as info:
        MultiModeObject(modes=("a", "b"), default_mode="c")
    assert info.value.parameter == "default_mode"
    modal = MultiModeObject(modes=("a", "b"), default_mode="b")
    assert modal.get_default_mode() == modal.get_current_mode() == "b"
    assert modal.get_pending_mode() is None


async def test_entering_a_context_twice_is_refused(virtual_clock: VirtualClock) -> None:
    ec = EventDrivenExecutionContext(clock=virtual_clock)
    async with ec:
        with pytest.raises(PreconditionNotMetError):
            await ec.__aenter__()


# -- every illegal call and its return code ------------------------------------------------

Case = Callable[[World], Awaitable[object]]


async def _initialize_twice(w: World) -> None:
    await w.a.initialize()
    await w.a.initialize()


async def _finalize_created(w: World) -> None:
    await w.a.finalize()


async def _finalize_participating(w: World) -> None:
    await w.joined(w.a)
    await w.a.finalize()


async def _finalize_twice(w: World) -> None:
    await w.a.initialize()
    await w.a.finalize()
    await w.a.finalize()


async def _initialize_finalized(w: World) -> None:
    await w.a.initialize()
    await w.a.finalize()
    await w.a.initialize()


async def _exit_created(w: World) -> None:
    await w.a.exit()


async def _exit_finalized(w: World) -> None:
    await w.a.initialize()
    await w.a.exit()
    await w.a.exit()


async def _attach_not_a_context(w: World) -> None:
    await w.a.initialize()
    w.a.attach_context("ec")  # type: ignore[arg-type]


async def _attach_created(w: World) -> None:
    w.a.attach_context(w.ec)


async def _attach_twice(w: World) -> None:
    await w.joined(w.a)
    w.a.attach_context(w.ec)


async def _detach_unknown_handle(w: World) -> None:
    await w.joined(w.a)
    w.a.detach_context(7)


async def _detach_active(w: World) -> None:
    await w.active(w.a)
    w.a.detach_context(w.a.get_context_handle(w.ec))


async def _detach_not_an_int(w: World) -> None:
    await w.joined(w.a)
    w.a.detach_context("0")  # type: ignore[arg-type]


async def _get_context_unknown(w: World) -> None:
    await w.joined(w.a)
    w.a.get_context(1)


async def _get_context_handle_unknown(w: World) -> None:
    await w.joined(w.a)
    w.a.get_context_handle(w.other)


async def _is_alive_is_not_an_error(w: World) -> None:
    assert w.a.is_alive(w.ec) is False
    raise RTCError("ok", code=RC.RTC_OK)


async def _add_not_a_component(w: World) -> None:
    await w.ec.add_component(object())  # type: ignore[arg-type]


async def _add_created(w: World) -> None:
    await w.ec.add_component(w.a)


async def _add_twice(w: World) -> None:
    await w.joined(w.a)
    await w.ec.add_component(w.a)


async def _add_finalized(w: World) -> None:
    await w.a.initialize()
    await w.a.finalize()
    await w.ec.add_component(w.a)


async def _remove_non_participant(w: World) -> None:
    await w.a.initialize()
    await w.ec.remove_component(w.a)


async def _remove_active(w: World) -> None:
    await w.active(w.a)
    await w.ec.remove_component(w.a)


async def _activate_non_participant(w: World) -> None:
    await w.a.initialize()
    await w.ec.activate_component(w.a)


async def _activate_active(w: World) -> None:
    await w.active(w.a)
    await w.ec.activate_component(w.a)


async def _activate_error(w: World) -> None:
    await w.in_error(w.a)
    await w.ec.activate_component(w.a)


async def _deactivate_inactive(w: World) -> None:
    await w.joined(w.a)
    await w.ec.deactivate_component(w.a)


async def _deactivate_error(w: World) -> None:
    await w.in_error(w.a)
    await w.ec.deactivate_component(w.a)


async def _deactivate_non_participant(w: World) -> None:
    await w.joined(w.a)
    await w.other.deactivate_component(w.a)


async def _reset_inactive(w: World) -> None:
    await w.joined(w.a)
    await w.ec.reset_component(w.a)


async def _reset_active(w: World) -> None:
    await w.active(w.a)
    await w.ec.reset_component(w.a)


async def _reset_non_participant(w: World) -> None:
    await w.ec.reset_component(w.a)


async def _state_non_participant(w: World) -> None:
    w.ec.get_component_state(w.a)


async def _start_running(w: World) -> None:
    await w.ec.start()
    await w.ec.start()


async def _stop_stopped(w: World) -> None:
    await w.ec.stop()


async def _start_outside_async_with(w: World) -> None:
    await PeriodicExecutionContext(10, clock=w.clock).start()


async def _set_rate_zero(w: World) -> None:
    await w.ec.set_rate(0)


async def _set_rate_nan(w: World) -> None:
    await w.ec.set_rate(math.nan)


async def _set_rate_text(w: World) -> None:
    await w.ec.set_rate("50")  # type: ignore[arg-type]


async def _event_driven_get_rate(w: World) -> None:
    w.other.get_rate()


async def _event_driven_set_rate(w: World) -> None:
    await w.other.set_rate(10)


async def _trigger_stopped(w: World) -> None:
    w.other.trigger()


async def _set_unknown_mode(w: World) -> None:
    await w.b.set_mode("turbo")


async def _set_mode_immediate_not_bool(w: World) -> None:
    await w.b.set_mode("safe", immediate=1)  # type: ignore[arg-type]


async def _set_mode_finalized(w: World) -> None:
    await w.b.initialize()
    await w.b.finalize()
    await w.b.set_mode("safe")


async def _mode_in_foreign_context(w: World) -> None:
    await w.joined(w.b)
    w.b.get_current_mode_in_context(w.other)


async def _pending_mode_in_foreign_context(w: World) -> None:
    w.b.get_pending_mode_in_context(w.ec)


async def _mode_of_unknown_handle(w: World) -> None:
    w.b.mode_of(0)


async def _activate_failing(w: World) -> None:
    await w.joined(w.a)
    w.a.fail["on_activated"] = RuntimeError("motor stuck")
    await w.ec.activate_component(w.a)


async def _deactivate_failing(w: World) -> None:
    await w.active(w.a)
    w.a.fail["on_deactivated"] = RC.RTC_ERROR
    await w.ec.deactivate_component(w.a)


async def _reset_failing(w: World) -> None:
    await w.in_error(w.a)
    w.a.fail["on_reset"] = RC.PRECONDITION_NOT_MET
    await w.ec.reset_component(w.a)


CASES: dict[str, tuple[Case, ReturnCode_t]] = {
    "initialize twice": (_initialize_twice, RC.PRECONDITION_NOT_MET),
    "finalize while Created": (_finalize_created, RC.PRECONDITION_NOT_MET),
    "finalize while participating": (_finalize_participating, RC.PRECONDITION_NOT_MET),
    "finalize twice": (_finalize_twice, RC.PRECONDITION_NOT_MET),
    "initialize after finalize": (_initialize_finalized, RC.PRECONDITION_NOT_MET),
    "exit while Created": (_exit_created, RC.PRECONDITION_NOT_MET),
    "exit after exit": (_exit_finalized, RC.PRECONDITION_NOT_MET),
    "attach_context(not a context)": (_attach_not_a_context, RC.BAD_PARAMETER),
    "attach_context while Created": (_attach_created, RC.PRECONDITION_NOT_MET),
    "attach_context twice": (_attach_twice, RC.PRECONDITION_NOT_MET),
    "detach_context(unknown handle)": (_detach_unknown_handle, RC.PRECONDITION_NOT_MET),
    "detach_context while Active": (_detach_active, RC.PRECONDITION_NOT_MET),
    "detach_context(not an int)": (_detach_not_an_int, RC.BAD_PARAMETER),
    "get_context(unknown handle)": (_get_context_unknown, RC.BAD_PARAMETER),
    "get_context_handle(unknown context)": (_get_context_handle_unknown, RC.BAD_PARAMETER),
    "is_alive is a query": (_is_alive_is_not_an_error, RC.RTC_OK),
    "add_component(not a component)": (_add_not_a_component, RC.BAD_PARAMETER),
    "add_component while Created": (_add_created, RC.PRECONDITION_NOT_MET),
    "add_component twice": (_add_twice, RC.PRECONDITION_NOT_MET),
    "add_component after finalize": (_add_finalized, RC.PRECONDITION_NOT_MET),
    "remove_component(non-participant)": (_remove_non_participant, RC.BAD_PARAMETER),
    "remove_component while Active": (_remove_active, RC.PRECONDITION_NOT_MET),
    "activate_component(non-participant)": (_activate_non_participant, RC.BAD_PARAMETER),
    "activate_component while Active": (_activate_active, RC.PRECONDITION_NOT_MET),
    "activate_component while in Error": (_activate_error, RC.PRECONDITION_NOT_MET),
    "deactivate_component while Inactive": (_deactivate_inactive, RC.PRECONDITION_NOT_MET),
    "deactivate_component while in Error": (_deactivate_error, RC.PRECONDITION_NOT_MET),
    "deactivate_component(non-participant)": (_deactivate_non_participant, RC.BAD_PARAMETER),
    "reset_component while Inactive": (_reset_inactive, RC.PRECONDITION_NOT_MET),
    "reset_component while Active": (_reset_active, RC.PRECONDITION_NOT_MET),
    "reset_component(non-participant)": (_reset_non_participant, RC.BAD_PARAMETER),
    "get_component_state(non-participant)": (_state_non_participant, RC.BAD_PARAMETER),
    "start while Running": (_start_running, RC.PRECONDITION_NOT_MET),
    "stop while Stopped": (_stop_stopped, RC.PRECONDITION_NOT_MET),
    "start outside async with": (_start_outside_async_with, RC.PRECONDITION_NOT_MET),
    "set_rate(0)": (_set_rate_zero, RC.BAD_PARAMETER),
    "set_rate(nan)": (_set_rate_nan, RC.BAD_PARAMETER),
    "set_rate('50')": (_set_rate_text, RC.BAD_PARAMETER),
    "get_rate of an event-driven context": (_event_driven_get_rate, RC.UNSUPPORTED),
    "set_rate of an event-driven context": (_event_driven_set_rate, RC.UNSUPPORTED),
    "trigger while Stopped": (_trigger_stopped, RC.PRECONDITION_NOT_MET),
    "set_mode(unknown mode)": (_set_unknown_mode, RC.BAD_PARAMETER),
    "set_mode(immediate=1)": (_set_mode_immediate_not_bool, RC.BAD_PARAMETER),
    "set_mode after finalize": (_set_mode_finalized, RC.PRECONDITION_NOT_MET),
    "get_current_mode_in_context(foreign)": (_mode_in_foreign_context, RC.BAD_PARAMETER),
    "get_pending_mode_in_context(foreign)": (_pending_mode_in_foreign_context, RC.BAD_PARAMETER),
    "mode_of(unknown handle)": (_mode_of_unknown_handle, RC.BAD_PARAMETER),
    "activate with a failing on_activated": (_activate_failing, RC.RTC_ERROR),
    "deactivate with a failing on_deactivated": (_deactivate_failing, RC.RTC_ERROR),
    "reset with a failing on_reset": (_reset_failing, RC.RTC_ERROR),
}


@pytest.mark.parametrize("case", list(CASES))
async def test_return_code_of_illegal_calls(world: World, case: str) -> None:
    action, code = CASES[case]
    with pytest.raises(RTCError) as info:
        await action(world)
    assert info.value.code is code, str(info.value)
    if code is RC.BAD_PARAMETER:
        assert isinstance(info.value, RTCBadParameterError)
        assert info.value.parameter in str(info.value)
    if code is RC.UNSUPPORTED:
        assert isinstance(info.value, UnsupportedError)
