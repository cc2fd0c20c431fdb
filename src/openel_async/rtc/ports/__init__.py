"""Ports of RT components: data ports (InPort/OutPort over connectors with OpenRTM's
options), service ports (provided/required interfaces) and the transport seam.

docs/rtc.md §13 describes them.
"""

from .base import Listener, PortBase
from .buffer import BufferOptions, EmptyPolicy, FullPolicy, RingBuffer
from .connector import Connector, ConnectorInfo, ConnectorStats, connect
from .dataport import DataPort, InPort, OutPort
from .datatypes import *  # noqa: F403
from .datatypes import __all__ as _datatypes_all
from .profile import ConnectorProfile, Dataflow, PushPolicy, Subscription
from .service import (
    ProvidedInterface,
    RequiredInterface,
    ServiceConnection,
    ServiceNotConnectedError,
    ServicePort,
    connect_services,
    interface_methods,
)
from .status import ListenerType, PortEvent, PortStatus
from .transport import (
    IN_PROCESS,
    InProcessTransport,
    PullSource,
    PushSink,
    Transport,
    register_transport,
    transport_for,
)

__all__ = [
    "IN_PROCESS",
    "BufferOptions",
    "Connector",
    "ConnectorInfo",
    "ConnectorProfile",
    "ConnectorStats",
    "DataPort",
    "Dataflow",
    "EmptyPolicy",
    "FullPolicy",
    "InPort",
    "InProcessTransport",
    "Listener",
    "ListenerType",
    "OutPort",
    "PortBase",
    "PortEvent",
    "PortStatus",
    "ProvidedInterface",
    "PullSource",
    "PushPolicy",
    "PushSink",
    "RequiredInterface",
    "RingBuffer",
    "ServiceConnection",
    "ServiceNotConnectedError",
    "ServicePort",
    "Subscription",
    "Transport",
    "connect",
    "connect_services",
    "interface_methods",
    "register_transport",
    "transport_for",
    *_datatypes_all,
]
