"""Device-side watchdogs of the CAN drivers (issue 22 §4) against simulated drives hosted on
a thread of their own (real clock), so they keep running while the app's loop is blocked.

The blocked loop is the point of these tests: ``time.sleep`` inside the event loop stands for
a GC pause or a blocking call. Each test is bounded (a few hundred ms of real time).
"""

from __future__ import annotations

import math
import time
import uuid
from collections.abc import AsyncIterator, Iterator
from contextlib import asynccontextmanager
from typing import TypeVar

import anyio
import pytest

from openel_async import Actuator, ComponentState, ErrorId
from openel_async.clock import default_clock
from openel_async.errors import BadParameterError
from openel_async.safety import EmergencyStop, ExitAction, Watchdog
from openel_async.testing import EventRecorder
from openel_can import CanBus, Cia402Drive, ODriveAxis
from openel_can import cansimple as cs
from openel_can import cia402 as ds
from openel_can.odrive import WATCHDOG_FEED_FRACTION, ODriveError
from openel_can.odrive_link import WatchdogFeeder
from openel_can.sim.cia402 import SimCia402Drive
from openel_can.sim.faults import peers_on_thread
from openel_can.sim.odrive import SimODrive

from .conftest import wait_until

D = TypeVar("D", ODriveAxis, Cia402Drive)

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


@asynccontextmanager
async def _observed(device: D) -> AsyncIterator[tuple[Actuator, D, EventRecorder]]:
    """An actuator over ``device``, entered, with an event recorder observing it."""
    recorder = EventRecorder(default_clock())
    async with Actuator(device) as axis:
        axis.add_observer(recorder)
        yield axis, device, recorder


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
    async with _observed(ODriveAxis(bus, 1, heartbeat_period=HB)) as (axis, device, recorder):
        await device.arm_watchdog(T)
        await anyio.sleep(10 * T)  # nothing commanded: the feeder alone keeps it alive
        assert odrives[0].watchdog_trips == 0
        assert odrives[0].axis_state is cs.AxisState.CLOSED_LOOP_CONTROL
        assert axis.state is ComponentState.ACTIVE and recorder.errors == []


async def test_odrive_axes_of_a_bus_share_one_feeder_until_the_last_is_disarmed(
    bus: CanBus, odrives: list[SimODrive]
) -> None:
    async with _observed(ODriveAxis(bus, 1, heartbeat_period=HB)) as (axis, device, recorder):
        async with Actuator(ODriveAxis(bus, 2, heartbeat_period=HB)) as other:
            second = other.device
            assert isinstance(second, ODriveAxis)
            await device.arm_watchdog(T)
            await second.arm_watchdog(T)
            feeder = WatchdogFeeder.for_bus(bus, default_clock(), T, WATCHDOG_FEED_FRACTION)
            assert feeder.running
            await anyio.sleep(4 * T)  # nothing commanded: one task polls both
            assert feeder.polls >= 4
        polls = feeder.polls  # the second axis closed: dropped, the first still fed
        await anyio.sleep(4 * T)
        assert feeder.polls > polls and feeder.running
        await device.disarm_watchdog()
        await wait_until(lambda: not feeder.running, 2)
        assert [sim.watchdog_trips for sim in odrives] == [0, 0]
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
    async with _observed(ODriveAxis(bus, 1, heartbeat_period=HB)) as (axis, device, recorder):
        await device.arm_watchdog(T)
        await device.disarm_watchdog()
        await wait_until(lambda: not odrives[0].enable_watchdog, 1)
        _block_loop(3 * T)
        assert odrives[0].watchdog_trips == 0
        assert odrives[0].axis_state is cs.AxisState.CLOSED_LOOP_CONTROL
        await anyio.sleep(2 * HB)
        assert axis.state is ComponentState.ACTIVE and recorder.errors == []


# -- CiA 402: heartbeat consumer 0x1016 + abort connection option 0x6007 = quick stop --------

CIA_NODES = (5, 6)


@pytest.fixture
def drives(channel: str) -> Iterator[list[SimCia402Drive]]:
    sims = [SimCia402Drive(node) for node in CIA_NODES]
    with peers_on_thread(sims, channel):
        yield sims


@pytest.fixture
async def cia_bus(drives: list[SimCia402Drive], channel: str) -> AsyncIterator[CanBus]:
    async with CanBus(interface="virtual", channel=channel, poll_interval=0.01, name="host") as b:
        yield b


async def test_cia402_blocked_loop_quick_stops_every_drive(
    cia_bus: CanBus, drives: list[SimCia402Drive]
) -> None:
    recorder = EventRecorder(default_clock())
    async with Actuator(Cia402Drive(cia_bus, 5)) as a1, Actuator(Cia402Drive(cia_bus, 6)) as a2:
        axes = (a1, a2)
        for axis in axes:
            axis.add_observer(recorder)
            device = axis.device
            assert isinstance(device, Cia402Drive) and isinstance(device, Watchdog)
            await device.arm_watchdog(T)
        for sim in drives:
            assert sim.od[(0x1016, 1)].value == 127 << 16 | 100
            assert sim.od[(0x6007, 0)].value == 3
            assert sim.power_state is ds.PowerState.OPERATION_ENABLED
        await anyio.sleep(2 * T)  # monitoring runs (started by the first host heartbeat)
        assert all(sim.consumer_heard_ns is not None for sim in drives)
        _block_loop(3 * T)
        # The drives quick-stopped by themselves (0x605A = 2: then Switch on disabled).
        for sim in drives:
            assert sim.heartbeat_errors == 1
            assert sim.power_state in (
                ds.PowerState.QUICK_STOP_ACTIVE,
                ds.PowerState.SWITCH_ON_DISABLED,
            )
            assert sim.emcy_sent.total and sim.emcy_sent[-1].error_code == 0x8130
        for axis in axes:
            record = await recorder.wait_for("error", source=axis, timeout=1)
            assert record.id == ErrorId.WATCHDOG
            assert axis.state is ComponentState.ERROR
        for axis in axes:
            await axis.re_init()
            assert axis.state is ComponentState.ACTIVE
        await anyio.sleep(3 * T)
        assert all(sim.power_state is ds.PowerState.OPERATION_ENABLED for sim in drives)
        assert all(sim.heartbeat_errors == 1 for sim in drives)
        assert len(recorder.errors) == 2


async def test_cia402_running_loop_never_trips(
    cia_bus: CanBus, drives: list[SimCia402Drive]
) -> None:
    async with _observed(Cia402Drive(cia_bus, 5)) as (axis, device, recorder):
        await device.arm_watchdog(T)
        await anyio.sleep(10 * T)
        assert drives[0].heartbeat_errors == 0
        assert drives[0].consumer_heard_ns is not None  # monitoring, fed
        assert drives[0].power_state is ds.PowerState.OPERATION_ENABLED
        assert axis.state is ComponentState.ACTIVE and recorder.errors == []


@pytest.mark.parametrize("bad", [0.0, 0.003, 0.1005, 65.536, float("nan"), -1.0, True])
async def test_cia402_refuses_a_timeout_the_protocol_cannot_express(
    cia_bus: CanBus, drives: list[SimCia402Drive], bad: float
) -> None:
    async with Actuator(Cia402Drive(cia_bus, 5)) as axis:
        device = axis.device
        assert isinstance(device, Cia402Drive)
        with pytest.raises(BadParameterError, match="timeout_s"):
            await device.arm_watchdog(bad)
        assert drives[0].od[(0x1016, 1)].value == 0


async def test_cia402_disarm_stops_feeding_without_a_trip(
    cia_bus: CanBus, drives: list[SimCia402Drive]
) -> None:
    async with _observed(Cia402Drive(cia_bus, 5)) as (axis, device, recorder):
        await device.arm_watchdog(T)
        await anyio.sleep(2 * T)
        await device.disarm_watchdog()
        assert drives[0].od[(0x1016, 1)].value == 0
        _block_loop(3 * T)
        await anyio.sleep(3 * T)  # the host heartbeat has stopped: nothing watches it
        assert drives[0].heartbeat_errors == 0
        assert drives[0].power_state is ds.PowerState.OPERATION_ENABLED
        assert axis.state is ComponentState.ACTIVE and recorder.errors == []


# -- e-stop and safe stop ---------------------------------------------------------------------


async def test_odrive_estop_faults_with_estop_and_re_init_recovers(
    bus: CanBus, odrives: list[SimODrive]
) -> None:
    async with _observed(ODriveAxis(bus, 1, heartbeat_period=HB)) as (axis, device, recorder):
        assert isinstance(device, EmergencyStop)
        await device.estop()
        record = await recorder.wait_for("error", source=axis, timeout=1)
        assert record.id == ErrorId.ESTOP and axis.state is ComponentState.ERROR
        await wait_until(lambda: odrives[0].axis_state is cs.AxisState.IDLE, 1)
        assert odrives[0].disarm_reason & ODriveError.ESTOP_REQUESTED
        await anyio.sleep(3 * HB)  # the heartbeats showing ESTOP_REQUESTED: no second report
        await axis.re_init()
        assert axis.state is ComponentState.ACTIVE
        assert odrives[0].axis_state is cs.AxisState.CLOSED_LOOP_CONTROL
        assert len(recorder.errors) == 1


async def test_cia402_estop_faults_with_estop_and_re_init_recovers(
    cia_bus: CanBus, drives: list[SimCia402Drive]
) -> None:
    async with _observed(Cia402Drive(cia_bus, 5)) as (axis, device, recorder):
        assert isinstance(device, EmergencyStop)
        await device.estop()
        record = await recorder.wait_for("error", source=axis, timeout=1)
        assert record.id == ErrorId.ESTOP and axis.state is ComponentState.ERROR
        await wait_until(
            lambda: (
                drives[0].power_state
                in (ds.PowerState.QUICK_STOP_ACTIVE, ds.PowerState.SWITCH_ON_DISABLED)
            ),
            1,
        )
        await axis.re_init()
        assert axis.state is ComponentState.ACTIVE
        assert drives[0].power_state is ds.PowerState.OPERATION_ENABLED
        assert len(recorder.errors) == 1


@pytest.mark.parametrize("action", list(ExitAction))
async def test_odrive_safe_stop_mapping(
    bus: CanBus, odrives: list[SimODrive], action: ExitAction
) -> None:
    recorder = EventRecorder(default_clock())
    sim = odrives[0]
    async with Actuator(ODriveAxis(bus, 1, heartbeat_period=HB)) as axis:
        axis.add_observer(recorder)
        device = axis.device
        assert isinstance(device, ODriveAxis)
        await device.safe_stop(action)
        expected = {
            ExitAction.HOLD: (cs.AxisState.CLOSED_LOOP_CONTROL, cs.ControlMode.POSITION),
            ExitAction.STOP: (cs.AxisState.CLOSED_LOOP_CONTROL, cs.ControlMode.VELOCITY),
            ExitAction.TORQUE_OFF: (cs.AxisState.IDLE, None),
        }[action]
        await wait_until(lambda: sim.axis_state is expected[0], 1)
        if expected[1] is not None:
            await wait_until(lambda: sim.control_mode is expected[1], 1)
        await anyio.sleep(3 * HB)
        assert axis.state is ComponentState.ACTIVE and recorder.errors == []


@pytest.mark.parametrize("action", list(ExitAction))
async def test_cia402_safe_stop_mapping(
    cia_bus: CanBus, drives: list[SimCia402Drive], action: ExitAction
) -> None:
    recorder = EventRecorder(default_clock())
    sim = drives[0]
    async with Actuator(Cia402Drive(cia_bus, 5)) as axis:
        axis.add_observer(recorder)
        device = axis.device
        assert isinstance(device, Cia402Drive)
        await device.safe_stop(action)
        if action is ExitAction.HOLD:
            await wait_until(lambda: sim.halted, 1)
            assert sim.power_state is ds.PowerState.OPERATION_ENABLED
        elif action is ExitAction.STOP:
            await wait_until(
                lambda: (
                    sim.power_state
                    in (ds.PowerState.QUICK_STOP_ACTIVE, ds.PowerState.SWITCH_ON_DISABLED)
                ),
                1,
            )
            assert ds.Command.QUICK_STOP in sim.received_controlwords
        else:
            await wait_until(lambda: sim.power_state is ds.PowerState.SWITCH_ON_DISABLED, 1)
            assert sim.received_controlwords[-1] == ds.Command.DISABLE_VOLTAGE
        await anyio.sleep(0.05)
        assert axis.state is ComponentState.ACTIVE and recorder.errors == []


async def test_bus_heartbeat_producer_refuses_bad_parameters(channel: str) -> None:
    owner, other = object(), object()
    async with CanBus(interface="virtual", channel=channel, name="host") as bus:
        for node, period in ((0, 0.01), (128, 0.01), (True, 0.01), (127, 0.0), (127, math.nan)):
            with pytest.raises(BadParameterError):
                bus.produce_heartbeat(node, period, owner)  # type: ignore[arg-type]
        bus.produce_heartbeat(127, 0.01, owner)
        with pytest.raises(BadParameterError, match="node_id"):
            bus.produce_heartbeat(100, 0.01, other)  # one host node id per bus
        bus.release_heartbeat(owner)
