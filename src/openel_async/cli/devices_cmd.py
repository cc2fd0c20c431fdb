"""``openel-async devices --profile``: the device characteristics profiles as JSON."""

from __future__ import annotations

import json
from typing import Any


def profiles_document() -> dict[str, Any]:
    """Every registered device's profile, keyed by ``driver.device``, and the devices the
    Device Kind ID registry refused (with the reason)."""
    from ..device_registry import DeviceRegistry
    from ..registry import discover_drivers

    entries = discover_drivers()
    registry = DeviceRegistry.from_drivers(entries)
    registered = {entry.device_class: entry for entry in registry}
    devices: dict[str, Any] = {}
    for driver in entries:
        if driver.info is None:
            continue
        for name, device_class in driver.info.devices.items():
            entry = registered.get(device_class)
            if entry is not None:
                devices[f"{driver.name}.{name}"] = entry.profile.to_dict()
    return {
        "devices": devices,
        "not_registered": {label: reason for label, reason in registry.skipped},
    }


def print_profiles() -> int:
    print(json.dumps(profiles_document(), indent=2))
    return 0


def print_devices() -> int:
    """``openel-async devices``: each driver, its description, and its devices with the class
    that implements each; a driver that cannot load says why."""
    import textwrap

    from ..registry import class_path, discover_drivers

    entries = discover_drivers()
    name_width = max((len(e.name) for e in entries), default=0) + 2
    for entry in entries:
        if entry.info is None:
            print(f"{entry.name:{name_width}}unavailable ({entry.value}): {entry.error}")
            continue
        print(
            textwrap.fill(
                entry.info.description,
                width=100,
                initial_indent=f"{entry.name:{name_width}}",
                subsequent_indent=" " * name_width,
            )
        )
        width = max((len(name) for name in entry.info.devices), default=0) + 2
        for device_name in entry.info.devices:
            print(f"  {device_name:{width}}{class_path(entry.info.devices, device_name)}")
    return 0
