"""Execution contexts: where RT components run (spec: ExecutionContextOperations).

A context holds its participants in the order they were added and runs *cycles*:

1. for each participant in order: the mode change pending in this context, if any
   (``on_mode_changed``), then ``on_execute`` while Active or ``on_error`` in Error;
2. for each participant that executed in step 1 and is still Active: ``on_state_update``.

:class:`PeriodicExecutionContext` runs a cycle on every tick of an
:class:`~openel_async.timer.EventTimer` (rate in Hz); :class:`EventDrivenExecutionContext`
runs one when :meth:`~EventDrivenExecutionContext.trigger` is called;
:class:`ExtTrigExecutionContext` runs one per :meth:`~ExtTrigExecutionContext.tick` and
returns after it (OpenRTM-aist's ExtTrigExecutionContext, for simulators and steppers).

Concurrency. Each (component, context) pair has a lock. The cycle takes a participant's
lock around that participant's callbacks only; a lifecycle call (activate, deactivate,
reset, remove, an immediate mode change) takes only the lock of the component it is
about and runs the callback in the caller's task. So a long ``on_execute`` delays the
lifecycle calls of *that* component (bounded by ``lifecycle_timeout``), never those of
the others. Cycles run in a worker task of their own, fed by the timer through a
one-slot mailbox: a tick that comes while a cycle is still running waits in the slot
(the cycle overran), and a second one replaces it (a skipped cycle); both are counted.

This module gathers the public names of the modules that implement it:

* :mod:`openel_async.rtc.context_types`: :class:`ExecutionKind`, :class:`LifeCycleState`,
  :class:`ExecutionContextStats`;
* :mod:`openel_async.rtc.participant`: a component in a context and its lock;
* :mod:`openel_async.rtc.context_base`: :class:`ExecutionContext`, the lifecycle operations
  and the cycle;
* :mod:`openel_async.rtc.context_kinds`: the periodic, event-driven, externally triggered and
  sporadic contexts.
"""

from __future__ import annotations

from ..run_profile_args import MAX_RATE_HZ, MIN_RATE_HZ
from .context_base import DEFAULT_LIFECYCLE_TIMEOUT_S as DEFAULT_LIFECYCLE_TIMEOUT_S
from .context_base import ExecutionContext
from .context_base import S as S
from .context_kinds import (
    EventDrivenExecutionContext,
    ExtTrigExecutionContext,
    PeriodicExecutionContext,
    SporadicExecutionContext,
)
from .context_types import ExecutionContextStats, ExecutionKind, LifeCycleState

__all__ = [
    "MAX_RATE_HZ",
    "MIN_RATE_HZ",
    "EventDrivenExecutionContext",
    "ExecutionContext",
    "ExecutionContextStats",
    "ExecutionKind",
    "ExtTrigExecutionContext",
    "LifeCycleState",
    "PeriodicExecutionContext",
    "SporadicExecutionContext",
]
