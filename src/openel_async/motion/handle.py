"""GroupMotion: the awaitable outcome of one motion of an axis group."""

from __future__ import annotations

from collections.abc import Generator
from enum import Enum
from typing import Any

import anyio
import anyio.lowlevel

from ..errors import HALError
from .planner import Plan


class GroupOutcome(Enum):
    PENDING = "pending"
    SUCCEEDED = "succeeded"
    """Every axis came within its goal tolerance of the final target (or a stop ended)."""
    PREEMPTED = "preempted"
    ABORTED = "aborted"
    """Path tolerance, goal timeout or an axis fault."""
    STOPPED = "stopped"
    """stop(), hold() or the group's context exited."""


class GroupMotion:
    """Handle of one motion (``move_to``, ``follow`` or the braking of ``stop``).

    ``await motion`` returns None once it succeeded and raises the error it ended with
    otherwise (:class:`PreemptedError`, :class:`PathToleranceError`,
    :class:`GoalTimeoutError`, :class:`AxisFaultError`, :class:`MotionStoppedError`).
    It can be awaited any number of times from any task, and cancelled like any wait.
    """

    __slots__ = (
        "_checks_path",
        "_done",
        "_error",
        "_goal_deadline_ns",
        "_goal_time_ns",
        "_goal_tolerance",
        "_path_tolerance",
        "_plan",
        "_settling",
        "finished_ns",
        "id",
        "kind",
        "outcome",
        "targets",
    )

    def __init__(
        self,
        ident: int,
        kind: str,
        plan: Plan,
        goal_tolerance: tuple[float, ...],
        path_tolerance: tuple[float | None, ...],
        goal_time_ns: int,
    ) -> None:
        self.id = ident
        self.kind = kind
        """'move', 'waypoints' or 'stop'."""
        self.targets = tuple(plan.final_position)
        """Final position of every axis."""
        self.outcome = GroupOutcome.PENDING
        self.finished_ns: int | None = None
        self._plan = plan
        self._goal_tolerance = goal_tolerance
        self._path_tolerance = path_tolerance
        self._checks_path = any(tol is not None for tol in path_tolerance)
        self._goal_time_ns = goal_time_ns
        self._goal_deadline_ns = 0
        self._settling = False
        self._error: HALError | None = None
        self._done = anyio.Event()

    # -- timing ------------------------------------------------------------------------
    @property
    def start_ns(self) -> int:
        """Clock time the trajectory starts at (the group's last tick when requested)."""
        return self._plan.start_ns

    @property
    def duration(self) -> float:
        """Planned duration of the trajectory in seconds."""
        return self._plan.duration

    @property
    def planned_end_ns(self) -> int:
        return self._plan.end_ns

    @property
    def waypoint_times(self) -> tuple[float, ...]:
        """Planned time (s from the start) of each waypoint; ``(duration,)`` for a move."""
        return self._plan.waypoint_times

    @property
    def settling(self) -> bool:
        """The final setpoints were sent; the group waits for the goal tolerance."""
        return self._settling

    # -- outcome -----------------------------------------------------------------------
    def done(self) -> bool:
        return self.outcome is not GroupOutcome.PENDING

    def error(self) -> HALError | None:
        """The exception ``await`` raises, or None while pending or once succeeded."""
        return self._error

    async def wait(self) -> None:
        if self.outcome is GroupOutcome.PENDING:
            await self._done.wait()
        else:
            await anyio.lowlevel.checkpoint()
        if self._error is not None:
            raise self._error

    def __await__(self) -> Generator[Any, None, None]:
        return self.wait().__await__()

    def _finish(self, outcome: GroupOutcome, at_ns: int, error: HALError | None = None) -> bool:
        if self.outcome is not GroupOutcome.PENDING:
            return False
        self.outcome = outcome
        self.finished_ns = at_ns
        self._error = error
        self._done.set()
        return True

    def __repr__(self) -> str:
        return (
            f"GroupMotion(#{self.id} {self.kind} -> {list(self.targets)}, "
            f"{self.duration:.3f} s, {self.outcome.value})"
        )
