"""Zenoh callbacks (Zenoh's threads) into the event loop, bounded.

A :class:`ThreadInbox` takes items from any thread into a bounded deque and wakes the
event loop once per batch (``call_soon_threadsafe``); when it is full the oldest item is
dropped and counted. The loop side drains it either from a task of the owner's task
group (``await inbox.wait()``) or, with ``drain=``, in the loop callback itself: one
thread-to-loop handoff per batch and no task switch (the drain function must not block
and must not raise; what it raises is logged and the batch's rest is lost to it).
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections import deque
from collections.abc import Callable
from typing import Generic, TypeVar

import anyio

from openel_async.logs import get_logger

T = TypeVar("T")

log = get_logger(__name__)


class ThreadInbox(Generic[T]):
    def __init__(
        self,
        maxsize: int,
        on_drop: Callable[[T], None] | None = None,
        *,
        drain: Callable[[list[T]], None] | None = None,
    ) -> None:
        self.maxsize = maxsize
        self.dropped = 0
        self._items: deque[T] = deque()
        self._lock = threading.Lock()
        self._loop = asyncio.get_running_loop()
        self._wakeup = anyio.Event()
        self._scheduled = False
        self._closed = False
        self._on_drop = on_drop
        self._drain = drain

    def put(self, item: T) -> None:
        """From any thread; never blocks."""
        dropped: T | None = None
        with self._lock:
            if self._closed:
                return
            if len(self._items) >= self.maxsize:
                dropped = self._items.popleft()
                self.dropped += 1
            self._items.append(item)
            schedule = not self._scheduled
            self._scheduled = True
        if dropped is not None and self._on_drop is not None:
            self._on_drop(dropped)
        if schedule:
            with contextlib.suppress(RuntimeError):  # a closed loop: the owner is gone
                self._loop.call_soon_threadsafe(self._wake)

    def __len__(self) -> int:
        """Items waiting (from any thread; a snapshot)."""
        return len(self._items)

    def _wake(self) -> None:
        drain = self._drain
        if drain is None:
            self._wakeup.set()
            return
        if self._closed:  # what is left is the owner's to answer (take_all)
            return
        items = self.take_all()
        if items:
            try:
                drain(items)
            except Exception:
                log.exception("inbox_drain_failed", items=len(items))

    def take_all(self) -> list[T]:
        with self._lock:
            items = list(self._items)
            self._items.clear()
            self._scheduled = False
        return items

    async def wait(self) -> list[T]:
        """The items received so far; waits (cancellably) for at least one."""
        while True:
            items = self.take_all()
            if items:
                return items
            await self._wakeup.wait()
            self._wakeup = anyio.Event()

    def close(self) -> None:
        with self._lock:
            self._closed = True
