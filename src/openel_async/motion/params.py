"""Parameters of group motions: kinematic limits, tolerances and waypoints."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from numbers import Real
from typing import TypeVar

from ..errors import BadParameterError

T = TypeVar("T")


def finite_positive(name: str, value: object) -> float:
    """``value`` as a float if it is a finite real number > 0, else BAD_PARAMETER."""
    if isinstance(value, bool) or not isinstance(value, Real):
        raise BadParameterError(name, value, "a finite number > 0")
    result = float(value)
    if not (math.isfinite(result) and result > 0):
        raise BadParameterError(name, value, "a finite number > 0")
    return result


def finite_non_negative(name: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, Real):
        raise BadParameterError(name, value, "a finite number >= 0")
    result = float(value)
    if not (math.isfinite(result) and result >= 0):
        raise BadParameterError(name, value, "a finite number >= 0")
    return result


def finite(name: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, Real):
        raise BadParameterError(name, value, "a finite real number")
    result = float(value)
    if not math.isfinite(result):
        raise BadParameterError(name, value, "a finite real number (not NaN or infinity)")
    return result


@dataclass(frozen=True, slots=True)
class AxisLimits:
    """Kinematic limits of one axis for the trajectories the group plans (SI units).

    The effective velocity limit of an axis is the smaller of ``max_velocity`` and its
    device's ``ActuatorLimits.velocity``.
    """

    max_velocity: float
    """rad/s or m/s."""
    max_acceleration: float
    """rad/s² or m/s²."""
    max_jerk: float
    """rad/s³ or m/s³."""

    def __post_init__(self) -> None:
        for name in ("max_velocity", "max_acceleration", "max_jerk"):
            object.__setattr__(self, name, finite_positive(name, getattr(self, name)))


@dataclass(frozen=True, slots=True)
class Tolerances:
    """Tolerances of one axis, in the axis' position unit (rad or m).

    - ``goal``: the move succeeds once every axis' POSITION_ACTUAL is within ``goal``
      of its final target (checked every tick after the last setpoint was sent, for
      at most the group's ``goal_time``).
    - ``path``: while moving, the move aborts when POSITION_ACTUAL differs from the
      setpoint sent at the previous tick by more than ``path`` (a following error).
      None: not checked (no actual position is read while moving).
    """

    goal: float = 1e-3
    path: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "goal", finite_positive("goal", self.goal))
        if self.path is not None:
            object.__setattr__(self, "path", finite_positive("path", self.path))


@dataclass(frozen=True, slots=True, init=False)
class Waypoint:
    """A point of a :meth:`AxisGroup.follow` path: one position per axis.

    ``time``: seconds from the start of the motion at which the group passes this
    waypoint; None: as early as the limits allow.
    """

    positions: tuple[float, ...]
    time: float | None

    def __init__(self, positions: Sequence[float], time: float | None = None) -> None:
        if isinstance(positions, str | bytes) or not isinstance(positions, Sequence):
            raise BadParameterError("positions", positions, "a sequence of positions")
        object.__setattr__(self, "positions", tuple(positions))
        object.__setattr__(self, "time", time)


def per_axis(value: T | Sequence[T], count: int, name: str, kind: type[T]) -> tuple[T, ...]:
    """One ``kind`` for every axis, or a sequence of exactly ``count`` of them."""
    if isinstance(value, kind):
        return (value,) * count
    if isinstance(value, str | bytes) or not isinstance(value, Sequence):
        raise BadParameterError(
            name, value, f"a {kind.__name__} or a sequence of {count} (one per axis)"
        )
    items = tuple(value)
    if len(items) != count:
        raise BadParameterError(
            name, value, f"a {kind.__name__} or {count} of them (one per axis), not {len(items)}"
        )
    for i, item in enumerate(items):
        if not isinstance(item, kind):
            raise BadParameterError(f"{name}[{i}]", item, f"a {kind.__name__}")
    return items
