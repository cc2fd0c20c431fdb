"""The description of a system: components (RTC profiles, contexts, configuration
sets) and the connections of their ports."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

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
    ``"<path>: <message>"``)."""

    def __init__(self, path: str, message: str) -> None:
        super().__init__(f"{path}: {message}" if path else message)
        self.path = path
        self.message = message


@dataclass(frozen=True, slots=True)
class PortRef:
    component: str
    port: str
    where: str
    """The field it came from, for error messages."""

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


@dataclass(frozen=True, slots=True)
class DataConnectionSpec:
    name: str
    source: PortRef
    target: PortRef
    properties: Mapping[str, object]
    where: str


@dataclass(frozen=True, slots=True)
class ServiceConnectionSpec:
    name: str
    a: PortRef
    b: PortRef
    where: str


@dataclass(frozen=True, slots=True)
class SystemSpec:
    name: str
    path: Path
    components: tuple[ComponentSpec, ...]
    connections: tuple[DataConnectionSpec, ...] = ()
    services: tuple[ServiceConnectionSpec, ...] = ()
