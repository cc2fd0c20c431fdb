"""The object dictionary of the simulated CiA 402 drive, built from an EDS file.

:func:`build_dictionary` turns an :class:`~openel_can.od.ObjectDictionary` (by default
the shipped :data:`~openel_can.od.SHIPPED_EDS`) into the simulated drive's live objects
(:class:`SimObject`): data types, access rights, PDO mappability and defaults are the
file's. The drive's model parameters override a few defaults (they describe the
simulated motor, not the file): the serial number 0x1018:4 (0x1234_0000 + node id), the
producer heartbeat time 0x1017, the encoder resolution 0x608F, the rated torque 0x6076,
the speed and ramp limits 0x6080-0x6085 (in increments of ``counts_per_rev``) and the
supported drive modes 0x6502 (the modes the simulation implements).

Objects of an integer type (and BOOLEAN, as UNSIGNED8) hold an int ``value``; the
others (strings, domains, REAL32/64, 24/40/48/56-bit integers) hold their bytes in
``data`` and are served by SDO as they are. Index 0x0000-0x0FFF (data type definitions,
dummy entries) is not part of the live dictionary.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Final

from .. import canopen as co
from ..od import SHIPPED_EDS, ObjectDictionary, OdEntry, load_od

__all__ = ["MAX_DATA_SIZE", "REQUIRED_OBJECTS", "SimObject", "build_dictionary", "load_sim_od"]

#: Largest value (bytes) of a variable-length object (string, domain) the drive stores.
MAX_DATA_SIZE: Final = 65536

#: Objects the simulated drive's behaviour reads or writes: an EDS without one is refused.
REQUIRED_OBJECTS: Final[tuple[tuple[int, int], ...]] = (
    (0x1001, 0),
    (0x1016, 1),
    (0x1017, 0),
    (0x2022, 0),
    (0x2030, 0),
    (0x603F, 0),
    (0x6007, 0),
    (0x6040, 0),
    (0x6041, 0),
    (0x605A, 0),
    (0x6060, 0),
    (0x6061, 0),
    (0x6064, 0),
    (0x606C, 0),
    (0x6071, 0),
    (0x6072, 0),
    (0x6076, 0),
    (0x6077, 0),
    (0x607A, 0),
    (0x607D, 1),
    (0x607D, 2),
    (0x6080, 0),
    (0x6081, 0),
    (0x6083, 0),
    (0x6084, 0),
    (0x6085, 0),
    (0x6087, 0),
    (0x608F, 1),
    (0x60FF, 0),
    *((0x1400 + n, s) for n in range(3) for s in (1, 2)),
    *((0x1600 + n, s) for n in range(3) for s in range(9)),
    *((0x1800 + n, s) for n in range(4) for s in (1, 2, 3, 5)),
    *((0x1A00 + n, s) for n in range(4) for s in range(9)),
)


@dataclass
class SimObject:
    """One live object of the simulated drive."""

    data_type: co.DataType | None
    """The integer type of ``value``; None: the object holds bytes (``data``)."""
    default: int
    access: str = "rw"  # "ro", "rw", "wo", "const", "rwr", "rww"
    mappable: bool = False
    size: int | None = None
    """Bytes of a value (None: variable length)."""
    data: bytes = b""
    """The value of an object that is not of an integer type."""
    entry: OdEntry | None = None
    """The file's entry."""
    value: int = field(init=False)

    def __post_init__(self) -> None:
        self.value = self.default
        if self.data_type is not None:
            self.size = self.data_type.size

    @property
    def readable(self) -> bool:
        return self.access != "wo"

    @property
    def writable(self) -> bool:
        return self.access in ("wo", "rw", "rwr", "rww")

    @property
    def rpdo_mappable(self) -> bool:
        return self.mappable and self.access in ("wo", "rw", "rww")

    @property
    def tpdo_mappable(self) -> bool:
        return self.mappable and self.access in ("ro", "const", "rw", "rwr")


def _sim_object(entry: OdEntry) -> SimObject:
    value = entry.value
    if entry.is_integer:
        data_type: co.DataType | None
        try:
            data_type = co.DataType(entry.data_type)
        except ValueError:  # BOOLEAN as UNSIGNED8; 24/40/48/56-bit integers as bytes
            data_type = co.DataType.UNSIGNED8 if entry.bit_length == 8 else None
        if data_type is not None:
            default = int(value) if isinstance(value, int | bool) else 0
            return SimObject(
                data_type, default, entry.access.value, entry.pdo_mappable, entry=entry
            )
    data = entry.encode(value) if value is not None else b""
    return SimObject(None, 0, entry.access.value, False, size=entry.size, data=data, entry=entry)


@functools.lru_cache(maxsize=32)
def _cached_od(path: str, node_id: int) -> ObjectDictionary:
    return load_od(path, node_id=node_id)


def load_sim_od(eds: str | os.PathLike[str] | None, node_id: int) -> ObjectDictionary:
    """The dictionary of ``eds`` (default :data:`SHIPPED_EDS`) with ``$NODEID`` = ``node_id``
    (parsed once per file and node id: dictionaries are immutable)."""
    return _cached_od(str(Path(SHIPPED_EDS if eds is None else eds).resolve()), node_id)


def build_dictionary(
    od: ObjectDictionary,
    *,
    node_id: int,
    counts_per_rev: int,
    rated_torque_mnm: int,
    heartbeat_ms: int,
    supported_modes: Iterable[int],
) -> dict[tuple[int, int], SimObject]:
    """Fresh live objects (every value at its default) from ``od``; ``ValueError`` naming
    the missing objects when ``od`` lacks one the simulation needs."""
    missing = [key for key in REQUIRED_OBJECTS if od.find(key) is None]
    if missing:
        names = ", ".join(f"{i:#06x}:{s}" for i, s in missing)
        raise ValueError(f"{od.source} lacks objects the simulated CiA 402 drive needs: {names}")
    objects = {entry.key: _sim_object(entry) for entry in od if entry.index >= 0x1000}
    cpr = counts_per_rev
    overrides = {
        (0x1018, 4): 0x1234_0000 + node_id,
        (0x1017, 0): heartbeat_ms,
        (0x608F, 1): cpr,
        (0x608F, 2): 1,
        (0x6076, 0): rated_torque_mnm,
        (0x6080, 0): 3 * cpr,
        (0x6081, 0): cpr,
        (0x6083, 0): 10 * cpr,
        (0x6084, 0): 10 * cpr,
        (0x6085, 0): 40 * cpr,
        (0x6502, 0): sum(1 << (mode - 1) for mode in supported_modes),
    }
    for key, value in overrides.items():
        obj = objects.get(key)
        if obj is not None and obj.data_type is not None:
            obj.default = obj.value = value
    return objects
