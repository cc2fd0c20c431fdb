"""start/stop/set_rate called from a participant's own callback are refused
(PRECONDITION_NOT_MET, nothing changed) instead of returning OK and silently skipping
that participant's on_startup/on_shutdown/on_rate_changed; and the periodic rate is
bounded so a context is never asked for a rate it cannot run."""

from __future__ import annotations

from collections.abc import Awaitable, Callable

import pytest

from openel_async import VirtualClock
from openel_async.rtc import (
    CallbackResult,
    LifeCycleState,
    PeriodicExecutionContext,
    PreconditionNotMetError,
    RTCBadParameterError,
)
from openel_async.rtc.context import MAX_RATE_HZ, MIN_RATE_HZ
from openel_async.rtc.runner import run_profile_cli

from .helpers import MS, Journal, Recorder
from .test_runner import APP

S = LifeCycleState


class CallsOwnContext(Recorder):
    """Calls ``action(ec)`` from its first on_execute and keeps what it raised."""

    def __init__(self, name: str, journal: Journal, clock: VirtualClock) -> None:
        super().__init__(name, journal, clock)
        self.action: Callable[[PeriodicExecutionContext], Awaitable[None]] | None = None
        self.ec: PeriodicExecutionContext | None = None
        self.raised: BaseException | None = None

    async def on_execute(self, exec_handle: int) -> CallbackResult:
        await super().on_execute(exec_handle)
        action, self.action = self.action, None
        if action is not None:
            assert self.ec is not None
            try:
                await action(self.ec)
            except PreconditionNotMetError as exc:
                self.raised = exc
        return None


async def _run(
    virtual_clock: VirtualClock,
    journal: Journal,
    action: Callable[[PeriodicExecutionContext], Awaitable[None]],
) -> tuple[CallsOwnContext, Recorder, PeriodicExecutionContext]:
    a = CallsOwnContext("A", journal, virtual_clock)
    b = Recorder("B", journal, virtual_clock)
    ec = PeriodicExecutionContext(100, clock=virtual_clock)
    async with ec:
        for comp in (a, b):
            await comp.initialize()
            await ec.add_component(comp)
        a.ec = ec
        a.action = action
        await ec.start()
        await ec.activate_component(a)
        await virtual_clock.sleep_until(35 * MS)
        assert ec.is_running()
        await ec.stop()
    return a, b, ec


@pytest.mark.parametrize(
    "action",
    [
        lambda ec: ec.set_rate(50),
        lambda ec: ec.stop(),
        lambda ec: ec.start(),
    ],
    ids=["set_rate", "stop", "start"],
)
async def test_own_callback_context_calls_are_refused_and_change_nothing(
    virtual_clock: VirtualClock,
    journal: Journal,
    action: Callable[[PeriodicExecutionContext], Awaitable[None]],
) -> None:
    a, _, ec = await _run(virtual_clock, journal, action)
    assert isinstance(a.raised, PreconditionNotMetError)
    assert "inside a callback of A" in str(a.raised)
    # nothing changed: same rate, still running (cycles at 10, 20, 30 ms), nobody told
    assert ec.get_rate() == 100.0
    assert [c.time_ns // MS for c in journal.of("A", "on_execute")] == [10, 20, 30]
    assert journal.of("A", "on_rate_changed") == journal.of("B", "on_rate_changed") == []
    # the one stop (from the test) told both participants
    assert len(journal.of("A", "on_shutdown")) == len(journal.of("B", "on_shutdown")) == 1
    assert ec.get_component_state(a) is S.ACTIVE


async def test_another_context_s_callback_may_change_the_rate(
    virtual_clock: VirtualClock, journal: Journal
) -> None:
    """The refusal is about the caller's own context: from a callback in another
    context the call goes through and every participant is told."""
    a = Recorder("A", journal, virtual_clock)
    driver = CallsOwnContext("D", journal, virtual_clock)
    target = PeriodicExecutionContext(100, clock=virtual_clock)
    other = PeriodicExecutionContext(100, clock=virtual_clock)
    async with target, other:
        await a.initialize()
        await driver.initialize()
        await target.add_component(a)
        await other.add_component(driver)
        driver.ec = target
        driver.action = lambda ec: ec.set_rate(50)
        await target.start()
        await other.start()
        await other.activate_component(driver)
        await virtual_clock.sleep_until(15 * MS)
        assert driver.raised is None
        assert target.get_rate() == 50.0
        assert [c.time_ns // MS for c in journal.of("A", "on_rate_changed")] == [10]


@pytest.mark.parametrize("rate", [MAX_RATE_HZ * 1.0001, 1e9, MIN_RATE_HZ / 2, 0, -1])
async def test_rates_out_of_bounds_are_refused(virtual_clock: VirtualClock, rate: float) -> None:
    with pytest.raises(RTCBadParameterError) as info:
        PeriodicExecutionContext(rate, clock=virtual_clock)
    assert info.value.parameter == "rate"
    assert f"{MAX_RATE_HZ:g}" in str(info.value)
    async with PeriodicExecutionContext(100, clock=virtual_clock) as ec:
        with pytest.raises(RTCBadParameterError):
            await ec.set_rate(rate)
        assert ec.get_rate() == 100.0
        await ec.set_rate(MAX_RATE_HZ)  # the bounds themselves are allowed
        await ec.set_rate(MIN_RATE_HZ)
        assert ec.get_rate() == MIN_RATE_HZ


def test_run_refuses_a_rate_it_cannot_run(capsys: pytest.CaptureFixture[str]) -> None:
    # Was: --rate 1e9 ran for tens of minutes at full CPU on the virtual clock.
    assert run_profile_cli(APP, ["--virtual", "--duration", "5", "--rate", "1e9"]) == 2
    err = capsys.readouterr().err
    assert "--rate: the rate must be a number of Hz" in err
    assert f"<= {MAX_RATE_HZ:g}" in err
    assert len(err.strip().splitlines()) == 1
