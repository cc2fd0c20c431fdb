"""The rig file: its schema and its reading (strict: unknown keys are refused with their
position). Nothing here opens hardware; :mod:`openel_async.rig.check` resolves the drivers and
:mod:`openel_async.rig.runtime` opens a rig.

```yaml
namespace: lab            # the key-expression namespace of `openel-async serve`
buses:
  can0: {type: can, interface: socketcan, channel: can0, bitrate: 1000000}
components:
  - name: MOTOR_1         # device name of the component
    driver: can           # a registered driver (openel-async devices)
    device: odrive_axis   # one of its device classes
    bus: can0             # the bus it is on (a device of a bus driver)
    params: {node_id: 1}  # the device class's arguments
    limits: {position: [-3.0, 3.0], velocity: 5.0, acceleration: 50.0, torque: 1.0}
    hal_id: {vendor_id: 0xE1, product_id: 0x100, instance_id: 1}   # optional
  - name: ENCODER_1
    driver: sim
    device: encoder
    params: {motor: {ref: MOTOR_0}}   # another component's device as a parameter
timers:
  sync: {period_ms: 10}
groups:
  arm: {axes: [MOTOR_1, MOTOR_2], timer: sync, limits: {max_jerk: 500.0}}
safety: {watchdog_timeout: 0.5, on_exit: stop}
```

docs/hardware.md documents every field; ``openel-async rig schema`` prints the JSON Schema
(:func:`json_schema`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import msgspec

from ..errors import BadParameterError
from ..positioned import (
    DocumentError,
    Location,
    YamlDocument,
    convert,
    load_yaml,
    relocate,
)
from ..safety import ExitAction

__all__ = [
    "BusSpec",
    "ComponentSpec",
    "GroupSpec",
    "JointLimits",
    "RigSpec",
    "SafetySpec",
    "TimerSpec",
    "json_schema",
    "load_rig",
    "parse_rig",
]


# -- the document (msgspec: strict, and the source of `rig schema`) ---------------------------


class LimitsDoc(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """Per-joint limits, enforced on the host before a command leaves it (SI units)."""

    position: tuple[float, float] | None = None
    """[min, max] position, rad (rotary) or m (linear)."""
    velocity: float | None = None
    """Largest |velocity|, rad/s or m/s (commands, and an axis group's planning)."""
    acceleration: float | None = None
    """Largest |acceleration|, rad/s² or m/s² (an axis group's planning)."""
    torque: float | None = None
    """Largest |torque|, Nm or N."""


class HalIdDoc(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """The component's HAL id; each field defaults to the device's."""

    device_kind_id: int | None = None
    vendor_id: int | None = None
    product_id: int | None = None
    instance_id: int | None = None


class ComponentDoc(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """One HAL component: a device of a driver, on a bus or not."""

    name: str
    """The component's device name (unique in the rig)."""
    driver: str
    """A registered driver (``openel-async devices``)."""
    device: str
    """One of the driver's device classes."""
    bus: str | None = None
    """The bus (a key of ``buses``) the device is on; the bus gives the device its bus
    argument (``bus``, ``port``), ``params`` give its address (``node_id``, ``dxl_id``)."""
    params: dict[str, Any] | None = None
    """The device class's keyword arguments; ``{ref: NAME}`` is an earlier component's
    device."""
    limits: LimitsDoc | None = None
    hal_id: HalIdDoc | None = None


class TimerDoc(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """An EventTimer the app gets by name."""

    period_ms: float
    """The tick period in ms (OpenEL timer periods are in ms)."""
    late_threshold_ms: float | None = None
    """A tick later than this counts as late in the timer's stats (default: one period)."""


class GroupLimitsDoc(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """The kinematic limits an axis group plans with, for every axis (a missing velocity or
    acceleration comes from each axis's ``limits``)."""

    max_velocity: float | None = None
    max_acceleration: float | None = None
    max_jerk: float
    """rad/s³ or m/s³."""


class GroupDoc(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """An AxisGroup: time-synchronized trajectories over actuators, streamed at a timer's
    ticks."""

    axes: list[str]
    """Actuator components of the rig, in order."""
    timer: str | None = None
    """A timer of ``timers`` (shared); or give ``period_ms`` for a timer of its own."""
    period_ms: float | None = None
    limits: GroupLimitsDoc
    goal_time: float = 1.0
    """Seconds the axes may take after the trajectory ends to be within their goal
    tolerance."""
    synchronization: Literal["phase", "time"] = "phase"


class SafetyDoc(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """What protects the machine when the host stalls, dies or stops."""

    watchdog_timeout: float | None = 0.5
    """Seconds: each device with a watchdog of its own (ODrive axis watchdog, CiA 402
    heartbeat consumer, Dynamixel Bus Watchdog) stops by itself when the host is silent for
    longer. ``null``: not armed."""
    on_exit: Literal["hold", "stop", "torque_off"] = "stop"
    """The state every actuator is left in when a run ends, however it ends."""
    exit_timeout: float = 2.0
    """Seconds the safe stop of one actuator may take."""
    estop_on_sigquit: bool = True
    """SIGQUIT (Ctrl-\\\\) e-stops every actuator of the rig."""


class RigDoc(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """A rig file."""

    description: str = ""
    """One line saying what the machine is (the summaries' title)."""
    namespace: str = "default"
    """The key-expression namespace (``openel/<namespace>/...``) of ``openel-async serve``."""
    buses: dict[str, dict[str, Any]] | None = None
    """Buses by name: ``type`` (a bus kind a driver registers: ``can``, ``serial``) and that
    kind's options."""
    components: list[ComponentDoc]
    timers: dict[str, TimerDoc] | None = None
    groups: dict[str, GroupDoc] | None = None
    safety: SafetyDoc | None = None


def json_schema() -> dict[str, Any]:
    """The JSON Schema of a rig file (bus options are per kind: see ``rig schema --bus``)."""
    schema: dict[str, Any] = msgspec.json.schema(RigDoc)
    return schema


# -- what the rest of the package works with -----------------------------------------------------


@dataclass(frozen=True)
class JointLimits:
    position: tuple[float, float] | None = None
    velocity: float | None = None
    acceleration: float | None = None
    torque: float | None = None

    def is_empty(self) -> bool:
        return all(
            v is None for v in (self.position, self.velocity, self.acceleration, self.torque)
        )


@dataclass(frozen=True)
class ComponentSpec:
    name: str
    driver: str
    device: str
    params: Mapping[str, Any] = field(default_factory=dict)
    hal_id: Mapping[str, int] | None = None
    locations: Mapping[str, Location] = field(default_factory=dict, compare=False, repr=False)
    """Where the entry (``""``), its ``bus`` (``"@bus"``) and each of its ``params`` keys are
    written, when read from a file."""
    bus: str | None = None
    limits: JointLimits = field(default_factory=JointLimits)


@dataclass(frozen=True)
class BusSpec:
    name: str
    type: str
    options: Mapping[str, Any]
    """The entry's keys besides ``type``, converted by the bus kind when resolved."""
    location: Location | None = field(default=None, compare=False, repr=False)
    doc: YamlDocument | None = field(default=None, compare=False, repr=False)
    raw: Any = field(default=None, compare=False, repr=False)
    """The entry as parsed (for positions of its keys)."""


@dataclass(frozen=True)
class TimerSpec:
    name: str
    period_ms: float
    late_threshold_ms: float | None = None


@dataclass(frozen=True)
class GroupSpec:
    name: str
    axes: tuple[str, ...]
    timer: str
    """A timer of the rig (a group with ``period_ms`` gets one named ``group:<name>``)."""
    max_jerk: float
    max_velocity: float | None = None
    max_acceleration: float | None = None
    goal_time: float = 1.0
    synchronization: str = "phase"
    location: Location | None = field(default=None, compare=False, repr=False)


@dataclass(frozen=True)
class SafetySpec:
    watchdog_timeout: float | None = 0.5
    on_exit: ExitAction = ExitAction.STOP
    exit_timeout: float = 2.0
    estop_on_sigquit: bool = True


@dataclass(frozen=True)
class RigSpec:
    namespace: str
    components: tuple[ComponentSpec, ...]
    buses: tuple[BusSpec, ...] = ()
    timers: tuple[TimerSpec, ...] = ()
    groups: tuple[GroupSpec, ...] = ()
    safety: SafetySpec = field(default_factory=SafetySpec)
    source: str = "rig"
    """The file it was read from (``rig`` for plain data)."""
    description: str = ""

    def component(self, name: str) -> ComponentSpec:
        for c in self.components:
            if c.name == name:
                return c
        raise KeyError(name)


# -- reading ------------------------------------------------------------------------------------


class _Reader:
    def __init__(self, data: object, source: str, doc: YamlDocument | None) -> None:
        self.located = doc is not None  # plain data (not from a file) has no positions
        self.doc = doc if doc is not None else YamlDocument(data, source, {})
        self.data = data
        self.source = source

    def error(
        self, parameter: str, value: object, allowed: str, location: Location | None
    ) -> BadParameterError:
        error = BadParameterError(parameter, value, allowed)
        if not self.located or location is None:
            return error
        return relocate(error, DocumentError(str(error), path=parameter, location=location))

    def value(self, container: object, key: object) -> Location | None:
        return self.doc.value(container, key) if self.located else None


def _positive(r: _Reader, where: str, value: float | None, container: object, key: str) -> None:
    if value is not None and not (math.isfinite(value) and value > 0):
        raise r.error(f"{where}.{key}", value, "a finite number > 0", r.value(container, key))


def parse_rig(data: object, source: str = "rig", doc: YamlDocument | None = None) -> RigSpec:
    """A rig from its parsed document (``doc`` gives the positions when it came from a
    file, see :func:`load_rig`); BadParameterError for any mistake the file alone shows
    (drivers, devices and bus options are checked by :func:`openel_async.rig.check_rig`)."""
    r = _Reader(data, source, doc)
    if not isinstance(data, Mapping):
        raise r.error(
            source, data, "a mapping with 'components'", r.doc.where(data) if r.located else None
        )
    try:
        rig = convert(r.doc, data, RigDoc, source)
    except DocumentError as exc:
        error = BadParameterError(exc.path, None, exc.message)
        cause = exc if r.located else DocumentError(exc.message, path=exc.path)
        raise relocate(error, cause) from None
    if not rig.namespace:
        raise r.error(
            f"{source}.namespace", rig.namespace, "a non-empty string", r.value(data, "namespace")
        )
    buses = _buses(r, rig, data)
    components = _components(r, rig, data, {b.name for b in buses})
    timers, groups = _timers_and_groups(r, rig, data, components)
    safety = _safety(r, rig, data)
    return RigSpec(
        rig.namespace, components, buses, timers, groups, safety, source, rig.description
    )


def _buses(r: _Reader, rig: RigDoc, data: Mapping[str, Any]) -> tuple[BusSpec, ...]:
    out: list[BusSpec] = []
    raw_buses = data.get("buses") or {}
    for name, entry in (rig.buses or {}).items():
        where = f"{r.source}.buses.{name}"
        raw = raw_buses[name]
        if not name:
            raise r.error(
                f"{r.source}.buses",
                name,
                "a non-empty bus name",
                r.doc.key(raw_buses, name) if r.located else None,
            )
        kind = entry.get("type")
        if not isinstance(kind, str) or not kind:
            raise r.error(
                f"{where}.type",
                kind,
                "a bus type registered by a driver (can, serial...)",
                r.value(raw, "type")
                if "type" in raw
                else (r.doc.where(raw) if r.located else None),
            )
        options = {k: v for k, v in entry.items() if k != "type"}
        out.append(
            BusSpec(
                name,
                kind,
                options,
                r.doc.where(raw) if r.located else None,
                r.doc if r.located else None,
                raw,
            )
        )
    return tuple(out)


def _components(
    r: _Reader, rig: RigDoc, data: Mapping[str, Any], buses: set[str]
) -> tuple[ComponentSpec, ...]:
    source = r.source
    entries = data["components"]
    if not rig.components:
        raise r.error(f"{source}.components", [], "a non-empty list", r.value(data, "components"))
    specs: list[ComponentSpec] = []
    for i, (entry, raw) in enumerate(zip(rig.components, entries, strict=True)):
        where = f"{source}.components[{i}]"
        for key in ("name", "driver", "device"):
            if not getattr(entry, key):
                raise r.error(f"{where}.{key}", "", "a non-empty string", r.value(raw, key))
        if entry.bus is not None and entry.bus not in buses:
            allowed = (
                f"a bus of the rig ({', '.join(sorted(buses))})"
                if buses
                else "a bus of the rig (it has no 'buses')"
            )
            raise r.error(f"{entry.name}.bus", entry.bus, allowed, r.value(raw, "bus"))
        hal_id = None
        if entry.hal_id is not None:
            hal_id = {
                k: v for k, v in msgspec.structs.asdict(entry.hal_id).items() if v is not None
            }
        limits = JointLimits()
        if entry.limits is not None:
            raw_limits = raw["limits"]
            lim = entry.limits
            if lim.position is not None:
                low, high = lim.position
                if not (math.isfinite(low) and math.isfinite(high) and low < high):
                    raise r.error(
                        f"{entry.name}.limits.position",
                        list(lim.position),
                        "[min, max] with min < max, both finite",
                        r.value(raw_limits, "position"),
                    )
            for key in ("velocity", "acceleration", "torque"):
                _positive(r, f"{entry.name}.limits", getattr(lim, key), raw_limits, key)
            limits = JointLimits(lim.position, lim.velocity, lim.acceleration, lim.torque)
        params = entry.params or {}
        raw_params = raw.get("params") or {}
        locations: dict[str, Location] = {}
        if r.located:
            locations = {"": r.doc.where(raw)} | {k: r.doc.key(raw_params, k) for k in params}
            if "bus" in raw:
                locations["@bus"] = r.doc.value(raw, "bus")
        specs.append(
            ComponentSpec(
                entry.name, entry.driver, entry.device, params, hal_id, locations, entry.bus, limits
            )
        )
    names = [s.name for s in specs]
    if len(set(names)) != len(names):
        twice = next(n for i, n in enumerate(names) if n in names[:i])
        raise r.error(
            f"{source}.components",
            names,
            f"unique names ({twice!r} twice)",
            r.value(entries[names.index(twice, names.index(twice) + 1)], "name"),
        )
    return tuple(specs)


def _timers_and_groups(
    r: _Reader, rig: RigDoc, data: Mapping[str, Any], components: tuple[ComponentSpec, ...]
) -> tuple[tuple[TimerSpec, ...], tuple[GroupSpec, ...]]:
    raw_timers = data.get("timers") or {}
    timers: list[TimerSpec] = []
    for name, t in (rig.timers or {}).items():
        _positive(r, f"timers.{name}", t.period_ms, raw_timers[name], "period_ms")
        _positive(r, f"timers.{name}", t.late_threshold_ms, raw_timers[name], "late_threshold_ms")
        timers.append(TimerSpec(name, t.period_ms, t.late_threshold_ms))
    names = {c.name: c for c in components}
    raw_groups = data.get("groups") or {}
    groups: list[GroupSpec] = []
    for name, g in (rig.groups or {}).items():
        raw = raw_groups[name]
        where = f"groups.{name}"
        if not g.axes:
            raise r.error(
                f"{where}.axes", [], "a non-empty list of actuator components", r.value(raw, "axes")
            )
        for i, axis in enumerate(g.axes):
            if axis not in names:
                raise r.error(
                    f"{where}.axes[{i}]",
                    axis,
                    f"a component of the rig ({', '.join(names)})",
                    r.value(raw["axes"], i),
                )
        if len(set(g.axes)) != len(g.axes):
            raise r.error(f"{where}.axes", g.axes, "each axis once", r.value(raw, "axes"))
        if (g.timer is None) == (g.period_ms is None):
            raise r.error(
                where,
                dict(raw),
                "exactly one of 'timer' (a timer of 'timers') and 'period_ms'",
                r.doc.where(raw) if r.located else None,
            )
        if g.timer is not None:
            if g.timer not in {t.name for t in timers}:
                known = ", ".join(t.name for t in timers) or "none"
                raise r.error(
                    f"{where}.timer",
                    g.timer,
                    f"a timer of 'timers' ({known})",
                    r.value(raw, "timer"),
                )
            timer = g.timer
        else:
            _positive(r, where, g.period_ms, raw, "period_ms")
            assert g.period_ms is not None
            timer = f"group:{name}"
            timers.append(TimerSpec(timer, g.period_ms))
        raw_limits = raw["limits"]
        for key in ("max_velocity", "max_acceleration", "max_jerk"):
            _positive(r, f"{where}.limits", getattr(g.limits, key), raw_limits, key)
        for key, joint_key in (("max_velocity", "velocity"), ("max_acceleration", "acceleration")):
            if getattr(g.limits, key) is None:
                missing = [a for a in g.axes if getattr(names[a].limits, joint_key) is None]
                if missing:
                    raise r.error(
                        f"{where}.limits.{key}",
                        None,
                        f"a value, or limits.{joint_key} on every axis (missing on {', '.join(missing)})",
                        r.doc.where(raw_limits) if r.located else None,
                    )
        _positive(r, where, g.goal_time, raw, "goal_time")
        groups.append(
            GroupSpec(
                name,
                tuple(g.axes),
                timer,
                g.limits.max_jerk,
                g.limits.max_velocity,
                g.limits.max_acceleration,
                g.goal_time,
                g.synchronization,
                r.doc.where(raw) if r.located else None,
            )
        )
    return tuple(timers), tuple(groups)


def _safety(r: _Reader, rig: RigDoc, data: Mapping[str, Any]) -> SafetySpec:
    if rig.safety is None:
        return SafetySpec()
    raw = data["safety"]
    s = rig.safety
    _positive(r, "safety", s.watchdog_timeout, raw, "watchdog_timeout")
    _positive(r, "safety", s.exit_timeout, raw, "exit_timeout")
    return SafetySpec(s.watchdog_timeout, ExitAction(s.on_exit), s.exit_timeout, s.estop_on_sigquit)


def load_rig(path: str | Path) -> RigSpec:
    """Read a rig file; BadParameterError naming the file (and the line and column)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise BadParameterError("rig", str(path), f"a readable YAML rig file ({exc})") from None
    try:
        doc = load_yaml(text, str(path))
    except DocumentError as exc:
        error = BadParameterError("rig", str(path), f"a valid YAML rig file ({exc.message})")
        raise relocate(error, exc) from None
    return dataclasses.replace(parse_rig(doc.data, "rig", doc), source=str(path))
