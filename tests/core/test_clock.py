"""Clocks: VirtualClock ordering and time travel, MonotonicClock sleepers and timerfd."""

from __future__ import annotations

import os
import select
import time

import anyio
import anyio.lowlevel
import pytest

from openel_async import timerfd
from openel_async.clock import (
    NS_PER_MS,
    NS_PER_S,
    Clock,
    MonotonicClock,
    Sleeper,
    VirtualClock,
    default_clock,
)
from openel_async.errors import BadParameterError, ReturnCode

needs_timerfd = pytest.mark.skipif(not timerfd.available(), reason="timerfd needs Linux")


def _readable(fd: int) -> bool:
    """Whether ``fd`` is readable right now (a zero-timeout poll, no waiting)."""
    return bool(select.select([fd], [], [], 0)[0])


# -- VirtualClock: ordering ------------------------------------------------------------


async def test_wakes_in_deadline_order_ties_in_arrival_order() -> None:
    clock = VirtualClock()
    woken: list[tuple[str, int]] = []

    async def sleeper(name: str, deadline: int) -> None:
        await clock.sleep_until(deadline)
        woken.append((name, clock.now_ns()))

    async with anyio.create_task_group() as tg:
        for name, deadline in [
            ("c", 30),
            ("a", 10),
            ("b1", 20),
            ("e", 50),
            ("b2", 20),
            ("d", 40),
            ("b3", 20),
        ]:
            tg.start_soon(sleeper, name, deadline)
        await clock.advance_to(100)

    # Strict deadline order, ties (b1, b2, b3) in the order they started sleeping,
    # and the clock reads exactly the deadline when each sleeper runs.
    assert woken == [
        ("a", 10),
        ("b1", 20),
        ("b2", 20),
        ("b3", 20),
        ("c", 30),
        ("d", 40),
        ("e", 50),
    ]
    assert clock.now_ns() == 100
    # One jump per distinct deadline.
    assert clock.jumps == 5


async def test_time_seen_by_woken_sleeper_is_its_deadline_even_when_advancing_past() -> None:
    clock = VirtualClock(start_ns=1_000)
    seen: list[int] = []

    async def sleeper(deadline: int) -> None:
        await clock.sleep_until(deadline)
        seen.append(clock.now_ns())
        # A follow-up sleep inside the advanced window is woken in the same advance.
        await clock.sleep_until(deadline + 5)
        seen.append(clock.now_ns())

    async with anyio.create_task_group() as tg:
        tg.start_soon(sleeper, 1_500)
        tg.start_soon(sleeper, 1_502)
        await clock.advance(10_000)

    assert seen == [1_500, 1_502, 1_505, 1_507]
    assert clock.now_ns() == 11_000


async def test_sleep_until_now_or_past_returns_without_moving_time() -> None:
    clock = VirtualClock(start_ns=500)
    await clock.sleep_until(500)
    await clock.sleep_until(0)
    assert clock.now_ns() == 500
    assert clock.next_deadline() is None
    assert clock.jumps == 0


# -- VirtualClock: manual advance ---------------------------------------------------------


async def test_advance_wakes_only_due_sleepers() -> None:
    clock = VirtualClock()
    woken: list[int] = []

    async def sleeper(deadline: int) -> None:
        await clock.sleep_until(deadline)
        woken.append(clock.now_ns())

    async with anyio.create_task_group() as tg:
        for deadline in (10, 20, 30):
            tg.start_soon(sleeper, deadline)

        await clock.advance(15)
        assert woken == [10]
        assert clock.now_ns() == 15
        assert clock.next_deadline() == 20

        await clock.advance(0)  # settles, wakes nothing new
        assert woken == [10]
        assert clock.now_ns() == 15

        await clock.advance(5)  # a deadline equal to the target is due
        assert woken == [10, 20]
        assert clock.now_ns() == 20

        await clock.advance_to(29)
        assert woken == [10, 20]
        assert clock.now_ns() == 29

        await clock.advance_to(1_000)
        assert woken == [10, 20, 30]
        assert clock.now_ns() == 1_000
        assert clock.next_deadline() is None


async def test_advance_to_the_current_time_is_allowed() -> None:
    clock = VirtualClock(start_ns=7)
    await clock.advance_to(7)
    assert clock.now_ns() == 7


async def test_sleep_in_seconds_rounds_to_nanoseconds() -> None:
    clock = VirtualClock()
    async with anyio.create_task_group() as tg:
        tg.start_soon(clock.sleep, 0.25)
        await clock.advance(0)
        assert clock.next_deadline() == NS_PER_S // 4
        await clock.advance_to(NS_PER_S)


# -- VirtualClock: cancellation ----------------------------------------------------------


async def test_cancelled_sleepers_are_skipped_and_do_not_move_time() -> None:
    clock = VirtualClock()
    woken: list[str] = []

    async def sleeper(name: str, deadline: int) -> None:
        await clock.sleep_until(deadline)
        woken.append(name)

    async with anyio.create_task_group() as tg:
        early_scope = anyio.CancelScope()

        async def cancellable() -> None:
            with early_scope:
                await sleeper("early", 10)

        tg.start_soon(cancellable)
        tg.start_soon(sleeper, "late", 50)
        await clock.advance(0)  # both registered
        assert clock.next_deadline() == 10

        early_scope.cancel()
        await clock.advance(0)
        # The cancelled entry is gone: the next deadline is the live one.
        assert clock.next_deadline() == 50

        await clock.advance_to(20)
        assert woken == []
        assert clock.now_ns() == 20
        assert clock.jumps == 0  # nothing was woken at 10

        await clock.advance_to(50)
        assert woken == ["late"]


async def test_autojump_skips_cancelled_sleepers() -> None:
    clock = VirtualClock()
    times: list[int] = []
    scope = anyio.CancelScope()

    async def doomed() -> None:
        with scope:
            await clock.sleep_until(10 * NS_PER_MS)
        times.append(-1)  # reached only through cancellation

    async with anyio.create_task_group() as tg:
        tg.start_soon(doomed)
        await anyio.wait_all_tasks_blocked()
        scope.cancel()
        async with clock.autojump():
            await clock.sleep_until(50 * NS_PER_MS)
            times.append(clock.now_ns())

    assert times == [-1, 50 * NS_PER_MS]
    # One leap, straight to 50 ms: the cancelled 10 ms deadline never set the time.
    assert clock.jumps == 1


async def test_cancelling_one_of_several_tied_sleepers_wakes_the_others() -> None:
    clock = VirtualClock()
    woken: list[str] = []
    scopes = {name: anyio.CancelScope() for name in ("a", "b", "c")}

    async def sleeper(name: str) -> None:
        with scopes[name]:
            await clock.sleep_until(100)
            woken.append(name)

    async with anyio.create_task_group() as tg:
        for name in scopes:
            tg.start_soon(sleeper, name)
        await clock.advance(0)
        scopes["b"].cancel()
        await clock.advance_to(100)

    assert woken == ["a", "c"]


# -- VirtualClock: autojump --------------------------------------------------------------


async def test_autojump_leaps_to_each_deadline_when_idle() -> None:
    clock = VirtualClock()
    async with clock.autojump():
        await clock.sleep(10.0)
        assert clock.now_ns() == 10 * NS_PER_S
        await clock.sleep_until(clock.now_ns() + 1)
        assert clock.now_ns() == 10 * NS_PER_S + 1
    assert clock.jumps == 2


async def test_autojump_runs_many_sleepers_in_order() -> None:
    clock = VirtualClock()
    woken: list[tuple[int, int]] = []

    async def sleeper(i: int, deadline: int) -> None:
        await clock.sleep_until(deadline)
        woken.append((clock.now_ns(), i))

    deadlines = [(7 * i) % 23 * NS_PER_MS + NS_PER_MS for i in range(23)]
    async with clock.autojump(), anyio.create_task_group() as tg:
        for i, deadline in enumerate(deadlines):
            tg.start_soon(sleeper, i, deadline)

    assert [t for t, _ in woken] == sorted(deadlines)
    assert all(deadlines[i] == t for t, i in woken)


async def test_autojump_never_jumps_while_a_task_is_runnable() -> None:
    clock = VirtualClock()
    seen: list[int] = []

    async def busy() -> None:
        for _ in range(200):
            seen.append(clock.now_ns())
            await anyio.lowlevel.checkpoint()

    async with clock.autojump(), anyio.create_task_group() as tg:
        tg.start_soon(clock.sleep_until, 5 * NS_PER_S)
        tg.start_soon(busy)

    assert seen == [0] * 200
    assert clock.now_ns() == 5 * NS_PER_S


async def test_autojump_waits_for_a_sleeper_that_arrives_late() -> None:
    clock = VirtualClock()
    gate = anyio.Event()
    times: list[int] = []

    async def later() -> None:
        await gate.wait()
        await clock.sleep(2.0)
        times.append(clock.now_ns())

    async with clock.autojump(), anyio.create_task_group() as tg:
        tg.start_soon(later)
        await anyio.wait_all_tasks_blocked()  # the driver idles with no deadline
        assert clock.now_ns() == 0
        gate.set()

    assert times == [2 * NS_PER_S]


async def test_virtual_clock_fixture_is_autojumping(virtual_clock: VirtualClock) -> None:
    start = virtual_clock.now_ns()
    await virtual_clock.sleep(3600.0)
    assert virtual_clock.now_ns() == start + 3600 * NS_PER_S


# -- VirtualClock: argument checks --------------------------------------------------------


@pytest.mark.parametrize("start_ns", [-1, 1.5, "0", None, True])
def test_bad_start_ns(start_ns: object) -> None:
    with pytest.raises(BadParameterError) as info:
        VirtualClock(start_ns=start_ns)  # type: ignore[arg-type]
    assert info.value.parameter == "start_ns"
    assert "start_ns" in str(info.value)
    assert info.value.code is ReturnCode.HAL_BAD_PARAMETER


@pytest.mark.parametrize("delta_ns", [-1, 0.5, "1", None])
async def test_bad_advance(delta_ns: object) -> None:
    clock = VirtualClock()
    with pytest.raises(BadParameterError) as info:
        await clock.advance(delta_ns)  # type: ignore[arg-type]
    assert info.value.parameter == "delta_ns"
    assert "delta_ns" in str(info.value)
    assert clock.now_ns() == 0


@pytest.mark.parametrize("target_ns", [99, 100.5, "200", None])
async def test_bad_advance_to(target_ns: object) -> None:
    clock = VirtualClock(start_ns=100)
    with pytest.raises(BadParameterError) as info:
        await clock.advance_to(target_ns)  # type: ignore[arg-type]
    assert info.value.parameter == "target_ns"
    assert "target_ns" in str(info.value)
    assert clock.now_ns() == 100


def test_clocks_implement_the_protocols() -> None:
    virtual = VirtualClock()
    real = MonotonicClock()
    assert isinstance(virtual, Clock)
    assert isinstance(real, Clock)
    assert isinstance(virtual.sleeper(), Sleeper)
    sleeper = real.sleeper()
    try:
        assert isinstance(sleeper, Sleeper)
    finally:
        sleeper.close()
    assert isinstance(default_clock(), MonotonicClock)
    assert default_clock() is default_clock()


async def test_virtual_sleeper_sleeps_on_the_virtual_clock() -> None:
    clock = VirtualClock()
    sleeper = clock.sleeper()
    async with clock.autojump():
        for k in range(1, 4):
            await sleeper.sleep_until(k * NS_PER_MS)
            assert clock.now_ns() == k * NS_PER_MS
    sleeper.close()


# -- MonotonicClock ------------------------------------------------------------------------


def test_monotonic_clock_reads_clock_monotonic() -> None:
    clock = MonotonicClock()
    before = time.monotonic_ns()
    now = clock.now_ns()
    after = time.monotonic_ns()
    assert before <= now <= after


@needs_timerfd
async def test_timerfd_sleeper_never_wakes_before_its_deadline() -> None:
    clock = MonotonicClock()
    assert clock.use_timerfd
    sleeper = clock.sleeper()
    assert type(sleeper).__name__ == "_TimerfdSleeper"
    try:
        for step_us in (1, 50, 200, 500, 1000, 100, 10):
            deadline = clock.now_ns() + step_us * 1_000
            await sleeper.sleep_until(deadline)
            assert clock.now_ns() >= deadline
        # Absolute deadlines: a sequence on a grid, each waited for in turn.
        start = clock.now_ns()
        for k in range(1, 11):
            deadline = start + k * 300_000
            await sleeper.sleep_until(deadline)
            assert clock.now_ns() >= deadline
        # A deadline already past returns at once (a checkpoint).
        await sleeper.sleep_until(clock.now_ns() - NS_PER_S)
    finally:
        sleeper.close()
        sleeper.close()  # idempotent


@needs_timerfd
async def test_timerfd_sleeper_wait_is_cancellable_and_reusable() -> None:
    clock = MonotonicClock()
    sleeper = clock.sleeper()
    try:
        async with anyio.create_task_group() as tg:
            tg.start_soon(sleeper.sleep_until, clock.now_ns() + 3600 * NS_PER_S)
            await anyio.wait_all_tasks_blocked()
            tg.cancel_scope.cancel()
        # The far deadline left armed does not disturb the next, near one.
        deadline = clock.now_ns() + 200_000
        await sleeper.sleep_until(deadline)
        assert clock.now_ns() >= deadline
    finally:
        sleeper.close()


@needs_timerfd
async def test_timerfd_expiring_after_a_cancelled_wait_leaves_no_reader_behind() -> None:
    """The fd stays registered with the loop between waits; one that expires with nobody
    waiting (its wait cancelled) is unregistered, not left readable for every loop pass."""
    fd = timerfd.Timerfd()
    try:
        with anyio.move_on_after(0.001):
            await fd.wait_until(time.monotonic_ns() + 20_000_000)  # cancelled while armed
        for _ in range(500):  # bounded: at most ~5 s
            if not fd.registered:  # expired; the reader ran, found no waiter and left
                break
            await anyio.sleep(0.01)
        assert not fd.registered
        assert _readable(fd.fileno())  # the expiry nobody read
        deadline = time.monotonic_ns() + 300_000
        await fd.wait_until(deadline)  # registers again (re-arming clears the expiry)
        assert time.monotonic_ns() >= deadline
        assert fd.registered
    finally:
        fd.close()
        assert not fd.registered


async def test_fallback_sleeper_never_wakes_before_its_deadline() -> None:
    clock = MonotonicClock(use_timerfd=False)
    assert clock.use_timerfd is False
    sleeper = clock.sleeper()
    assert type(sleeper).__name__ == "DeadlineSleeper"
    try:
        for step_us in (1, 100, 700, 1500, 3):
            deadline = clock.now_ns() + step_us * 1_000
            await sleeper.sleep_until(deadline)
            assert clock.now_ns() >= deadline
        await sleeper.sleep_until(clock.now_ns() - NS_PER_S)  # past: returns at once
    finally:
        sleeper.close()


async def test_monotonic_sleep_until_never_wakes_early() -> None:
    clock = MonotonicClock(use_timerfd=False)
    for step_us in (10, 1100, 2):
        deadline = clock.now_ns() + step_us * 1_000
        await clock.sleep_until(deadline)
        assert clock.now_ns() >= deadline


def test_sleeper_falls_back_when_timerfd_is_unavailable(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(timerfd, "_libc", None)
    assert timerfd.available() is False
    with pytest.raises(OSError):
        timerfd.Timerfd()
    clock = MonotonicClock()
    assert clock.use_timerfd is False
    assert type(clock.sleeper()).__name__ == "DeadlineSleeper"
    assert "use_timerfd=False" in repr(clock)


@needs_timerfd
def test_sleeper_falls_back_when_timerfd_cannot_be_created(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    clock = MonotonicClock()
    assert clock.use_timerfd

    def refuse() -> None:
        raise OSError(24, "Too many open files")

    monkeypatch.setattr(timerfd, "Timerfd", refuse)
    assert type(clock.sleeper()).__name__ == "DeadlineSleeper"


# -- the timerfd binding ----------------------------------------------------------------------


@needs_timerfd
def test_timerfd_arm_fire_rearm_and_close() -> None:
    fd = timerfd.Timerfd()
    try:
        number = fd.fileno()
        assert number >= 0
        assert not _readable(number)  # a new timerfd is disarmed

        fd.arm_absolute(time.monotonic_ns() + 3600 * NS_PER_S)
        assert not _readable(number)  # far in the future: not expired

        fd.arm_absolute(time.monotonic_ns() - NS_PER_MS)  # already past: expires at once
        assert _readable(number)
        count = int.from_bytes(os.read(number, 8), "little")
        assert count == 1
        assert not _readable(number)  # reading consumed the expiration

        # Re-arming discards an expiration that was never read (a cancelled wait).
        fd.arm_absolute(time.monotonic_ns() - NS_PER_MS)
        assert _readable(number)
        fd.arm_absolute(time.monotonic_ns() + 3600 * NS_PER_S)
        assert not _readable(number)

        fd.arm_absolute(0)  # deadline 0 is clamped to 1 ns: long past
        assert _readable(number)
    finally:
        fd.close()
    with pytest.raises(ValueError, match="closed"):
        fd.fileno()
    with pytest.raises(ValueError, match="closed"):
        fd.arm_absolute(time.monotonic_ns())
    fd.close()  # idempotent


@needs_timerfd
async def test_timerfd_wait_until_past_and_future() -> None:
    fd = timerfd.Timerfd()
    try:
        await fd.wait_until(time.monotonic_ns() - NS_PER_S)
        deadline = time.monotonic_ns() + 250_000
        await fd.wait_until(deadline)
        assert time.monotonic_ns() >= deadline
    finally:
        fd.close()


# -- elapsed_s: seconds since the start or since a reading ------------------------------


async def test_elapsed_s_on_a_virtual_clock_counts_simulated_seconds() -> None:
    clock = VirtualClock(start_ns=2 * NS_PER_S)
    assert clock.start_ns == 2 * NS_PER_S and clock.elapsed_s() == 0.0
    async with anyio.create_task_group() as tg:
        tg.start_soon(clock.sleep, 1.5)
        await clock.advance(1_500 * NS_PER_MS)
    mark = clock.now_ns()
    assert clock.elapsed_s() == 1.5  # since the start
    await clock.advance(250 * NS_PER_MS)
    assert clock.elapsed_s(mark) == 0.25 and clock.elapsed_s() == 1.75
    for bad in (1.0, True, "0"):
        with pytest.raises(BadParameterError, match="since_ns"):
            clock.elapsed_s(bad)  # type: ignore[arg-type]


async def test_elapsed_s_on_the_monotonic_clock_counts_real_seconds() -> None:
    before = time.monotonic_ns()
    clock = MonotonicClock()
    after = time.monotonic_ns()
    assert before <= clock.start_ns <= after  # now_ns() is time.monotonic_ns()
    mark = clock.now_ns()
    await clock.sleep_until(mark + 20 * NS_PER_MS)
    assert 0.02 <= clock.elapsed_s(mark) < 5.0
    since_mark = clock.elapsed_s(mark)
    assert clock.elapsed_s() >= since_mark  # read later, from an earlier start
    assert default_clock().elapsed_s() > 0.0  # since openel_async was imported


@pytest.mark.skipif(not timerfd.available(), reason="timerfd is Linux's")
async def test_monotonic_sleep_until_waits_a_short_wait_on_a_timerfd(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """asyncio's selector rounds a timeout up to a whole millisecond: a wait shorter than
    PRECISE_BELOW_NS takes a timerfd of its own (closed after), a longer one does not."""
    from openel_async.clock import PRECISE_BELOW_NS, MonotonicClock

    made: list[timerfd.Timerfd] = []
    real = timerfd.Timerfd

    def counted() -> timerfd.Timerfd:
        fd = real()
        made.append(fd)
        return fd

    monkeypatch.setattr(timerfd, "Timerfd", counted)
    clock = MonotonicClock()
    start = time.monotonic_ns()
    await clock.sleep_until(start + 200_000)  # 200 us
    assert time.monotonic_ns() >= start + 200_000
    assert len(made) == 1 and not made[0].registered
    with pytest.raises(ValueError, match="closed"):
        made[0].fileno()
    await clock.sleep_until(time.monotonic_ns() + PRECISE_BELOW_NS + 1_000_000)
    assert len(made) == 1  # anyio.sleep
    assert MonotonicClock(use_timerfd=False).use_timerfd is False
