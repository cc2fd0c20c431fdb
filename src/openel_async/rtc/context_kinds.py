"""The four kinds of execution context: :class:`PeriodicExecutionContext` (a cycle per tick
of an EventTimer), :class:`EventDrivenExecutionContext` (a cycle per trigger),
:class:`ExtTrigExecutionContext` (a cycle per ``tick()``, returning after it) and
:class:`SporadicExecutionContext` (triggered, at most once per minimum interval).

Re-exported by :mod:`openel_async.rtc.context`.
"""

from __future__ import annotations

import math
from typing import ClassVar

import anyio

from ..clock import NS_PER_S, Clock
from ..run_profile_args import MAX_RATE_HZ, MIN_RATE_HZ
from ..timer import EventTimer
from .context_base import DEFAULT_LIFECYCLE_TIMEOUT_S, ExecutionContext
from .context_types import ExecutionKind
from .errors import PreconditionNotMetError, RTCBadParameterError, RTCTimeoutError
from .rtobject import RTObject

__all__ = [
    "EventDrivenExecutionContext",
    "ExtTrigExecutionContext",
    "PeriodicExecutionContext",
    "SporadicExecutionContext",
]


class PeriodicExecutionContext(ExecutionContext):
    """Runs a cycle every period, driven by an EventTimer (absolute deadlines)."""

    kind: ClassVar[ExecutionKind] = ExecutionKind.PERIODIC

    def __init__(
        self,
        rate: float = 1000.0,
        *,
        name: str = "",
        owner: RTObject | None = None,
        clock: Clock | None = None,
        lifecycle_timeout: float | None = DEFAULT_LIFECYCLE_TIMEOUT_S,
    ) -> None:
        _check_rate(rate)
        super().__init__(name=name, owner=owner, clock=clock, lifecycle_timeout=lifecycle_timeout)
        self._rate = float(rate)
        self._timer = EventTimer(1000.0 / self._rate, clock=self.clock, name=f"{self.name}-timer")

    @property
    def timer(self) -> EventTimer:
        """The EventTimer that ticks this context."""
        return self._timer

    @property
    def period_ns(self) -> int:
        return self._timer.period_ns

    def get_rate(self) -> float:
        return self._rate

    async def set_rate(self, rate: float) -> None:
        """Change the rate (MIN_RATE_HZ..MAX_RATE_HZ, BAD_PARAMETER otherwise) from the
        next period on, then run on_rate_changed for every participant (concurrently,
        each under its lock; a failure moves that participant to Error).
        PRECONDITION_NOT_MET, changing nothing, from a participant's own callback."""
        _check_rate(rate)
        self._refuse_own_callback("set_rate")
        async with self._op_lock:
            old = self._rate
            self._rate = float(rate)
            self._timer.set_event_period(1000.0 / self._rate)
            self.log.info("ec_rate_changed", old_hz=old, new_hz=self._rate)
            await self._each("set_rate", "on_rate_changed")

    async def _enter(self) -> None:
        await self._timer.__aenter__()
        self._timer.add_observer(self._on_tick)

    async def _exit(self) -> None:
        self._timer.remove_observer(self._on_tick)
        await self._timer.__aexit__(None, None, None)

    def _start_ticking(self) -> None:
        self._timer.start_timer()

    def _stop_ticking(self) -> None:
        self._timer.stop_timer()

    def _on_tick(self, timer: EventTimer) -> None:
        tick = timer.last_tick
        if tick is not None and self._running:
            self._submit(tick.deadline_ns)

    def _timer_missed(self) -> int:
        return self._timer.stats.missed_ticks


class EventDrivenExecutionContext(ExecutionContext):
    """Runs a cycle when triggered (e.g. from a HAL observer or another component)."""

    kind: ClassVar[ExecutionKind] = ExecutionKind.EVENT_DRIVEN

    def trigger(self) -> None:
        """Run a cycle as soon as possible; never blocks. Triggers that come while a
        cycle runs are merged into one next cycle. PRECONDITION_NOT_MET when stopped."""
        if not self._running:
            raise PreconditionNotMetError("trigger", "Stopped", ["Running"])
        self._submit(self.clock.now_ns())

    async def trigger_and_wait(self) -> None:
        """trigger(), then wait (bounded by lifecycle_timeout) until a cycle that started
        after the trigger has finished."""
        self.trigger()
        target = self._cycles_started + 1
        timeout = self._timeout_ns
        deadline = None if timeout is None else self.clock.now_ns() + timeout
        while self._cycles_done < target and self._running:
            end = self._cycle_end
            if deadline is None:
                await end.wait()
            elif not await _wait_until(self.clock, end, deadline):
                raise RTCTimeoutError(f"trigger_and_wait: no cycle finished on {self.name}")


class ExtTrigExecutionContext(ExecutionContext):
    """Runs one cycle per :meth:`tick`, and nothing else: OpenRTM-aist's
    ExtTrigExecutionContext, the context of components stepped from outside (a simulator,
    a test, a person pressing Enter).

    As in OpenRTM-aist, ``get_kind()`` is PERIODIC and the context has a rate
    (``get_rate``/``set_rate``, ``on_rate_changed``): it is *nominal*, the period each
    tick stands for (e.g. for a component computing ``dt = 1 / rate``); nothing ticks at
    that rate. Lifecycle calls (activate, deactivate, reset...) go through the context as
    in the other contexts and take effect at once, without a tick; unlike OpenRTM-aist,
    activation does not run an extra ``on_execute``: N ticks run exactly N cycles.
    """

    kind: ClassVar[ExecutionKind] = ExecutionKind.PERIODIC

    def __init__(
        self,
        rate: float = 1000.0,
        *,
        name: str = "",
        owner: RTObject | None = None,
        clock: Clock | None = None,
        lifecycle_timeout: float | None = DEFAULT_LIFECYCLE_TIMEOUT_S,
    ) -> None:
        _check_rate(rate)
        super().__init__(name=name, owner=owner, clock=clock, lifecycle_timeout=lifecycle_timeout)
        self._rate = float(rate)
        self._tick_lock = anyio.Lock()
        self._ticks = 0

    @property
    def ticks(self) -> int:
        """Ticks accepted since the context was created."""
        return self._ticks

    def get_rate(self) -> float:
        """The nominal rate in Hz (nothing ticks at it)."""
        return self._rate

    async def set_rate(self, rate: float) -> None:
        """Change the nominal rate (MIN_RATE_HZ..MAX_RATE_HZ, BAD_PARAMETER otherwise),
        then run on_rate_changed for every participant, as a periodic context does.
        PRECONDITION_NOT_MET, changing nothing, from a participant's own callback."""
        _check_rate(rate)
        self._refuse_own_callback("set_rate")
        async with self._op_lock:
            old = self._rate
            self._rate = float(rate)
            self.log.info("ec_rate_changed", old_hz=old, new_hz=self._rate)
            await self._each("set_rate", "on_rate_changed")

    async def tick(self) -> None:
        """Run one cycle (on_execute of the Active participants, on_error of those in
        Error, then on_state_update) and return after it.

        Ticks from several tasks run one cycle each, one after the other (never merged).
        The wait is bounded by ``lifecycle_timeout`` (RTCTimeoutError). Cancelling
        ``tick()`` abandons the wait, not the cycle: once accepted, it runs in the
        context's worker. When ``stop()`` comes first, the cycle is cut short or never
        runs and ``tick()`` returns. PRECONDITION_NOT_MET when the context is stopped
        (OpenRTM-aist ignores such a tick) or from a participant's own callback in this
        context (it would wait for itself).
        """
        self._refuse_own_callback("tick")
        if not self._running:
            raise PreconditionNotMetError("tick", "Stopped", ["Running"])
        timeout = self._timeout_ns
        deadline = None if timeout is None else self.clock.now_ns() + timeout
        async with self._tick_lock:
            # A tick cancelled while waiting may have left its cycle pending or running.
            while self._pending is not None or self._cycles_started > self._cycles_done:
                await self._cycle_change(deadline)
            if not self._running:
                raise PreconditionNotMetError("tick", "Stopped", ["Running"])
            target = self._cycles_done + 1
            generation = self._generation
            self._ticks += 1
            self._submit(self.clock.now_ns())
            while self._cycles_done < target and self._generation == generation:
                await self._cycle_change(deadline)

    async def _cycle_change(self, deadline_ns: int | None) -> None:
        """Wait for the end of a cycle (or a stop), until ``deadline_ns``."""
        end = self._cycle_end
        if deadline_ns is None:
            await end.wait()
        elif not await _wait_until(self.clock, end, deadline_ns):
            raise RTCTimeoutError(f"tick: no cycle finished on {self.name} within the timeout")

    def _stop_ticking(self) -> None:
        # Wake the ticks waiting for a cycle that stop() cuts short or drops.
        self._cycle_end.set()
        self._cycle_end = anyio.Event()


class SporadicExecutionContext(ExecutionContext):
    """Runs a cycle when triggered, at most once per ``min_interval`` seconds.

    The RTC Profile's SPORADIC activity type ("actions run irregularly"); the RTC
    PIM's ExecutionKind has no SPORADIC, so ``get_kind()`` is OTHER. A trigger within
    ``min_interval`` of the previous cycle's trigger is deferred to the end of the
    interval (the classic sporadic task's minimum inter-arrival time); triggers that
    come while one is deferred are merged into it (counted in ``stats.skipped``). With
    ``min_interval=0`` it behaves like an event-driven context.
    """

    kind: ClassVar[ExecutionKind] = ExecutionKind.OTHER

    def __init__(
        self,
        min_interval: float = 0.0,
        *,
        name: str = "",
        owner: RTObject | None = None,
        clock: Clock | None = None,
        lifecycle_timeout: float | None = DEFAULT_LIFECYCLE_TIMEOUT_S,
    ) -> None:
        if (
            isinstance(min_interval, bool)
            or not isinstance(min_interval, int | float)
            or not math.isfinite(min_interval)
            or not 0 <= min_interval <= 1 / MIN_RATE_HZ
        ):
            raise RTCBadParameterError(
                "min_interval", min_interval, f"seconds, 0 <= min_interval <= {1 / MIN_RATE_HZ:g}"
            )
        super().__init__(name=name, owner=owner, clock=clock, lifecycle_timeout=lifecycle_timeout)
        self._min_interval_ns = round(min_interval * NS_PER_S)
        self._last_release: int | None = None
        self._deferred = False

    @property
    def min_interval_ns(self) -> int:
        return self._min_interval_ns

    def trigger(self) -> None:
        """Release a cycle now, or at the end of the minimum interval; never blocks.
        PRECONDITION_NOT_MET when stopped."""
        if not self._running:
            raise PreconditionNotMetError("trigger", "Stopped", ["Running"])
        if self._deferred:
            self._skipped += 1
            return
        now = self.clock.now_ns()
        last = self._last_release
        if last is None or now - last >= self._min_interval_ns:
            self._last_release = now
            self._submit(now)
            return
        due = last + self._min_interval_ns
        assert self._tg is not None
        self._deferred = True
        self._tg.start_soon(self._release_at, due, self._generation)

    async def _release_at(self, due_ns: int, generation: int) -> None:
        try:
            await self.clock.sleep_until(due_ns)
        finally:
            self._deferred = False
        if self._running and self._generation == generation:
            self._last_release = due_ns
            self._submit(due_ns)


async def _wait_until(clock: Clock, event: anyio.Event, deadline_ns: int) -> bool:
    """Wait for ``event`` until ``deadline_ns`` on ``clock``; False on timeout."""
    with anyio.CancelScope() as scope:
        async with anyio.create_task_group() as tg:

            async def alarm() -> None:
                await clock.sleep_until(deadline_ns)
                scope.cancel()

            tg.start_soon(alarm)
            await event.wait()
            tg.cancel_scope.cancel()
    return not scope.cancelled_caught


def _check_rate(rate: object) -> None:
    if (
        isinstance(rate, bool)
        or not isinstance(rate, int | float)
        or not math.isfinite(rate)
        or not MIN_RATE_HZ <= rate <= MAX_RATE_HZ
    ):
        raise RTCBadParameterError(
            "rate", rate, f"a rate in Hz, {MIN_RATE_HZ:g} <= rate <= {MAX_RATE_HZ:g}"
        )
