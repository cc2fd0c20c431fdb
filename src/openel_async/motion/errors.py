"""Why a group motion did not succeed.

Every error is a :class:`~openel_async.errors.HALError`. Those about one axis derive
from :class:`AxisError` and carry the axis index, the actuator's device name and, where
it applies, by how much the axis was off.
"""

from __future__ import annotations

from ..errors import HALError, MotionCancelledError, SupersededError


class GroupMotionError(HALError):
    """Base of the errors a :class:`GroupMotion` ends with."""


class AxisError(GroupMotionError):
    """A group motion failed because of one axis (the worst one if several)."""

    def __init__(
        self,
        message: str,
        *,
        axis: int,
        axis_name: str,
        deviation: float | None = None,
        tolerance: float | None = None,
        time_ns: int | None = None,
    ) -> None:
        super().__init__(message)
        self.axis = axis
        """Index of the axis in the group."""
        self.axis_name = axis_name
        """Device name of the axis' actuator."""
        self.deviation = deviation
        """Signed position error (actual - reference) in the axis' unit, if measured."""
        self.tolerance = tolerance
        self.time_ns = time_ns
        """Clock time of the tick that detected the failure."""


class PathToleranceError(AxisError):
    """While moving, an axis' actual position left the path tolerance of its setpoint."""


class GoalTimeoutError(AxisError):
    """The goal time ran out with an axis still outside its goal tolerance."""


class AxisFaultError(AxisError):
    """An axis faulted or left the Active state (Error, Finalized) during the motion.

    ``cause`` is the actuator's :class:`DeviceFaultError` (``last_fault``) or the
    exception its ``set_value``/``get_value`` raised.
    """

    def __init__(
        self,
        message: str,
        *,
        axis: int,
        axis_name: str,
        cause: BaseException | None = None,
        time_ns: int | None = None,
    ) -> None:
        super().__init__(message, axis=axis, axis_name=axis_name, time_ns=time_ns)
        self.cause = cause


class AxisStateError(AxisError):
    """A motion was requested while an axis is not Active; nothing was changed."""

    def __init__(self, message: str, *, axis: int, axis_name: str, state: object) -> None:
        super().__init__(message, axis=axis, axis_name=axis_name)
        self.state = state


class PreemptedError(GroupMotionError, SupersededError):
    """A later motion of the group replaced this one before it finished."""

    def __init__(self, message: str, *, by: int) -> None:
        super().__init__(message)
        self.by = by
        """Id of the motion that replaced this one."""


class MotionStoppedError(GroupMotionError, MotionCancelledError):
    """``stop()``, ``hold()`` or leaving the group's context ended the motion."""


class TrajectoryError(GroupMotionError):
    """Ruckig could not compute a trajectory for the request."""
