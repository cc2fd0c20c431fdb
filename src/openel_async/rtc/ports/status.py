"""Status codes and listener kinds of data ports (OpenRTM's DataPortStatus and the
ConnectorDataListener / ConnectorListener types)."""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .connector import ConnectorInfo
    from .datatypes import TimedValue

__all__ = ["ListenerType", "PortEvent", "PortStatus"]


class PortStatus(Enum):
    """DataPortStatus of OpenRTM-aist (the subset a connector can produce)."""

    PORT_OK = "PORT_OK"
    PORT_ERROR = "PORT_ERROR"
    BUFFER_FULL = "BUFFER_FULL"
    BUFFER_EMPTY = "BUFFER_EMPTY"
    BUFFER_TIMEOUT = "BUFFER_TIMEOUT"
    SEND_FULL = "SEND_FULL"
    SEND_TIMEOUT = "SEND_TIMEOUT"
    RECV_EMPTY = "RECV_EMPTY"
    RECV_TIMEOUT = "RECV_TIMEOUT"
    PRECONDITION_NOT_MET = "PRECONDITION_NOT_MET"
    CONNECTION_LOST = "CONNECTION_LOST"

    def __str__(self) -> str:
        return self.value


class ListenerType(Enum):
    """When a port listener is called (OpenRTM's listener names)."""

    ON_BUFFER_WRITE = "ON_BUFFER_WRITE"
    """A value went into a buffer (the connector's, on either side)."""
    ON_BUFFER_FULL = "ON_BUFFER_FULL"
    """A write found the buffer full (any full policy)."""
    ON_BUFFER_WRITE_TIMEOUT = "ON_BUFFER_WRITE_TIMEOUT"
    ON_BUFFER_OVERWRITE = "ON_BUFFER_OVERWRITE"
    """The oldest unread value was dropped to make room (``data`` is the dropped one)."""
    ON_BUFFER_READ = "ON_BUFFER_READ"
    ON_SEND = "ON_SEND"
    """An OutPort's publisher hands a value to the transport."""
    ON_RECEIVED = "ON_RECEIVED"
    """An InPort's connector accepted a pushed value (data arrival)."""
    ON_RECEIVER_FULL = "ON_RECEIVER_FULL"
    ON_RECEIVER_TIMEOUT = "ON_RECEIVER_TIMEOUT"
    ON_SKIPPED = "ON_SKIPPED"
    """A NEW/PERIODIC publisher's push policy dropped a value (``data``) unsent."""
    ON_BUFFER_EMPTY = "ON_BUFFER_EMPTY"
    ON_BUFFER_READ_TIMEOUT = "ON_BUFFER_READ_TIMEOUT"
    ON_CONNECT = "ON_CONNECT"
    ON_DISCONNECT = "ON_DISCONNECT"


@dataclass(frozen=True, slots=True)
class PortEvent:
    """What a listener receives."""

    kind: ListenerType
    connector: ConnectorInfo
    data: TimedValue | None = None
