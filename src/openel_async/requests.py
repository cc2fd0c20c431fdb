"""Request codes of an Actuator's SetValue/GetValue and the event ids of HALObserver."""

from __future__ import annotations

from enum import IntEnum

from .errors import BadParameterError


class Request(IntEnum):
    """Request codes of the OpenEL reference implementation.

    1-3 are control modes for ``set_value`` and the last *commanded* value for
    ``get_value``; 5-7 read the *actual* value. ``NO_EXCITE`` de-energizes the motor.
    """

    NO_EXCITE = 0
    POSITION = 1
    VELOCITY = 2
    TORQUE = 3
    POSITION_ACTUAL = 5
    VELOCITY_ACTUAL = 6
    TORQUE_ACTUAL = 7

    @property
    def is_command(self) -> bool:
        return self in _COMMANDS

    @property
    def actual(self) -> Request:
        """The ``*_ACTUAL`` code reading the quantity that this control mode commands."""
        return _ACTUAL_OF[self]


_COMMANDS = frozenset({Request.NO_EXCITE, Request.POSITION, Request.VELOCITY, Request.TORQUE})
_ACTUAL_OF = {
    Request.POSITION: Request.POSITION_ACTUAL,
    Request.VELOCITY: Request.VELOCITY_ACTUAL,
    Request.TORQUE: Request.TORQUE_ACTUAL,
    Request.POSITION_ACTUAL: Request.POSITION_ACTUAL,
    Request.VELOCITY_ACTUAL: Request.VELOCITY_ACTUAL,
    Request.TORQUE_ACTUAL: Request.TORQUE_ACTUAL,
}

SET_VALUE_REQUESTS = (Request.NO_EXCITE, Request.POSITION, Request.VELOCITY, Request.TORQUE)
GET_VALUE_REQUESTS = (
    Request.POSITION,
    Request.VELOCITY,
    Request.TORQUE,
    Request.POSITION_ACTUAL,
    Request.VELOCITY_ACTUAL,
    Request.TORQUE_ACTUAL,
)


def coerce_request(
    request: object, allowed: tuple[Request, ...], parameter: str = "request"
) -> Request:
    """Turn an int or Request into one of ``allowed`` or raise BAD_PARAMETER."""
    if type(request) is Request and request in allowed:  # the hot path: no allocation
        return request
    code = _BY_VALUE.get(request) if type(request) is int else None
    if code is None or code not in allowed:
        allowed_text = ", ".join(f"{r.name}={r.value}" for r in allowed)
        raise BadParameterError(parameter, request, f"one of {allowed_text}")
    return code


_BY_VALUE: dict[object, Request] = {int(r): r for r in Request}


class EventId(IntEnum):
    """Event ids of HALObserver.notify_event: 0 reserved, 1 COMPLETED, 2+ device-specific."""

    RESERVED = 0
    COMPLETED = 1
    LIMIT_REACHED = 2
    """First device-specific id; our drivers use it for 'stopped at a position limit'."""
