"""A VirtualClock that nothing drives: its sleepers get a VirtualClockStalledError (with
the ways to drive it) once the loop has been otherwise idle for ``stall_timeout`` real
seconds, and never while something real may still advance it."""

from __future__ import annotations

import socket
import threading
import time

import anyio
import pytest

from openel_async import Actuator, StateError
from openel_async.clock import STALL_TIMEOUT_S, VirtualClock
from openel_async.errors import BadParameterError, ReturnCode, VirtualClockStalledError
from openel_sim import SimMotor

FIX = ("clock.autojump()", "clock.advance(delta_ns)", "virtual_clock")


async def test_an_actuator_on_a_clock_nobody_advances_raises_instead_of_hanging() -> None:
    """Issue 21: ``Actuator(SimMotor(), clock=VirtualClock())`` then ``await motion`` hung
    forever in silence."""
    started = time.monotonic()
    with pytest.raises(BaseExceptionGroup) as info:  # from the motor's task: the component's
        with anyio.fail_after(10):  # a deadline does not count as something that may drive it
            async with Actuator(SimMotor(), clock=VirtualClock(stall_timeout=0.2)) as actuator:
                motion = await actuator.set_value(1.0)
                await motion
    assert time.monotonic() - started < 5
    assert info.group_contains(VirtualClockStalledError, match="nothing advances this clock")
    (error,) = info.value.exceptions
    assert isinstance(error, VirtualClockStalledError) and isinstance(error, StateError)
    assert error.code is ReturnCode.HAL_ERROR
    assert all(fix in str(error) for fix in FIX), str(error)


async def test_a_sleeper_in_the_calling_task_gets_the_error() -> None:
    clock = VirtualClock(stall_timeout=0.1)
    with anyio.fail_after(5):
        with pytest.raises(VirtualClockStalledError, match=r"1 task\(s\) sleep on it"):
            await clock.sleep(1.0)
        # The clock still works once driven.
        async with anyio.create_task_group() as tg:
            tg.start_soon(clock.sleep_until, 10)
            await clock.advance(10)
    assert clock.now_ns() == 10


async def test_a_clock_advanced_after_a_real_wait_does_not_fire() -> None:
    """Another task waits in real time (a timer), longer than stall_timeout, then advances."""
    clock = VirtualClock(stall_timeout=0.05)
    woken: list[int] = []

    async def driver() -> None:
        await anyio.sleep(0.3)
        await clock.advance(10)

    async def sleeper() -> None:
        await clock.sleep_until(10)
        woken.append(clock.now_ns())

    with anyio.fail_after(5):
        async with anyio.create_task_group() as tg:
            tg.start_soon(sleeper)
            tg.start_soon(driver)
    assert woken == [10]


async def test_a_clock_advanced_after_real_io_does_not_fire() -> None:
    """Another task waits for I/O (a socket a thread writes to later), then advances."""
    clock = VirtualClock(stall_timeout=0.05)
    ours, theirs = socket.socketpair()
    writer = threading.Timer(0.3, theirs.send, [b"x"])
    woken: list[int] = []

    async def driver() -> None:
        await anyio.wait_readable(ours)
        await clock.advance(10)

    async def sleeper() -> None:
        await clock.sleep_until(10)
        woken.append(clock.now_ns())

    try:
        writer.start()
        with anyio.fail_after(5):
            async with anyio.create_task_group() as tg:
                tg.start_soon(sleeper)
                tg.start_soon(driver)
    finally:
        writer.join()
        ours.close()
        theirs.close()
    assert woken == [10]


async def test_an_auto_jumping_clock_and_a_disabled_check_never_fire() -> None:
    clock = VirtualClock(stall_timeout=0.05)
    with anyio.fail_after(5):
        async with clock.autojump():
            await clock.sleep(3600)
    quiet = VirtualClock(stall_timeout=None)
    with anyio.move_on_after(0.3) as scope:
        await quiet.sleep(1.0)  # waits (bounded here), as before
    assert scope.cancelled_caught


def test_stall_timeout_is_checked() -> None:
    assert VirtualClock().stall_timeout == STALL_TIMEOUT_S == 5.0
    for bad in (0, -1.0, float("inf"), float("nan"), True, "1"):
        with pytest.raises(BadParameterError, match="stall_timeout"):
            VirtualClock(stall_timeout=bad)  # type: ignore[arg-type]
