"""A listen-only decoder of a servo bus's byte stream, both directions at once (the serial
side of ``openel-async bus monitor``, :mod:`openel_serial.monitor`).

A second adapter on the same RS-485/TTL line hears the host's instruction packets and the
servos' status packets as one stream, in the order they pass. :class:`DynamixelSniffer` and
:class:`FeetechSniffer` split it into packets (:class:`DynamixelSplitter`,
:class:`FeetechSplitter`: resynchronised on the next header after garbage, counting checksum
and length errors and the bytes dropped) and print each with its instruction and its
control-table items by name:

* **Dynamixel Protocol 2.0** (byte stuffing, CRC-16): a packet says what it is (STATUS is
  instruction 0x55). A status is decoded by the request it answers: the last READ, SYNC READ
  or BULK READ that asked its id (the items by name), a PING (model number and firmware);
  its error byte by :class:`openel_serial.dynamixel.ErrorNumber` and the alert bit.
* **Feetech SCS/STS** (checksum, no stuffing): an instruction and a status have the same
  shape, so the direction is inferred: a packet from an id that owes a reply (a PING or READ
  to it, a SYNC READ naming it; a WRITE, REG WRITE, ACTION or RESET to it, when the packet
  carries no params: those statuses are empty) is a status; a packet whose code is not an
  instruction (0: no alarm) is a status; anything else is an instruction. The status's error
  byte is the servo's alarms (:class:`openel_serial.feetech.StatusError`).

Items are named from the driver's tables (:class:`openel_serial.dynamixel_table.XSeries`,
:class:`openel_serial.feetech.STS`): ``GOAL_POSITION`` prints as ``Goal Position``; bytes
of no item print as ``@45=0x12``.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Final, Protocol

from . import dynamixel as dx
from . import feetech as ft
from .errors import DynamixelDecodeError, FeetechDecodeError

__all__ = [
    "DynamixelSniffer",
    "DynamixelSplitter",
    "FeetechSniffer",
    "FeetechSplitter",
    "Frame",
    "Sniffer",
    "SplitCounters",
    "item_names",
]


class _Item(Protocol):
    @property
    def address(self) -> int: ...

    @property
    def size(self) -> int: ...

    def decode(self, data: bytes) -> int: ...


_ACRONYMS: Final = frozenset({"ID", "LED", "PWM", "CW", "CCW", "P", "I", "D"})


def _title(name: str) -> str:
    return " ".join(w if w in _ACRONYMS else w.capitalize() for w in name.split("_"))


def item_names(table: type) -> dict[int, tuple[str, _Item]]:
    """``{address: (name, item)}`` of a control-table class's items."""
    out: dict[int, tuple[str, _Item]] = {}
    for name, value in vars(table).items():
        if hasattr(value, "address") and hasattr(value, "size") and hasattr(value, "decode"):
            out.setdefault(value.address, (_title(name), value))
    return out


def _covered(table: Mapping[int, tuple[str, _Item]], address: int, length: int) -> list[str]:
    return [
        n
        for a, (n, item) in sorted(table.items())
        if address <= a and a + item.size <= address + length
    ]


def _read_text(table: Mapping[int, tuple[str, _Item]], address: int, length: int) -> str:
    names = _covered(table, address, length)
    exact = address in table and table[address][1].size == length
    if exact:
        return names[0]
    return f"{address}+{length}" + (f" ({', '.join(names)})" if names else "")


def _items_text(table: Mapping[int, tuple[str, _Item]], address: int, data: bytes) -> str:
    """``Goal Position=2048 Goal Time=0``: each item the bytes from ``address`` hold."""
    parts: list[str] = []
    at = 0
    while at < len(data):
        found = table.get(address + at)
        if found is not None and at + found[1].size <= len(data):
            name, item = found
            try:
                parts.append(f"{name}={item.decode(bytes(data[at : at + item.size]))}")
            except (ValueError, DynamixelDecodeError, FeetechDecodeError):
                parts.append(f"{name}=?")
            at += item.size
            continue
        parts.append(f"@{address + at}={data[at]:#04x}")
        at += 1
    return " ".join(parts)


@dataclass(frozen=True)
class Frame:
    """One packet heard, decoded."""

    timestamp: float
    data: bytes
    """The packet's bytes as on the wire."""
    protocol: str
    """``dynamixel`` or ``feetech``."""
    text: str
    servo_id: int | None = None
    kind: str = ""
    """The instruction (``PING``, ``SYNC READ``...) or ``STATUS``; ``CORRUPT``: a packet whose
    checksum failed."""
    malformed: bool = False

    def line(self, since: float = 0.0) -> str:
        shown = self.data.hex(" ")
        if len(shown) > 47:
            shown = shown[:44] + "..."
        return f"{self.timestamp - since:10.4f}  [{len(self.data):3}] {shown:<47}  {self.text}"

    def to_dict(self) -> dict[str, Any]:
        return {
            "t": round(self.timestamp, 6),
            "id": self.servo_id,
            "data": self.data.hex(),
            "protocol": self.protocol,
            "kind": self.kind,
            "text": self.text,
            "malformed": self.malformed,
        }


@dataclass
class SplitCounters:
    """What a splitter counted besides the packets."""

    packets: int = 0
    checksum_errors: int = 0
    length_errors: int = 0
    dropped_bytes: int = 0


@dataclass(frozen=True)
class Corrupt:
    """A packet-shaped run of bytes whose checksum failed."""

    data: bytes


# -- splitters ----------------------------------------------------------------------------


@dataclass
class DynamixelSplitter:
    """Dynamixel 2.0 packets out of a byte stream (never raises): bytes before a header are
    dropped; a candidate is given up (its first byte dropped, the search resumes after it)
    when its length field is out of range, when a header starts inside it (byte stuffing
    keeps one out of a genuine packet, but for its last 4 bytes) or when its CRC fails."""

    max_length: int = 1024
    counters: SplitCounters = field(default_factory=SplitCounters)
    _buf: bytearray = field(default_factory=bytearray)

    @property
    def buffered(self) -> int:
        return len(self._buf)

    def feed(self, data: bytes) -> list[bytes | Corrupt]:
        buf = self._buf
        buf += data
        out: list[bytes | Corrupt] = []
        c = self.counters
        header = dx.HEADER
        while True:
            start = buf.find(header)
            if start < 0:
                keep = next((k for k in (3, 2, 1) if buf.endswith(header[:k])), 0)
                c.dropped_bytes += len(buf) - keep
                del buf[: len(buf) - keep]
                break
            if start:
                c.dropped_bytes += start
                del buf[:start]
            if len(buf) < 7:
                break
            length = buf[5] | buf[6] << 8
            if not 3 <= length <= self.max_length:
                c.length_errors += 1
                c.dropped_bytes += 1
                del buf[:1]
                continue
            total = 7 + length
            if buf.find(header, 1, min(len(buf), total - 1)) >= 0:
                c.length_errors += 1  # cut short by the next packet
                c.dropped_bytes += 1
                del buf[:1]
                continue
            if len(buf) < total:
                break
            packet = bytes(buf[:total])
            if dx.crc16(packet[:-2]) != int.from_bytes(packet[-2:], "little"):
                c.checksum_errors += 1
                c.dropped_bytes += 1
                out.append(Corrupt(packet))
                del buf[:1]
                continue
            del buf[:total]
            c.packets += 1
            out.append(packet)
        return out


@dataclass
class FeetechSplitter:
    """Feetech packets out of a byte stream (never raises): ``FF FF``, an id (0..0xFE), a
    length 2..``max_length`` and a matching checksum; else the first byte is dropped and the
    search resumes after it."""

    max_length: int = ft.MAX_LENGTH
    counters: SplitCounters = field(default_factory=SplitCounters)
    _buf: bytearray = field(default_factory=bytearray)

    @property
    def buffered(self) -> int:
        return len(self._buf)

    def feed(self, data: bytes) -> list[bytes | Corrupt]:
        buf = self._buf
        buf += data
        out: list[bytes | Corrupt] = []
        c = self.counters
        while True:
            start = buf.find(ft.HEADER)
            if start < 0:
                keep = 1 if buf.endswith(b"\xff") else 0
                c.dropped_bytes += len(buf) - keep
                del buf[: len(buf) - keep]
                break
            if start:
                c.dropped_bytes += start
                del buf[:start]
            if len(buf) < 4:
                break
            servo_id, length = buf[2], buf[3]
            if servo_id == 0xFF:  # FF FF FF: the header may start one byte later
                c.dropped_bytes += 1
                del buf[:1]
                continue
            if not 2 <= length <= self.max_length:
                c.length_errors += 1
                c.dropped_bytes += 1
                del buf[:1]
                continue
            total = 4 + length
            if len(buf) < total:
                break
            packet = bytes(buf[:total])
            if ft.checksum(packet[2:-1]) != packet[-1]:
                c.checksum_errors += 1
                c.dropped_bytes += 1
                out.append(Corrupt(packet))
                del buf[:1]
                continue
            del buf[:total]
            c.packets += 1
            out.append(packet)
        return out


# -- sniffers -----------------------------------------------------------------------------


class Sniffer(Protocol):
    """A protocol's decoder of the stream (see the module docstring)."""

    protocol: str
    malformed: int
    kinds: Counter[str]

    @property
    def counters(self) -> SplitCounters: ...

    def feed(self, data: bytes, timestamp: float) -> list[Frame]: ...


def _ids(ids: Sequence[int]) -> str:
    """``1..6`` for a run, else ``1,3,5``."""
    if len(ids) > 2 and list(ids) == list(range(ids[0], ids[0] + len(ids))):
        return f"{ids[0]}..{ids[-1]}"
    return ",".join(map(str, ids))


def _sync_write_text(
    table: Mapping[int, tuple[str, _Item]], address: int, items: Sequence[Any]
) -> str:
    one = table.get(address)
    if one is not None and all(len(i.data) == one[1].size for i in items):
        name, item = one
        values = []
        for i in items:
            try:
                values.append(f"{i.id}={item.decode(bytes(i.data))}")
            except (ValueError, DynamixelDecodeError, FeetechDecodeError):
                values.append(f"{i.id}=?")
        return f"{_ids([i.id for i in items])} {name} {' '.join(values)}"
    return "; ".join(f"{i.id}: {_items_text(table, address, bytes(i.data))}" for i in items)


@dataclass
class DynamixelSniffer:
    """Dynamixel 2.0 packets of both directions, decoded (module docstring)."""

    table: Mapping[int, tuple[str, _Item]] = field(default_factory=lambda: item_names(dx.XSeries))
    splitter: DynamixelSplitter = field(default_factory=DynamixelSplitter)
    protocol: str = "dynamixel"
    malformed: int = 0
    kinds: Counter[str] = field(default_factory=Counter)
    _asked: dict[int, tuple[int, int] | None] = field(default_factory=dict)
    """What each id owes an answer to: (address, length) of a read, None for a PING."""

    @property
    def counters(self) -> SplitCounters:
        return self.splitter.counters

    def feed(self, data: bytes, timestamp: float) -> list[Frame]:
        frames = []
        for packet in self.splitter.feed(data):
            if isinstance(packet, Corrupt):
                raw = packet.data
                frames.append(
                    Frame(timestamp, raw, self.protocol,
                          f"Dynamixel {raw[4]}: CRC error (instruction {raw[7]:#04x})",
                          raw[4], "CORRUPT", True)
                )  # fmt: skip
                self.kinds["CORRUPT"] += 1
                continue
            frames.append(self._decode(packet, timestamp))
        return frames

    def _decode(self, packet: bytes, t: float) -> Frame:
        try:
            msg = dx.decode(packet)
        except DynamixelDecodeError as exc:
            self.malformed += 1
            self.kinds["MALFORMED"] += 1
            return Frame(t, packet, self.protocol, f"Dynamixel {packet[4]}: malformed: {exc}",
                         packet[4], "MALFORMED", True)  # fmt: skip
        kind, servo, text = self._text(msg)
        self.kinds[kind] += 1
        who = "Dynamixel" if servo is None else f"Dynamixel {servo}"
        return Frame(t, packet, self.protocol, f"{who} {kind} {text}".rstrip(), servo, kind)

    def _text(self, msg: dx.DynamixelMessage) -> tuple[str, int | None, str]:
        table = self.table
        if isinstance(msg, dx.Status):
            asked = self._asked.pop(msg.id, "?")
            error = ""
            if msg.error_number:
                try:
                    error = f" error={dx.ErrorNumber(msg.error_number).name}"
                except ValueError:
                    error = f" error={msg.error_number:#04x}"
            if msg.alert:
                error += " ALERT (hardware error status)"
            if asked is None and len(msg.params) == 3:
                model, firmware = msg.ping_info()
                body = f"model={model} firmware={firmware}"
            elif isinstance(asked, tuple) and len(msg.params) == asked[1]:
                body = _items_text(table, asked[0], msg.params)
            else:
                body = msg.params.hex(" ")
            return "STATUS", msg.id, (body + error).strip()
        if isinstance(msg, dx.Ping):
            if msg.id != dx.BROADCAST_ID:
                self._asked[msg.id] = None
            return "PING", msg.id, ""
        if isinstance(msg, dx.Read):
            self._asked[msg.id] = (msg.address, msg.length)
            return "READ", msg.id, _read_text(table, msg.address, msg.length)
        if isinstance(msg, dx.Write):  # and RegWrite
            kind = "REG_WRITE" if isinstance(msg, dx.RegWrite) else "WRITE"
            self._asked[msg.id] = (msg.address, 0)
            return kind, msg.id, _items_text(table, msg.address, msg.data)
        if isinstance(msg, dx.SyncRead):  # and FastSyncRead
            for i in msg.ids:
                self._asked[i] = (msg.address, msg.length)
            kind = "FAST SYNC READ" if isinstance(msg, dx.FastSyncRead) else "SYNC READ"
            return kind, None, f"{_ids(msg.ids)} {_read_text(table, msg.address, msg.length)}"
        if isinstance(msg, dx.SyncWrite):
            return "SYNC WRITE", None, _sync_write_text(table, msg.address, msg.items)
        if isinstance(msg, dx.BulkRead):
            for r in msg.items:
                self._asked[r.id] = (r.address, r.length)
            return (
                "BULK READ",
                None,
                "; ".join(f"{r.id}: {_read_text(table, r.address, r.length)}" for r in msg.items),
            )
        if isinstance(msg, dx.BulkWrite):
            return (
                "BULK WRITE",
                None,
                "; ".join(f"{w.id}: {_items_text(table, w.address, w.data)}" for w in msg.items),
            )
        if isinstance(msg, dx.FactoryReset):
            return "FACTORY_RESET", msg.id, f"mode={msg.mode.name}"
        if isinstance(msg, dx.Clear):
            return "CLEAR", msg.id, f"option={msg.option}"
        return type(msg).__name__.upper(), msg.id, ""  # Action, Reboot


_FEETECH_CODES: Final = frozenset(int(i) for i in ft.Instruction)
_FEETECH_ANSWERED: Final = frozenset({ft.Instruction.PING, ft.Instruction.READ})
_FEETECH_MAYBE: Final = frozenset(
    {ft.Instruction.WRITE, ft.Instruction.REG_WRITE, ft.Instruction.ACTION, ft.Instruction.RESET}
)


@dataclass
class FeetechSniffer:
    """Feetech packets of both directions, decoded (module docstring)."""

    table: Mapping[int, tuple[str, _Item]] = field(default_factory=lambda: item_names(ft.STS))
    splitter: FeetechSplitter = field(default_factory=FeetechSplitter)
    protocol: str = "feetech"
    malformed: int = 0
    kinds: Counter[str] = field(default_factory=Counter)
    _asked: dict[int, tuple[int, int] | None] = field(default_factory=dict)
    """Ids owing a status: (address, length) of a read, None for a PING."""
    _maybe: set[int] = field(default_factory=set)
    """Ids that may answer a write (Response Status Level 1) with an empty status."""

    @property
    def counters(self) -> SplitCounters:
        return self.splitter.counters

    def feed(self, data: bytes, timestamp: float) -> list[Frame]:
        frames = []
        for packet in self.splitter.feed(data):
            if isinstance(packet, Corrupt):
                raw = packet.data
                frames.append(
                    Frame(timestamp, raw, self.protocol, f"Feetech {raw[2]}: checksum error",
                          raw[2], "CORRUPT", True)
                )  # fmt: skip
                self.kinds["CORRUPT"] += 1
                continue
            frames.append(self._decode(packet, timestamp))
        return frames

    def _is_status(self, servo_id: int, code: int, params: int) -> bool:
        if servo_id in self._asked:
            return True
        if servo_id in self._maybe and params == 0:
            return True
        return code not in _FEETECH_CODES

    def _decode(self, packet: bytes, t: float) -> Frame:
        servo_id, code = packet[2], packet[4]
        status = self._is_status(servo_id, code, len(packet) - 6)
        self._maybe.discard(servo_id)
        try:
            msg = ft.decode(packet, status=status)
        except FeetechDecodeError as exc:
            self.malformed += 1
            self.kinds["MALFORMED"] += 1
            return Frame(t, packet, self.protocol, f"Feetech {servo_id}: malformed: {exc}",
                         servo_id, "MALFORMED", True)  # fmt: skip
        kind, servo, text = self._text(msg)
        self.kinds[kind] += 1
        who = "Feetech" if servo is None else f"Feetech {servo}"
        return Frame(t, packet, self.protocol, f"{who} {kind} {text}".rstrip(), servo, kind)

    def _text(self, msg: ft.FeetechMessage) -> tuple[str, int | None, str]:
        table = self.table
        if isinstance(msg, ft.Status):
            asked = self._asked.pop(msg.id, "?")
            alarms = "" if not msg.error else f" alarms={msg.alarms.describe()}"
            if asked is None or not msg.params:
                body = msg.params.hex(" ")
            elif isinstance(asked, tuple) and len(msg.params) == asked[1]:
                body = _items_text(table, asked[0], msg.params)
            else:
                body = msg.params.hex(" ")
            return "STATUS", msg.id, (body + alarms).strip()
        broadcast = getattr(msg, "id", None) == ft.BROADCAST_ID
        if isinstance(msg, ft.Ping):
            if not broadcast:
                self._asked[msg.id] = None
            return "PING", msg.id, ""
        if isinstance(msg, ft.Read):
            if not broadcast:
                self._asked[msg.id] = (msg.address, msg.length)
            return "READ", msg.id, _read_text(table, msg.address, msg.length)
        if isinstance(msg, ft.SyncRead):
            for i in msg.ids:
                self._asked[i] = (msg.address, msg.length)
            return (
                "SYNC READ",
                None,
                f"{_ids(msg.ids)} {_read_text(table, msg.address, msg.length)}",
            )
        if isinstance(msg, ft.SyncWrite):
            return "SYNC WRITE", None, _sync_write_text(table, msg.address, msg.items)
        if not broadcast:
            self._maybe.add(msg.id)
        if isinstance(msg, ft.Write):  # and RegWrite
            kind = "REG_WRITE" if isinstance(msg, ft.RegWrite) else "WRITE"
            return kind, msg.id, _items_text(table, msg.address, msg.data)
        return type(msg).__name__.upper(), msg.id, ""  # Action, Reset
