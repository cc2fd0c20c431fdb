"""Driver discovery through the ``openel_async.drivers`` entry-point group.

A driver's device classes and bus kinds may be given by where they are (``"module:Class"``,
:func:`lazy_classes`, :func:`lazy_bus_kinds`) rather than as objects: each is imported when
first looked up, so that a rig naming two of a driver's devices, or ``openel-async
devices``, does not import every module of every driver.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Collection, Iterator, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, TypeVar

from openel_async.logs import get_logger

from .entrypoints import entry_points

if TYPE_CHECKING:
    from .rig.buses import BusKind

log = get_logger(__name__)

ENTRY_POINT_GROUP = "openel_async.drivers"

V = TypeVar("V")


def _load(path: str) -> Any:
    module, _, attribute = path.partition(":")
    value: Any = importlib.import_module(module)
    for part in attribute.split("."):
        value = getattr(value, part)
    return value


class LazyMapping(Mapping[str, V]):
    """A mapping whose values are built on first lookup (then kept); its keys and the
    ``"module:attribute"`` each value comes from are known without importing anything."""

    def __init__(self, paths: Mapping[str, str], build: Callable[[Any], V]) -> None:
        self.paths = dict(paths)
        """``"module:attribute"`` by key."""
        self._build = build
        self._values: dict[str, V] = {}

    def __getitem__(self, key: str) -> V:
        value = self._values.get(key)
        if value is None:
            value = self._values[key] = self._build(_load(self.paths[key]))
        return value

    def __iter__(self) -> Iterator[str]:
        return iter(self.paths)

    def __len__(self) -> int:
        return len(self.paths)

    def path(self, key: str) -> str:
        """Where the value of ``key`` comes from, as ``module.attribute``, without loading it."""
        return self.paths[key].replace(":", ".")


def lazy_classes(paths: Mapping[str, str]) -> Mapping[str, type]:
    """A driver's device classes by name, each given as ``"module:Class"`` and imported on
    first lookup."""

    def check(value: Any) -> type:
        if not isinstance(value, type):
            raise TypeError(f"{value!r} is not a class")
        return value

    return LazyMapping(paths, check)


def lazy_bus_kinds(paths: Mapping[str, str]) -> Mapping[str, BusKind]:
    """A driver's bus kinds by type name, each given as ``"module:Factory"`` (a BusKind class
    or a function returning one), built on first lookup."""
    return LazyMapping(paths, lambda factory: factory())


def class_path(devices: Mapping[str, type], name: str) -> str:
    """``module.Class`` of device ``name``, without importing it when it is lazy."""
    if isinstance(devices, LazyMapping):
        return devices.path(name)
    cls = devices[name]
    return f"{cls.__module__}.{cls.__qualname__}"


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
