"""The HAL4RT surface layer: message model, XML PSM, compact codec and ``Surface``."""

from .application import (
    ApplicationBase,
    ApplicationQueue,
    Completed,
    ErrorNotification,
    EventNotification,
    SurfaceNotice,
)
from .messages import ArgumentList, CommandMessage, DataType, Device, Message, Parameter, ResultList
from .profiles import DEFAULT_PROFILES, KindProfile, Operation, kind_of
from .surface import ANY_EVENT, LOGICAL_ID, Surface, SurfaceEntry

__all__ = [
    "ANY_EVENT",
    "DEFAULT_PROFILES",
    "LOGICAL_ID",
    "ApplicationBase",
    "ApplicationQueue",
    "ArgumentList",
    "CommandMessage",
    "Completed",
    "DataType",
    "Device",
    "ErrorNotification",
    "EventNotification",
    "KindProfile",
    "Message",
    "Operation",
    "Parameter",
    "ResultList",
    "Surface",
    "SurfaceEntry",
    "SurfaceNotice",
    "kind_of",
]
