"""The CANopen (CiA 301) subset a CiA 402 drive needs, pure and byte-exact.

Covered: NMT node control, SYNC, EMCY, heartbeat / boot-up, expedited and
segmented SDO upload and download (initiate, segments, aborts), raw PDOs and
bit-exact PDO packing from a mapping list. SDO block transfer is not
implemented: a client's block (or invalid, ccs 7) request decodes to
:class:`SdoUnsupportedRequest` so a server can abort it (0x05040001); a
server's block response is a decode error. TIME and LSS are out of scope and
decode to :class:`~openel_can.errors.CanOpenDecodeError` like any malformed
frame. Unknown NMT state or command values are kept as plain ``int``.
Encoders raise :class:`ValueError` for values that do not fit.

COB-IDs use the CiA 301 predefined connection set: function code in bits 10..7,
node id (1..127) in bits 6..0.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum, IntFlag
from typing import Final, TypeAlias, TypeVar

from openel_can.errors import CanOpenDecodeError

__all__ = [
    "DEVICE_TYPE",
    "EMCY_BASE",
    "ERROR_REGISTER",
    "HEARTBEAT_BASE",
    "MAX_NODE_ID",
    "NMT_COB_ID",
    "PDO_COB_ID_INVALID",
    "PRODUCER_HEARTBEAT_TIME",
    "RPDO_BASES",
    "RPDO_COMM_BASE",
    "RPDO_MAPPING_BASE",
    "SDO_CLIENT_MESSAGES",
    "SDO_RX_BASE",
    "SDO_SEGMENT_SIZE",
    "SDO_TX_BASE",
    "SYNC_COB_ID",
    "TPDO_BASES",
    "TPDO_COMM_BASE",
    "TPDO_MAPPING_BASE",
    "CanOpenDecodeError",
    "CanOpenMessage",
    "DataType",
    "EmcyCode",
    "Emergency",
    "ErrorRegister",
    "Heartbeat",
    "NmtCommand",
    "NmtControl",
    "NmtState",
    "ObjectEntry",
    "Pdo",
    "PdoCodec",
    "PdoMapEntry",
    "SdoAbort",
    "SdoAbortCode",
    "SdoDownloadRequest",
    "SdoDownloadResponse",
    "SdoDownloadSegment",
    "SdoDownloadSegmentResponse",
    "SdoSegmentedDownloadRequest",
    "SdoSegmentedUploadResponse",
    "SdoUnsupportedRequest",
    "SdoUploadRequest",
    "SdoUploadResponse",
    "SdoUploadSegment",
    "SdoUploadSegmentRequest",
    "Sync",
    "decode",
    "encode",
    "pack_pdo",
    "rpdo_cob_id",
    "tpdo_cob_id",
    "unpack_pdo",
]

# --- COB-ID bases (CiA 301 predefined connection set) ------------------------------------
NMT_COB_ID: Final = 0x000
SYNC_COB_ID: Final = 0x080
EMCY_BASE: Final = 0x080
TPDO_BASES: Final = (0x180, 0x280, 0x380, 0x480)
RPDO_BASES: Final = (0x200, 0x300, 0x400, 0x500)
SDO_TX_BASE: Final = 0x580  # server (drive) -> client
SDO_RX_BASE: Final = 0x600  # client -> server (drive)
HEARTBEAT_BASE: Final = 0x700

# --- Communication-profile objects a master configures -----------------------------------
DEVICE_TYPE: Final = 0x1000
ERROR_REGISTER: Final = 0x1001
PRODUCER_HEARTBEAT_TIME: Final = 0x1017
RPDO_COMM_BASE: Final = 0x1400  # + pdo number - 1; sub 1 COB-ID, sub 2 transmission type
RPDO_MAPPING_BASE: Final = 0x1600
TPDO_COMM_BASE: Final = 0x1800
TPDO_MAPPING_BASE: Final = 0x1A00
#: Bit 31 of a PDO COB-ID entry: the PDO is disabled while set.
PDO_COB_ID_INVALID: Final = 0x8000_0000

MAX_NODE_ID: Final = 127
#: Data bytes per SDO segment (CiA 301 segmented transfer).
SDO_SEGMENT_SIZE: Final = 7
_SDO_LEN: Final = 8
_MAX_PDO_BITS: Final = 64


def _check_node(node_id: int, *, allow_broadcast: bool = False) -> None:
    low = 0 if allow_broadcast else 1
    if not low <= node_id <= MAX_NODE_ID:
        raise ValueError(f"node_id {node_id} outside {low}..{MAX_NODE_ID}")


def _check_uint(value: int, bits: int, name: str) -> None:
    if not 0 <= value < 1 << bits:
        raise ValueError(f"{name} {value} does not fit {bits} unsigned bits")


_E = TypeVar("_E", bound=IntEnum)


def _enum_or_int(enum_type: type[_E], value: int) -> _E | int:
    """The enum member for ``value``, or the plain int when the enum does not know it."""
    if not isinstance(value, int):
        raise ValueError(f"{enum_type.__name__} value must be an int, got {value!r}")
    try:
        return enum_type(value)
    except ValueError:
        return int(value)


def tpdo_cob_id(number: int, node_id: int) -> int:
    """Default COB-ID of TPDO ``number`` (1..4, drive -> master)."""
    _check_node(node_id)
    return TPDO_BASES[_pdo_slot(number)] + node_id


def rpdo_cob_id(number: int, node_id: int) -> int:
    """Default COB-ID of RPDO ``number`` (1..4, master -> drive)."""
    _check_node(node_id)
    return RPDO_BASES[_pdo_slot(number)] + node_id


def _pdo_slot(number: int) -> int:
    if not 1 <= number <= 4:
        raise ValueError(f"PDO number {number} outside 1..4")
    return number - 1


# --- NMT, SYNC, EMCY, heartbeat ------------------------------------------------------------


class NmtCommand(IntEnum):
    START = 0x01
    STOP = 0x02
    ENTER_PRE_OPERATIONAL = 0x80
    RESET_NODE = 0x81
    RESET_COMMUNICATION = 0x82


class NmtState(IntEnum):
    """Heartbeat state byte (bit 7, the node-guarding toggle, excluded)."""

    BOOT_UP = 0x00
    STOPPED = 0x04
    OPERATIONAL = 0x05
    PRE_OPERATIONAL = 0x7F


@dataclass(frozen=True)
class NmtControl:
    """NMT node control; ``node_id`` 0 addresses all nodes."""

    command: NmtCommand | int
    node_id: int = 0

    def __post_init__(self) -> None:
        _check_uint(self.command, 8, "NMT command")
        object.__setattr__(self, "command", _enum_or_int(NmtCommand, self.command))
        _check_node(self.node_id, allow_broadcast=True)


@dataclass(frozen=True)
class Sync:
    """SYNC; ``counter`` (1..240) only when the sync counter overflow value is set."""

    counter: int | None = None

    def __post_init__(self) -> None:
        if self.counter is not None and not 1 <= self.counter <= 240:
            raise ValueError(f"SYNC counter {self.counter} outside 1..240")


class ErrorRegister(IntFlag):
    """Object 0x1001, repeated in byte 2 of every EMCY."""

    GENERIC = 0x01
    CURRENT = 0x02
    VOLTAGE = 0x04
    TEMPERATURE = 0x08
    COMMUNICATION = 0x10
    DEVICE_PROFILE = 0x20
    MANUFACTURER = 0x80


class EmcyCode(IntEnum):
    """A few CiA 301 / CiA 402 emergency error codes (the field itself stays an int)."""

    NO_ERROR = 0x0000  # error reset
    GENERIC = 0x1000
    CONTINUOUS_OVER_CURRENT = 0x2310
    DC_LINK_OVER_VOLTAGE = 0x3210
    DC_LINK_UNDER_VOLTAGE = 0x3220
    DEVICE_OVER_TEMPERATURE = 0x4210
    DEVICE_HARDWARE = 0x5000
    INTERNAL_SOFTWARE = 0x6100
    CAN_OVERRUN = 0x8110
    CAN_ERROR_PASSIVE = 0x8120
    LIFE_GUARD_OR_HEARTBEAT = 0x8130
    CAN_BUS_OFF_RECOVERED = 0x8140
    PDO_LENGTH_ERROR = 0x8210
    FOLLOWING_ERROR = 0x8611
    DEVICE_SPECIFIC = 0xFF00


@dataclass(frozen=True)
class Emergency:
    node_id: int
    error_code: int
    error_register: int
    manufacturer: bytes = bytes(5)

    def __post_init__(self) -> None:
        _check_node(self.node_id)
        _check_uint(self.error_code, 16, "error_code")
        _check_uint(self.error_register, 8, "error_register")
        if len(self.manufacturer) != 5:
            raise ValueError("EMCY manufacturer field is exactly 5 bytes")


@dataclass(frozen=True)
class Heartbeat:
    """Heartbeat producer message; ``state`` BOOT_UP is the boot-up message."""

    node_id: int
    state: NmtState | int
    toggle: bool = False  # only meaningful for node-guarding replies

    def __post_init__(self) -> None:
        _check_node(self.node_id)
        _check_uint(self.state, 7, "NMT state")
        object.__setattr__(self, "state", _enum_or_int(NmtState, self.state))


# --- SDO (expedited and segmented) -------------------------------------------------------------------------


class SdoAbortCode(IntEnum):
    """CiA 301 SDO abort codes (:class:`SdoAbort` keeps any u32)."""

    TOGGLE_BIT_NOT_ALTERNATED = 0x0503_0000
    TIMEOUT = 0x0504_0000
    INVALID_COMMAND_SPECIFIER = 0x0504_0001
    OUT_OF_MEMORY = 0x0504_0005
    UNSUPPORTED_ACCESS = 0x0601_0000
    WRITE_ONLY = 0x0601_0001
    READ_ONLY = 0x0601_0002
    OBJECT_DOES_NOT_EXIST = 0x0602_0000
    CANNOT_BE_MAPPED = 0x0604_0041
    PDO_LENGTH_EXCEEDED = 0x0604_0042
    GENERAL_PARAMETER_INCOMPATIBILITY = 0x0604_0043
    GENERAL_INTERNAL_INCOMPATIBILITY = 0x0604_0047
    HARDWARE_ERROR = 0x0606_0000
    LENGTH_MISMATCH = 0x0607_0010
    LENGTH_TOO_HIGH = 0x0607_0012
    LENGTH_TOO_LOW = 0x0607_0013
    SUBINDEX_DOES_NOT_EXIST = 0x0609_0011
    INVALID_VALUE = 0x0609_0030
    VALUE_TOO_HIGH = 0x0609_0031
    VALUE_TOO_LOW = 0x0609_0032
    MAX_LESS_THAN_MIN = 0x0609_0036
    GENERAL_ERROR = 0x0800_0000
    CANNOT_TRANSFER = 0x0800_0020
    CANNOT_TRANSFER_LOCAL_CONTROL = 0x0800_0021
    CANNOT_TRANSFER_DEVICE_STATE = 0x0800_0022
    NO_OBJECT_DICTIONARY = 0x0800_0023
    NO_DATA_AVAILABLE = 0x0800_0024


# Command specifiers (bits 7..5 of byte 0).
_CCS_DOWNLOAD_SEGMENT: Final = 0  # download segment request   (client)
_CCS_DOWNLOAD: Final = 1  # initiate download request  (client)
_CCS_UPLOAD: Final = 2  # initiate upload request    (client)
_CCS_UPLOAD_SEGMENT: Final = 3  # upload segment request     (client)
_SCS_UPLOAD_SEGMENT: Final = 0  # upload segment response    (server)
_SCS_DOWNLOAD_SEGMENT: Final = 1  # download segment response  (server)
_SCS_UPLOAD: Final = 2  # initiate upload response   (server)
_SCS_DOWNLOAD: Final = 3  # initiate download response (server)
_CS_ABORT: Final = 4
_E_BIT: Final = 0x02  # expedited
_S_BIT: Final = 0x01  # size indicated (then n = bits 3..2 = 4 - data length)
_T_BIT: Final = 0x10  # segment toggle
_C_BIT: Final = 0x01  # last segment


@dataclass(frozen=True)
class _SdoBase:
    node_id: int
    index: int
    subindex: int

    def __post_init__(self) -> None:
        _check_node(self.node_id)
        _check_uint(self.index, 16, "index")
        _check_uint(self.subindex, 8, "subindex")


def _check_expedited(data: bytes) -> None:
    if not 1 <= len(data) <= 4:
        raise ValueError(f"expedited SDO carries 1..4 bytes, got {len(data)}")


@dataclass(frozen=True)
class SdoUploadRequest(_SdoBase):
    """Read request, client -> server (command byte 0x40)."""


@dataclass(frozen=True)
class SdoUploadResponse(_SdoBase):
    """Expedited read reply, server -> client (0x43/0x47/0x4B/0x4F).

    A reply without size indication (0x42) decodes with all 4 data bytes.
    """

    data: bytes

    def __post_init__(self) -> None:
        super().__post_init__()
        _check_expedited(self.data)


@dataclass(frozen=True)
class SdoDownloadRequest(_SdoBase):
    """Expedited write, client -> server (0x23/0x27/0x2B/0x2F).

    ``size_indicated`` False is the 0x22 form: four data bytes and no size, the server
    takes as many as its object holds (CiA 301).
    """

    data: bytes
    size_indicated: bool = True

    def __post_init__(self) -> None:
        super().__post_init__()
        _check_expedited(self.data)
        if not self.size_indicated and len(self.data) != 4:
            raise ValueError("an expedited download without size carries 4 bytes")


@dataclass(frozen=True)
class SdoDownloadResponse(_SdoBase):
    """Write confirmation, server -> client (0x60)."""


def _check_size(size: int | None) -> None:
    if size is not None:
        _check_uint(size, 32, "size")


@dataclass(frozen=True)
class SdoSegmentedUploadResponse(_SdoBase):
    """Initiate upload response of a segmented upload, server -> client (0x41, or 0x40
    without size); the data follows in :class:`SdoUploadSegment` answers."""

    size: int | None

    def __post_init__(self) -> None:
        super().__post_init__()
        _check_size(self.size)


@dataclass(frozen=True)
class SdoSegmentedDownloadRequest(_SdoBase):
    """Initiate a segmented download, client -> server (0x21, or 0x20 without size);
    answered by :class:`SdoDownloadResponse`, then the data goes in
    :class:`SdoDownloadSegment` frames."""

    size: int | None

    def __post_init__(self) -> None:
        super().__post_init__()
        _check_size(self.size)


@dataclass(frozen=True)
class _SdoSegmentBase:
    node_id: int
    toggle: bool

    def __post_init__(self) -> None:
        _check_node(self.node_id)


@dataclass(frozen=True)
class _SdoDataSegment(_SdoSegmentBase):
    data: bytes
    last: bool

    def __post_init__(self) -> None:
        super().__post_init__()
        if len(self.data) > SDO_SEGMENT_SIZE:
            raise ValueError(f"an SDO segment carries 0..7 bytes, got {len(self.data)}")


@dataclass(frozen=True)
class SdoUploadSegmentRequest(_SdoSegmentBase):
    """Upload segment request, client -> server (0x60 / 0x70 with the toggle bit)."""


@dataclass(frozen=True)
class SdoUploadSegment(_SdoDataSegment):
    """Upload segment response, server -> client: 0..7 data bytes, ``last`` = c bit."""


@dataclass(frozen=True)
class SdoDownloadSegment(_SdoDataSegment):
    """Download segment request, client -> server: 0..7 data bytes, ``last`` = c bit."""


@dataclass(frozen=True)
class SdoDownloadSegmentResponse(_SdoSegmentBase):
    """Download segment response, server -> client (0x20 / 0x30 with the toggle bit)."""


@dataclass(frozen=True)
class SdoUnsupportedRequest(_SdoBase):
    """A client request this codec does not implement: block upload (ccs 5), block
    download (ccs 6) or the invalid ccs 7. ``command`` is byte 0, ``payload`` bytes 4..7;
    a server answers it with abort 0x05040001 on (``index``, ``subindex``)."""

    command: int
    payload: bytes = bytes(4)

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.command >> 5 not in (5, 6, 7) or self.command > 0xFF:
            raise ValueError(f"command {self.command:#x} is not a block/invalid SDO request")
        if len(self.payload) != 4:
            raise ValueError("payload is bytes 4..7 of the frame: exactly 4 bytes")


@dataclass(frozen=True)
class SdoAbort(_SdoBase):
    """Abort transfer (0x80), sent by either side; ``from_client`` picks the COB-ID."""

    code: int
    from_client: bool = False

    def __post_init__(self) -> None:
        super().__post_init__()
        _check_uint(self.code, 32, "abort code")


# --- PDO -----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Pdo:
    """Raw PDO: ``transmit`` True for a TPDO (drive -> master), False for an RPDO."""

    node_id: int
    number: int
    transmit: bool
    data: bytes

    def __post_init__(self) -> None:
        _check_node(self.node_id)
        _pdo_slot(self.number)
        if len(self.data) > 8:
            raise ValueError("a PDO carries at most 8 bytes")


@dataclass(frozen=True)
class PdoMapEntry:
    """One mapping entry, on the wire ``index << 16 | subindex << 8 | bit_length``.

    ``signed`` is not part of the wire format; it tells :func:`unpack_pdo` how
    to interpret the bits (take it from the object's data type).
    """

    index: int
    subindex: int
    bit_length: int
    signed: bool = False

    def __post_init__(self) -> None:
        _check_uint(self.index, 16, "index")
        _check_uint(self.subindex, 8, "subindex")
        if not 1 <= self.bit_length <= _MAX_PDO_BITS:
            raise ValueError(f"bit_length {self.bit_length} outside 1..{_MAX_PDO_BITS}")

    def to_u32(self) -> int:
        return self.index << 16 | self.subindex << 8 | self.bit_length

    @classmethod
    def from_u32(cls, value: int, *, signed: bool = False) -> PdoMapEntry:
        """Parse a mapping object value (raises :class:`CanOpenDecodeError`)."""
        if not 0 <= value <= 0xFFFF_FFFF:
            raise CanOpenDecodeError(f"mapping entry {value:#x} is not a u32")
        length = value & 0xFF
        if not 1 <= length <= _MAX_PDO_BITS:
            raise CanOpenDecodeError(f"mapping entry {value:#010x}: bit length {length}")
        return cls(value >> 16, (value >> 8) & 0xFF, length, signed)


def _total_bits(mapping: Sequence[PdoMapEntry]) -> int:
    total = sum(entry.bit_length for entry in mapping)
    if total > _MAX_PDO_BITS:
        raise ValueError(f"mapping has {total} bits, a PDO holds at most {_MAX_PDO_BITS}")
    return total


def pack_pdo(mapping: Sequence[PdoMapEntry], values: Sequence[int]) -> bytes:
    """Pack ``values`` LSB-first in mapping order (CiA 301), padded to whole bytes."""
    if len(values) != len(mapping):
        raise ValueError(f"{len(values)} values for {len(mapping)} mapping entries")
    total = _total_bits(mapping)
    acc = 0
    offset = 0
    for entry, value in zip(mapping, values, strict=True):
        bits = entry.bit_length
        low, high = (-(1 << (bits - 1)), 1 << (bits - 1)) if entry.signed else (0, 1 << bits)
        if not low <= value < high:
            raise ValueError(f"value {value} does not fit {entry}")
        acc |= (value & ((1 << bits) - 1)) << offset
        offset += bits
    return acc.to_bytes((total + 7) // 8, "little")


def unpack_pdo(mapping: Sequence[PdoMapEntry], data: bytes | bytearray) -> list[int]:
    """Inverse of :func:`pack_pdo`; extra trailing bytes are ignored, missing ones are an error.

    Raises :class:`ValueError` for an impossible mapping and
    :class:`CanOpenDecodeError` for a payload that is too short.
    """
    total = _total_bits(mapping)
    need = (total + 7) // 8
    if len(data) < need:
        raise CanOpenDecodeError(f"PDO needs {need} bytes for its mapping, got {len(data)}")
    acc = int.from_bytes(data[:need], "little")
    values: list[int] = []
    for entry in mapping:
        bits = entry.bit_length
        raw = acc & ((1 << bits) - 1)
        acc >>= bits
        if entry.signed and raw >= 1 << (bits - 1):
            raw -= 1 << bits
        values.append(raw)
    return values


_BYTE_FORMATS: Final = {
    (8, False): "B",
    (8, True): "b",
    (16, False): "H",
    (16, True): "h",
    (32, False): "I",
    (32, True): "i",
    (64, False): "Q",
    (64, True): "q",
}


class PdoCodec:
    """:func:`pack_pdo` / :func:`unpack_pdo` for one mapping, compiled once.

    A mapping of whole 8/16/32/64-bit entries packs and unpacks with one ``struct``
    call (the per-set-point path); any other mapping uses the bit-by-bit functions.
    Same results and the same errors as those functions.
    """

    __slots__ = ("_struct", "mapping", "size")

    def __init__(self, mapping: Sequence[PdoMapEntry]) -> None:
        self.mapping = tuple(mapping)
        self.size = (_total_bits(self.mapping) + 7) // 8
        formats = [_BYTE_FORMATS.get((e.bit_length, e.signed)) for e in self.mapping]
        self._struct = (
            struct.Struct("<" + "".join(f for f in formats if f is not None))
            if all(f is not None for f in formats)
            else None
        )

    def pack(self, values: Sequence[int]) -> bytes:
        """As :func:`pack_pdo` (ValueError for a value that does not fit its entry)."""
        packer = self._struct
        if packer is None or len(values) != len(self.mapping):
            return pack_pdo(self.mapping, values)
        try:
            return packer.pack(*values)
        except struct.error:
            return pack_pdo(self.mapping, values)  # raises the ValueError naming the entry

    def unpack(self, data: bytes | bytearray) -> tuple[int, ...]:
        """As :func:`unpack_pdo` (CanOpenDecodeError for a payload that is too short)."""
        unpacker = self._struct
        if unpacker is None or len(data) < self.size:
            return tuple(unpack_pdo(self.mapping, data))
        return unpacker.unpack_from(data)


# --- Object dictionary entries -------------------------------------------------------------


class DataType(IntEnum):
    """CiA 301 static data type indices (integer types only)."""

    INTEGER8 = 0x0002
    INTEGER16 = 0x0003
    INTEGER32 = 0x0004
    UNSIGNED8 = 0x0005
    UNSIGNED16 = 0x0006
    UNSIGNED32 = 0x0007
    INTEGER64 = 0x0015
    UNSIGNED64 = 0x001B

    @property
    def size(self) -> int:
        return _TYPE_FORMATS[self][1]

    @property
    def signed(self) -> bool:
        return _TYPE_FORMATS[self][0].islower()


_TYPE_FORMATS: Final[dict[DataType, tuple[str, int]]] = {
    DataType.INTEGER8: ("b", 1),
    DataType.INTEGER16: ("h", 2),
    DataType.INTEGER32: ("i", 4),
    DataType.UNSIGNED8: ("B", 1),
    DataType.UNSIGNED16: ("H", 2),
    DataType.UNSIGNED32: ("I", 4),
    DataType.INTEGER64: ("q", 8),
    DataType.UNSIGNED64: ("Q", 8),
}


@dataclass(frozen=True)
class ObjectEntry:
    """An object dictionary entry with its data type, to (de)serialise SDO/PDO values."""

    index: int
    subindex: int
    data_type: DataType

    def encode(self, value: int) -> bytes:
        try:
            return struct.pack("<" + _TYPE_FORMATS[self.data_type][0], value)
        except struct.error as exc:
            raise ValueError(f"{value} does not fit {self.data_type.name}") from exc

    def decode(self, data: bytes) -> int:
        """Decode the first ``size`` bytes (an expedited reply without size carries 4)."""
        fmt, size = _TYPE_FORMATS[self.data_type]
        if len(data) < size:
            raise CanOpenDecodeError(
                f"{self.index:#06x}:{self.subindex} needs {size} bytes, got {len(data)}"
            )
        value: int = struct.unpack_from("<" + fmt, data)[0]
        return value

    def map_entry(self) -> PdoMapEntry:
        return PdoMapEntry(
            self.index, self.subindex, self.data_type.size * 8, self.data_type.signed
        )


# --- Frame codec ---------------------------------------------------------------------------

CanOpenMessage: TypeAlias = (
    NmtControl
    | Sync
    | Emergency
    | Heartbeat
    | SdoUploadRequest
    | SdoUploadResponse
    | SdoDownloadRequest
    | SdoDownloadResponse
    | SdoSegmentedUploadResponse
    | SdoSegmentedDownloadRequest
    | SdoUploadSegmentRequest
    | SdoUploadSegment
    | SdoDownloadSegment
    | SdoDownloadSegmentResponse
    | SdoUnsupportedRequest
    | SdoAbort
    | Pdo
)

#: Every SDO message sent by a client (on 0x600 + node).
SDO_CLIENT_MESSAGES: Final = (
    SdoUploadRequest,
    SdoDownloadRequest,
    SdoSegmentedDownloadRequest,
    SdoUploadSegmentRequest,
    SdoDownloadSegment,
    SdoUnsupportedRequest,
)


def _sdo_frame(command: int, msg: _SdoBase, data: bytes = b"") -> bytes:
    return struct.pack("<BHB", command, msg.index, msg.subindex) + data.ljust(4, b"\x00")


def _expedited_command(specifier: int, data: bytes) -> int:
    return specifier << 5 | (4 - len(data)) << 2 | _E_BIT | _S_BIT


def _segmented_initiate(specifier: int, msg: _SdoBase, size: int | None) -> bytes:
    if size is None:
        return _sdo_frame(specifier << 5, msg)
    return _sdo_frame(specifier << 5 | _S_BIT, msg, size.to_bytes(4, "little"))


def _segment_frame(
    specifier: int, msg: _SdoSegmentBase, data: bytes = b"", *, last: bool | None = None
) -> bytes:
    command = specifier << 5 | (_T_BIT if msg.toggle else 0)
    if last is not None:
        command |= (SDO_SEGMENT_SIZE - len(data)) << 1 | (_C_BIT if last else 0)
    return bytes((command,)) + data.ljust(SDO_SEGMENT_SIZE, b"\x00")


def encode(msg: CanOpenMessage) -> tuple[int, bytes]:
    """Return ``(cob_id, data)`` for one message."""
    match msg:
        case NmtControl():
            return NMT_COB_ID, bytes((msg.command, msg.node_id))
        case Sync():
            return SYNC_COB_ID, b"" if msg.counter is None else bytes((msg.counter,))
        case Emergency():
            body = struct.pack("<HB", msg.error_code, msg.error_register) + msg.manufacturer
            return EMCY_BASE + msg.node_id, body
        case Heartbeat():
            return HEARTBEAT_BASE + msg.node_id, bytes((msg.state | (0x80 if msg.toggle else 0),))
        case SdoUploadRequest():
            return SDO_RX_BASE + msg.node_id, _sdo_frame(_CCS_UPLOAD << 5, msg)
        case SdoDownloadRequest():
            if msg.size_indicated:
                command = _expedited_command(_CCS_DOWNLOAD, msg.data)
            else:
                command = _CCS_DOWNLOAD << 5 | _E_BIT
            return SDO_RX_BASE + msg.node_id, _sdo_frame(command, msg, msg.data)
        case SdoSegmentedDownloadRequest():
            return SDO_RX_BASE + msg.node_id, _segmented_initiate(_CCS_DOWNLOAD, msg, msg.size)
        case SdoSegmentedUploadResponse():
            return SDO_TX_BASE + msg.node_id, _segmented_initiate(_SCS_UPLOAD, msg, msg.size)
        case SdoUploadSegmentRequest():
            return SDO_RX_BASE + msg.node_id, _segment_frame(_CCS_UPLOAD_SEGMENT, msg)
        case SdoDownloadSegmentResponse():
            return SDO_TX_BASE + msg.node_id, _segment_frame(_SCS_DOWNLOAD_SEGMENT, msg)
        case SdoUploadSegment():
            frame = _segment_frame(_SCS_UPLOAD_SEGMENT, msg, msg.data, last=msg.last)
            return SDO_TX_BASE + msg.node_id, frame
        case SdoDownloadSegment():
            frame = _segment_frame(_CCS_DOWNLOAD_SEGMENT, msg, msg.data, last=msg.last)
            return SDO_RX_BASE + msg.node_id, frame
        case SdoUnsupportedRequest():
            return SDO_RX_BASE + msg.node_id, _sdo_frame(msg.command, msg, msg.payload)
        case SdoUploadResponse():
            command = _expedited_command(_SCS_UPLOAD, msg.data)
            return SDO_TX_BASE + msg.node_id, _sdo_frame(command, msg, msg.data)
        case SdoDownloadResponse():
            return SDO_TX_BASE + msg.node_id, _sdo_frame(_SCS_DOWNLOAD << 5, msg)
        case SdoAbort():
            base = SDO_RX_BASE if msg.from_client else SDO_TX_BASE
            return base + msg.node_id, _sdo_frame(
                _CS_ABORT << 5, msg, msg.code.to_bytes(4, "little")
            )
        case Pdo():
            bases = TPDO_BASES if msg.transmit else RPDO_BASES
            return bases[msg.number - 1] + msg.node_id, msg.data
    raise TypeError(f"not a CANopen message: {msg!r}")


def _expedited_data(command: int, payload: bytes) -> bytes:
    if not command & _S_BIT:
        return payload  # size not indicated: all four bytes
    return payload[: 4 - ((command >> 2) & 0x03)]


def _indicated_size(command: int, payload: bytes) -> int | None:
    return int.from_bytes(payload, "little") if command & _S_BIT else None


def _segment_data(data: bytes) -> tuple[bool, bytes, bool]:
    command = data[0]
    size = SDO_SEGMENT_SIZE - ((command >> 1) & 0x07)
    return bool(command & _T_BIT), data[1 : 1 + size], bool(command & _C_BIT)


def _decode_sdo(node_id: int, data: bytes, *, from_client: bool) -> CanOpenMessage:
    if len(data) != _SDO_LEN:
        raise CanOpenDecodeError(f"SDO frames are 8 bytes, got {len(data)}")
    command, index, subindex = struct.unpack_from("<BHB", data)
    payload = data[4:8]
    specifier = command >> 5
    toggle = bool(command & _T_BIT)
    if specifier == _CS_ABORT:
        code = int.from_bytes(payload, "little")
        return SdoAbort(node_id, index, subindex, code, from_client)
    if from_client:
        if specifier == _CCS_UPLOAD:
            return SdoUploadRequest(node_id, index, subindex)
        if specifier == _CCS_DOWNLOAD and command & _E_BIT:
            indicated = bool(command & _S_BIT)
            return SdoDownloadRequest(
                node_id, index, subindex, _expedited_data(command, payload), indicated
            )
        if specifier == _CCS_DOWNLOAD:
            size = _indicated_size(command, payload)
            return SdoSegmentedDownloadRequest(node_id, index, subindex, size)
        if specifier == _CCS_UPLOAD_SEGMENT:
            return SdoUploadSegmentRequest(node_id, toggle)
        if specifier == _CCS_DOWNLOAD_SEGMENT:
            return SdoDownloadSegment(node_id, *_segment_data(data))
        return SdoUnsupportedRequest(node_id, index, subindex, command, payload)
    if specifier == _SCS_UPLOAD and command & _E_BIT:
        return SdoUploadResponse(node_id, index, subindex, _expedited_data(command, payload))
    if specifier == _SCS_UPLOAD:
        return SdoSegmentedUploadResponse(
            node_id, index, subindex, _indicated_size(command, payload)
        )
    if specifier == _SCS_DOWNLOAD:
        return SdoDownloadResponse(node_id, index, subindex)
    if specifier == _SCS_UPLOAD_SEGMENT:
        return SdoUploadSegment(node_id, *_segment_data(data))
    if specifier == _SCS_DOWNLOAD_SEGMENT:
        return SdoDownloadSegmentResponse(node_id, toggle)
    raise CanOpenDecodeError(f"unsupported SDO server command specifier {specifier} (block)")


def decode(cob_id: int, data: bytes | bytearray) -> CanOpenMessage:
    """Decode one frame; raises only :class:`CanOpenDecodeError`."""
    data = bytes(data)
    if len(data) > 8:
        raise CanOpenDecodeError(f"classic CAN frame carries at most 8 bytes, got {len(data)}")
    if not 0 <= cob_id <= 0x7FF:
        raise CanOpenDecodeError(f"COB-ID {cob_id:#x} is not an 11-bit id")
    if cob_id == NMT_COB_ID:
        if len(data) != 2:
            raise CanOpenDecodeError(f"NMT frames are 2 bytes, got {len(data)}")
        try:
            return NmtControl(data[0], data[1])
        except ValueError as exc:
            raise CanOpenDecodeError(f"bad NMT frame {data.hex()}: {exc}") from None
    if cob_id == SYNC_COB_ID:
        if len(data) > 1 or (data and not 1 <= data[0] <= 240):
            raise CanOpenDecodeError(f"bad SYNC payload {data.hex()}")
        return Sync(data[0] if data else None)
    function, node_id = cob_id & 0x780, cob_id & 0x7F
    if node_id == 0:
        raise CanOpenDecodeError(f"COB-ID {cob_id:#05x} has node id 0")
    if function == EMCY_BASE:
        if len(data) != 8:
            raise CanOpenDecodeError(f"EMCY frames are 8 bytes, got {len(data)}")
        code, register = struct.unpack_from("<HB", data)
        return Emergency(node_id, code, register, data[3:8])
    if function == HEARTBEAT_BASE:
        if len(data) != 1:
            raise CanOpenDecodeError(f"heartbeat frames are 1 byte, got {len(data)}")
        return Heartbeat(node_id, data[0] & 0x7F, bool(data[0] & 0x80))
    if function == SDO_TX_BASE:
        return _decode_sdo(node_id, data, from_client=False)
    if function == SDO_RX_BASE:
        return _decode_sdo(node_id, data, from_client=True)
    if function in TPDO_BASES:
        return Pdo(node_id, TPDO_BASES.index(function) + 1, True, data)
    if function in RPDO_BASES:
        return Pdo(node_id, RPDO_BASES.index(function) + 1, False, data)
    raise CanOpenDecodeError(f"unsupported COB-ID {cob_id:#05x}")
