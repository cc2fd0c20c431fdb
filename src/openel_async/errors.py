"""Return codes of OpenEL 3.2 / HAL4RT and the exceptions that carry them.

The PIM models errors as ``ReturnCode`` values; our Python PSM maps every code other
than ``HAL_OK`` to an exception whose ``code`` attribute is that value.
"""

from __future__ import annotations

from collections.abc import Iterable
from enum import IntEnum


class ReturnCode(IntEnum):
    """OpenEL 3.2 (HAL_OK, HAL_ERROR) plus the HAL4RT 1.0 codes."""

    HAL_OK = 0
    HAL_ERROR = 1
    HAL_NO_CONNECTED = 2
    HAL_NO_MEMORY = 3
    HAL_NULL_PARAMETER = 4
    HAL_NOT_IMPLEMENTED = 5
    HAL_BAD_PARAMETER = 6


class HALError(Exception):
    """Base of every error of the HAL; ``code`` is the spec's ReturnCode."""

    code: ReturnCode = ReturnCode.HAL_ERROR

    def __init__(self, message: str, *, code: ReturnCode | None = None) -> None:
        super().__init__(message)
        if code is not None:
            self.code = code


class NotConnectedError(HALError):
    """HAL_NO_CONNECTED: the target device is not connected."""

    code = ReturnCode.HAL_NO_CONNECTED


class OutOfMemoryError(HALError):
    """HAL_NO_MEMORY: the target ran out of the memory needed for the operation."""

    code = ReturnCode.HAL_NO_MEMORY


class NullParameterError(HALError):
    """HAL_NULL_PARAMETER: a required parameter was not given."""

    code = ReturnCode.HAL_NULL_PARAMETER


class NotImplementedHALError(HALError):
    """HAL_NOT_IMPLEMENTED: the device or implementation does not support the operation."""

    code = ReturnCode.HAL_NOT_IMPLEMENTED


class WouldBlockError(NotImplementedHALError):
    """HAL_NOT_IMPLEMENTED: a ``*_nowait`` call on a device that needs to wait (bus I/O);
    use the async operation instead."""


class BadParameterError(HALError, ValueError):
    """HAL_BAD_PARAMETER: an illegal argument; the message names the parameter."""

    code = ReturnCode.HAL_BAD_PARAMETER

    def __init__(self, parameter: str, value: object, allowed: str) -> None:
        super().__init__(f"{parameter}={value!r} is not allowed: expected {allowed}")
        self.parameter = parameter
        self.value = value
        self.allowed = allowed


STATE_HINTS: dict[object, str] = {}
"""What to do about a state, by state (an enum member): appended to a :class:`StateError`'s
message (the component module registers its Initializing and Initialized states)."""


class StateError(HALError):
    """HAL_ERROR: the operation is not callable in the component's current state.

    The message names the operation, the state and the states it is allowed in, and, for a
    state with a hint in :data:`STATE_HINTS` (a component never entered, or never
    initialized), how to get out of it.
    """

    def __init__(self, operation: str, state: object, allowed: Iterable[object]) -> None:
        allowed_names = ", ".join(str(s) for s in allowed) or "none"
        message = f"{operation}() is not callable in state {state}; allowed in: {allowed_names}"
        try:
            hint = STATE_HINTS.get(state) if operation != "__aenter__" else None
        except TypeError:  # an unhashable state
            hint = None
        super().__init__(message if hint is None else f"{message}. {hint}")
        self.operation = operation
        self.state = state
        self.allowed = tuple(allowed)


class VirtualClockStalledError(StateError):
    """A task sleeps on a VirtualClock that nothing drives: the clock is not in auto-jump,
    no ``advance`` runs, and the event loop has had nothing else to do for the clock's
    ``stall_timeout`` of real time. Raised in every task sleeping on that clock; the
    message says how to drive it."""

    def __init__(self, message: str) -> None:
        HALError.__init__(self, message)
        self.operation = "sleep_until"
        self.state = "manual, never advanced"
        self.allowed = ("auto-jump", "advanced")


class DeviceFaultError(HALError):
    """The device faulted; the component went to the Error state."""

    def __init__(self, message: str, *, error_id: int, code: ReturnCode = ReturnCode.HAL_ERROR):
        super().__init__(message, code=code)
        self.error_id = error_id


class SupersededError(HALError):
    """A later set_value replaced this command's target before it was reached."""


class MotionCancelledError(HALError):
    """The command ended without reaching its target: the actuator was finalized, or
    left Active while the command was being sent."""


def check_code(code: ReturnCode | int, message: str = "") -> None:
    """Raise the exception matching a return code received from a C-style API."""
    code = ReturnCode(code)
    if code is ReturnCode.HAL_OK:
        return
    text = message or code.name
    if code is ReturnCode.HAL_BAD_PARAMETER:
        raise BadParameterError("parameter", None, text)
    for cls in (
        NotConnectedError,
        OutOfMemoryError,
        NullParameterError,
        NotImplementedHALError,
    ):
        if cls.code is code:
            raise cls(text)
    raise HALError(text, code=code)
