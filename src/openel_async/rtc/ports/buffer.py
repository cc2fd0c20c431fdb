"""The connector buffer: OpenRTM's RingBuffer with its full and empty policies.

- ``full_policy`` (``buffer.write.full_policy``): ``overwrite`` drops the oldest unread
  value (counted in ``overwritten``), ``do_nothing`` refuses the new one (BUFFER_FULL,
  counted in ``refused``), ``block`` waits until a reader makes room, at most
  ``write_timeout_s`` seconds on the clock (BUFFER_TIMEOUT, counted in ``write_timeouts``).
- ``empty_policy`` (``buffer.read.empty_policy``): ``readback`` returns the last value read
  again (BUFFER_EMPTY while nothing was ever written), ``do_nothing`` returns BUFFER_EMPTY,
  ``block`` waits for a writer at most ``read_timeout_s`` (BUFFER_TIMEOUT).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum
from typing import Generic, TypeVar

import anyio

from ...clock import NS_PER_S, Clock
from ._wait import wait_event
from .status import PortStatus

__all__ = ["BufferOptions", "EmptyPolicy", "FullPolicy", "ReadOutcome", "RingBuffer"]

T = TypeVar("T")


class FullPolicy(Enum):
    OVERWRITE = "overwrite"
    DO_NOTHING = "do_nothing"
    BLOCK = "block"


class EmptyPolicy(Enum):
    READBACK = "readback"
    DO_NOTHING = "do_nothing"
    BLOCK = "block"


class ReadOutcome(Enum):
    NEW = "new"
    """An unread value."""
    READBACK = "readback"
    """The last value again (readback policy on an empty buffer)."""
    NONE = "none"


@dataclass(frozen=True, slots=True)
class BufferOptions:
    """``buffer.*`` properties of a connector (OpenRTM's defaults)."""

    length: int = 8
    full_policy: FullPolicy = FullPolicy.OVERWRITE
    write_timeout_s: float = 1.0
    empty_policy: EmptyPolicy = EmptyPolicy.READBACK
    read_timeout_s: float = 1.0

    @property
    def blocking(self) -> bool:
        return self.full_policy is FullPolicy.BLOCK or self.empty_policy is EmptyPolicy.BLOCK


_OK = PortStatus.PORT_OK
_FULL = PortStatus.BUFFER_FULL
_OK_NONE: tuple[PortStatus, None] = (_OK, None)


class RingBuffer(Generic[T]):
    """A bounded FIFO of values with OpenRTM's policies; waits are on ``clock``."""

    __slots__ = (
        "_items",
        "_last",
        "_length",
        "_not_empty",
        "_not_full",
        "_overwrite",
        "_refuse",
        "clock",
        "options",
        "overwritten",
        "read_count",
        "read_timeouts",
        "readable",
        "refused",
        "write_timeouts",
        "written",
    )

    def __init__(self, options: BufferOptions, clock: Clock) -> None:
        self.options = options
        self.clock = clock
        self._length = options.length
        self._items: deque[T] = deque()
        self._overwrite = options.full_policy is FullPolicy.OVERWRITE
        self._refuse = options.full_policy is FullPolicy.DO_NOTHING
        self.readable: Callable[[], int] = self._items.__len__
        """Unread values (the deque's own ``len``, the cheapest call for ``is_new``)."""
        self._last: T | None = None
        self._not_empty: anyio.Event | None = None
        self._not_full: anyio.Event | None = None
        self.written = 0
        self.read_count = 0
        self.overwritten = 0
        self.refused = 0
        self.write_timeouts = 0
        self.read_timeouts = 0

    def __len__(self) -> int:
        return len(self._items)

    def full(self) -> bool:
        return len(self._items) >= self._length

    def empty(self) -> bool:
        return not self._items

    def offer(self, value: T) -> PortStatus | None:
        """Store ``value`` without waiting: PORT_OK (the oldest unread value dropped and
        counted when full with ``overwrite``), BUFFER_FULL (counted) when full with
        ``do_nothing``, None when full with ``block`` (nothing done: use :meth:`write`).
        For callers without listeners: it does not return the dropped value."""
        items = self._items
        if len(items) >= self._length:
            if self._overwrite:
                items.popleft()
                self.overwritten += 1
            elif self._refuse:
                self.refused += 1
                return _FULL
            else:
                return None
        items.append(value)
        self.written += 1
        if self._not_empty is not None:
            self._not_empty.set()
            self._not_empty = None
        return _OK

    async def write(self, value: T) -> tuple[PortStatus, T | None]:
        """Store ``value``: (PORT_OK, dropped value or None), (BUFFER_FULL, None) or
        (BUFFER_TIMEOUT, None)."""
        items = self._items
        if len(items) < self._length:  # the common case, without a wait
            items.append(value)
            self.written += 1
            if self._not_empty is not None:
                self._not_empty.set()
                self._not_empty = None
            return _OK_NONE
        dropped: T | None = None
        if len(items) >= self._length:
            policy = self.options.full_policy
            if policy is FullPolicy.OVERWRITE:
                dropped = items.popleft()
                self.overwritten += 1
            elif policy is FullPolicy.DO_NOTHING:
                self.refused += 1
                return PortStatus.BUFFER_FULL, None
            else:
                deadline = self.clock.now_ns() + round(self.options.write_timeout_s * NS_PER_S)
                while len(items) >= self._length:
                    if self._not_full is None:
                        self._not_full = anyio.Event()
                    if not await wait_event(self.clock, self._not_full, deadline):
                        self.write_timeouts += 1
                        return PortStatus.BUFFER_TIMEOUT, None
        items.append(value)
        self.written += 1
        if self._not_empty is not None:
            self._not_empty.set()
            self._not_empty = None
        return PortStatus.PORT_OK, dropped

    def _take(self) -> T:
        value = self._items.popleft()
        self._last = value
        self.read_count += 1
        if self._not_full is not None:
            self._not_full.set()
            self._not_full = None
        return value

    def take(self) -> T | None:
        """The oldest unread value, or None (no empty policy: publishers and the read
        fast path)."""
        items = self._items
        if not items:
            return None
        value = items.popleft()
        self._last = value
        self.read_count += 1
        if self._not_full is not None:
            self._not_full.set()
            self._not_full = None
        return value

    def take_all(self) -> list[T]:
        """Every unread value, oldest first (publishers)."""
        out = list(self._items)
        self._items.clear()
        if out:
            self._last = out[-1]
            self.read_count += len(out)
            if self._not_full is not None:
                self._not_full.set()
                self._not_full = None
        return out

    async def read(self) -> tuple[PortStatus, ReadOutcome, T | None]:
        """The oldest unread value, or what the empty policy gives."""
        if self._items:
            return PortStatus.PORT_OK, ReadOutcome.NEW, self._take()
        policy = self.options.empty_policy
        if policy is EmptyPolicy.READBACK:
            if self._last is None:
                return PortStatus.BUFFER_EMPTY, ReadOutcome.NONE, None
            return PortStatus.PORT_OK, ReadOutcome.READBACK, self._last
        if policy is EmptyPolicy.DO_NOTHING:
            return PortStatus.BUFFER_EMPTY, ReadOutcome.NONE, None
        deadline = self.clock.now_ns() + round(self.options.read_timeout_s * NS_PER_S)
        while not self._items:
            if self._not_empty is None:
                self._not_empty = anyio.Event()
            if not await wait_event(self.clock, self._not_empty, deadline):
                self.read_timeouts += 1
                return PortStatus.BUFFER_TIMEOUT, ReadOutcome.NONE, None
        return PortStatus.PORT_OK, ReadOutcome.NEW, self._take()
