"""ReturnCode_t and its exceptions; callback results."""

from __future__ import annotations

import pytest

from openel_async.rtc import (
    CallbackFailedError,
    OutOfResourcesError,
    PreconditionNotMetError,
    ReturnCode_t,
    RTCBadParameterError,
    RTCError,
    RTCTimeoutError,
    UnsupportedError,
    check_return_code,
)
from openel_async.rtc._callbacks import invoke, outcome_of


def test_return_codes_follow_the_idl_order() -> None:
    assert [c.name for c in ReturnCode_t] == [
        "RTC_OK",
        "RTC_ERROR",
        "BAD_PARAMETER",
        "UNSUPPORTED",
        "OUT_OF_RESOURCES",
        "PRECONDITION_NOT_MET",
    ]
    assert [int(c) for c in ReturnCode_t] == [0, 1, 2, 3, 4, 5]


@pytest.mark.parametrize(
    ("error", "code"),
    [
        (RTCError("x"), ReturnCode_t.RTC_ERROR),
        (RTCBadParameterError("rate", -1, "> 0"), ReturnCode_t.BAD_PARAMETER),
        (UnsupportedError("x"), ReturnCode_t.UNSUPPORTED),
        (OutOfResourcesError("x"), ReturnCode_t.OUT_OF_RESOURCES),
        (
            PreconditionNotMetError("start", "Running", ["Stopped"]),
            ReturnCode_t.PRECONDITION_NOT_MET,
        ),
        (
            CallbackFailedError("c", "on_activated", ReturnCode_t.BAD_PARAMETER),
            ReturnCode_t.RTC_ERROR,
        ),
        (RTCTimeoutError("x"), ReturnCode_t.RTC_ERROR),
    ],
)
def test_every_exception_carries_its_code(error: RTCError, code: ReturnCode_t) -> None:
    assert isinstance(error, RTCError)
    assert error.code is code


def test_messages_name_the_parameter_and_the_state() -> None:
    bad = RTCBadParameterError("rate", -1.0, "a rate > 0")
    assert isinstance(bad, ValueError)
    assert str(bad) == "rate=-1.0 is not allowed: expected a rate > 0"
    assert (bad.parameter, bad.value) == ("rate", -1.0)
    pnm = PreconditionNotMetError("start", "Running", ["Stopped"])
    assert str(pnm) == "start() is not allowed in state Running; allowed: Stopped"
    failed = CallbackFailedError("comp", "on_reset", ReturnCode_t.OUT_OF_RESOURCES)
    assert failed.callback_code is ReturnCode_t.OUT_OF_RESOURCES
    assert "on_reset failed with OUT_OF_RESOURCES" in str(failed)
    assert isinstance(RTCTimeoutError("x"), TimeoutError)


def test_check_return_code() -> None:
    check_return_code(ReturnCode_t.RTC_OK)
    check_return_code(0)
    with pytest.raises(UnsupportedError):
        check_return_code(3)
    with pytest.raises(OutOfResourcesError):
        check_return_code(ReturnCode_t.OUT_OF_RESOURCES, "no memory")
    for code in (
        ReturnCode_t.RTC_ERROR,
        ReturnCode_t.BAD_PARAMETER,
        ReturnCode_t.PRECONDITION_NOT_MET,
    ):
        with pytest.raises(RTCError) as info:
            check_return_code(code)
        assert info.value.code is code
    with pytest.raises(ValueError):
        check_return_code(42)


@pytest.mark.parametrize(
    ("result", "code"),
    [
        (None, ReturnCode_t.RTC_OK),
        (ReturnCode_t.RTC_OK, ReturnCode_t.RTC_OK),
        (0, ReturnCode_t.RTC_OK),
        (ReturnCode_t.BAD_PARAMETER, ReturnCode_t.BAD_PARAMETER),
        (5, ReturnCode_t.PRECONDITION_NOT_MET),
        (True, ReturnCode_t.RTC_ERROR),
        (False, ReturnCode_t.RTC_ERROR),
        (99, ReturnCode_t.RTC_ERROR),
        ("ok", ReturnCode_t.RTC_ERROR),
    ],
)
def test_callback_results(result: object, code: ReturnCode_t) -> None:
    outcome = outcome_of("on_execute", result)
    assert outcome.code is code
    assert outcome.ok is (code is ReturnCode_t.RTC_OK)
    if code is ReturnCode_t.RTC_ERROR:
        assert isinstance(outcome.error, TypeError)
        assert "on_execute returned" in str(outcome.error)


async def test_raised_exceptions_are_failures_with_their_code() -> None:
    async def raises(exc: BaseException) -> None:
        raise exc

    plain = await invoke("on_execute", raises, RuntimeError("boom"))
    assert plain.code is ReturnCode_t.RTC_ERROR
    assert isinstance(plain.error, RuntimeError)
    coded = await invoke("on_execute", raises, OutOfResourcesError("full"))
    assert coded.code is ReturnCode_t.OUT_OF_RESOURCES
    weird = await invoke("on_execute", raises, RTCError("ok?", code=ReturnCode_t.RTC_OK))
    assert weird.code is ReturnCode_t.RTC_ERROR
