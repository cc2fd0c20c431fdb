"""Motion: the awaitable outcome of one Actuator.set_value command."""

from __future__ import annotations

from collections.abc import Generator
from enum import Enum
from typing import Any

import anyio
import anyio.lowlevel

from .errors import DeviceFaultError, HALError, MotionCancelledError, SupersededError
from .requests import Request


class Outcome(Enum):
    PENDING = "pending"
    REACHED = "reached"
    SUPERSEDED = "superseded"
    FAULTED = "faulted"
    CANCELLED = "cancelled"


# Enum members are class attributes, and reading one costs ~80 ns on CPython 3.11; the
# per-command paths (a setpoint per axis per tick) use module constants instead.
_PENDING = Outcome.PENDING
_REACHED = Outcome.REACHED
_SUPERSEDED = Outcome.SUPERSEDED


class Motion:
    """Handle of one command: completes when its target is reached.

    ``await motion`` returns None once the target is reached and raises
    :class:`SupersededError` when a later ``set_value`` replaced it,
    :class:`DeviceFaultError` when the actuator faulted, or
    :class:`MotionCancelledError` when the actuator was finalized or re-initialized.
    It can be awaited any number of times, from any task, and cancelled like any wait.

    ``posts_completed``: whether reaching the target posts COMPLETED to the actuator's
    observers. True for ``set_value`` (and ``ActuatorBank.set_values``); False for the
    setpoints an :class:`~openel_async.motion.AxisGroup` streams (the group posts one
    COMPLETED per axis when its motion arrives) or a bank built with
    ``setpoint_events=False``: such a Motion is still reached, superseded or faulted.
    """

    __slots__ = (
        "_done",
        "_error",
        "_superseded_by",
        "issued_ns",
        "outcome",
        "posts_completed",
        "reached_ns",
        "request",
        "sequence",
        "target",
    )

    def __init__(
        self,
        request: Request,
        target: float,
        sequence: int,
        issued_ns: int,
        posts_completed: bool = True,
    ) -> None:
        self.request = request
        self.target = target
        self.sequence = sequence
        self.issued_ns = issued_ns
        self.posts_completed = posts_completed
        self.reached_ns: int | None = None
        self.outcome = _PENDING
        self._error: HALError | None = None
        self._superseded_by = 0
        # Created on the first wait: most streamed setpoints are never awaited.
        self._done: anyio.Event | None = None

    def done(self) -> bool:
        return self.outcome is not _PENDING

    async def wait(self) -> None:
        if self.outcome is _PENDING:
            if self._done is None:
                self._done = anyio.Event()
            await self._done.wait()
        else:
            await anyio.lowlevel.checkpoint()
        error = self.error()
        if error is not None:
            raise error

    def error(self) -> HALError | None:
        """The exception ``await`` raises, or None while pending or once reached."""
        if self._error is None and self.outcome is Outcome.SUPERSEDED:
            self._error = SupersededError(
                f"target {self.target} ({self.request.name}) replaced by command "
                f"#{self._superseded_by}"
            )
        return self._error

    def __await__(self) -> Generator[Any, None, None]:
        return self.wait().__await__()

    # -- used by the Actuator -------------------------------------------------------
    def _finish(
        self, outcome: Outcome, error: HALError | None = None, at_ns: int | None = None
    ) -> bool:
        if self.outcome is not _PENDING:
            return False
        self.outcome = outcome
        self._error = error
        if outcome is _REACHED:
            self.reached_ns = at_ns
        if self._done is not None:
            self._done.set()
        return True

    def _reach(self, at_ns: int) -> bool:
        return self._finish(_REACHED, None, at_ns)

    def _supersede(self, by_sequence: int) -> bool:
        # The SupersededError is built only if someone awaits this motion.
        self._superseded_by = by_sequence
        return self._finish(_SUPERSEDED)

    def _fault(self, error: DeviceFaultError) -> bool:
        return self._finish(Outcome.FAULTED, error)

    def _cancel(self, reason: str) -> bool:
        return self._finish(Outcome.CANCELLED, MotionCancelledError(reason))

    def __repr__(self) -> str:
        return f"Motion(#{self.sequence} {self.request.name}={self.target}, {self.outcome.value})"
