"""What every port has: a name, an owner (the RTC it was added to), a clock, listeners."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from openel_async.logs import get_logger

from ...clock import Clock, default_clock
from ..errors import PreconditionNotMetError, RTCBadParameterError
from .status import ListenerType, PortEvent

if TYPE_CHECKING:
    from ..rtobject import RTObject
    from .connector import ConnectorInfo
    from .datatypes import TimedValue

__all__ = ["Listener", "PortBase"]

log = get_logger(__name__)

Listener = Callable[[PortEvent], None]
"""A port listener: called inline with each event; exceptions are logged."""


class PortBase:
    """Base of InPort, OutPort and ServicePort."""

    def __init__(self, name: str, *, clock: Clock | None = None) -> None:
        if not isinstance(name, str) or not name or any(c.isspace() for c in name) or "." in name:
            raise RTCBadParameterError("name", name, "a non-empty port name without '.' or spaces")
        self.name = name
        self.owner: RTObject | None = None
        self._clock = clock
        self._listeners: dict[ListenerType, list[Listener]] = {}
        self.has_listeners = False
        """Whether any listener is registered (connectors skip events otherwise)."""

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.full_name!r})"

    @property
    def clock(self) -> Clock:
        """The port's clock: the one given, else its owner's, else the default clock."""
        if self._clock is not None:
            return self._clock
        if self.owner is not None:
            return self.owner.clock
        self._clock = default_clock()
        return self._clock

    @property
    def full_name(self) -> str:
        """``instance.port`` as OpenRTM names ports (just ``port`` before it is added)."""
        return f"{self.owner.instance_name}.{self.name}" if self.owner is not None else self.name

    def bind(self, owner: RTObject) -> None:
        """Called by :meth:`RTObject.add_port`."""
        if self.owner is not None and self.owner is not owner:
            raise PreconditionNotMetError(
                "add_port", f"{self.name} belongs to {self.owner.instance_name}", "a free port"
            )
        self.owner = owner

    def add_listener(self, kind: ListenerType, listener: Listener) -> None:
        """Call ``listener(event)`` inline on every event of ``kind``."""
        if not isinstance(kind, ListenerType):
            raise RTCBadParameterError("kind", kind, "a ListenerType")
        if not callable(listener):
            raise RTCBadParameterError("listener", listener, "a callable taking a PortEvent")
        self._listeners.setdefault(kind, []).append(listener)
        self.has_listeners = True

    def remove_listener(self, kind: ListenerType, listener: Listener) -> None:
        entries = self._listeners.get(kind, [])
        if listener not in entries:
            raise RTCBadParameterError("listener", listener, f"a listener added for {kind.name}")
        entries.remove(listener)
        if not entries:
            del self._listeners[kind]
        self.has_listeners = bool(self._listeners)

    def notify(
        self, kind: ListenerType, connector: ConnectorInfo, data: TimedValue | None = None
    ) -> None:
        """Call the listeners of ``kind`` (cheap when there are none)."""
        entries = self._listeners.get(kind) if self.has_listeners else None
        if not entries:
            return
        event = PortEvent(kind, connector, data)
        for listener in tuple(entries):
            try:
                listener(event)
            except Exception as exc:
                log.warning(
                    "port_listener_failed", port=self.full_name, kind=kind.name, error=repr(exc)
                )
