"""Statistics: lateness of periodic loops (timers, execution contexts, benchmarks) and
delivery to observers (every notice dropped on the way is counted here)."""

from __future__ import annotations

import math
from array import array
from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class LatenessSummary:
    count: int
    p50_ns: int
    p99_ns: int
    max_ns: int
    mean_ns: float

    def as_us(self) -> dict[str, float]:
        return {
            "p50_us": self.p50_ns / 1e3,
            "p99_us": self.p99_ns / 1e3,
            "max_us": self.max_ns / 1e3,
            "mean_us": self.mean_ns / 1e3,
        }


def percentile(sorted_values: list[int], q: float) -> int:
    """Nearest-rank percentile of an ascending list (0 for an empty one)."""
    if not sorted_values:
        return 0
    # Nearest rank is ceil(q/100 x n); round() would halve down on ties (banker's
    # rounding: the median of 5 values would be the 2nd).
    rank = max(0, min(len(sorted_values) - 1, math.ceil(q * len(sorted_values) / 100) - 1))
    return sorted_values[rank]


class LatenessRecorder:
    """Keeps the most recent ``window`` samples in a ring; counts every sample."""

    def __init__(self, window: int = 100_000) -> None:
        self.window = window
        self._ring = array("q")
        self._next = 0
        self.count = 0
        self.max_ns = 0

    def record(self, lateness_ns: int) -> None:
        self.count += 1
        if lateness_ns > self.max_ns:
            self.max_ns = lateness_ns
        if len(self._ring) < self.window:
            self._ring.append(lateness_ns)
        else:
            self._ring[self._next] = lateness_ns
            self._next = (self._next + 1) % self.window

    def summary(self) -> LatenessSummary:
        values = sorted(self._ring)
        mean = sum(values) / len(values) if values else 0.0
        return LatenessSummary(
            count=self.count,
            p50_ns=percentile(values, 50),
            p99_ns=percentile(values, 99),
            max_ns=self.max_ns,
            mean_ns=mean,
        )

    def reset(self) -> None:
        self._ring = array("q")
        self._next = 0
        self.count = 0
        self.max_ns = 0


@dataclass(frozen=True, slots=True)
class MailboxStats:
    """Delivery to one async observer (its mailbox), since it was added.

    ``queued == delivered + pending + lost`` except while a notice is being delivered
    (then one fewer is delivered).
    """

    observer: object
    queued: int
    """Notices put in the mailbox."""
    delivered: int
    """Notices whose observer call finished (returned or raised)."""
    pending: int
    """Notices in the mailbox now."""
    overflowed: int
    """Oldest notices dropped because the mailbox was full."""
    discarded: int
    """Notices dropped by EventTimer.stop_timer before delivery."""
    abandoned: int
    """Notices left undelivered, or cut short while running, when the owner exited."""

    @property
    def lost(self) -> int:
        return self.overflowed + self.discarded + self.abandoned


@dataclass(frozen=True, slots=True)
class ObserverStats:
    """Delivery figures of one publisher (a component's or a timer's ``observer_stats``).

    Plain (inline) observers get every notice at once, so only async observers'
    mailboxes can drop; the totals include observers removed since.
    """

    published: int
    """Notifications published (each to every observer registered for its kind)."""
    failures: int
    """Observer calls that raised (logged, never propagated)."""
    overflowed: int
    """Notices dropped from full mailboxes."""
    discarded: int
    """Notices dropped from mailboxes by EventTimer.stop_timer."""
    abandoned: int
    """Notices left in mailboxes, or cut short, when the owner exited."""
    mailboxes: tuple[MailboxStats, ...]
    """The async observers registered now, in registration order."""
    unpublished: int = 0
    """Events and errors a driver posted while the component was neither Active nor in
    Error: the state machine notifies no observer then, so they reached nobody (counted,
    and logged at debug level). Not part of :attr:`lost`, which counts delivery losses."""

    @property
    def lost(self) -> int:
        return self.overflowed + self.discarded + self.abandoned
