"""Interop with Feetech's own implementation, feetech-servo-sdk (``scservo_sdk``).

Packet level: the SDK's packet handler and GroupSync* build their instruction packets on a
recording port handler; ours are byte-identical. Wire level, both ways:

* the SDK's PortHandler opens our simulated bus's pty (pyserial) and drives the simulated
  STS3215s: ping, 1- and 2-byte reads and writes of every register of the STS table, the
  sign-magnitude registers, GroupSyncRead / GroupSyncWrite, the lock, a damaged packet;
* our FeetechPort drives a peer whose packets are the SDK's: a fake servo on the other end of a
  pty that parses our instructions with the SDK's ``rxPacket`` and answers with packets framed
  by the SDK's ``txPacket`` (checksum and all).

The SDK's blocking calls run in worker threads, each bounded by its own packet timeout and by
``anyio.fail_after``.
"""

from __future__ import annotations

import os
import threading
from collections.abc import AsyncIterator, Iterator
from typing import Any

import anyio
import pytest
import scservo_sdk as sdk

from openel_serial import feetech as ft
from openel_serial.feetech_peers import SimFeetechBus, SimStsServo
from openel_serial.feetech_port import FeetechPort
from openel_serial.ptypeer import PtyPort

from .conftest import BAUD, RecordingPort, in_thread

pytestmark = pytest.mark.timeout(60)

S = ft.STS
PH = sdk.PacketHandler(0)  # STS/SMS: little-endian (SCS_END = 0)


# -- packet level ----------------------------------------------------------------------------


def test_sdk_instruction_packets_equal_ours() -> None:
    port: Any = RecordingPort()
    PH.ping(port, 1)
    PH.read2ByteTxRx(port, 3, S.PRESENT_POSITION.address)
    PH.write1ByteTxRx(port, 4, S.TORQUE_ENABLE.address, 1)
    PH.write2ByteTxRx(port, 5, S.GOAL_POSITION.address, 3000)
    PH.regWriteTxRx(port, 6, S.GOAL_POSITION.address, 2, [0x00, 0x08])
    PH.action(port, ft.BROADCAST_ID)
    writer = sdk.GroupSyncWrite(port, PH, S.GOAL_POSITION.address, 2)
    writer.addParam(1, [0x00, 0x08])
    writer.addParam(2, [0xFF, 0x0F])
    writer.txPacket()
    reader = sdk.GroupSyncRead(port, PH, S.PRESENT_POSITION.address, 15)
    for i in (1, 2, 3):
        reader.addParam(i)
    reader.txPacket()
    assert port.written == [
        ft.encode(ft.Ping(1)),
        ft.encode(ft.Read(3, 56, 2)),
        ft.encode(ft.Write(4, 40, b"\x01")),
        ft.encode(ft.Write(5, 42, (3000).to_bytes(2, "little"))),
        ft.encode(ft.RegWrite(6, 42, b"\x00\x08")),
        ft.encode(ft.Action()),
        ft.encode(
            ft.SyncWrite(
                42, 2, (ft.SyncWriteItem(1, b"\x00\x08"), ft.SyncWriteItem(2, b"\xff\x0f"))
            )
        ),
        ft.encode(ft.SyncRead(56, 15, (1, 2, 3))),
    ]


def test_sdk_parses_our_status_packets() -> None:
    status = ft.encode(ft.Status(7, 0x20, (2100).to_bytes(2, "little")))
    port: Any = RecordingPort(b"\x00\xff" + status)  # a glitch first
    value, result, error = PH.read2ByteTxRx(port, 7, S.PRESENT_POSITION.address)
    assert (value, result, error) == (2100, sdk.COMM_SUCCESS, 0x20)


# -- the SDK drives our simulated servos -------------------------------------------------------


def _every_register() -> list[tuple[str, ft.ControlItem]]:
    return [(name, item) for name, item in vars(S).items() if isinstance(item, ft.ControlItem)]


async def test_sdk_drives_simulated_servos_over_a_pty() -> None:
    servos = [SimStsServo(1), SimStsServo(2, position=1000)]
    async with SimFeetechBus(servos) as bus:
        port = sdk.PortHandler(bus.path)
        assert await in_thread(port.openPort)
        try:
            assert await in_thread(lambda: port.setBaudRate(BAUD))
            model, result, error = await in_thread(lambda: PH.ping(port, 1))
            assert (model, result, error) == (ft.STS3215_MODEL, sdk.COMM_SUCCESS, 0)
            _, result, _ = await in_thread(lambda: PH.ping(port, 9))
            assert result == sdk.COMM_RX_TIMEOUT  # nobody there

            # Every register of the table, read with the SDK's 1-/2-byte reads.
            for name, item in _every_register():
                read = PH.read1ByteTxRx if item.size == 1 else PH.read2ByteTxRx
                raw, result, error = await in_thread(lambda r=read, a=item.address: r(port, 2, a))
                assert (result, error) == (sdk.COMM_SUCCESS, 0), name
                expected = bus[2].get(item)
                sign = item.sign_bit
                assert (raw if sign is None else sdk.SCS_TOHOST(raw, sign)) == expected, name
            position, _, _ = await in_thread(lambda: PH.read2ByteTxRx(port, 2, 56))
            assert position == 1000

            # Writes of every writable register (RAM and, unlocked, EEPROM), read back.
            writable = {
                S.RETURN_DELAY: 3,
                S.MIN_ANGLE_LIMIT: 100,
                S.MAX_ANGLE_LIMIT: 4000,
                S.MAX_TEMPERATURE: 65,
                S.MAX_VOLTAGE: 130,
                S.MIN_VOLTAGE: 45,
                S.MAX_TORQUE: 900,
                S.PHASE: 0,
                S.UNLOADING_CONDITION: 44,
                S.P_COEFFICIENT: 16,
                S.D_COEFFICIENT: 32,
                S.I_COEFFICIENT: 0,
                S.CW_DEAD_ZONE: 0,
                S.CCW_DEAD_ZONE: 0,
                S.PROTECTION_CURRENT: 400,
                S.HOMING_OFFSET: 0,
                S.OPERATING_MODE: 0,
                S.PROTECTIVE_TORQUE: 20,
                S.PROTECTION_TIME: 200,
                S.OVERLOAD_TORQUE: 80,
                S.ACCELERATION: 50,
                S.GOAL_TIME: 0,
                S.GOAL_SPEED: 800,
                S.TORQUE_LIMIT: 900,
            }
            assert await in_thread(lambda: PH.write1ByteTxRx(port, 1, S.LOCK.address, 0)) == (
                sdk.COMM_SUCCESS,
                0,
            )
            for item, value in writable.items():
                write = PH.write1ByteTxRx if item.size == 1 else PH.write2ByteTxRx
                assert await in_thread(
                    lambda w=write, a=item.address, v=value: w(port, 1, a, v)
                ) == (sdk.COMM_SUCCESS, 0)
                assert bus[1].get(item) == value, item
            await in_thread(lambda: PH.write1ByteTxRx(port, 1, S.LOCK.address, 1))

            # Sign-magnitude: a negative homing offset (bit 11) and wheel speed (bit 15).
            await in_thread(
                lambda: PH.write2ByteTxRx(port, 1, S.HOMING_OFFSET.address, sdk.SCS_TOSCS(-48, 11))
            )
            assert bus[1].get(S.HOMING_OFFSET) == -48
            assert bus[1].get(S.PRESENT_POSITION) == 2048 + 48

            # Position move: torque on, goal position; the servo moves there.
            await in_thread(lambda: PH.write1ByteTxRx(port, 2, S.TORQUE_ENABLE.address, 1))
            await in_thread(lambda: PH.write2ByteTxRx(port, 2, S.GOAL_POSITION.address, 1200))
            for _ in range(300):  # 3 s at most
                moving, _, _ = await in_thread(lambda: PH.read1ByteTxRx(port, 2, S.MOVING.address))
                if not moving:
                    break
                await anyio.sleep(0.01)
            position, _, _ = await in_thread(lambda: PH.read2ByteTxRx(port, 2, 56))
            assert position == 1200

            # GroupSyncWrite of goals, GroupSyncRead of the present block 56..70.
            writer = sdk.GroupSyncWrite(port, PH, S.GOAL_SPEED.address, 2)
            writer.addParam(1, [0x20, 0x03])
            writer.addParam(2, [0x40, 0x06])
            assert await in_thread(writer.txPacket) == sdk.COMM_SUCCESS
            reader = sdk.GroupSyncRead(port, PH, S.PRESENT_POSITION.address, 15)
            reader.addParam(1)
            reader.addParam(2)
            assert await in_thread(reader.txRxPacket) == sdk.COMM_SUCCESS
            assert reader.getData(2, S.PRESENT_POSITION.address, 2) == 1200
            assert reader.getData(1, S.PRESENT_VOLTAGE.address, 1) == 120
            # The statuses came after the SYNC WRITE was handled (one stream, in order).
            assert (bus[1].get(S.GOAL_SPEED), bus[2].get(S.GOAL_SPEED)) == (800, 1600)
            assert bus.corrupt_instructions == 0
        finally:
            port.closePort()


async def test_sim_drops_a_damaged_packet_and_the_sdk_times_out() -> None:
    async with SimFeetechBus([SimStsServo(1)]) as bus:
        port = sdk.PortHandler(bus.path)
        assert await in_thread(port.openPort)
        try:

            def send_damaged() -> tuple[list[int], int]:
                damaged = bytearray(ft.encode(ft.Write(1, 42, b"\x00\x09")))
                damaged[-1] ^= 0x5A
                port.writePort(bytes(damaged))
                port.setPacketTimeout(6)
                port.is_using = True
                result: tuple[list[int], int] = PH.rxPacket(port)
                return result

            _, result = await in_thread(send_damaged)
            assert result == sdk.COMM_RX_TIMEOUT
            assert bus.corrupt_instructions == 1
            assert bus[1].get(S.GOAL_POSITION) == 2048  # not executed
        finally:
            port.closePort()


# -- our driver drives a servo made of the SDK's packet code -----------------------------------


class SdkServo:
    """A fake STS servo on the device end of a pty whose packets are the SDK's: every
    instruction we send is checked against the SDK's own framing of it (``txPacket`` on a
    recording port: header, length, checksum -- the SDK's status parser ``rxPacket`` refuses
    a code byte above 0x7F, so it cannot read a SYNC READ), and every status is framed by the
    SDK's ``txPacket``."""

    def __init__(self, pty: PtyPort, servo_id: int) -> None:
        self.pty = pty
        self.id = servo_id
        self.table = bytearray(S.TABLE_SIZE)
        self.table[S.MODEL_NUMBER.address : S.MODEL_NUMBER.address + 2] = S.MODEL_NUMBER.encode(
            ft.STS3215_MODEL
        )
        self.table[S.ID.address] = servo_id
        self.table[56:58] = S.PRESENT_POSITION.encode(2500)
        self.table[58:60] = S.PRESENT_SPEED.encode(-20)
        self.table[60:62] = S.PRESENT_LOAD.encode(-150)
        self.table[62] = 74
        self.is_using = False
        self._stop = threading.Event()
        self.handled: list[int] = []
        self.rejected = 0

    # the PortHandler interface of the SDK's txPacket
    def clearPort(self) -> None:
        pass

    def writePort(self, packet: list[int]) -> int:
        return os.write(self.pty._fd(), bytes(packet))

    def _frames(self) -> Iterator[bytes]:
        buf = b""
        while not self._stop.is_set():
            try:
                buf += os.read(self.pty._fd(), 256)
            except BlockingIOError:
                self._stop.wait(0.0005)
                continue
            while len(buf) >= 4:
                start = buf.find(b"\xff\xff")
                if start < 0:
                    buf = b""
                    break
                buf = buf[start:]
                total = buf[3] + 4
                if len(buf) < total:
                    break
                yield buf[:total]
                buf = buf[total:]

    def serve(self) -> None:
        for frame in self._frames():
            servo_id, instruction, params = frame[2], frame[4], list(frame[5:-1])
            check: Any = RecordingPort()
            PH.txPacket(check, [0, 0, servo_id, frame[3], instruction, *params, 0])
            if check.written != [frame]:
                self.rejected += 1  # the SDK would compute another checksum
                continue
            self.handled.append(instruction)
            reply: list[int] | None = None
            if instruction == sdk.INST_SYNC_READ:
                address, length, ids = params[0], params[1], params[2:]
                if self.id in ids:
                    reply = list(self.table[address : address + length])
            elif servo_id != self.id:
                continue
            elif instruction == sdk.INST_PING:
                reply = []
            elif instruction == sdk.INST_READ:
                reply = list(self.table[params[0] : params[0] + params[1]])
            elif instruction == sdk.INST_WRITE:
                self.table[params[0] : params[0] + len(params) - 1] = bytes(params[1:])
                reply = []
            if reply is None:
                continue
            PH.txPacket(self, [0, 0, self.id, len(reply) + 2, 0x00, *reply, 0])
            self.is_using = False

    def stop(self) -> None:
        self._stop.set()


@pytest.fixture
async def sdk_servo() -> AsyncIterator[tuple[PtyPort, SdkServo]]:
    pty = PtyPort()
    pty.open()
    servo = SdkServo(pty, 3)
    thread = threading.Thread(target=servo.serve, daemon=True)
    thread.start()
    try:
        yield pty, servo
    finally:
        servo.stop()
        await anyio.to_thread.run_sync(thread.join, 2.0)
        pty.remove()


async def test_our_port_drives_a_servo_built_from_the_sdk(
    sdk_servo: tuple[PtyPort, SdkServo],
) -> None:
    pty, servo = sdk_servo
    async with FeetechPort(
        str(pty.path), baudrate=BAUD, return_delay=0, timeout_margin=0.1, retries=0
    ) as port:
        with anyio.fail_after(5):
            info = await port.ping(3)
            assert info.model_number == ft.STS3215_MODEL
            assert await port.read_item(3, S.PRESENT_POSITION) == 2500
            assert await port.write_item(3, S.GOAL_POSITION, 1234) == 0
            assert servo.table[42:44] == (1234).to_bytes(2, "little")
            await port.write_item(3, S.GOAL_SPEED, -300)
            assert servo.table[46:48] == (300 | 0x8000).to_bytes(2, "little")
            block = await port.sync_read([3], 56, 15)
            assert S.PRESENT_SPEED.of(block[3], 56) == -20
            assert S.PRESENT_LOAD.of(block[3], 56) == -150
            assert S.PRESENT_VOLTAGE.of(block[3], 56) == 74
    assert sdk.INST_SYNC_READ in servo.handled
    assert servo.rejected == 0
