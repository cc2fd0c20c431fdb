"""Clocks: every time-based part of the framework reads and waits through one.

``MonotonicClock`` is the real clock (CLOCK_MONOTONIC in integer nanoseconds).
``VirtualClock`` is deterministic simulated time for tests and lockstep simulation:
with auto-jump running, time leaps to the next deadline whenever every task is
waiting, so ten simulated seconds of a 1 kHz timer take a fraction of a wall second.

"Every task is waiting" is decided by :func:`wait_idle`, one idle detector per event
loop shared by every clock on it: idle moments are handed to the waiting clocks one
at a time, in the order they asked, so several virtual clocks (or concurrent
``advance`` calls) in one loop take turns instead of keeping each other busy.

Work that runs outside the loop (a worker thread, a subprocess the loop waits for) leaves
the loop with nothing runnable although something is still happening: :func:`external_work`
(and :func:`run_in_thread`, which wraps ``anyio.to_thread.run_sync`` in it) tells the
detector so, and no idle moment is handed out while such work is in flight, so simulated
time does not pass during it. It is for bounded work only: a thread that waits for
external input (a bus reader, standard input) must not hold it, or time would stop.

A VirtualClock that nothing drives (no auto-jump, no ``advance``) would leave its sleepers
waiting forever in silence; once the loop has had nothing else to do for the clock's
``stall_timeout`` of real time, they get a :class:`VirtualClockStalledError` saying how to
drive it.
"""

from __future__ import annotations

import functools
import heapq
import itertools
import math
import time
import weakref
from collections import Counter, deque
from collections.abc import AsyncIterator, Callable, Coroutine
from contextlib import asynccontextmanager
from types import TracebackType
from typing import TYPE_CHECKING, Any, Protocol, TypeVar, TypeVarTuple, cast, runtime_checkable

import anyio
import anyio.abc
import anyio.to_thread

from openel_async.logs import get_logger

from . import timerfd
from .errors import BadParameterError, StateError, VirtualClockStalledError
from .lazy import first_use

if TYPE_CHECKING:
    import asyncio

NS_PER_S = 1_000_000_000
NS_PER_MS = 1_000_000

EXTERNAL_WORK_WARNING_S = 10.0
"""Real seconds an idle waiter waits for external work before a warning names what is in
flight (once per wait: a clock held that long usually means work that never ends)."""

STALL_TIMEOUT_S = 5.0
"""Default ``VirtualClock(stall_timeout=...)``: real seconds of an otherwise idle event loop
after which the sleepers of a clock that nothing drives get a VirtualClockStalledError."""

_STALL_SAMPLE_S = 0.1
"""Real seconds between two looks of a manual clock's stall watchdog (at most)."""

log = get_logger(__name__)

T = TypeVar("T")
PosArgsT = TypeVarTuple("PosArgsT")


# asyncio is imported at the first wait, not with the module: every part of the framework
# imports the clocks, and a program that never waits (an app printing its --help) does not
# load asyncio. The waits call these globals, rebound then to asyncio's own functions.
_running_loop: Callable[[], asyncio.AbstractEventLoop] = first_use(
    globals(), "_running_loop", "asyncio", "get_running_loop"
)
_sleep: Callable[[float], Coroutine[Any, Any, None]] = first_use(
    globals(), "_sleep", "asyncio", "sleep"
)


@runtime_checkable
class Sleeper(Protocol):
    """A reusable waiter for absolute deadlines (one per periodic loop)."""

    async def sleep_until(self, deadline_ns: int) -> None: ...

    def close(self) -> None: ...


@runtime_checkable
class Clock(Protocol):
    """Time source of components, timers and simulations; integer nanoseconds."""

    def now_ns(self) -> int: ...

    async def sleep_until(self, deadline_ns: int) -> None: ...

    def sleeper(self) -> Sleeper:
        """A waiter suited to periodic absolute deadlines (a timerfd on Linux)."""
        ...


@runtime_checkable
class ScheduledCall(Protocol):
    """Handle of a :meth:`InlineScheduler.call_at` callback."""

    def cancel(self) -> None: ...


@runtime_checkable
class InlineScheduler(Clock, Protocol):
    """A clock that calls a function synchronously as its time passes a deadline.

    Simulation clocks that advance time themselves between physics steps offer it
    (``openel_mujoco.LockstepClock``): the callback runs inside the simulation loop, before
    any task woken at the same time, so an :class:`~openel_async.EventTimer` on such a
    clock ticks its observers without a task switch.
    """

    def call_at(self, deadline_ns: int, callback: Callable[[], int | None]) -> ScheduledCall:
        """Call ``callback()`` when time reaches ``deadline_ns``; if it returns an int, call
        it again at that deadline under the same handle (periodic callbacks), else once."""
        ...


class DeadlineSleeper:
    """A Sleeper over any clock's ``sleep_until`` (the portable fallback on real time)."""

    def __init__(self, clock: Clock) -> None:
        self._clock = clock

    async def sleep_until(self, deadline_ns: int) -> None:
        await self._clock.sleep_until(deadline_ns)

    def close(self) -> None:
        pass


class _TimerfdSleeper:
    def __init__(self) -> None:
        self._fd = timerfd.Timerfd()

    async def sleep_until(self, deadline_ns: int) -> None:
        if deadline_ns <= time.monotonic_ns():
            await anyio.lowlevel.checkpoint()
            return
        await self._fd.wait_until(deadline_ns)

    def close(self) -> None:
        self._fd.close()


class ClockBase:
    """What the framework's clocks (:class:`MonotonicClock`, :class:`VirtualClock`) add to
    the :class:`Clock` protocol: the reading they started at and the seconds elapsed since a
    reading. A clock of your own may subclass it (and set ``start_ns``); code that accepts
    any :class:`Clock` must not rely on it.
    """

    start_ns: int
    """This clock's reading when it was created (``now_ns()`` then)."""

    def now_ns(self) -> int:
        raise NotImplementedError

    def elapsed_s(self, since_ns: int | None = None) -> float:
        """Seconds of this clock from ``since_ns`` (an earlier ``now_ns()`` of this clock)
        to now; by default since the clock started (:attr:`start_ns`)."""
        if since_ns is None:
            since_ns = self.start_ns
        elif isinstance(since_ns, bool) or not isinstance(since_ns, int):
            raise BadParameterError(
                "since_ns", since_ns, "an int (a reading of this clock's now_ns(), ns) or None"
            )
        return (self.now_ns() - since_ns) / NS_PER_S


PRECISE_BELOW_NS = 2_000_000
""":meth:`MonotonicClock.sleep_until` waits shorter than this (ns) on a timerfd."""


class MonotonicClock(ClockBase):
    """The real clock: CLOCK_MONOTONIC, with timerfd deadlines where available.

    ``now_ns()`` is ``time.monotonic_ns()``: nanoseconds from an unspecified point (on
    Linux, the boot, not counting time suspended), the same for every MonotonicClock of the
    machine and never going back; only differences between readings mean something (it is
    not wall-clock time). :attr:`start_ns` is the reading when the clock was created
    (for :func:`default_clock`, when ``openel_async`` was imported) and
    ``elapsed_s(since_ns=None)`` the seconds since it or since a reading.
    """

    def __init__(self, *, use_timerfd: bool = True) -> None:
        if not use_timerfd:
            self.use_timerfd = False
        self.start_ns = time.monotonic_ns()

    @functools.cached_property
    def use_timerfd(self) -> bool:
        """Whether waits take timerfd deadlines: asked for and available (Linux). Looked up
        at its first read (that loads ctypes and libc), not when the clock is made: the
        default clock is made when the framework is imported."""
        return timerfd.available()

    # time.monotonic_ns itself (no Python frame): read once per command and per tick.
    now_ns = staticmethod(time.monotonic_ns)

    async def sleep_until(self, deadline_ns: int) -> None:
        """Sleep until ``deadline_ns``. A wait shorter than :data:`PRECISE_BELOW_NS` waits
        on a timerfd of its own (where available): asyncio's selector rounds its timeout up
        to a whole millisecond, so a 2 us wait would last 1 ms (a simulated motor's short
        move, COMPLETED a millisecond late); longer waits are ``anyio.sleep``."""
        remaining = deadline_ns - time.monotonic_ns()
        if remaining <= 0:
            await anyio.lowlevel.checkpoint()
        elif remaining < PRECISE_BELOW_NS and self.use_timerfd:
            fd = timerfd.Timerfd()
            try:
                await fd.wait_until(deadline_ns)
            finally:
                fd.close()
        else:
            await anyio.sleep(remaining / NS_PER_S)

    def sleeper(self) -> Sleeper:
        if self.use_timerfd:
            try:
                return _TimerfdSleeper()
            except OSError:
                pass
        return DeadlineSleeper(self)

    def __repr__(self) -> str:
        return f"MonotonicClock(use_timerfd={self.use_timerfd})"


class _TimerfdScheduler:
    """An :class:`InlineScheduler` view of a timerfd :class:`MonotonicClock` on the running
    asyncio loop (see :func:`realtime_scheduler`)."""

    __slots__ = ("_loop", "now_ns")

    def __init__(self, clock: MonotonicClock, loop: asyncio.AbstractEventLoop) -> None:
        self.now_ns = clock.now_ns
        self._loop = loop

    def call_at(self, deadline_ns: int, callback: Callable[[], int | None]) -> ScheduledCall:
        return timerfd.TimerfdCall(self._loop, deadline_ns, callback)


def realtime_scheduler(clock: Clock) -> InlineScheduler | None:
    """Periodic callbacks on the real clock without a task: for the default
    :class:`MonotonicClock` with timerfd, on an asyncio loop, a scheduler whose ``call_at``
    arms one timerfd that the loop watches and calls the callback from (one loop pass per
    call, no task wake-up, no epoll registration per wait); None otherwise. An
    :class:`~openel_async.EventTimer` on such a clock ticks this way (the clock itself is
    not an :class:`InlineScheduler`: nothing else treats it as a lockstep clock)."""
    if type(clock) is not MonotonicClock or not clock.use_timerfd:
        return None
    try:
        loop = _running_loop()
    except RuntimeError:  # not asyncio (trio)
        return None
    return _TimerfdScheduler(clock, loop)  # type: ignore[return-value]


_DEFAULT_CLOCK = MonotonicClock()


def default_clock() -> MonotonicClock:
    """The process-wide real clock used where no clock is given."""
    return _DEFAULT_CLOCK


class VirtualClock(ClockBase):
    """Deterministic simulated time, from ``start_ns`` (0 by default: ``now_ns()`` and
    ``elapsed_s()`` count simulated time since the start).

    Sleepers are woken strictly in deadline order (ties in arrival order). Time moves
    only through :meth:`advance`/:meth:`advance_to` (manual mode) or, inside
    :meth:`autojump`, whenever every other task of the event loop is waiting; the two
    modes exclude each other (:class:`StateError`).

    ``stall_timeout`` (real seconds, or None: never): in manual mode, when tasks sleep on
    the clock and, for that long, the clock did not move, is not in auto-jump, no
    ``advance`` runs and the event loop had nothing else to do (no runnable task, no
    :func:`external_work`, no I/O being waited for, no real-time timer other than the
    deadlines of cancel scopes), every sleeper gets a :class:`VirtualClockStalledError`
    naming the ways to drive the clock, instead of waiting forever.
    """

    def __init__(self, start_ns: int = 0, *, stall_timeout: float | None = STALL_TIMEOUT_S) -> None:
        _check_ns("start_ns", start_ns, 0)
        if stall_timeout is not None and (
            isinstance(stall_timeout, bool)
            or not isinstance(stall_timeout, int | float)
            or not (math.isfinite(stall_timeout) and stall_timeout > 0)
        ):
            raise BadParameterError(
                "stall_timeout", stall_timeout, "a finite number of real seconds > 0, or None"
            )
        self.stall_timeout = stall_timeout
        """Real seconds of an idle loop before the sleepers of this clock, if nothing drives
        it, get a VirtualClockStalledError (None: never); may be changed at any time."""
        self._watchdog: asyncio.TimerHandle | None = None
        self._idle_since: float | None = None
        self._seen = (0, start_ns)
        self.start_ns = start_ns
        self._now = start_ns
        self._heap: list[tuple[int, int, asyncio.Future[None]]] = []
        self._seq = itertools.count()
        self._new_sleeper: asyncio.Future[None] | None = None
        self._autojumping = False
        self._advancing = 0  # advance calls running or queued
        self._advance_lock = anyio.Lock()
        self.jumps = 0

    def now_ns(self) -> int:
        return self._now

    def sleeper(self) -> Sleeper:
        return DeadlineSleeper(self)

    async def sleep_until(self, deadline_ns: int) -> None:
        if deadline_ns <= self._now:
            await anyio.lowlevel.checkpoint()
            return
        # Loop futures rather than anyio.Event: this is the clock's innermost hot path,
        # and the clock is tied to the asyncio backend anyway (see wait_idle).
        loop = _running_loop()
        future: asyncio.Future[None] = loop.create_future()
        heapq.heappush(self._heap, (deadline_ns, next(self._seq), future))
        waker = self._new_sleeper
        if waker is not None and not waker.done():
            waker.set_result(None)
        elif not self._autojumping and self._watchdog is None:  # manual: watch for a stall
            self._arm_watchdog(loop)
        try:
            await future
        except BaseException:  # cancelled (the future itself, if failed, is done already)
            future.cancel()  # the driver skips cancelled entries
            raise

    async def sleep(self, seconds: float) -> None:
        await self.sleep_until(self._now + round(seconds * NS_PER_S))

    def next_deadline(self) -> int | None:
        self._drop_cancelled()
        return self._heap[0][0] if self._heap else None

    @property
    def autojumping(self) -> bool:
        """Whether auto-jump drives this clock (then :meth:`advance` is refused)."""
        return self._autojumping

    async def advance(self, delta_ns: int) -> None:
        """Move time forward by ``delta_ns``, waking every sleeper due on the way in order.

        Concurrent calls on one clock run one after another, in call order; ``delta_ns``
        counts from the time at which the call's turn comes.
        """
        _check_ns("delta_ns", delta_ns, 0)
        self._check_manual("advance")
        self._advancing += 1
        try:
            async with self._advance_lock:
                await self._advance_to(self._now + delta_ns)
        finally:
            self._advancing -= 1

    async def advance_to(self, target_ns: int) -> None:
        """Move time forward to ``target_ns``, waking every sleeper due on the way in order.

        Concurrent calls on one clock run one after another, in call order; a call whose
        target an earlier one already passed only lets the woken tasks run.
        """
        _check_ns("target_ns", target_ns, self._now, f"now ({self._now})")
        self._check_manual("advance_to")
        self._advancing += 1
        try:
            async with self._advance_lock:
                await self._advance_to(max(target_ns, self._now))
        finally:
            self._advancing -= 1

    async def _advance_to(self, target_ns: int) -> None:
        await wait_idle()
        while True:
            deadline = self.next_deadline()
            if deadline is None or deadline > target_ns:
                break
            self._wake_next()
            await wait_idle()
        self._now = target_ns

    async def run_autojump(self) -> None:
        """Drive time forever: whenever the loop is idle, jump to the next deadline.

        Refused (:class:`StateError`) while another auto-jump or an :meth:`advance`
        drives this clock.
        """
        self._claim_autojump("run_autojump")
        try:
            await self._drive()
        finally:
            self._autojumping = False

    @asynccontextmanager
    async def autojump(self) -> AsyncIterator[VirtualClock]:
        """Run auto-jump in the background for the duration of the block.

        Refused (:class:`StateError`) while another auto-jump or an :meth:`advance`
        drives this clock; inside the block, :meth:`advance` is refused.
        """
        self._claim_autojump("autojump")
        try:
            async with anyio.create_task_group() as tg:
                tg.start_soon(self._drive)
                try:
                    yield self
                finally:
                    tg.cancel_scope.cancel()
        finally:
            self._autojumping = False

    def _claim_autojump(self, operation: str) -> None:
        if self._autojumping:
            raise StateError(operation, "auto-jump", ["manual"])
        if self._advancing:
            raise StateError(operation, "advancing", ["manual, with no advance running"])
        self._autojumping = True

    def _check_manual(self, operation: str) -> None:
        if self._autojumping:
            raise StateError(operation, "auto-jump", ["manual"])

    async def _drive(self) -> None:
        loop = _running_loop()
        detector = _idle_detector(loop)
        while True:
            await detector.wait(loop)
            if self.next_deadline() is None:
                self._new_sleeper = loop.create_future()
                try:
                    await self._new_sleeper
                finally:
                    self._new_sleeper = None
                continue
            self._wake_next()

    # -- the stall watchdog (manual mode) -------------------------------------------------------
    def _arm_watchdog(self, loop: asyncio.AbstractEventLoop) -> None:
        timeout = self.stall_timeout
        if timeout is None:
            return
        self._idle_since = None
        self._seen = (self.jumps, self._now)
        self._watchdog = loop.call_later(min(_STALL_SAMPLE_S, timeout / 4), self._watch_stall, loop)

    def _watch_stall(self, loop: asyncio.AbstractEventLoop) -> None:
        """One look of the watchdog: a stall is a loop idle for ``stall_timeout`` while this
        clock has sleepers and does not move (see the class docstring)."""
        self._watchdog = None
        timeout = self.stall_timeout
        sleepers = [future for _, _, future in self._heap if not future.done()]
        if timeout is None or not sleepers:
            return  # the next sleeper arms it again
        now = loop.time()
        seen = (self.jumps, self._now)
        if self._autojumping or self._advancing or seen != self._seen or not _loop_idle(loop):
            self._idle_since = None
            self._seen = seen
        elif self._idle_since is None:
            self._idle_since = now
        elif now - self._idle_since >= timeout:
            self._stalled(sleepers, now - self._idle_since)
            return
        self._watchdog = loop.call_later(min(_STALL_SAMPLE_S, timeout / 4), self._watch_stall, loop)

    def _stalled(self, sleepers: list[asyncio.Future[None]], idle_s: float) -> None:
        deadline = min(d for d, _, future in self._heap if not future.done())
        message = (
            f"{self!r}: nothing advances this clock: {len(sleepers)} task(s) sleep on it "
            f"(the earliest until {deadline} ns), it is not in auto-jump, no advance() runs "
            f"and the event loop has had nothing else to do for {idle_s:.1f} s of real time. "
            "Drive it: run the code inside `async with clock.autojump():` (or a task running "
            "`await clock.run_autojump()`), or call `await clock.advance(delta_ns)` / "
            "`await clock.advance_to(t_ns)` from another task; in pytest, the "
            "`virtual_clock` fixture is a clock in auto-jump. "
            f"(This check fires after stall_timeout={self.stall_timeout:g} s of an idle "
            "loop; VirtualClock(stall_timeout=None) turns it off.)"
        )
        log.warning("virtual_clock_stalled", clock=repr(self), sleepers=len(sleepers))
        for future in sleepers:
            future.set_exception(VirtualClockStalledError(message))

    def _drop_cancelled(self) -> None:
        heap = self._heap
        while heap and heap[0][2].done():
            heapq.heappop(heap)

    def _wake_next(self) -> None:
        """Set time to the earliest deadline and wake every sleeper due then."""
        heap = self._heap
        deadline = heap[0][0]
        self._now = deadline
        self.jumps += 1
        while heap and heap[0][0] == deadline:
            future = heapq.heappop(heap)[2]
            if not future.done():
                future.set_result(None)

    def __repr__(self) -> str:
        return f"VirtualClock(now_ns={self._now})"


_DEADLINE_CALLBACKS: frozenset[object] | None = None


def _deadline_callbacks() -> frozenset[object]:
    """Callbacks of real-time timers that only cancel a wait (a cancel scope's deadline,
    ``asyncio.timeout``, ``wait_for``) or watch a clock: they never drive a VirtualClock."""
    global _DEADLINE_CALLBACKS
    if _DEADLINE_CALLBACKS is None:
        from asyncio import tasks, timeouts

        from anyio._backends import _asyncio as anyio_asyncio

        found = (
            VirtualClock._watch_stall,
            getattr(timeouts.Timeout, "_on_timeout", None),
            getattr(tasks, "_release_waiter", None),
            getattr(anyio_asyncio.CancelScope, "_timeout", None),
        )
        _DEADLINE_CALLBACKS = frozenset(f for f in found if f is not None)
    return _DEADLINE_CALLBACKS


def _loop_idle(loop: asyncio.AbstractEventLoop) -> bool:
    """Whether nothing in ``loop`` can happen by itself: no runnable callback, no external
    work, no I/O being waited for and no real-time timer but deadlines (False when the loop
    does not expose what this needs: never a stall there)."""
    ready = getattr(loop, "_ready", None)
    scheduled = getattr(loop, "_scheduled", None)
    selector = getattr(loop, "_selector", None)
    if ready is None or scheduled is None or selector is None or ready:
        return False
    detector = _IDLE_DETECTORS.get(loop)
    if detector is not None and detector.external_count:
        return False
    try:
        watched = len(selector.get_map())
    except Exception:
        return False
    if watched > (1 if getattr(loop, "_ssock", None) is not None else 0):  # beyond the self-pipe
        return False
    deadlines = _deadline_callbacks()
    for handle in scheduled:
        if handle.cancelled():
            continue
        callback = handle._callback
        if getattr(callback, "__func__", callback) not in deadlines:
            return False
    return True


def _check_ns(name: str, value: object, minimum: int, what: str | None = None) -> None:
    """Times are integer nanoseconds: reject floats, bools and values below ``minimum``."""
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise BadParameterError(name, value, f"an int >= {what or minimum}")


class _IdleDetector:
    """Hands the idle moments of one event loop to its waiters, one at a time, in FIFO order.

    Only the waiter at the head of the queue polls the loop's ready queue; the others
    wait on a future, outside the ready queue, so they cannot keep the poller from
    seeing the loop idle (two pollers yielding in turn would each always see the other
    runnable: a busy loop that never ends). When the head's idle moment comes it leaves
    the queue and hands the polling turn to the next waiter, which sees the loop idle
    only once everything the head woke has run.

    An empty ready queue is not idle while external work is in flight
    (:func:`external_work`): the head then waits for the last of it to end, outside the
    ready queue, and polls again.
    """

    def __init__(self) -> None:
        # No reference to the loop: the detector is the value of a weak mapping keyed by it.
        # The head of the queue is whatever token its waiter appended; every waiter behind
        # it appended a future, resolved when its turn comes.
        self._queue: deque[object] = deque()
        self.external: Counter[str] = Counter()  # what is in flight outside the loop
        self.external_count = 0
        self._released: asyncio.Future[None] | None = None

    def hold(self, what: str) -> None:
        self.external[what] += 1
        self.external_count += 1

    def release(self, what: str) -> None:
        external = self.external
        left = external[what] - 1
        if left > 0:
            external[what] = left
        else:
            del external[what]
        self.external_count -= 1
        if not self.external_count:
            released = self._released
            if released is not None and not released.done():
                released.set_result(None)

    async def _wait_external(self, loop: asyncio.AbstractEventLoop) -> None:
        """Wait until no external work is in flight (warn if it takes long)."""
        started = time.monotonic()

        def warn() -> None:
            log.warning(
                "clock_waits_for_external_work",
                waited_s=round(time.monotonic() - started, 1),
                in_flight=dict(self.external),
            )

        warning = loop.call_later(EXTERNAL_WORK_WARNING_S, warn)
        try:
            while self.external_count:
                released = self._released = loop.create_future()
                try:
                    await released
                finally:
                    self._released = None
        finally:
            warning.cancel()

    async def wait(self, loop: asyncio.AbstractEventLoop) -> None:
        """Wait for an idle moment of ``loop``, the running loop."""
        queue = self._queue
        # Behind another waiter: a future resolved when this one's turn comes. At the head
        # (the common case, one waiter): a plain token, polling starts at once.
        future: asyncio.Future[None] | None = loop.create_future() if queue else None
        turn = object() if future is None else future
        queue.append(turn)
        try:
            if future is not None:
                await future
            ready = getattr(loop, "_ready", None)
            while True:
                if ready is None:  # a loop that does not expose its ready queue: bounded yields
                    for _ in range(64):
                        await _sleep(0)
                else:
                    await _sleep(0)
                    while ready:  # polling the ready queue is the point (a yield each)
                        await _sleep(0)
                if not self.external_count:
                    return
                await self._wait_external(loop)
        finally:
            head = queue[0] is turn
            queue.remove(turn)
            if head and queue:
                following = cast("asyncio.Future[None]", queue[0])  # behind the head: futures
                if not following.done():
                    following.set_result(None)


_IDLE_DETECTORS: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, _IdleDetector] = (
    weakref.WeakKeyDictionary()
)


async def wait_idle() -> None:
    """Return at a moment when no other task of the event loop is runnable.

    "Not runnable" means waiting on time, I/O, an event or a lock, with no
    :func:`external_work` in flight (while some is, this waits for its end). All callers
    on one loop share one detector: each idle moment goes to one caller, in the order they
    called, and the next caller's moment comes only after every task that the previous
    one woke has run. Needs asyncio (it reads the loop's ready queue; a loop that does
    not expose it gets a bounded number of yields instead).
    """
    loop = _running_loop()
    await _idle_detector(loop).wait(loop)


def _idle_detector(loop: asyncio.AbstractEventLoop) -> _IdleDetector:
    detector = _IDLE_DETECTORS.get(loop)
    if detector is None:
        detector = _IDLE_DETECTORS[loop] = _IdleDetector()
    return detector


class ExternalWork:
    """Marks work in flight outside the event loop; made by :func:`external_work`.

    A context manager, both plain (``with``) and asynchronous (``async with``). While it is
    entered, the running loop is never reported idle (:func:`wait_idle`), so no virtual or
    lockstep clock of that loop moves. Holds are counted per loop: they nest, the same
    object may be entered again (each exit ends the latest entry), and each ends on exit,
    whether by return, exception or cancellation. Enter and exit it in the loop's thread.
    """

    __slots__ = ("_held", "what")

    def __init__(self, what: str) -> None:
        if not isinstance(what, str) or not what:
            raise BadParameterError("what", what, "a non-empty str naming the work")
        self.what = what
        """What is in flight (named by the warning of a clock that waits long for it)."""
        self._held: list[_IdleDetector] = []

    def __enter__(self) -> ExternalWork:
        detector = _idle_detector(_running_loop())
        detector.hold(self.what)
        self._held.append(detector)
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if not self._held:
            raise StateError("__exit__", "not entered", ["entered"])
        self._held.pop().release(self.what)

    async def __aenter__(self) -> ExternalWork:
        return self.__enter__()

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.__exit__(exc_type, exc, tb)


def external_work(what: str = "external work") -> ExternalWork:
    """Tell the running loop's idle detector that work is in flight outside the loop.

    ``with external_work("reading the config"): await ...`` (or ``async with``): while
    the block runs, :func:`wait_idle` does not report the loop idle, so a VirtualClock
    in auto-jump does not jump and a lockstep simulation does not step: simulated time
    does not pass for work that should take none. Tasks keep running meanwhile; only
    time stands still.

    Only for **bounded** work that does not itself wait for simulated time: a call on a
    worker thread (:func:`run_in_thread`), opening or closing a device, a subprocess
    that finishes on its own. Never around a wait for external input (a bus reader
    thread, standard input, a peer's answer that may need simulated time to come): time
    would stop until it arrives. A clock that waits longer than
    :data:`EXTERNAL_WORK_WARNING_S` real seconds logs ``clock_waits_for_external_work``
    with what is in flight.
    """
    return ExternalWork(what)


def external_work_in_flight() -> int:
    """How many :func:`external_work` holds the running loop has open (0: none)."""
    detector = _IDLE_DETECTORS.get(_running_loop())
    return 0 if detector is None else detector.external_count


async def run_in_thread(
    func: Callable[[*PosArgsT], T],
    *args: *PosArgsT,
    abandon_on_cancel: bool = False,
    limiter: anyio.CapacityLimiter | None = None,
) -> T:
    """``anyio.to_thread.run_sync(func, *args)`` under :func:`external_work`: the loop is
    not idle (simulated time does not pass) until the call returns.

    With ``abandon_on_cancel=True`` a cancelled call returns at once and the hold ends
    with it (the abandoned thread runs on, unseen by the clocks); otherwise cancellation
    waits for the thread, as in anyio. For bounded work only (see :func:`external_work`).
    """
    name = getattr(func, "__qualname__", None) or repr(func)
    with ExternalWork(f"thread: {name}"):
        return await anyio.to_thread.run_sync(
            func, *args, abandon_on_cancel=abandon_on_cancel, limiter=limiter
        )
