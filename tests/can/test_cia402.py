"""Cia402Drive and Cia402Temperature against the simulated CiA 402 drive."""

from __future__ import annotations

import math

import anyio
import can
import pytest

from openel_async import (
    Actuator,
    BadParameterError,
    ComponentState,
    DeviceFaultError,
    ErrorId,
    EventId,
    HALError,
    Outcome,
    Request,
    Sensor,
    SupersededError,
)
from openel_async.testing import EventRecorder
from openel_can import CanBus, Cia402Drive, Cia402Temperature, SdoAbortError
from openel_can import canopen as co
from openel_can import cia402 as ds
from openel_can.sim.cia402 import SimCia402Drive

from .conftest import Components, Peers, drain, wait_until

NODE = 5
CPR = 10_000  # the simulated drive's encoder increments per revolution (0x608F)
COMPLETED = EventId.COMPLETED


def _sim(**kwargs: object) -> SimCia402Drive:
    return SimCia402Drive(NODE, **kwargs)  # type: ignore[arg-type]


def _drive(bus: CanBus, **kwargs: object) -> Cia402Drive:
    kwargs.setdefault("heartbeat_ms", 50)
    return Cia402Drive(bus, NODE, **kwargs)  # type: ignore[arg-type]


async def _frames(raw: can.BusABC, ids: set[int], count: int) -> list[tuple[int, str]]:
    """The next ``count`` frames with one of ``ids`` seen on the raw bus (bounded wait)."""
    found: list[tuple[int, str]] = []
    with anyio.fail_after(1):
        while len(found) < count:
            found += [
                (m.arbitration_id, bytes(m.data).hex(" "))
                for m in drain(raw)
                if m.arbitration_id in ids
            ]
            await anyio.sleep(0.002)
    return found


async def test_open_configures_pdos_by_sdo_and_starts_the_node(
    peers: Peers, host_bus: CanBus, components: Components
) -> None:
    sim = await peers.start(_sim())
    axis = await components.actuator(_drive(host_bus))
    od = sim.od
    assert sim.nmt_state is co.NmtState.OPERATIONAL
    assert od[(0x1017, 0)].value == 50
    assert [od[(0x1600, s)].value for s in range(3)] == [2, 0x6040_0010, 0x607A_0020]
    assert [od[(0x1601, s)].value for s in range(3)] == [2, 0x6040_0010, 0x60FF_0020]
    assert [od[(0x1602, s)].value for s in range(3)] == [2, 0x6040_0010, 0x6071_0010]
    assert [od[(0x1A00, s)].value for s in range(4)] == [3, 0x6041_0010, 0x6064_0020, 0x6077_0010]
    assert [od[(0x1A01, s)].value for s in range(3)] == [2, 0x606C_0020, 0x6061_0008]
    for comm, base in (
        (0x1400, 0x200),
        (0x1401, 0x300),
        (0x1402, 0x400),
        (0x1800, 0x180),
        (0x1801, 0x280),
    ):
        assert od[(comm, 1)].value == base + NODE  # valid (bit 31 clear)
    assert od[(0x1800, 2)].value == 0xFF and od[(0x1800, 5)].value == 10
    device = axis.device
    assert isinstance(device, Cia402Drive)
    assert device.counts_per_rev == CPR and device.rated_torque == 1.0  # read from 0x608F, 0x6076


async def test_power_state_machine_reaches_operation_enabled(
    peers: Peers, host_bus: CanBus, components: Components
) -> None:
    sim = await peers.start(_sim())
    axis = await components.actuator(_drive(host_bus))
    assert sim.received_controlwords[:3] == [0x06, 0x07, 0x0F]  # shutdown, switch on, enable
    assert sim.power_state is ds.PowerState.OPERATION_ENABLED
    device = axis.device
    assert isinstance(device, Cia402Drive)
    assert device.power_state is ds.PowerState.OPERATION_ENABLED
    await axis.set_value(0.0, Request.NO_EXCITE)
    assert sim.power_state is ds.PowerState.SWITCHED_ON  # disable operation, confirmed
    await axis.finalize()
    await wait_until(lambda: sim.power_state is ds.PowerState.READY_TO_SWITCH_ON, 1)


async def test_golden_frames_sent_by_the_driver(
    peers: Peers, host_bus: CanBus, components: Components, raw_bus: can.BusABC
) -> None:
    await peers.start(_sim())
    axis = await components.actuator(_drive(host_bus))
    ids = {0x205, 0x305, 0x405, 0x605}
    drain(raw_bus)
    await axis.set_value(math.tau / 4, Request.POSITION)  # 2500 increments
    assert await _frames(raw_bus, ids, 2) == [
        (0x205, "3f 00 c4 09 00 00"),  # controlword enable + new set-point + immediately
        (0x205, "2f 00 c4 09 00 00"),  # new set-point low after the acknowledge
    ]
    await axis.set_value(math.tau, Request.VELOCITY)  # 10000 increments/s
    await axis.set_value(0.25, Request.TORQUE)  # 250 per mille of 1 Nm
    assert await _frames(raw_bus, ids, 8) == [
        (0x605, "2f 60 60 00 03 00 00 00"),  # SDO download 0x6060 = profile velocity
        (0x605, "40 61 60 00 00 00 00 00"),  # SDO upload 0x6061 (mode display)
        (0x305, "0f 00 10 27 00 00"),  # RPDO2: enable operation, 10000 inc/s
        (0x605, "40 41 60 00 00 00 00 00"),  # SDO upload statusword: acknowledgement
        (0x605, "2f 60 60 00 04 00 00 00"),  # 0x6060 = profile torque
        (0x605, "40 61 60 00 00 00 00 00"),
        (0x405, "0f 00 fa 00"),  # RPDO3: enable operation, 250 per mille
        (0x605, "40 41 60 00 00 00 00 00"),
    ]


async def test_position_move_completes_exactly_once(
    peers: Peers, host_bus: CanBus, components: Components, recorder: EventRecorder
) -> None:
    sim = await peers.start(_sim())
    axis = await components.actuator(_drive(host_bus))
    motion = await axis.set_value(2.0)
    with anyio.fail_after(2):
        await motion
    assert sim.position == pytest.approx(2.0 * CPR / math.tau, abs=0.5)
    assert await axis.get_value(Request.POSITION_ACTUAL) == pytest.approx(2.0, abs=1e-3)
    await anyio.sleep(0.05)  # more TPDOs with target reached set (event timer)
    assert recorder.count("event", COMPLETED, source=axis) == 1
    # A target equal to the position is reached at once, and reported once.
    with anyio.fail_after(1):
        await (await axis.set_value(await axis.get_value(Request.POSITION_ACTUAL)))
    assert recorder.count("event", COMPLETED, source=axis) == 2


async def test_target_reached_counts_only_after_the_setpoint_acknowledge(
    peers: Peers, host_bus: CanBus, components: Components, recorder: EventRecorder
) -> None:
    # The drive latches a new set-point 40 ms after the edge: meanwhile its event-timer
    # TPDOs still show target reached (bit 10) for the previous target.
    sim = await peers.start(_sim(setpoint_ack_delay=0.04))
    axis = await components.actuator(_drive(host_bus))
    with anyio.fail_after(2):
        await (await axis.set_value(0.5))
    second = await axis.set_value(1.5)  # returns once bit 12 acknowledged it
    with anyio.fail_after(2):
        await second
    assert sim.position == pytest.approx(1.5 * CPR / math.tau, abs=0.5)
    assert recorder.count("event", COMPLETED, source=axis) == 2


async def test_superseded_targets_complete_only_the_last(
    peers: Peers, host_bus: CanBus, components: Components, recorder: EventRecorder
) -> None:
    sim = await peers.start(_sim())
    axis = await components.actuator(_drive(host_bus))
    first = await axis.set_value(3.0)
    second = await axis.set_value(-2.0)
    third = await axis.set_value(0.5)
    with anyio.fail_after(2):
        await third
    for replaced in (first, second):
        with pytest.raises(SupersededError):
            await replaced
    assert third.outcome is Outcome.REACHED
    assert sim.position == pytest.approx(0.5 * CPR / math.tau, abs=0.5)
    assert recorder.count("event", COMPLETED, source=axis) == 1


async def test_velocity_and_torque_modes(
    peers: Peers, host_bus: CanBus, components: Components
) -> None:
    sim = await peers.start(_sim())
    axis = await components.actuator(_drive(host_bus))
    with anyio.fail_after(2):
        await (await axis.set_value(4.0, Request.VELOCITY))
    assert sim.mode == ds.ModeOfOperation.PROFILE_VELOCITY
    device = axis.device
    assert isinstance(device, Cia402Drive)
    # TPDO2 (velocity) runs on its 10 ms event timer: take one sent after the arrival.
    reached = axis.get_time()
    await wait_until(lambda: (device._tpdo2_ns or 0) > reached, 1)
    assert await axis.get_value(Request.VELOCITY_ACTUAL) == pytest.approx(4.0, abs=1e-3)
    with anyio.fail_after(2):
        await (await axis.set_value(0.0, Request.VELOCITY))
    with anyio.fail_after(2):
        await (await axis.set_value(0.2, Request.TORQUE))
    assert sim.mode == ds.ModeOfOperation.PROFILE_TORQUE
    assert await axis.get_value(Request.TORQUE_ACTUAL) == pytest.approx(0.2, abs=1e-3)
    with anyio.fail_after(2):
        await (await axis.set_value(0.0, Request.TORQUE))
    with anyio.fail_after(2):
        await (await axis.set_value(1.0, Request.POSITION))


async def test_sdo_timeout_faults_with_timeout(
    peers: Peers, host_bus: CanBus, components: Components, recorder: EventRecorder
) -> None:
    sim = await peers.start(_sim())
    axis = await components.actuator(_drive(host_bus, sdo_timeout=0.05))
    sim.sdo_silent = True
    with pytest.raises(DeviceFaultError) as info:
        await axis.set_value(1.0, Request.VELOCITY)  # selecting the mode needs an SDO
    assert info.value.error_id == ErrorId.TIMEOUT
    assert axis.state is ComponentState.ERROR
    assert (await recorder.wait_for("error", source=axis, timeout=1)).id == ErrorId.TIMEOUT
    sim.sdo_silent = False
    await axis.re_init()
    with anyio.fail_after(2):
        await (await axis.set_value(1.0, Request.VELOCITY))


async def test_sdo_abort_is_a_clear_error_without_fault(
    peers: Peers, host_bus: CanBus, components: Components
) -> None:
    await peers.start(_sim())
    axis = await components.actuator(_drive(host_bus))
    device = axis.device
    assert isinstance(device, Cia402Drive)
    with pytest.raises(SdoAbortError, match=r"0x06020000 \(OBJECT_DOES_NOT_EXIST\).*0x2099:0"):
        await device.sdo.read(co.ObjectEntry(0x2099, 0, co.DataType.UNSIGNED16))
    with pytest.raises(SdoAbortError, match="READ_ONLY") as info:
        await device.sdo.write(ds.STATUSWORD, 0)
    assert info.value.abort_code == co.SdoAbortCode.READ_ONLY
    assert axis.state is ComponentState.ACTIVE
    with pytest.raises(SdoAbortError, match="OBJECT_DOES_NOT_EXIST"):
        async with Sensor(
            Cia402Temperature(
                host_bus, NODE, entry=co.ObjectEntry(0x2099, 0, co.DataType.INTEGER16)
            )
        ):
            pass


async def test_emcy_warning_posts_an_error_only(
    peers: Peers, host_bus: CanBus, components: Components, recorder: EventRecorder
) -> None:
    sim = await peers.start(_sim())
    axis = await components.actuator(_drive(host_bus))
    sim.warn(co.EmcyCode.DEVICE_OVER_TEMPERATURE)
    assert (await recorder.wait_for("error", source=axis, timeout=1)).id == ErrorId.DEVICE_ERROR
    assert axis.state is ComponentState.ACTIVE
    with anyio.fail_after(2):
        await (await axis.set_value(0.3))


async def test_fault_emcy_then_re_init_resets_the_fault(
    peers: Peers, host_bus: CanBus, components: Components, recorder: EventRecorder
) -> None:
    sim = await peers.start(_sim())
    axis = await components.actuator(_drive(host_bus))
    motion = await axis.set_value(5.0)
    sim.trip(co.EmcyCode.CONTINUOUS_OVER_CURRENT)
    with pytest.raises(DeviceFaultError):
        with anyio.fail_after(1):
            await motion
    assert axis.state is ComponentState.ERROR
    assert "CONTINUOUS_OVER_CURRENT" in str(axis.last_fault)
    await recorder.wait_for("error", source=axis, timeout=1)
    await anyio.sleep(0.05)  # more statuswords: the EMCY of the fault is not posted again
    assert [r.id for r in recorder.errors] == [ErrorId.DEVICE_ERROR]  # one fault, one report
    await axis.re_init()
    assert ds.ControlBit.FAULT_RESET in [
        ds.ControlBit(cw & ds.ControlBit.FAULT_RESET) for cw in sim.received_controlwords
    ]
    assert sim.power_state is ds.PowerState.OPERATION_ENABLED
    assert sim.od[(0x603F, 0)].value == 0
    assert sim.emcy_sent[-1].error_code == co.EmcyCode.NO_ERROR  # error reset EMCY
    with anyio.fail_after(2):
        await (await axis.set_value(0.5))


async def test_heartbeat_loss_faults_disconnected(
    peers: Peers, host_bus: CanBus, components: Components, recorder: EventRecorder
) -> None:
    sim = await peers.start(_sim())
    axis = await components.actuator(_drive(host_bus, sdo_timeout=0.05))
    sim.set_silent()
    assert (await recorder.wait_for("error", source=axis, timeout=1)).id == ErrorId.DISCONNECTED
    with pytest.raises(HALError):
        await axis.re_init()
    sim.set_silent(False)
    await axis.re_init()
    with anyio.fail_after(2):
        await (await axis.set_value(0.5))


async def test_reboot_faults_and_re_init_reconfigures(
    peers: Peers, host_bus: CanBus, components: Components, recorder: EventRecorder
) -> None:
    sim = await peers.start(_sim())
    axis = await components.actuator(_drive(host_bus))
    sim.reboot()
    await recorder.wait_for("error", source=axis, timeout=1)
    assert "rebooted" in str(axis.last_fault)
    assert sim.od[(0x1601, 0)].value == 0  # the mapping is back to its defaults
    await axis.re_init()
    assert sim.od[(0x1601, 1)].value == 0x6040_0010 and sim.nmt_state is co.NmtState.OPERATIONAL
    with anyio.fail_after(2):
        await (await axis.set_value(1.0, Request.VELOCITY))


async def test_quick_stop_then_next_command_re_enables(
    peers: Peers, host_bus: CanBus, components: Components, recorder: EventRecorder
) -> None:
    sim = await peers.start(_sim())
    axis = await components.actuator(_drive(host_bus))
    await axis.set_value(3.0, Request.VELOCITY)
    device = axis.device
    assert isinstance(device, Cia402Drive)
    await device.quick_stop()
    await wait_until(lambda: sim.power_state is ds.PowerState.SWITCH_ON_DISABLED, 1)
    assert axis.state is ComponentState.ACTIVE
    with anyio.fail_after(2):
        await (await axis.set_value(0.5))
    assert recorder.errors == []


async def test_tpdos_on_sync(channel: str, peers: Peers, recorder: EventRecorder) -> None:
    sim = await peers.start(_sim())
    async with (
        CanBus(interface="virtual", channel=channel, poll_interval=0.01, sync_period=0.005) as bus,
        Actuator(_drive(bus, sync=True)) as axis,
    ):
        axis.add_observer(recorder)
        assert sim.od[(0x1800, 2)].value == 1 and sim.od[(0x1801, 2)].value == 1
        with anyio.fail_after(2):
            await (await axis.set_value(1.0))
        assert await axis.get_value(Request.POSITION_ACTUAL) == pytest.approx(1.0, abs=1e-3)


async def test_corrupt_frames_are_counted_and_dropped(
    peers: Peers, host_bus: CanBus, components: Components, raw_bus: can.BusABC
) -> None:
    await peers.start(_sim())
    axis = await components.actuator(_drive(host_bus))
    device = axis.device
    assert isinstance(device, Cia402Drive)
    for cob_id, data in (
        (0x180 + NODE, b"\x27\x02"),  # TPDO1 too short for its mapping
        (0x180 + NODE, b"\x01\x00\x00\x00\x00\x00\x00\x00"),  # statusword of no state
        (0x080 + NODE, b"\x00\x10"),  # EMCY of 2 bytes
        (0x700 + NODE, b"\x42"),  # heartbeat with an unknown NMT state
    ):
        raw_bus.send(can.Message(arbitration_id=cob_id, data=data, is_extended_id=False))
    await wait_until(lambda: device.malformed_frames == 4, 1)
    assert axis.state is ComponentState.ACTIVE
    with anyio.fail_after(2):
        await (await axis.set_value(0.4))


async def test_temperature_sensor(peers: Peers, host_bus: CanBus, components: Components) -> None:
    await peers.start(_sim())
    await components.actuator(_drive(host_bus))
    thermometer = await components.sensor(Cia402Temperature(host_bus, NODE))
    (kelvin,) = await thermometer.get_value()
    assert thermometer.units == ("K",)
    assert kelvin == pytest.approx(298.15, abs=2)


async def test_temperature_sensor_survives_an_sdo_silence(
    peers: Peers, host_bus: CanBus, components: Components, recorder: EventRecorder
) -> None:
    """A 0.3 s SDO silence (the CAN demo's case): the read fails with a TIMEOUT fault that
    is notified; once the drive answers again re_init brings the sensor back, and the
    drive's actuator on the same node is untouched."""
    sim = await peers.start(_sim())
    axis = await components.actuator(_drive(host_bus))
    thermometer = await components.sensor(Cia402Temperature(host_bus, NODE))
    sim.sdo_silent = True
    with pytest.raises(DeviceFaultError) as info:
        await thermometer.get_value()
    assert info.value.error_id == ErrorId.TIMEOUT
    assert (await recorder.wait_for("error", source=thermometer, timeout=1)).id == ErrorId.TIMEOUT
    assert thermometer.state is ComponentState.ERROR
    await anyio.sleep(0.3)
    sim.sdo_silent = False
    with anyio.fail_after(2):
        await thermometer.re_init()
    (kelvin,) = await thermometer.get_value()
    assert kelvin == pytest.approx(298.15, abs=2)
    assert axis.state is ComponentState.ACTIVE


def test_bad_parameters_name_the_parameter() -> None:
    bus = CanBus(interface="virtual", channel="unused")
    with pytest.raises(BadParameterError, match="node_id"):
        Cia402Drive(bus, 0)
    with pytest.raises(BadParameterError, match="counts_per_rev"):
        Cia402Drive(bus, 1, counts_per_rev=0)
    with pytest.raises(BadParameterError, match="heartbeat_ms"):
        Cia402Drive(bus, 1, heartbeat_ms=0)
    with pytest.raises(BadParameterError, match="sdo_timeout"):
        Cia402Drive(bus, 1, sdo_timeout=math.nan)


async def test_a_fault_ends_a_waiting_setpoint_handshake_at_once(
    peers: Peers, host_bus: CanBus, components: Components, recorder: EventRecorder
) -> None:
    # The drive acknowledges set-points 10 s late and the handshake would wait up to its
    # 5 s state timeout: the heartbeat loss (150 ms) must end that wait, not the timeout.
    sim = await peers.start(_sim(setpoint_ack_delay=10.0))
    axis = await components.actuator(_drive(host_bus, state_timeout=5.0))
    outcome: list[BaseException | None] = []

    async def command() -> None:
        try:
            await (await axis.set_value(1.0))
            outcome.append(None)
        except (DeviceFaultError, HALError) as exc:
            outcome.append(exc)

    with anyio.fail_after(1.5):
        async with anyio.create_task_group() as tg:
            tg.start_soon(command)
            await wait_until(lambda: sim.setpoint_due_ns is not None)  # waiting for the ack
            sim.set_silent()
    assert (await recorder.wait_for("error", source=axis, timeout=1)).id == ErrorId.DISCONNECTED
    assert len(outcome) == 1 and outcome[0] is not None
    assert axis.state is ComponentState.ERROR


async def test_an_unacknowledged_setpoint_times_out_after_state_timeout(
    peers: Peers, host_bus: CanBus, components: Components, recorder: EventRecorder
) -> None:
    # TPDOs keep coming (event timer) but none acknowledges: the wait ends at its timer.
    await peers.start(_sim(setpoint_ack_delay=10.0))
    axis = await components.actuator(_drive(host_bus, state_timeout=0.1))
    started = anyio.current_time()
    with anyio.fail_after(1), pytest.raises(DeviceFaultError) as info:
        await axis.set_value(1.0)
    assert 0.1 <= anyio.current_time() - started < 0.9
    assert info.value.error_id == ErrorId.TIMEOUT
    assert (await recorder.wait_for("error", source=axis, timeout=1)).id == ErrorId.TIMEOUT


async def test_statusword_waits_each_end_at_their_own_deadline(
    peers: Peers, host_bus: CanBus, components: Components
) -> None:
    """The node's one status timer: a later, shorter wait is not held to the earlier, longer
    one's deadline, and the longer one still ends at its own once the timer fired early."""
    await peers.start(_sim())
    drive = _drive(host_bus)
    await components.actuator(drive)
    outcome: list[str] = []

    async def long_wait() -> None:
        try:
            await drive._wait_status(lambda sw: False, "never")
        except TimeoutError:
            outcome.append("long")

    drive.state_timeout = 0.6
    async with anyio.create_task_group() as tg:
        tg.start_soon(long_wait)
        await anyio.sleep(0.01)
        drive.state_timeout = 0.05
        started = anyio.current_time()
        with anyio.fail_after(2), pytest.raises(TimeoutError):
            await drive._wait_status(lambda sw: False, "never either")
        assert anyio.current_time() - started < 0.5
        assert outcome == []  # the long wait goes on past the short one's deadline
    assert outcome == ["long"]
    assert drive._status_waiters == []


async def test_a_cancelled_setpoint_leaves_the_next_one_working(
    peers: Peers, host_bus: CanBus, components: Components
) -> None:
    sim = await peers.start(_sim(setpoint_ack_delay=0.2))
    axis = await components.actuator(_drive(host_bus))
    with anyio.move_on_after(0.05) as scope:
        await axis.set_value(1.0)  # cancelled while waiting for the acknowledge
    assert scope.cancelled_caught
    sim.setpoint_ack_delay = 0.0
    with anyio.fail_after(2):
        await (await axis.set_value(0.5))
    assert sim.position == pytest.approx(0.5 * CPR / math.tau, abs=0.5)


def test_state_from_statusword_is_the_first_match_of_the_cia402_table() -> None:
    """The lookup by the state bits (``statusword & 0x6F``) against the table it is built
    from, for every value of the low seven bits with the high ones clear, some set, all
    set; out of range and no state raise."""
    patterns = (
        (0x4F, ds.PowerState.NOT_READY_TO_SWITCH_ON),
        (0x4F, ds.PowerState.SWITCH_ON_DISABLED),
        (0x6F, ds.PowerState.READY_TO_SWITCH_ON),
        (0x6F, ds.PowerState.SWITCHED_ON),
        (0x6F, ds.PowerState.OPERATION_ENABLED),
        (0x6F, ds.PowerState.QUICK_STOP_ACTIVE),
        (0x4F, ds.PowerState.FAULT_REACTION_ACTIVE),
        (0x4F, ds.PowerState.FAULT),
    )
    for statusword in (low | high for low in range(0x80) for high in (0, 0x1280, 0xFF80)):
        expected = next((s for m, s in patterns if statusword & m == s.value), None)
        if expected is None:
            with pytest.raises(ds.Cia402DecodeError, match="matches no CiA 402 state"):
                ds.state_from_statusword(statusword)
        else:
            assert ds.state_from_statusword(statusword) is expected
    for bad in (-1, 0x10000):
        with pytest.raises(ds.Cia402DecodeError, match="not a u16"):
            ds.state_from_statusword(bad)
