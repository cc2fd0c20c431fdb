"""Wakeup: a reusable wake-up for waiting tasks, for per-tick and per-event paths.

``anyio.Event`` is single-use, so a task woken every tick builds a new one every tick;
building one asks anyio for the running backend (``current_async_library()``) and
waiting on it goes through asyncio's ``_get_loop``, 25-30 % of an AxisGroup tick when
profiled. A :class:`Wakeup` is made once and reused: ``set()`` wakes the tasks waiting in
:meth:`Wakeup.wait` (or, if none is waiting, makes the next wait return at once), and a
wait costs one loop future.

Needs the asyncio backend, as the clocks do (docs/architecture.md). Cancellation (an
anyio cancel scope, ``Task.cancel``) ends a wait as it ends any await of a future.
"""

from __future__ import annotations

from collections.abc import Callable, Coroutine
from typing import TYPE_CHECKING, Any

from .lazy import first_use

if TYPE_CHECKING:
    import asyncio

__all__ = ["Wakeup"]


# asyncio's functions, bound at the first wait (asyncio imported then): a program that
# only makes Wakeups (an app printing its --help) does not load asyncio.
_running_loop: Callable[[], asyncio.AbstractEventLoop] = first_use(
    globals(), "_running_loop", "asyncio", "get_running_loop"
)
_sleep: Callable[[float], Coroutine[Any, Any, None]] = first_use(
    globals(), "_sleep", "asyncio", "sleep"
)


class Wakeup:
    """A level-triggered, reusable wake-up.

    ``set()`` never blocks. It wakes every task waiting in :meth:`wait`; when none is, it
    sets a flag instead, and the next :meth:`wait` returns at once (after one checkpoint,
    as an ``anyio.Event`` that is already set does) and clears it. A publisher that wants
    edge-triggered wake-ups (only tasks already waiting) calls ``set()`` only while
    :attr:`waiting`.
    """

    __slots__ = ("_flag", "_more", "waiter")

    def __init__(self) -> None:
        self._flag = False
        self.waiter: asyncio.Future[None] | None = None
        """The first waiting task's future (the usual, only one); None: no task waits.
        Read only: ``wakeup.waiter is not None`` is :attr:`waiting` without a call, for
        a publisher's per-notice path."""
        self._more: list[asyncio.Future[None]] | None = None
        """The futures of the other waiting tasks, in the order they came."""

    @property
    def waiting(self) -> bool:
        """Whether a task is waiting."""
        return self.waiter is not None

    def is_set(self) -> bool:
        return self._flag

    def set(self) -> None:
        waiter = self.waiter
        if waiter is None:
            self._flag = True
            return
        self.waiter = None
        if not waiter.done():
            waiter.set_result(None)
        more = self._more
        if more is not None:
            self._more = None
            for future in more:
                if not future.done():
                    future.set_result(None)

    def clear(self) -> None:
        self._flag = False

    async def wait(self) -> None:
        """Until :meth:`set` is called (at once, after a checkpoint, if it was already)."""
        if self._flag:
            self._flag = False
            await _sleep(0)
            return
        future: asyncio.Future[None] = _running_loop().create_future()
        if self.waiter is None:
            self.waiter = future
        elif self._more is None:
            self._more = [future]
        else:
            self._more.append(future)
        try:
            await future
        except BaseException:  # cancelled: leave the line (set() removed a woken one)
            self._leave(future)
            raise

    def arm(self) -> asyncio.Future[None]:
        """:meth:`wait` in two steps, for a consumer's hot loop (one coroutine frame less):
        clear the flag and return a future in the line of waiters, resolved by the next
        :meth:`set`. Await it; if the await raises (cancellation), call :meth:`disarm`."""
        self._flag = False
        future: asyncio.Future[None] = _running_loop().create_future()
        if self.waiter is None:
            self.waiter = future
        elif self._more is None:
            self._more = [future]
        else:
            self._more.append(future)
        return future

    def disarm(self, future: asyncio.Future[None]) -> None:
        """Take a future of :meth:`arm` out of the line (its await was cancelled)."""
        self._leave(future)

    def _leave(self, future: asyncio.Future[None]) -> None:
        more = self._more
        if self.waiter is future:
            self.waiter = more.pop(0) if more else None
        elif more is not None and future in more:
            more.remove(future)
        if not self._more:
            self._more = None

    def __repr__(self) -> str:
        state = "waiting" if self.waiter is not None else ("set" if self._flag else "clear")
        return f"Wakeup({state})"
