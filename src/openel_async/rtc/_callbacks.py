"""Invoking component callbacks: a return code or an exception becomes an Outcome."""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from dataclasses import dataclass

from .errors import ReturnCode_t, RTCError

OK_CODE = ReturnCode_t.RTC_OK


@dataclass(frozen=True, slots=True)
class Outcome:
    """What a callback gave back: RTC_OK, or a failure code with the exception raised."""

    code: ReturnCode_t
    error: BaseException | None = None

    @property
    def ok(self) -> bool:
        return self.code is OK_CODE


OK = Outcome(OK_CODE)


def outcome_of(name: str, result: object) -> Outcome:
    """The Outcome of a callback that returned ``result`` (None means RTC_OK)."""
    if result is None or result is OK_CODE:
        return OK
    if isinstance(result, int) and not isinstance(result, bool):
        try:
            code = ReturnCode_t(result)
        except ValueError:
            pass
        else:
            return OK if code is OK_CODE else Outcome(code)
    return Outcome(
        ReturnCode_t.RTC_ERROR,
        TypeError(f"{name} returned {result!r}; expected a ReturnCode_t or None"),
    )


async def invoke(name: str, method: Callable[..., Awaitable[object]], *args: object) -> Outcome:
    """Await one callback; exceptions (not cancellation) are failures, not raised."""
    try:
        result = await method(*args)
    except RTCError as exc:
        code = exc.code if exc.code is not OK_CODE else ReturnCode_t.RTC_ERROR
        return Outcome(code, exc)
    except Exception as exc:
        return Outcome(ReturnCode_t.RTC_ERROR, exc)
    return outcome_of(name, result)
