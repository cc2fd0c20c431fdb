"""A serial adapter unplugged and noticed by a write is a disconnect, not a crash: the
component reports it (Error, DISCONNECTED, PortDisconnectedError) and nothing reaches the
event loop's exception handler (issue 21, point 18: pyserial-asyncio-fast's
``_fatal_error`` logged "Fatal write error on serial transport" at ERROR with a
traceback, and anyio's pytest plugin raised it after the test's body had passed).

Real time on ptys: every wait is bounded.
"""

from __future__ import annotations

import asyncio
import os
import tty
from collections.abc import Iterator
from contextlib import AsyncExitStack, contextmanager
from typing import Any

import anyio
import anyio.lowlevel
import pytest
import serial

from openel_async import Actuator, ComponentState, ErrorId, MonotonicClock, ReturnCode
from openel_async.testing import EventRecorder
from openel_serial import DynamixelPort, DynamixelServo, PortDisconnectedError
from openel_serial import dynamixel as dx
from openel_serial.link import FdSerialTransport
from openel_serial.peers import SimDynamixelBus

from .conftest import BAUD, WAIT_S, make_servo

pytestmark = pytest.mark.timeout(30)

X = dx.XSeries


@contextmanager
def loop_exception_handler() -> Iterator[list[dict[str, Any]]]:
    """Record what reaches the running loop's exception handler (restored after)."""
    loop = asyncio.get_running_loop()
    previous = loop.get_exception_handler()
    calls: list[dict[str, Any]] = []
    loop.set_exception_handler(lambda _loop, context: calls.append(context))
    try:
        yield calls
    finally:
        loop.set_exception_handler(previous)


async def test_a_write_noticing_the_unplug_raises_not_connected_quietly() -> None:
    with loop_exception_handler() as calls:
        async with (
            SimDynamixelBus([make_servo(1)]) as bus,
            DynamixelPort(bus.path, baudrate=BAUD, return_delay=0.0, retries=0) as port,
        ):
            await port.ping(1)
            bus.unplug()
            # Nothing polls (no servo attached): the ping's own write meets the vanished
            # device (EIO), unless the reader saw it first while the ping took the bus lock
            # (a loop pass; on a loaded machine the reader's EIO can be ready by then).
            with anyio.fail_after(WAIT_S), pytest.raises(PortDisconnectedError) as info:
                await port.ping(1)
            message = str(info.value)
            assert "port lost: write failed: [Errno 5]" in message or message.endswith(
                "not open"
            ), message
            assert not port.connected and port.stats.losses == 1
    assert calls == []


async def test_the_component_reports_an_unplug_a_write_noticed() -> None:
    recorder = EventRecorder(MonotonicClock())
    with loop_exception_handler() as calls:
        async with (
            SimDynamixelBus([make_servo(1), make_servo(2)]) as bus,
            DynamixelPort(
                bus.path, baudrate=BAUD, return_delay=0.0, timeout_margin=0.1, poll_period=0.005
            ) as port,
            AsyncExitStack() as stack,
        ):
            actuators = []
            for dxl_id in (1, 2):
                actuator = await stack.enter_async_context(Actuator(DynamixelServo(port, dxl_id)))
                actuator.add_observer(recorder)
                actuators.append(actuator)
            # Holding the bus lock, the poller is between cycles: the goal position written
            # now, before the reader notices the unplug, meets EIO.
            async with port._lock:
                bus.unplug()
                port.link.write(dx.encode(X.GOAL_POSITION.write(1, 2048)))
            for actuator in actuators:
                await recorder.wait_for(
                    "error", ErrorId.DISCONNECTED, source=actuator, timeout=WAIT_S
                )
                assert actuator.state is ComponentState.ERROR
                assert actuator.last_fault is not None
                assert actuator.last_fault.code is ReturnCode.HAL_NO_CONNECTED
            assert port.link.lost_reason is not None
            assert port.link.lost_reason.startswith("port lost: write failed")
    assert calls == []


async def test_only_an_io_error_is_a_quiet_disconnect() -> None:
    """The transport's override: an OSError (SerialException) aborts it quietly, with the
    error for connection_lost; anything else is a bug and still reaches the handler."""
    lost: list[Exception | None] = []
    ended = anyio.Event()

    class Recording(asyncio.Protocol):
        def connection_lost(self, exc: Exception | None) -> None:
            lost.append(exc)
            ended.set()

    for error, handled in ((serial.SerialException("write failed: gone"), 0), (KeyError(1), 1)):
        master, slave = os.openpty()
        tty.setraw(slave)
        port = serial.serial_for_url(os.ttyname(slave), baudrate=BAUD)
        ended = anyio.Event()
        try:
            with loop_exception_handler() as calls:
                transport = FdSerialTransport(asyncio.get_running_loop(), Recording(), port)
                await anyio.lowlevel.checkpoint()  # connection_made, reader registered
                transport._fatal_error(error, "Fatal write error on serial transport")
                with anyio.fail_after(WAIT_S):
                    await ended.wait()
            assert lost[-1] is error
            assert len(calls) == handled
        finally:
            port.close()
            os.close(master)
            os.close(slave)
