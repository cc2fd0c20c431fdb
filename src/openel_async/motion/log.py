"""TrajectoryLog: what an axis group commanded (and, if asked, measured) at each tick.

A fixed-size ring of numpy rows, written once per tick while a motion runs; a
:meth:`TrajectoryLog.snapshot` copies it out oldest first, e.g. to plot commanded
against actual positions.

The group logs a tick as (time, motion, plan) with :meth:`TrajectoryLog.append_plan`:
what it commanded is the plan sampled at that time, so the row's positions, velocities
and accelerations are computed from the plan (the same floats) when a snapshot is
taken, not converted into numpy on every tick.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, TypeAlias

from ..clock import NS_PER_S
from ..errors import BadParameterError
from .planner import Plan

if TYPE_CHECKING:
    import numpy as np
    import numpy.typing as npt

    FloatArray: TypeAlias = npt.NDArray[np.float64]
    IntArray: TypeAlias = npt.NDArray[np.int64]

# numpy is imported when a log first needs its arrays (:meth:`TrajectoryLog.allocate`), not
# with the module: importing the framework (an app's --help) does not load it. An AxisGroup
# allocates its log in a worker thread as it is entered: a first import of numpy takes
# 0.1-1 s, which must not stall the event loop (heartbeats, watchdogs, other timers).


@dataclass(frozen=True, slots=True)
class TrajectorySamples:
    """Copied rows of a :class:`TrajectoryLog`, oldest first; row i is one tick."""

    time_ns: IntArray
    """Tick deadline (the time the setpoints were computed for), shape (n,)."""
    motion_id: IntArray
    """Id of the GroupMotion each row belongs to, shape (n,)."""
    commanded: FloatArray
    """Commanded position of every axis, shape (n, axes)."""
    velocity: FloatArray
    """Commanded velocity (from the trajectory, not differentiated), shape (n, axes)."""
    acceleration: FloatArray
    """Commanded acceleration, shape (n, axes)."""
    actual: FloatArray | None
    """POSITION_ACTUAL read at the tick, before the setpoints were sent; None unless
    the group logs actual positions."""

    def __len__(self) -> int:
        return int(self.time_ns.shape[0])

    @property
    def time_s(self) -> FloatArray:
        """Seconds since the first row."""
        import numpy as np

        if len(self) == 0:
            return np.zeros(0)
        return np.asarray((self.time_ns - self.time_ns[0]) / NS_PER_S, dtype=np.float64)

    def of_motion(self, motion_id: int) -> TrajectorySamples:
        """Only the rows of one motion."""
        keep = self.motion_id == motion_id
        return TrajectorySamples(
            self.time_ns[keep],
            self.motion_id[keep],
            self.commanded[keep],
            self.velocity[keep],
            self.acceleration[keep],
            None if self.actual is None else self.actual[keep],
        )


class TrajectoryLog:
    """Ring buffer of the last ``capacity`` ticks of an axis group (0: disabled)."""

    def __init__(self, axes: int, capacity: int = 10_000, *, actual: bool = False) -> None:
        if isinstance(capacity, bool) or not isinstance(capacity, int) or capacity < 0:
            raise BadParameterError("log_capacity", capacity, "an int >= 0 (0: no log)")
        self.axes = axes
        self.capacity = capacity
        self.records_actual = actual
        self.allocated = False
        """Whether the arrays exist (:meth:`allocate`; the first write or snapshot does it)."""
        self._time: IntArray
        self._motion: IntArray
        self._p: FloatArray
        self._v: FloatArray
        self._a: FloatArray
        self._actual: FloatArray | None = None
        self._planned: list[tuple[int, int, Plan] | None] = [None] * capacity
        """Rows logged by :meth:`append_plan` and not yet sampled into the arrays."""
        self._count = 0
        """Rows ever written (the next row is ``_count % capacity``)."""

    def allocate(self) -> None:
        """Import numpy and make the ring's arrays, if not done yet (blocking: the first
        import of numpy in a process takes 0.1-1 s; :class:`AxisGroup` calls it in a
        worker thread as it is entered)."""
        if self.allocated:
            return
        import numpy as np

        capacity, axes = self.capacity, self.axes
        self._time = np.zeros(capacity, dtype=np.int64)
        self._motion = np.zeros(capacity, dtype=np.int64)
        self._p = np.zeros((capacity, axes))
        self._v = np.zeros((capacity, axes))
        self._a = np.zeros((capacity, axes))
        self._actual = np.full((capacity, axes), np.nan) if self.records_actual else None
        self.allocated = True

    def __len__(self) -> int:
        return min(self._count, self.capacity)

    @property
    def total(self) -> int:
        """Rows written since the last clear, including those overwritten."""
        return self._count

    def append(
        self,
        time_ns: int,
        motion_id: int,
        position: Sequence[float],
        velocity: Sequence[float],
        acceleration: Sequence[float],
        actual: Sequence[float] | None = None,
    ) -> None:
        capacity = self.capacity
        if capacity == 0:
            return
        if not self.allocated:
            self.allocate()
        row = self._count % capacity
        self._count += 1
        self._time[row] = time_ns
        self._motion[row] = motion_id
        self._p[row] = position
        self._v[row] = velocity
        self._a[row] = acceleration
        self._planned[row] = None
        if self._actual is not None:
            self._actual[row] = math.nan if actual is None else actual

    def append_plan(
        self, time_ns: int, motion_id: int, plan: Plan, actual: Sequence[float] | None = None
    ) -> None:
        """A row whose commanded state is ``plan.sample(time_ns)``, sampled at snapshot time."""
        capacity = self.capacity
        if capacity == 0:
            return
        if not self.allocated:
            self.allocate()
        row = self._count % capacity
        self._count += 1
        self._planned[row] = (time_ns, motion_id, plan)
        if self._actual is not None:
            self._actual[row] = math.nan if actual is None else actual

    def plan_rows(self, motion_id: int, plan: Plan) -> Callable[[int], None]:
        """``append_plan(t, motion_id, plan)`` as a call of one argument ``t`` (what a
        streaming tick logs through: no actual positions)."""
        capacity = self.capacity
        if capacity == 0:
            return _no_row
        self.allocate()
        planned = self._planned
        actual = self._actual

        def row(time_ns: int) -> None:
            count = self._count
            self._count = count + 1
            index = count % capacity
            planned[index] = (time_ns, motion_id, plan)
            if actual is not None:
                actual[index] = math.nan

        return row

    def _sample_planned(self) -> None:
        planned = self._planned
        for row, entry in enumerate(planned):
            if entry is None:
                continue
            time_ns, motion_id, plan = entry
            state = plan.sample(time_ns)
            self._time[row] = time_ns
            self._motion[row] = motion_id
            self._p[row] = state.position
            self._v[row] = state.velocity
            self._a[row] = state.acceleration
            planned[row] = None

    def snapshot(self) -> TrajectorySamples:
        import numpy as np

        self.allocate()
        self._sample_planned()
        n = len(self)
        start = self._count % self.capacity if self._count > self.capacity else 0
        order = (np.arange(n) + start) % self.capacity if n else np.zeros(0, dtype=np.int64)
        return TrajectorySamples(
            self._time[order].copy(),
            self._motion[order].copy(),
            self._p[order].copy(),
            self._v[order].copy(),
            self._a[order].copy(),
            None if self._actual is None else self._actual[order].copy(),
        )

    def clear(self) -> None:
        self._count = 0
        self._planned[:] = [None] * self.capacity


def _no_row(time_ns: int) -> None:
    """The row writer of a disabled log."""
