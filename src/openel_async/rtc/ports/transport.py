"""The transport seam of data connectors.

A connector is two halves joined by a link: on PUSH connectors the OutPort's publisher
sends values to the InPort's :class:`PushSink`; on PULL connectors the InPort asks the
OutPort's :class:`PullSource`. A :class:`Transport` makes the link: in-process it is the
other half itself; a network transport (e.g. Zenoh: the OutPort side puts encoded values
on a key, the InPort side subscribes and calls the sink) implements the same protocol.
Values are :mod:`msgspec` Structs (``msgspec.msgpack.encode(value)`` /
``decode(raw, type=data_type)``), and :attr:`ConnectorInfo.key` is a stable name for
the connection. Links are async context managers: entering opens what the link needs,
leaving closes it.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import AbstractAsyncContextManager, asynccontextmanager
from typing import TYPE_CHECKING, Protocol

from ..errors import RTCBadParameterError
from .status import PortStatus

if TYPE_CHECKING:
    from .connector import ConnectorInfo
    from .datatypes import TimedValue

__all__ = [
    "IN_PROCESS",
    "InProcessTransport",
    "PullSource",
    "PushSink",
    "Transport",
    "register_transport",
    "transport_for",
]


class PushSink(Protocol):
    """The InPort half of a PUSH connector."""

    async def put(self, data: TimedValue) -> PortStatus:
        """Deliver one value: PORT_OK, or why it was not stored (BUFFER_FULL,
        BUFFER_TIMEOUT, CONNECTION_LOST...)."""
        ...


class PullSource(Protocol):
    """The OutPort half of a PULL connector."""

    async def get(self) -> tuple[PortStatus, TimedValue | None, bool]:
        """The next value: (status, value or None, whether the value is unread)."""
        ...

    def readable(self) -> int:
        """Unread values waiting (0 when unknown)."""
        ...


class Transport(Protocol):
    """Makes the links of connectors whose ``interface_type`` names it."""

    name: str

    def push_link(
        self, info: ConnectorInfo, sink: PushSink
    ) -> AbstractAsyncContextManager[PushSink]:
        """A sink the OutPort side calls, delivering to ``sink`` on the InPort side."""
        ...

    def pull_link(
        self, info: ConnectorInfo, source: PullSource
    ) -> AbstractAsyncContextManager[PullSource]:
        """A source the InPort side calls, reading from ``source`` on the OutPort side."""
        ...


class InProcessTransport:
    """Both halves in this process: the link is the other half itself (no copy)."""

    name = "inprocess"

    @asynccontextmanager
    async def push_link(self, info: ConnectorInfo, sink: PushSink) -> AsyncIterator[PushSink]:
        yield sink

    @asynccontextmanager
    async def pull_link(self, info: ConnectorInfo, source: PullSource) -> AsyncIterator[PullSource]:
        yield source


IN_PROCESS = InProcessTransport()

_TRANSPORTS: dict[str, Transport] = {}
_ALIASES = ("inprocess", "direct", "corba_cdr", "data_service", "shared_memory")
"""``interface_type`` values served in-process: OpenRTM's own names for its transports
(what RTSystemEditor writes) mean "the usual transport", which between components of
one process is a direct call."""


def register_transport(transport: Transport, *names: str) -> None:
    """Make ``transport`` serve the ``interface_type`` ``names`` (its own name too)."""
    for name in (transport.name, *names):
        _TRANSPORTS[name.lower()] = transport


def transport_for(interface_type: str) -> Transport:
    """The transport of an ``interface_type`` (BAD_PARAMETER naming the known ones)."""
    found = _TRANSPORTS.get(interface_type.strip().lower())
    if found is None:
        raise RTCBadParameterError(
            "dataport.interface_type", interface_type, "one of " + ", ".join(sorted(_TRANSPORTS))
        )
    return found


register_transport(IN_PROCESS, *_ALIASES)
