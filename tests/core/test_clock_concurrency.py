"""VirtualClock with company: several clocks, drivers and advance calls in one event loop.

Every wait here is bounded by ``anyio.fail_after`` on real time: a regression to the old
busy settle loop (each waiter's yield kept the other runnable) fails instead of hanging.
"""

from __future__ import annotations

import asyncio
import gc
import weakref

import anyio
import anyio.lowlevel
import pytest

from openel_async.clock import VirtualClock, wait_idle
from openel_async.errors import StateError

BOUND_S = 5  # real seconds; every test below takes milliseconds when correct


async def _ticker(
    name: str, clock: VirtualClock, period_ns: int, count: int, log: list[tuple[str, int]]
) -> None:
    for _ in range(count):
        await clock.sleep_until(clock.now_ns() + period_ns)
        log.append((name, clock.now_ns()))


# -- several auto-jump clocks in one loop --------------------------------------------------


async def test_fixture_clock_and_a_rig_clock_both_autojump(virtual_clock: VirtualClock) -> None:
    rig = VirtualClock()
    log: list[tuple[str, int]] = []
    with anyio.fail_after(BOUND_S):
        async with rig.autojump(), anyio.create_task_group() as tg:
            tg.start_soon(_ticker, "fixture", virtual_clock, 10, 4, log)
            tg.start_soon(_ticker, "rig", rig, 15, 3, log)
    assert [t for n, t in log if n == "fixture"] == [10, 20, 30, 40]
    assert [t for n, t in log if n == "rig"] == [15, 30, 45]
    assert virtual_clock.jumps == 4 and rig.jumps == 3


async def test_two_autojump_clocks_take_turns_deterministically() -> None:
    async def run() -> list[tuple[str, int]]:
        a, b = VirtualClock(), VirtualClock()
        log: list[tuple[str, int]] = []
        with anyio.fail_after(BOUND_S):
            async with a.autojump(), b.autojump(), anyio.create_task_group() as tg:
                tg.start_soon(_ticker, "a", a, 10, 4, log)
                tg.start_soon(_ticker, "b", b, 15, 3, log)
        return log

    first = await run()
    # Each idle moment goes to one clock, in turn: one jump of a, one of b, ...
    assert first == [
        ("a", 10),
        ("b", 15),
        ("a", 20),
        ("b", 30),
        ("a", 30),
        ("b", 45),
        ("a", 40),
    ]
    assert await run() == first


async def test_a_clock_with_an_endless_timer_does_not_starve_another() -> None:
    busy, other = VirtualClock(), VirtualClock()
    log: list[tuple[str, int]] = []
    with anyio.fail_after(BOUND_S):
        async with busy.autojump(), other.autojump(), anyio.create_task_group() as tg:
            tg.start_soon(_ticker, "busy", busy, 1, 10**9, log)  # never ends by itself
            await _ticker("other", other, 1_000, 5, log)
            tg.cancel_scope.cancel()
    assert [t for n, t in log if n == "other"] == [1_000, 2_000, 3_000, 4_000, 5_000]
    # Turns alternate: the busy clock jumped about as often as the other one.
    assert 5 <= busy.jumps <= 7


async def test_idle_autojump_clocks_leave_the_loop_idle() -> None:
    """With no deadline on either clock nothing polls: the loop sleeps in its selector."""
    a, b = VirtualClock(), VirtualClock()
    loop = asyncio.get_running_loop()
    ready_seen: list[int] = []
    woke = anyio.Event()

    def probe() -> None:
        ready_seen.append(len(loop._ready))  # type: ignore[attr-defined]
        woke.set()

    with anyio.fail_after(BOUND_S):
        async with a.autojump(), b.autojump():
            await a.sleep(1)  # both drivers have run and now wait for a sleeper
            await b.sleep(1)
            loop.call_later(0.02, probe)
            await woke.wait()
    assert ready_seen == [0]


# -- advance: refused under auto-jump, safe when concurrent -------------------------------


async def test_advance_under_autojump_is_refused() -> None:
    clock = VirtualClock()
    with anyio.fail_after(BOUND_S):
        async with clock.autojump():
            await clock.sleep(1)
            before = (clock.now_ns(), clock.jumps)
            with pytest.raises(StateError, match=r"advance\(\) is not callable in state auto-jump"):
                await clock.advance(10)
            with pytest.raises(StateError, match=r"advance_to\(\)"):
                await clock.advance_to(clock.now_ns() + 10)
            assert (clock.now_ns(), clock.jumps) == before
            assert clock.autojumping
    assert not clock.autojumping
    await clock.advance(10)  # manual mode again after the block
    assert clock.now_ns() == before[0] + 10


async def test_advance_on_the_fixture_clock_is_refused(virtual_clock: VirtualClock) -> None:
    with anyio.fail_after(BOUND_S), pytest.raises(StateError, match="auto-jump"):
        await virtual_clock.advance(1)


async def test_second_autojump_on_one_clock_is_refused() -> None:
    clock = VirtualClock()
    with anyio.fail_after(BOUND_S):
        async with clock.autojump():
            with pytest.raises(StateError, match=r"autojump\(\)"):
                async with clock.autojump():
                    pass  # pragma: no cover - refused before the block
            with pytest.raises(StateError, match=r"run_autojump\(\)"):
                await clock.run_autojump()
            await clock.sleep(1)  # the first driver still works
    assert clock.now_ns() == 10**9


async def test_autojump_while_advancing_is_refused() -> None:
    clock = VirtualClock()
    refused: list[StateError] = []

    async def sleeper() -> None:
        await clock.sleep_until(10)
        try:
            async with clock.autojump():
                pass  # pragma: no cover - refused
        except StateError as exc:
            refused.append(exc)

    with anyio.fail_after(BOUND_S):
        async with anyio.create_task_group() as tg:
            tg.start_soon(sleeper)
            await clock.advance(20)
    assert len(refused) == 1 and "advancing" in str(refused[0])
    assert not clock.autojumping and clock.now_ns() == 20


async def test_concurrent_advances_of_two_clocks() -> None:
    a, b = VirtualClock(), VirtualClock()
    log: list[tuple[str, int]] = []

    async def sleeper(name: str, clock: VirtualClock, deadline: int) -> None:
        await clock.sleep_until(deadline)
        log.append((name, clock.now_ns()))

    with anyio.fail_after(BOUND_S):
        async with anyio.create_task_group() as tg:
            for deadline in (5, 15, 25):
                tg.start_soon(sleeper, "a", a, deadline)
                tg.start_soon(sleeper, "b", b, deadline + 1)
            await wait_idle()  # every sleeper registered
            async with anyio.create_task_group() as advancers:
                advancers.start_soon(a.advance, 30)
                advancers.start_soon(b.advance, 30)
    assert [t for n, t in log if n == "a"] == [5, 15, 25]
    assert [t for n, t in log if n == "b"] == [6, 16, 26]
    assert a.now_ns() == b.now_ns() == 30


async def test_concurrent_advances_of_one_clock_run_in_call_order() -> None:
    clock = VirtualClock()
    woken: list[int] = []

    async def sleeper(deadline: int) -> None:
        await clock.sleep_until(deadline)
        woken.append(clock.now_ns())

    with anyio.fail_after(BOUND_S):
        async with anyio.create_task_group() as tg:
            for deadline in (5, 15, 25):
                tg.start_soon(sleeper, deadline)
            await wait_idle()
            async with anyio.create_task_group() as advancers:
                advancers.start_soon(clock.advance, 10)  # 0 -> 10
                advancers.start_soon(clock.advance, 10)  # then 10 -> 20
                advancers.start_soon(clock.advance_to, 12)  # already passed: no move back
            assert woken == [5, 15] and clock.now_ns() == 20
            await clock.advance_to(25)
    assert woken == [5, 15, 25]


async def test_manual_clock_advances_beside_an_autojump_clock() -> None:
    auto, manual = VirtualClock(), VirtualClock()
    log: list[tuple[str, int]] = []
    with anyio.fail_after(BOUND_S):
        async with auto.autojump(), anyio.create_task_group() as tg:
            tg.start_soon(_ticker, "auto", auto, 1, 10**9, log)  # endless
            tg.start_soon(_ticker, "manual", manual, 7, 3, log)
            await manual.advance(21)
            tg.cancel_scope.cancel()
    assert [t for n, t in log if n == "manual"] == [7, 14, 21]
    assert auto.jumps >= 1


# -- wait_idle -----------------------------------------------------------------------------


async def test_wait_idle_waits_for_runnable_tasks_and_serves_callers_in_order() -> None:
    order: list[str] = []

    async def busy(steps: int) -> None:
        for _ in range(steps):
            await anyio.lowlevel.checkpoint()
        order.append("busy done")

    async def waiter(name: str) -> None:
        await wait_idle()
        order.append(name)

    with anyio.fail_after(BOUND_S):
        async with anyio.create_task_group() as tg:
            tg.start_soon(busy, 50)
            for name in ("w1", "w2", "w3"):
                tg.start_soon(waiter, name)
    assert order == ["busy done", "w1", "w2", "w3"]


async def test_a_cancelled_wait_idle_passes_its_turn_on() -> None:
    order: list[str] = []
    scopes: dict[str, anyio.CancelScope] = {}

    async def waiter(name: str) -> None:
        with anyio.CancelScope() as scope:
            scopes[name] = scope
            await wait_idle()
            order.append(name)

    async def busy() -> None:
        for step in range(20):
            if step == 5:
                scopes["w1"].cancel()  # the head of the queue, polling right now
                scopes["w2"].cancel()  # queued behind it
            await anyio.lowlevel.checkpoint()

    with anyio.fail_after(BOUND_S):
        async with anyio.create_task_group() as tg:
            for name in ("w1", "w2", "w3"):
                tg.start_soon(waiter, name)
            tg.start_soon(busy)
    assert order == ["w3"]


def test_the_idle_detector_does_not_keep_its_loop_alive() -> None:
    async def main() -> None:
        clock = VirtualClock()
        async with clock.autojump():
            await clock.sleep(1)
        await wait_idle()

    loop = asyncio.new_event_loop()
    try:
        loop.run_until_complete(main())
    finally:
        loop.close()
    ref = weakref.ref(loop)
    del loop
    gc.collect()
    assert ref() is None
