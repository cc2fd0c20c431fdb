"""RTC component model: RTObject lifecycle, execution contexts, modes, profile apps.

- :mod:`.rtobject`: :class:`RTObject` (LightweightRTObject + ComponentAction +
  DataFlowComponentAction), :class:`MultiModeObject` in :mod:`.modes`;
- :mod:`.context`: :class:`PeriodicExecutionContext`, :class:`EventDrivenExecutionContext`,
  :class:`ExtTrigExecutionContext`, :class:`SporadicExecutionContext`;
- :mod:`.errors`: ``ReturnCode_t`` and the exceptions carrying it;
- :mod:`.profile`, :mod:`.constraints`, :mod:`.configuration`: RTC Profiles and
  configuration sets; :mod:`.runner`: running a component described by a profile;
- :mod:`.ports`: data ports, connectors, service ports, the transport seam;
- :mod:`.system`: systems of components (system files, ``openel-async run SYSTEM``);
- :mod:`.composite`: composite components.

docs/rtc.md maps the RTC PIM to this API.
"""

from .composite import CompositeRTObject, composite_of
from .context import (
    EventDrivenExecutionContext,
    ExecutionContext,
    ExecutionContextStats,
    ExecutionKind,
    ExtTrigExecutionContext,
    LifeCycleState,
    PeriodicExecutionContext,
    SporadicExecutionContext,
)
from .errors import (
    CallbackFailedError,
    OutOfResourcesError,
    PreconditionNotMetError,
    ReturnCode_t,
    RTCBadParameterError,
    RTCError,
    RTCTimeoutError,
    UnsupportedError,
    check_return_code,
)
from .modes import MultiModeObject
from .rtobject import ECOTHER_OFFSET, CallbackResult, ObjectState, RTObject

__all__ = [
    "ECOTHER_OFFSET",
    "CallbackFailedError",
    "CallbackResult",
    "CompositeRTObject",
    "EventDrivenExecutionContext",
    "ExecutionContext",
    "ExecutionContextStats",
    "ExecutionKind",
    "ExtTrigExecutionContext",
    "LifeCycleState",
    "MultiModeObject",
    "ObjectState",
    "OutOfResourcesError",
    "PeriodicExecutionContext",
    "PreconditionNotMetError",
    "RTCBadParameterError",
    "RTCError",
    "RTCTimeoutError",
    "RTObject",
    "ReturnCode_t",
    "SporadicExecutionContext",
    "UnsupportedError",
    "check_return_code",
    "composite_of",
]
