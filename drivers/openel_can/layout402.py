"""A CiA 402 drive configured from its files: the object dictionary (EDS or DCF), the DCF's
parameter values and the PDO maps the driver runs with (:class:`DriveFiles`,
:class:`DriveLayout`).

``Cia402Drive(bus, node, eds=..., dcf=..., pdos=...)`` (in a rig: ``params: {node_id: 1,
mode: csp, eds: servo.eds, pdos: [...]}``, paths relative to the rig file):

* ``eds``: the drive's EDS (a path relative to the rig file, or the bare name of a file
  shipped in ``openel_can/eds``: ``openel_servo402.eds``); SDO transfers and PDO maps use its objects, data types and
  access rights; ``dcf``: a DCF (an EDS with ``ParameterValue`` entries): its writable
  parameter values are written at every configuration, in PRE-OPERATIONAL, before the
  driver's own objects (:func:`openel_can.od.write_parameter_values`). With both, the
  DCF's parameters must be objects of the EDS (the dictionary is the EDS's); with the DCF
  alone, the dictionary is the DCF's.
* ``pdos``: the PDO maps (:class:`openel_can.pdomap.PdoSpec` items, the rig's form), else
  the PDOs the DCF configures, else :func:`drive_pdos` for the drive's ``mode``; written
  with :func:`openel_can.pdomap.configure_pdos` (disable, map, enable; read back and
  verified; the file's other PDOs disabled) before NMT start.

What the driver needs of the maps (:func:`plan_layout`, a
:class:`~openel_can.pdomap.PdoMapError` naming ``pdos`` and the PDO otherwise):

* an RPDO carrying the controlword 0x6040 and the target of each mode it runs (0x607A
  position, 0x60FF velocity, 0x6071 torque; in ``pp`` the profile position one at least:
  the velocity and torque requests are offered when their RPDO is mapped); RPDOs carry
  only objects the driver writes (those, and modes of operation 0x6060);
* a TPDO carrying the statusword 0x6041. When none sends it on event (only on SYNC), the
  driver reads the statusword by SDO while it waits for a power state transition.

TPDO objects the driver knows (statusword, position actual 0x6064, velocity actual
0x606C, torque actual 0x6077, mode display 0x6061) feed its state and ``get_value``; any
other mapped object is kept by name in ``Cia402Node.pdo_values``. A synchronous TPDO
(trigger ``sync``) is the cycle's feedback of a cyclic drive.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Final

from openel_async.errors import BadParameterError

from . import canopen as co
from . import cia402 as ds
from .od import SHIPPED_EDS, ObjectDictionary, load_od
from .pdomap import PdoMapError, PdoSpec, ResolvedPdo, default_pdos, maps_from_od, resolve_pdos

__all__ = [
    "FEEDBACK_OBJECTS",
    "TARGET_OF_MODE",
    "WRITTEN_OBJECTS",
    "DriveFiles",
    "DriveLayout",
    "LayoutRpdo",
    "LayoutTpdo",
    "drive_file",
    "drive_pdos",
    "load_drive_files",
    "plan_layout",
]

Mode = ds.ModeOfOperation
SHIPPED_DIR: Final = SHIPPED_EDS.parent
"""Files shipped with the driver: an ``eds``/``dcf`` not found relative to the rig file is
looked up here by its bare name (``openel_servo402.eds``)."""

CONTROLWORD: Final = 0x6040
STATUSWORD: Final = 0x6041
MODES_OF_OPERATION: Final = 0x6060
TARGET_OF_MODE: Final[dict[Mode, int]] = {
    Mode.PROFILE_POSITION: 0x607A,
    Mode.PROFILE_VELOCITY: 0x60FF,
    Mode.PROFILE_TORQUE: 0x6071,
    Mode.CYCLIC_SYNC_POSITION: 0x607A,
    Mode.CYCLIC_SYNC_VELOCITY: 0x60FF,
    Mode.CYCLIC_SYNC_TORQUE: 0x6071,
}
"""The target object of each mode the driver runs."""
WRITTEN_OBJECTS: Final = frozenset({CONTROLWORD, MODES_OF_OPERATION, 0x607A, 0x60FF, 0x6071})
"""The objects an RPDO may carry: those the driver writes."""
FEEDBACK_OBJECTS: Final = {
    STATUSWORD: "statusword",
    0x6064: "position",
    0x606C: "velocity",
    0x6077: "torque",
    0x6061: "mode display",
}
"""The TPDO objects the driver follows (any other is kept by name)."""
_DRIVE_MODES: Final = {
    "pp": (Mode.PROFILE_POSITION, Mode.PROFILE_VELOCITY, Mode.PROFILE_TORQUE),
    "csp": (Mode.CYCLIC_SYNC_POSITION,),
    "csv": (Mode.CYCLIC_SYNC_VELOCITY,),
    "cst": (Mode.CYCLIC_SYNC_TORQUE,),
}


@dataclass(frozen=True)
class DriveFiles:
    """What a drive's rig entry names: its dictionary, its DCF and its PDO maps."""

    od: ObjectDictionary
    """The dictionary names are looked up in (the EDS's, else the DCF's)."""
    dcf: ObjectDictionary | None
    """The DCF whose parameter values are written at configuration."""
    specs: tuple[PdoSpec, ...]
    origin: str
    """Where the maps come from: ``pdos``, ``the DCF`` or ``defaults for <mode>``."""


@dataclass(frozen=True)
class LayoutRpdo:
    """An RPDO the driver packs: a slot per mapped object."""

    pdo: ResolvedPdo
    codec: co.PdoCodec
    slots: tuple[int, ...]
    """The object index of each mapped entry, in frame order."""

    @property
    def synchronous(self) -> bool:
        return self.pdo.transmission_type <= 240


@dataclass(frozen=True)
class LayoutTpdo:
    """A TPDO the driver unpacks."""

    pdo: ResolvedPdo
    codec: co.PdoCodec
    slots: tuple[int, ...]
    names: tuple[str, ...]
    synchronous: bool
    status_at: int | None
    """The statusword's position among the slots (None: not carried)."""


@dataclass(frozen=True)
class DriveLayout:
    """The resolved maps and what the driver does with each PDO."""

    pdos: tuple[ResolvedPdo, ...]
    rpdo_of_mode: Mapping[Mode, LayoutRpdo]
    tpdos: Mapping[int, LayoutTpdo]
    """By COB-ID."""
    status_on_event: bool
    """An event-driven TPDO carries the statusword (else it is read by SDO while waiting)."""

    def carries(self, index: int) -> bool:
        """A TPDO carries object ``index``."""
        return any(index in t.slots for t in self.tpdos.values())


def drive_pdos(mode: str, *, sync: bool = False, event_ms: int = 10) -> tuple[PdoSpec, ...]:
    """The maps a drive runs with when its rig gives none: :func:`default_pdos` of the
    mode; in ``pp`` (the profile modes chosen by each command) also RPDO2 controlword +
    target velocity and RPDO3 controlword + target torque, and with ``sync`` the TPDOs on
    every SYNC."""
    if mode != "pp":
        return default_pdos(mode)
    rpdo1, tpdo1, tpdo2 = default_pdos("pp", event_ms=event_ms)
    extra = (
        PdoSpec(pdo="rpdo2", objects=("0x6040", "0x60FF")),
        PdoSpec(pdo="rpdo3", objects=("0x6040", "0x6071")),
    )
    if sync:
        tpdo1, tpdo2 = (
            PdoSpec(pdo=t.pdo, objects=t.objects, trigger="sync") for t in (tpdo1, tpdo2)
        )
    return (rpdo1, *extra, tpdo1, tpdo2)


@functools.lru_cache(maxsize=32)
def _cached_od(path: str, mtime_ns: int, node_id: int | None) -> ObjectDictionary:
    return load_od(path, node_id=node_id)


def drive_file(key: str, value: object, files_dir: Path | None) -> str:
    """The path of a drive's ``eds``/``dcf`` parameter: relative to ``files_dir`` (the rig
    file's directory), else a file shipped in ``openel_can/eds`` by its bare name;
    ``BadParameterError`` naming ``key`` when there is none."""
    if not isinstance(value, str | os.PathLike) or not str(value):
        raise BadParameterError(key, value, "the path of a file")
    text = str(value)
    path = Path(text)
    if not path.is_absolute() and files_dir is not None:
        path = files_dir / path
    suffix = ".eds" if key == "eds" else ".dcf"
    kind = suffix[1:].upper()
    if path.suffix.lower() != suffix:
        raise BadParameterError(key, text, f"a {kind} file ({suffix})")
    if not path.is_file() and Path(text).name == text and (SHIPPED_DIR / text).is_file():
        path = SHIPPED_DIR / text
    if not path.is_file():
        where = f" (relative to {files_dir})" if files_dir is not None else ""
        shipped = ", ".join(sorted(p.name for p in SHIPPED_DIR.iterdir() if p.suffix == suffix))
        raise BadParameterError(
            key, text, f"an existing {kind} file{where}, or one shipped: {shipped or 'none'}"
        )
    return str(path.resolve())


def _load(key: str, value: object, files_dir: Path | None, node_id: int) -> ObjectDictionary:
    path = drive_file(key, value, files_dir)
    try:
        return _cached_od(path, Path(path).stat().st_mtime_ns, node_id)
    except BadParameterError as exc:
        raise BadParameterError(key, str(value), exc.allowed) from None


def load_drive_files(
    node_id: int,
    mode: str,
    *,
    eds: str | os.PathLike[str] | None = None,
    dcf: str | os.PathLike[str] | None = None,
    pdos: object = None,
    files_dir: Path | None = None,
    sync: bool = False,
    tpdo_event_ms: int = 10,
) -> DriveFiles | None:
    """The drive's files (None when it names none: the driver's fixed maps); every
    refusal is a ``BadParameterError`` naming the parameter (``eds``, ``dcf``,
    ``pdos[1].objects[0]``)."""
    if eds is None and dcf is None:
        if pdos is not None:
            raise BadParameterError(
                "pdos", pdos, "maps with the drive's dictionary: give 'eds' or 'dcf' too"
            )
        return None
    eds_od = None if eds is None else _load("eds", eds, files_dir, node_id)
    dcf_od = None if dcf is None else _load("dcf", dcf, files_dir, node_id)
    od = eds_od if eds_od is not None else dcf_od
    assert od is not None
    if eds_od is not None and dcf_od is not None:
        for entry in dcf_od.parameter_values():
            found = eds_od.find((entry.index, entry.subindex))
            if found is None or found.data_type != entry.data_type:
                raise BadParameterError(
                    "dcf",
                    str(dcf),
                    f"parameters of the EDS's objects: {entry.label} "
                    + ("is not in it" if found is None else f"is {found.type_name} there"),
                )
    origin = "pdos"
    if pdos is not None:
        if isinstance(pdos, Sequence) and not isinstance(pdos, str):
            if all(isinstance(p, PdoSpec) for p in pdos):
                specs = tuple(p for p in pdos if isinstance(p, PdoSpec))
            else:
                from .pdomap import parse_pdos

                specs = parse_pdos(list(pdos))
        else:
            raise BadParameterError("pdos", pdos, "a list of PDO maps")
    elif dcf_od is not None and (from_dcf := maps_from_od(dcf_od)):
        specs, origin = from_dcf, "the DCF"
    else:
        specs, origin = drive_pdos(mode, sync=sync, event_ms=tpdo_event_ms), f"defaults for {mode}"
    return DriveFiles(od, dcf_od, specs, origin)


def _named(exc: BadParameterError, origin: str) -> BadParameterError:
    """``exc`` with its parameter under ``pdos`` (or said to come from the DCF/defaults)."""
    if origin == "pdos":
        return PdoMapError(exc.parameter, exc.value, exc.allowed)
    return PdoMapError(f"{exc.parameter} ({origin})", exc.value, exc.allowed)


def plan_layout(files: DriveFiles, node_id: int, mode: str) -> DriveLayout:
    """Resolve the maps against the dictionary and check what the driver needs of them
    (module docstring)."""
    try:
        resolved = resolve_pdos(files.specs, files.od, node_id=node_id)
    except BadParameterError as exc:
        raise _named(exc, files.origin) from None
    rpdo_of_mode: dict[Mode, LayoutRpdo] = {}
    tpdos: dict[int, LayoutTpdo] = {}
    status_on_event = False
    for i, pdo in enumerate(resolved):
        if not pdo.spec.enabled:
            continue
        slots = tuple(e.index for e in pdo.entries)
        codec = co.PdoCodec(pdo.map_entries)
        if not pdo.transmit:
            for j, entry in enumerate(pdo.entries):
                if entry.index not in WRITTEN_OBJECTS or entry.subindex:
                    raise _named(
                        BadParameterError(
                            f"pdos[{i}].objects[{j}]",
                            pdo.spec.objects[j],
                            "an object the driver writes in an RPDO: controlword 0x6040, "
                            "modes of operation 0x6060, target position 0x607A, target "
                            f"velocity 0x60FF, target torque 0x6071 ({entry.label} is not)",
                        ),
                        files.origin,
                    )
            layout = LayoutRpdo(pdo, codec, slots)
            if CONTROLWORD in slots:
                for m, target in TARGET_OF_MODE.items():
                    if target in slots:
                        rpdo_of_mode.setdefault(m, layout)
        else:
            synchronous = pdo.transmission_type <= 240
            status_on_event = status_on_event or (STATUSWORD in slots and not synchronous)
            tpdos[pdo.cob_id] = LayoutTpdo(
                pdo,
                codec,
                slots,
                tuple(e.name for e in pdo.entries),
                synchronous,
                slots.index(STATUSWORD) if STATUSWORD in slots else None,
            )
    needed = _DRIVE_MODES[mode][:1]
    for m in needed:
        if m not in rpdo_of_mode:
            found = files.od.find(TARGET_OF_MODE[m])
            label = found.label if found is not None else f"{TARGET_OF_MODE[m]:#06x}"
            raise _named(
                BadParameterError(
                    "pdos",
                    [p.pdo for p in files.specs],
                    f"an RPDO carrying the controlword 0x6040 and {label} (mode {mode})",
                ),
                files.origin,
            )
    if not any(STATUSWORD in t.slots for t in tpdos.values()):
        raise _named(
            BadParameterError(
                "pdos",
                [p.pdo for p in files.specs],
                "a TPDO carrying the statusword 0x6041 (the driver follows the drive's state "
                "by it)",
            ),
            files.origin,
        )
    return DriveLayout(resolved, rpdo_of_mode, tpdos, status_on_event)
