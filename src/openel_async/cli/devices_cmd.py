"""``openel-async devices --profile``: the device characteristics profiles as JSON."""

from __future__ import annotations

import json
from typing import Any

from ..device_registry import DeviceRegistry


def profiles_document() -> dict[str, Any]:
    """Every registered device's profile, keyed by ``driver.device``, and the devices the
    Device Kind ID registry refused (with the reason)."""
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
