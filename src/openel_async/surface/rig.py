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

A device class that subclasses ``ActuatorDevice`` becomes an ``Actuator``, a
``SensorDevice`` a ``Sensor``. Every mistake is a :class:`BadParameterError` naming the
entry and what was allowed.
"""

from __future__ import annotations

from collections.abc import AsyncIterator, Mapping
from contextlib import AsyncExitStack, asynccontextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from ..actuator import Actuator
from ..clock import Clock
from ..component import HALComponent
from ..device import ActuatorDevice, SensorDevice
from ..errors import BadParameterError
from ..ids import DeviceKind, HALId
from ..motor import Motor
from ..registry import discover_drivers
from ..sensor_kinds import sensor_class


@dataclass(frozen=True)
class ComponentSpec:
    name: str
    driver: str
    device: str
    params: Mapping[str, Any] = field(default_factory=dict)
    hal_id: Mapping[str, int] | None = None


@dataclass(frozen=True)
class RigSpec:
    namespace: str
    components: tuple[ComponentSpec, ...]


def parse_rig(data: object, source: str = "rig") -> RigSpec:
    if not isinstance(data, Mapping):
        raise BadParameterError(source, data, "a mapping with 'components'")
    namespace = data.get("namespace", "default")
    if not isinstance(namespace, str) or not namespace:
        raise BadParameterError(f"{source}.namespace", namespace, "a non-empty string")
    entries = data.get("components")
    if not isinstance(entries, list) or not entries:
        raise BadParameterError(f"{source}.components", entries, "a non-empty list")
    specs: list[ComponentSpec] = []
    for i, entry in enumerate(entries):
        where = f"{source}.components[{i}]"
        if not isinstance(entry, Mapping):
            raise BadParameterError(where, entry, "a mapping with name, driver, device")
        unknown = set(entry) - {"name", "driver", "device", "params", "hal_id"}
        if unknown:
            raise BadParameterError(
                where, sorted(unknown), "keys among name, driver, device, params, hal_id"
            )
        for key in ("name", "driver", "device"):
            if not isinstance(entry.get(key), str) or not entry[key]:
                raise BadParameterError(f"{where}.{key}", entry.get(key), "a non-empty string")
        params = entry.get("params") or {}
        if not isinstance(params, Mapping):
            raise BadParameterError(f"{where}.params", params, "a mapping of keyword arguments")
        hal_id = entry.get("hal_id")
        if hal_id is not None and not isinstance(hal_id, Mapping):
            raise BadParameterError(
                f"{where}.hal_id", hal_id, "a mapping of vendor_id, product_id, instance_id"
            )
        specs.append(
            ComponentSpec(entry["name"], entry["driver"], entry["device"], dict(params), hal_id)
        )
    names = [s.name for s in specs]
    if len(set(names)) != len(names):
        raise BadParameterError(f"{source}.components", names, "unique names")
    return RigSpec(namespace, tuple(specs))


def load_rig(path: str | Path) -> RigSpec:
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, yaml.YAMLError) as exc:
        raise BadParameterError("rig", str(path), f"a readable YAML rig file ({exc})") from None
    return parse_rig(data, path.name)


def _device_classes() -> dict[str, Mapping[str, type]]:
    return {e.name: e.info.devices for e in discover_drivers() if e.info is not None}


def build_components(spec: RigSpec, clock: Clock | None = None) -> list[HALComponent]:
    """The components of a rig, not yet entered."""
    drivers = _device_classes()
    built: dict[str, HALComponent] = {}
    for c in spec.components:
        devices = drivers.get(c.driver)
        if devices is None:
            raise BadParameterError(f"{c.name}.driver", c.driver, f"one of {sorted(drivers)}")
        cls = devices.get(c.device)
        if cls is None:
            raise BadParameterError(
                f"{c.name}.device", c.device, f"one of {sorted(devices)} of driver {c.driver}"
            )
        params = {k: _resolve(c.name, k, v, built) for k, v in c.params.items()}
        try:
            device = cls(**params)
        except TypeError as exc:
            raise BadParameterError(
                f"{c.name}.params", dict(c.params), f"the arguments of {cls.__name__} ({exc})"
            ) from None
        hal_id = None
        if c.hal_id is not None:
            info = device.info
            hal_id = HALId(
                int(c.hal_id.get("device_kind_id", int(info.kind))),
                int(c.hal_id.get("vendor_id", info.vendor_id)),
                int(c.hal_id.get("product_id", info.product_id)),
                int(c.hal_id.get("instance_id", len(built) + 1)),
            )
        # The HAL4RT class of the device's kind: a Motor for motor devices, the kind's
        # Sensor class (Encoder, GyroSensor, GPSSensor...) for sensors, so that the surface
        # serves their HAL4RT operations (SetSpeed with tmAcc, SetOrigin, units...).
        component: HALComponent
        if isinstance(device, ActuatorDevice):
            actuator_class = Motor if int(device.info.kind) == DeviceKind.MOTOR else Actuator
            component = actuator_class(device, hal_id=hal_id, device_name=c.name, clock=clock)
        elif isinstance(device, SensorDevice):
            kind_class = sensor_class(int(device.info.kind))
            component = kind_class(device, hal_id=hal_id, device_name=c.name, clock=clock)
        else:
            raise BadParameterError(
                f"{c.name}.device", c.device, "an actuator or sensor device class"
            )
        built[c.name] = component
    return list(built.values())


def _resolve(name: str, key: str, value: Any, built: Mapping[str, HALComponent]) -> Any:
    if isinstance(value, Mapping) and set(value) == {"ref"}:
        target = built.get(value["ref"])
        if target is None:
            raise BadParameterError(
                f"{name}.params.{key}",
                value,
                f"a reference to an earlier component among {sorted(built)}",
            )
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
