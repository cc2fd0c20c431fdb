"""A gate that lets another thread run a short section as if it were a callback of an
idle event loop.

:class:`GatedEventLoop` is an ``asyncio.SelectorEventLoop`` whose selector holds a lock
(the loop's :class:`LoopGate`) at all times except while it waits in ``select``. Another
thread that gets the gate with :meth:`LoopGate.try_enter` therefore knows that the loop
thread runs no Python code (it is parked in ``select``, or blocked until the gate is
left), so whatever the section reads or changes is seen exactly as a loop callback would
see it, between two loop iterations; the loop cannot resume until :meth:`LoopGate.leave`.
The gate is refused while the loop is busy (the lock is held) and while the loop thread
waits to take it back after ``select`` (so sections cannot starve the loop).

A section runs with the loop set as the thread's running loop (code that asks for it
finds it) and must wake the loop afterwards if it scheduled anything there: the loop is
still waiting in ``select`` with the timeout it computed before. :func:`work_marker`
before and :func:`needs_wake` after the section tell (an asyncio loop schedules through
its ready queue and its timer heap; for a loop without them the answer is always yes). In debug mode (``loop.get_debug()``) asyncio checks that the loop's
non-thread-safe methods are called from its own thread: use no sections then.

``openel-async serve`` runs on this loop (``anyio.run(..., backend_options={"loop_factory":
GatedEventLoop})``), so that :class:`~openel_zenoh.server.SurfaceServer` answers plain reads
on Zenoh's thread without waking the loop (see docs/remote.md, "Threads").
"""

from __future__ import annotations

import asyncio
import selectors
import threading
from collections.abc import Mapping
from typing import Any

from openel_async.errors import BadParameterError


class LoopGate:
    """The lock of one :class:`GatedEventLoop`: held by the loop thread except in ``select``."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._lock.acquire()  # by the thread that creates the loop, which runs it
        self._loop_waiting = False
        self.entered = 0
        """Sections run so far (other threads')."""

    def try_enter(self) -> bool:
        """From another thread: True if the loop is parked (then :meth:`leave` soon)."""
        if self._loop_waiting or not self._lock.acquire(blocking=False):
            return False
        self.entered += 1
        return True

    def leave(self) -> None:
        self._lock.release()

    # the loop thread, around select
    def park(self) -> None:
        self._lock.release()

    def resume(self) -> None:
        """Take the gate back after ``select`` (waiting for a running section to end).

        An exception raised while it waits (a signal handler's, e.g. a second Ctrl-C) is
        raised only once the gate is taken back: the loop thread never runs loop code
        without it (a section would run beside it, and the next :meth:`park` would release
        a lock it does not hold)."""
        self._loop_waiting = True
        interrupted: BaseException | None = None
        try:
            while True:
                try:
                    self._lock.acquire()
                except BaseException as exc:  # interrupted: the section still runs
                    if interrupted is None:
                        interrupted = exc
                    continue
                break
        finally:
            self._loop_waiting = False
        if interrupted is not None:
            raise interrupted


class GatedSelector(selectors.BaseSelector):
    """A selector that leaves the gate open only while it waits in ``select``."""

    def __init__(self, gate: LoopGate, inner: selectors.BaseSelector | None = None) -> None:
        self.gate = gate
        self._inner = inner if inner is not None else selectors.DefaultSelector()

    def register(self, fileobj: Any, events: int, data: Any = None) -> selectors.SelectorKey:
        return self._inner.register(fileobj, events, data)

    def unregister(self, fileobj: Any) -> selectors.SelectorKey:
        return self._inner.unregister(fileobj)

    def modify(self, fileobj: Any, events: int, data: Any = None) -> selectors.SelectorKey:
        return self._inner.modify(fileobj, events, data)

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        self.gate.park()
        try:
            return self._inner.select(timeout)
        finally:
            self.gate.resume()

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
