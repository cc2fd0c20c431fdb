"""The drivers' bounded worker-thread calls keep simulated time still.

Each driver call site is slowed down by a blocking call that waits, on its worker thread, for
ticks of an auto-jumping VirtualClock (``HOLD_S`` real seconds at most): under
``run_in_thread`` no tick comes; with the bare ``anyio.to_thread.run_sync`` they used before,
the clock jumped while the thread waited and the ticks released it at once.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable
from typing import Any

import anyio
import can
import pytest
import serial
import zenoh

from openel_async import VirtualClock
from openel_can import CanBus
from openel_serial.link import SerialLink
from openel_zenoh.client import close_session, open_session

HOLD_S = 0.1


class Ticks:
    """Ten 1 ms sleeps on the clock; ``wait()`` (on a worker thread) for them, HOLD_S at most."""

    def __init__(self, clock: VirtualClock) -> None:
        self.clock = clock
        self.done = threading.Event()
        self.waits: list[bool] = []  # what each wait() saw

    async def run(self) -> None:
        for _ in range(10):
            await self.clock.sleep(0.001)
        self.done.set()

    def wait(self) -> None:
        self.waits.append(self.done.wait(HOLD_S))

    def slowed(self, func: Callable[..., Any]) -> Callable[..., Any]:
        def call(*args: Any, **kwargs: Any) -> Any:
            self.wait()
            return func(*args, **kwargs)

        return call


async def _with_ticks(clock: VirtualClock, body: Callable[[Ticks], Any]) -> Ticks:
    ticks = Ticks(clock)
    with anyio.fail_after(20):
        async with anyio.create_task_group() as tg:
            tg.start_soon(ticks.run)
            await anyio.lowlevel.checkpoint()
            await body(ticks)
            tg.cancel_scope.cancel()
    return ticks


async def test_can_bus_open_and_shutdown_hold_the_clock(virtual_clock: VirtualClock) -> None:
    channel = f"hold-{os.getpid()}"

    async def body(ticks: Ticks) -> None:
        def factory() -> can.BusABC:
            ticks.wait()
            bus = can.Bus(interface="virtual", channel=channel)
            bus.shutdown = ticks.slowed(bus.shutdown)  # type: ignore[method-assign]
            return bus

        async with CanBus(bus_factory=factory, name="held"):
            assert virtual_clock.now_ns() == 0

    ticks = await _with_ticks(virtual_clock, body)
    assert ticks.waits == [False, False]  # opened and shut down with no tick meanwhile
    assert virtual_clock.now_ns() == 0


async def test_serial_open_holds_the_clock(
    virtual_clock: VirtualClock, monkeypatch: pytest.MonkeyPatch
) -> None:
    async def body(ticks: Ticks) -> None:
        monkeypatch.setattr(serial, "serial_for_url", ticks.slowed(serial.serial_for_url))
        link = SerialLink("loop://", baudrate=115200, on_data=lambda _: None, on_lost=print)
        await link.open()
        try:
            assert virtual_clock.now_ns() == 0
        finally:
            await link.close()

    ticks = await _with_ticks(virtual_clock, body)
    assert ticks.waits == [False]


async def test_zenoh_session_open_and_close_hold_the_clock(
    virtual_clock: VirtualClock, monkeypatch: pytest.MonkeyPatch
) -> None:
    class FakeSession:
        def __init__(self, ticks: Ticks) -> None:
            self.close = ticks.slowed(lambda: None)

    async def body(ticks: Ticks) -> None:
        monkeypatch.setattr(zenoh, "open", ticks.slowed(lambda config: FakeSession(ticks)))
        session = await open_session(zenoh.Config())
        assert virtual_clock.now_ns() == 0
        await close_session(session)

    ticks = await _with_ticks(virtual_clock, body)
    assert ticks.waits == [False, False]
    assert virtual_clock.now_ns() == 0
