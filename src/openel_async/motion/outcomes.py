"""The tolerance checks of an :class:`~openel_async.motion.AxisGroup`'s motion and the errors
that end it (split out of :mod:`openel_async.motion.group`)."""

from __future__ import annotations

from collections.abc import Sequence

from ..actuator import Actuator
from ..clock import NS_PER_S
from ..component import ComponentState
from .errors import AxisFaultError, GoalTimeoutError, PathToleranceError
from .handle import GroupMotion

__all__ = ["axis_failure", "goal_timeout", "left_active", "path_violation", "worst_goal_miss"]

Miss = tuple[float, int, float, float]
"""(deviation / tolerance, axis, deviation, tolerance) of the axis farthest out."""


def path_violation(
    name: str,
    axes: Sequence[Actuator],
    motion: GroupMotion,
    actual: Sequence[float],
    commanded: Sequence[float],
    t: int,
) -> PathToleranceError | None:
    """The error for the axis farthest beyond its path tolerance (relative to it) from its
    setpoint, or None when every axis is within its own."""
    worst: Miss | None = None
    for i, tol in enumerate(motion._path_tolerance):
        if tol is None:
            continue
        deviation = actual[i] - commanded[i]
        if abs(deviation) > tol:
            ratio = abs(deviation) / tol
            if worst is None or ratio > worst[0]:
                worst = (ratio, i, deviation, tol)
    if worst is None:
        return None
    _, i, deviation, tol = worst
    axis_name = axes[i].device_name
    return PathToleranceError(
        f"{name}: axis {i} ({axis_name}) is {deviation:+.6g} from its setpoint, "
        f"beyond the path tolerance {tol:g}",
        axis=i,
        axis_name=axis_name,
        deviation=deviation,
        tolerance=tol,
        time_ns=t,
    )


def worst_goal_miss(motion: GroupMotion, actual: Sequence[float]) -> Miss | None:
    """The axis farthest beyond its goal tolerance from its target, or None (all arrived)."""
    targets = motion.targets
    worst: Miss | None = None
    for i, tol in enumerate(motion._goal_tolerance):
        deviation = actual[i] - targets[i]
        if abs(deviation) > tol:
            ratio = abs(deviation) / tol
            if worst is None or ratio > worst[0]:
                worst = (ratio, i, deviation, tol)
    return worst


def goal_timeout(
    name: str, axes: Sequence[Actuator], motion: GroupMotion, worst: Miss, t: int
) -> GoalTimeoutError:
    """The error of a motion whose axis ``worst`` missed its goal within the goal time."""
    _, i, deviation, tol = worst
    axis_name = axes[i].device_name
    return GoalTimeoutError(
        f"{name}: axis {i} ({axis_name}) is still {deviation:+.6g} from its "
        f"target {motion.targets[i]:g} (goal tolerance {tol:g}) "
        f"{motion._goal_time_ns / NS_PER_S:g} s after the trajectory ended",
        axis=i,
        axis_name=axis_name,
        deviation=deviation,
        tolerance=tol,
        time_ns=t,
    )


def left_active(name: str, axes: Sequence[Actuator], t: int) -> AxisFaultError | None:
    """The error naming the first axis that is no longer Active (with its fault), if any."""
    active = ComponentState.ACTIVE
    for i, axis in enumerate(axes):
        if axis.state is not active:
            cause = axis.last_fault
            return AxisFaultError(
                f"{name}: axis {i} ({axis.device_name}) left Active "
                f"({axis.state})" + (f": {cause}" if cause is not None else ""),
                axis=i,
                axis_name=axis.device_name,
                cause=cause,
                time_ns=t,
            )
    return None


def axis_failure(
    name: str, axes: Sequence[Actuator], index: int, exc: Exception, t: int
) -> AxisFaultError:
    """The error of a call to axis ``index`` that raised ``exc``."""
    axis = axes[index]
    return AxisFaultError(
        f"{name}: axis {index} ({axis.device_name}) failed: {type(exc).__name__}: {exc}",
        axis=index,
        axis_name=axis.device_name,
        cause=exc,
        time_ns=t,
    )
