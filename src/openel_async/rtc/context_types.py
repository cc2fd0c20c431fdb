"""The spec's types of an execution context: its kind (:class:`ExecutionKind`), a
component's state in it (:class:`LifeCycleState`), and the figures of the cycles it ran
(:class:`ExecutionContextStats`).

Re-exported by :mod:`openel_async.rtc.context`.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

from ..stats import LatenessSummary

__all__ = ["ExecutionContextStats", "ExecutionKind", "LifeCycleState"]


class ExecutionKind(IntEnum):
    """ExecutionKind of the spec."""

    PERIODIC = 0
    EVENT_DRIVEN = 1
    OTHER = 2

    def __str__(self) -> str:
        return self.name


class LifeCycleState(IntEnum):
    """LifeCycleState of the spec: a component's state in one context."""

    CREATED = 0
    INACTIVE = 1
    ACTIVE = 2
    ERROR = 3

    def __str__(self) -> str:
        return self.name


@dataclass(frozen=True, slots=True)
class ExecutionContextStats:
    """Figures of the cycles a context ran."""

    cycles: int
    """Cycles run."""
    overruns: int
    """Cycles whose work took longer than the period (periodic contexts)."""
    skipped: int
    """Cycles never run: a tick or trigger replaced a pending one while a cycle ran."""
    timer_missed: int
    """Periods the EventTimer itself skipped because it woke a whole period late."""
    lateness: LatenessSummary
    """Start of each cycle after its tick's deadline (or its trigger)."""
    execution: LatenessSummary
    """Duration of each cycle (both passes, every participant)."""
    last_lateness_ns: int
    """Start of the last cycle minus its tick's deadline (periodic contexts). Deadlines sit
    on an absolute grid, so this never accumulates into drift."""

    @property
    def drift_ns(self) -> int:
        """Deprecated alias of ``last_lateness_ns``."""
        return self.last_lateness_ns
