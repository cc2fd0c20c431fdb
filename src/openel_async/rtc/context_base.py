"""The base of every execution context (:class:`ExecutionContext`): its participants, the
spec's lifecycle operations, each under the lock of the component it is about and bounded by
``lifecycle_timeout``, and the two-pass cycle its worker task runs.

Re-exported by :mod:`openel_async.rtc.context` (whose docstring describes cycles and
concurrency).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Awaitable, Callable, Iterator
from contextlib import contextmanager
from types import TracebackType
from typing import ClassVar, Self, TypeVar

import anyio
import anyio.abc

from openel_async.logs import get_logger

from ..clock import NS_PER_S, Clock, default_clock
from ..stats import LatenessRecorder
from ._callbacks import Outcome, invoke, outcome_of
from .context_types import ExecutionContextStats, ExecutionKind, LifeCycleState
from .errors import (
    CallbackFailedError,
    PreconditionNotMetError,
    ReturnCode_t,
    RTCBadParameterError,
    RTCError,
    RTCTimeoutError,
    UnsupportedError,
)
from .modes import MultiModeObject
from .participant import HOLDING, Participant
from .rtobject import ObjectState, RTObject

__all__ = ["DEFAULT_LIFECYCLE_TIMEOUT_S", "ExecutionContext"]

log = get_logger(__name__)

T = TypeVar("T")
_instances = itertools.count(1)

DEFAULT_LIFECYCLE_TIMEOUT_S = 10.0


S = LifeCycleState


class _Alarm:
    """Cancels ``target`` at ``deadline_ns`` on ``clock`` unless cancelled itself first."""

    __slots__ = ("clock", "deadline_ns", "own", "target")

    def __init__(self, clock: Clock, deadline_ns: int) -> None:
        self.clock = clock
        self.deadline_ns = deadline_ns
        self.target = anyio.CancelScope()
        self.own = anyio.CancelScope()

    async def run(self) -> None:
        with self.own:
            await self.clock.sleep_until(self.deadline_ns)
            self.target.cancel()


def _positive_seconds(name: str, value: object) -> int | None:
    if value is None:
        return None
    if (
        isinstance(value, bool)
        or not isinstance(value, int | float)
        or not math.isfinite(value)
        or value <= 0
    ):
        raise RTCBadParameterError(name, value, "a finite number of seconds > 0, or None")
    return max(1, round(value * NS_PER_S))


class ExecutionContext:
    """Base of execution contexts; use one as an async context manager.

    ``async with`` starts the worker task (and the timer of a periodic context); leaving
    the block stops the context if it is running. Participants keep their state across
    stop and start. ``lifecycle_timeout`` (seconds on ``clock``, None for no bound)
    bounds each lifecycle call, including the wait for the component's running callback.
    """

    kind: ClassVar[ExecutionKind] = ExecutionKind.OTHER

    def __init__(
        self,
        *,
        name: str = "",
        owner: RTObject | None = None,
        clock: Clock | None = None,
        lifecycle_timeout: float | None = DEFAULT_LIFECYCLE_TIMEOUT_S,
    ) -> None:
        if not isinstance(name, str):
            raise RTCBadParameterError("name", name, "a string")
        if owner is not None and not isinstance(owner, RTObject):
            raise RTCBadParameterError("owner", owner, "an RTObject or None")
        self.name = name or f"{type(self).__name__}{next(_instances)}"
        self.clock: Clock = clock or default_clock()
        self._timeout_ns = _positive_seconds("lifecycle_timeout", lifecycle_timeout)
        self._owner = owner
        self._participants: dict[RTObject, Participant] = {}
        self._running = False
        self._generation = 0
        self._tg: anyio.abc.TaskGroup | None = None
        self._op_lock = anyio.Lock()
        # The one-slot mailbox between ticks/triggers and the worker.
        self._pending: int | None = None
        self._wake = anyio.Event()
        self._cycles_started = 0
        self._cycles_done = 0
        self._stat_cycles = 0
        self._cycle_end = anyio.Event()
        self._skipped = 0
        self._overruns = 0
        self._drift = 0
        self._lateness = LatenessRecorder()
        self._execution = LatenessRecorder()
        self._last_overrun_warning = -NS_PER_S
        self.log = log.bind(ec=self.name)
        if owner is not None:
            owner._own(self)

    def __repr__(self) -> str:
        state = "Running" if self._running else "Stopped"
        return (
            f"{type(self).__name__}({self.name!r}, {state}, {len(self._participants)} participants)"
        )

    # -- async context manager -----------------------------------------------------------
    async def __aenter__(self) -> Self:
        if self._tg is not None:
            raise PreconditionNotMetError("__aenter__", "entered", "a context not yet entered")
        tg = await anyio.create_task_group().__aenter__()
        self._tg = tg
        try:
            await self._enter()
        except BaseException as exc:
            self._tg = None
            tg.cancel_scope.cancel()
            await tg.__aexit__(type(exc), exc, exc.__traceback__)
            raise
        tg.start_soon(self._worker)
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> bool | None:
        tg = self._tg
        assert tg is not None
        try:
            if self._running:
                with anyio.CancelScope(shield=True):
                    try:
                        await self.stop()
                    except RTCError as error:
                        self.log.warning("stop_on_exit_failed", error=str(error))
        finally:
            # Not in a new (shielded) scope: _exit leaves task groups entered by _enter.
            await self._exit()
            self._tg = None
            tg.cancel_scope.cancel()
        return await tg.__aexit__(exc_type, exc, tb)

    async def _enter(self) -> None:
        """Subclass hook: set up what ticks the context (inside its task group)."""

    async def _exit(self) -> None:
        """Subclass hook: tear it down."""

    def _start_ticking(self) -> None:
        """Subclass hook: cycles may come from now on."""

    def _stop_ticking(self) -> None:
        """Subclass hook: no more cycles."""

    # -- ExecutionContextOperations ---------------------------------------------------
    @property
    def owner(self) -> RTObject | None:
        """The RTC that owns this context (given at construction), or None."""
        return self._owner

    @property
    def participants(self) -> tuple[RTObject, ...]:
        """The participants in execution order."""
        return tuple(self._participants)

    def is_running(self) -> bool:
        """True between start() and stop()."""
        return self._running

    def get_kind(self) -> ExecutionKind:
        """PERIODIC, EVENT_DRIVEN or OTHER."""
        return self.kind

    def get_rate(self) -> float:
        """The rate in Hz (periodic contexts); UNSUPPORTED otherwise."""
        raise UnsupportedError(f"{self.name}: a {self.kind} context has no rate")

    async def set_rate(self, rate: float) -> None:
        """Change the rate in Hz (periodic contexts); UNSUPPORTED otherwise."""
        raise UnsupportedError(f"{self.name}: a {self.kind} context has no rate")

    async def start(self) -> None:
        """Stopped -> Running: on_startup for every participant, then cycles begin.

        PRECONDITION_NOT_MET when already running or outside ``async with``. A failing
        on_startup moves that participant to Error; the context starts all the same.
        """
        self._refuse_own_callback("start")
        async with self._op_lock:
            if self._tg is None:
                raise PreconditionNotMetError(
                    "start", "not entered", "inside 'async with' the context"
                )
            if self._running:
                raise PreconditionNotMetError("start", "Running", ["Stopped"])
            await self._each("start", "on_startup")
            self._generation += 1
            self._running = True
            self._start_ticking()
            self.log.info("ec_started", kind=str(self.kind), participants=len(self._participants))

    async def stop(self) -> None:
        """Running -> Stopped: no cycle starts after this, then on_shutdown for every
        participant (each after its running callback, if any, has returned).

        PRECONDITION_NOT_MET when not running. Participants keep their states.
        """
        self._refuse_own_callback("stop")
        async with self._op_lock:
            if not self._running:
                raise PreconditionNotMetError("stop", "Stopped", ["Running"])
            self._running = False
            self._generation += 1
            self._stop_ticking()
            self._pending = None
            await self._each("stop", "on_shutdown")
            self.log.info("ec_stopped", cycles=self._cycles_done, overruns=self._overruns)

    async def add_component(self, comp: RTObject) -> None:
        """Make ``comp`` a participant (Inactive), after the current ones.

        BAD_PARAMETER when ``comp`` is not an RTObject; PRECONDITION_NOT_MET when it is
        not Alive (initialize it first) or already participates.
        """
        if not isinstance(comp, RTObject):
            raise RTCBadParameterError("comp", comp, "an RTObject")
        if comp in self._participants:
            raise PreconditionNotMetError(
                "add_component", "participating", "a component not yet in this context"
            )
        if comp.state is not ObjectState.ALIVE:
            raise PreconditionNotMetError("add_component", comp.state, [ObjectState.ALIVE])
        handle = comp.attach_context(self)
        self._participants[comp] = Participant(comp, handle)
        self.log.info("component_added", rtc=comp.instance_name, handle=handle)
        await comp._shared_context_event(self, "add")

    async def remove_component(self, comp: RTObject) -> None:
        """Remove a participant that is not Active (after its running callback returned).

        BAD_PARAMETER when ``comp`` does not participate; PRECONDITION_NOT_MET while it
        is Active.
        """
        p = self._participant(comp)
        self._require(p, "remove_component", S.INACTIVE, S.ERROR)
        await comp._shared_context_event(self, "remove")

        async def body() -> None:
            self._require(p, "remove_component", S.INACTIVE, S.ERROR)
            comp.detach_context(p.handle)  # calls _forget

        await self._locked(p, "remove_component", body)
        self.log.info("component_removed", rtc=comp.instance_name)

    async def activate_component(self, comp: RTObject) -> None:
        """Inactive -> Active, running on_activated in the caller's task.

        BAD_PARAMETER when ``comp`` does not participate; PRECONDITION_NOT_MET unless it
        is Inactive. When on_activated fails the component enters Error (on_aborting
        runs) and CallbackFailedError is raised.
        """
        await self._transition(comp, "activate_component", S.INACTIVE, "on_activated", S.ACTIVE)
        await comp._shared_context_event(self, "activate")

    async def deactivate_component(self, comp: RTObject) -> None:
        """Active -> Inactive after the component's running callback returned, running
        on_deactivated in the caller's task; no on_execute follows.

        BAD_PARAMETER when ``comp`` does not participate; PRECONDITION_NOT_MET unless it
        is Active. When on_deactivated fails the component enters Error and
        CallbackFailedError is raised.
        """
        await self._transition(comp, "deactivate_component", S.ACTIVE, "on_deactivated", S.INACTIVE)
        await comp._shared_context_event(self, "deactivate")

    async def _transition(
        self,
        comp: RTObject,
        operation: str,
        source: LifeCycleState,
        callback: str,
        target: LifeCycleState,
    ) -> None:
        """``source`` -> ``target`` when ``callback`` succeeds, else Error and raise."""
        p = self._participant(comp)
        self._require(p, operation, source)

        async def body() -> None:
            self._require(p, operation, source)  # the state may have moved while queued
            outcome = await self._call(p, callback)
            if outcome.ok:
                self._set_state(p, target)
                return
            await self._fail(p, callback, outcome)
            raise CallbackFailedError(comp.instance_name, callback, outcome.code) from outcome.error

        await self._locked(p, operation, body)

    async def reset_component(self, comp: RTObject) -> None:
        """Error -> Inactive when on_reset returns RTC_OK.

        BAD_PARAMETER when ``comp`` does not participate; PRECONDITION_NOT_MET unless it
        is in Error. When on_reset fails the component stays in Error and
        CallbackFailedError is raised.
        """
        p = self._participant(comp)
        self._require(p, "reset_component", S.ERROR)

        async def body() -> None:
            self._require(p, "reset_component", S.ERROR)
            outcome = await self._call(p, "on_reset")
            if outcome.ok:
                self._set_state(p, S.INACTIVE)
                return
            p.rtc._failed("on_reset", outcome)
            raise CallbackFailedError(
                comp.instance_name, "on_reset", outcome.code
            ) from outcome.error

        await self._locked(p, "reset_component", body)

    def get_component_state(self, comp: RTObject) -> LifeCycleState:
        """INACTIVE, ACTIVE or ERROR of a participant (BAD_PARAMETER otherwise)."""
        return self._participant(comp).state

    @property
    def stats(self) -> ExecutionContextStats:
        """Cycle statistics since the context was created (or reset_stats)."""
        return ExecutionContextStats(
            cycles=self._stat_cycles,
            overruns=self._overruns,
            skipped=self._skipped,
            timer_missed=self._timer_missed(),
            lateness=self._lateness.summary(),
            execution=self._execution.summary(),
            last_lateness_ns=self._drift,
        )

    def reset_stats(self) -> None:
        self._stat_cycles = self._overruns = self._skipped = 0
        self._lateness.reset()
        self._execution.reset()

    def _timer_missed(self) -> int:
        return 0

    @property
    def period_ns(self) -> int | None:
        """The cycle period (periodic contexts), None otherwise."""
        return None

    # -- internals used by RTObject / MultiModeObject ---------------------------------
    def _state_of(self, comp: RTObject) -> LifeCycleState | None:
        p = self._participants.get(comp)
        return None if p is None else p.state

    def _forget(self, comp: RTObject) -> None:
        p = self._participants.pop(comp, None)
        if p is not None:
            p.removed = True

    async def _change_mode_now(self, comp: MultiModeObject) -> None:
        p = self._participants.get(comp)
        if p is None:
            return
        if HOLDING.get() is p:
            # Called from one of the component's callbacks in this context.
            if comp._take_pending_mode(self):
                p.mode_due = True
            return

        async def body() -> None:
            if not p.removed and comp._take_pending_mode(self):
                await self._mode_changed(p)

        await self._locked(p, "set_mode", body)

    # -- helpers -----------------------------------------------------------------------
    def _refuse_own_callback(self, operation: str) -> None:
        """start/stop/set_rate run a callback of every participant: called from one of
        them, the caller's own callback could not run (it holds its gate), so refuse
        before changing anything (PRECONDITION_NOT_MET)."""
        p = HOLDING.get()
        if p is not None and self._participants.get(p.rtc) is p:
            raise PreconditionNotMetError(
                operation,
                f"inside a callback of {p.rtc.instance_name} in {self.name}",
                "outside the callbacks of this context's participants "
                "(e.g. from another task or another context)",
            )

    def _participant(self, comp: RTObject) -> Participant:
        p = self._participants.get(comp) if isinstance(comp, RTObject) else None
        if p is None:
            raise RTCBadParameterError("comp", comp, f"a participant of {self.name}")
        return p

    @staticmethod
    def _require(p: Participant, operation: str, *allowed: LifeCycleState) -> None:
        if p.removed:
            raise RTCBadParameterError("comp", p.rtc, "a participant (it was removed)")
        if p.state not in allowed:
            raise PreconditionNotMetError(operation, p.state, allowed)

    def _set_state(self, p: Participant, state: LifeCycleState) -> None:
        if p.state is not state:
            p.rtc.log.info(
                "component_state_changed", ec=self.name, old=str(p.state), new=str(state)
            )
            p.state = state

    async def _call(self, p: Participant, name: str) -> Outcome:
        p.current = name
        outcome = await invoke(name, getattr(p.rtc, name), p.handle)
        p.current = None
        return outcome

    async def _fail(self, p: Participant, callback: str, outcome: Outcome) -> None:
        """A callback failed: the participant enters Error (on_aborting once).

        Leaving Active also deactivates it in this context first (on_deactivated), so a
        failing on_execute gives on_deactivated, on_aborting, then on_error each cycle.
        """
        p.rtc._failed(callback, outcome)
        if p.state is S.ERROR:
            return
        was_active = p.state is S.ACTIVE
        self._set_state(p, S.ERROR)
        if was_active and callback != "on_deactivated":
            deactivated = await self._call(p, "on_deactivated")
            if not deactivated.ok:
                p.rtc._failed("on_deactivated", deactivated)
        aborting = await self._call(p, "on_aborting")
        if not aborting.ok:
            p.rtc._failed("on_aborting", aborting)

    async def _mode_changed(self, p: Participant) -> None:
        outcome = await self._call(p, "on_mode_changed")
        if not outcome.ok:
            await self._fail(p, "on_mode_changed", outcome)

    async def _flush_mode(self, p: Participant) -> None:
        while p.mode_due and not p.removed:
            p.mode_due = False
            await self._mode_changed(p)

    @contextmanager
    def _deadline(self, operation: str, p: Participant) -> Iterator[None]:
        """Bound the block by lifecycle_timeout on the context's clock.

        The alarm is a task of the context's task group that cancels the block's scope
        (no task group around the block, so its exceptions pass through unchanged).
        Outside ``async with`` the block is not bounded (it stays cancellable).
        """
        timeout = self._timeout_ns
        tg = self._tg
        if timeout is None or tg is None:
            yield
            return
        alarm = _Alarm(self.clock, self.clock.now_ns() + timeout)
        tg.start_soon(alarm.run)
        try:
            with alarm.target:
                yield
        finally:
            alarm.own.cancel()
        if alarm.target.cancelled_caught:  # not when the block finished as the alarm fired
            raise RTCTimeoutError(
                f"{operation}({p.rtc.instance_name}) did not finish within "
                f"{timeout / NS_PER_S:g} s on {self.name}"
            )

    async def _locked(self, p: Participant, operation: str, body: Callable[[], Awaitable[T]]) -> T:
        """Run ``body`` holding the participant's lock, bounded by lifecycle_timeout."""
        if HOLDING.get() is p:
            raise PreconditionNotMetError(
                operation,
                f"inside a callback of {p.rtc.instance_name} in {self.name}",
                "outside the component's own callbacks in this context "
                "(return an error code to enter Error instead)",
            )
        cut_off: str | None = None
        try:
            with self._deadline(operation, p):
                await p.gate.enter()
                token = HOLDING.set(p)
                p.current = None
                try:
                    result = await body()
                    await self._flush_mode(p)
                finally:
                    HOLDING.reset(token)
                    # Set only when one of our callbacks did not return (cut off).
                    cut_off, p.current = p.current, None
                    p.gate.leave()
                return result
        except RTCTimeoutError:
            if cut_off is not None and not p.removed:
                # The callback was cut off: the component cannot be trusted any more.
                await self._after_timeout(p, cut_off, operation)
            raise
        raise AssertionError("unreachable")  # pragma: no cover - the deadline raises

    async def _after_timeout(self, p: Participant, callback: str, operation: str) -> None:
        timeout = TimeoutError(f"{callback} cut off by the lifecycle timeout of {operation}")
        try:
            with self._deadline(operation, p):
                await p.gate.enter()
                token = HOLDING.set(p)
                try:
                    await self._fail(p, callback, Outcome(ReturnCode_t.RTC_ERROR, timeout))
                finally:
                    HOLDING.reset(token)
                    p.gate.leave()
        except RTCTimeoutError:
            p.state = S.ERROR
            p.rtc.log.warning("on_aborting_timed_out", ec=self.name)

    async def _each(self, operation: str, callback: str) -> None:
        """Run a context-wide callback for every participant, concurrently, each under
        its own lock; failures move that participant to Error."""

        async def one(p: Participant) -> None:
            async def body() -> None:
                if p.removed:
                    return
                outcome = await self._call(p, callback)
                if not outcome.ok:
                    await self._fail(p, callback, outcome)

            try:
                await self._locked(p, operation, body)
            except RTCError as exc:
                p.rtc.log.warning("context_callback_failed", ec=self.name, error=str(exc))

        parts = tuple(self._participants.values())
        if len(parts) == 1:
            await one(parts[0])
            return
        async with anyio.create_task_group() as tg:
            for p in parts:
                tg.start_soon(one, p)

    # -- cycles --------------------------------------------------------------------------
    def _submit(self, deadline_ns: int) -> None:
        """Queue a cycle due at ``deadline_ns`` (never blocks; called by ticks/triggers)."""
        if self._pending is not None:
            self._skipped += 1
        self._pending = deadline_ns
        self._wake.set()

    async def _worker(self) -> None:
        while True:
            deadline = self._pending
            if deadline is None:
                await self._wake.wait()
                self._wake = anyio.Event()
                continue
            self._pending = None
            if not self._running:
                continue
            try:
                if await self._cycle(deadline):
                    self._stat_cycles += 1
            finally:
                self._cycles_done += 1
                self._cycle_end.set()
                self._cycle_end = anyio.Event()

    async def _cycle(self, deadline_ns: int) -> bool:
        """Run one cycle; False when a stop cut it short."""
        clock = self.clock
        start = clock.now_ns()
        self._cycles_started += 1
        cycle = self._cycles_started
        generation = self._generation
        self._lateness.record(start - deadline_ns)
        self._drift = start - deadline_ns
        parts = tuple(self._participants.values())
        # Pass 1: pending mode change, then on_execute (Active) or on_error (Error).
        for p in parts:
            if self._generation != generation:
                return False
            gate = p.gate
            if not gate.try_enter():
                await gate.enter()
            token = HOLDING.set(p)
            try:
                if p.removed or self._generation != generation:
                    continue
                p.current = None
                modal = p.modal
                if modal is not None and modal._take_pending_mode(self):
                    await self._mode_changed(p)
                state = p.state
                if state is S.ACTIVE:
                    outcome = await self._quick_call(p, "on_execute")
                    if outcome is None:
                        p.executed = cycle
                    else:
                        await self._fail(p, "on_execute", outcome)
                elif state is S.ERROR:
                    outcome = await self._quick_call(p, "on_error")
                    if outcome is not None:
                        p.rtc.log.debug("on_error_failed", ec=self.name, code=outcome.code.name)
                if p.mode_due:
                    await self._flush_mode(p)
            finally:
                HOLDING.reset(token)
                gate.leave()
        # Pass 2: on_state_update of those that executed and are still Active.
        for p in parts:
            if p.executed != cycle:
                continue
            if self._generation != generation:
                return False
            gate = p.gate
            if not gate.try_enter():
                await gate.enter()
            token = HOLDING.set(p)
            try:
                if p.removed or p.state is not S.ACTIVE or self._generation != generation:
                    continue
                outcome = await self._quick_call(p, "on_state_update")
                if outcome is not None:
                    await self._fail(p, "on_state_update", outcome)
                if p.mode_due:
                    await self._flush_mode(p)
            finally:
                HOLDING.reset(token)
                gate.leave()
        self._cycle_finished(start, clock.now_ns())
        return True

    async def _quick_call(self, p: Participant, name: str) -> Outcome | None:
        """The cycle's callback call: None for RTC_OK (the common case, kept cheap)."""
        p.current = name
        try:
            result = await getattr(p.rtc, name)(p.handle)
        except RTCError as exc:
            p.current = None
            code = exc.code if exc.code is not ReturnCode_t.RTC_OK else ReturnCode_t.RTC_ERROR
            return Outcome(code, exc)
        except Exception as exc:
            p.current = None
            return Outcome(ReturnCode_t.RTC_ERROR, exc)
        p.current = None
        if result is None or result is ReturnCode_t.RTC_OK:
            return None
        outcome = outcome_of(name, result)
        return None if outcome.ok else outcome

    def _cycle_finished(self, start_ns: int, end_ns: int) -> None:
        duration = end_ns - start_ns
        self._execution.record(duration)
        period = self.period_ns
        if period is not None and duration > period:
            self._overruns += 1
            if end_ns - self._last_overrun_warning >= NS_PER_S:
                self._last_overrun_warning = end_ns
                self.log.warning(
                    "ec_overrun",
                    cycle_us=duration // 1000,
                    period_us=period // 1000,
                    overruns=self._overruns,
                )
