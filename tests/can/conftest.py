"""Fixtures of the CAN tests: a fresh virtual channel, simulated peers, a host CanBus.

Everything runs in real time on python-can's ``virtual`` interface. Peers and the host
use short poll intervals and fast cyclic rates where that does not weaken a test; every
wait is bounded (``anyio.fail_after`` or a bounded helper).
"""

from __future__ import annotations

import uuid
from collections.abc import AsyncIterator, Awaitable, Callable, Iterator
from contextlib import AsyncExitStack, asynccontextmanager, contextmanager
from typing import Any, TypeVar

import anyio
import anyio.abc
import anyio.to_thread
import can
import canopen
import pytest

from openel_async import Actuator, HALComponent, Sensor
from openel_async.clock import default_clock
from openel_async.testing import EventRecorder
from openel_can import CanBus

C = TypeVar("C", bound=HALComponent)


@pytest.fixture
def channel() -> str:
    return f"test-{uuid.uuid4().hex}"


class Peers:
    """Simulated peers running for the test (each on its own bus on the channel)."""

    def __init__(self, tg: anyio.abc.TaskGroup, channel: str) -> None:
        self.tg = tg
        self.channel = channel

    async def start(self, peer: Any) -> Any:
        await self.tg.start(peer.serve, self.channel)
        return peer


@pytest.fixture
async def peers(channel: str) -> AsyncIterator[Peers]:
    async with anyio.create_task_group() as tg:
        yield Peers(tg, channel)
        tg.cancel_scope.cancel()


@pytest.fixture
async def host_bus(peers: Peers, channel: str) -> AsyncIterator[CanBus]:
    async with CanBus(interface="virtual", channel=channel, poll_interval=0.01, name="host") as bus:
        yield bus


class Components:
    """Enters components on the real clock with a recorder observing them."""

    def __init__(self, stack: AsyncExitStack, recorder: EventRecorder) -> None:
        self._stack = stack
        self.recorder = recorder

    async def enter(self, component: C) -> C:
        await self._stack.enter_async_context(component)
        component.add_observer(self.recorder)
        return component

    async def actuator(self, device: Any, **kwargs: Any) -> Actuator:
        return await self.enter(Actuator(device, **kwargs))

    async def sensor(self, device: Any, **kwargs: Any) -> Sensor:
        return await self.enter(Sensor(device, **kwargs))


@pytest.fixture
def recorder() -> EventRecorder:
    return EventRecorder(default_clock())


@pytest.fixture
async def components(host_bus: CanBus, recorder: EventRecorder) -> AsyncIterator[Components]:
    async with AsyncExitStack() as stack:
        yield Components(stack, recorder)


@pytest.fixture
def raw_bus(channel: str) -> Iterator[can.BusABC]:
    """A plain python-can bus on the channel: to inject frames or capture what is sent."""
    bus = can.Bus(interface="virtual", channel=channel)
    try:
        yield bus
    finally:
        bus.shutdown()


def drain(bus: can.BusABC) -> list[can.Message]:
    """Every frame queued on a raw bus (non-blocking)."""
    frames = []
    while (msg := bus.recv(0.0)) is not None:
        frames.append(msg)
    return frames


async def wait_until(predicate: Callable[[], bool], timeout: float = 2.0) -> None:  # noqa: ASYNC109
    """Poll a condition every millisecond, bounded (for states with no event to await)."""
    with anyio.fail_after(timeout):
        while not predicate():  # noqa: ASYNC110 - the condition has no event to wait on
            await anyio.sleep(0.001)


@contextmanager
def canopen_network(**connect: Any) -> Iterator[canopen.Network]:
    """A canopen-py network connected with python-can's ``connect`` arguments; at exit its
    SYNC stopped and the network disconnected at once (its notifier's receive timeout, which
    ``disconnect`` waits out, is 50 ms instead of 1 s)."""
    net = canopen.Network()
    net.NOTIFIER_CYCLE = 0.05
    net.connect(**connect)
    try:
        yield net
    finally:
        net.sync.stop()
        net.disconnect()


@asynccontextmanager
async def slcan_host_bus(port: str) -> AsyncIterator[CanBus]:
    """Our host's CanBus through python-can's ``slcan`` interface on ``port`` (a simulated
    adapter's pty), at 1 Mbit/s, without python-can's 2 s wait after opening."""
    async with CanBus(
        interface="slcan",
        channel=port,
        bitrate=1_000_000,
        sleep_after_open=0,
        poll_interval=0.01,
        name="host-slcan",
    ) as bus:
        yield bus


T = TypeVar("T")


async def in_thread(fn: Callable[[], T], limit: float = 10) -> T:
    """``fn`` (a blocking peer's code, canopen-py's) in a worker thread, bounded."""
    with anyio.fail_after(limit):
        return await anyio.to_thread.run_sync(fn)


async def through_slcan(master: Callable[[canopen.Network, CanBus], Awaitable[None]]) -> None:
    """``master(network, bus)`` with our host bus through python-can's ``slcan`` interface on
    a simulated adapter's pty, and a canopen-py network on the adapter's far side; the
    adapter saw no error."""
    from openel_can.sim.slcan import SlcanAdapter

    with (
        SlcanAdapter() as adapter,
        canopen_network(
            interface="virtual", channel=adapter.channel, receive_own_messages=False
        ) as net,
    ):
        async with slcan_host_bus(adapter.port) as bus:
            await master(net, bus)
    assert adapter.stats.errors == 0
