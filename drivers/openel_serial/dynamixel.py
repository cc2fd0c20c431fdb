"""Dynamixel Protocol 2.0 codec (ROBOTIS e-manual), pure and byte-exact.

Packet: ``FF FF FD 00 | id | length (u16 LE) | instruction | params | CRC (u16 LE)``.
``length`` counts instruction + (stuffed) params + CRC. The CRC-16 (poly 0x8005,
init 0, no reflection: the ROBOTIS table algorithm) covers every byte from the
header to the last param, after byte stuffing. Stuffing inserts an extra 0xFD
after each ``FF FF FD`` inside instruction + params, so a header can never
appear inside a packet.

:func:`decode` takes one complete packet and raises only
:class:`~openel_serial.errors.DynamixelDecodeError` (CRC mismatches as its
subclass :class:`~openel_serial.errors.DynamixelCrcError`). :class:`PacketParser`
decodes a byte stream and never raises. Encoders raise :class:`ValueError`.

Also: X-series (XM430/XL430) control table items and unit conversions.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable
from dataclasses import dataclass
from enum import IntEnum
from typing import Final, TypeAlias

from fastcrc.crc16 import umts as _umts

from openel_serial.dynamixel_table import (
    ACCELERATION_UNIT_RPM2,
    BAUD_RATES,
    BUS_WATCHDOG_ERROR,
    BUS_WATCHDOG_FIRMWARE,
    BUS_WATCHDOG_MAX,
    BUS_WATCHDOG_UNIT_S,
    CURRENT_UNIT_A,
    PWM_FULL_SCALE,
    RETURN_DELAY_MAX,
    RETURN_DELAY_UNIT_S,
    VELOCITY_UNIT_RPM,
    VOLTAGE_UNIT_V,
    ControlItem,
    HardwareError,
    MovingStatus,
    OperatingMode,
    XSeries,
    acceleration_to_rad_s2,
    amps_to_current,
    bus_watchdog_units,
    current_to_amps,
    rad_s2_to_acceleration,
    rad_s_to_velocity,
    velocity_to_rad_s,
)
from openel_serial.errors import DynamixelCrcError, DynamixelDecodeError
from openel_serial.servocodec import (
    CENTER_TICK,
    TICKS_PER_REV,
    check_item_lengths,
    rad_to_ticks,
    ticks_to_rad,
)

__all__ = [
    "ACCELERATION_UNIT_RPM2",
    "ALERT_BIT",
    "BAUD_RATES",
    "BROADCAST_ID",
    "BUS_WATCHDOG_ERROR",
    "BUS_WATCHDOG_FIRMWARE",
    "BUS_WATCHDOG_MAX",
    "BUS_WATCHDOG_UNIT_S",
    "CENTER_TICK",
    "CLEAR_KEY",
    "CURRENT_UNIT_A",
    "HEADER",
    "MAX_ID",
    "PWM_FULL_SCALE",
    "RETURN_DELAY_MAX",
    "RETURN_DELAY_UNIT_S",
    "TICKS_PER_REV",
    "VELOCITY_UNIT_RPM",
    "VOLTAGE_UNIT_V",
    "Action",
    "BulkRead",
    "BulkReadItem",
    "BulkWrite",
    "BulkWriteItem",
    "Clear",
    "ControlItem",
    "CorruptPacket",
    "DynamixelCrcError",
    "DynamixelDecodeError",
    "DynamixelMessage",
    "ErrorNumber",
    "FactoryReset",
    "FactoryResetMode",
    "FastSyncRead",
    "HardwareError",
    "Instruction",
    "MovingStatus",
    "OperatingMode",
    "PacketParser",
    "Ping",
    "Read",
    "Reboot",
    "RegWrite",
    "Status",
    "SyncRead",
    "SyncWrite",
    "SyncWriteItem",
    "Write",
    "XSeries",
    "acceleration_to_rad_s2",
    "amps_to_current",
    "bus_watchdog_units",
    "crc16",
    "current_to_amps",
    "decode",
    "encode",
    "rad_s2_to_acceleration",
    "rad_s_to_velocity",
    "rad_to_ticks",
    "stuff",
    "ticks_to_rad",
    "unstuff",
    "velocity_to_rad_s",
]

HEADER: Final = b"\xff\xff\xfd\x00"
BROADCAST_ID: Final = 0xFE
MAX_ID: Final = 0xFC  # 253 (0xFD) and 255 (0xFF) would clash with the header bytes
_PREFIX_LEN: Final = 7  # header + id + length
_CRC_LEN: Final = 2
_HEADER_LEN: Final = 4
_STATUS_OVERHEAD: Final = 11  # header 4, id, length 2, instruction, error, CRC 2
_BULK_LAYOUT_CACHE: Final = 64
_BULK_MIN: Final = 3
"""From this many statuses on, PacketParser.feed_bulk checks their fixed bytes with extended
slices (each CRC on its own); fewer are unpacked one by one."""
_BulkLayout: TypeAlias = tuple[tuple[tuple[int, bytes], ...], struct.Struct]
_BULK_LAYOUTS: dict[tuple[int, int], _BulkLayout] = {}


def _bulk_layout(param_length: int, count: int) -> _BulkLayout:
    """``count`` statuses of ``param_length`` params back to back, without stuffing: each
    fixed byte's offset in a packet with that byte repeated ``count`` times (what the
    extended slice ``data[offset::size]`` must equal), and the layout of every params
    (for fewer than :data:`_BULK_MIN`: no offsets, and the layout of one packet's fields)."""
    wire_length = param_length + 4  # instruction, error, params, CRC
    fixed = (
        *((offset, HEADER[offset : offset + 1]) for offset in range(4)),
        (5, bytes((wire_length & 0xFF,))),
        (6, bytes((wire_length >> 8,))),
        (7, bytes((_STATUS,))),
    )
    if count < _BULK_MIN:  # a packet's fields (PacketParser.feed_bulk unpacks each once)
        return (), struct.Struct(f"<4sBHBB{param_length}sH")
    return (
        tuple((offset, byte * count) for offset, byte in fixed),
        struct.Struct("<" + f"9x{param_length}s2x" * count),
    )


def _lone_status(
    data: bytes, layout: struct.Struct, param_length: int
) -> tuple[int, int, bytes] | None:
    """``(id, error, params)`` of the one unstuffed status of ``param_length`` params that
    ``data`` is (``layout``: its fields), when every check of the parser passes."""
    header, dxl_id, length, instruction, error, params, crc = layout.unpack(data)
    if (
        header != HEADER
        or length != param_length + 4
        or instruction != _STATUS
        or dxl_id > MAX_ID
        or _umts(data[:-_CRC_LEN]) != crc
    ):
        return None
    return dxl_id, error, params


def _crcs_match(data: bytes, size: int, count: int) -> bool:
    """Whether each of the ``count`` packets of ``size`` bytes that make up ``data`` ends
    with the CRC of the rest of it: every packet checked on its own, as the protocol
    defines. (One CRC pass over the whole run, with each CRC's bytes swapped, would be
    cheaper, but 4 or more bits flipped across two packets could cancel out there: the odds
    of two damaged packets passing would be those of one, 2^-16 instead of 2^-32.)"""
    if count == 1:
        return _umts(data[:-_CRC_LEN]) == data[-2] | data[-1] << 8
    body = size - _CRC_LEN
    for j in range(0, len(data), size):
        end = j + body
        if _umts(data[j:end]) != data[end] | data[end + 1] << 8:
            return False
    return True


_STUFF_PATTERN: Final = b"\xff\xff\xfd"
_STATUS: Final = 0x55  # Instruction.STATUS as a plain int (fast comparison)


class Instruction(IntEnum):
    PING = 0x01
    READ = 0x02
    WRITE = 0x03
    REG_WRITE = 0x04
    ACTION = 0x05
    FACTORY_RESET = 0x06
    REBOOT = 0x08
    CLEAR = 0x10
    STATUS = 0x55
    SYNC_READ = 0x82
    SYNC_WRITE = 0x83
    FAST_SYNC_READ = 0x8A
    BULK_READ = 0x92
    BULK_WRITE = 0x93


class ErrorNumber(IntEnum):
    """Status packet error number (bits 0..6 of the error byte)."""

    NONE = 0x00
    RESULT_FAIL = 0x01
    INSTRUCTION_ERROR = 0x02
    CRC_ERROR = 0x03
    DATA_RANGE_ERROR = 0x04
    DATA_LENGTH_ERROR = 0x05
    DATA_LIMIT_ERROR = 0x06
    ACCESS_ERROR = 0x07


#: Bit 7 of the status error byte: check Hardware Error Status (address 70).
ALERT_BIT: Final = 0x80


class FactoryResetMode(IntEnum):
    ALL = 0xFF
    EXCEPT_ID = 0x01
    EXCEPT_ID_AND_BAUDRATE = 0x02


# --- CRC and stuffing ----------------------------------------------------------------------


def crc16(data: bytes | bytearray | memoryview, crc: int = 0) -> int:
    """ROBOTIS ``update_crc``: CRC-16 poly 0x8005, MSB first, initial value ``crc``.

    This is CRC-16/UMTS (no reflection, no final xor), computed by ``fastcrc`` (Rust):
    about 0.06 µs for a status packet where a pure-Python table loop takes 1 µs.
    """
    return _umts(data, crc)


def stuff(data: bytes) -> bytes:
    """Insert 0xFD after every ``FF FF FD`` (patterns cannot overlap since FD != FF)."""
    return data.replace(_STUFF_PATTERN, _STUFF_PATTERN + b"\xfd")


def unstuff(data: bytes) -> bytes:
    """Inverse of :func:`stuff`; a pattern not followed by 0xFD is a decode error."""
    out = bytearray()
    i = 0
    while True:
        j = data.find(_STUFF_PATTERN, i)
        if j < 0:
            out += data[i:]
            return bytes(out)
        end = j + len(_STUFF_PATTERN)
        if data[end : end + 1] != b"\xfd":
            raise DynamixelDecodeError(f"unstuffed FF FF FD at offset {j}")
        out += data[i:end]
        i = end + 1


# --- Messages ------------------------------------------------------------------------------


def _check_id(dxl_id: int, *, broadcast: bool = True) -> None:
    if not (0 <= dxl_id <= MAX_ID or (broadcast and dxl_id == BROADCAST_ID)):
        raise ValueError(f"Dynamixel id {dxl_id} invalid")


def _check_u16(value: int, name: str) -> None:
    if not 0 <= value <= 0xFFFF:
        raise ValueError(f"{name} {value} is not a u16")


@dataclass(frozen=True)
class _Addressed:
    id: int

    def __post_init__(self) -> None:
        _check_id(self.id)


@dataclass(frozen=True)
class Ping(_Addressed):
    pass


@dataclass(frozen=True)
class Read(_Addressed):
    address: int
    length: int

    def __post_init__(self) -> None:
        super().__post_init__()
        _check_u16(self.address, "address")
        _check_u16(self.length, "length")


@dataclass(frozen=True)
class Write(_Addressed):
    address: int
    data: bytes

    def __post_init__(self) -> None:
        super().__post_init__()
        _check_u16(self.address, "address")


@dataclass(frozen=True)
class RegWrite(Write):
    """Like :class:`Write` but applied on the next :class:`Action`."""


@dataclass(frozen=True)
class Action(_Addressed):
    pass


@dataclass(frozen=True)
class FactoryReset(_Addressed):
    mode: FactoryResetMode = FactoryResetMode.ALL

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "mode", FactoryResetMode(self.mode))


@dataclass(frozen=True)
class Reboot(_Addressed):
    pass


#: Fixed key that must follow the Clear option byte.
CLEAR_KEY: Final = b"\x44\x58\x4c\x22"  # "DXL\""


@dataclass(frozen=True)
class Clear(_Addressed):
    """Clear instruction; option 0x01 resets the multi-turn position."""

    option: int = 0x01

    def __post_init__(self) -> None:
        super().__post_init__()
        if not 0 <= self.option <= 0xFF:
            raise ValueError(f"clear option {self.option} is not a byte")


@dataclass(frozen=True)
class SyncRead:
    """Read the same item from several devices (sent to the broadcast id)."""

    address: int
    length: int
    ids: tuple[int, ...]

    def __post_init__(self) -> None:
        _check_u16(self.address, "address")
        _check_u16(self.length, "length")
        for dxl_id in self.ids:
            _check_id(dxl_id, broadcast=False)


@dataclass(frozen=True)
class FastSyncRead(SyncRead):
    """Same request layout as :class:`SyncRead`; devices answer in one combined packet."""


@dataclass(frozen=True)
class SyncWriteItem:
    id: int
    data: bytes

    def __post_init__(self) -> None:
        _check_id(self.id, broadcast=False)


@dataclass(frozen=True)
class SyncWrite:
    """Write the same item (``length`` bytes at ``address``) on several devices."""

    address: int
    length: int
    items: tuple[SyncWriteItem, ...]

    def __post_init__(self) -> None:
        _check_u16(self.address, "address")
        _check_u16(self.length, "length")
        check_item_lengths(self.length, self.items)


@dataclass(frozen=True)
class BulkReadItem:
    id: int
    address: int
    length: int

    def __post_init__(self) -> None:
        _check_id(self.id, broadcast=False)
        _check_u16(self.address, "address")
        _check_u16(self.length, "length")


@dataclass(frozen=True)
class BulkRead:
    items: tuple[BulkReadItem, ...]


@dataclass(frozen=True)
class BulkWriteItem:
    id: int
    address: int
    data: bytes

    def __post_init__(self) -> None:
        _check_id(self.id, broadcast=False)
        _check_u16(self.address, "address")
        _check_u16(len(self.data), "data length")


@dataclass(frozen=True)
class BulkWrite:
    items: tuple[BulkWriteItem, ...]


@dataclass(frozen=True)
class Status(_Addressed):
    """Status (reply) packet; ``params`` meaning depends on the request."""

    error: int = 0
    params: bytes = b""

    def __post_init__(self) -> None:
        super().__post_init__()
        if not 0 <= self.error <= 0xFF:
            raise ValueError(f"status error {self.error} is not a byte")

    @property
    def alert(self) -> bool:
        return bool(self.error & ALERT_BIT)

    @property
    def error_number(self) -> int:
        """Bits 0..6; compare with :class:`ErrorNumber`."""
        return self.error & 0x7F

    def ping_info(self) -> tuple[int, int]:
        """``(model_number, firmware_version)`` of a ping reply."""
        if len(self.params) != 3:
            raise DynamixelDecodeError(f"ping reply has 3 params, got {len(self.params)}")
        model, firmware = struct.unpack("<HB", self.params)
        return int(model), int(firmware)


DynamixelMessage: TypeAlias = (
    Ping
    | Read
    | Write
    | RegWrite
    | Action
    | FactoryReset
    | Reboot
    | Clear
    | SyncRead
    | FastSyncRead
    | SyncWrite
    | BulkRead
    | BulkWrite
    | Status
)


# --- Packet framing ------------------------------------------------------------------------


def _frame(dxl_id: int, body: bytes) -> bytes:
    """Frame instruction+params ``body``: stuff, add header/length, append the CRC."""
    stuffed = stuff(body)
    length = len(stuffed) + _CRC_LEN
    if length > 0xFFFF:
        raise ValueError(f"packet too long ({length} bytes after stuffing)")
    packet = HEADER + bytes((dxl_id,)) + struct.pack("<H", length) + stuffed
    return packet + struct.pack("<H", crc16(packet))


def _addr_len(address: int, length: int) -> bytes:
    return struct.pack("<HH", address, length)


def _instruction_body(msg: DynamixelMessage) -> tuple[int, bytes]:
    match msg:
        case Ping():
            return msg.id, bytes((Instruction.PING,))
        case Read():
            return msg.id, bytes((Instruction.READ,)) + _addr_len(msg.address, msg.length)
        case RegWrite():  # before Write: RegWrite is a subclass
            return msg.id, bytes((Instruction.REG_WRITE,)) + struct.pack(
                "<H", msg.address
            ) + msg.data
        case Write():
            return msg.id, bytes((Instruction.WRITE,)) + struct.pack("<H", msg.address) + msg.data
        case Action():
            return msg.id, bytes((Instruction.ACTION,))
        case FactoryReset():
            return msg.id, bytes((Instruction.FACTORY_RESET, msg.mode))
        case Reboot():
            return msg.id, bytes((Instruction.REBOOT,))
        case Clear():
            return msg.id, bytes((Instruction.CLEAR, msg.option)) + CLEAR_KEY
        case FastSyncRead():  # before SyncRead: subclass
            ids = bytes(msg.ids)
            return BROADCAST_ID, bytes((Instruction.FAST_SYNC_READ,)) + _addr_len(
                msg.address, msg.length
            ) + ids
        case SyncRead():
            ids = bytes(msg.ids)
            return BROADCAST_ID, bytes((Instruction.SYNC_READ,)) + _addr_len(
                msg.address, msg.length
            ) + ids
        case SyncWrite():
            data = b"".join(bytes((item.id,)) + item.data for item in msg.items)
            return BROADCAST_ID, bytes((Instruction.SYNC_WRITE,)) + _addr_len(
                msg.address, msg.length
            ) + data
        case BulkRead():
            data = b"".join(bytes((i.id,)) + _addr_len(i.address, i.length) for i in msg.items)
            return BROADCAST_ID, bytes((Instruction.BULK_READ,)) + data
        case BulkWrite():
            data = b"".join(
                bytes((i.id,)) + _addr_len(i.address, len(i.data)) + i.data for i in msg.items
            )
            return BROADCAST_ID, bytes((Instruction.BULK_WRITE,)) + data
        case Status():
            return msg.id, bytes((Instruction.STATUS, msg.error)) + msg.params
    raise TypeError(f"not a Dynamixel message: {msg!r}")


def encode(msg: DynamixelMessage) -> bytes:
    """Encode one complete packet (header to CRC)."""
    dxl_id, body = _instruction_body(msg)
    return _frame(dxl_id, body)


def _split_every(data: bytes, size: int, what: str) -> Iterable[bytes]:
    if size == 0 or len(data) % size:
        raise DynamixelDecodeError(f"{what}: {len(data)} bytes is not a multiple of {size}")
    return (data[i : i + size] for i in range(0, len(data), size))


def _parse_bulk_write(params: bytes) -> BulkWrite:
    items: list[BulkWriteItem] = []
    i = 0
    while i < len(params):
        if len(params) - i < 5:
            raise DynamixelDecodeError("bulk write: truncated item header")
        dxl_id = params[i]
        address, length = struct.unpack_from("<HH", params, i + 1)
        start = i + 5
        if start + length > len(params):
            raise DynamixelDecodeError("bulk write: truncated item data")
        items.append(BulkWriteItem(dxl_id, address, params[start : start + length]))
        i = start + length
    return BulkWrite(tuple(items))


def _parse_body(dxl_id: int, instruction: int, params: bytes) -> DynamixelMessage:
    def need(count: int, exact: bool = True) -> None:
        if len(params) < count or (exact and len(params) != count):
            name = Instruction(instruction).name
            raise DynamixelDecodeError(f"{name}: unexpected param length {len(params)}")

    def broadcast_only() -> None:
        if dxl_id != BROADCAST_ID:
            name = Instruction(instruction).name
            raise DynamixelDecodeError(f"{name} must be sent to the broadcast id")

    match instruction:
        case Instruction.STATUS:
            need(1, exact=False)
            return Status(dxl_id, params[0], params[1:])
        case Instruction.PING:
            need(0)
            return Ping(dxl_id)
        case Instruction.READ:
            need(4)
            return Read(dxl_id, *struct.unpack("<HH", params))
        case Instruction.WRITE | Instruction.REG_WRITE:
            need(2, exact=False)
            cls = Write if instruction == Instruction.WRITE else RegWrite
            return cls(dxl_id, struct.unpack_from("<H", params)[0], params[2:])
        case Instruction.ACTION:
            need(0)
            return Action(dxl_id)
        case Instruction.FACTORY_RESET:
            need(1)
            return FactoryReset(dxl_id, FactoryResetMode(params[0]))
        case Instruction.REBOOT:
            need(0)
            return Reboot(dxl_id)
        case Instruction.CLEAR:
            need(5)
            if params[1:] != CLEAR_KEY:
                raise DynamixelDecodeError("clear: wrong key bytes")
            return Clear(dxl_id, params[0])
        case Instruction.SYNC_READ | Instruction.FAST_SYNC_READ:
            broadcast_only()
            need(4, exact=False)
            address, length = struct.unpack_from("<HH", params)
            read_cls = SyncRead if instruction == Instruction.SYNC_READ else FastSyncRead
            return read_cls(address, length, tuple(params[4:]))
        case Instruction.SYNC_WRITE:
            broadcast_only()
            need(4, exact=False)
            address, length = struct.unpack_from("<HH", params)
            items = tuple(
                SyncWriteItem(chunk[0], chunk[1:])
                for chunk in _split_every(params[4:], length + 1, "sync write")
            )
            return SyncWrite(address, length, items)
        case Instruction.BULK_READ:
            broadcast_only()
            reads = tuple(
                BulkReadItem(chunk[0], *struct.unpack_from("<HH", chunk, 1))
                for chunk in _split_every(params, 5, "bulk read")
            )
            return BulkRead(reads)
        case Instruction.BULK_WRITE:
            broadcast_only()
            return _parse_bulk_write(params)
    raise DynamixelDecodeError(f"unknown instruction {instruction:#04x}")


def decode(packet: bytes) -> DynamixelMessage:
    """Decode exactly one complete packet; raises only :class:`DynamixelDecodeError`."""
    packet = bytes(packet)
    if len(packet) < _PREFIX_LEN + 1 + _CRC_LEN or not packet.startswith(HEADER):
        raise DynamixelDecodeError("missing header or packet too short")
    (length,) = struct.unpack_from("<H", packet, 5)
    if len(packet) != _PREFIX_LEN + length:
        raise DynamixelDecodeError(f"length field {length} disagrees with {len(packet)} bytes")
    (crc,) = struct.unpack_from("<H", packet, len(packet) - _CRC_LEN)
    computed = crc16(packet[:-_CRC_LEN])
    if crc != computed:
        raise DynamixelCrcError(f"CRC {crc:#06x} != {computed:#06x}")
    return _decode_checked(packet)


def _decode_checked(packet: bytes) -> DynamixelMessage:
    """Decode a framed packet whose length and CRC are already checked."""
    body = unstuff(packet[_PREFIX_LEN:-_CRC_LEN])
    dxl_id = packet[4]
    if not (dxl_id <= MAX_ID or dxl_id == BROADCAST_ID):
        raise DynamixelDecodeError(f"invalid id {dxl_id:#04x}")
    try:
        return _parse_body(dxl_id, body[0], body[1:])
    except DynamixelDecodeError:
        raise
    except ValueError as exc:  # enum or dataclass validation of wire values
        raise DynamixelDecodeError(str(exc)) from exc


# --- Streaming parser ----------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class CorruptPacket:
    """A complete packet whose CRC did not match (reported by :meth:`PacketParser.feed_all`).

    ``id`` and ``instruction`` are the bytes at their places, unverified: a device
    answers an instruction addressed to it with :attr:`ErrorNumber.CRC_ERROR`.
    """

    id: int
    instruction: int
    length: int
    """The length field (instruction + params + CRC)."""


class PacketParser:
    """Incremental decoder for a byte stream; never raises on garbage, runs in linear time.

    Bytes before a header are dropped. A header is a packet candidate that is given up
    (only its 4 header bytes dropped, then the parser resynchronises on the next
    header, so a corrupted length cannot swallow the packets after it) when:

    * its length field is below 3 or above ``max_length`` (``length_errors``);
    * another header starts inside the claimed packet (``interrupted``): byte stuffing
      keeps ``FF FF FD 00`` out of a genuine packet (except its last 4 bytes: a body
      ending ``FF FF`` followed by the CRC ``FD 00``), so this is a false header in
      noise or a packet cut short. It is decided as soon as the inner header
      arrives, before the claimed length is complete and without a CRC;
    * its CRC does not match (``crc_errors``).

    A packet with a valid CRC but invalid contents is dropped whole (``malformed``).
    Because a CRC is only computed over a candidate with no header inside it, the
    candidates checked overlap by at most 4 bytes: any byte stream costs at most
    about one CRC pass over its bytes, whatever its noise.

    Nothing is lost untold: every byte fed is delivered in a packet, counted in
    ``dropped_bytes``, or still ``buffered``. The buffer never holds more than one
    packet of ``max_length`` (plus its 7-byte prefix).
    """

    def __init__(self, *, max_length: int = 1024) -> None:
        if max_length < 3:
            raise ValueError("max_length must allow instruction + CRC")
        self.max_length = max_length
        self._buf = bytearray()
        self._scanned = 1
        """Offset from which the candidate at the buffer start still needs an inner-header search."""
        self.packets = 0
        self.crc_errors = 0
        self.length_errors = 0
        self.interrupted = 0
        self.malformed = 0
        self.dropped_bytes = 0

    @property
    def buffered(self) -> int:
        return len(self._buf)

    def reset(self) -> None:
        """Forget the partial packet (its bytes are counted in ``dropped_bytes``)."""
        self._drop(len(self._buf))

    def _drop(self, count: int) -> None:
        del self._buf[:count]
        self.dropped_bytes += count
        self._scanned = 1

    def feed(self, data: bytes) -> list[DynamixelMessage]:
        """The packets completed by ``data``, in stream order."""
        return self._parse(data, False)  # type: ignore[return-value]  # no CorruptPacket

    def feed_bulk(
        self, data: bytes, param_length: int
    ) -> tuple[bytes, bytes, tuple[bytes, ...]] | None:
        """The statuses of ``param_length`` params that make up ``data`` (the replies to a
        SYNC READ, as one read brings them), checked in bulk and not decoded into objects.

        Returns ``(ids, errors, params)``: the id byte, the error byte and the params of
        each status in stream order, when nothing is buffered and ``data`` is exactly
        whole such statuses back to back, each passing every check :meth:`feed` makes
        (header, length field, instruction STATUS, id up to :data:`MAX_ID`, no byte
        stuffing, CRC: see :func:`_crcs_match`); they count in ``packets``. Otherwise
        None, with nothing consumed or counted: give ``data`` to :meth:`feed` or
        :meth:`feed_statuses`.
        """
        size = _STATUS_OVERHEAD + param_length
        total = len(data)
        count = total // size
        if self._buf or not count or count * size != total or param_length + 4 > self.max_length:
            return None
        if type(data) is not bytes:
            data = bytes(data)
        # Exactly one FF FF FD per packet (its header): no stuffing, no inner header.
        if data.count(_STUFF_PATTERN) != count:
            return None
        layout = _BULK_LAYOUTS.get((param_length, count))
        if layout is None:
            layout = _bulk_layout(param_length, count)
            if len(_BULK_LAYOUTS) < _BULK_LAYOUT_CACHE:
                _BULK_LAYOUTS[param_length, count] = layout
        fixed, params_layout = layout
        if count == 1:  # a SYNC READ of one servo: its fields in one unpack
            one = _lone_status(data, params_layout, param_length)
            if one is None:
                return None
            self.packets += 1
            return data[4:5], data[8:9], (one[2],)
        if count < _BULK_MIN:  # two: one unpack each, fields compared (fewer steps)
            ones = []
            for j in range(0, total, size):
                one = _lone_status(data[j : j + size], params_layout, param_length)
                if one is None:
                    return None
                ones.append(one)
            self.packets += count
            ones_ids, ones_errors, ones_params = zip(*ones, strict=True)
            return bytes(ones_ids), bytes(ones_errors), ones_params
        for offset, expected in fixed:  # every fixed byte of every packet at once
            if data[offset::size] != expected:
                return None
        ids = data[4::size]
        if max(ids) > MAX_ID or not _crcs_match(data, size, count):
            return None
        self.packets += count
        return ids, data[8::size], params_layout.unpack(data)

    def feed_statuses(
        self, data: bytes, param_length: int
    ) -> tuple[list[Status], list[DynamixelMessage]]:
        """:meth:`feed` for a stream expected to hold statuses of ``param_length`` params.

        Returns ``(statuses, others)``: ``statuses + others`` is what :meth:`feed`
        returns (the same packets in the same order, the same counters). When ``data``
        starts, with nothing buffered, with such statuses back to back (the replies to a
        SYNC READ), those are checked in bulk (:meth:`feed_bulk`) and returned in
        ``statuses``: each a :class:`Status` with exactly ``param_length`` params.
        Whatever follows them, or anything else (a byte-stuffed packet, another packet,
        noise), goes through :meth:`feed` into ``others``.
        """
        size = _STATUS_OVERHEAD + param_length
        whole = len(data) // size * size
        if self._buf or not whole:
            return [], self.feed(data)
        count = whole // size
        if count < _BULK_MIN and data.count(_STUFF_PATTERN, 0, whole) == count:
            layout = _BULK_LAYOUTS.get((param_length, 1))  # one or two: one unpack each
            if layout is None:
                layout = _bulk_layout(param_length, 1)
                if len(_BULK_LAYOUTS) < _BULK_LAYOUT_CACHE:
                    _BULK_LAYOUTS[param_length, 1] = layout
            out: list[Status] = []
            for j in range(0, whole, size):
                one = _lone_status(data[j : j + size], layout[1], param_length)
                if one is None:
                    return [], self.feed(data)  # nothing counted yet: parse it all again
                out.append(_wire_status(*one))
            self.packets += count
            return out, self.feed(data[whole:]) if whole < len(data) else []
        bulk = self.feed_bulk(data if whole == len(data) else data[:whole], param_length)
        if bulk is None:
            return [], self.feed(data)  # nothing counted yet: parse it all again
        new = object.__new__
        out = []
        for dxl_id, error, params in zip(*bulk, strict=True):
            msg = new(Status)  # as _wire_status does, inline
            fields = msg.__dict__
            fields["id"] = dxl_id
            fields["error"] = error
            fields["params"] = params
            out.append(msg)
        return out, self.feed(data[whole:]) if whole < len(data) else []

    def feed_all(self, data: bytes) -> list[DynamixelMessage | CorruptPacket]:
        """Like :meth:`feed`, with a :class:`CorruptPacket` where a CRC did not match."""
        return self._parse(data, True)

    def _parse(self, data: bytes, corrupt: bool) -> list[DynamixelMessage | CorruptPacket]:
        # Works on one bytes object with a read offset ``i`` (no per-packet buffer
        # shifting); what is left after the last complete packet is kept in ``_buf``.
        if self._buf:
            self._buf += data
            buf = bytes(self._buf)
        else:
            buf = data if type(data) is bytes else bytes(data)
        n = len(buf)
        i = 0  # first byte neither delivered nor dropped
        scanned = self._scanned
        dropped = 0
        max_length = self.max_length
        find = buf.find
        out: list[DynamixelMessage | CorruptPacket] = []
        while True:
            start = find(HEADER, i)
            if start < 0:
                # Keep a tail that may be the start of a header split across reads.
                keep = next((k for k in (3, 2, 1) if buf.endswith(HEADER[:k], i)), 0)
                if n - keep > i:
                    dropped += n - keep - i
                    i = n - keep
                    scanned = 1
                break
            if start > i:
                dropped += start - i
                i = start
                scanned = 1
            if n - i < _PREFIX_LEN:
                break
            length = buf[i + 5] | buf[i + 6] << 8
            if not 3 <= length <= max_length:
                self.length_errors += 1
                dropped += _HEADER_LEN
                i += _HEADER_LEN
                scanned = 1
                continue
            total = _PREFIX_LEN + length
            # A header starting at 1..total-5 lies wholly before the packet's last 4 bytes.
            end = i + total - 1
            if end > n:
                end = n
            if find(HEADER, i + scanned, end) >= 0:
                self.interrupted += 1
                dropped += _HEADER_LEN
                i += _HEADER_LEN
                scanned = 1
                continue
            if n - i < total:
                scanned = max(1, end - i - _HEADER_LEN + 1)
                break
            body_end = i + total - _CRC_LEN
            if _umts(buf[i:body_end]) != buf[body_end] | buf[body_end + 1] << 8:
                self.crc_errors += 1
                if corrupt:
                    out.append(CorruptPacket(buf[i + 4], buf[i + 7], length))
                dropped += _HEADER_LEN
                i += _HEADER_LEN
                scanned = 1
                continue
            msg: DynamixelMessage
            dxl_id = buf[i + 4]
            if (
                buf[i + 7] == _STATUS
                and length >= 4
                and (dxl_id <= MAX_ID or dxl_id == BROADCAST_ID)
                and find(_STUFF_PATTERN, i + _PREFIX_LEN, body_end) < 0
            ):
                # Fast path (every status a SYNC READ brings): no stuffing to undo, id
                # valid, error byte present: the checks of _decode_checked all pass.
                msg = _wire_status(dxl_id, buf[i + 8], buf[i + 9 : body_end])
            else:
                try:
                    msg = _decode_checked(buf[i : i + total])
                except DynamixelDecodeError:
                    self.malformed += 1
                    dropped += total
                    i += total
                    scanned = 1
                    continue
            i += total
            scanned = 1
            self.packets += 1
            out.append(msg)
        if dropped:
            self.dropped_bytes += dropped
        self._scanned = scanned
        if i < n:
            self._buf = bytearray(buf[i:])
        elif self._buf:
            self._buf = bytearray()
        return out


def _wire_status(dxl_id: int, error: int, params: bytes) -> Status:
    """A :class:`Status` from fields already checked on the wire (id valid, error a byte).

    Equal to ``Status(dxl_id, error, params)``; skips the dataclass ``__init__`` and its
    validation, which cost more than the rest of the parse of a status.
    """
    msg = object.__new__(Status)
    fields = msg.__dict__
    fields["id"] = dxl_id
    fields["error"] = error
    fields["params"] = params
    return msg
