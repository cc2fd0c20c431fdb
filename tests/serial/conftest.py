"""Fixtures of the serial tests: simulated peers on ptys and the real serial stack.

Everything runs in real time (a pty has no virtual clock): every wait is bounded with
``anyio.fail_after`` or ``EventRecorder.wait_for(timeout=...)``.
"""

from __future__ import annotations

from collections.abc import AsyncIterator, Callable
from contextlib import AsyncExitStack
from typing import Any, TypeVar

import anyio
import pytest

from openel_async import Actuator, MonotonicClock
from openel_async.testing import EventRecorder
from openel_serial import DynamixelPort, DynamixelServo
from openel_serial.peers import SimDynamixelBus, SimServo

BAUD = 1_000_000
WAIT_S = 3.0
"""Bound of every wait for an event: far above the expected ~0.1-0.5 s."""

T = TypeVar("T")


class RecordingPort:
    """The part of a vendor SDK's PortHandler (dynamixel-sdk, scservo_sdk) that its packet
    handler uses, without a serial port.

    ``written`` collects every packet sent; ``rx`` holds the bytes the SDK will read.
    """

    def __init__(self, rx: bytes = b"") -> None:
        self.is_using = False
        self.written: list[bytes] = []
        self.rx = bytearray(rx)

    def clearPort(self) -> None:
        pass

    def writePort(self, packet: list[int]) -> int:
        self.written.append(bytes(packet))
        return len(packet)

    def readPort(self, length: int) -> bytes:
        data = bytes(self.rx[:length])
        del self.rx[:length]
        return data

    def setPacketTimeout(self, packet_length: int) -> None:
        pass

    def setPacketTimeoutMillis(self, msec: float) -> None:
        pass

    def isPacketTimeout(self) -> bool:
        return not self.rx  # nothing more will arrive

    def getBaudRate(self) -> int:
        return BAUD


def make_servo(dxl_id: int, **kwargs: Any) -> SimServo:
    # Profile: 400 x 0.229 rpm = 9.6 rad/s, 400 x 214.6 rev/min^2 = 150 rad/s^2: moves of
    # a fraction of a radian last ~0.1-0.2 s.
    kwargs.setdefault("profile_velocity", 400)
    kwargs.setdefault("profile_acceleration", 400)
    kwargs.setdefault("velocity_limit", 600)
    return SimServo(dxl_id, **kwargs)


async def actuators(
    stack: AsyncExitStack, port: DynamixelPort, recorder: EventRecorder, *ids: int, **kw: Any
) -> list[Actuator]:
    """Open an Actuator over a DynamixelServo for each id on ``stack``, observed by
    ``recorder``."""
    out = []
    for dxl_id in ids:
        actuator = await stack.enter_async_context(Actuator(DynamixelServo(port, dxl_id, **kw)))
        actuator.add_observer(recorder)
        out.append(actuator)
    return out


async def in_thread(call: Callable[[], T]) -> T:
    """Run a blocking call (dynamixel-sdk's) in a worker thread, bounded by WAIT_S."""
    with anyio.fail_after(WAIT_S):
        return await anyio.to_thread.run_sync(call)


@pytest.fixture
async def bus() -> AsyncIterator[SimDynamixelBus]:
    async with SimDynamixelBus([make_servo(1), make_servo(2)]) as sim:
        yield sim


@pytest.fixture
async def port(bus: SimDynamixelBus) -> AsyncIterator[DynamixelPort]:
    async with DynamixelPort(
        bus.path, baudrate=BAUD, return_delay=0.0, timeout_margin=0.1, poll_period=0.005
    ) as dxl_port:
        yield dxl_port


@pytest.fixture
def recorder() -> EventRecorder:
    return EventRecorder(MonotonicClock())
