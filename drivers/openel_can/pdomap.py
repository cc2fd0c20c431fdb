"""PDO maps: which objects each RPDO and TPDO of a node carries, how it is transmitted, and
their configuration by SDO as CiA 301 prescribes, read back and verified.

A :class:`PdoMap` names its PDO (``rpdo`` or ``tpdo`` and its number, 1..512), the objects it
carries (by name, index text or ``(index, subindex)``, as :mod:`openel_can.od` finds them),
its COB-ID (default: the predefined connection set for PDOs 1..4) and its transmission:

* ``transmission`` 1..240: synchronous, sent (TPDO) or applied (RPDO) every n-th SYNC;
* 0: synchronous acyclic (a TPDO on the SYNC after a change);
* 254 / 255: event-driven (manufacturer / device profile specific), with a TPDO's
  ``inhibit_time`` (0x18xx:3, in 100 us) and ``event_timer`` (0x18xx:5, in ms).

:func:`resolve_maps` checks maps against a node's object dictionary before anything is
sent: an object that is not there, not PDO-mappable, not writable for an RPDO or readable
for a TPDO, not of a fixed size, or more than 64 bits in one PDO is refused with a
``BadParameterError`` naming the object (or the PDO) and what is allowed.
:func:`configure_pdos` writes them by SDO (the node in PRE-OPERATIONAL) in the order of
CiA 301 §7.5.2.36: the COB-ID with bit 31 set (PDO invalid), the transmission type, inhibit
time and event timer, the number of mapped objects 0, each mapping entry, the number of
entries, the COB-ID without bit 31; then reads every written entry back and refuses
(``PdoMappingError``) a node that holds another value. A node that refuses to map an object
(abort 0x06040041, not mappable; 0x06040042, the mapping too long) raises ``PdoMappingError``
naming the PDO, the object and the abort.

:func:`cia402_maps` gives the CiA 402 maps of each mode of operation: profile modes
(event-driven feedback) and the cyclic synchronous ones (every SYNC). :class:`PdoSpec` is the
strict form of a map in a rig file (``params: {pdos: [...]}``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import msgspec

from openel_async.errors import BadParameterError, HALError

from . import canopen as co
from .od import ObjectDictionary, ObjectKey, OdEntry
from .sdo import SdoAbortError, SdoClient

__all__ = [
    "MAX_PDO_BITS",
    "PdoMap",
    "PdoMappingError",
    "PdoSpec",
    "ResolvedPdo",
    "cia402_maps",
    "configure_pdos",
    "read_pdo",
    "resolve_maps",
]

MAX_PDO_BITS = 64
"""The data of a classical CAN frame."""

Direction = Literal["rpdo", "tpdo"]
_U8, _U16, _U32 = co.DataType.UNSIGNED8, co.DataType.UNSIGNED16, co.DataType.UNSIGNED32


class PdoMappingError(HALError):
    """The node holds another PDO configuration than the one written."""


@dataclass(frozen=True)
class PdoMap:
    """One PDO of a node: see the module docstring."""

    direction: Direction
    number: int
    objects: tuple[ObjectKey, ...]
    transmission: int = 1
    cob_id: int | None = None
    inhibit_time: int | None = None
    """TPDO only: the minimum time between two transmissions, in 100 us."""
    event_timer: int | None = None
    """TPDO only: ms between event-driven transmissions (0: none)."""

    @property
    def name(self) -> str:
        return f"{self.direction.upper()}{self.number}"


@dataclass(frozen=True)
class ResolvedPdo:
    """A map checked against a node's dictionary: its objects' entries and where it lives."""

    map: PdoMap
    entries: tuple[OdEntry, ...]
    cob_id: int
    communication: int
    """The communication parameter's index (0x1400 + n - 1, 0x1800 + n - 1)."""
    mapping: int
    """The mapping parameter's index (0x1600 + n - 1, 0x1A00 + n - 1)."""

    @property
    def map_entries(self) -> tuple[co.PdoMapEntry, ...]:
        return tuple(entry.map_entry() for entry in self.entries)

    @property
    def bits(self) -> int:
        return sum(e.bit_length for e in self.map_entries)

    def codec(self) -> co.PdoCodec:
        """Packs and unpacks this PDO's data."""
        return co.PdoCodec(self.map_entries)


def _check_map(m: PdoMap) -> None:
    if m.direction not in ("rpdo", "tpdo"):
        raise BadParameterError("direction", m.direction, "'rpdo' or 'tpdo'")
    if isinstance(m.number, bool) or not isinstance(m.number, int) or not 1 <= m.number <= 512:
        raise BadParameterError(f"{m.name}.number", m.number, "a PDO number in 1..512")
    if not m.objects:
        raise BadParameterError(f"{m.name}.objects", [], "at least one object")
    if len(m.objects) > 8:  # one mapping entry per sub-index 1..8 is all a frame can carry
        raise BadParameterError(f"{m.name}.objects", list(m.objects), "at most 8 objects")
    t = m.transmission
    if isinstance(t, bool) or not isinstance(t, int) or not (0 <= t <= 240 or t in (254, 255)):
        raise BadParameterError(
            f"{m.name}.transmission", t, "0 (acyclic), 1..240 (every n SYNCs), 254 or 255"
        )
    for key, value, bits in (
        ("inhibit_time", m.inhibit_time, 16),
        ("event_timer", m.event_timer, 16),
    ):
        if value is None:
            continue
        if m.direction == "rpdo":
            raise BadParameterError(f"{m.name}.{key}", value, "a TPDO's parameter (not an RPDO's)")
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < 1 << bits:
            raise BadParameterError(f"{m.name}.{key}", value, f"0..{(1 << bits) - 1}")
    if m.cob_id is not None and (
        isinstance(m.cob_id, bool)
        or not isinstance(m.cob_id, int)
        or not 0x001 <= m.cob_id <= 0x7FF
    ):
        raise BadParameterError(f"{m.name}.cob_id", m.cob_id, "an 11-bit CAN id in 0x001..0x7FF")


def resolve_maps(
    maps: Sequence[PdoMap], od: ObjectDictionary, node_id: int
) -> tuple[ResolvedPdo, ...]:
    """``maps`` checked against ``od`` (see the module docstring); nothing is sent."""
    seen: set[tuple[str, int]] = set()
    resolved = []
    for m in maps:
        _check_map(m)
        if (m.direction, m.number) in seen:
            raise BadParameterError(m.name, list(m.objects), "one map per PDO")
        seen.add((m.direction, m.number))
        entries = []
        for key in m.objects:
            entry = od.entry(key)
            mappable = entry.rpdo_mappable if m.direction == "rpdo" else entry.tpdo_mappable
            if not mappable:
                why = (
                    "not PDO-mappable"
                    if not entry.pdo_mappable
                    else f"access {entry.access}: not {'writable' if m.direction == 'rpdo' else 'readable'} by a PDO"
                )
                raise BadParameterError(
                    f"{m.name}.objects",
                    entry.label,
                    f"an object {'an RPDO writes' if m.direction == 'rpdo' else 'a TPDO reads'} "
                    f"({entry.label} is {why} in {od.source})",
                )
            if entry.bit_length is None:
                raise BadParameterError(
                    f"{m.name}.objects", entry.label, "an object of a fixed size"
                )
            entries.append(entry)
        bits = sum(e.bit_length or 0 for e in entries)
        if bits > MAX_PDO_BITS:
            raise BadParameterError(
                f"{m.name}.objects",
                " + ".join(f"{e.name} ({e.bit_length})" for e in entries),
                f"at most {MAX_PDO_BITS} bits in one PDO ({bits} given)",
            )
        n = m.number
        if m.cob_id is not None:
            cob_id = m.cob_id
        elif n <= 4:
            cob_id = (
                co.rpdo_cob_id(n, node_id) if m.direction == "rpdo" else co.tpdo_cob_id(n, node_id)
            )
        else:
            raise BadParameterError(
                f"{m.name}.cob_id", None, "a COB-ID (PDOs above 4 have no default)"
            )
        base = (
            (co.RPDO_COMM_BASE, co.RPDO_MAPPING_BASE)
            if m.direction == "rpdo"
            else (
                co.TPDO_COMM_BASE,
                co.TPDO_MAPPING_BASE,
            )
        )
        resolved.append(ResolvedPdo(m, tuple(entries), cob_id, base[0] + n - 1, base[1] + n - 1))
    return tuple(resolved)


def _writes(p: ResolvedPdo) -> list[tuple[co.ObjectEntry, int]]:
    """The SDO writes that configure ``p``, in CiA 301's order."""
    comm, mapping, m = p.communication, p.mapping, p.map
    writes = [(co.ObjectEntry(comm, 1, _U32), p.cob_id | co.PDO_COB_ID_INVALID)]
    writes.append((co.ObjectEntry(comm, 2, _U8), m.transmission))
    if m.inhibit_time is not None:
        writes.append((co.ObjectEntry(comm, 3, _U16), m.inhibit_time))
    if m.event_timer is not None:
        writes.append((co.ObjectEntry(comm, 5, _U16), m.event_timer))
    writes.append((co.ObjectEntry(mapping, 0, _U8), 0))
    for sub, entry in enumerate(p.map_entries, start=1):
        writes.append((co.ObjectEntry(mapping, sub, _U32), entry.to_u32()))
    writes.append((co.ObjectEntry(mapping, 0, _U8), len(p.entries)))
    writes.append((co.ObjectEntry(comm, 1, _U32), p.cob_id))
    return writes


async def configure_pdos(
    sdo: SdoClient,
    pdos: Sequence[ResolvedPdo],
    *,
    timeout: float | None = None,  # noqa: ASYNC109
) -> None:
    """Write ``pdos`` to the node (in PRE-OPERATIONAL) and verify them by reading back."""
    for p in pdos:
        for entry, value in _writes(p):
            try:
                await sdo.write(entry, value, timeout=timeout)
            except SdoAbortError as exc:
                if entry.index != p.mapping or value == 0:
                    raise
                # an entry (sub 1..8), or the count (sub 0), where a node checks the whole map
                refused = [p.entries[entry.subindex - 1]] if entry.subindex else p.entries
                raise PdoMappingError(
                    f"node {sdo.node_id} {p.map.name}: the node refused to map "
                    f"{', '.join(e.label for e in refused)} ({exc})"
                ) from exc
    for p in pdos:
        held = await read_pdo(sdo, p.map.direction, p.map.number, timeout=timeout)
        expected = (p.cob_id, p.map.transmission, tuple(e.to_u32() for e in p.map_entries))
        if held != expected:
            raise PdoMappingError(
                f"node {sdo.node_id} {p.map.name}: holds COB-ID {held[0]:#x}, transmission "
                f"{held[1]}, mapping {[f'{v:#010x}' for v in held[2]]} after it was written "
                f"{expected[0]:#x}, {expected[1]}, {[f'{v:#010x}' for v in expected[2]]}"
            )


async def read_pdo(
    sdo: SdoClient,
    direction: Direction,
    number: int,
    *,
    timeout: float | None = None,  # noqa: ASYNC109
) -> tuple[int, int, tuple[int, ...]]:
    """A PDO as the node holds it: (COB-ID, transmission type, mapping entries as u32)."""
    comm = (co.RPDO_COMM_BASE if direction == "rpdo" else co.TPDO_COMM_BASE) + number - 1
    mapping = (co.RPDO_MAPPING_BASE if direction == "rpdo" else co.TPDO_MAPPING_BASE) + number - 1
    cob_id = await sdo.read(co.ObjectEntry(comm, 1, _U32), timeout=timeout)
    transmission = await sdo.read(co.ObjectEntry(comm, 2, _U8), timeout=timeout)
    count = await sdo.read(co.ObjectEntry(mapping, 0, _U8), timeout=timeout)
    entries = [
        await sdo.read(co.ObjectEntry(mapping, sub, _U32), timeout=timeout)
        for sub in range(1, count + 1)
    ]
    return cob_id, transmission, tuple(entries)


Mode = Literal["pp", "pv", "tq", "csp", "csv", "cst"]
_TARGETS: dict[str, str] = {
    "pp": "Target position",
    "csp": "Target position",
    "pv": "Target velocity",
    "csv": "Target velocity",
    "tq": "Target torque",
    "cst": "Target torque",
}


def cia402_maps(mode: Mode, *, event_timer: int = 10) -> tuple[PdoMap, ...]:
    """The CiA 402 maps of a mode: RPDO1 controlword and the mode's target; TPDO1 statusword,
    position and torque actual; TPDO2 velocity actual and the mode display. Cyclic
    synchronous modes (csp, csv, cst) send and apply them every SYNC; profile modes (pp,
    pv, tq) apply the RPDO at once and send the TPDOs on change and every ``event_timer``
    ms."""
    if mode not in _TARGETS:
        raise BadParameterError("mode", mode, f"one of {', '.join(_TARGETS)}")
    cyclic = mode.startswith("cs")
    rx = 1 if cyclic else 255
    tx_timer = None if cyclic else event_timer
    return (
        PdoMap("rpdo", 1, ("Controlword", _TARGETS[mode]), transmission=rx),
        PdoMap(
            "tpdo",
            1,
            ("Statusword", "Position actual value", "Torque actual value"),
            transmission=rx,
            event_timer=tx_timer,
        ),
        PdoMap(
            "tpdo",
            2,
            ("Velocity actual value", "Modes of operation display"),
            transmission=rx,
            event_timer=tx_timer,
        ),
    )


class PdoSpec(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """A PDO map in a rig file (a drive's ``params: {pdos: [...]}``)."""

    pdo: str
    """``rpdo1`` .. ``rpdo512``, ``tpdo1`` .. ``tpdo512``."""
    objects: list[str | int]
    """The objects it carries, by name (``Controlword``) or index text (``0x607A``)."""
    transmission: int = 1
    """1..240: every n SYNCs; 0: acyclic synchronous; 254/255: event-driven."""
    cob_id: int | None = None
    inhibit_time: int | None = None
    event_timer: int | None = None

    def to_map(self) -> PdoMap:
        text = self.pdo.lower()
        direction = text[:4]
        if direction not in ("rpdo", "tpdo") or not text[4:].isdigit():
            raise BadParameterError("pdo", self.pdo, "rpdoN or tpdoN (N in 1..512)")
        return PdoMap(
            direction,  # type: ignore[arg-type]
            int(text[4:]),
            tuple(self.objects),
            transmission=self.transmission,
            cob_id=self.cob_id,
            inhibit_time=self.inhibit_time,
            event_timer=self.event_timer,
        )
