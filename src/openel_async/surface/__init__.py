"""The HAL4RT surface layer: message model, XML PSM, compact codec and ``Surface``."""

from typing import TYPE_CHECKING

from ..lazy import lazy_exports

if TYPE_CHECKING:
    from .application import (
        ApplicationBase,
        ApplicationQueue,
        Completed,
        ErrorNotification,
        EventNotification,
        SurfaceNotice,
    )
    from .messages import (
        ArgumentList,
        CommandMessage,
        DataType,
        Device,
        Message,
        Parameter,
        ResultList,
    )
    from .profiles import DEFAULT_PROFILES, KindProfile, Operation, kind_of
    from .surface import ANY_EVENT, LOGICAL_ID, Surface, SurfaceEntry

# Each name loads its module on first use (a command line's parser imports this package's light modules only).
_LAZY = {
    "ApplicationBase": "application",
    "ApplicationQueue": "application",
    "Completed": "application",
    "ErrorNotification": "application",
    "EventNotification": "application",
    "SurfaceNotice": "application",
    "ArgumentList": "messages",
    "CommandMessage": "messages",
    "DataType": "messages",
    "Device": "messages",
    "Message": "messages",
    "Parameter": "messages",
    "ResultList": "messages",
    "DEFAULT_PROFILES": "profiles",
    "KindProfile": "profiles",
    "Operation": "profiles",
    "kind_of": "profiles",
    "ANY_EVENT": "surface",
    "LOGICAL_ID": "surface",
    "Surface": "surface",
    "SurfaceEntry": "surface",
}

__getattr__, __dir__ = lazy_exports(__name__, _LAZY)

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
