"""A CANopen (CiA 402) drive's parameters for ``openel-async param``: the objects of its
EDS/DCF (:mod:`openel_can.od`), by name (``Profile velocity``, ``Identity
object.Vendor-ID``) or index (``6081``, ``0x6081:00``, ``0x1018sub1``), read and written by
expedited or segmented SDO (:class:`~openel_can.sdo.SdoClient`) with the file's data type,
access rights and limits.

A drive whose rig entry names no ``eds:``/``dcf:`` is described by the shipped EDS
(:data:`~openel_can.od.SHIPPED_EDS`: the CiA 301 and CiA 402 objects the driver uses; a real
drive may lack some of them: its SDO server then aborts, "object does not exist").

Units, where CiA 402 fixes them: positions in increments (``inc``), velocities in inc/s,
accelerations in inc/s², torques in per mille of the rated torque (0x6076, mNm), times in
ms or µs. Storage: a writable object is ``ram`` (CiA 301 keeps it at power-off only once
0x1010 "Store parameters" is written; writing 0x1010/0x1011 is an ``eeprom`` write and
asks first), a read-only one ``volatile``, a ``const`` one ``eeprom``. The controlword and
the targets (0x6040, 0x607A, 0x60FF, 0x6071, 0x60B0-0x60B2) are commands: the param command
reads them and writes none (it never enables or moves a drive).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Final

from canopen import objectdictionary as cod

from openel_async.params import ParameterInfo, ParamValue, Storage, not_found

from .bus import CanBus
from .layout402 import drive_file
from .od import (
    SHIPPED_EDS,
    Access,
    ObjectDictionary,
    ObjectNotFoundError,
    OdEntry,
    load_od,
    parse_key,
)
from .sdo import SdoClient

__all__ = ["COMMAND_OBJECTS", "CanOpenParameters", "parameter_info"]

PARAM_SDO_TIMEOUT: Final = 0.5
"""Seconds one SDO exchange may take (the command bounds each read more)."""

COMMAND_OBJECTS: Final = frozenset({0x6040, 0x607A, 0x60FF, 0x6071, 0x60B0, 0x60B1, 0x60B2})
"""Objects that command the drive (enable, move): read, never written by ``param``."""

_STORE: Final = frozenset({0x1010, 0x1011})
"""Store / restore parameters: writing them changes what the drive keeps at power-off."""

_INC: Final = "inc"
_UNITS: Final[Mapping[int, str]] = {
    0x1006: "µs",
    0x1007: "µs",
    0x1017: "ms",
    0x6062: _INC,
    0x6063: _INC,
    0x6064: _INC,
    0x6065: _INC,
    0x6067: _INC,
    0x607A: _INC,
    0x607C: _INC,
    0x607D: _INC,
    0x60F4: _INC,
    0x6069: "inc/s",
    0x606B: "inc/s",
    0x606C: "inc/s",
    0x607F: "inc/s",
    0x6081: "inc/s",
    0x60FF: "inc/s",
    0x60B1: "inc/s",
    0x6083: "inc/s²",
    0x6084: "inc/s²",
    0x6085: "inc/s²",
    0x60C5: "inc/s²",
    0x60C6: "inc/s²",
    0x6071: "‰ rated torque",
    0x6072: "‰ rated torque",
    0x6074: "‰ rated torque",
    0x6077: "‰ rated torque",
    0x60B2: "‰ rated torque",
    0x6087: "‰ rated torque/s",
    0x6076: "mNm",
    0x6075: "mA",
    0x6078: "‰ rated current",
}
"""The units CiA 301/402 fix for an object (by index)."""
_SHIPPED_UNITS: Final[Mapping[int, tuple[str, float]]] = {
    0x2022: ("°C", 0.1),
    0x2030: ("µs", 1.0),
    0x2031: ("mJ", 1.0),
}
"""The manufacturer objects of the shipped EDS (README of openel_can/eds)."""

_ACCESS: Final[Mapping[Access, str]] = {
    Access.RO: "ro",
    Access.CONST: "const",
    Access.WO: "wo",
    Access.RW: "rw",
    Access.RWR: "rw",
    Access.RWW: "rw",
}


def _kind(entry: OdEntry) -> Any:
    code = entry.data_type
    if code == cod.BOOLEAN:
        return "bool"
    if code in (cod.REAL32, cod.REAL64):
        return "float"
    if code in (cod.VISIBLE_STRING, cod.UNICODE_STRING):
        return "str"
    if code in (cod.OCTET_STRING, cod.DOMAIN):
        return "bytes"
    return "int"


def _range(entry: OdEntry) -> tuple[float | None, float | None]:
    low: float | None = entry.low
    high: float | None = entry.high
    size = entry.bit_length
    if entry.is_integer and entry.data_type != cod.BOOLEAN and size is not None:
        type_low, type_high = (
            (-(2 ** (size - 1)), 2 ** (size - 1) - 1) if entry.signed else (0, 2**size - 1)
        )
        low = type_low if low is None else max(low, type_low)
        high = type_high if high is None else min(high, type_high)
    return low, high


def _storage(entry: OdEntry) -> Storage:
    if entry.index in _STORE:
        return "eeprom"
    if entry.access is Access.CONST:
        return "eeprom"
    return "ram" if entry.writable else "volatile"


def parameter_info(entry: OdEntry, *, shipped: bool = False, record: bool = False) -> ParameterInfo:
    """The :class:`~openel_async.params.ParameterInfo` of an object (``shipped``: the
    dictionary is the shipped EDS, whose manufacturer objects have known units; ``record``:
    the object is a record or array, whose sub-index 0 counts its entries)."""
    count = record and entry.subindex == 0
    unit, scale = ("" if count else _UNITS.get(entry.index, "")), 1.0
    if shipped and entry.index in _SHIPPED_UNITS:
        unit, scale = _SHIPPED_UNITS[entry.index]
    low, high = _range(entry)
    description = ""
    if entry.index in COMMAND_OBJECTS:
        description = "a command (enables or moves the drive): read-only here"
    elif entry.index in _STORE:
        description = "write the signature 'save' (0x65766173) / 'load' (0x64616F6C)"
    return ParameterInfo(
        name=entry.name,
        address=f"{entry.index:#06x}:{entry.subindex:02x}",
        type=entry.type_name,
        access=_ACCESS[entry.access],  # type: ignore[arg-type]
        unit=unit,
        storage=_storage(entry),
        description=description,
        kind=_kind(entry),
        low=low,
        high=high,
        scale=scale,
        command=entry.index in COMMAND_OBJECTS,
    )


class CanOpenParameters:
    """The objects of one node's dictionary, by SDO (see the module docstring)."""

    def __init__(self, bus: CanBus, node_id: int, od: ObjectDictionary, source: str) -> None:
        self.od = od
        self.sdo = SdoClient(bus, node_id, timeout=PARAM_SDO_TIMEOUT, od=od)
        self.node_id = node_id
        self._source = source
        shipped = Path(od.source).name == SHIPPED_EDS.name
        self._entries: dict[str, OdEntry] = {}
        self._infos: list[ParameterInfo] = []
        for entry in od:
            if entry.index < 0x1000:  # the data type definitions (DummyUsage), no values
                continue
            info = parameter_info(entry, shipped=shipped, record=od.is_record(entry.index))
            self._entries[info.address] = entry
            self._infos.append(info)
        self._by_address = {i.address: i for i in self._infos}

    @classmethod
    def for_device(
        cls, bus: CanBus, params: Mapping[str, Any], rig_dir: Path | None
    ) -> CanOpenParameters:
        """The parameters of a rig's ``cia402_*`` entry: its DCF, else its EDS, else the
        shipped EDS."""
        node_id = int(params["node_id"])
        for key in ("dcf", "eds"):
            value = params.get(key)
            if value is not None:
                path = drive_file(key, value, rig_dir)
                od = load_od(path, node_id=node_id)
                return cls(
                    bus, node_id, od, f"CiA 402 node {node_id}, {key.upper()} {Path(path).name}"
                )
        od = load_od(SHIPPED_EDS, node_id=node_id)
        source = (
            f"CiA 402 node {node_id}, EDS {SHIPPED_EDS.name} (the rig names no eds: for it: the "
            "CiA 301/402 objects the driver uses)"
        )
        return cls(bus, node_id, od, source)

    @property
    def source(self) -> str:
        return self._source

    def parameters(self) -> Sequence[ParameterInfo]:
        return tuple(self._infos)

    def parameter(self, key: str) -> ParameterInfo:
        try:
            entry = self.od.entry(key)
        except ObjectNotFoundError as exc:
            if parse_key(key) is not None:  # an index: the dictionary's own hint
                raise
            raise not_found(key, [i.name for i in self._infos], self.od.source) from exc
        info = self._by_address.get(f"{entry.index:#06x}:{entry.subindex:02x}")
        if info is None:
            raise not_found(key, [i.name for i in self._infos], self.od.source)
        return info

    async def read(self, info: ParameterInfo) -> ParamValue:
        return await self.sdo.read(self._entries[info.address])

    async def write_blocker(self, info: ParameterInfo) -> str | None:
        return None

    async def write(self, info: ParameterInfo, value: ParamValue, *, unblock: bool = False) -> None:
        await self.sdo.write(self._entries[info.address], value)
