"""Wakeup: a reusable wake-up (no anyio.Event per wait) that keeps the Event's semantics
where its users rely on them: set() wakes every waiter, a set() with no waiter makes the
next wait return, cancellation leaves the line without losing the other waiters."""

from __future__ import annotations

import anyio
import anyio.lowlevel
import pytest

from openel_async.wakeup import Wakeup


async def test_set_wakes_the_waiter_and_the_wakeup_is_reused() -> None:
    wakeup = Wakeup()
    woken: list[int] = []

    async def waiter() -> None:
        for i in range(3):
            await wakeup.wait()
            woken.append(i)

    with anyio.fail_after(5):
        async with anyio.create_task_group() as tg:
            tg.start_soon(waiter)
            for i in range(3):
                while not wakeup.waiting:
                    await anyio.lowlevel.checkpoint()
                wakeup.set()
                while len(woken) <= i:
                    await anyio.lowlevel.checkpoint()
    assert woken == [0, 1, 2]
    assert not wakeup.waiting and not wakeup.is_set()


async def test_a_set_without_waiter_is_kept_for_the_next_wait() -> None:
    wakeup = Wakeup()
    wakeup.set()
    assert wakeup.is_set()
    with anyio.fail_after(5):
        await wakeup.wait()  # returns at once
    assert not wakeup.is_set()
    wakeup.set()
    wakeup.clear()
    with anyio.move_on_after(0.01) as scope:
        await wakeup.wait()
    assert scope.cancelled_caught


async def test_every_waiter_is_woken_and_a_cancelled_one_leaves_the_line() -> None:
    wakeup = Wakeup()
    woken: list[str] = []

    async def waiter(name: str) -> None:
        await wakeup.wait()
        woken.append(name)

    with anyio.fail_after(5):
        async with anyio.create_task_group() as tg:
            tg.start_soon(waiter, "a")
            tg.start_soon(waiter, "b")
            scope_b = anyio.CancelScope()

            async def cancellable() -> None:
                with scope_b:
                    await waiter("c")

            tg.start_soon(cancellable)
            tg.start_soon(waiter, "d")
            for _ in range(5):
                await anyio.lowlevel.checkpoint()
            scope_b.cancel()  # "c" leaves; the first waiter's place passes on if needed
            for _ in range(5):
                await anyio.lowlevel.checkpoint()
            assert wakeup.waiting
            wakeup.set()
    assert sorted(woken) == ["a", "b", "d"]
    assert not wakeup.waiting


async def test_the_first_waiter_cancelled_passes_its_place_on() -> None:
    wakeup = Wakeup()
    woken: list[str] = []
    first = anyio.CancelScope()

    async def waiter(name: str, scope: anyio.CancelScope | None = None) -> None:
        if scope is None:
            await wakeup.wait()
        else:
            with scope:
                await wakeup.wait()
            if scope.cancelled_caught:
                return
        woken.append(name)

    with anyio.fail_after(5):
        async with anyio.create_task_group() as tg:
            tg.start_soon(waiter, "first", first)
            await anyio.lowlevel.checkpoint()
            tg.start_soon(waiter, "second")
            await anyio.lowlevel.checkpoint()
            first.cancel()
            for _ in range(3):
                await anyio.lowlevel.checkpoint()
            assert wakeup.waiting  # the second is the first in line now
            wakeup.set()
    assert woken == ["second"]
    with pytest.raises(TimeoutError):
        with anyio.fail_after(0.01):
            await wakeup.wait()


async def test_arm_and_disarm_are_wait_in_two_steps() -> None:
    wakeup = Wakeup()
    wakeup.set()
    first = wakeup.arm()  # clears the flag: only the next set() resolves it
    second = wakeup.arm()
    assert not wakeup.is_set() and wakeup.waiter is first
    wakeup.disarm(first)  # its await was cancelled: the second is first in line
    assert wakeup.waiter is second
    wakeup.set()
    with anyio.fail_after(5):
        await second
    assert not first.done() and not wakeup.waiting
    first.cancel()


async def test_a_cancelled_queue_consumer_leaves_no_waiter_behind() -> None:
    from openel_async import ObserverQueue

    queue: ObserverQueue = ObserverQueue(4)
    with anyio.move_on_after(0.01):
        async for _ in queue:
            pass
    assert not queue._wakeup.waiting
