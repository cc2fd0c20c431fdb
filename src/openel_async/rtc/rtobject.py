"""RTObject: the LightweightRTObject of the RTC spec with its ComponentAction and
DataFlowComponentAction callbacks.

An RTC is Created, becomes Alive with :meth:`RTObject.initialize` and ends Finalized.
While Alive it participates in execution contexts; its Inactive/Active/Error state is
held per context by the context (:meth:`ExecutionContext.get_component_state`).
Callbacks are ``async`` methods to override; each may return a :class:`ReturnCode_t`
(None means RTC_OK) or raise, and anything other than RTC_OK is a failure.
"""

from __future__ import annotations

import itertools
from enum import Enum
from typing import TYPE_CHECKING, TypeVar

import anyio

from openel_async.logs import get_logger

from ..clock import Clock, default_clock
from ._callbacks import Outcome, invoke
from .configuration import Configuration
from .errors import (
    CallbackFailedError,
    PreconditionNotMetError,
    ReturnCode_t,
    RTCBadParameterError,
    RTCError,
)

if TYPE_CHECKING:
    from .context import ExecutionContext
    from .ports.base import PortBase

P = TypeVar("P", bound="PortBase")

__all__ = ["ECOTHER_OFFSET", "CallbackResult", "ObjectState", "RTObject"]

log = get_logger(__name__)

ECOTHER_OFFSET = 1000
"""Handles of contexts the RTC does not own start here (owned ones start at 0), as in
OpenRTM-aist, so ``0`` is the handle of a component's own first context."""

CallbackResult = ReturnCode_t | None
"""What a callback returns: a return code, or None for RTC_OK."""

_instances = itertools.count(1)


class ObjectState(Enum):
    """The RTC's own lifecycle (spec Figure 5.9): Created -> Alive -> Finalized."""

    CREATED = "Created"
    ALIVE = "Alive"
    FINALIZED = "Finalized"

    def __str__(self) -> str:
        return self.value


class RTObject:
    """A data flow RT component: override the ``on_*`` callbacks you need.

    ``configuration`` holds the component's configuration sets (empty by default; the
    profile runner builds it from the RTC Profile); ``clock`` is the time source its
    HAL components and computations should use (the runner passes the context's).
    """

    def __init__(
        self,
        instance_name: str = "",
        *,
        configuration: Configuration | None = None,
        clock: Clock | None = None,
    ) -> None:
        if not isinstance(instance_name, str):
            raise RTCBadParameterError("instance_name", instance_name, "a string")
        if configuration is not None and not isinstance(configuration, Configuration):
            raise RTCBadParameterError("configuration", configuration, "a Configuration or None")
        self.instance_name = instance_name or f"{type(self).__name__}{next(_instances)}"
        self.configuration = configuration if configuration is not None else Configuration([])
        self.clock: Clock = clock or default_clock()
        self._state = ObjectState.CREATED
        self._owned: list[ExecutionContext] = []
        self._handles: dict[int, ExecutionContext] = {}
        self._next_owned = 0
        self._next_other = ECOTHER_OFFSET
        self._lifecycle_lock = anyio.Lock()
        self._ports: dict[str, PortBase] = {}
        self.log = log.bind(rtc=self.instance_name)

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.instance_name!r}, {self._state})"

    @property
    def state(self) -> ObjectState:
        """Created, Alive or Finalized."""
        return self._state

    # -- LightweightRTObject: lifecycle ------------------------------------------------
    async def initialize(self) -> None:
        """Created -> Alive, running on_initialize.

        Raises PreconditionNotMetError unless Created; CallbackFailedError when
        on_initialize fails (the RTC then stays Created and may be initialized again).
        """
        async with self._lifecycle_lock:
            if self._state is not ObjectState.CREATED:
                raise PreconditionNotMetError("initialize", self._state, [ObjectState.CREATED])
            outcome = await invoke("on_initialize", self.on_initialize)
            if not outcome.ok:
                self._failed("on_initialize", outcome)
                raise CallbackFailedError(
                    self.instance_name, "on_initialize", outcome.code
                ) from outcome.error
            self._state = ObjectState.ALIVE
            self.log.info("rtc_initialized")

    async def finalize(self) -> None:
        """Alive -> Finalized, running on_finalize.

        Raises PreconditionNotMetError when Created or Finalized, or while the RTC still
        participates in a context (remove it first). When on_finalize fails the RTC is
        finalized all the same and CallbackFailedError reports the failure.
        """
        async with self._lifecycle_lock:
            await self._finalize()

    async def _finalize(self) -> None:
        if self._state is not ObjectState.ALIVE:
            raise PreconditionNotMetError("finalize", self._state, [ObjectState.ALIVE])
        if self._handles:
            names = ", ".join(ec.name for ec in self._handles.values())
            raise PreconditionNotMetError(
                "finalize",
                f"{self._state} (participating in {names})",
                "after remove_component from every context",
            )
        outcome = await invoke("on_finalize", self.on_finalize)
        self._state = ObjectState.FINALIZED
        self.log.info("rtc_finalized")
        if not outcome.ok:
            self._failed("on_finalize", outcome)
            raise CallbackFailedError(
                self.instance_name, "on_finalize", outcome.code
            ) from outcome.error

    async def exit(self) -> None:
        """Stop the contexts this RTC owns, deactivate it and leave every context it
        participates in, then finalize it (spec: LightweightRTObject::exit).

        Raises PreconditionNotMetError unless Alive. Failures of on_shutdown or
        on_deactivated are logged (the component goes on leaving its contexts); a
        failing on_finalize raises CallbackFailedError after the RTC was finalized.
        """
        async with self._lifecycle_lock:
            if self._state is not ObjectState.ALIVE:
                raise PreconditionNotMetError("exit", self._state, [ObjectState.ALIVE])
            from .context import LifeCycleState

            for ec in tuple(self._owned):
                if ec.is_running():
                    try:
                        await ec.stop()
                    except RTCError as exc:
                        self.log.warning("exit_stop_failed", ec=ec.name, error=str(exc))
            for ec in tuple(self._handles.values()):
                if ec.get_component_state(self) is LifeCycleState.ACTIVE:
                    try:
                        await ec.deactivate_component(self)
                    except CallbackFailedError as exc:
                        self.log.warning("exit_deactivate_failed", ec=ec.name, error=str(exc))
                await ec.remove_component(self)
            await self._finalize()
            self.log.info("rtc_exited")

    def is_alive(self, exec_context: ExecutionContext) -> bool:
        """True when the RTC is Alive and Inactive, Active or in Error in ``exec_context``
        (that is, it participates in it)."""
        return self._state is ObjectState.ALIVE and any(
            ec is exec_context for ec in self._handles.values()
        )

    # -- LightweightRTObject: contexts -------------------------------------------------
    def attach_context(self, exec_context: ExecutionContext) -> int:
        """Record participation in ``exec_context`` and return its handle.

        Called by :meth:`ExecutionContext.add_component`; calling it directly does not
        make the context run the component.
        """
        from .context import ExecutionContext

        if not isinstance(exec_context, ExecutionContext):
            raise RTCBadParameterError("exec_context", exec_context, "an ExecutionContext")
        if self._state is not ObjectState.ALIVE:
            raise PreconditionNotMetError("attach_context", self._state, [ObjectState.ALIVE])
        if any(ec is exec_context for ec in self._handles.values()):
            raise PreconditionNotMetError(
                "attach_context", f"attached to {exec_context.name}", "a context not yet attached"
            )
        if exec_context.owner is self:
            handle, self._next_owned = self._next_owned, self._next_owned + 1
        else:
            handle, self._next_other = self._next_other, self._next_other + 1
        self._handles[handle] = exec_context
        self._context_attached(exec_context)
        self.log.debug("context_attached", ec=exec_context.name, handle=handle)
        return handle

    def detach_context(self, exec_handle: int) -> None:
        """End participation in the context of ``exec_handle``.

        Raises PreconditionNotMetError when the handle is not one of a context the RTC
        participates in, or while the RTC is Active in that context.
        """
        if isinstance(exec_handle, bool) or not isinstance(exec_handle, int):
            raise RTCBadParameterError("exec_handle", exec_handle, "an int handle")
        ec = self._handles.get(exec_handle)
        if ec is None:
            raise PreconditionNotMetError(
                "detach_context",
                f"not participating in a context with handle {exec_handle}",
                "a handle returned by attach_context",
            )
        from .context import LifeCycleState

        state = ec._state_of(self)
        if state is LifeCycleState.ACTIVE:
            raise PreconditionNotMetError(
                "detach_context", state, [LifeCycleState.INACTIVE, LifeCycleState.ERROR]
            )
        del self._handles[exec_handle]
        self._context_detached(ec)
        ec._forget(self)
        self.log.debug("context_detached", ec=ec.name, handle=exec_handle)

    def get_context(self, exec_handle: int) -> ExecutionContext:
        """The context of a handle returned by attach_context (BAD_PARAMETER otherwise)."""
        ec = (
            None
            if isinstance(exec_handle, bool) or not isinstance(exec_handle, int)
            else self._handles.get(exec_handle)
        )
        if ec is None:
            raise RTCBadParameterError(
                "exec_handle", exec_handle, f"one of {sorted(self._handles)}"
            )
        return ec

    def get_owned_contexts(self) -> tuple[ExecutionContext, ...]:
        """Contexts created with this RTC as their owner."""
        return tuple(self._owned)

    def get_participating_contexts(self) -> tuple[ExecutionContext, ...]:
        """Contexts this RTC participates in, in the order it joined them."""
        return tuple(self._handles.values())

    def get_context_handle(self, cxt: ExecutionContext) -> int:
        """The handle of a context this RTC participates in (BAD_PARAMETER otherwise)."""
        for handle, ec in self._handles.items():
            if ec is cxt:
                return handle
        raise RTCBadParameterError("cxt", cxt, "a context this RTC participates in")

    # -- ports (PortService) ---------------------------------------------------------------
    def add_port(self, port: P) -> P:
        """Add a data or service port (names are unique within the RTC); returns it.

        The port takes this RTC's clock unless it was given one; its full name becomes
        ``instance_name.port``."""
        from .ports.base import PortBase

        if not isinstance(port, PortBase):
            raise RTCBadParameterError("port", port, "an InPort, OutPort or ServicePort")
        existing = self._ports.get(port.name)
        if existing is not None and existing is not port:
            raise RTCBadParameterError(
                "port", port.name, f"a port name not yet used by {self.instance_name}"
            )
        port.bind(self)
        self._ports[port.name] = port
        return port

    def get_port(self, name: str) -> PortBase:
        """The port called ``name`` (BAD_PARAMETER naming the ports there are)."""
        port = self._ports.get(name) if isinstance(name, str) else None
        if port is None:
            raise RTCBadParameterError(
                "port", name, f"a port of {self.instance_name}: {sorted(self._ports) or 'none'}"
            )
        return port

    @property
    def ports(self) -> tuple[PortBase, ...]:
        """The ports, in the order they were added."""
        return tuple(self._ports.values())

    # -- hooks used by contexts and subclasses ----------------------------------------------
    def _own(self, ec: ExecutionContext) -> None:
        self._owned.append(ec)

    async def _shared_context_event(self, ec: ExecutionContext, event: str) -> None:
        """Subclass hook (composites): ``ec`` added, activated or deactivated this RTC
        (after the change), or is about to remove it (``"add"``, ``"activate"``,
        ``"deactivate"``, ``"remove"``)."""

    def _context_attached(self, ec: ExecutionContext) -> None:
        """Subclass hook (modes): a context was attached."""

    def _context_detached(self, ec: ExecutionContext) -> None:
        """Subclass hook (modes): a context was detached."""

    def _failed(self, callback: str, outcome: Outcome) -> None:
        self.log.warning(
            "callback_failed",
            callback=callback,
            code=outcome.code.name,
            error=repr(outcome.error) if outcome.error is not None else None,
        )

    def report(self) -> dict[str, object]:
        """Figures an application wants printed at the end of a run (override)."""
        return {}

    # -- ComponentAction ---------------------------------------------------------------
    async def on_initialize(self) -> CallbackResult:
        """The RTC has been initialized and entered the Alive state."""
        return None

    async def on_finalize(self) -> CallbackResult:
        """The RTC is being destroyed."""
        return None

    async def on_startup(self, exec_handle: int) -> CallbackResult:
        """The context ``exec_handle`` went from Stopped to Running."""
        return None

    async def on_shutdown(self, exec_handle: int) -> CallbackResult:
        """The context ``exec_handle`` went from Running to Stopped."""
        return None

    async def on_activated(self, exec_handle: int) -> CallbackResult:
        """The RTC is being activated in the context (Inactive -> Active)."""
        return None

    async def on_deactivated(self, exec_handle: int) -> CallbackResult:
        """The RTC is being deactivated in the context (Active -> Inactive)."""
        return None

    async def on_aborting(self, exec_handle: int) -> CallbackResult:
        """The RTC is entering the Error state in the context (once per entry)."""
        return None

    async def on_error(self, exec_handle: int) -> CallbackResult:
        """The RTC remains in Error: runs instead of on_execute/on_state_update."""
        return None

    async def on_reset(self, exec_handle: int) -> CallbackResult:
        """Recover from Error; RTC_OK returns the RTC to Inactive."""
        return None

    # -- DataFlowComponentAction -------------------------------------------------------
    async def on_execute(self, exec_handle: int) -> CallbackResult:
        """First pass of a cycle while Active (all participants, in order)."""
        return None

    async def on_state_update(self, exec_handle: int) -> CallbackResult:
        """Second pass of a cycle while Active, after every participant's on_execute."""
        return None

    async def on_rate_changed(self, exec_handle: int) -> CallbackResult:
        """The rate of the (periodic) context changed."""
        return None
