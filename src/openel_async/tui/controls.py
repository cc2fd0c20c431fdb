"""What every jog session has, local (:class:`~openel_async.tui.jogger.Jogger`) or served
(the Zenoh driver's remote jogger): its rows and the selected one, the jog step and velocity
chosen from :data:`STEPS` and :data:`VELOCITIES`, the event and error log, and the task group
its background work runs in."""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable, Coroutine, Sequence
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

import anyio.abc

from ..logs import get_logger

__all__ = ["STEPS", "VELOCITIES", "JogControls", "LogEntry", "nearest_index"]

log = get_logger(__name__)

STEPS = (0.001, 0.005, 0.01, 0.05, 0.1, 0.25, 0.5, 1.0)
"""The jog steps ``[`` and ``]`` choose from (rad or m)."""
VELOCITIES = (0.01, 0.05, 0.1, 0.25, 0.5, 1.0, 2.0, 5.0)
"""The jog velocities ``-`` and ``+`` choose from (rad/s or m/s)."""

RowT = TypeVar("RowT")


@dataclass(frozen=True, slots=True)
class LogEntry:
    """One line of the event and error log."""

    time: float
    """``time.time()`` when it happened."""
    level: str
    """``info``, ``warning`` or ``error``."""
    text: str


def nearest_index(choices: tuple[float, ...], value: float) -> int:
    """The index of the choice nearest ``value`` (by ratio: the steps are logarithmic)."""
    return min(range(len(choices)), key=lambda i: abs(math.log(choices[i] / value)))


class JogControls(Generic[RowT]):
    """The rows, selection, step, velocity, log and task group of a jog session."""

    def __init__(self, *, step: float, velocity: float) -> None:
        self.step = step
        self.velocity = velocity
        self.rows: list[RowT] = []
        self.selected = 0
        self.log: deque[LogEntry] = deque(maxlen=1000)
        self.completed = 0
        """COMPLETED events heard (not logged one by one)."""
        self.on_log: Callable[[LogEntry], object] | None = None
        """Told of every new log entry (the UI's log panel)."""
        self._tg: anyio.abc.TaskGroup | None = None

    def start_soon(self, func: Callable[[], Coroutine[Any, Any, None]]) -> None:
        """Run ``func`` in the session's task group (only inside ``async with``)."""
        if self._tg is None:
            raise RuntimeError(f"the jogger runs inside 'async with {type(self).__name__}(...)'")
        self._tg.start_soon(func)

    def note(self, level: str, text: str) -> None:
        """Add a line to the log (and tell ``on_log``)."""
        entry = LogEntry(time.time(), level, text)
        self.log.append(entry)
        log.debug("jog_log", level=level, text=text)
        if self.on_log is not None:
            self.on_log(entry)

    @property
    def row(self) -> RowT:
        return self.rows[self.selected]

    def select(self, index: int) -> None:
        if self.rows:
            self.selected = max(0, min(len(self.rows) - 1, index))

    def change_step(self, delta: int) -> float:
        """The next smaller (``delta`` -1) or larger (+1) step of :data:`STEPS`."""
        index = nearest_index(STEPS, self.step) + delta
        self.step = STEPS[max(0, min(len(STEPS) - 1, index))]
        return self.step

    def change_velocity(self, delta: int) -> float:
        """The next smaller (``delta`` -1) or larger (+1) velocity of :data:`VELOCITIES`."""
        index = nearest_index(VELOCITIES, self.velocity) + delta
        self.velocity = VELOCITIES[max(0, min(len(VELOCITIES) - 1, index))]
        return self.velocity

    def next_target(
        self,
        name: str,
        direction: int,
        last_target: float | None,
        values: Sequence[float],
        limits: tuple[float, float],
    ) -> tuple[float, float] | None:
        """Where a jog of one step in ``direction`` (-1, +1) takes axis ``name``, as (from,
        to): from the last jog's target (where it went or is going), else the position
        read, to one step on clamped to ``limits``; None, with a line in the log, when no
        position was read yet or the axis is at its limit already."""
        low, high = limits
        if last_target is not None:
            base = last_target
        elif values:
            base = values[0]
        else:
            self.note("warning", f"{name}: no position read yet: not jogged")
            return None
        target = min(high, max(low, base + direction * self.step))
        if target == base:
            self.note("warning", f"{name}: at its limit {target:g} (limits [{low:g}, {high:g}])")
            return None
        return base, target
