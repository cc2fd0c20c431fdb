"""Return codes of the RTC PIM (``ReturnCode_t``) and the exceptions that carry them.

As for the HAL (:mod:`openel_async.errors`), the Python PSM maps ``RTC_OK`` to a normal
return and every other code to an exception whose ``code`` attribute is that value.
Component callbacks go the other way: they may return a ``ReturnCode_t`` (or None for
``RTC_OK``) or raise; see :func:`callback_result`.
"""

from __future__ import annotations

from collections.abc import Iterable
from enum import IntEnum

__all__ = [
    "CallbackFailedError",
    "OutOfResourcesError",
    "PreconditionNotMetError",
    "RTCBadParameterError",
    "RTCError",
    "RTCTimeoutError",
    "ReturnCode_t",
    "UnsupportedError",
    "check_return_code",
]


class ReturnCode_t(IntEnum):
    """ReturnCode_t of the RTC specification, numbered in the IDL's order."""

    RTC_OK = 0
    RTC_ERROR = 1
    BAD_PARAMETER = 2
    UNSUPPORTED = 3
    OUT_OF_RESOURCES = 4
    PRECONDITION_NOT_MET = 5


class RTCError(Exception):
    """Base of every error of the RTC runtime; ``code`` is the spec's ReturnCode_t."""

    code: ReturnCode_t = ReturnCode_t.RTC_ERROR

    def __init__(self, message: str, *, code: ReturnCode_t | None = None) -> None:
        super().__init__(message)
        if code is not None:
            self.code = code


class RTCBadParameterError(RTCError, ValueError):
    """BAD_PARAMETER: an illegal argument; the message names the parameter."""

    code = ReturnCode_t.BAD_PARAMETER

    def __init__(self, parameter: str, value: object, allowed: str) -> None:
        super().__init__(f"{parameter}={value!r} is not allowed: expected {allowed}")
        self.parameter = parameter
        self.value = value
        self.allowed = allowed


class UnsupportedError(RTCError):
    """UNSUPPORTED: the operation is not supported by this object (e.g. a rate of an
    event-driven context)."""

    code = ReturnCode_t.UNSUPPORTED


class OutOfResourcesError(RTCError):
    """OUT_OF_RESOURCES: the runtime could not get what the operation needs."""

    code = ReturnCode_t.OUT_OF_RESOURCES


class PreconditionNotMetError(RTCError):
    """PRECONDITION_NOT_MET: the operation is not allowed in the current state."""

    code = ReturnCode_t.PRECONDITION_NOT_MET

    def __init__(self, operation: str, state: object, allowed: Iterable[object] | str) -> None:
        allowed_text = allowed if isinstance(allowed, str) else ", ".join(str(s) for s in allowed)
        super().__init__(
            f"{operation}() is not allowed in state {state}; allowed: {allowed_text or 'none'}"
        )
        self.operation = operation
        self.state = state
        self.allowed = allowed_text


class CallbackFailedError(RTCError):
    """RTC_ERROR: a component callback returned a code other than RTC_OK or raised.

    ``callback`` names it (``on_activated``...), ``callback_code`` is the code it returned
    (or carried, when it raised an :class:`RTCError`; RTC_ERROR for other exceptions) and
    ``__cause__`` is the exception it raised, if any.
    """

    def __init__(self, component: str, callback: str, callback_code: ReturnCode_t) -> None:
        super().__init__(f"{component}: {callback} failed with {callback_code.name}")
        self.component = component
        self.callback = callback
        self.callback_code = callback_code


class RTCTimeoutError(RTCError, TimeoutError):
    """RTC_ERROR: a lifecycle operation did not finish within the context's
    ``lifecycle_timeout`` (measured on the context's clock)."""


_BY_CODE: dict[ReturnCode_t, type[RTCError]] = {
    ReturnCode_t.UNSUPPORTED: UnsupportedError,
    ReturnCode_t.OUT_OF_RESOURCES: OutOfResourcesError,
}


def check_return_code(code: ReturnCode_t | int, message: str = "") -> None:
    """Raise the exception matching a code received from a C-style API (RTC_OK returns).

    BAD_PARAMETER and PRECONDITION_NOT_MET become a plain :class:`RTCError` with that
    ``code`` (their own classes need the parameter or the state to describe).
    """
    code = ReturnCode_t(code)
    if code is ReturnCode_t.RTC_OK:
        return
    cls = _BY_CODE.get(code)
    text = message or code.name
    if cls is not None:
        raise cls(text)
    raise RTCError(text, code=code)
