"""Feetech SCS/STS serial-servo protocol codec, pure and byte-exact.

Packet (both directions; the Dynamixel Protocol 1.0 layout)::

    FF FF | id | length | instruction (or error) | params | checksum

``length`` counts the params + 2 (the instruction/error byte and the checksum); the checksum is
``~(id + length + instruction + sum(params)) & 0xFF``. There is no byte stuffing: a stream is
resynchronised on ``FF FF`` followed by a valid id, length and checksum, as the vendor's SDK
(``scservo_sdk``, ``protocol_packet_handler.rxPacket``) does. An instruction packet and a
status packet have the same shape: a stream is parsed as one or the other
(:class:`PacketParser` ``status=True`` on the host, False on a servo).

Instructions: PING 0x01, READ 0x02 (address, length), WRITE 0x03 (address, data), REG_WRITE
0x04 (held until ACTION), ACTION 0x05, RESET 0x06 (factory reset), SYNC READ 0x82 (STS/SMS:
address, length, ids; each servo answers with its own status, in the order of the ids), SYNC
WRITE 0x83 (address, length, then id + data per servo; no status). Address and length are one
byte each: the control table has 256 bytes at most.

Status error byte (:class:`StatusError`): bit 0 voltage, bit 1 angle (sensor), bit 2 overheat,
bit 3 overcurrent ("OverEle"), bit 5 overload. Unlike Dynamixel 2.0 these are the servo's
alarm flags, not a refusal: the instruction was executed.

Registers: the STS/SMS series are little-endian, the SCS series big-endian (the SDK's
``SCS_END`` 0 / 1). Signed values are sign-magnitude, not two's complement: bit 15 of a 16-bit
register on the STS (present position, present speed, goal speed, goal position in the
vendor's WritePosEx, present current), bit 10 for the present load, bit 11 for the homing
offset; bit 10 on the SCS's speed and load (:func:`to_sign_magnitude`,
:func:`from_sign_magnitude`, :class:`ControlItem` ``sign_bit``).

The STS3215 control table (:class:`STS`) and the SCS's (:class:`SCS`) are below, with units.
Addresses 0..39 are EEPROM: a write there takes effect at once and is kept at power-off only
while Lock (55 on the STS, 48 on the SCS) is 0 (the vendor's memory table: "Lock 0: values
written to EEPROM addresses are saved; 1: not saved"); the servo powers up locked.

Sources (facts, no code): the vendor's Python SDK (feetech-servo-sdk on PyPI,
github:ftservo/FTServo_Python: ``sms_sts.py``, ``scservo_def.py``), its C++ SDK (``SMS_STS.h``:
the baud rate table), LeRobot's ``motors/feetech/tables.py`` (the full STS/SMS and SCS tables,
model numbers).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from enum import IntEnum
from typing import Final, TypeAlias

from openel_serial.errors import FeetechChecksumError, FeetechDecodeError
from openel_serial.servocodec import (
    CENTER_TICK,
    RAD_PER_TICK,
    TICKS_PER_REV,
    DescribedFlag,
    check_item_lengths,
    rad_to_ticks,
    ticks_to_rad,
)

__all__ = [
    "ACCELERATION_UNIT_STEPS_S2",
    "BAUD_RATES",
    "BROADCAST_ID",
    "CENTER_TICK",
    "CURRENT_UNIT_A",
    "HEADER",
    "LOAD_UNIT",
    "MAX_ID",
    "MAX_LENGTH",
    "RETURN_DELAY_MAX",
    "RETURN_DELAY_UNIT_S",
    "SCS",
    "STATUS_OVERHEAD",
    "STS",
    "STS3215_MODEL",
    "TICKS_PER_REV",
    "VOLTAGE_UNIT_V",
    "Action",
    "ControlItem",
    "CorruptPacket",
    "FeetechChecksumError",
    "FeetechDecodeError",
    "FeetechMessage",
    "Instruction",
    "OperatingMode",
    "PacketParser",
    "Ping",
    "Read",
    "RegWrite",
    "Reset",
    "Status",
    "StatusError",
    "SyncRead",
    "SyncWrite",
    "SyncWriteItem",
    "Write",
    "checksum",
    "decode",
    "encode",
    "encode_sync_write",
    "from_sign_magnitude",
    "rad_s_to_speed",
    "rad_to_ticks",
    "speed_to_rad_s",
    "ticks_to_rad",
    "to_sign_magnitude",
]

HEADER: Final = b"\xff\xff"
BROADCAST_ID: Final = 0xFE
MAX_ID: Final = 0xFD
"""Largest servo id (0xFE is broadcast; 0xFF cannot follow the header)."""
MAX_LENGTH: Final = 250
"""Largest length byte accepted (the SDK's RXPACKET_MAX_LEN)."""
STATUS_OVERHEAD: Final = 6
"""Bytes of a status packet besides its params: header 2, id, length, error, checksum."""
_PREFIX: Final = 4  # header, id, length


class Instruction(IntEnum):
    PING = 0x01
    READ = 0x02
    WRITE = 0x03
    REG_WRITE = 0x04
    ACTION = 0x05
    RESET = 0x06
    SYNC_READ = 0x82
    SYNC_WRITE = 0x83


class StatusError(DescribedFlag):
    """Bits of a status packet's error byte (the SDK's ERRBIT_*): the servo's alarms."""

    VOLTAGE = 0x01
    ANGLE = 0x02
    OVERHEAT = 0x04
    OVERCURRENT = 0x08
    """The SDK's "OverEle"."""
    OVERLOAD = 0x20


class OperatingMode(IntEnum):
    """Operating Mode (33) of the STS/SMS."""

    POSITION = 0
    WHEEL = 1
    """Constant speed: Goal Speed (46, sign-magnitude bit 15) in steps/s."""
    PWM = 2
    STEP = 3


# --- sign-magnitude ----------------------------------------------------------------------


def to_sign_magnitude(value: int, sign_bit: int) -> int:
    """``value`` with its sign in bit ``sign_bit`` and its magnitude below (the SDK's
    ``SCS_TOSCS``); ValueError if the magnitude does not fit below the sign bit."""
    magnitude = -value if value < 0 else value
    if magnitude >= 1 << sign_bit:
        raise ValueError(f"{value} does not fit sign-magnitude with the sign in bit {sign_bit}")
    return magnitude | (1 << sign_bit) if value < 0 else magnitude


def from_sign_magnitude(raw: int, sign_bit: int) -> int:
    """The signed value of register contents ``raw`` (the SDK's ``SCS_TOHOST``)."""
    bit = 1 << sign_bit
    return -(raw & ~bit) if raw & bit else raw


# --- checksum and messages ---------------------------------------------------------------


def checksum(body: bytes | bytearray | memoryview) -> int:
    """``~sum(body) & 0xFF`` over id, length, instruction/error and params."""
    return ~sum(body) & 0xFF


def _check_id(servo_id: int, *, broadcast: bool = True) -> None:
    if not (0 <= servo_id <= MAX_ID or (broadcast and servo_id == BROADCAST_ID)):
        raise ValueError(f"Feetech id {servo_id} invalid")


def _check_byte(value: int, name: str) -> None:
    if not 0 <= value <= 0xFF:
        raise ValueError(f"{name} {value} is not a byte")


@dataclass(frozen=True, slots=True)
class Ping:
    id: int

    def __post_init__(self) -> None:
        _check_id(self.id)


@dataclass(frozen=True, slots=True)
class Read:
    id: int
    address: int
    length: int

    def __post_init__(self) -> None:
        _check_id(self.id)
        _check_byte(self.address, "address")
        _check_byte(self.length, "length")


@dataclass(frozen=True, slots=True)
class Write:
    id: int
    address: int
    data: bytes

    def __post_init__(self) -> None:
        _check_id(self.id)
        _check_byte(self.address, "address")


@dataclass(frozen=True, slots=True)
class RegWrite(Write):
    """Like :class:`Write`, applied at the next :class:`Action` (a subclass: match it first)."""


@dataclass(frozen=True, slots=True)
class Action:
    id: int = BROADCAST_ID

    def __post_init__(self) -> None:
        _check_id(self.id)


@dataclass(frozen=True, slots=True)
class Reset:
    """Factory reset (RESET 0x06)."""

    id: int

    def __post_init__(self) -> None:
        _check_id(self.id)


@dataclass(frozen=True, slots=True)
class SyncRead:
    """``length`` bytes at ``address`` of every servo of ``ids`` (sent to broadcast)."""

    address: int
    length: int
    ids: tuple[int, ...]

    def __post_init__(self) -> None:
        _check_byte(self.address, "address")
        _check_byte(self.length, "length")
        for servo_id in self.ids:
            _check_id(servo_id, broadcast=False)


@dataclass(frozen=True, slots=True)
class SyncWriteItem:
    id: int
    data: bytes

    def __post_init__(self) -> None:
        _check_id(self.id, broadcast=False)


@dataclass(frozen=True, slots=True)
class SyncWrite:
    address: int
    length: int
    items: tuple[SyncWriteItem, ...]

    def __post_init__(self) -> None:
        _check_byte(self.address, "address")
        _check_byte(self.length, "length")
        check_item_lengths(self.length, self.items)


@dataclass(frozen=True, slots=True)
class Status:
    """A status (reply) packet: the servo's alarm bits and the params a request asked for."""

    id: int
    error: int = 0
    params: bytes = b""

    def __post_init__(self) -> None:
        _check_id(self.id, broadcast=False)
        _check_byte(self.error, "error")

    @property
    def alarms(self) -> StatusError:
        return StatusError(self.error)


_new = object.__new__
_set_id: Callable[[Status, int], None] = vars(Status)["id"].__set__
_set_error: Callable[[Status, int], None] = vars(Status)["error"].__set__
_set_params: Callable[[Status, bytes], None] = vars(Status)["params"].__set__
"""The slots' setters: a parsed :class:`Status` is built without ``__init__`` and its
validation (the parser has checked the id and the error byte), 1 us less per status."""


@dataclass(frozen=True, slots=True)
class CorruptPacket:
    """A packet whose checksum did not match (what :meth:`PacketParser.feed_all` reports)."""

    id: int
    code: int
    """The instruction (or error) byte as received."""
    length: int


FeetechMessage: TypeAlias = (
    Ping | Read | Write | RegWrite | Action | Reset | SyncRead | SyncWrite | Status
)


def _frame(servo_id: int, code: int, params: bytes) -> bytes:
    length = len(params) + 2
    if length > 0xFF:
        raise ValueError(f"packet too long ({len(params)} params)")
    body = bytes((servo_id, length, code)) + params
    return HEADER + body + bytes((checksum(body),))


def encode(msg: FeetechMessage) -> bytes:
    """One complete packet, header to checksum (ValueError if it cannot be encoded)."""
    match msg:
        case Ping():
            return _frame(msg.id, Instruction.PING, b"")
        case Read():
            return _frame(msg.id, Instruction.READ, bytes((msg.address, msg.length)))
        case RegWrite():
            return _frame(msg.id, Instruction.REG_WRITE, bytes((msg.address,)) + msg.data)
        case Write():
            return _frame(msg.id, Instruction.WRITE, bytes((msg.address,)) + msg.data)
        case Action():
            return _frame(msg.id, Instruction.ACTION, b"")
        case Reset():
            return _frame(msg.id, Instruction.RESET, b"")
        case SyncRead():
            params = bytes((msg.address, msg.length)) + bytes(msg.ids)
            return _frame(BROADCAST_ID, Instruction.SYNC_READ, params)
        case SyncWrite():
            data = b"".join(bytes((item.id,)) + item.data for item in msg.items)
            return _frame(
                BROADCAST_ID, Instruction.SYNC_WRITE, bytes((msg.address, msg.length)) + data
            )
        case Status():
            return _frame(msg.id, msg.error, msg.params)
    raise TypeError(f"not a Feetech message: {msg!r}")


def encode_sync_write(address: int, length: int, data: Mapping[int, bytes]) -> bytes:
    """``encode(SyncWrite(address, length, items))`` for ``{id: data}``, built directly (the
    port's per-cycle write; the same checks, ValueError when one fails)."""
    _check_byte(address, "address")
    _check_byte(length, "length")
    params = bytearray((address, length))
    for servo_id, item in data.items():
        if not 0 <= servo_id <= MAX_ID:
            raise ValueError(f"Feetech id {servo_id} invalid")
        if len(item) != length:
            raise ValueError(f"id {servo_id}: {len(item)} bytes, expected {length}")
        params.append(servo_id)
        params += item
    return _frame(BROADCAST_ID, Instruction.SYNC_WRITE, bytes(params))


def _instruction(servo_id: int, code: int, params: bytes) -> FeetechMessage:
    def need(count: int, exact: bool = True) -> None:
        if len(params) < count or (exact and len(params) != count):
            raise FeetechDecodeError(
                f"{Instruction(code).name}: {len(params)} params, expected "
                f"{'' if exact else 'at least '}{count}"
            )

    try:
        match code:
            case Instruction.PING:
                need(0)
                return Ping(servo_id)
            case Instruction.READ:
                need(2)
                return Read(servo_id, params[0], params[1])
            case Instruction.WRITE:
                need(2, exact=False)
                return Write(servo_id, params[0], params[1:])
            case Instruction.REG_WRITE:
                need(2, exact=False)
                return RegWrite(servo_id, params[0], params[1:])
            case Instruction.ACTION:
                need(0)
                return Action(servo_id)
            case Instruction.RESET:
                need(0)
                return Reset(servo_id)
            case Instruction.SYNC_READ:
                need(3, exact=False)
                return SyncRead(params[0], params[1], tuple(params[2:]))
            case Instruction.SYNC_WRITE:
                need(2, exact=False)
                address, length = params[0], params[1]
                data = params[2:]
                size = length + 1
                if length == 0 or not data or len(data) % size:
                    raise FeetechDecodeError(
                        f"SYNC WRITE: {len(data)} bytes of items of {size} bytes each"
                    )
                items = tuple(
                    SyncWriteItem(data[i], data[i + 1 : i + size])
                    for i in range(0, len(data), size)
                )
                return SyncWrite(address, length, items)
    except ValueError as exc:  # an id out of range in the packet
        if isinstance(exc, FeetechDecodeError):
            raise
        raise FeetechDecodeError(str(exc)) from exc
    raise FeetechDecodeError(f"unknown instruction {code:#04x}")


def decode(packet: bytes, *, status: bool) -> FeetechMessage:
    """One complete packet: a :class:`Status` (``status=True``) or an instruction.

    Raises :class:`FeetechChecksumError` for a checksum mismatch and
    :class:`FeetechDecodeError` for anything else malformed.
    """
    if len(packet) < STATUS_OVERHEAD or packet[:2] != HEADER:
        raise FeetechDecodeError(f"not a packet: {packet.hex(' ')}")
    servo_id, length, code = packet[2], packet[3], packet[4]
    if length < 2 or len(packet) != _PREFIX + length:
        raise FeetechDecodeError(f"length byte {length} for {len(packet)} bytes")
    if checksum(packet[2:-1]) != packet[-1]:
        raise FeetechChecksumError(
            f"checksum {packet[-1]:#04x}, computed {checksum(packet[2:-1]):#04x}"
        )
    params = bytes(packet[5:-1])
    if status:
        if servo_id > MAX_ID:
            raise FeetechDecodeError(f"status from id {servo_id}")
        return Status(servo_id, code, params)
    if servo_id == 0xFF:
        raise FeetechDecodeError("id 0xFF")
    return _instruction(servo_id, code, params)


class PacketParser:
    """Decodes a byte stream into packets; never raises.

    ``status``: the stream carries status packets (the host's side) or instructions (a
    servo's). Garbage is skipped (``dropped_bytes``); a packet whose checksum fails is counted
    (``checksum_errors``) and its header skipped, so a real packet inside it is still found; a
    well-framed packet that does not decode (an unknown instruction) counts as ``malformed``.
    """

    def __init__(self, *, status: bool, max_length: int = MAX_LENGTH) -> None:
        self.status = status
        self.max_length = max_length
        self._buf = b""
        self.packets = 0
        self.checksum_errors = 0
        self.malformed = 0
        self.length_errors = 0
        self.dropped_bytes = 0

    def reset(self) -> None:
        self._buf = b""

    def feed(self, data: bytes) -> list[FeetechMessage]:
        return self._parse(data, False)  # type: ignore[return-value]  # no CorruptPacket

    def feed_all(self, data: bytes) -> list[FeetechMessage | CorruptPacket]:
        """Like :meth:`feed`, with a :class:`CorruptPacket` where a checksum failed."""
        return self._parse(data, True)

    def _parse(self, data: bytes, corrupt: bool) -> list[FeetechMessage | CorruptPacket]:
        buf = self._buf + bytes(data) if self._buf else bytes(data)
        n = len(buf)
        i = 0
        out: list[FeetechMessage | CorruptPacket] = []
        max_id = MAX_ID if self.status else BROADCAST_ID
        while True:
            start = buf.find(HEADER, i)
            if start < 0:
                keep = 1 if n > i and buf[-1] == 0xFF else 0
                self.dropped_bytes += n - keep - i
                i = n - keep
                break
            self.dropped_bytes += start - i
            i = start
            if n - i < _PREFIX:
                break
            servo_id, length = buf[i + 2], buf[i + 3]
            if servo_id > max_id:  # FF FF FF: the header may start one byte later
                self.dropped_bytes += 1
                i += 1
                continue
            if not 2 <= length <= self.max_length:
                self.length_errors += 1
                self.dropped_bytes += 1
                i += 1
                continue
            total = _PREFIX + length
            if n - i < total:
                break
            end = i + total - 1
            if checksum(buf[i + 2 : end]) != buf[end]:
                self.checksum_errors += 1
                if corrupt:
                    out.append(CorruptPacket(servo_id, buf[i + 4], length))
                self.dropped_bytes += 2
                i += 2
                continue
            code = buf[i + 4]
            params = buf[i + 5 : end]
            msg: FeetechMessage
            if self.status:  # id and error byte checked above: no dataclass validation
                msg = _new(Status)
                _set_id(msg, servo_id)
                _set_error(msg, code)
                _set_params(msg, params)
            else:
                try:
                    msg = _instruction(servo_id, code, params)
                except FeetechDecodeError:
                    self.malformed += 1
                    self.dropped_bytes += total
                    i += total
                    continue
            i += total
            self.packets += 1
            out.append(msg)
        self._buf = buf[i:] if i < n else b""
        return out


# --- control tables ----------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class ControlItem:
    """A control-table register: ``size`` bytes at ``address``; ``sign_bit``: sign-magnitude
    with the sign in that bit (None: unsigned); ``big_endian``: the SCS's byte order."""

    address: int
    size: int
    sign_bit: int | None = None
    big_endian: bool = False
    read_only: bool = False

    @property
    def eeprom(self) -> bool:
        return self.address < 40

    def encode(self, value: int) -> bytes:
        raw = value if self.sign_bit is None else to_sign_magnitude(value, self.sign_bit)
        try:
            return raw.to_bytes(self.size, "big" if self.big_endian else "little")
        except OverflowError as exc:
            raise ValueError(f"{value} does not fit {self}") from exc

    def decode(self, data: bytes | bytearray | memoryview) -> int:
        if len(data) != self.size:
            raise FeetechDecodeError(
                f"item at {self.address} is {self.size} bytes, got {len(data)}"
            )
        raw = int.from_bytes(data, "big" if self.big_endian else "little")
        return raw if self.sign_bit is None else from_sign_magnitude(raw, self.sign_bit)

    def of(self, block: bytes | bytearray, start: int) -> int:
        """This item's value in ``block``, the bytes read from address ``start`` on."""
        offset = self.address - start
        return self.decode(block[offset : offset + self.size])


def _item(address: int, size: int, sign_bit: int | None = None, *, ro: bool = False) -> ControlItem:
    return ControlItem(address, size, sign_bit, big_endian=False, read_only=ro)


class STS:
    """The STS/SMS series' control table (STS3215), little-endian.

    EEPROM (0..39; kept at power-off only while LOCK is 0) and SRAM (40..). Units: positions
    in steps (4096 per turn on the STS3215), speeds in steps/s, acceleration in 100 steps/s^2
    (0: the fastest), voltages in 0.1 V, temperatures in deg C, torque/load in 0.1 % of the
    stall torque, current in 6.5 mA, Return Delay in 2 us, Protection Time in 10 ms.
    """

    FIRMWARE_MAJOR: Final = _item(0, 1, ro=True)
    FIRMWARE_MINOR: Final = _item(1, 1, ro=True)
    MODEL_NUMBER: Final = _item(3, 2, ro=True)
    ID: Final = _item(5, 1)
    BAUD_RATE: Final = _item(6, 1)
    RETURN_DELAY: Final = _item(7, 1)
    RESPONSE_STATUS_LEVEL: Final = _item(8, 1)
    """0: a status only for PING and READ; 1: for every instruction addressed to the servo."""
    MIN_ANGLE_LIMIT: Final = _item(9, 2)
    MAX_ANGLE_LIMIT: Final = _item(11, 2)
    MAX_TEMPERATURE: Final = _item(13, 1)
    MAX_VOLTAGE: Final = _item(14, 1)
    MIN_VOLTAGE: Final = _item(15, 1)
    MAX_TORQUE: Final = _item(16, 2)
    PHASE: Final = _item(18, 1)
    UNLOADING_CONDITION: Final = _item(19, 1)
    """The :class:`StatusError` bits that turn the torque off ("unload") when they trip."""
    LED_ALARM_CONDITION: Final = _item(20, 1)
    P_COEFFICIENT: Final = _item(21, 1)
    D_COEFFICIENT: Final = _item(22, 1)
    I_COEFFICIENT: Final = _item(23, 1)
    MINIMUM_STARTUP_FORCE: Final = _item(24, 2)
    CW_DEAD_ZONE: Final = _item(26, 1)
    CCW_DEAD_ZONE: Final = _item(27, 1)
    PROTECTION_CURRENT: Final = _item(28, 2)
    ANGULAR_RESOLUTION: Final = _item(30, 1)
    HOMING_OFFSET: Final = _item(31, 2, 11)
    """Present Position = the encoder's position - HOMING_OFFSET (sign-magnitude, bit 11)."""
    OPERATING_MODE: Final = _item(33, 1)
    PROTECTIVE_TORQUE: Final = _item(34, 1)
    PROTECTION_TIME: Final = _item(35, 1)
    OVERLOAD_TORQUE: Final = _item(36, 1)
    TORQUE_ENABLE: Final = _item(40, 1)
    """0 off, 1 on, 128: make the present position read 2048 (writes HOMING_OFFSET)."""
    ACCELERATION: Final = _item(41, 1)
    GOAL_POSITION: Final = _item(42, 2, 15)
    GOAL_TIME: Final = _item(44, 2)
    GOAL_SPEED: Final = _item(46, 2, 15)
    TORQUE_LIMIT: Final = _item(48, 2)
    LOCK: Final = _item(55, 1)
    PRESENT_POSITION: Final = _item(56, 2, 15, ro=True)
    PRESENT_SPEED: Final = _item(58, 2, 15, ro=True)
    PRESENT_LOAD: Final = _item(60, 2, 10, ro=True)
    PRESENT_VOLTAGE: Final = _item(62, 1, ro=True)
    PRESENT_TEMPERATURE: Final = _item(63, 1, ro=True)
    ASYNC_WRITE_FLAG: Final = _item(64, 1, ro=True)
    SERVO_STATUS: Final = _item(65, 1, ro=True)
    """The :class:`StatusError` bits in force (as in the status packets' error byte)."""
    MOVING: Final = _item(66, 1, ro=True)
    PRESENT_CURRENT: Final = _item(69, 2, 15, ro=True)
    TABLE_SIZE: Final = 86
    """Addresses 0..85 (Maximum Acceleration, 85-86, is beyond the published table)."""


def _scs(address: int, size: int, sign_bit: int | None = None, *, ro: bool = False) -> ControlItem:
    return ControlItem(address, size, sign_bit, big_endian=True, read_only=ro)


class SCS:
    """The SCS series' control table (SCS0009, SCS15...): big-endian, 1024 steps over its
    range; speed and load signed in bit 10; Lock at 48."""

    MODEL_NUMBER: Final = _scs(3, 2, ro=True)
    ID: Final = _scs(5, 1)
    BAUD_RATE: Final = _scs(6, 1)
    RETURN_DELAY: Final = _scs(7, 1)
    RESPONSE_STATUS_LEVEL: Final = _scs(8, 1)
    MIN_ANGLE_LIMIT: Final = _scs(9, 2)
    MAX_ANGLE_LIMIT: Final = _scs(11, 2)
    TORQUE_ENABLE: Final = _scs(40, 1)
    GOAL_POSITION: Final = _scs(42, 2)
    GOAL_TIME: Final = _scs(44, 2)
    GOAL_SPEED: Final = _scs(46, 2, 10)
    LOCK: Final = _scs(48, 1)
    PRESENT_POSITION: Final = _scs(56, 2, ro=True)
    PRESENT_SPEED: Final = _scs(58, 2, 10, ro=True)
    PRESENT_LOAD: Final = _scs(60, 2, 10, ro=True)
    PRESENT_VOLTAGE: Final = _scs(62, 1, ro=True)
    PRESENT_TEMPERATURE: Final = _scs(63, 1, ro=True)
    MOVING: Final = _scs(66, 1, ro=True)


# --- units -------------------------------------------------------------------------------

STS3215_MODEL: Final = 777
"""Model Number (3) of the STS3215 (LeRobot's MODEL_NUMBER_TABLE)."""
ACCELERATION_UNIT_STEPS_S2: Final = 100
LOAD_UNIT: Final = 0.001
"""Present Load (60) unit: 0.1 % of the stall torque."""
VOLTAGE_UNIT_V: Final = 0.1
CURRENT_UNIT_A: Final = 0.0065
RETURN_DELAY_UNIT_S: Final = 2e-6
RETURN_DELAY_MAX: Final = 254
BAUD_RATES: Final = (1_000_000, 500_000, 250_000, 128_000, 115_200, 76_800, 57_600, 38_400)
"""Baud Rate (6) setting -> bit/s, settings 0..7 (the vendor's SMS_STS.h; LeRobot's table
has 57600, 38400, 19200 at 5..7 instead)."""


def speed_to_rad_s(steps_s: int | float) -> float:
    return steps_s * RAD_PER_TICK


def rad_s_to_speed(rad_s: float) -> int:
    return round(rad_s / RAD_PER_TICK)
