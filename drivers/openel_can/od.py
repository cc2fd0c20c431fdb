"""Object dictionaries from EDS and DCF files (CiA 306), addressed by name or index.

:func:`load_od` parses a vendor's EDS, or a DCF (an EDS with ``ParameterValue`` entries
and the node's commissioning), with canopen-py's parser
(:func:`canopen.objectdictionary.import_od`) and turns it into an immutable
:class:`ObjectDictionary` of :class:`OdEntry` items: index and sub-index, name, CiA 301
data type, access rights, PDO mappability, default value, the DCF's parameter value and
the limits. ``$NODEID`` in a default or parameter value is resolved with ``node_id`` (a
DCF names its own node id).

An object is found by any :data:`ObjectKey`: its name (``"Controlword"``; a record's or
array's entry as ``"Identity object.Vendor-ID"``), its index text (``"0x6040"``,
``"0x1018:1"``, ``"0x1018sub1"``), an ``(index, subindex)`` pair, an ``int`` index of a
variable, an :class:`OdEntry` or a :class:`~openel_can.canopen.ObjectEntry`. A name
matches exactly first, then as an index text, then ignoring case. An unknown object raises
:class:`ObjectNotFoundError` (a :class:`~openel_async.errors.BadParameterError`) naming
the key, the file and the closest names.

:meth:`OdEntry.encode` / :meth:`OdEntry.decode` convert values by the entry's data type
(integers of 8..64 bits, BOOLEAN, REAL32/REAL64, VISIBLE_STRING, UNICODE_STRING,
OCTET_STRING, DOMAIN); a value of the wrong type or outside the type's range or the
file's LowLimit/HighLimit raises ``BadParameterError`` naming the object and what is
allowed. The SDO client reads and writes by entry or name
(:meth:`openel_can.sdo.SdoClient.read`), and :func:`write_parameter_values` writes a DCF's
parameter values to a node.

:data:`SHIPPED_EDS` is the EDS of the simulated CiA 402 servo drive
(:class:`~openel_can.sim.cia402.SimCia402Drive`), package data in ``openel_can/eds``.
"""

from __future__ import annotations

import configparser
import difflib
import math
import os
import re
import struct
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Final, TypeAlias

from canopen import objectdictionary as cod

from openel_async.errors import BadParameterError
from openel_async.logs import get_logger

from . import canopen as co
from .errors import CanOpenDecodeError

if TYPE_CHECKING:
    from .sdo import SdoClient

__all__ = [
    "SHIPPED_EDS",
    "Access",
    "ObjectDictionary",
    "ObjectKey",
    "ObjectNotFoundError",
    "OdEntry",
    "OdValue",
    "load_od",
    "parse_key",
    "write_parameter_values",
]

log = get_logger(__name__)

SHIPPED_EDS: Final = Path(__file__).parent / "eds" / "openel_servo402.eds"
"""The EDS of the simulated CiA 402 servo drive (see ``openel_can/eds/README.md``)."""

OdValue: TypeAlias = int | float | str | bytes | bool
"""A decoded object value: int (integer types), bool (BOOLEAN), float (REAL32/64), str
(VISIBLE_STRING, UNICODE_STRING) or bytes (OCTET_STRING, DOMAIN)."""


class Access(StrEnum):
    """CiA 306 AccessType: ``rww`` is writable and mappable into RPDOs (process output),
    ``rwr`` readable and mappable into TPDOs (process input)."""

    RO = "ro"
    WO = "wo"
    RW = "rw"
    RWR = "rwr"
    RWW = "rww"
    CONST = "const"

    @property
    def readable(self) -> bool:
        return self is not Access.WO

    @property
    def writable(self) -> bool:
        return self in (Access.WO, Access.RW, Access.RWR, Access.RWW)


# CiA 301 data types: integer types as (bits, signed).
_INTEGERS: Final[dict[int, tuple[int, bool]]] = {
    cod.INTEGER8: (8, True),
    cod.INTEGER16: (16, True),
    cod.INTEGER24: (24, True),
    cod.INTEGER32: (32, True),
    cod.INTEGER40: (40, True),
    cod.INTEGER48: (48, True),
    cod.INTEGER56: (56, True),
    cod.INTEGER64: (64, True),
    cod.UNSIGNED8: (8, False),
    cod.UNSIGNED16: (16, False),
    cod.UNSIGNED24: (24, False),
    cod.UNSIGNED32: (32, False),
    cod.UNSIGNED40: (40, False),
    cod.UNSIGNED48: (48, False),
    cod.UNSIGNED56: (56, False),
    cod.UNSIGNED64: (64, False),
}
_FLOATS: Final[dict[int, str]] = {cod.REAL32: "<f", cod.REAL64: "<d"}
_TYPE_NAMES: Final[dict[int, str]] = {
    code: name
    for name, code in vars(cod.datatypes).items()
    if name.isupper() and isinstance(code, int) and code <= 0x1B
}
_STRINGS: Final = (cod.VISIBLE_STRING, cod.UNICODE_STRING)
_BYTES: Final = (cod.OCTET_STRING, cod.DOMAIN)
_SUPPORTED: Final = frozenset((*_INTEGERS, *_FLOATS, cod.BOOLEAN, *_STRINGS, *_BYTES))


def _type_name(code: int) -> str:
    return _TYPE_NAMES.get(code, f"data type {code:#06x}")


@dataclass(frozen=True, slots=True)
class OdEntry:
    """One object (or sub-object) of an object dictionary file."""

    index: int
    subindex: int
    name: str
    """``"Controlword"``; an entry of a record or array: ``"Identity object.Vendor-ID"``."""
    data_type: int
    """CiA 301 data type code (0x0007 UNSIGNED32 ...); :attr:`type_name` spells it."""
    access: Access
    pdo_mappable: bool
    default: OdValue | None = None
    parameter_value: OdValue | None = None
    """A DCF's ParameterValue (None in an EDS)."""
    low: int | float | None = None
    high: int | float | None = None

    @property
    def key(self) -> tuple[int, int]:
        return self.index, self.subindex

    @property
    def label(self) -> str:
        """``Controlword (0x6040:0)``: how errors name the object."""
        return f"{self.name} ({self.index:#06x}:{self.subindex})"

    @property
    def type_name(self) -> str:
        return _type_name(self.data_type)

    @property
    def readable(self) -> bool:
        return self.access.readable

    @property
    def writable(self) -> bool:
        return self.access.writable

    @property
    def rpdo_mappable(self) -> bool:
        """May be mapped into an RPDO (master -> node): PDO-mappable and writable by the
        bus (``wo``, ``rw``, ``rww``; ``rwr`` is process input, TPDO only)."""
        return self.pdo_mappable and self.access in (Access.WO, Access.RW, Access.RWW)

    @property
    def tpdo_mappable(self) -> bool:
        """May be mapped into a TPDO (node -> master): PDO-mappable and readable
        (``ro``, ``const``, ``rw``, ``rwr``; ``rww`` is process output, RPDO only)."""
        return self.pdo_mappable and self.access in (Access.RO, Access.CONST, Access.RW, Access.RWR)

    @property
    def value(self) -> OdValue | None:
        """The configured value: the DCF's parameter value, else the default."""
        return self.default if self.parameter_value is None else self.parameter_value

    @property
    def size(self) -> int | None:
        """Bytes of a value (None: variable length, strings and domains)."""
        if self.data_type in _INTEGERS:
            return _INTEGERS[self.data_type][0] // 8
        if self.data_type in _FLOATS:
            return struct.calcsize(_FLOATS[self.data_type])
        if self.data_type == cod.BOOLEAN:
            return 1
        return None

    @property
    def bit_length(self) -> int | None:
        """Bits in a PDO (None: not a fixed-size type)."""
        size = self.size
        return None if size is None else size * 8

    @property
    def signed(self) -> bool:
        return self.data_type in _INTEGERS and _INTEGERS[self.data_type][1]

    @property
    def is_integer(self) -> bool:
        """An integer or BOOLEAN: carried as an int in PDOs and by :attr:`object_entry`."""
        return self.data_type in _INTEGERS or self.data_type == cod.BOOLEAN

    @property
    def object_entry(self) -> co.ObjectEntry:
        """The codec entry of :mod:`openel_can.canopen` (8/16/32/64-bit integers only)."""
        try:
            data_type = co.DataType(self.data_type)
        except ValueError:
            raise BadParameterError(
                self.label,
                self.type_name,
                "an 8, 16, 32 or 64-bit integer object (openel_can.canopen.DataType)",
            ) from None
        return co.ObjectEntry(self.index, self.subindex, data_type)

    def map_entry(self) -> co.PdoMapEntry:
        """Its PDO mapping entry (``index << 16 | subindex << 8 | bits``)."""
        bits = self.bit_length
        if bits is None:
            raise BadParameterError(self.label, self.type_name, "a fixed-size object for a PDO")
        return co.PdoMapEntry(self.index, self.subindex, bits, self.signed)

    # -- values ---------------------------------------------------------------------------
    def check(self, value: object) -> OdValue:
        """``value`` as this object holds it; ``BadParameterError`` naming the object and
        what is allowed (type, range of the type, the file's limits)."""
        code = self.data_type
        if code == cod.BOOLEAN:
            if isinstance(value, bool) or (isinstance(value, int) and value in (0, 1)):
                return bool(value)
            raise BadParameterError(self.label, value, "a BOOLEAN (True/False or 0/1)")
        if code in _INTEGERS:
            bits, signed = _INTEGERS[code]
            low = -(1 << (bits - 1)) if signed else 0
            high = (1 << (bits - 1)) - 1 if signed else (1 << bits) - 1
            if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
                raise BadParameterError(self.label, value, f"a {self.type_name} in {low}..{high}")
            self._check_limits(value)
            return value
        if code in _FLOATS:
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise BadParameterError(self.label, value, f"a {self.type_name} (a number)")
            number = float(value)
            if code == cod.REAL32 and math.isfinite(number) and abs(number) > 3.4028234663852886e38:
                raise BadParameterError(self.label, value, "a REAL32 within ±3.4028235e38")
            self._check_limits(number)
            return number
        if code in _STRINGS:
            if not isinstance(value, str) or (
                code == cod.VISIBLE_STRING and not (value.isascii() and value.isprintable())
            ):
                raise BadParameterError(self.label, value, f"a {self.type_name} (printable text)")
            return value
        if code in _BYTES:
            if not isinstance(value, bytes | bytearray):
                raise BadParameterError(self.label, value, f"{self.type_name} bytes")
            return bytes(value)
        raise BadParameterError(
            self.label, self.type_name, "a data type openel_can.od supports: " + _supported()
        )

    def _check_limits(self, value: int | float) -> None:
        low, high = self.low, self.high
        if (low is not None and value < low) or (high is not None and value > high):
            raise BadParameterError(
                self.label,
                value,
                f"a value in {'-inf' if low is None else low}..{'inf' if high is None else high}"
                " (the file's LowLimit..HighLimit)",
            )

    def encode(self, value: object) -> bytes:
        """The bytes of ``value`` (checked as by :meth:`check`), little-endian."""
        checked = self.check(value)
        code = self.data_type
        if code == cod.BOOLEAN:
            return b"\x01" if checked else b"\x00"
        if code in _INTEGERS:
            assert isinstance(checked, int)
            bits, signed = _INTEGERS[code]
            return checked.to_bytes(bits // 8, "little", signed=signed)
        if code in _FLOATS:
            assert isinstance(checked, float)
            return struct.pack(_FLOATS[code], checked)
        if code in _STRINGS:
            assert isinstance(checked, str)
            return checked.encode("ascii" if code == cod.VISIBLE_STRING else "utf-16-le")
        assert isinstance(checked, bytes)
        return checked

    def decode(self, data: bytes | bytearray) -> OdValue:
        """The value in ``data`` (a fixed-size type takes its first bytes: an expedited
        reply without size carries 4); :class:`CanOpenDecodeError` if too short."""
        data = bytes(data)
        size = self.size
        if size is not None:
            if len(data) < size:
                raise CanOpenDecodeError(f"{self.label} needs {size} bytes, got {len(data)}")
            data = data[:size]
        code = self.data_type
        if code == cod.BOOLEAN:
            return bool(data[0])
        if code in _INTEGERS:
            return int.from_bytes(data, "little", signed=_INTEGERS[code][1])
        if code in _FLOATS:
            value: float = struct.unpack(_FLOATS[code], data)[0]
            return value
        if code == cod.VISIBLE_STRING:
            return data.rstrip(b"\x00").decode("ascii", errors="replace")
        if code == cod.UNICODE_STRING:
            return data.decode("utf-16-le", errors="replace").rstrip("\x00")
        if code in _BYTES:
            return data
        raise CanOpenDecodeError(f"{self.label}: {self.type_name} is not supported")


def _supported() -> str:
    return ", ".join(sorted(_type_name(c) for c in _SUPPORTED))


ObjectKey: TypeAlias = "str | int | tuple[int, int] | OdEntry | co.ObjectEntry"
"""How an object is named: see the module docstring."""

_INDEX_KEY: Final = re.compile(
    r"^(?:0x([0-9a-f]{1,4})|([0-9a-f]{4})h?)(?:(?::|sub)(?:0x)?([0-9a-f]{1,2}))?$", re.IGNORECASE
)


def parse_key(text: str) -> tuple[int, int | None] | None:
    """``(index, subindex)`` of an index text (``"0x6040"``, ``"0x1018:1"``,
    ``"0x1018sub1"``, ``"1018sub1"``, ``"6040h"``); sub-index None when not given; None
    when ``text`` is not an index (a name).

    A sub-index is hexadecimal, as in EDS section names (``"0x1600:a"`` and
    ``"0x1600sub0A"`` are sub-index 10).
    """
    match = _INDEX_KEY.match(text.strip())
    if match is None:
        return None
    index = int(match.group(1) or match.group(2), 16)
    sub = match.group(3)
    return index, None if sub is None else int(sub, 16)


class ObjectNotFoundError(BadParameterError):
    """No object of the dictionary has that name or index."""

    def __init__(self, key: object, od: ObjectDictionary, hint: str = "") -> None:
        allowed = (
            f"an object of {od.source} by name (e.g. {od.example_names()}) or by index "
            f"('0x6040', '0x1018:1')"
        )
        super().__init__("object", key, allowed + (f"; {hint}" if hint else ""))


class ObjectDictionary:
    """An immutable object dictionary: entries by ``(index, subindex)`` and by name."""

    def __init__(
        self,
        entries: Iterable[OdEntry],
        *,
        source: str = "<object dictionary>",
        node_id: int | None = None,
        device: dict[str, object] | None = None,
        records: Iterable[int] = (),
    ) -> None:
        self.source = source
        """The file (its name) the dictionary was read from."""
        self.node_id = node_id
        """The node id ``$NODEID`` was resolved with (a DCF's own, or the one given)."""
        self.device: dict[str, object] = dict(device or {})
        """The file's DeviceInfo (vendor_name, product_name, nr_of_RXPDO ...)."""
        self._entries: dict[tuple[int, int], OdEntry] = {}
        for entry in sorted(entries, key=lambda e: e.key):
            if entry.key in self._entries:
                raise BadParameterError("object", entry.label, "one entry per index/sub-index")
            self._entries[entry.key] = entry
        self._records = frozenset(records)
        self._names: dict[str, OdEntry] = {}
        self._folded: dict[str, list[OdEntry]] = {}
        for entry in self._entries.values():
            self._names.setdefault(entry.name, entry)
            self._folded.setdefault(entry.name.casefold(), []).append(entry)

    def __len__(self) -> int:
        return len(self._entries)

    def __iter__(self) -> Iterator[OdEntry]:
        return iter(self._entries.values())

    def __contains__(self, key: object) -> bool:
        return self.find(key) is not None  # type: ignore[arg-type]

    def __getitem__(self, key: ObjectKey) -> OdEntry:
        return self.entry(key)

    def __repr__(self) -> str:
        return f"ObjectDictionary({self.source!r}, {len(self)} entries, node_id={self.node_id})"

    def is_record(self, index: int) -> bool:
        """True when ``index`` is a record or an array (entries by sub-index)."""
        return index in self._records

    def has_index(self, index: int) -> bool:
        return any(True for _ in self.subentries(index))

    def subentries(self, index: int) -> tuple[OdEntry, ...]:
        """Every entry of ``index``, by sub-index."""
        return tuple(e for (i, _), e in self._entries.items() if i == index)

    def example_names(self) -> str:
        names = [e.name for e in self._entries.values() if e.index >= 0x1000 and "." not in e.name]
        names = names[:2]
        return ", ".join(repr(n) for n in names) or "'Controlword'"

    def find(self, key: ObjectKey) -> OdEntry | None:
        """The entry ``key`` names, or None (an ambiguous key is an error, see :meth:`entry`)."""
        try:
            return self.entry(key)
        except ObjectNotFoundError:
            return None

    def entry(self, key: ObjectKey) -> OdEntry:
        """The entry ``key`` names; :class:`ObjectNotFoundError` naming the key and the
        closest names otherwise."""
        if isinstance(key, OdEntry | co.ObjectEntry):
            found = self._entries.get((key.index, key.subindex))
            if found is None:
                raise ObjectNotFoundError(f"{key.index:#06x}:{key.subindex}", self)
            return found
        if isinstance(key, tuple):
            if len(key) != 2 or not all(isinstance(k, int) for k in key):
                raise ObjectNotFoundError(key, self, "an (index, subindex) pair of ints")
            return self._by_index(f"{key[0]:#06x}:{key[1]}", key[0], key[1])
        if isinstance(key, int) and not isinstance(key, bool):
            return self._by_index(f"{key:#06x}", key, None)
        if not isinstance(key, str):
            raise ObjectNotFoundError(key, self)
        found = self._names.get(key.strip())
        if found is not None:
            return found
        parsed = parse_key(key)
        if parsed is not None:
            return self._by_index(key, *parsed)
        folded = self._folded.get(key.strip().casefold(), [])
        if len(folded) == 1:
            return folded[0]
        if len(folded) > 1:
            raise ObjectNotFoundError(
                key, self, "several objects match ignoring case: " + _labels(folded)
            )
        close = difflib.get_close_matches(key, list(self._names), n=3, cutoff=0.6)
        raise ObjectNotFoundError(
            key, self, ("closest: " + ", ".join(repr(c) for c in close)) if close else ""
        )

    def _by_index(self, key: object, index: int, subindex: int | None) -> OdEntry:
        if subindex is None:
            if self.is_record(index):
                subs = self.subentries(index)
                raise ObjectNotFoundError(
                    key, self, f"{index:#06x} is a record/array: name a sub-index ({_labels(subs)})"
                )
            subindex = 0
        found = self._entries.get((index, subindex))
        if found is not None:
            return found
        subs = self.subentries(index)
        hint = f"{index:#06x} has sub-indices {_labels(subs)}" if subs else ""
        raise ObjectNotFoundError(key, self, hint)

    def parameter_values(self) -> tuple[OdEntry, ...]:
        """Entries with a DCF ParameterValue, by index."""
        return tuple(e for e in self._entries.values() if e.parameter_value is not None)

    def supported_modes(self) -> frozenset[int]:
        """Modes of operation 0x6502 (Supported drive modes) sets: bit n is mode n + 1 for
        the CiA 402 modes 1..10 (empty when the file has no 0x6502)."""
        entry = self._entries.get((0x6502, 0))
        value = None if entry is None else entry.value
        if not isinstance(value, int):
            return frozenset()
        return frozenset(bit + 1 for bit in range(10) if value >> bit & 1)


def _labels(entries: Iterable[OdEntry]) -> str:
    items = [f"{e.index:#06x}:{e.subindex} {e.name!r}" for e in entries]
    return ", ".join(items[:6]) + (", ..." if len(items) > 6 else "")


def _entry(var: cod.ODVariable, name: str, source: str) -> OdEntry:
    access_text = (var.access_type or "rw").lower()
    try:
        access = Access(access_text)
    except ValueError:
        raise BadParameterError(
            "source",
            source,
            f"a CiA 306 file: {name} ({var.index:#06x}:{var.subindex}) has AccessType "
            f"{access_text!r}, allowed {', '.join(a.value for a in Access)}",
        ) from None
    data_type = var.data_type if var.data_type is not None else cod.DOMAIN
    return OdEntry(
        index=var.index,
        subindex=var.subindex,
        name=name,
        data_type=data_type,
        access=access,
        pdo_mappable=bool(var.pdo_mappable),
        default=var.default,
        parameter_value=var.value,
        low=var.min,
        high=var.max,
    )


def load_od(source: str | os.PathLike[str], *, node_id: int | None = None) -> ObjectDictionary:
    """Parse an EDS or DCF file (by its suffix) with canopen-py.

    ``node_id`` resolves ``$NODEID`` (a DCF's ``[DeviceComissioning] NodeID`` when not
    given; relative defaults are None when neither is known). A missing or malformed file
    raises ``BadParameterError`` naming it.
    """
    path = Path(source)
    text = str(path)
    if path.suffix.lower() not in (".eds", ".dcf"):
        raise BadParameterError("source", text, "an EDS (.eds) or DCF (.dcf) file")
    if not path.is_file():
        raise BadParameterError("source", text, "an existing EDS or DCF file")
    if node_id is not None and (
        isinstance(node_id, bool) or not isinstance(node_id, int) or not 1 <= node_id <= 127
    ):
        raise BadParameterError("node_id", node_id, "a CANopen node id in 1..127")
    try:
        raw = cod.import_od(text, node_id)
    except (configparser.Error, cod.ObjectDictionaryError, KeyError, ValueError) as exc:
        raise BadParameterError("source", text, f"a CiA 306 EDS/DCF file ({exc!r})") from exc
    entries: list[OdEntry] = []
    records: list[int] = []
    for obj in raw.values():
        if isinstance(obj, cod.ODVariable):
            entries.append(_entry(obj, obj.name, text))
            continue
        records.append(obj.index)
        for sub in obj.subindices.values():
            entries.append(_entry(sub, f"{obj.name}.{sub.name}", text))
    info = raw.device_information
    device = {k: v for k, v in vars(info).items() if not k.startswith("_")}
    own_id = raw.node_id if isinstance(raw.node_id, int) else node_id
    od = ObjectDictionary(entries, source=path.name, node_id=own_id, device=device, records=records)
    log.debug("od_loaded", source=text, entries=len(od), node_id=own_id)
    return od


# Objects a parameter download never writes: PDO parameters (written with the CiA 301
# disable/map/enable sequence by openel_can.pdomap.configure_pdos), store/restore
# parameters (a write is a command) and the program-download area.
_NOT_PARAMETERS: Final = (
    range(0x1400, 0x1C00),
    range(0x1010, 0x1012),
    range(0x1F50, 0x1F60),
)


async def write_parameter_values(
    sdo: SdoClient,
    od: ObjectDictionary,
    *,
    timeout: float | None = None,  # noqa: ASYNC109
) -> tuple[OdEntry, ...]:
    """Write a DCF's ParameterValues to the node by SDO, in index order; return the
    entries written.

    Skipped: entries that are not writable (ro/const: identity, device type), PDO
    communication and mapping parameters 0x1400-0x1BFF (give them to
    :func:`openel_can.pdomap.configure_pdos` through :func:`openel_can.pdomap.maps_from_od`),
    store/restore 0x1010/0x1011 and 0x1F50-0x1F5F. A refusal raises the SDO client's
    error (:class:`~openel_can.sdo.SdoAbortError` names the object).
    """
    written: list[OdEntry] = []
    for entry in od.parameter_values():
        if not entry.writable or any(entry.index in r for r in _NOT_PARAMETERS):
            continue
        await sdo.write(entry, entry.parameter_value, timeout=timeout)
        written.append(entry)
    log.debug("parameter_values_written", node=sdo.node_id, count=len(written))
    return tuple(written)
