"""Driver discovery through the ``openel_async.drivers`` entry-point group."""

from __future__ import annotations

from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from importlib.metadata import entry_points
from typing import TYPE_CHECKING

from openel_async.logs import get_logger

if TYPE_CHECKING:
    from .rig.buses import BusKind

log = get_logger(__name__)

ENTRY_POINT_GROUP = "openel_async.drivers"


@dataclass(frozen=True)
class DriverInfo:
    """What a driver package registers: a name, a description, its device classes and the
    kinds of bus a rig file can name (``buses: {can0: {type: can, ...}}``, see
    :class:`openel_async.rig.BusKind`)."""

    name: str
    description: str
    devices: Mapping[str, type] = field(default_factory=dict)
    buses: Mapping[str, BusKind] = field(default_factory=dict)


@dataclass(frozen=True)
class DriverEntry:
    name: str
    value: str
    info: DriverInfo | None
    error: str | None = None


def discover_drivers(names: Collection[str] | None = None) -> list[DriverEntry]:
    """Load every registered driver (``names``: only those of these names, so that a rig
    that uses two drivers does not import the others); a driver that fails to import is
    reported, not raised."""
    found: list[DriverEntry] = []
    for ep in sorted(entry_points(group=ENTRY_POINT_GROUP), key=lambda e: e.name):
        if names is not None and ep.name not in names:
            continue
        try:
            info = ep.load()
        except Exception as exc:  # a broken optional driver must not hide the others
            log.warning("driver_load_failed", driver=ep.name, error=repr(exc))
            found.append(DriverEntry(ep.name, ep.value, None, f"{type(exc).__name__}: {exc}"))
            continue
        if not isinstance(info, DriverInfo):
            found.append(DriverEntry(ep.name, ep.value, None, "entry point is not a DriverInfo"))
            continue
        found.append(DriverEntry(ep.name, ep.value, info))
    return found
