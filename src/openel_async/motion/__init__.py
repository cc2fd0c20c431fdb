"""Coordinated motion: time-synchronized, jerk-limited moves of several actuators.

An :class:`AxisGroup` plans each motion with ruckig and streams POSITION setpoints to
its actuators at every tick of an :class:`~openel_async.timer.EventTimer`, through the
public Actuator API only, so it works with any driver. See docs/motion.md.
"""

from .errors import (
    AxisError,
    AxisFaultError,
    AxisStateError,
    GoalTimeoutError,
    GroupMotionError,
    MotionStoppedError,
    PathToleranceError,
    PreemptedError,
    TrajectoryError,
)
from .group import AxisGroup, GroupStats
from .handle import GroupMotion, GroupOutcome
from .log import TrajectoryLog, TrajectorySamples
from .params import AxisLimits, Tolerances, Waypoint
from .planner import KinematicState, Plan, Planner

__all__ = [
    "AxisError",
    "AxisFaultError",
    "AxisGroup",
    "AxisLimits",
    "AxisStateError",
    "GoalTimeoutError",
    "GroupMotion",
    "GroupMotionError",
    "GroupOutcome",
    "GroupStats",
    "KinematicState",
    "MotionStoppedError",
    "PathToleranceError",
    "Plan",
    "Planner",
    "PreemptedError",
    "Tolerances",
    "TrajectoryError",
    "TrajectoryLog",
    "TrajectorySamples",
    "Waypoint",
]
