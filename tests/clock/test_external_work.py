"""Work in flight outside the event loop keeps virtual and lockstep time still.

A task that awaits a worker thread leaves the loop with nothing runnable, which the idle
detector (``openel_async.clock.wait_idle``) took for idle: an auto-jumping VirtualClock
jumped and a lockstep simulation stepped physics at full speed for as long as the thread
ran. ``external_work()``/``run_in_thread()`` tell the detector; the first tests show the
hazard with a bare ``anyio.to_thread.run_sync`` (the thread is released only once
simulated time has passed), the others that a hold stops it.

Every wait is bounded: real time by ``anyio.fail_after``, the threads' own waits by a
timeout; the held cases wait ``HOLD_S`` real seconds for a release that must not come.
"""

from __future__ import annotations

import threading

import anyio
import pytest
from structlog.testing import capture_logs

import openel_async.clock as clock_module
from openel_async import BadParameterError, StateError, VirtualClock
from openel_async.clock import (
    ExternalWork,
    external_work,
    external_work_in_flight,
    run_in_thread,
    wait_idle,
)

HOLD_S = 0.1
"""Real seconds a thread waits, in the held cases, for a tick that must not come."""

TICKS = 10


async def _ticker(clock: VirtualClock, ticked: threading.Event, log: list[int]) -> None:
    """TICKS sleeps of 1 ms on ``clock``, then set ``ticked`` (seen by a worker thread)."""
    for _ in range(TICKS):
        await clock.sleep(0.001)
        log.append(clock.now_ns())
    ticked.set()


# -- the hazard ------------------------------------------------------------------------------
async def test_bare_worker_thread_lets_virtual_time_pass(virtual_clock: VirtualClock) -> None:
    """Without a hold, the clock jumps while the task waits for its thread: the thread sees
    the ticks happen (documents why run_in_thread exists)."""
    ticked = threading.Event()
    log: list[int] = []
    with anyio.fail_after(10):
        async with anyio.create_task_group() as tg:
            tg.start_soon(_ticker, virtual_clock, ticked, log)
            await anyio.lowlevel.checkpoint()
            before = virtual_clock.now_ns()
            seen = await anyio.to_thread.run_sync(ticked.wait, 5.0)
    assert seen and before == 0
    assert virtual_clock.now_ns() == TICKS * 1_000_000 and len(log) == TICKS


# -- the fix: VirtualClock -------------------------------------------------------------------
async def test_run_in_thread_keeps_virtual_time_still(virtual_clock: VirtualClock) -> None:
    ticked = threading.Event()
    log: list[int] = []
    with anyio.fail_after(10):
        async with anyio.create_task_group() as tg:
            tg.start_soon(_ticker, virtual_clock, ticked, log)
            await anyio.lowlevel.checkpoint()
            seen = await run_in_thread(ticked.wait, HOLD_S)
            assert not seen  # no tick during the call
            assert virtual_clock.now_ns() == 0 and log == []
            assert external_work_in_flight() == 0
    # released: time moves again, the ticks come in order
    assert log == [k * 1_000_000 for k in range(1, TICKS + 1)]


async def test_run_in_thread_returns_the_result_and_raises_the_error(
    virtual_clock: VirtualClock,
) -> None:
    with anyio.fail_after(10):
        assert await run_in_thread(divmod, 7, 2) == (3, 1)
        with pytest.raises(ZeroDivisionError):
            await run_in_thread(divmod, 1, 0)
        assert external_work_in_flight() == 0


async def test_sync_and_async_holds_nest_and_count(virtual_clock: VirtualClock) -> None:
    work = external_work("nested")
    with anyio.fail_after(10):
        async with work:
            assert external_work_in_flight() == 1
            with work, external_work("other") as other:  # re-entered, and a second hold
                assert isinstance(other, ExternalWork)
                assert external_work_in_flight() == 3
            assert external_work_in_flight() == 1
            ticked = threading.Event()
            async with anyio.create_task_group() as tg:
                tg.start_soon(_ticker, virtual_clock, ticked, [])
                assert not await anyio.to_thread.run_sync(ticked.wait, HOLD_S)
                assert virtual_clock.now_ns() == 0
                tg.cancel_scope.cancel()
        assert external_work_in_flight() == 0


async def test_hold_ends_on_exception_and_on_cancellation(virtual_clock: VirtualClock) -> None:
    with anyio.fail_after(10):
        with pytest.raises(RuntimeError), external_work("failing"):
            raise RuntimeError("boom")
        assert external_work_in_flight() == 0

        gate = threading.Event()  # never set: the abandoned thread ends at its own timeout
        with anyio.move_on_after(HOLD_S) as scope:
            await run_in_thread(gate.wait, 5.0, abandon_on_cancel=True)
        assert scope.cancelled_caught
        assert external_work_in_flight() == 0
        gate.set()
        # and time moves again
        await virtual_clock.sleep(1.0)
        assert virtual_clock.now_ns() == 1_000_000_000


async def test_manual_advance_waits_for_external_work() -> None:
    clock = VirtualClock()
    ticked = threading.Event()
    log: list[int] = []
    advanced = anyio.Event()

    async def advance() -> None:
        await clock.advance(5_000_000)
        advanced.set()

    with anyio.fail_after(10):
        async with anyio.create_task_group() as tg:
            tg.start_soon(_ticker, clock, ticked, log)
            with external_work("slow"):
                tg.start_soon(advance)
                assert not await anyio.to_thread.run_sync(ticked.wait, HOLD_S)
                assert clock.now_ns() == 0 and log == []
            await advanced.wait()  # the hold ended: the advance completes
            assert clock.now_ns() == 5_000_000 and len(log) == 5
            await clock.advance(5_000_000)
    assert ticked.is_set()


async def test_tasks_keep_running_while_time_is_held(virtual_clock: VirtualClock) -> None:
    """A thread that needs the loop (from_thread) gets it: only time stands still."""

    def ask_the_loop() -> int:
        return anyio.from_thread.run_sync(virtual_clock.now_ns)

    with anyio.fail_after(10):
        assert await run_in_thread(ask_the_loop) == 0


async def test_wait_idle_returns_once_the_work_ends(virtual_clock: VirtualClock) -> None:
    order: list[str] = []

    async def idle() -> None:
        await wait_idle()
        order.append("idle")

    with anyio.fail_after(10):
        async with anyio.create_task_group() as tg:
            with external_work("brief"):
                tg.start_soon(idle)
                await anyio.to_thread.run_sync(threading.Event().wait, HOLD_S)
                order.append("released")
    assert order == ["released", "idle"]


def test_external_work_refuses_bad_names_and_unbalanced_exit() -> None:
    with pytest.raises(BadParameterError, match="what"):
        external_work("")
    with pytest.raises(StateError):
        external_work("never entered").__exit__(None, None, None)


def test_external_work_needs_a_running_loop() -> None:
    with pytest.raises(RuntimeError), external_work("outside a loop"):
        pass


async def test_a_long_hold_is_named_in_a_warning(
    virtual_clock: VirtualClock, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(clock_module, "EXTERNAL_WORK_WARNING_S", HOLD_S / 4)
    ticked = threading.Event()
    with anyio.fail_after(10), capture_logs() as logs:
        async with anyio.create_task_group() as tg:
            tg.start_soon(_ticker, virtual_clock, ticked, [])
            await anyio.lowlevel.checkpoint()
            assert not await run_in_thread(ticked.wait, HOLD_S)
    warnings = [e for e in logs if e["event"] == "clock_waits_for_external_work"]
    assert len(warnings) == 1  # once per wait
    assert warnings[0]["in_flight"] == {"thread: Event.wait": 1}
