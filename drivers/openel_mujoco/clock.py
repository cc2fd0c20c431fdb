"""LockstepClock: the framework clock of a lockstep simulation; its time IS the simulation time.

The clock itself never moves: :class:`openel_mujoco.MujocoSim` advances it by one physics time
step after each ``mj_step`` and wakes the sleepers whose deadline has come, in deadline order
(ties in arrival order).  The simulation steps only when no task of the event loop is runnable,
so every task sees the physics advance exactly between its waits and a run gives the same
result every time, as fast as the CPU allows.  Work held outside the loop
(``openel_async.clock.external_work``: a worker-thread call through ``run_in_thread``) keeps
it from stepping until the work ends, so no simulated time passes for it.

A deadline between two physics steps is served at the first step at or after it: with a 1 ms
time step a 1.5 ms deadline wakes at 2 ms (lateness reported by an EventTimer: 0.5 ms).  Choose
timer periods that are multiples of the time step.

``call_at`` (the ``InlineScheduler`` capability of ``openel_async.clock``) runs a callback
synchronously inside the simulation loop when time reaches its deadline, before the tasks woken
then: an ``EventTimer`` on this clock ticks its observers that way, with no task switch, so a
control step of plain TimerObservers costs function calls only.

While the simulation is faulted (unstable physics) the clock behaves like
``VirtualClock.autojump``: time jumps to the next deadline whenever the loop is idle, so timers
and timeouts on the clock keep working without physics.

Like :class:`openel_async.VirtualClock`, this clock relies on asyncio (anyio's asyncio backend):
its sleepers are loop futures.
"""

from __future__ import annotations

import asyncio
import heapq
import itertools
import math
from collections.abc import Callable

import anyio.lowlevel

from openel_async.clock import NS_PER_S, DeadlineSleeper, Sleeper, wait_idle
from openel_async.errors import BadParameterError
from openel_async.logs import get_logger

__all__ = ["LockstepClock"]

log = get_logger(__name__)

_heappop = heapq.heappop  # module names: read once per inline tick, not as attributes
_heappush = heapq.heappush


class LockstepClock:
    """Simulation time in integer nanoseconds, advanced by the simulation (never by itself)."""

    def __init__(self, start_ns: int = 0) -> None:
        if isinstance(start_ns, bool) or not isinstance(start_ns, int) or start_ns < 0:
            raise BadParameterError("start_ns", start_ns, "an int >= 0")
        self._now = start_ns
        self._heap: list[tuple[int, int, asyncio.Future[None] | _InlineCall]] = []
        self._seq = itertools.count()
        self._kick: asyncio.Future[None] | None = None
        self.wakeups = 0
        """Sleepers woken so far (a sleeper cancelled before its deadline is not counted)."""

    # -- Clock protocol ----------------------------------------------------------------
    def now_ns(self) -> int:
        return self._now

    async def sleep_until(self, deadline_ns: int) -> None:
        if deadline_ns <= self._now:
            await anyio.lowlevel.checkpoint()
            return
        future: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        heapq.heappush(self._heap, (deadline_ns, next(self._seq), future))
        self.kick()
        try:
            await future
        except asyncio.CancelledError:
            future.cancel()  # dropped when it reaches the top of the heap
            raise

    def sleeper(self) -> Sleeper:
        return DeadlineSleeper(self)

    def call_at(self, deadline_ns: int, callback: Callable[[], int | None]) -> _InlineCall:
        """Call ``callback()`` inside the simulation loop when time reaches ``deadline_ns``
        (:class:`~openel_async.clock.InlineScheduler`), before the tasks woken then run.

        A deadline already reached is served at the next physics step.  A callback that
        returns an int is called again at that deadline, under the same handle (a periodic
        callback re-arms without a new handle per period).  An exception of the callback is
        logged, ends its re-arming and does not stop the simulation.
        """
        call = _InlineCall(callback)
        if deadline_ns <= self._now:
            deadline_ns = self._now + 1
        heapq.heappush(self._heap, (deadline_ns, next(self._seq), call))
        if self._kick is not None:
            self.kick()
        return call

    # -- conveniences ------------------------------------------------------------------
    async def sleep(self, seconds: float) -> None:
        """Sleep ``seconds`` of simulated time."""
        if (
            isinstance(seconds, bool)
            or not isinstance(seconds, int | float)
            or not math.isfinite(seconds)
            or seconds < 0
        ):
            raise BadParameterError("seconds", seconds, "a finite number of seconds >= 0")
        await self.sleep_until(self._now + round(seconds * NS_PER_S))

    def next_deadline(self) -> int | None:
        heap = self._heap
        while heap and heap[0][2].done():
            heapq.heappop(heap)
        return heap[0][0] if heap else None

    # -- driven by the simulation ------------------------------------------------------
    def _advance(self, delta_ns: int) -> bool:
        """Move time forward by ``delta_ns`` and wake the sleepers now due; True if any woke."""
        now = self._now + delta_ns
        self._now = now
        heap = self._heap
        if not heap or heap[0][0] > now:
            return False
        return self._wake_due(now)

    def _jump_to_next(self) -> bool:
        """Without physics: set time to the next deadline and serve what is due then (sleepers
        and callbacks); False if nothing waits on the clock."""
        deadline = self.next_deadline()
        if deadline is None:
            return False
        self._now = max(self._now, deadline)
        self._wake_due(self._now)
        return True

    def _wake_due(self, now: int) -> bool:
        heap = self._heap
        seq = self._seq
        woke = False
        while heap and heap[0][0] <= now:
            entry = _heappop(heap)[2]
            if type(entry) is _InlineCall:
                if entry._done:
                    continue
                # the callback, inline (a control step's timer tick comes this way)
                try:
                    again = entry._callback()
                except Exception:  # a broken callback must not stop the physics
                    log.exception("clock_callback_failed", callback=repr(entry._callback))
                    again = None
                if entry._done or type(again) is not int:  # cancelled meanwhile, or not re-armed
                    entry._done = True
                    continue
                # periodic: re-armed under the same handle
                _heappush(heap, (again if again > now else now + 1, next(seq), entry))
            elif not entry.done():
                entry.set_result(None)  # type: ignore[union-attr]  # a sleeper's future
                self.wakeups += 1
                woke = True
        return woke

    async def _wait_kick(self) -> None:
        """Wait until a sleeper is added or :meth:`kick` is called (used while idle)."""
        self._kick = asyncio.get_running_loop().create_future()
        try:
            await self._kick
        finally:
            self._kick = None

    def kick(self) -> None:
        kick = self._kick
        if kick is not None and not kick.done():
            kick.set_result(None)

    def __repr__(self) -> str:
        return f"LockstepClock(now_ns={self._now})"


class _InlineCall:
    """A pending :meth:`LockstepClock.call_at` callback (the ScheduledCall handle)."""

    __slots__ = ("_callback", "_done")

    def __init__(self, callback: Callable[[], int | None]) -> None:
        self._callback = callback
        self._done = False

    def done(self) -> bool:
        return self._done

    def cancel(self) -> None:
        self._done = True


async def settle() -> None:
    """Yield until no other task is runnable (every task waits on time, I/O or an event) and
    no work is held outside the loop (:func:`openel_async.clock.external_work`).

    Asks the idle detector of the event loop that every VirtualClock of the loop shares
    (:func:`openel_async.clock.wait_idle`), so a lockstep simulation and an auto-jumping
    VirtualClock in one loop (the ``virtual_clock`` test fixture, say) take turns instead of
    keeping each other busy forever.
    """
    await wait_idle()
