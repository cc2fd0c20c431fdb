"""Device-side watchdogs of the CAN drivers (issue 22 §4) against simulated drives hosted on
a thread of their own (real clock), so they keep running while the app's loop is blocked.

The blocked loop is the point of these tests: ``time.sleep`` inside the event loop stands for
a GC pause or a blocking call. Each test is bounded (a few hundred ms of real time).
"""

from __future__ import annotations

import time
import uuid
from collections.abc import AsyncIterator, Iterator

import anyio
import pytest

from openel_async import Actuator, ComponentState, ErrorId
from openel_async.clock import default_clock
from openel_async.errors import BadParameterError
from openel_async.safety import Watchdog
from openel_async.testing import EventRecorder
from openel_can import CanBus, ODriveAxis
from openel_can import cansimple as cs
from openel_can.odrive import ODriveError
from openel_can.sim.faults import peers_on_thread
from openel_can.sim.odrive import SimODrive

from .conftest import wait_until

T = 0.1  # the watchdog timeout under test
HB = 0.02  # heartbeat period of the simulated ODrives here (real default: 0.1 s)
ODRIVE_NODES = (1, 2)


@pytest.fixture
def channel() -> str:
    return f"wd-{uuid.uuid4().hex}"


@pytest.fixture
def odrives(channel: str) -> Iterator[list[SimODrive]]:
    sims = [SimODrive(node, heartbeat_period=HB) for node in ODRIVE_NODES]
    with peers_on_thread(sims, channel):
        yield sims


@pytest.fixture
async def bus(odrives: list[SimODrive], channel: str) -> AsyncIterator[CanBus]:
    async with CanBus(interface="virtual", channel=channel, poll_interval=0.01, name="host") as b:
        yield b


def _block_loop(seconds: float) -> None:
    """A deliberate stall of the event loop (what a GC pause or a blocking call does)."""
    time.sleep(seconds)  # the point of the test


async def test_odrive_blocked_loop_trips_every_axis_watchdog(
    bus: CanBus, odrives: list[SimODrive]
) -> None:
    recorder = EventRecorder(default_clock())
    async with (
        Actuator(ODriveAxis(bus, 1, heartbeat_period=HB)) as a1,
        Actuator(ODriveAxis(bus, 2, heartbeat_period=HB)) as a2,
    ):
        axes = (a1, a2)
        for axis in axes:
            axis.add_observer(recorder)
            device = axis.device
            assert isinstance(device, ODriveAxis) and isinstance(device, Watchdog)
            await device.arm_watchdog(T)
        for sim in odrives:
            assert sim.enable_watchdog and sim.watchdog_timeout == pytest.approx(T)
            assert sim.axis_state is cs.AxisState.CLOSED_LOOP_CONTROL
        _block_loop(3 * T)
        # The drives stopped by themselves while the loop was stuck.
        for sim in odrives:
            assert sim.axis_state is cs.AxisState.IDLE
            assert sim.disarm_reason & ODriveError.WATCHDOG_TIMER_EXPIRED
            assert sim.watchdog_trips == 1
        # The loop resumes: each component reports the trip as a watchdog error.
        for axis in axes:
            record = await recorder.wait_for("error", source=axis, timeout=1)
            assert record.id == ErrorId.WATCHDOG
            assert axis.state is ComponentState.ERROR
        for axis in axes:
            await axis.re_init()  # Clear_Errors, closed loop again, still fed
            assert axis.state is ComponentState.ACTIVE
        await anyio.sleep(3 * T)
        assert all(sim.axis_state is cs.AxisState.CLOSED_LOOP_CONTROL for sim in odrives)
        assert len(recorder.errors) == 2


async def test_odrive_running_loop_never_trips(bus: CanBus, odrives: list[SimODrive]) -> None:
    recorder = EventRecorder(default_clock())
    async with Actuator(ODriveAxis(bus, 1, heartbeat_period=HB)) as axis:
        axis.add_observer(recorder)
        device = axis.device
        assert isinstance(device, ODriveAxis)
        await device.arm_watchdog(T)
        await anyio.sleep(10 * T)  # nothing commanded: the feeder alone keeps it alive
        assert odrives[0].watchdog_trips == 0
        assert odrives[0].axis_state is cs.AxisState.CLOSED_LOOP_CONTROL
        assert axis.state is ComponentState.ACTIVE and recorder.errors == []


@pytest.mark.parametrize("bad", [0.0, -0.1, float("nan"), float("inf"), 1e39, 1e-50, True])
async def test_odrive_refuses_a_timeout_the_protocol_cannot_express(
    bus: CanBus, odrives: list[SimODrive], bad: float
) -> None:
    async with Actuator(ODriveAxis(bus, 1, heartbeat_period=HB)) as axis:
        device = axis.device
        assert isinstance(device, ODriveAxis)
        with pytest.raises(BadParameterError, match="timeout_s"):
            await device.arm_watchdog(bad)
        assert not odrives[0].enable_watchdog


async def test_odrive_disarm_stops_feeding_without_a_trip(
    bus: CanBus, odrives: list[SimODrive]
) -> None:
    recorder = EventRecorder(default_clock())
    async with Actuator(ODriveAxis(bus, 1, heartbeat_period=HB)) as axis:
        axis.add_observer(recorder)
        device = axis.device
        assert isinstance(device, ODriveAxis)
        await device.arm_watchdog(T)
        await device.disarm_watchdog()
        await wait_until(lambda: not odrives[0].enable_watchdog, 1)
        _block_loop(3 * T)
        assert odrives[0].watchdog_trips == 0
        assert odrives[0].axis_state is cs.AxisState.CLOSED_LOOP_CONTROL
        await anyio.sleep(2 * HB)
        assert axis.state is ComponentState.ACTIVE and recorder.errors == []
