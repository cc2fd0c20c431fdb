"""Identity of a component: HALId, Property, the device-kind registry and name rule."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from enum import IntEnum

from .errors import BadParameterError

_U32_MAX = 0xFFFF_FFFF

EXTENSION_KIND_IDS = range(0x7F00_0000, 0x8000_0000)
"""Device kind ids this project gives to kinds the OpenEL registry lacks (GPS): far above
the registry's ids and inside the C PSM's ``int32_t deviceKindId``."""

RESERVED_PRODUCT_IDS = frozenset({0x0000_0000, 0xFFFF_FFFF})
"""Product ids the device kind id registry refuses: 0 ("no product", the default of a
``DeviceInfo``) and 0xFFFFFFFF (all bits set, "any product")."""


class DeviceKind(IntEnum):
    """Device kind ids of the OpenEL reference implementation's registry, plus GPS from
    :data:`EXTENSION_KIND_IDS` (docs/psm.md §4.3)."""

    MOTOR = 0x1
    GYRO = 0x2
    TORQUE = 0x3
    ACCEL = 0x4
    COMPASS = 0x5
    DISTANCE = 0x6
    FORCE = 0x7
    TEMPERATURE = 0x8
    HUMIDITY = 0x9
    CO2 = 0xA
    COLOR = 0xB
    TOUCH = 0xC
    CURRENT = 0xD
    ROTARY_ANGLE = 0xE
    GPS = 0x7F00_0001
    """Not in the OpenEL registry: HAL4RT's GPS Sensor (§7.4.5.13), from the extension range."""


def check_u32(name: str, value: int) -> int:
    """``value`` if it is an int in 0..0xFFFFFFFF, else BadParameterError naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise BadParameterError(name, value, "an int")
    if not 0 <= value <= _U32_MAX:
        raise BadParameterError(name, value, "a 32-bit unsigned integer in 0..0xFFFFFFFF")
    return value


def check_product_id(product_id: object, parameter: str = "product_id") -> int:
    """A product id the device kind id registry accepts: 32-bit, not reserved."""
    value = check_u32(parameter, product_id)  # type: ignore[arg-type]
    if value in RESERVED_PRODUCT_IDS:
        raise BadParameterError(
            parameter,
            product_id,
            "a product id in 0x00000001..0xFFFFFFFE (0 and 0xFFFFFFFF are reserved)",
        )
    return value


def check_vendor_name(vendor_name: object) -> str:
    """HAL4RT's vendor-name rule: 2 to 16 characters beginning with an uppercase letter."""
    if not isinstance(vendor_name, str) or not _VENDOR_NAME.fullmatch(vendor_name):
        raise BadParameterError(
            "vendor_name",
            vendor_name,
            "2 to 16 letters, digits or '_' beginning with an uppercase letter",
        )
    return vendor_name


def profile_name(kind_id: int) -> str:
    """The profile name of a device kind id in component names: ``MOTOR`` -> ``Motor``,
    ``ROTARY_ANGLE`` -> ``RotaryAngle``; ``Kind<id>`` (decimal) outside the registry."""
    try:
        kind = DeviceKind(kind_id)
    except ValueError:
        return f"Kind{kind_id}"
    return kind.name.title().replace("_", "")


@dataclass(frozen=True, slots=True)
class HALId:
    """HALId: deviceKindId, vendorId, productId, instanceId (each a 32-bit unsigned)."""

    device_kind_id: int
    vendor_id: int
    product_id: int
    instance_id: int

    def __post_init__(self) -> None:
        for name in ("device_kind_id", "vendor_id", "product_id", "instance_id"):
            check_u32(name, getattr(self, name))

    @property
    def device_kind(self) -> DeviceKind | None:
        """The registered kind, or None for a kind outside the registry."""
        try:
            return DeviceKind(self.device_kind_id)
        except ValueError:
            return None

    def __str__(self) -> str:
        return (
            f"HALId(kind=0x{self.device_kind_id:X}, vendor=0x{self.vendor_id:X}, "
            f"product=0x{self.product_id:X}, instance={self.instance_id})"
        )


@dataclass(frozen=True, slots=True)
class Property:
    """Property: the component's id, device name and the functions it implements."""

    id: HALId
    device_name: str
    function_list: tuple[str, ...] = field(default_factory=tuple)

    def __post_init__(self) -> None:
        if not isinstance(self.device_name, str) or not self.device_name:
            raise BadParameterError("device_name", self.device_name, "a non-empty string")
        if not all(isinstance(f, str) and f for f in self.function_list):
            raise BadParameterError(
                "function_list", self.function_list, "a sequence of non-empty strings"
            )


_VENDOR_NAME = re.compile(r"[A-Z][A-Za-z0-9_]{1,15}")
_NAME_PART = re.compile(r"[A-Za-z][A-Za-z0-9_]*")


def component_name(profile_name: str, vendor_name: str, product_name: str) -> str:
    """HAL4RT's component name rule: ``Hal + Profile name + Vendor Name + Product Name``.

    The vendor name is a 2 to 16 character string beginning with an uppercase letter.
    """
    check_vendor_name(vendor_name)
    for name, part in (("profile_name", profile_name), ("product_name", product_name)):
        if not _NAME_PART.fullmatch(part):
            raise BadParameterError(name, part, "an identifier beginning with a letter")
    return f"Hal{profile_name[:1].upper()}{profile_name[1:]}{vendor_name}{product_name}"
