"""Rig files: the components a host serves, described the same way for every driver.

```yaml
namespace: lab            # the key-expression namespace (openel/<namespace>/...)
components:
  - name: MOTOR_1         # device name of the component
    driver: sim           # a registered driver (openel-async devices)
    device: motor         # one of its device classes
    params: {max_velocity: 3.0, max_acceleration: 40.0}
    hal_id: {vendor_id: 0xE1, product_id: 0x100, instance_id: 1}   # optional
  - name: ENCODER_1
    driver: sim
    device: encoder
    params: {motor: {ref: MOTOR_1}}   # another component's device as a parameter
```

A device becomes the component class of its kind (``device_registry.component_class``): a
``Motor`` (``SensingMotor`` for a device with its own sensor) or an ``Actuator``, a
kind's ``Sensor`` class. Every mistake is a :class:`BadParameterError` naming the
entry and what was allowed; read from a file, its text starts with ``FILE:LINE:COL:``
and it carries ``location``.  Keys are strict: an unknown key (at the top, in a
component, in ``hal_id``, or a ``params`` key the device class does not take) is refused
with a "did you mean" for near misses.
"""

from __future__ import annotations

import inspect
from collections.abc import AsyncIterator, Mapping
from contextlib import AsyncExitStack, asynccontextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgspec

from ..clock import Clock
from ..component import HALComponent
from ..device_registry import component_class
from ..errors import BadParameterError
from ..ids import HALId
from ..positioned import (
    DocumentError,
    Location,
    YamlDocument,
    convert,
    load_yaml,
    relocate,
    unknown_key_message,
)
from ..registry import discover_drivers


@dataclass(frozen=True)
class ComponentSpec:
    name: str
    driver: str
    device: str
    params: Mapping[str, Any] = field(default_factory=dict)
    hal_id: Mapping[str, int] | None = None
    locations: Mapping[str, Location] = field(default_factory=dict, compare=False, repr=False)
    """Where the entry (``""``) and each of its ``params`` keys are written, when read
    from a file (for the messages of :func:`build_components`)."""


@dataclass(frozen=True)
class RigSpec:
    namespace: str
    components: tuple[ComponentSpec, ...]


class _HalIdDoc(msgspec.Struct, forbid_unknown_fields=True):
    device_kind_id: int | None = None
    vendor_id: int | None = None
    product_id: int | None = None
    instance_id: int | None = None


class _ComponentDoc(msgspec.Struct, forbid_unknown_fields=True):
    name: str
    driver: str
    device: str
    params: dict[str, Any] | None = None
    hal_id: _HalIdDoc | None = None


class _RigDoc(msgspec.Struct, forbid_unknown_fields=True):
    components: list[_ComponentDoc]
    namespace: str = "default"


def parse_rig(data: object, source: str = "rig", doc: YamlDocument | None = None) -> RigSpec:
    """A rig from its parsed document (``doc`` gives the positions when it came from a
    file, see :func:`load_rig`); BadParameterError for any mistake."""
    located = doc is not None  # plain data (not from a file) has no positions
    if doc is None:
        doc = YamlDocument(data, source, {})

    def _located(error: BadParameterError, location: Location) -> BadParameterError:
        if not located:
            return error
        cause = DocumentError(str(error), path=error.parameter, location=location)
        return relocate(error, cause)

    if not isinstance(data, Mapping):
        raise _located(
            BadParameterError(source, data, "a mapping with 'components'"), doc.where(data)
        )
    try:
        rig = convert(doc, data, _RigDoc, source)
    except DocumentError as exc:
        error = BadParameterError(exc.path, None, exc.message)
        cause = exc if located else DocumentError(exc.message, path=exc.path)
        raise relocate(error, cause) from None
    if not rig.namespace:
        raise _located(
            BadParameterError(f"{source}.namespace", rig.namespace, "a non-empty string"),
            doc.value(data, "namespace"),
        )
    entries = data["components"]
    if not rig.components:
        raise _located(
            BadParameterError(f"{source}.components", [], "a non-empty list"),
            doc.value(data, "components"),
        )
    specs: list[ComponentSpec] = []
    for i, (entry, raw) in enumerate(zip(rig.components, entries, strict=True)):
        where = f"{source}.components[{i}]"
        for key in ("name", "driver", "device"):
            if not getattr(entry, key):
                raise _located(
                    BadParameterError(f"{where}.{key}", "", "a non-empty string"),
                    doc.value(raw, key),
                )
        hal_id = None
        if entry.hal_id is not None:
            hal_id = {
                k: v for k, v in msgspec.structs.asdict(entry.hal_id).items() if v is not None
            }
        params = entry.params or {}
        raw_params = raw.get("params") or {}
        locations = (
            {"": doc.where(raw)} | {k: doc.key(raw_params, k) for k in params} if located else {}
        )
        specs.append(
            ComponentSpec(entry.name, entry.driver, entry.device, params, hal_id, locations)
        )
    names = [s.name for s in specs]
    if len(set(names)) != len(names):
        twice = next(n for i, n in enumerate(names) if n in names[:i])
        raise _located(
            BadParameterError(f"{source}.components", names, f"unique names ({twice!r} twice)"),
            doc.value(entries[names.index(twice, names.index(twice) + 1)], "name"),
        )
    return RigSpec(rig.namespace, tuple(specs))


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
    return parse_rig(doc.data, "rig", doc)


def _device_classes() -> dict[str, Mapping[str, type]]:
    return {e.name: e.info.devices for e in discover_drivers() if e.info is not None}


def build_components(spec: RigSpec, clock: Clock | None = None) -> list[HALComponent]:
    """The components of a rig, not yet entered."""
    drivers = _device_classes()
    built: dict[str, HALComponent] = {}
    for c in spec.components:
        devices = drivers.get(c.driver)
        if devices is None:
            error = BadParameterError(f"{c.name}.driver", c.driver, f"one of {sorted(drivers)}")
            raise _at(error, c, "")
        cls = devices.get(c.device)
        if cls is None:
            error = BadParameterError(
                f"{c.name}.device", c.device, f"one of {sorted(devices)} of driver {c.driver}"
            )
            raise _at(error, c, "")
        _check_params(c, cls)
        params = {k: _resolve(c, k, v, built) for k, v in c.params.items()}
        try:
            device = cls(**params)
        except TypeError as exc:
            error = BadParameterError(
                f"{c.name}.params", dict(c.params), f"the arguments of {cls.__name__} ({exc})"
            )
            raise _at(error, c, "") from None
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
        # GPSSensor...) for sensors, so that the surface serves their HAL4RT operations
        # (SetSpeed with tmAcc, SetOrigin, units, a sensing motor's sensor operations...).
        try:
            component_cls = component_class(device)
        except BadParameterError:
            raise BadParameterError(
                f"{c.name}.device", c.device, "an actuator or sensor device class"
            ) from None
        component = component_cls(device, hal_id=hal_id, device_name=c.name, clock=clock)
        built[c.name] = component
    return list(built.values())


def _at(error: BadParameterError, spec: ComponentSpec, key: str) -> BadParameterError:
    """``error`` located at the entry (``key=""``) or its params key, when known."""
    location = spec.locations.get(key) or spec.locations.get("")
    if location is None:
        return error
    return relocate(error, DocumentError(str(error), path=error.parameter, location=location))


def _check_params(spec: ComponentSpec, cls: type) -> None:
    """Refuse a params key the device class does not take, naming the close ones."""
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
    ]
    for key in spec.params:
        if key not in allowed:
            where = f"{spec.name}.params (arguments of {cls.__name__})"
            message = unknown_key_message(key, where, allowed)
            error = BadParameterError(f"{spec.name}.params", key, f"an argument of {cls.__name__}")
            location = spec.locations.get(key) or spec.locations.get("")
            cause = DocumentError(message, path=f"{spec.name}.params")
            if location is not None:
                cause = DocumentError(cause.message, path=cause.path, location=location)
            raise relocate(error, cause)


def _resolve(spec: ComponentSpec, key: str, value: Any, built: Mapping[str, HALComponent]) -> Any:
    if isinstance(value, Mapping) and set(value) == {"ref"}:
        target = built.get(value["ref"])
        if target is None:
            error = BadParameterError(
                f"{spec.name}.params.{key}",
                value,
                f"a reference to an earlier component among {sorted(built)}",
            )
            raise _at(error, spec, key)
        return target.device
    return value


@asynccontextmanager
async def open_rig(spec: RigSpec, clock: Clock | None = None) -> AsyncIterator[list[HALComponent]]:
    """Build and enter (Init) every component; finalize them on exit."""
    components = build_components(spec, clock)
    async with AsyncExitStack() as stack:
        for component in components:
            await stack.enter_async_context(component)
        yield components
