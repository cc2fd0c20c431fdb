"""The checks of an :class:`~openel_async.motion.AxisGroup`'s arguments: its actuators, and
the positions and waypoints of a motion (split out of :mod:`openel_async.motion.group`)."""

from __future__ import annotations

from collections.abc import Iterable, Sequence

from ..actuator import Actuator
from ..component import ComponentState
from ..errors import BadParameterError
from ..requests import Request
from .params import Waypoint, finite, finite_positive

__all__ = ["check_actuators", "positions_arg", "waypoints_arg"]


def check_actuators(actuators: object) -> tuple[Actuator, ...]:
    """A group's axes: a non-empty sequence of distinct Actuators, none Finalized, each
    over a device that supports POSITION control."""
    if isinstance(actuators, str | bytes) or not isinstance(actuators, Sequence):
        raise BadParameterError("actuators", actuators, "a sequence of Actuators")
    axes = tuple(actuators)
    if not axes:
        raise BadParameterError("actuators", actuators, "at least one Actuator")
    seen: dict[int, int] = {}
    for i, axis in enumerate(axes):
        if not isinstance(axis, Actuator):
            raise BadParameterError(f"actuators[{i}]", axis, "an Actuator")
        first = seen.setdefault(id(axis), i)
        if first != i:
            raise BadParameterError(
                f"actuators[{i}]",
                axis.device_name,
                f"an actuator not already in the group (it is actuators[{first}])",
            )
        if axis.state is ComponentState.FINALIZED:
            raise BadParameterError(
                f"actuators[{i}]", axis.device_name, "an Actuator that is not Finalized"
            )
        if Request.POSITION not in axis.device.supported_requests:
            raise BadParameterError(
                f"actuators[{i}]",
                axis.device_name,
                "an Actuator whose device supports POSITION control",
            )
    return axes


def positions_arg(
    value: object,
    name: str,
    axes: Sequence[Actuator],
    bounds: Sequence[tuple[float, float]],
) -> list[float]:
    """``value`` as one finite position per axis, each within its axis' ``bounds``."""
    n = len(axes)
    if isinstance(value, str | bytes) or not isinstance(value, Iterable):
        raise BadParameterError(name, value, f"a sequence of {n} positions (one per axis)")
    items = list(value)
    if len(items) != n:
        raise BadParameterError(name, value, f"{n} positions (one per axis), not {len(items)}")
    out: list[float] = []
    for i, (item, (low, high)) in enumerate(zip(items, bounds, strict=True)):
        position = finite(f"{name}[{i}]", item)
        if not low <= position <= high:
            raise BadParameterError(
                f"{name}[{i}]",
                item,
                f"a position in [{low}, {high}] (the limits of axis {i}, {axes[i].device_name})",
            )
        out.append(position)
    return out


def waypoints_arg(
    waypoints: object,
    axes: Sequence[Actuator],
    bounds: Sequence[tuple[float, float]],
) -> list[tuple[list[float], float | None]]:
    """``waypoints`` as (positions, time or None) pairs: each a :class:`Waypoint` whose
    positions pass :func:`positions_arg`, timed ones in increasing time."""
    if isinstance(waypoints, str | bytes) or not isinstance(waypoints, Sequence):
        raise BadParameterError("waypoints", waypoints, "a sequence of Waypoint")
    if not waypoints:
        raise BadParameterError("waypoints", waypoints, "at least one Waypoint")
    points: list[tuple[list[float], float | None]] = []
    last_time = 0.0
    for i, point in enumerate(waypoints):
        if not isinstance(point, Waypoint):
            raise BadParameterError(f"waypoints[{i}]", point, "a Waypoint")
        positions = positions_arg(point.positions, f"waypoints[{i}].positions", axes, bounds)
        at: float | None = None
        if point.time is not None:
            at = finite_positive(f"waypoints[{i}].time", point.time)
            if at <= last_time:
                raise BadParameterError(
                    f"waypoints[{i}].time",
                    point.time,
                    f"a time after the previous timed waypoint ({last_time:g} s)",
                )
            last_time = at
        points.append((positions, at))
    return points
