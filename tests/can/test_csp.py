"""Cyclic synchronous modes (CSP/CSV/CST) on SYNC from an EventTimer: Cia402CyclicDrive,
CanSync and the simulated drive's cyclic modes."""

from __future__ import annotations

import itertools
import math
from contextlib import AsyncExitStack

import anyio
import can
import pytest

from openel_async import Actuator, BadParameterError, EventTimer, Request
from openel_async.clock import default_clock
from openel_async.device import ErrorId
from openel_async.motion import AxisGroup, AxisLimits
from openel_async.observers import TimerTick
from openel_async.testing import EventRecorder
from openel_can import CanBus, CanSync, Cia402CyclicDrive, Cia402Drive, NodePort
from openel_can import canopen as co
from openel_can import cia402 as ds
from openel_can.cyclic402 import interpolation_period
from openel_can.sim.cia402 import SimCia402Drive

from .conftest import Peers, drain, wait_until

CPR = 10_000
PERIOD_MS = 2.0
Mode = ds.ModeOfOperation


def _drive(bus: CanBus, node: int, mode: str = "csp") -> Cia402Drive:
    return Cia402Drive(bus, node, mode=mode, heartbeat_ms=100)


def test_mode_selects_the_cyclic_drive_and_bad_modes_are_refused() -> None:
    bus = CanBus(interface="virtual", channel="unused")
    assert type(_drive(bus, 1)) is Cia402CyclicDrive
    assert type(Cia402Drive(bus, 1)) is Cia402Drive
    drive = _drive(bus, 2, "csv")
    assert isinstance(drive, Cia402CyclicDrive)
    assert drive.supported_requests == frozenset({Request.VELOCITY})
    with pytest.raises(BadParameterError, match="mode"):
        Cia402Drive(bus, 1, mode="ip")
    with pytest.raises(BadParameterError, match="mode"):
        Cia402CyclicDrive(bus, 1, mode="pp")


def test_interpolation_period_encoding() -> None:
    assert interpolation_period(2_000_000) == (2, -3)
    assert interpolation_period(1_000_000) == (1, -3)
    assert interpolation_period(250_000) == (25, -5)
    assert interpolation_period(1_500_000) == (15, -4)
    assert interpolation_period(1_000_000_000) == (1, 0)


async def test_axis_group_streams_csp_with_no_sdo_in_the_loop(
    channel: str, peers: Peers, host_bus: CanBus, raw_bus: can.BusABC
) -> None:
    sims = [await peers.start(SimCia402Drive(node)) for node in (1, 2)]
    sims[1].segments = [sims[1].segments[0]._replace(p0=1234.0)]  # not at zero: no jump
    async with AsyncExitStack() as stack:
        axes = [await stack.enter_async_context(Actuator(_drive(host_bus, n))) for n in (1, 2)]
        for sim in sims:
            assert sim.mode == Mode.CYCLIC_SYNC_POSITION
            assert sim.power_state is ds.PowerState.OPERATION_ENABLED
        assert sims[1].position == pytest.approx(1234.0)
        assert sims[1].od[(0x607A, 0)].value == 1234
        timer = await stack.enter_async_context(EventTimer(PERIOD_MS, name="cycle"))
        sync = CanSync.of(host_bus)
        await sync.start(timer, counter_overflow=4)
        stack.callback(sync.stop)
        for sim in sims:  # 0x60C2 from the timer's period, before the first SYNC
            assert (sim.od[(0x60C2, 1)].value, sim.od[(0x60C2, 2)].value) == (2, -3)
            assert sim.interpolation_period_ns() == 2_000_000
        limits = AxisLimits(max_velocity=4.0, max_acceleration=40.0, max_jerk=400.0)
        group = await stack.enter_async_context(AxisGroup(axes, timer=timer, limits=limits))
        drives = [a.device for a in axes]
        assert all(isinstance(d, Cia402CyclicDrive) for d in drives)
        # The timer runs: every drive answers each SYNC with TPDO1 (fresh actual values).
        await wait_until(lambda: all(d.feedback_cycle > 0 for d in drives))  # type: ignore[attr-defined]
        drain(raw_bus)
        with anyio.fail_after(5):
            await (await group.move_to([1.0, -0.5]))
        frames = drain(raw_bus)
        sdo = [f for f in frames if f.arbitration_id in (co.SDO_RX_BASE + 1, co.SDO_RX_BASE + 2)]
        assert sdo == [], [(f.arbitration_id, bytes(f.data).hex()) for f in sdo]
        syncs = [f for f in frames if f.arbitration_id == co.SYNC_COB_ID]
        rpdos = [f for f in frames if f.arbitration_id in (0x201, 0x202)]
        assert len(syncs) > 50 and len(rpdos) > 50, (
            len(frames),
            sync.cycle,
            sync.stats,
            sims[0].position,
        )
        counters = [f.data[0] for f in syncs]
        assert set(counters) == {1, 2, 3, 4}
        assert all(b == a % 4 + 1 for a, b in itertools.pairwise(counters))
        # Every RPDO of a cycle precedes the SYNC that latches it: between two SYNCs at most
        # one RPDO per drive.
        between: list[int] = []
        for f in frames:
            if f.arbitration_id == co.SYNC_COB_ID:
                assert len(between) == len(set(between))
                between = []
            elif f.arbitration_id in (0x201, 0x202):
                between.append(f.arbitration_id)
        await wait_until(lambda: abs(sims[0].position - CPR / math.tau) < 2)
        assert sims[1].position == pytest.approx(-0.5 * CPR / math.tau, abs=2)
        assert sims[0].syncs > 50
        await wait_until(lambda: all(d.feedback_cycle >= sync.cycle - 1 for d in drives))  # type: ignore[attr-defined]
        assert await axes[0].get_value(Request.POSITION_ACTUAL) == pytest.approx(1.0, abs=1e-3)
        stats = sync.stats
        assert stats.cycles == sync.cycle > 50 and stats.rpdos >= len(rpdos)


async def test_entering_leaving_and_re_entering_csp(
    channel: str, peers: Peers, host_bus: CanBus
) -> None:
    sim = await peers.start(SimCia402Drive(3))
    async with Actuator(_drive(host_bus, 3)) as axis, EventTimer(PERIOD_MS) as timer:
        drive = axis.device
        assert isinstance(drive, Cia402CyclicDrive)
        sync = CanSync.of(host_bus)
        with pytest.raises(Exception, match="SYNC"):
            await axis.set_value(0.1)  # no SYNC producer yet: refused, not sent
        await sync.start(timer)
        try:
            timer.start_timer()
            await axis.set_value(0.3)
            await wait_until(lambda: abs(sim.position - 0.3 * CPR / math.tau) < 2)
            await drive.leave_cyclic()
            assert sim.mode == Mode.PROFILE_POSITION
            assert sim.power_state is ds.PowerState.OPERATION_ENABLED
            assert sim.position == pytest.approx(0.3 * CPR / math.tau, abs=2)
            with pytest.raises(Exception, match="not enabled in csp"):
                await axis.set_value(0.5)
            await drive.enter_cyclic()
            assert sim.mode == Mode.CYCLIC_SYNC_POSITION
            await axis.set_value(0.5)
            await wait_until(lambda: abs(sim.position - 0.5 * CPR / math.tau) < 2)
        finally:
            sync.stop()
    # closing left the cyclic mode (halt, profile position), then shut down
    assert sim.mode == Mode.PROFILE_POSITION


async def test_csv_and_cst_follow_the_setpoint_of_each_sync(
    channel: str, peers: Peers, host_bus: CanBus
) -> None:
    sims = [await peers.start(SimCia402Drive(node)) for node in (4, 5)]
    async with (
        Actuator(_drive(host_bus, 4, "csv")) as vel,
        Actuator(_drive(host_bus, 5, "cst")) as tq,
        EventTimer(PERIOD_MS) as timer,
    ):
        sync = CanSync.of(host_bus)
        await sync.start(timer)
        try:
            timer.start_timer()
            assert sims[0].mode == Mode.CYCLIC_SYNC_VELOCITY
            assert sims[1].mode == Mode.CYCLIC_SYNC_TORQUE
            await vel.set_value(2.0, Request.VELOCITY)
            await tq.set_value(0.2, Request.TORQUE)
            await wait_until(lambda: sims[0].od[(0x606C, 0)].value == round(2.0 * CPR / math.tau))
            await wait_until(lambda: sims[1].od[(0x6077, 0)].value == 200)
            assert sims[0].cyclic_target == round(2.0 * CPR / math.tau)
            assert sims[1].cyclic_target == 200
            with pytest.raises(Exception, match="POSITION"):
                await vel.set_value(1.0, Request.POSITION)
        finally:
            sync.stop()


async def test_missed_cycles_are_counted_not_burst(host_bus: CanBus, raw_bus: can.BusABC) -> None:
    async with EventTimer(PERIOD_MS, name="cycle") as timer:
        sync = CanSync.of(host_bus)
        await sync.start(timer)
        try:
            drain(raw_bus)
            timer.last_tick = TimerTick(timer, 5, 0, 0, missed_ticks=3)
            sync.notify_timer(timer)
            await wait_until(lambda: sync.cycle == 1)
            assert sync.stats.missed == 3
            await anyio.sleep(0.01)
            assert [f.arbitration_id for f in drain(raw_bus)] == [co.SYNC_COB_ID]
        finally:
            sync.stop()
        assert sync.timer is None


async def test_one_sync_producer_per_bus(channel: str) -> None:
    async with (
        CanBus(interface="virtual", channel=channel, sync_period=0.01) as bus,
        EventTimer(PERIOD_MS) as timer,
    ):
        with pytest.raises(BadParameterError, match="SYNC producer"):
            await CanSync.of(bus).start(timer)
        with pytest.raises(BadParameterError, match="counter_overflow"):
            await CanSync.of(bus).start(timer, counter_overflow=1)


async def test_an_emcy_in_csp_faults_the_component_at_once(
    channel: str, peers: Peers, host_bus: CanBus, raw_bus: can.BusABC
) -> None:
    """A warning EMCY (the drive stays enabled): the component faults on the EMCY itself,
    one error event naming the code's class, the set-point stream stops and the drive
    gets a quick stop."""
    sim = await peers.start(SimCia402Drive(6))
    recorder = EventRecorder(default_clock())
    async with Actuator(_drive(host_bus, 6)) as axis, EventTimer(PERIOD_MS) as timer:
        axis.add_observer(recorder)
        drive = axis.device
        assert isinstance(drive, Cia402CyclicDrive)
        sync = CanSync.of(host_bus)
        await sync.start(timer)
        try:
            timer.start_timer()
            await axis.set_value(0.2)
            await wait_until(lambda: drive.feedback_cycle > 2)
            sim.warn(0x8611, co.ErrorRegister.GENERIC)
            error = await recorder.wait_for("error", source=axis, timeout=1)
            assert error.id == ErrorId.DEVICE_ERROR
            assert axis.state.value == "Error"
            assert "in csp: EMCY 0x8611 following error (monitoring: control)" in str(
                axis.last_fault
            )
            stopped = (ds.PowerState.QUICK_STOP_ACTIVE, ds.PowerState.SWITCH_ON_DISABLED)
            await wait_until(lambda: sim.power_state in stopped)  # quick stop, 0x605A
            with pytest.raises(Exception, match="Error"):
                await axis.set_value(0.3)
            drain(raw_bus)
            await anyio.sleep(0.02)  # SYNCs go on; no set-point for the faulted drive
            assert 0x206 not in {f.arbitration_id for f in drain(raw_bus)}
            assert [r.id for r in recorder.errors] == [ErrorId.DEVICE_ERROR]  # once
        finally:
            sync.stop()


async def test_the_sync_counter_wraps_at_its_overflow_and_a_missed_sync_skips_no_value(
    channel: str,
    peers: Peers,
    host_bus: CanBus,
    raw_bus: can.BusABC,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """0x1019 written to the drive before the first SYNC; the counter runs 1..3 over the
    SYNCs sent: one the bus refuses is missed, counted, and the next SYNC carries the value
    it would have carried (ticks delivered by hand: the timer is not started)."""
    sim = await peers.start(SimCia402Drive(7))
    async with Actuator(_drive(host_bus, 7)) as axis, EventTimer(PERIOD_MS) as timer:
        drive = axis.device
        assert isinstance(drive, Cia402CyclicDrive)
        sync = CanSync.of(host_bus)
        await sync.start(timer, counter_overflow=3)
        try:
            assert sim.od[(0x1019, 0)].value == 3 and drive.sync_counter == 3
            drain(raw_bus)
            for _ in range(5):
                sync.notify_timer(timer)
            with monkeypatch.context() as patch:
                patch.setattr(NodePort, "send_frame_nowait", lambda *args, **kwargs: False)
                sync.notify_timer(timer)  # the bus does not take it
            sync.notify_timer(timer)
            assert sync.stats.cycles == 6 and sync.stats.missed == 1
            await wait_until(lambda: len(sim.sync_counters) == 6)
            assert list(sim.sync_counters) == [1, 2, 3, 1, 2, 3]
            sent = [f.data[0] for f in drain(raw_bus) if f.arbitration_id == co.SYNC_COB_ID]
            assert sent == [1, 2, 3, 1, 2, 3]
        finally:
            sync.stop()
