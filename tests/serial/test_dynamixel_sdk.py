"""Interop with ROBOTIS' own implementation, dynamixel-sdk (Protocol 2.0).

Packet level: the SDK's PacketHandler and GroupSync* build their instruction packets on a
fake port handler that records the bytes; ours must be identical. The SDK also parses
our status packets. Wire level: the SDK's PortHandler opens our simulated bus's pty
with pyserial and talks to the simulated servos; its blocking calls run in a worker
thread (``anyio.to_thread``), each bounded by the SDK's own packet timeout and by
``anyio.fail_after``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import dynamixel_sdk as sdk
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from openel_serial import dynamixel as dx
from openel_serial.peers import SimDynamixelBus

from .conftest import BAUD, RecordingPort, in_thread, make_servo

pytestmark = pytest.mark.timeout(30)

X = dx.XSeries
PH = sdk.PacketHandler(2.0)


# -- packet level ----------------------------------------------------------------------------


@settings(max_examples=80, deadline=None)
@given(st.binary(max_size=300))
def test_crc_matches_sdk_update_crc(data: bytes) -> None:
    assert dx.crc16(data) == PH.updateCRC(0, list(data), len(data))


def _u32(value: int) -> list[int]:
    return list(value.to_bytes(4, "little"))


def test_ping_read_write_bytes_match_sdk() -> None:
    port = RecordingPort(dx.encode(dx.Status(7, 0, b"\xfc\x03\x30")))
    model, result, error = PH.ping(port, 7)
    assert (model, result, error) == (1020, sdk.COMM_SUCCESS, 0)
    assert port.written == [dx.encode(dx.Ping(7))]

    port = RecordingPort(dx.encode(dx.Status(7, 0, (2100).to_bytes(4, "little"))))
    value, result, error = PH.read4ByteTxRx(port, 7, X.PRESENT_POSITION.address)
    assert (value, result, error) == (2100, sdk.COMM_SUCCESS, 0)
    assert port.written == [dx.encode(dx.Read(7, 132, 4))]

    port = RecordingPort(dx.encode(dx.Status(7, dx.ErrorNumber.DATA_LIMIT_ERROR)))
    result, error = PH.write4ByteTxRx(port, 7, X.GOAL_POSITION.address, 5000)
    assert (result, error) == (sdk.COMM_SUCCESS, dx.ErrorNumber.DATA_LIMIT_ERROR)
    assert port.written == [dx.encode(dx.Write(7, 116, (5000).to_bytes(4, "little")))]


def test_other_instructions_match_sdk() -> None:
    ack = dx.encode(dx.Status(3, 0))
    cases: list[tuple[Callable[[RecordingPort], Any], dx.DynamixelMessage]] = [
        (lambda p: PH.reboot(p, 3), dx.Reboot(3)),
        (lambda p: PH.action(p, 3), dx.Action(3)),
        (lambda p: PH.clearMultiTurn(p, 3), dx.Clear(3, 0x01)),
        (lambda p: PH.factoryReset(p, 3, 0x02), dx.FactoryReset(3, dx.FactoryResetMode(2))),
        (lambda p: PH.regWriteTxOnly(p, 3, 116, 4, _u32(10)), dx.RegWrite(3, 116, _u32b(10))),
        (lambda p: PH.write1ByteTxOnly(p, 3, 64, 1), dx.Write(3, 64, b"\x01")),
    ]
    for call, msg in cases:
        port = RecordingPort(ack)
        call(port)
        assert port.written == [dx.encode(msg)], msg


def _u32b(value: int) -> bytes:
    return value.to_bytes(4, "little")


def test_sync_read_and_sync_write_match_sdk() -> None:
    ids = (1, 2, 5)
    replies = b"".join(
        dx.encode(dx.Status(i, 0, (1000 * i).to_bytes(4, "little") + bytes(10))) for i in ids
    )
    port = RecordingPort(replies)
    group = sdk.GroupSyncRead(port, PH, 122, 14)
    for dxl_id in ids:
        assert group.addParam(dxl_id)
    assert group.txRxPacket() == sdk.COMM_SUCCESS
    assert port.written == [dx.encode(dx.SyncRead(122, 14, ids))]
    for dxl_id in ids:
        assert group.getData(dxl_id, 122, 4) == 1000 * dxl_id

    port = RecordingPort()
    writer = sdk.GroupSyncWrite(port, PH, X.GOAL_POSITION.address, 4)
    goals = {1: 2048, 2: 1024, 5: 0xFFFF}
    for dxl_id, goal in goals.items():
        assert writer.addParam(dxl_id, _u32(goal))
    assert writer.txPacket() == sdk.COMM_SUCCESS
    items = tuple(dx.SyncWriteItem(i, _u32b(g)) for i, g in goals.items())
    assert port.written == [dx.encode(dx.SyncWrite(116, 4, items))]


payload = st.lists(
    st.sampled_from([b"\xff", b"\xfd", b"\x00", b"\xff\xff\xfd", b"\x55"]), max_size=12
).map(b"".join) | st.binary(max_size=20)


def _sdk_write_packet(dxl_id: int, address: int, data: bytes) -> list[int]:
    """The WRITE packet as the SDK's writeTxOnly lays it out before txPacket."""
    packet = [0] * (len(data) + 12)
    packet[4], packet[5], packet[6] = dxl_id, (len(data) + 5) & 0xFF, (len(data) + 5) >> 8
    packet[7:10] = [dx.Instruction.WRITE, address & 0xFF, address >> 8]
    packet[10 : 10 + len(data)] = data
    return packet


@settings(max_examples=80, deadline=None)
@given(st.integers(0, dx.MAX_ID), st.integers(0, 0xFFFF), payload.filter(bool))
def test_write_with_stuffing_matches_sdk(dxl_id: int, address: int, data: bytes) -> None:
    ours = dx.encode(dx.Write(dxl_id, address, data))
    # The SDK's stuffing algorithm (addStuffing's result, framed as txPacket frames it).
    stuffed = PH.addStuffing(_sdk_write_packet(dxl_id, address, data))
    stuffed[0:4] = dx.HEADER
    crc = PH.updateCRC(0, stuffed, len(stuffed) - 2)
    stuffed[-2:] = [crc & 0xFF, crc >> 8]
    assert bytes(stuffed) == ours
    # On the wire: identical whenever no stuffing is needed.
    port = RecordingPort()
    PH.writeTxOnly(port, dxl_id, address, len(data), list(data))
    if len(ours) == len(data) + 12:  # nothing stuffed
        assert port.written == [ours]


def test_sdk_tx_packet_loses_its_byte_stuffing() -> None:
    # dynamixel-sdk 4.1.0 (Python): txPacket ignores the longer list addStuffing returns,
    # so FF FF FD in the data goes out unstuffed. Our decoder refuses such a packet
    # (counted as malformed) rather than misread it; the e-manual's stuffing is ours.
    port = RecordingPort()
    PH.writeTxOnly(port, 1, X.GOAL_POSITION.address, 4, [0xFF, 0xFF, 0xFD, 0x01])
    (wire,) = port.written
    assert wire != dx.encode(dx.Write(1, 116, b"\xff\xff\xfd\x01"))
    assert wire[7:-2] == b"\x03\x74\x00\xff\xff\xfd\x01"  # unstuffed
    with pytest.raises(dx.DynamixelDecodeError, match="unstuffed"):
        dx.decode(wire)
    parser = dx.PacketParser()
    assert parser.feed(wire) == [] and parser.malformed == 1


def _sdk_status(dxl_id: int, error: int, params: bytes) -> bytes:
    """A status packet stuffed and framed with the SDK's own addStuffing and updateCRC."""
    length = len(params) + 4
    packet = [0xFF, 0xFF, 0xFD, 0x00, dxl_id, length & 0xFF, length >> 8, 0x55, error]
    stuffed = PH.addStuffing([*packet, *params, 0, 0])
    crc = PH.updateCRC(0, stuffed, len(stuffed) - 2)
    stuffed[-2:] = [crc & 0xFF, crc >> 8]
    return bytes(stuffed)


def _sdk_reads(wire: bytes) -> tuple[list[int], int]:
    port = RecordingPort(b"\x00\xff" + wire)
    result: tuple[list[int], int] = PH.rxPacket(port, False)
    return result


@settings(max_examples=80, deadline=None)
@given(st.integers(0, dx.MAX_ID), st.integers(0, 0x7F), payload)
def test_sdk_parses_our_status_packets(dxl_id: int, error: int, params: bytes) -> None:
    ours = dx.encode(dx.Status(dxl_id, error, params))
    assert ours == _sdk_status(dxl_id, error, params)  # the very bytes the SDK would build
    packet, result = _sdk_reads(ours)
    assert result == sdk.COMM_SUCCESS
    assert (packet[4], packet[7], packet[8]) == (dxl_id, dx.Instruction.STATUS, error)
    # The SDK unstuffs in place and keeps the stuffed length of the list.
    sdk_params = bytes(packet[9 : 9 + len(params)])
    if dx.stuff(params) == params:
        assert sdk_params == params
    else:  # where it unstuffs, it reads our packets exactly as it reads its own
        assert sdk_params == bytes(
            _sdk_reads(_sdk_status(dxl_id, error, params))[0][9:][: len(params)]
        )
    assert dx.decode(ours) == dx.Status(dxl_id, error, params)


def test_sdk_remove_stuffing_loses_bytes() -> None:
    # dynamixel-sdk 4.1.0 (Python): removeStuffing compacts the list in place and then
    # tests bytes it has already moved, so some stuffed runs come back wrong, for its own
    # packets as for ours. Our decoder reads them as sent.
    params = b"\xff\xff\xfd\xff\xfd\xfd"
    ours = dx.encode(dx.Status(1, 0, params))
    assert ours == _sdk_status(1, 0, params)
    packet, result = _sdk_reads(ours)
    assert result == sdk.COMM_SUCCESS and bytes(packet[9:15]) != params
    assert dx.decode(ours) == dx.Status(1, 0, params)


# -- over a pty: the SDK talks to our simulated servos ----------------------------------------


async def test_sdk_drives_simulated_servos_over_a_pty() -> None:
    servos = [make_servo(1), make_servo(2, position=1000)]
    async with SimDynamixelBus(servos) as bus:
        port = sdk.PortHandler(bus.path)
        assert await in_thread(port.openPort)
        try:
            assert await in_thread(lambda: port.setBaudRate(BAUD))
            model, result, error = await in_thread(lambda: PH.ping(port, 1))
            assert (model, result, error) == (1020, sdk.COMM_SUCCESS, 0)
            _, result, _ = await in_thread(lambda: PH.ping(port, 9))
            assert result == sdk.COMM_RX_TIMEOUT  # nobody there

            position, result, error = await in_thread(
                lambda: PH.read4ByteTxRx(port, 2, X.PRESENT_POSITION.address)
            )
            assert (position, result, error) == (1000, sdk.COMM_SUCCESS, 0)
            # EEPROM locked while the torque is on: ACCESS_ERROR.
            await in_thread(lambda: PH.write1ByteTxRx(port, 1, X.TORQUE_ENABLE.address, 1))
            result, error = await in_thread(
                lambda: PH.write1ByteTxRx(port, 1, X.OPERATING_MODE.address, 1)
            )
            assert (result, error) == (sdk.COMM_SUCCESS, dx.ErrorNumber.ACCESS_ERROR)
            result, error = await in_thread(
                lambda: PH.write4ByteTxRx(port, 1, X.GOAL_POSITION.address, 2100)
            )
            assert (result, error) == (sdk.COMM_SUCCESS, 0)
            assert bus[1].get(X.GOAL_POSITION) == 2100

            writer = sdk.GroupSyncWrite(port, PH, X.PROFILE_VELOCITY.address, 4)
            writer.addParam(1, _u32(123))
            writer.addParam(2, _u32(456))
            assert await in_thread(writer.txPacket) == sdk.COMM_SUCCESS
            reader = sdk.GroupSyncRead(port, PH, X.PROFILE_VELOCITY.address, 4)
            reader.addParam(1)
            reader.addParam(2)
            assert await in_thread(reader.txRxPacket) == sdk.COMM_SUCCESS
            assert reader.getData(1, X.PROFILE_VELOCITY.address, 4) == 123
            assert reader.getData(2, X.PROFILE_VELOCITY.address, 4) == 456
            assert bus.corrupt_instructions == 0
        finally:
            port.closePort()


async def test_sim_answers_a_damaged_instruction_with_crc_error_to_the_sdk() -> None:
    async with SimDynamixelBus([make_servo(1), make_servo(2)]) as bus:
        port = sdk.PortHandler(bus.path)
        assert await in_thread(port.openPort)
        try:
            assert await in_thread(lambda: port.setBaudRate(BAUD))

            def send_damaged(packet: bytes) -> tuple[list[int], int]:
                damaged = bytearray(packet)
                damaged[-1] ^= 0x5A  # the CRC no longer matches
                port.writePort(bytes(damaged))
                port.setPacketTimeout(11)  # a status without params
                port.is_using = True
                result: tuple[list[int], int] = PH.rxPacket(port, False)
                return result

            packet, result = await in_thread(
                lambda: send_damaged(dx.encode(dx.Write(2, 116, _u32b(3000))))
            )
            assert result == sdk.COMM_SUCCESS
            assert (packet[4], packet[8]) == (2, dx.ErrorNumber.CRC_ERROR)
            assert PH.getRxPacketError(packet[8]) == "[RxPacketError] CRC doesn't match!"
            assert bus[2].get(X.GOAL_POSITION) != 3000  # not executed
            assert (bus[2].crc_errors, bus[1].crc_errors, bus.corrupt_instructions) == (1, 0, 1)

            # A damaged broadcast gets no answer.
            _, result = await in_thread(lambda: send_damaged(dx.encode(dx.Ping(dx.BROADCAST_ID))))
            assert result == sdk.COMM_RX_TIMEOUT
            # The bus goes on: the next good instruction is answered.
            model, result, error = await in_thread(lambda: PH.ping(port, 2))
            assert (model, result, error) == (1020, sdk.COMM_SUCCESS, 0)
        finally:
            port.closePort()
