"""Wakeup: a reusable wake-up for one waiting task, for per-tick and per-event paths.

``anyio.Event`` is single-use, so a task woken every tick builds a new one every tick;
building one asks anyio for the running backend (``current_async_library()``) and
waiting on it goes through asyncio's ``_get_loop``, 25-30 % of an AxisGroup tick when
profiled. A :class:`Wakeup` is made once and reused: ``set()`` wakes the task waiting in
:meth:`Wakeup.wait` (or, if none is waiting, makes its next wait return at once), and a
wait costs one loop future.

Needs the asyncio backend, as the clocks do (docs/architecture.md). Cancellation (an
anyio cancel scope, ``Task.cancel``) ends a wait as it ends any await of a future.
"""

from __future__ import annotations

import asyncio

__all__ = ["Wakeup"]


class Wakeup:
    """A level-triggered, reusable wake-up for **one** waiting task at a time.

    ``set()`` never blocks and may be called any number of times before the task waits:
    the next :meth:`wait` then returns at once (after one checkpoint, as an
    ``anyio.Event`` that is already set does), and clears the flag.
    """

    __slots__ = ("_flag", "_waiter")

    def __init__(self) -> None:
        self._flag = False
        self._waiter: asyncio.Future[None] | None = None

    def is_set(self) -> bool:
        return self._flag

    def set(self) -> None:
        waiter = self._waiter
        if waiter is None:
            self._flag = True
            return
        self._waiter = None
        if not waiter.done():
            waiter.set_result(None)

    def clear(self) -> None:
        self._flag = False

    async def wait(self) -> None:
        """Until :meth:`set` is called (at once, after a checkpoint, if it was already)."""
        if self._waiter is not None:
            raise RuntimeError("Wakeup.wait: another task is already waiting")
        if self._flag:
            self._flag = False
            await asyncio.sleep(0)
            return
        waiter = self._waiter = asyncio.get_running_loop().create_future()
        try:
            await waiter
        finally:
            if self._waiter is waiter:
                self._waiter = None

    def __repr__(self) -> str:
        state = "waiting" if self._waiter is not None else ("set" if self._flag else "clear")
        return f"Wakeup({state})"
