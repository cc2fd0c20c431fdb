"""The description of a system: components (RTC profiles, contexts, configuration
sets) and the connections of their ports."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from ...positioned import DocumentError, Location, relocate

__all__ = [
    "ComponentSpec",
    "ContextSpec",
    "DataConnectionSpec",
    "PortRef",
    "ServiceConnectionSpec",
    "SystemFileError",
    "SystemSpec",
]


class SystemFileError(ValueError):
    """A system file that cannot be run; ``path`` names the field (``str(e)`` is
    ``"<path>: <message>"``, or ``"FILE:LINE:COL: <path>: <message>"`` when the place
    is known: then ``location``, ``source``, ``line`` and ``column`` say where)."""

    location: Location | None = None
    source: str | None = None
    line: int | None = None
    column: int | None = None

    def __init__(self, path: str, message: str) -> None:
        super().__init__(f"{path}: {message}" if path else message)
        self.path = path
        self.message = message

    def at(self, location: Location | None) -> SystemFileError:
        """This error located at ``location`` (unchanged when None, or already located)."""
        if location is None or self.location is not None:
            return self
        return relocate(self, DocumentError(str(self), path=self.path, location=location))


@dataclass(frozen=True, slots=True)
class PortRef:
    component: str
    port: str
    where: str
    """The field it came from, for error messages."""
    location: Location | None = None
    """Where it is written (file, line, column), when the loader knows."""

    def __str__(self) -> str:
        return f"{self.component}.{self.port}"


@dataclass(frozen=True, slots=True)
class ContextSpec:
    """Overrides of the context the profile asks for."""

    type: str | None = None
    """``periodic``, ``event_driven`` or ``sporadic`` (None: the profile's)."""
    rate_hz: float | None = None
    """Rate of a periodic context, highest rate of a sporadic one."""


@dataclass(frozen=True, slots=True)
class ComponentSpec:
    name: str
    profile: Path
    where: str
    context: ContextSpec = ContextSpec()
    configuration_sets: Mapping[str, Mapping[str, str]] = field(default_factory=dict)
    active_set: str | None = None
    location: Location | None = None
    """Where the component is written (file, line, column), when the loader knows."""


@dataclass(frozen=True, slots=True)
class DataConnectionSpec:
    name: str
    source: PortRef
    target: PortRef
    properties: Mapping[str, object]
    where: str
    location: Location | None = None
    """Where the connection is written (file, line, column), when the loader knows."""


@dataclass(frozen=True, slots=True)
class ServiceConnectionSpec:
    name: str
    a: PortRef
    b: PortRef
    where: str
    location: Location | None = None
    """Where the connection is written (file, line, column), when the loader knows."""


@dataclass(frozen=True, slots=True)
class SystemSpec:
    name: str
    path: Path
    components: tuple[ComponentSpec, ...]
    connections: tuple[DataConnectionSpec, ...] = ()
    services: tuple[ServiceConnectionSpec, ...] = ()
