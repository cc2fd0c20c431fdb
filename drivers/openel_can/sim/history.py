"""A bounded record of what a simulated peer received, for tests and inspection.

A peer that runs for hours (the CAN demo streams setpoints at the timer rate) must not
keep every command it ever received: :class:`History` keeps the newest ``maxlen`` items
and counts the older ones it discarded, so a reader knows how much is missing.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterator, Sequence
from typing import Generic, TypeVar, overload

__all__ = ["DEFAULT_HISTORY", "History"]

T = TypeVar("T")

#: Items a simulated peer keeps per record by default.
DEFAULT_HISTORY = 1024


class History(Sequence[T], Generic[T]):
    """The newest ``maxlen`` items appended (oldest first); ``discarded`` counts the rest."""

    def __init__(self, maxlen: int = DEFAULT_HISTORY) -> None:
        if isinstance(maxlen, bool) or not isinstance(maxlen, int) or maxlen < 1:
            raise ValueError(f"maxlen must be an int >= 1, got {maxlen!r}")
        self._items: deque[T] = deque(maxlen=maxlen)
        self.discarded = 0
        """Items dropped (oldest first) to keep at most ``maxlen``."""

    @property
    def maxlen(self) -> int:
        maxlen = self._items.maxlen
        assert maxlen is not None
        return maxlen

    @property
    def total(self) -> int:
        """Items ever appended: ``len(self) + discarded``."""
        return len(self._items) + self.discarded

    def append(self, item: T) -> None:
        if len(self._items) == self.maxlen:
            self.discarded += 1
        self._items.append(item)

    def clear(self) -> None:
        """Forget the kept items (they count as discarded)."""
        self.discarded += len(self._items)
        self._items.clear()

    @overload
    def __getitem__(self, index: int) -> T: ...

    @overload
    def __getitem__(self, index: slice) -> list[T]: ...

    def __getitem__(self, index: int | slice) -> T | list[T]:
        if isinstance(index, slice):
            return list(self._items)[index]
        return self._items[index]

    def __len__(self) -> int:
        return len(self._items)

    def __iter__(self) -> Iterator[T]:
        return iter(self._items)

    def __repr__(self) -> str:
        return f"History({list(self._items)!r}, discarded={self.discarded})"
