"""PDO maps: which objects each RPDO/TPDO carries, how it is sent, written and verified.

A :class:`PdoSpec` describes one PDO as a rig file does (msgspec: :func:`parse_pdos`
reads the ``pdos:`` entry of a device's params, :func:`dump_pdos` writes it back)::

    pdos:
      - {pdo: rpdo1, objects: [Controlword, Target position], trigger: sync}
      - {pdo: tpdo1, objects: [Statusword, "0x6064"], trigger: sync, every: 1}
      - {pdo: tpdo2, objects: [Velocity actual value], trigger: event,
         inhibit_us: 500, event_ms: 10}

* ``pdo``: ``rpdo1`` .. ``rpdo512`` (master -> node) or ``tpdo1`` .. ``tpdo512``;
* ``objects``: by name or index text (:data:`openel_can.od.ObjectKey`), in frame order;
* ``trigger``: ``sync`` -- transmission type ``every`` (1..240): a TPDO is sent on every
  ``every``-th SYNC, an RPDO is applied at the next SYNC -- or ``event`` (type 0xFF, the
  device profile's event: a TPDO when its data changes and every ``event_ms``, never
  closer than ``inhibit_us``; an RPDO applied at once);
* ``cob_id``: the 11-bit CAN id (default: the CiA 301 predefined set for PDOs 1..4,
  0x180/0x200 + 0x100 * (n - 1) + node id); ``enabled`` False disables the PDO.

:func:`resolve_pdos` checks specs against the node's object dictionary
(:class:`openel_can.od.ObjectDictionary`) and gives :class:`ResolvedPdo` items (the
mapping entries, COB-ID, transmission type, a codec to pack RPDOs and unpack TPDOs). A
spec the node would refuse is a :class:`PdoMapError` (a ``BadParameterError``) naming the
PDO and the object: an unknown object, an object the file does not mark PDO-mappable,
an object mapped twice in one PDO, one of the wrong direction (an RPDO writes: ``wo``/``rw``/``rww``; a TPDO reads:
``ro``/``const``/``rw``/``rwr``), more than 64 bits, more objects than the mapping
record holds, a PDO number the file does not have, timers on a PDO whose communication
record has no such entry, two PDOs on one COB-ID.

:func:`configure_pdos` writes them by SDO with the CiA 301 sequence, for each PDO:

1. COB-ID (comm sub 1) with bit 31 set: the PDO is invalid while it changes;
2. mapping sub 0 = 0: the mapping is cleared;
3. mapping sub 1..n = ``index << 16 | subindex << 8 | bits``;
4. mapping sub 0 = n;
5. transmission type (sub 2), inhibit time (sub 3, 100 µs) and event timer (sub 5, ms)
   where the record has them;
6. COB-ID without bit 31: the PDO is valid again (a disabled spec keeps it set).

PDOs of the dictionary that no spec names are disabled (``disable_unused``). Then every
written entry is read back: a value that differs raises :class:`PdoVerifyError` naming
the PDO, the entry and both values; a refusal by the node (an SDO abort) raises
:class:`PdoConfigError` naming the PDO, the entry and the mapped object. The node must be
in PRE-OPERATIONAL (the caller sends NMT enter pre-operational before and NMT start
after). :func:`default_pdos` gives sensible CiA 402 maps per mode, :func:`maps_from_od`
the PDOs a DCF configures.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Annotated, Final, Literal

import msgspec

from openel_async.errors import BadParameterError, HALError
from openel_async.logs import get_logger

from . import canopen as co
from . import cia402 as ds
from .od import ObjectDictionary, ObjectNotFoundError, OdEntry
from .sdo import SdoAbortError, SdoClient

__all__ = [
    "MAX_PDO_BITS",
    "PdoConfigError",
    "PdoMapError",
    "PdoSpec",
    "PdoVerifyError",
    "ResolvedPdo",
    "configure_pdos",
    "default_pdos",
    "dump_pdos",
    "maps_from_od",
    "parse_pdos",
    "resolve_pdos",
]

log = get_logger(__name__)

MAX_PDO_BITS: Final = 64
_PDO_NAME: Final = re.compile(r"^(rpdo|tpdo)([1-9][0-9]{0,2})$", re.IGNORECASE)
_RTR_NOT_ALLOWED: Final = 0x4000_0000
_EVENT: Final = 0xFF

ObjectName = str | tuple[int, int]


class PdoSpec(
    msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True, omit_defaults=True
):
    """One PDO as a rig file or a program says it (see the module docstring)."""

    pdo: Annotated[str, msgspec.Meta(pattern=r"^(?i:rpdo|tpdo)[1-9][0-9]{0,2}$")]
    objects: tuple[ObjectName, ...] = ()
    trigger: Literal["sync", "event"] = "event"
    every: Annotated[int, msgspec.Meta(ge=1, le=240)] = 1
    inhibit_us: Annotated[int, msgspec.Meta(ge=0, le=6_553_500, multiple_of=100)] = 0
    event_ms: Annotated[int, msgspec.Meta(ge=0, le=0xFFFF)] = 0
    cob_id: Annotated[int, msgspec.Meta(ge=1, le=0x7FF)] | None = None
    enabled: bool = True


def parse_pdos(raw: object, *, where: str = "pdos") -> tuple[PdoSpec, ...]:
    """The specs of a rig file's ``pdos:`` entry (a list of mappings);
    ``BadParameterError`` naming the position of a bad one."""
    try:
        return msgspec.convert(raw, tuple[PdoSpec, ...], strict=True)
    except msgspec.ValidationError as exc:
        raise BadParameterError(where, raw, f"a list of PDO maps ({exc})") from None


def dump_pdos(specs: Sequence[PdoSpec]) -> list[dict[str, object]]:
    """Plain data of ``specs`` (defaults omitted): what a rig file's ``pdos:`` holds."""
    out: list[dict[str, object]] = msgspec.json.decode(msgspec.json.encode(tuple(specs)))
    return out


class PdoMapError(BadParameterError):
    """A PDO map the node would refuse; the message names the PDO and the object."""


class PdoConfigError(HALError):
    """The node refused a write of the PDO configuration (an SDO abort)."""


class PdoVerifyError(HALError):
    """A PDO configuration entry read back differs from what was written."""


@dataclass(frozen=True)
class ResolvedPdo:
    """A spec checked against an object dictionary: what is written and how frames are
    packed (RPDO) or unpacked (TPDO)."""

    spec: PdoSpec
    transmit: bool
    """True for a TPDO (node -> master)."""
    number: int
    cob_id: int
    transmission_type: int
    inhibit: int
    """Inhibit time in 100 µs units."""
    event_ms: int
    entries: tuple[OdEntry, ...]
    comm: Mapping[int, OdEntry]
    """The communication record's entries by sub-index (1, 2 and 3/5 where present)."""
    mapping: Mapping[int, OdEntry]
    """The mapping record's entries by sub-index (0 .. highest)."""

    @property
    def name(self) -> str:
        return f"{'TPDO' if self.transmit else 'RPDO'}{self.number}"

    @property
    def comm_index(self) -> int:
        return (co.TPDO_COMM_BASE if self.transmit else co.RPDO_COMM_BASE) + self.number - 1

    @property
    def map_index(self) -> int:
        return (co.TPDO_MAPPING_BASE if self.transmit else co.RPDO_MAPPING_BASE) + self.number - 1

    @property
    def map_entries(self) -> tuple[co.PdoMapEntry, ...]:
        return tuple(e.map_entry() for e in self.entries)

    @property
    def bits(self) -> int:
        return sum(e.bit_length or 0 for e in self.entries)

    @property
    def codec(self) -> co.PdoCodec:
        return co.PdoCodec(self.map_entries)

    def pack(self, values: Mapping[str, int] | Sequence[int]) -> bytes:
        """The frame data of ``values`` (by object name, or in map order)."""
        if isinstance(values, Mapping):
            missing = [e.name for e in self.entries if e.name not in values]
            if missing:
                raise BadParameterError(
                    "values", dict(values), f"a value for each of {[e.name for e in self.entries]}"
                )
            ordered = [int(values[e.name]) for e in self.entries]
        else:
            ordered = [int(v) for v in values]
        try:
            return self.codec.pack(ordered)
        except ValueError as exc:
            raise BadParameterError(f"{self.name} values", ordered, str(exc)) from None

    def unpack(self, data: bytes | bytearray) -> dict[str, int]:
        """The values in a received frame, by object name (``CanOpenDecodeError`` when it
        is too short)."""
        return dict(zip((e.name for e in self.entries), self.codec.unpack(data), strict=True))


def _pdo_number(text: str, where: str) -> tuple[bool, int]:
    match = _PDO_NAME.match(text.strip())
    if match is None or not 1 <= int(match.group(2)) <= 512:
        raise PdoMapError(f"{where}.pdo", text, "rpdo1..rpdo512 or tpdo1..tpdo512")
    return match.group(1).lower() == "tpdo", int(match.group(2))


def _record(od: ObjectDictionary, index: int) -> dict[int, OdEntry]:
    return {e.subindex: e for e in od.subentries(index)}


def resolve_pdos(
    specs: Sequence[PdoSpec], od: ObjectDictionary, *, node_id: int | None = None
) -> tuple[ResolvedPdo, ...]:
    """Check ``specs`` against ``od`` (see the module docstring); ``node_id`` (default the
    dictionary's) gives the predefined COB-IDs."""
    node = od.node_id if node_id is None else node_id
    resolved: list[ResolvedPdo] = []
    seen: dict[tuple[bool, int], str] = {}
    cob_ids: dict[int, str] = {}
    for i, spec in enumerate(specs):
        where = f"pdos[{i}]"
        if not isinstance(spec, PdoSpec):
            raise PdoMapError(where, spec, "a PdoSpec")
        transmit, number = _pdo_number(spec.pdo, where)
        kind = "TPDO" if transmit else "RPDO"
        name = f"{kind}{number}"
        if (transmit, number) in seen:
            raise PdoMapError(
                f"{where}.pdo", spec.pdo, f"each PDO once ({name} is also {seen[transmit, number]})"
            )
        seen[transmit, number] = where
        comm_index = (co.TPDO_COMM_BASE if transmit else co.RPDO_COMM_BASE) + number - 1
        map_index = (co.TPDO_MAPPING_BASE if transmit else co.RPDO_MAPPING_BASE) + number - 1
        comm, mapping = _record(od, comm_index), _record(od, map_index)
        if 1 not in comm or 2 not in comm or 0 not in mapping:
            have = sorted(
                n + 1
                for n in range(512)
                if od.find(((co.TPDO_COMM_BASE if transmit else co.RPDO_COMM_BASE) + n, 1))
            )
            raise PdoMapError(
                f"{where}.pdo",
                spec.pdo,
                f"a {kind} of {od.source} ({kind}s {_ranges(have) or 'none'}: {comm_index:#06x}/"
                f"{map_index:#06x} are not in the file)",
            )
        slots = max(mapping) if mapping else 0
        if len(spec.objects) > slots:
            raise PdoMapError(
                f"{where}.objects",
                list(spec.objects),
                f"at most {slots} objects: {name}'s mapping {map_index:#06x} has sub-indices 1..{slots}",
            )
        entries: list[OdEntry] = []
        bits = 0
        for j, key in enumerate(spec.objects):
            at = f"{where}.objects[{j}]"
            try:
                entry = od.entry(key)
            except ObjectNotFoundError as exc:
                raise PdoMapError(at, key, f"an object of {od.source}: {exc.allowed}") from None
            if entry in entries:
                raise PdoMapError(
                    at, key, f"each object once per PDO: {entry.label} is mapped twice"
                )
            if not entry.pdo_mappable:
                raise PdoMapError(
                    at,
                    key,
                    f"a PDO-mappable object: {entry.label} is not (PDOMapping=0 in {od.source})",
                )
            if not (entry.tpdo_mappable if transmit else entry.rpdo_mappable):
                need = (
                    "readable by the node (ro, const, rw, rwr)"
                    if transmit
                    else "written by the master (wo, rw, rww)"
                )
                raise PdoMapError(
                    at,
                    key,
                    f"an object a {kind} can carry, {need}: {entry.label} is {entry.access}",
                )
            if not entry.is_integer or entry.bit_length is None:
                raise PdoMapError(at, key, f"an integer object: {entry.label} is {entry.type_name}")
            bits += entry.bit_length
            if bits > MAX_PDO_BITS:
                raise PdoMapError(
                    at,
                    key,
                    f"at most {MAX_PDO_BITS} bits in {name}: {entry.label} ({entry.bit_length} "
                    f"bits) makes {bits}",
                )
            entries.append(entry)
        if spec.trigger == "event" and spec.every != 1:
            raise PdoMapError(f"{where}.every", spec.every, "1: 'every' applies to trigger sync")
        for sub, field, value in (
            (3, "inhibit_us", spec.inhibit_us),
            (5, "event_ms", spec.event_ms),
        ):
            if value and spec.trigger == "sync":
                raise PdoMapError(
                    f"{where}.{field}", value, "0: a synchronous PDO has no timers (trigger event)"
                )
            if value and sub not in comm:
                raise PdoMapError(
                    f"{where}.{field}",
                    value,
                    f"0: {name}'s communication record {comm_index:#06x} has no sub-index {sub}",
                )
        cob_id = spec.cob_id
        if cob_id is None:
            if number > 4 or node is None:
                raise PdoMapError(
                    f"{where}.cob_id",
                    None,
                    "a COB-ID: the predefined set covers PDOs 1..4 of a known node id"
                    if number > 4
                    else "a COB-ID, or a node id to derive it (the dictionary has none)",
                )
            cob_id = co.tpdo_cob_id(number, node) if transmit else co.rpdo_cob_id(number, node)
        if spec.enabled:
            if cob_id in cob_ids:
                raise PdoMapError(
                    f"{where}.cob_id",
                    hex(cob_id),
                    f"a COB-ID of its own ({cob_ids[cob_id]} uses it)",
                )
            cob_ids[cob_id] = name
        resolved.append(
            ResolvedPdo(
                spec=spec,
                transmit=transmit,
                number=number,
                cob_id=cob_id,
                transmission_type=spec.every if spec.trigger == "sync" else _EVENT,
                inhibit=spec.inhibit_us // 100,
                event_ms=spec.event_ms,
                entries=tuple(entries),
                comm={s: e for s, e in comm.items() if s in (1, 2, 3, 5)},
                mapping=mapping,
            )
        )
    return tuple(resolved)


def _ranges(numbers: Sequence[int]) -> str:
    if not numbers:
        return ""
    return f"{numbers[0]}..{numbers[-1]}" if len(numbers) > 1 else str(numbers[0])


# -- defaults ---------------------------------------------------------------------------------
_MODE_NAMES: Final[dict[str, int]] = {
    "pp": ds.ModeOfOperation.PROFILE_POSITION,
    "pv": ds.ModeOfOperation.PROFILE_VELOCITY,
    "tq": ds.ModeOfOperation.PROFILE_TORQUE,
    "csp": ds.ModeOfOperation.CYCLIC_SYNC_POSITION,
    "csv": ds.ModeOfOperation.CYCLIC_SYNC_VELOCITY,
    "cst": ds.ModeOfOperation.CYCLIC_SYNC_TORQUE,
}
_TARGETS: Final[dict[int, str]] = {
    ds.ModeOfOperation.PROFILE_POSITION: "0x607A",
    ds.ModeOfOperation.PROFILE_VELOCITY: "0x60FF",
    ds.ModeOfOperation.PROFILE_TORQUE: "0x6071",
    ds.ModeOfOperation.CYCLIC_SYNC_POSITION: "0x607A",
    ds.ModeOfOperation.CYCLIC_SYNC_VELOCITY: "0x60FF",
    ds.ModeOfOperation.CYCLIC_SYNC_TORQUE: "0x6071",
}
_CYCLIC: Final = frozenset(
    (
        ds.ModeOfOperation.CYCLIC_SYNC_POSITION,
        ds.ModeOfOperation.CYCLIC_SYNC_VELOCITY,
        ds.ModeOfOperation.CYCLIC_SYNC_TORQUE,
    )
)


def default_pdos(mode: str | int, *, every: int = 1, event_ms: int = 10) -> tuple[PdoSpec, ...]:
    """Sensible CiA 402 maps for ``mode`` (``pp``/``pv``/``tq``/``csp``/``csv``/``cst`` or
    its 0x6060 value), objects by index so any vendor's EDS names them:

    ========  ===============================================  ==========================
    RPDO1     controlword 0x6040 + the mode's target:          cyclic modes: sync
              0x607A (pp, csp), 0x60FF (pv, csv), 0x6071       (``every``); profile
              (tq, cst)                                        modes: event
    TPDO1     statusword 0x6041, position actual 0x6064,       cyclic: on every
              torque actual 0x6077                             ``every``-th SYNC;
                                                               profile: event, timer
                                                               ``event_ms``
    TPDO2     profile: velocity actual 0x606C, mode display    profile: event, timer
              0x6061; cyclic: statusword 0x6041, mode          ``event_ms``; cyclic:
              display 0x6061                                   event, no timer (on change)
    ========  ===============================================  ==========================

    In the cyclic modes TPDO2 carries every statusword change at once, so the power state
    machine runs before SYNC does (a drive is enabled before its timer starts); the
    velocity is then read by SDO. Other PDOs are left out (:func:`configure_pdos`
    disables them).
    """
    value = _MODE_NAMES.get(mode.lower()) if isinstance(mode, str) else mode
    if value not in _TARGETS:
        raise BadParameterError(
            "mode", mode, "one of " + ", ".join(_MODE_NAMES) + " (or 1, 3, 4, 8, 9, 10)"
        )
    assert value is not None
    tpdos = (("0x6041", "0x6064", "0x6077"), ("0x606C", "0x6061"))
    if value in _CYCLIC:
        return (
            PdoSpec(pdo="rpdo1", objects=("0x6040", _TARGETS[value]), trigger="sync", every=every),
            PdoSpec(pdo="tpdo1", objects=tpdos[0], trigger="sync", every=every),
            PdoSpec(pdo="tpdo2", objects=("0x6041", "0x6061")),
        )
    return (
        PdoSpec(pdo="rpdo1", objects=("0x6040", _TARGETS[value])),
        *(
            PdoSpec(pdo=f"tpdo{n}", objects=objs, event_ms=event_ms)
            for n, objs in enumerate(tpdos, start=1)
        ),
    )


def maps_from_od(od: ObjectDictionary, *, configured_only: bool = True) -> tuple[PdoSpec, ...]:
    """The PDOs a DCF configures (``configured_only``: those with a ParameterValue in
    their communication or mapping record; else every PDO of the file), from their
    values (parameter value, else default): objects as index texts, COB-ID, trigger
    (types 1..240 sync, 0xFE/0xFF event; type 0, acyclic synchronous, is refused),
    inhibit time, event timer, enabled (bit 31 clear)."""
    specs: list[PdoSpec] = []
    for transmit in (False, True):
        comm_base = co.TPDO_COMM_BASE if transmit else co.RPDO_COMM_BASE
        map_base = co.TPDO_MAPPING_BASE if transmit else co.RPDO_MAPPING_BASE
        for n in range(512):
            comm, mapping = _record(od, comm_base + n), _record(od, map_base + n)
            if 1 not in comm or 2 not in comm or 0 not in mapping:
                continue
            records = (*comm.values(), *mapping.values())
            if configured_only and all(e.parameter_value is None for e in records):
                continue
            name = f"{'tpdo' if transmit else 'rpdo'}{n + 1}"
            cob = _int(comm[1])
            ttype = _int(comm[2])
            count = _int(mapping[0])
            objects: list[ObjectName] = []
            for sub in range(1, count + 1):
                raw = _int(mapping[sub]) if sub in mapping else 0
                objects.append(f"0x{raw >> 16:04X}:{(raw >> 8) & 0xFF:X}")
            if ttype == 0 or 240 < ttype < 0xFE:
                raise PdoMapError(
                    f"{od.source} {name} transmission type", ttype, "1..240, 0xFE or 0xFF"
                )
            sync = ttype <= 240
            specs.append(
                PdoSpec(
                    pdo=name,
                    objects=tuple(objects),
                    trigger="sync" if sync else "event",
                    every=ttype if sync else 1,
                    inhibit_us=0 if sync or 3 not in comm else _int(comm[3]) * 100,
                    event_ms=0 if sync or 5 not in comm else _int(comm[5]),
                    cob_id=cob & 0x7FF,
                    enabled=not cob & co.PDO_COB_ID_INVALID,
                )
            )
    return tuple(specs)


def _int(entry: OdEntry) -> int:
    value = entry.value
    if not isinstance(value, int):
        raise PdoMapError(
            entry.label, value, "an integer value (a $NODEID default needs a node id)"
        )
    return value


# -- configuration by SDO ---------------------------------------------------------------------
async def configure_pdos(
    sdo: SdoClient,
    maps: Sequence[PdoSpec | ResolvedPdo],
    *,
    od: ObjectDictionary | None = None,
    disable_unused: bool = True,
    timeout: float | None = None,  # noqa: ASYNC109
) -> tuple[ResolvedPdo, ...]:
    """Write ``maps`` to the node by SDO and verify them (see the module docstring);
    return them resolved. ``od`` defaults to the SDO client's dictionary; the node must
    be in PRE-OPERATIONAL."""
    od = od if od is not None else sdo.od
    if od is None:
        raise BadParameterError(
            "od", None, "the node's object dictionary (configure_pdos(..., od=) or SdoClient.od)"
        )
    specs = [m for m in maps if isinstance(m, PdoSpec)]
    given = iter(resolve_pdos(specs, od, node_id=sdo.node_id))
    resolved = tuple(m if isinstance(m, ResolvedPdo) else next(given) for m in maps)
    written: list[tuple[str, OdEntry, int]] = []

    async def put(pdo: str, entry: OdEntry, value: int, what: str = "") -> None:
        try:
            await sdo.write(entry, value, timeout=timeout)
        except SdoAbortError as exc:
            raise PdoConfigError(
                f"{pdo} of node {sdo.node_id}: writing {entry.label} = {value:#x}{what} "
                f"was refused: {exc}"
            ) from exc
        written.append((pdo, entry, value))

    if disable_unused:
        used = {(p.transmit, p.number) for p in resolved}
        for transmit in (False, True):
            base = co.TPDO_COMM_BASE if transmit else co.RPDO_COMM_BASE
            for n in range(512):
                entry = od.find((base + n, 1))
                if entry is None or (transmit, n + 1) in used:
                    continue
                current = await sdo.read(entry, timeout=timeout)
                assert isinstance(current, int)
                if not current & co.PDO_COB_ID_INVALID:
                    await put(
                        f"{'TPDO' if transmit else 'RPDO'}{n + 1}",
                        entry,
                        current | co.PDO_COB_ID_INVALID,
                    )
    for pdo in resolved:
        name = pdo.name
        await put(name, pdo.comm[1], pdo.cob_id | co.PDO_COB_ID_INVALID, " (disable)")
        if pdo.spec.enabled:
            await put(name, pdo.mapping[0], 0, " (clear)")
            for sub, entry in enumerate(pdo.entries, start=1):
                raw = entry.map_entry().to_u32()
                await put(name, pdo.mapping[sub], raw, f" (maps {entry.label})")
            objects = ", ".join(e.label for e in pdo.entries)
            await put(name, pdo.mapping[0], len(pdo.entries), f" (count of {objects or 'nothing'})")
            await put(name, pdo.comm[2], pdo.transmission_type, " (transmission type)")
            if 3 in pdo.comm and pdo.comm[3].writable:
                await put(name, pdo.comm[3], pdo.inhibit, " (inhibit time, 100 µs)")
            if 5 in pdo.comm and pdo.comm[5].writable:
                await put(name, pdo.comm[5], pdo.event_ms, " (event timer, ms)")
            await put(name, pdo.comm[1], pdo.cob_id, " (enable)")
    # Verify: the last value written to each entry, read back.
    final: dict[tuple[int, int], tuple[str, OdEntry, int]] = {}
    for pdo_name, entry, value in written:
        final[entry.key] = (pdo_name, entry, value)
    for pdo_name, entry, value in final.values():
        got = await sdo.read(entry, timeout=timeout)
        mask = ~_RTR_NOT_ALLOWED if entry.subindex == 1 and entry.index < 0x1600 else -1
        if not isinstance(got, int) or got & mask != value & mask:
            mapped = ""
            if 0x1600 <= entry.index < 0x1800 or 0x1A00 <= entry.index < 0x1C00:
                mapped = f" (mapping {_describe(od, value)})" if entry.subindex else ""
            raise PdoVerifyError(
                f"{pdo_name} of node {sdo.node_id}: {entry.label} reads back "
                f"{hex(got) if isinstance(got, int) else repr(got)}, written {value:#x}{mapped}"
            )
    log.debug(
        "pdos_configured", node=sdo.node_id, pdos=[p.name for p in resolved], writes=len(written)
    )
    return resolved


def _describe(od: ObjectDictionary, raw: int) -> str:
    entry = od.find((raw >> 16, (raw >> 8) & 0xFF))
    return entry.label if entry is not None else f"{raw >> 16:#06x}:{(raw >> 8) & 0xFF}"
