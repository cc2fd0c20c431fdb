"""DynamixelPort and DynamixelServo end to end: driver -> pyserial-asyncio-fast -> pty -> peer."""

from __future__ import annotations

import math
from contextlib import AsyncExitStack

import anyio
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from openel_async import (
    Actuator,
    BadParameterError,
    ComponentState,
    ErrorId,
    EventId,
    HALError,
    NotImplementedHALError,
    Outcome,
    Request,
    ReturnCode,
    SupersededError,
)
from openel_async.testing import EventRecorder
from openel_serial import (
    DRIVER,
    DynamixelPort,
    DynamixelServo,
    DynamixelStatusError,
    DynamixelTimeoutError,
    PortDisconnectedError,
)
from openel_serial import dynamixel as dx
from openel_serial.peers import SimDynamixelBus

from .conftest import BAUD, WAIT_S, actuators, make_servo

pytestmark = pytest.mark.timeout(20)

X = dx.XSeries
TICK = 2 * math.pi / 4096
GOLDEN_SYNC_WRITE = bytes.fromhex(
    "ff ff fd 00 fe 11 00 83 74 00 04 00 01 00 08 00 00 02 00 04 00 00 98 4c"
)


# -- wire format ------------------------------------------------------------------------------


async def test_sync_write_golden_bytes_on_the_wire(
    bus: SimDynamixelBus, port: DynamixelPort
) -> None:
    await port.sync_write_item(X.GOAL_POSITION, {1: 2048, 2: 1024})
    await port.ping(1)  # the peer handles packets in order: the sync write came first
    assert GOLDEN_SYNC_WRITE in bus.received
    assert bus.instructions[0] == dx.decode(GOLDEN_SYNC_WRITE)
    assert bus[1].get_raw(X.GOAL_POSITION) == 2048
    assert bus[2].get_raw(X.GOAL_POSITION) == 1024


async def test_ping_read_write_and_sync_read(bus: SimDynamixelBus, port: DynamixelPort) -> None:
    info = await port.ping(2)
    assert (info.model_number, info.firmware_version, info.alert) == (1020, 48, False)
    await port.write_item(1, X.LED, 1)
    assert await port.read_item(1, X.LED) == 1
    data = await port.sync_read([1, 2], X.PRESENT_POSITION.address, 4)
    assert {k: X.PRESENT_POSITION.decode(v) for k, v in data.items()} == {1: 2048, 2: 2048}
    # One SYNC READ instruction for both servos, each answered once.
    sync_reads = [m for m in bus.instructions if isinstance(m, dx.SyncRead)]
    assert sync_reads == [dx.SyncRead(132, 4, (1, 2))]
    assert port.stats.retries == port.stats.timeouts == 0


# -- motion and completion --------------------------------------------------------------------


async def test_two_servos_move_and_complete_exactly_once(
    bus: SimDynamixelBus, port: DynamixelPort, recorder: EventRecorder
) -> None:
    async with AsyncExitStack() as stack:
        a1, a2 = await actuators(stack, port, recorder, 1, 2)
        assert a1.device_name == "HalMotorRobotisDynamixel"
        start = len(bus.instructions)
        m1 = await a1.set_value(0.6)
        between = len(bus.instructions)  # a poll cycle may run before servo 2 has a target
        m2 = await a2.set_value(-0.4)
        both = len(bus.instructions)
        assert bus[1].get_raw(X.GOAL_POSITION) == dx.rad_to_ticks(0.6)
        with anyio.fail_after(WAIT_S):
            await m1
            await m2
        assert (m1.outcome, m2.outcome) == (Outcome.REACHED, Outcome.REACHED)
        # The servos really got there (not a stale 'not moving' right after the write).
        assert await a1.get_value(Request.POSITION_ACTUAL) == pytest.approx(0.6, abs=4 * TICK)
        assert await a2.get_value(Request.POSITION_ACTUAL) == pytest.approx(-0.4, abs=4 * TICK)
        assert bus[1].clock.now_ns() >= bus[1].arrival_ns()
        for _ in range(3):  # more polls after arrival post nothing more
            await port.poll_once()
        assert recorder.count("event", EventId.COMPLETED, source=a1) == 1
        assert recorder.count("event", EventId.COMPLETED, source=a2) == 1
        assert recorder.errors == []
        # Polling: one SYNC READ of both servos per cycle, never one READ per servo.
        early = [m for m in bus.instructions[start:between] if isinstance(m, dx.SyncRead)]
        assert all(p.ids == (1,) for p in early)  # only the servo that had a target then
        polls = [m for m in bus.instructions[both:] if isinstance(m, dx.SyncRead)]
        assert polls[0].ids in ((1,), (1, 2))  # a cycle queued behind servo 2's write
        assert len(polls) >= 3 and all(p.ids == (1, 2) for p in polls[1:])
        assert not any(isinstance(m, dx.Read) for m in bus.instructions[start:])
        assert port.stats.poll_cycles >= 3


async def test_stale_not_moving_after_a_write_does_not_complete(
    bus: SimDynamixelBus, port: DynamixelPort, recorder: EventRecorder
) -> None:
    async with AsyncExitStack() as stack:
        (a1,) = await actuators(stack, port, recorder, 1)
        # The servo starts moving 60 ms after the goal write; meanwhile ~10 polls still
        # report 'not moving' at the old position.
        bus[1].reaction_delay = 0.06
        polls_before = port.stats.poll_cycles
        motion = await a1.set_value(0.5)
        with anyio.fail_after(WAIT_S):
            await motion
        assert port.stats.poll_cycles - polls_before >= 5  # stale polls were seen
        assert motion.reached_ns is not None
        assert motion.reached_ns - motion.issued_ns >= 60_000_000
        assert await a1.get_value(Request.POSITION_ACTUAL) == pytest.approx(0.5, abs=4 * TICK)
        assert recorder.count("event", EventId.COMPLETED) == 1


async def test_superseded_target_posts_only_the_final_completion(
    bus: SimDynamixelBus, port: DynamixelPort, recorder: EventRecorder
) -> None:
    async with AsyncExitStack() as stack:
        (a1,) = await actuators(stack, port, recorder, 1)
        first = await a1.set_value(1.5)
        second = await a1.set_value(-0.3)
        with anyio.fail_after(WAIT_S):
            await second
        assert first.outcome is Outcome.SUPERSEDED
        with pytest.raises(SupersededError):
            await first
        await port.poll_once()
        assert recorder.count("event", EventId.COMPLETED) == 1
        assert await a1.get_value(Request.POSITION_ACTUAL) == pytest.approx(-0.3, abs=4 * TICK)


async def test_velocity_mode_switches_with_torque_off(
    bus: SimDynamixelBus, port: DynamixelPort, recorder: EventRecorder
) -> None:
    async with AsyncExitStack() as stack:
        (a1,) = await actuators(stack, port, recorder, 1)
        start = len(bus.instructions)
        motion = await a1.set_value(3.0, Request.VELOCITY)
        assert bus[1].mode == dx.OperatingMode.VELOCITY and bus[1].torque_enabled
        writes = [(m.address, m.data) for m in bus.instructions[start:] if isinstance(m, dx.Write)]
        assert writes == [
            (64, b"\x00"),  # torque off: Operating Mode is EEPROM
            (11, b"\x01"),  # velocity mode: the servo resets its profile to 0...
            (108, X.PROFILE_ACCELERATION.encode(400)),  # ...so the driver restores it
            (104, X.GOAL_VELOCITY.encode(dx.rad_s_to_velocity(3.0))),
            (64, b"\x01"),
        ]
        assert bus[1].get_raw(X.PROFILE_ACCELERATION) == 400
        with anyio.fail_after(WAIT_S):
            await motion
        # Within velocity_tolerance (0.05 rad/s) of the goal quantised to 0.024 rad/s units.
        velocity_unit = dx.velocity_to_rad_s(1)
        actual = await a1.get_value(Request.VELOCITY_ACTUAL)
        assert actual == pytest.approx(3.0, abs=0.05 + velocity_unit / 2)
        # Back to position control: the mode switches again and the move completes.
        back = await a1.set_value(0.0, Request.POSITION)
        assert bus[1].mode == dx.OperatingMode.POSITION
        # Both profile items back after the second mode change.
        assert bus[1].get_raw(X.PROFILE_ACCELERATION) == 400
        assert bus[1].get_raw(X.PROFILE_VELOCITY) == 400
        with anyio.fail_after(WAIT_S):
            await back
        assert await a1.get_value(Request.VELOCITY_ACTUAL) == 0.0
        assert recorder.count("event", EventId.COMPLETED) == 2


async def test_no_excite_disables_torque_and_torque_needs_a_constant(
    bus: SimDynamixelBus, port: DynamixelPort, recorder: EventRecorder
) -> None:
    async with AsyncExitStack() as stack:
        a1, a2 = await actuators(stack, port, recorder, 1, 2, torque_constant=1.5)
        assert bus[1].torque_enabled
        await a1.set_value(0.0, Request.NO_EXCITE)
        assert not bus[1].torque_enabled
        motion = await a1.set_value(0.2)  # re-enables the torque
        assert bus[1].torque_enabled
        with anyio.fail_after(WAIT_S):
            await motion
        # TORQUE through current mode: Goal Current = 0.3 Nm / 1.5 Nm/A / 2.69 mA.
        torque = await a2.set_value(0.3, Request.TORQUE)
        assert bus[2].mode == dx.OperatingMode.CURRENT
        assert bus[2].get_raw(X.GOAL_CURRENT) == round(0.3 / 1.5 / dx.CURRENT_UNIT_A)
        with anyio.fail_after(WAIT_S):
            await torque
        assert await a2.get_value(Request.TORQUE_ACTUAL) == pytest.approx(0.3, abs=0.01)


async def test_torque_without_constant_is_not_implemented(
    bus: SimDynamixelBus, port: DynamixelPort, recorder: EventRecorder
) -> None:
    async with AsyncExitStack() as stack:
        (a1,) = await actuators(stack, port, recorder, 1)
        with pytest.raises(NotImplementedHALError) as excinfo:
            await a1.set_value(0.1, Request.TORQUE)
        assert excinfo.value.code is ReturnCode.HAL_NOT_IMPLEMENTED
        with pytest.raises(NotImplementedHALError, match="torque_constant"):
            await a1.get_value(Request.TORQUE_ACTUAL)
        assert a1.state is ComponentState.ACTIVE


async def test_limits_come_from_the_control_table() -> None:
    async with (
        SimDynamixelBus(
            [make_servo(1, min_position=1024, max_position=3072, velocity_limit=100)]
        ) as bus,
        DynamixelPort(bus.path, baudrate=BAUD, return_delay=0.0) as port,
        Actuator(DynamixelServo(port, 1)) as a1,
    ):
        limits = a1.device.limits
        assert limits.position == (pytest.approx(-math.pi / 2), pytest.approx(math.pi / 2))
        assert limits.velocity == pytest.approx(dx.velocity_to_rad_s(100))
        with pytest.raises(BadParameterError, match="value"):
            await a1.set_value(2.0)
        with pytest.raises(BadParameterError, match="value"):
            await a1.set_value(3.0, Request.VELOCITY)


# -- errors and faults ---------------------------------------------------------------------


async def test_lost_reply_is_retried_and_a_silent_servo_faults(
    bus: SimDynamixelBus, port: DynamixelPort, recorder: EventRecorder
) -> None:
    # One reply lost on the wire: the retry gets it, nobody notices.
    bus.drop_replies = 1
    assert (await port.ping(1)).model_number == 1020
    assert (port.stats.retries, port.stats.timeouts) == (1, 0)
    async with AsyncExitStack() as stack:
        a1, a2 = await actuators(stack, port, recorder, 1, 2)
        start = len(bus.instructions)
        bus[2].responsive = False
        record = await recorder.wait_for("error", ErrorId.TIMEOUT, source=a2, timeout=WAIT_S)
        assert record.source is a2 and a2.state is ComponentState.ERROR
        assert a2.last_fault is not None and "no status from servo 2" in str(a2.last_fault)
        # The poll was retried asking only the silent servo, `retries` times.
        retried = [
            m for m in bus.instructions[start:] if isinstance(m, dx.SyncRead) and m.ids == (2,)
        ]
        assert len(retried) >= port.retries
        assert port.stats.timeouts >= 1 and port.stats.poll_misses >= 1
        # The other servo is untouched: polling goes on and it still completes moves.
        assert a1.state is ComponentState.ACTIVE
        with anyio.fail_after(WAIT_S):
            await (await a1.set_value(0.3))
        # A direct request to the silent servo raises the timeout (a link fault).
        with pytest.raises(DynamixelTimeoutError, match="servo 2"):
            await port.read_item(2, X.LED)
        # It answers again: re_init recovers it.
        bus[2].responsive = True
        await a2.re_init()
        assert a2.state is ComponentState.ACTIVE
        with anyio.fail_after(WAIT_S):
            await (await a2.set_value(-0.3))


async def test_status_error_notifies_and_keeps_the_servo_active(
    bus: SimDynamixelBus, port: DynamixelPort, recorder: EventRecorder
) -> None:
    async with AsyncExitStack() as stack:
        (a1,) = await actuators(stack, port, recorder, 1, position_limits=(-4.0, 4.0))
        bus[1].inject_status_error(dx.ErrorNumber.DATA_RANGE_ERROR)
        with pytest.raises(DynamixelStatusError, match="DATA_RANGE_ERROR") as excinfo:
            await a1.set_value(0.5)
        assert excinfo.value.dxl_id == 1 and excinfo.value.error_number == 4
        await recorder.wait_for("error", ErrorId.PROTOCOL_ERROR, timeout=WAIT_S)
        # Beyond the servo's own Max Position Limit (4095): it refuses with Data Limit.
        with pytest.raises(DynamixelStatusError, match="DATA_LIMIT_ERROR"):
            await a1.set_value(3.5)
        await recorder.wait_for("error", ErrorId.PROTOCOL_ERROR, count=2, timeout=WAIT_S)
        assert a1.state is ComponentState.ACTIVE
        with anyio.fail_after(WAIT_S):
            await (await a1.set_value(0.5))
        assert recorder.count("event", EventId.COMPLETED) == 1


async def test_hardware_alert_faults_and_re_init_reboots(
    bus: SimDynamixelBus, port: DynamixelPort, recorder: EventRecorder
) -> None:
    async with AsyncExitStack() as stack:
        a1, a2 = await actuators(stack, port, recorder, 1, 2)
        bus[2].inject_hardware_error(dx.HardwareError.OVERHEATING)
        await recorder.wait_for("error", ErrorId.DEVICE_ERROR, source=a2, timeout=WAIT_S)
        assert a2.state is ComponentState.ERROR and a1.state is ComponentState.ACTIVE
        assert a2.last_fault is not None and "OVERHEATING" in str(a2.last_fault)
        assert not bus[2].torque_enabled
        await a2.re_init()
        assert bus[2].reboots == 1 and bus[2].hardware_error == 0 and bus[2].torque_enabled
        with anyio.fail_after(WAIT_S):
            await (await a2.set_value(0.4))


async def test_corrupt_bytes_are_counted_and_dropped(
    bus: SimDynamixelBus, port: DynamixelPort, recorder: EventRecorder
) -> None:
    async with AsyncExitStack() as stack:
        (a1,) = await actuators(stack, port, recorder, 1)
        bus.inject_garbage(b"\x00\x13\x37\xff\xff\xfd\x00\xaa")
        bus.corrupt_replies = 1  # the next reply has a wrong CRC: dropped, then retried
        assert (await port.ping(1)).model_number == 1020
        assert port.parser.crc_errors >= 1
        assert port.parser.dropped_bytes >= 4
        assert port.stats.retries >= 1
        with anyio.fail_after(WAIT_S):
            await (await a1.set_value(0.25))
        assert recorder.errors == [] and a1.state is ComponentState.ACTIVE


async def test_instruction_damaged_on_the_wire_is_answered_crc_error_and_resent(
    bus: SimDynamixelBus, port: DynamixelPort
) -> None:
    bus.corrupt_requests = 1  # the servo receives the READ with a bad CRC
    assert await port.read_item(1, X.PRESENT_POSITION) == 2048
    assert (bus[1].crc_errors, port.stats.crc_rejected, port.stats.retries) == (1, 1, 1)
    bus.corrupt_requests = 1
    await port.write_item(2, X.PROFILE_VELOCITY, 77)  # executed once, after the resend
    assert bus[2].get(X.PROFILE_VELOCITY) == 77 and bus[2].crc_errors == 1
    bus.corrupt_requests = port.retries + 1  # every attempt damaged: the servo's answer
    with pytest.raises(DynamixelStatusError) as info:
        await port.ping(1)
    assert info.value.error_number == dx.ErrorNumber.CRC_ERROR
    assert port.stats.crc_rejected == 2 + port.retries + 1
    assert port.stats.timeouts == 0  # the servo answered every time
    assert bus.corrupt_instructions == 2 + port.retries + 1


def test_simulated_servo_answers_crc_error_by_status_return_level() -> None:
    servo = make_servo(4)
    crc_error = dx.Status(4, dx.ErrorNumber.CRC_ERROR)
    write = dx.CorruptPacket(4, dx.Instruction.WRITE, 9)
    read = dx.CorruptPacket(4, dx.Instruction.READ, 7)
    ping = dx.CorruptPacket(4, dx.Instruction.PING, 3)
    assert servo.handle_corrupt(write) == crc_error
    assert servo.handle_corrupt(dx.CorruptPacket(5, dx.Instruction.WRITE, 9)) is None
    assert servo.handle_corrupt(dx.CorruptPacket(4, dx.Instruction.STATUS, 4)) is None
    servo.handle(X.STATUS_RETURN_LEVEL.write(4, 1))  # level 1: reads answered, writes not
    assert servo.handle_corrupt(write) is None
    assert servo.handle_corrupt(read) == servo.handle_corrupt(ping) == crc_error
    servo.responsive = False
    assert servo.handle_corrupt(ping) is None
    assert servo.crc_errors == 4 and servo.instructions == 1  # nothing executed


async def test_port_vanishing_faults_every_servo_and_re_init_recovers(
    bus: SimDynamixelBus, port: DynamixelPort, recorder: EventRecorder
) -> None:
    async with AsyncExitStack() as stack:
        a1, a2 = await actuators(stack, port, recorder, 1, 2)
        bus.unplug()
        for actuator in (a1, a2):
            await recorder.wait_for("error", ErrorId.DISCONNECTED, source=actuator, timeout=WAIT_S)
        assert recorder.count("error", ErrorId.DISCONNECTED) == 2
        for actuator in (a1, a2):
            assert actuator.state is ComponentState.ERROR
            assert actuator.last_fault is not None
            assert actuator.last_fault.code is ReturnCode.HAL_NO_CONNECTED
        assert not port.connected and port.stats.losses == 1
        with pytest.raises(PortDisconnectedError):
            await port.ping(1)
        # The adapter is still gone: re_init fails and the servo stays in Error.
        with pytest.raises(HALError, match="cannot open"):
            await a1.re_init()
        assert a1.state is ComponentState.ERROR
        bus.plug()
        await a1.re_init()
        await a2.re_init()
        assert port.connected and port.stats.reconnects == 1
        m1, m2 = await a1.set_value(-0.2), await a2.set_value(0.2)
        with anyio.fail_after(WAIT_S):
            await m1
            await m2


# -- configuration --------------------------------------------------------------------------


async def test_bad_configuration_names_the_parameter(port: DynamixelPort) -> None:
    with pytest.raises(BadParameterError, match="dxl_id"):
        DynamixelServo(port, 253)
    with pytest.raises(BadParameterError, match="position_limits"):
        DynamixelServo(port, 1, position_limits=(1.0, -1.0))
    with pytest.raises(BadParameterError, match="torque_constant"):
        DynamixelServo(port, 1, torque_constant=0.0)
    with pytest.raises(BadParameterError, match="baudrate"):
        DynamixelPort("/dev/null", baudrate=0)
    with pytest.raises(BadParameterError, match="timeout_margin"):
        DynamixelPort("/dev/null", timeout_margin=-1.0)
    # Two components on one id of one port.
    async with Actuator(DynamixelServo(port, 1)):
        with pytest.raises(BadParameterError, match="dxl_id"):
            async with Actuator(DynamixelServo(port, 1)):
                pass  # pragma: no cover


async def test_missing_port_and_unknown_servo() -> None:
    with pytest.raises(PortDisconnectedError, match="cannot open"):
        async with DynamixelPort("/nonexistent/ttyUSB9"):
            pass  # pragma: no cover
    async with (
        SimDynamixelBus([make_servo(1)]) as bus,
        DynamixelPort(bus.path, baudrate=BAUD, return_delay=0.0, retries=1) as port,
    ):
        with pytest.raises(DynamixelTimeoutError, match="servo 7"):
            async with Actuator(DynamixelServo(port, 7)):
                pass  # pragma: no cover
        assert port.clients == {}


def test_response_timeout_follows_baud_rate_and_packet_size() -> None:
    port = DynamixelPort("/dev/null", baudrate=1_000_000, return_delay=0.0, timeout_margin=0.01)
    # A SYNC READ of 14 bytes from 8 servos: 22 + 8 x 25 bytes = 2.22 ms on the wire.
    assert port.response_timeout(22, 8, 14) == pytest.approx(0.00222 + 0.01)
    slow = DynamixelPort("/dev/null", baudrate=57_600, return_delay=500e-6, timeout_margin=0.01)
    assert slow.response_timeout(10, 1, 3) == pytest.approx(24 * 10 / 57_600 + 500e-6 + 0.01)


@settings(max_examples=100, deadline=None)
@given(st.lists(st.binary(max_size=64), max_size=20))
def test_reader_never_raises_on_garbage(chunks: list[bytes]) -> None:
    port = DynamixelPort("/dev/null")
    for chunk in chunks:
        port._on_data(chunk)
    assert port.stats.stray <= port.parser.packets
    assert port.parser.buffered <= 7 + port.parser.max_length


def test_driver_registration() -> None:
    assert DRIVER.name == "serial"
    assert DRIVER.devices["dynamixel"] is DynamixelServo
