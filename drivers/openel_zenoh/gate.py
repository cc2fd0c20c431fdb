"""A gate that lets another thread run a short section as if it were a callback of an
idle event loop.

:class:`GatedEventLoop` is an ``asyncio.SelectorEventLoop`` whose selector holds a lock
(the loop's :class:`LoopGate`) at all times except while it waits in ``select``. Another
thread that gets the gate with :meth:`LoopGate.try_enter` therefore knows that the loop
thread runs no loop code (no callback, no task step, no I/O handling: it is in
``select``, or blocked until the gate is left), so whatever the section reads or changes
is seen exactly as a loop callback would see it, between two loop iterations; the loop
cannot resume until :meth:`LoopGate.leave`. Python-level signal handlers are the one
exception (below).
The gate is refused while the loop is busy (the lock is held) and while the loop thread
waits to take it back after ``select`` (so sections cannot starve the loop).

A section runs with the loop set as the thread's running loop (code that asks for it
finds it) and must wake the loop afterwards if it scheduled anything there: the loop is
still waiting in ``select`` with the timeout it computed before. :func:`work_marker`
before and :func:`needs_wake` after the section tell (an asyncio loop schedules through
its ready queue and its timer heap; for a loop without them the answer is always yes). In debug mode (``loop.get_debug()``) asyncio checks that the loop's
non-thread-safe methods are called from its own thread: use no sections then.

Signals: CPython runs a Python-level signal handler on the main thread (the loop's, under
``openel-async serve``) inside a blocking call (``select`` retries after EINTR, PEP 475)
and where it checks between bytecodes (as a call returns), so also in the few bytecodes
between :meth:`LoopGate.park` and the wait in ``select`` and after it: beside a section.
What is guaranteed and why that is harmless:

- callbacks of ``loop.add_signal_handler`` are loop callbacks (run after ``select``,
  under the gate); ``asyncio.Runner``'s SIGINT handler (``anyio.run`` uses it), the one
  handler that runs there, only cancels the main task: ``Task.cancel`` marks it and
  cancels the future it waits on, whose callbacks are queued with ``call_soon`` (an
  append to the ready queue, atomic under the GIL, as a section's own ``call_soon``),
  and wakes the loop. No task code runs until the loop has the gate back, and a
  section (server.THREAD_READS) reads component state, which none of this touches;
- a handler that raises (Runner's second Ctrl-C: KeyboardInterrupt) ends ``select``:
  :meth:`LoopGate.resume` raises it only once the gate is taken back. Park and resume
  ask the lock whether this thread holds it, so an exception raised just as park's
  release or resume's acquire returns neither leaves the gate open nor makes resume wait
  for itself (tests/remote/test_gate_interrupt.py);
- not guaranteed: an exception raised on entry to resume (before it waits) leaves
  ``select`` with the gate open. The loop code that then runs is that exception's
  unwinding (asyncio's run_forever cleanup, the Runner cancelling the remaining tasks,
  which only queues callbacks), and the next ``select`` (the Runner runs the loop again
  to let them finish) finds the gate open and takes it back. A section may overlap that
  unwinding of a loop stopping on KeyboardInterrupt; it reads component state, which
  the unwinding does not change.

``openel-async serve`` runs on this loop (``anyio.run(..., backend_options={"loop_factory":
GatedEventLoop})``), so that :class:`~openel_zenoh.server.SurfaceServer` answers plain reads
on Zenoh's thread without waking the loop (see docs/remote.md, "Threads").
"""

from __future__ import annotations

import asyncio
import select
import selectors
import threading
from collections.abc import Callable, Mapping
from typing import Any, cast

from openel_async.errors import BadParameterError

FINE_WAIT_BELOW = 0.005
"""Waits shorter than this (seconds) are timed to the microsecond, not epoll's millisecond."""
SELECT_FD_LIMIT = 1024
"""FD_SETSIZE: ``select.select`` takes descriptors below it only."""


class LoopGate:
    """The lock of one :class:`GatedEventLoop`: held by the loop thread except in ``select``.

    An RLock only so that the loop thread can ask whether it holds it (``_is_owned``, as
    ``threading.Condition`` does); it is never taken twice. :meth:`park` and
    :meth:`resume` decide by that, not by where an exception left them (see the module
    doc, "Signals")."""

    def __init__(self) -> None:
        self._lock = threading.RLock()
        self._lock.acquire()  # by the thread that creates the loop, which runs it
        self._owned: Callable[[], bool] = cast(Any, self._lock)._is_owned
        self._loop_waiting = False
        self.entered = 0
        """Sections run so far (other threads')."""

    def try_enter(self) -> bool:
        """From another thread: True if the loop is parked (then :meth:`leave` soon)."""
        if self._loop_waiting or self._owned() or not self._lock.acquire(blocking=False):
            return False
        self.entered += 1
        return True

    def leave(self) -> None:
        self._lock.release()

    # the loop thread, around select
    def park(self) -> None:
        """Open the gate (unless an interrupted ``select`` left it open)."""
        if self._owned():
            self._lock.release()

    def resume(self) -> None:
        """Take the gate back after ``select`` (waiting for a running section to end).

        An exception raised while it waits (a signal handler's, e.g. a second Ctrl-C) is
        raised only once the gate is taken back: the loop thread never runs loop code
        without it (a section would run beside it). Whether the gate is held is asked of
        the lock, so an exception raised just after ``acquire`` returned (a signal handler
        run when the call ends) does not make it wait for itself."""
        self._loop_waiting = True
        interrupted: BaseException | None = None
        try:
            while not self._owned():
                try:
                    self._lock.acquire()
                except BaseException as exc:  # interrupted: the section may still run
                    if interrupted is None:
                        interrupted = exc
        finally:
            self._loop_waiting = False
        if interrupted is not None:
            raise interrupted


class GatedSelector(selectors.BaseSelector):
    """A selector that leaves the gate open only while it waits in ``select``."""

    def __init__(self, gate: LoopGate, inner: selectors.BaseSelector | None = None) -> None:
        self.gate = gate
        self._inner = inner if inner is not None else selectors.DefaultSelector()
        epoll: Any = getattr(selectors, "EpollSelector", None)  # Linux only
        fd = self._inner.fileno() if epoll is not None and isinstance(self._inner, epoll) else -1
        self._fd: int = fd if 0 <= fd < SELECT_FD_LIMIT else -1
        """The epoll descriptor, for :meth:`_fine_select` (-1: not an epoll selector, or
        beyond what ``select`` takes: waits are then epoll's own)."""

    def register(self, fileobj: Any, events: int, data: Any = None) -> selectors.SelectorKey:
        return self._inner.register(fileobj, events, data)

    def unregister(self, fileobj: Any) -> selectors.SelectorKey:
        return self._inner.unregister(fileobj)

    def modify(self, fileobj: Any, events: int, data: Any = None) -> selectors.SelectorKey:
        return self._inner.modify(fileobj, events, data)

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        gate = self.gate
        try:  # park inside the try: an exception raised as it returns still resumes
            gate.park()
            if timeout is not None and 0.0 < timeout < FINE_WAIT_BELOW and self._fd >= 0:
                return self._fine_select(timeout)
            return self._inner.select(timeout)
        finally:
            gate.resume()

    def _fine_select(self, timeout: float) -> list[tuple[selectors.SelectorKey, int]]:
        """A short wait to the microsecond: epoll waits whole milliseconds, rounded up, so
        a timer due in 100 us would fire 1 ms late; ``select`` on the epoll descriptor
        (readable when one of its descriptors is ready) waits in microseconds."""
        ready = self._inner.select(0)
        if ready:
            return ready
        select.select([self._fd], [], [], timeout)
        return self._inner.select(0)

    def get_key(self, fileobj: Any) -> selectors.SelectorKey:
        return self._inner.get_key(fileobj)

    def get_map(self) -> Mapping[Any, selectors.SelectorKey]:
        return self._inner.get_map()

    def close(self) -> None:
        self._inner.close()


class GatedEventLoop(asyncio.SelectorEventLoop):
    """An asyncio event loop with a :class:`LoopGate` (``loop.gate``); create it in the
    thread that runs it (as ``anyio.run``'s ``loop_factory`` does)."""

    def __init__(self) -> None:
        self.gate = LoopGate()
        super().__init__(GatedSelector(self.gate))


def gate_of(loop: asyncio.AbstractEventLoop) -> LoopGate | None:
    """The gate of ``loop`` if it is a GatedEventLoop not in debug mode, else None."""
    gate = getattr(loop, "gate", None)
    if not isinstance(gate, LoopGate) or loop.get_debug():
        return None
    return gate


def enter_as_loop(loop: asyncio.AbstractEventLoop) -> None:
    """Inside a section: make ``loop`` this thread's running loop (until :func:`exit_loop`)."""
    # asyncio's low-level API for event-loop implementations (asyncio.events.__all__)
    if asyncio._get_running_loop() is not None:
        raise BadParameterError("thread", "one running an event loop", "a thread without one")
    asyncio._set_running_loop(loop)


def exit_loop() -> None:
    asyncio._set_running_loop(None)


def work_marker(loop: asyncio.AbstractEventLoop) -> tuple[int, int] | None:
    """What ``loop`` has scheduled (ready callbacks, timers), to compare after a section."""
    ready = getattr(loop, "_ready", None)
    timers = getattr(loop, "_scheduled", None)
    if ready is None or timers is None:
        return None
    return len(ready), len(timers)


def needs_wake(loop: asyncio.AbstractEventLoop, before: tuple[int, int] | None) -> bool:
    """Whether a section scheduled work on ``loop`` (or it cannot tell)."""
    return before is None or work_marker(loop) != before
