"""Resolving a rig against the installed drivers (``rig check``: nothing is opened) and
building its components on opened buses."""

from __future__ import annotations

import dataclasses
import inspect
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgspec

from ..clock import Clock
from ..component import HALComponent
from ..device_registry import component_class
from ..errors import BadParameterError
from ..ids import HALId
from ..positioned import DocumentError, convert, relocate, unknown_key_message
from ..registry import DriverInfo, discover_drivers
from .buses import BusKind, BusLoad, SimulatedDevice
from .spec import BusSpec, ComponentSpec, RigSpec

__all__ = ["ResolvedBus", "ResolvedRig", "build_components", "resolve_rig"]


@dataclass(frozen=True)
class ResolvedBus:
    spec: BusSpec
    driver: str
    kind: BusKind
    options: Any
    """An instance of ``kind.options_type``."""
    devices: tuple[SimulatedDevice, ...]
    """The rig's devices on this bus."""
    load: BusLoad | None = None
    """Its computed load (:meth:`BusKind.load`), if its kind computes one."""
    timer: str | None = None
    """The rig's timer driving the bus (its groups', the fastest; else the rig's fastest
    timer; None without timers): the cycle of :attr:`load` and of
    :meth:`BusKind.bind_timer`."""


@dataclass(frozen=True)
class ResolvedRig:
    """A rig whose drivers, device classes and bus options are known to be right."""

    spec: RigSpec
    classes: Mapping[str, type]
    """The device class of each component, by name."""
    buses: Mapping[str, ResolvedBus]


def _located(error: BadParameterError, spec: ComponentSpec, key: str) -> BadParameterError:
    """``error`` located at the entry (``key=""``), its bus (``"@bus"``) or a params key."""
    location = spec.locations.get(key) or spec.locations.get("")
    if location is None:
        return error
    return relocate(error, DocumentError(str(error), path=error.parameter, location=location))


def _bus_error(error: BadParameterError, bus: BusSpec) -> BadParameterError:
    if bus.location is None:
        return error
    return relocate(error, DocumentError(str(error), path=error.parameter, location=bus.location))


def _drivers_of(spec: RigSpec) -> tuple[dict[str, DriverInfo], dict[str, tuple[str, BusKind]]]:
    """The drivers a rig names and the bus kinds they offer. Only the drivers its components
    name and those named as its bus types are loaded (a bus type is first looked for in the
    driver of its name, as the shipped drivers name theirs); every installed driver when
    something is not found there, so that a refusal lists what exists."""
    named = {c.driver for c in spec.components}
    types = {b.type for b in spec.buses}
    for names in (named | types, None):
        drivers = {e.name: e.info for e in discover_drivers(names) if e.info is not None}
        kinds: dict[str, tuple[str, BusKind]] = {}
        for driver_name, info in drivers.items():
            for type_name, kind in info.buses.items():
                kinds[type_name] = (driver_name, kind)
        if named <= drivers.keys() and types <= kinds.keys():
            break
    return drivers, kinds


def resolve_rig(spec: RigSpec) -> ResolvedRig:
    """Check a rig against the installed drivers without opening anything: drivers, device
    classes, ``params`` keys, bus types and their options, devices on buses (their kind's
    ``check``). BadParameterError at the first mistake, with its position."""
    drivers, kinds = _drivers_of(spec)
    classes: dict[str, type] = {}
    for c in spec.components:
        driver = drivers.get(c.driver)
        if driver is None:
            error = BadParameterError(f"{c.name}.driver", c.driver, f"one of {sorted(drivers)}")
            raise _located(error, c, "")
        cls = driver.devices.get(c.device)
        if cls is None:
            error = BadParameterError(
                f"{c.name}.device",
                c.device,
                f"one of {sorted(driver.devices)} of driver {c.driver}",
            )
            raise _located(error, c, "")
        classes[c.name] = cls
    buses: dict[str, ResolvedBus] = {}
    for bus in spec.buses:
        found = kinds.get(bus.type)
        if found is None:
            error = BadParameterError(
                f"buses.{bus.name}.type", bus.type, f"a bus type of a driver: {sorted(kinds)}"
            )
            raise _bus_error(error, bus)
        driver_name, kind = found
        if bus.doc is not None:
            # The entry as written (with its 'type'), so that a refusal names its position.
            typed = msgspec.defstruct(
                kind.options_type.__name__,
                [("type", str)],
                bases=(kind.options_type,),
                kw_only=True,
                forbid_unknown_fields=True,
            )
            try:
                entry = convert(bus.doc, bus.raw, typed, f"buses.{bus.name}")
            except DocumentError as exc:
                raise relocate(BadParameterError(exc.path, None, exc.message), exc) from None
            fields = msgspec.structs.asdict(entry)
            fields.pop("type")
            options = kind.options_type(**fields)
        else:
            try:
                options = convert_plain(bus.options, kind.options_type)
            except ValueError as exc:
                raise BadParameterError(f"buses.{bus.name}", dict(bus.options), str(exc)) from None
        rig_dir = _rig_dir(spec)
        if rig_dir is not None:  # the option's files relative to the rig file, not the cwd
            options = kind.resolve_paths(options, rig_dir)
        devices: list[SimulatedDevice] = []
        for c in spec.components:
            if c.bus != bus.name:
                continue
            if c.driver != driver_name:
                error = BadParameterError(
                    f"{c.name}.bus",
                    c.bus,
                    f"a bus of driver {c.driver} (bus {bus.name} is a {bus.type} bus of driver "
                    f"{driver_name})",
                )
                raise _located(error, c, "@bus")
            devices.append(
                SimulatedDevice(c.name, c.driver, c.device, dict(c.params), _rig_dir(spec))
            )
        buses[bus.name] = ResolvedBus(bus, driver_name, kind, options, tuple(devices))
    for c in spec.components:  # each entry's own keys first, then what the buses refuse
        _check_params(
            c, classes[c.name], buses[c.bus] if c.bus is not None else None, _rig_dir(spec)
        )
    for name, resolved_bus in buses.items():
        try:
            resolved_bus.kind.check(resolved_bus.options, resolved_bus.devices)
        except BadParameterError as exc:
            raise _bus_error(exc, resolved_bus.spec) from None
        cyclic, cycle_s, timer = _cycle(spec, resolved_bus.devices)
        load = resolved_bus.kind.load(resolved_bus.options, resolved_bus.devices, cyclic, cycle_s)
        if load is not None and load.fraction > 1.0:
            error = BadParameterError(
                f"buses.{name}",
                f"{load.fraction:.0%} bus load ({load.detail})",
                f"at most 100 %: {load.advice}" if load.advice else "at most 100 %",
            )
            raise _bus_error(error, resolved_bus.spec)
        buses[name] = dataclasses.replace(resolved_bus, load=load, timer=timer)
    return ResolvedRig(spec, classes, buses)


def _cycle(
    spec: RigSpec, devices: Sequence[SimulatedDevice]
) -> tuple[tuple[SimulatedDevice, ...], float | None, str | None]:
    """The devices of a bus an axis group streams set-points to, and the period and name of
    the fastest timer driving the bus: its groups' timers, else (no group on the bus) the
    rig's fastest timer; None without timers."""
    periods = {t.name: t.period_ms / 1000 for t in spec.timers}
    names = {d.name for d in devices}
    grouped: set[str] = set()
    timer: str | None = None
    for g in spec.groups:
        on_bus = names.intersection(g.axes)
        if on_bus and g.timer in periods:
            grouped |= on_bus
            if timer is None or periods[g.timer] < periods[timer]:
                timer = g.timer
    if timer is None and periods:
        timer = min(periods, key=lambda t: periods[t])
    cycle = None if timer is None else periods[timer]
    return tuple(d for d in devices if d.name in grouped), cycle, timer


def convert_plain(options: Mapping[str, Any], options_type: type[Any]) -> Any:
    """Bus options given as plain data (no file positions)."""
    try:
        return msgspec.convert(dict(options), options_type)
    except msgspec.ValidationError as exc:
        raise ValueError(str(exc)) from None


def _rig_dir(spec: RigSpec) -> Path | None:
    """The directory of the rig's file (None: the rig was given as plain data)."""
    return None if spec.source == "rig" else Path(spec.source).parent


def _bus_arguments(
    bus: ResolvedBus | None, spec: ComponentSpec, directory: Path | None
) -> set[str]:
    """The argument names the bus gives the device (asked with a placeholder bus object)."""
    if bus is None:
        return set()
    device = SimulatedDevice(spec.name, spec.driver, spec.device, dict(spec.params), directory)
    return set(bus.kind.device_arguments(object(), bus.options, device))


def _check_params(
    spec: ComponentSpec, cls: type, bus: ResolvedBus | None, directory: Path | None
) -> None:
    """Refuse a params key the device class does not take (naming the close ones), or one
    the bus gives."""
    given_by_bus = _bus_arguments(bus, spec, directory)
    for key in spec.params:
        if key in given_by_bus:
            error = BadParameterError(
                f"{spec.name}.params", key, f"no {key!r}: the bus {spec.bus} gives it"
            )
            raise _located(error, spec, key)
    try:
        parameters = inspect.signature(cls).parameters.values()
    except (TypeError, ValueError):  # no signature to check against: the call will tell
        return
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters):
        return
    allowed = [
        p.name
        for p in parameters
        if p.kind in (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
        and p.name not in given_by_bus
    ]
    for key in spec.params:
        if key not in allowed:
            where = f"{spec.name}.params (arguments of {cls.__name__})"
            message = unknown_key_message(key, where, allowed)
            error = BadParameterError(f"{spec.name}.params", key, f"an argument of {cls.__name__}")
            location = spec.locations.get(key) or spec.locations.get("")
            cause = DocumentError(message, path=f"{spec.name}.params", location=location)
            raise relocate(error, cause)
    required = [
        p.name
        for p in parameters
        if p.default is inspect.Parameter.empty
        and p.kind in (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
        and p.name not in given_by_bus
        and p.name not in spec.params
    ]
    if required:
        error = BadParameterError(
            f"{spec.name}.params",
            dict(spec.params),
            f"the arguments of {cls.__name__}, with {', '.join(required)}"
            + ("" if spec.bus is not None else " (or 'bus:' naming a bus of the rig)"),
        )
        raise _located(error, spec, "")


def build_components(
    rig: RigSpec | ResolvedRig,
    clock: Clock | None = None,
    buses: Mapping[str, object] | None = None,
    *,
    auto_init: bool = True,
) -> list[HALComponent]:
    """The components of a rig, not yet entered; ``buses``: the opened bus objects by name
    (needed when a component names a bus)."""
    resolved = rig if isinstance(rig, ResolvedRig) else resolve_rig(rig)
    built: dict[str, HALComponent] = {}
    for c in resolved.spec.components:
        cls = resolved.classes[c.name]
        params = {k: _resolve(c, k, v, built) for k, v in c.params.items()}
        if c.bus is not None:
            if buses is None or c.bus not in buses:
                raise BadParameterError(f"{c.name}.bus", c.bus, "an opened bus (open_rig)")
            bus = resolved.buses[c.bus]
            device_spec = SimulatedDevice(
                c.name, c.driver, c.device, dict(c.params), _rig_dir(resolved.spec)
            )
            params.update(bus.kind.device_arguments(buses[c.bus], bus.options, device_spec))
        try:
            device = cls(**params)
        except TypeError as exc:
            error = BadParameterError(
                f"{c.name}.params", dict(c.params), f"the arguments of {cls.__name__} ({exc})"
            )
            raise _located(error, c, "") from None
        hal_id = None
        if c.hal_id is not None:
            info = device.info
            hal_id = HALId(
                int(c.hal_id.get("device_kind_id", int(info.kind))),
                int(c.hal_id.get("vendor_id", info.vendor_id)),
                int(c.hal_id.get("product_id", info.product_id)),
                int(c.hal_id.get("instance_id", len(built) + 1)),
            )
        # The HAL4RT class of the device: a Motor for motor devices (a SensingMotor for one
        # with a sensor of its own), the kind's Sensor class (Encoder, GyroSensor,
        # GPSSensor...) for sensors, so that the surface serves their HAL4RT operations.
        try:
            component_cls = component_class(device)
        except BadParameterError:
            raise BadParameterError(
                f"{c.name}.device", c.device, "an actuator or sensor device class"
            ) from None
        built[c.name] = component_cls(
            device, hal_id=hal_id, device_name=c.name, clock=clock, auto_init=auto_init
        )
    return list(built.values())


def _resolve(spec: ComponentSpec, key: str, value: Any, built: Mapping[str, HALComponent]) -> Any:
    if isinstance(value, Mapping) and set(value) == {"ref"}:
        target = built.get(value["ref"])
        if target is None:
            error = BadParameterError(
                f"{spec.name}.params.{key}",
                value,
                f"a reference to an earlier component among {sorted(built)}",
            )
            raise _located(error, spec, key)
        return target.device
    return value
