"""The Device Kind ID registry (HAL4RT §7.4.5.1): (device kind, vendor id, product id) ->
the driver's device class, and creation of a component from a HALId, as OpenEL's
HalCreate does.

``DeviceRegistry.from_drivers()`` fills a registry from every installed driver's
``DriverInfo.devices``; ``create(hal_id, **device_args)`` builds the device and wraps it in
the component class of its kind (``Motor`` for a motor, the HAL4RT Sensor class of a sensor
kind, else ``Actuator``/``Sensor``) with that HALId, not yet entered.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

from openel_async.logs import get_logger

from .actuator import Actuator
from .component import HALComponent
from .device import ActuatorDevice, Device, SensorDevice
from .device_profile import DeviceProfile, profile_of
from .errors import BadParameterError, NotImplementedHALError
from .ids import DeviceKind, HALId, check_product_id, check_u32, check_vendor_name
from .motor import Motor
from .registry import DriverEntry, discover_drivers
from .sensing import SensingActuatorDevice, SensingMotor
from .sensor_kinds import sensor_class

log = get_logger(__name__)

Key = tuple[int, int, int]


@dataclass(frozen=True)
class RegistryEntry:
    """One registered device: its key, class and profile, and the driver that gave it."""

    key: Key
    device_class: type[Device]
    driver: str
    profile: DeviceProfile

    @property
    def kind_id(self) -> int:
        return self.key[0]


class DeviceRegistry:
    """Device classes keyed by (device kind id, vendor id, product id)."""

    def __init__(self) -> None:
        self._entries: dict[Key, RegistryEntry] = {}
        self.skipped: list[tuple[str, str]] = []
        """(device, reason) of the devices :meth:`from_drivers` could not register."""

    def __len__(self) -> int:
        return len(self._entries)

    def __iter__(self) -> Iterator[RegistryEntry]:
        return iter(sorted(self._entries.values(), key=lambda e: e.key))

    def register(self, device_class: type[Device], *, driver: str = "") -> RegistryEntry:
        """Register a device class under its ``info`` (kind, vendor id, product id).

        Refused (BadParameterError): not a Device class, a reserved product id (0,
        0xFFFFFFFF), a vendor name breaking HAL4RT's rule, a key already registered.
        """
        if not (isinstance(device_class, type) and issubclass(device_class, Device)):
            raise BadParameterError("device_class", device_class, "a Device subclass")
        info = device_class.info
        kind = check_u32("kind", int(info.kind))
        vendor = check_u32("vendor_id", info.vendor_id)
        product = check_product_id(info.product_id)
        check_vendor_name(info.vendor_name)
        key = (kind, vendor, product)
        existing = self._entries.get(key)
        if existing is not None:
            raise BadParameterError(
                "device_class",
                device_class,
                f"a key not yet registered: {_key_text(key)} is "
                f"{existing.device_class.__qualname__} of driver {existing.driver!r}",
            )
        entry = RegistryEntry(key, device_class, driver, profile_of(device_class))
        self._entries[key] = entry
        return entry

    def lookup(self, kind: int, vendor_id: int, product_id: int) -> RegistryEntry:
        """The entry of a key; NotImplementedHALError when nothing is registered there."""
        key = (int(kind), int(vendor_id), int(product_id))
        entry = self._entries.get(key)
        if entry is None:
            raise NotImplementedHALError(f"no device registered for {_key_text(key)}")
        return entry

    def create_device(self, hal_id: HALId, *args: Any, **kwargs: Any) -> Device:
        """The device of ``hal_id``'s key, built with the given constructor arguments."""
        if not isinstance(hal_id, HALId):
            raise BadParameterError("hal_id", hal_id, "a HALId")
        check_product_id(hal_id.product_id, "hal_id.product_id")
        entry = self.lookup(hal_id.device_kind_id, hal_id.vendor_id, hal_id.product_id)
        return entry.device_class(*args, **kwargs)

    def create(self, hal_id: HALId, *args: Any, **kwargs: Any) -> HALComponent:
        """HalCreate: the component for ``hal_id`` (its device built with the arguments),
        with that HALId, registered in its profile's instance register; enter it with
        ``async with``. Component options (``clock``, ``auto_init``...) go in
        ``component_options``."""
        options: dict[str, Any] = kwargs.pop("component_options", {}) or {}
        device = self.create_device(hal_id, *args, **kwargs)
        factory = component_class(device)
        component: HALComponent = factory(device, hal_id=hal_id, **options)
        entry = self.lookup(hal_id.device_kind_id, hal_id.vendor_id, hal_id.product_id)
        entry.profile.register_instance(component)  # the profile's instance register
        return component

    @classmethod
    def from_drivers(cls, entries: Sequence[DriverEntry] | None = None) -> DeviceRegistry:
        """A registry of every device class of the installed drivers; those that cannot
        be registered (reserved product id, duplicate key...) are listed in ``skipped``."""
        registry = cls()
        for entry in discover_drivers() if entries is None else entries:
            if entry.info is None:
                continue
            for name, device_class in entry.info.devices.items():
                label = f"{entry.name}.{name}"
                try:
                    registry.register(device_class, driver=entry.name)
                except Exception as exc:  # one bad declaration must not hide the others
                    registry.skipped.append((label, str(exc)))
                    log.debug("device_not_registered", device=label, reason=str(exc))
        return registry


def component_class(device: Device) -> Callable[..., HALComponent]:
    """The component class for a device: Motor, a HAL4RT sensor class, Actuator or Sensor."""
    kind = int(device.info.kind)
    if isinstance(device, SensingActuatorDevice):
        return SensingMotor
    if isinstance(device, ActuatorDevice):
        return Motor if kind == DeviceKind.MOTOR else Actuator
    if isinstance(device, SensorDevice):
        return sensor_class(kind)
    raise BadParameterError("device", device, "an ActuatorDevice or a SensorDevice")


def _key_text(key: Key) -> str:
    return f"(kind 0x{key[0]:X}, vendor 0x{key[1]:X}, product 0x{key[2]:X})"
