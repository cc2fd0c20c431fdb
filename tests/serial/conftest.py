"""Fixtures of the serial tests: simulated peers on ptys and the real serial stack.

Everything runs in real time (a pty has no virtual clock): every wait is bounded with
``anyio.fail_after`` or ``EventRecorder.wait_for(timeout=...)``.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from typing import Any

import pytest

from openel_async import MonotonicClock
from openel_async.testing import EventRecorder
from openel_serial import DynamixelPort
from openel_serial.peers import SimDynamixelBus, SimServo

BAUD = 1_000_000
WAIT_S = 3.0
"""Bound of every wait for an event: far above the expected ~0.1-0.5 s."""


def make_servo(dxl_id: int, **kwargs: Any) -> SimServo:
    # Profile: 400 x 0.229 rpm = 9.6 rad/s, 400 x 214.6 rev/min^2 = 150 rad/s^2: moves of
    # a fraction of a radian last ~0.1-0.2 s.
    kwargs.setdefault("profile_velocity", 400)
    kwargs.setdefault("profile_acceleration", 400)
    kwargs.setdefault("velocity_limit", 600)
    return SimServo(dxl_id, **kwargs)


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
