"""What the bus monitor (:mod:`openel_can.monitor`) knows of a rig's CANopen nodes: the PDO
maps of its CiA 402 drives, to print every PDO field by name, and their object
dictionaries, to name the objects of SDO transfers and decode their values; and the
segmented SDO transfers followed frame by frame (:class:`SdoTracker`).

The maps are the ones the driver writes to the drive (:func:`rig_knowledge`):

* a drive that names its files (``eds``, ``dcf``, ``pdos``): the maps of
  :func:`openel_can.layout402.load_drive_files` (the rig's ``pdos``, else the DCF's, else
  the defaults of its ``mode``) resolved against its dictionary
  (:func:`openel_can.pdomap.resolve_pdos`), at their COB-IDs (a ``cob_id`` of the rig too);
* a drive that names none: the driver's fixed maps (:func:`fixed_layouts`): RPDO1..3
  controlword + target position / velocity / torque, TPDO1 statusword + position actual +
  torque actual, TPDO2 velocity actual + mode display (``pp``) or statusword + mode display
  (``csp``, ``csv``, ``cst``), named by the shipped EDS (``openel_servo402.eds``).

Without a rig, ``--cia402 2,3:csp`` gives nodes and their mode (default ``pp``): the fixed
maps of that mode.
"""

from __future__ import annotations

import functools
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, Final

from . import canopen as co
from . import cia402 as ds
from .errors import DecodeError
from .od import SHIPPED_EDS, Access, ObjectDictionary, OdEntry, OdValue, load_od

__all__ = [
    "CIA402_MODES",
    "CanopenKnowledge",
    "PdoLayout",
    "SdoTracker",
    "fixed_layouts",
    "format_value",
    "rig_knowledge",
]

CIA402_MODES: Final = ("pp", "csp", "csv", "cst")
"""The ``mode`` of a rig's CiA 402 drive (and of ``--cia402 NODE:MODE``)."""

_RPDO_MAPS: Final = (
    (ds.CONTROLWORD, ds.TARGET_POSITION),
    (ds.CONTROLWORD, ds.TARGET_VELOCITY),
    (ds.CONTROLWORD, ds.TARGET_TORQUE),
)
_TPDO1: Final = (ds.STATUSWORD, ds.POSITION_ACTUAL_VALUE, ds.TORQUE_ACTUAL_VALUE)
_TPDO2_PROFILE: Final = (ds.VELOCITY_ACTUAL_VALUE, ds.MODES_OF_OPERATION_DISPLAY)
_TPDO2_CYCLIC: Final = (ds.STATUSWORD, ds.MODES_OF_OPERATION_DISPLAY)
"""The driver's fixed maps (``openel_can.node402`` RPDO_MAPS/TPDO_MAPS, ``openel_can.cyclic402``
STATUS_TPDO_MAP); tests/can/test_monitor_pdo.py checks they still are."""

_HEX_OBJECTS: Final = frozenset({0x603F, 0x6040, 0x6041})
"""Printed in hex: error code, controlword, statusword (bit fields, not quantities)."""
_MODE_OBJECTS: Final = frozenset({0x6060, 0x6061})


@functools.cache
def _shipped() -> ObjectDictionary:
    return load_od(SHIPPED_EDS)


def format_value(entry: OdEntry, value: OdValue) -> str:
    """``0x000f`` (controlword), ``0x0237 OPERATION_ENABLED`` (statusword), ``8 CYCLIC_SYNC_POSITION``
    (mode), ``12345``; strings quoted, bytes in hex."""
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, int):
        if entry.index in _HEX_OBJECTS and not entry.subindex:
            text = f"{value:#0{2 + 2 * (entry.size or 2)}x}"
            if entry.index == 0x6041:
                try:
                    text += f" {ds.state_from_statusword(value).name}"
                except DecodeError:
                    text += " (no CiA 402 state)"
            return text
        if entry.index in _MODE_OBJECTS and not entry.subindex:
            try:
                return f"{value} {ds.ModeOfOperation(value).name}"
            except ValueError:
                return str(value)
        return str(value)
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, str):
        return repr(value)
    return value.hex(" ")


@dataclass(frozen=True)
class PdoLayout:
    """One PDO of one node: its mapped objects in frame order."""

    node_id: int
    name: str
    """``RPDO1``, ``TPDO2``."""
    entries: tuple[OdEntry, ...]

    @property
    def size(self) -> int:
        return sum(e.size or 0 for e in self.entries)

    def decode(self, data: bytes) -> tuple[str, tuple[dict[str, Any], ...], bool]:
        """The text, the fields (``object``, ``name``, ``type``, ``value``) and whether the
        frame is malformed (its length is not the map's)."""
        head = f"node {self.node_id} {self.name}"
        if len(data) != self.size:
            mapped = ", ".join(e.name for e in self.entries)
            return (
                f"{head} malformed: {len(data)} bytes, the map ({mapped}) is {self.size}",
                (),
                True,
            )
        parts: list[str] = []
        fields: list[dict[str, Any]] = []
        at = 0
        for entry in self.entries:
            size = entry.size or 0
            value = entry.decode(data[at : at + size])
            at += size
            parts.append(f"{entry.name}={format_value(entry, value)}")
            fields.append(
                {
                    "object": f"{entry.index:04X}:{entry.subindex:02X}",
                    "name": entry.name,
                    "type": entry.type_name,
                    "value": value,
                }
            )
        return " ".join([head, *parts]), tuple(fields), False


def _named(entry: co.ObjectEntry) -> OdEntry:
    found = _shipped().find((entry.index, entry.subindex))
    if found is not None:
        return found
    name = f"{entry.index:#06x}:{entry.subindex}"
    return OdEntry(entry.index, entry.subindex, name, entry.data_type, Access.RW, True)


def fixed_layouts(node_id: int, mode: str = "pp") -> dict[int, PdoLayout]:
    """The driver's fixed maps of a drive that names no files, by COB-ID."""
    if mode not in CIA402_MODES:
        raise ValueError(f"mode {mode!r}: one of {', '.join(CIA402_MODES)}")
    tpdo2 = _TPDO2_PROFILE if mode == "pp" else _TPDO2_CYCLIC
    out: dict[int, PdoLayout] = {}
    for number, rmap in enumerate(_RPDO_MAPS, start=1):
        out[co.rpdo_cob_id(number, node_id)] = PdoLayout(
            node_id, f"RPDO{number}", tuple(_named(o) for o in rmap)
        )
    tpdos: tuple[tuple[co.ObjectEntry, ...], ...] = (_TPDO1, tpdo2)
    for number, objects in enumerate(tpdos, start=1):
        out[co.tpdo_cob_id(number, node_id)] = PdoLayout(
            node_id, f"TPDO{number}", tuple(_named(o) for o in objects)
        )
    return out


@dataclass
class CanopenKnowledge:
    """The PDO maps by COB-ID and the object dictionaries by node id."""

    pdos: dict[int, PdoLayout] = field(default_factory=dict)
    ods: dict[int, ObjectDictionary] = field(default_factory=dict)

    def add_fixed(self, node_id: int, mode: str = "pp") -> None:
        """A CiA 402 drive with the driver's fixed maps of ``mode``."""
        self.pdos.update(fixed_layouts(node_id, mode))
        self.ods.setdefault(node_id, _shipped())


def rig_knowledge(devices: Iterable[Any]) -> CanopenKnowledge:
    """What the rig's ``cia402_drive`` devices (:class:`openel_async.rig.SimulatedDevice`)
    say of their PDOs and dictionaries (the rig is checked: its files load)."""
    from .layout402 import load_drive_files
    from .pdomap import resolve_pdos

    known = CanopenKnowledge()
    for d in devices:
        if d.device != "cia402_drive":
            continue
        node = int(d.params["node_id"])
        mode = str(d.params.get("mode", "pp"))
        event_ms = d.params.get("tpdo_event_ms", 10)
        files = load_drive_files(
            node,
            mode,
            eds=d.params.get("eds"),
            dcf=d.params.get("dcf"),
            pdos=d.params.get("pdos"),
            files_dir=d.rig_dir,
            sync=d.params.get("sync", False) is True,
            tpdo_event_ms=event_ms if isinstance(event_ms, int) else 10,
        )
        if files is None:
            known.add_fixed(node, mode)
            continue
        known.ods[node] = files.od
        for pdo in resolve_pdos(files.specs, files.od, node_id=node):
            if pdo.spec.enabled:
                known.pdos[pdo.cob_id] = PdoLayout(node, pdo.name, pdo.entries)
    return known


@dataclass
class _Transfer:
    index: int
    subindex: int
    upload: bool
    size: int | None
    data: bytearray = field(default_factory=bytearray)


@dataclass
class SdoTracker:
    """Follows each node's segmented SDO transfer: the object at its start, the value and
    size at its last segment."""

    ods: Mapping[int, ObjectDictionary] = field(default_factory=dict)
    transfers: dict[int, _Transfer] = field(default_factory=dict)

    def name(self, node: int, index: int, subindex: int) -> str:
        """`` Identity object.Vendor-ID`` when the node's dictionary has it, else ``""``."""
        od = self.ods.get(node)
        entry = None if od is None else od.find((index, subindex))
        return "" if entry is None else f" {entry.name}"

    def value(self, node: int, index: int, subindex: int, data: bytes) -> str:
        """``= 305397762 (02 00 34 12)``, by the object's type when known."""
        od = self.ods.get(node)
        entry = None if od is None else od.find((index, subindex))
        raw = f"({data.hex(' ')})" if data else "(no data)"
        if entry is not None:
            try:
                return f"= {format_value(entry, entry.decode(data))} {raw}"
            except Exception:  # a reply that does not fit the type: the bytes alone
                return f"= {raw}"
        if len(data) <= 8:
            return f"= {int.from_bytes(data, 'little')} {raw}"
        return f"= {raw}"

    def note(self, msg: object) -> tuple[str, bool]:
        """What a frame adds to a transfer (appended to its line), and whether it is out of
        place (a segment with no transfer, a size that does not match)."""
        if isinstance(msg, co.SdoAbort):
            self.transfers.pop(msg.node_id, None)
            return "", False
        if isinstance(msg, co.SdoSegmentedUploadResponse | co.SdoSegmentedDownloadRequest):
            upload = isinstance(msg, co.SdoSegmentedUploadResponse)
            self.transfers[msg.node_id] = _Transfer(msg.index, msg.subindex, upload, msg.size)
            return ("" if msg.size is None else f" size={msg.size}"), False
        if isinstance(msg, co.SdoUploadSegment | co.SdoDownloadSegment):
            upload = isinstance(msg, co.SdoUploadSegment)
            transfer = self.transfers.get(msg.node_id)
            text = f" {len(msg.data)} bytes" + (", last" if msg.last else "")
            if transfer is None or transfer.upload != upload:
                return text + " (no transfer seen starting)", False
            transfer.data += msg.data
            if not msg.last:
                return text, False
            del self.transfers[msg.node_id]
            data = bytes(transfer.data)
            where = f"{transfer.index:04X}:{transfer.subindex:02X}"
            name = self.name(msg.node_id, transfer.index, transfer.subindex)
            shown = self.value(msg.node_id, transfer.index, transfer.subindex, data)
            done = (
                f": {'upload' if upload else 'download'} {where}{name} {shown}, {len(data)} bytes"
            )
            if transfer.size is not None and transfer.size != len(data):
                return f"{done} (announced {transfer.size}: malformed)", True
            return done, False
        return "", False
