"""HALComponent: identity, observers, time and the state machine of OpenEL 3.2.

States (Figure 7.4): Initializing -> Initialized -> (Init) Active -> (fault) Error
-> (ReInit) Active; Finalize ends in the terminal Finalized state. Every public call
checks the state and raises :class:`StateError` naming the state and the allowed ones.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Awaitable, Callable, Coroutine
from contextlib import AsyncExitStack
from dataclasses import replace
from enum import Enum
from types import MethodType, TracebackType
from typing import Any, ClassVar, Self

import anyio
import anyio.abc

from openel_async.logs import get_logger

from .clock import Clock, default_clock
from .device import Device, ErrorId
from .errors import (
    STATE_HINTS,
    BadParameterError,
    DeviceFaultError,
    HALError,
    NotConnectedError,
    ReturnCode,
    StateError,
)
from .fanout import Fanout
from .ids import DeviceKind, HALId, Property, component_name, profile_name
from .listeners import LISTENING, ComponentListener
from .observers import ErrorNotice, EventNotice
from .safety import EmergencyStop
from .stats import ObserverStats

log = get_logger(__name__)


class ComponentState(Enum):
    INITIALIZING = "Initializing"
    INITIALIZED = "Initialized"
    ACTIVE = "Active"
    ERROR = "Error"
    FINALIZED = "Finalized"

    def __str__(self) -> str:
        return self.value


S = ComponentState

STATE_HINTS[S.INITIALIZING] = (
    "The component was never entered: use `async with component:` first (it opens the "
    "device and calls init(); with auto_init=False, `await component.init()` inside the block)"
)
STATE_HINTS[S.INITIALIZED] = (
    "The component was entered with auto_init=False but never initialized: "
    "`await component.init()` first"
)

# Observers hear from a component only while it is operating.
# The states that notify observers (Active, Error), tested by identity: ``in`` a set would
# call Enum.__hash__ (Python code) on every event.
_NOTIFY_ACTIVE = ComponentState.ACTIVE
_NOTIFY_ERROR = ComponentState.ERROR

# Exceptions of a device call that mean the link or the device failed (-> Error state).
LINK_FAULTS: tuple[type[BaseException], ...] = (
    NotConnectedError,
    TimeoutError,
    OSError,
    anyio.BrokenResourceError,
    anyio.ClosedResourceError,
)
_instances = itertools.count(1)


class StateChanges:
    """Counts state changes of every component (a bank skips its members' per-call Active
    checks while it has not moved since they were all Active)."""

    __slots__ = ("value",)

    def __init__(self) -> None:
        self.value = 0


STATE_CHANGES = StateChanges()

EXIT_DRAIN_S = 1.0
"""How long leaving ``async with component`` waits for async observers (real seconds)."""


_ENTRY_CACHE = 32
"""Event ids per component whose mailbox entry or notice is kept for reuse (more are built
per event)."""

_EAGER_REFRESH = 32
"""Observers of a component up to which a registration or a state change sets the event
port's fast paths at once (past it, the next event does: registering stays O(1))."""


class _EventPort:
    """A component's events from its device (``ctx.post_event``), with fast paths.

    While the component notifies (Active, Error), :meth:`post_event` delivers by itself
    when its event observers are all alike: one small slotted object read per event
    instead of the component's state, its fan-out and that one's per-kind table (at 1000
    components, the memory touched per event is what the cost grows with).

    - One plain observer that is a bound method: called as its function with its object
      (:attr:`func`, or :attr:`nfunc` with the ``EventNotice`` when it takes one): no
      method object, no tuple read. The notice of an event id is built once and reused
      (a value, never assigned to, as the notice one publish shares among its observers
      already is): an ``ObserverQueue`` holds no new GC-tracked object per event, which
      at 1000 components doubled the young collections per tick.
    - Plain observers taking no notice: :attr:`fast`, called in order.
    - Async observers only, taking no notice: :attr:`puts`, their mailboxes' ``put``; the
      entry for an event id is built once and reused (immutable: nothing allocated per
      event).

    Otherwise all are None and the event goes the general way
    (``HALComponent._publish_event``: state test, mixed observers, notices). A state change
    or an observer registration only marks the port :attr:`stale` (O(1): registering N
    observers stays O(N) in all); the next event sets the fast paths again
    (``HALComponent._refresh_events``, O(observers) once).
    """

    __slots__ = (
        "component",
        "entries",
        "fanout",
        "fast",
        "func",
        "nfunc",
        "obj",
        "published",
        "puts",
        "stale",
    )

    def __init__(self, component: HALComponent, fanout: Fanout) -> None:
        self.component = component
        self.fanout = fanout
        self.func: Callable[..., Any] | None = None
        self.nfunc: Callable[..., Any] | None = None
        self.obj: object = None
        self.fast: tuple[Callable[..., Any], ...] | None = None
        self.puts: tuple[Callable[[Any], None], ...] | None = None
        self.entries: dict[int, Any] = {}
        """Per event id, the mailbox entry (:attr:`puts`) or the notice (:attr:`nfunc`)
        reused for it; emptied by :meth:`set`."""
        self.published = 0
        """Events delivered by the fast paths (added to the fan-out's ``published``)."""
        self.stale = False
        """The state or the observers changed since the fast paths were set."""

    def set(
        self,
        direct: tuple[tuple[Callable[..., Any], ...], bool] | None,
        puts: tuple[Callable[[Any], None], ...] | None,
    ) -> None:
        self.func = self.nfunc = self.obj = self.fast = self.puts = None
        self.entries.clear()
        if direct is not None:
            methods, with_notice = direct
            if len(methods) == 1 and type(methods[0]) is MethodType:
                method = methods[0]
                self.obj = method.__self__
                if with_notice:
                    self.nfunc = method.__func__
                else:
                    self.func = method.__func__
            elif not with_notice:
                self.fast = methods
        elif puts is not None:
            self.puts = puts

    def post_event(self, event_id: int) -> None:
        func = self.func
        if func is not None:
            self.published += 1
            try:
                func(self.obj, self.component, event_id)
            except Exception:
                self.fanout.failed(MethodType(func, self.obj))
            return
        func = self.nfunc
        if func is not None:
            self.published += 1
            source = self.component
            notice = self.entries.get(event_id)
            if notice is None:
                notice = EventNotice(source, event_id)
                if len(self.entries) < _ENTRY_CACHE:
                    self.entries[event_id] = notice
            try:
                func(self.obj, source, event_id, notice)
            except Exception:
                self.fanout.failed(MethodType(func, self.obj))
            return
        puts = self.puts
        if puts is not None:
            self.published += 1
            entry = self.entries.get(event_id)
            if entry is None:
                entry = self.fanout.mailbox_entry("notify_event", (self.component, event_id))
                if len(self.entries) < _ENTRY_CACHE:
                    self.entries[event_id] = entry
            wakeup = self.fanout.wakeup
            if wakeup.waiter is not None:  # mailbox tasks wait (Fanout._wake, inlined)
                wakeup.set()
            for put in puts:
                put(entry)
            return
        methods = self.fast
        if methods is None:
            if self.stale:  # the first event since a change: set the fast paths, then go
                self.stale = False
                self.component._refresh_events()
                if self.func or self.nfunc or self.puts or self.fast:
                    self.post_event(event_id)
                    return
            self.component._publish_event(event_id)
            return
        self.published += 1
        source = self.component
        for method in methods:
            try:
                method(source, event_id)
            except Exception:
                self.fanout.failed(method)


class _Context:
    """The DeviceContext a component hands to its device."""

    def __init__(self, component: HALComponent) -> None:
        self._component = component
        self.port = _EventPort(component, component._observers)
        self.post_event: Callable[[int], None] = self.port.post_event
        """The event port's method (no call through this object: a driver's events are a
        hot path)."""

    @property
    def clock(self) -> Clock:
        return self._component.clock

    @property
    def name(self) -> str:
        return self._component.device_name

    @property
    def hal_id(self) -> HALId:
        return self._component.hal_id

    def start_soon(self, func: Callable[..., Coroutine[Any, Any, Any]], *args: Any) -> None:
        self._component._task_group().start_soon(self._component._run_device_task, func, args)

    def target_reached(self) -> None:
        self._component._on_target_reached()

    def post_error(self, error_id: int) -> None:
        self._component._publish_error(error_id)

    def fault(self, error_id: int, reason: str, code: ReturnCode = ReturnCode.HAL_ERROR) -> None:
        self._component._fault(error_id, reason, code)


def _check_arguments(
    device_class: type[Device],
    device: object,
    hal_id: object,
    function_list: object,
    clock: object,
    auto_init: object,
    open_timeout: object,
) -> None:
    """BadParameterError for a constructor argument of the wrong kind (before any is used)."""
    if not isinstance(device, device_class):
        raise BadParameterError("device", device, f"an instance of {device_class.__name__}")
    if hal_id is not None and not isinstance(hal_id, HALId):
        raise BadParameterError("hal_id", hal_id, "a HALId or None")
    if function_list is not None and (
        isinstance(function_list, str) or not isinstance(function_list, tuple | list)
    ):
        raise BadParameterError("function_list", function_list, "a tuple of strings or None")
    if clock is not None and (isinstance(clock, type) or not isinstance(clock, Clock)):
        raise BadParameterError("clock", clock, "a Clock (now_ns and sleep_until) or None")
    if not isinstance(auto_init, bool):
        raise BadParameterError("auto_init", auto_init, "True or False")
    if (
        isinstance(open_timeout, bool)
        or not isinstance(open_timeout, int | float)
        or not (math.isfinite(open_timeout) and open_timeout > 0)
    ):
        raise BadParameterError("open_timeout", open_timeout, "a finite number of seconds > 0")


class HALComponent:
    """Common part of every OpenEL component; use it as an async context manager.

    ``async with`` runs the device's Initializing processing, then Init unless
    ``auto_init=False`` (then call :meth:`init` yourself, as in the spec's Figure 7.6),
    and finalizes on exit.
    """

    device_class: ClassVar[type[Device]] = Device
    """The driver base class the constructor accepts (ActuatorDevice for an Actuator...)."""

    estop_latched: bool = False
    """An e-stop (:meth:`estop`) holds until :meth:`release_estop`: ``re_init`` is refused
    meanwhile. (A class default: the instance attribute exists only once latched.)"""
    _active_hooks: tuple[Callable[[HALComponent], Awaitable[None]], ...] = ()

    def __init__(
        self,
        device: Device,
        *,
        hal_id: HALId | None = None,
        device_name: str | None = None,
        function_list: tuple[str, ...] | None = None,
        clock: Clock | None = None,
        auto_init: bool = True,
        open_timeout: float = 10.0,
    ) -> None:
        _check_arguments(
            self.device_class, device, hal_id, function_list, clock, auto_init, open_timeout
        )
        info = device.info
        if hal_id is None:
            hal_id = HALId(int(info.kind), info.vendor_id, info.product_id, next(_instances))
        if device_name is None:
            profile = profile_name(hal_id.device_kind_id)
            device_name = component_name(profile, info.vendor_name, info.product_name)
        self.device = device
        self.hal_id = hal_id
        self.property = Property(hal_id, device_name, tuple(function_list or info.functions))
        self.clock: Clock = clock or default_clock()
        self.auto_init = auto_init
        self.open_timeout = open_timeout
        self.state = S.INITIALIZING
        self.last_fault: DeviceFaultError | None = None
        self._observers = Fanout(device_name, ("notify_event", "notify_error"))
        # Set once entered. (Few instance attributes: past 29, CPython 3.11 stops sharing
        # the instance dict's keys and every attribute read on the per-call paths slows.)
        self._stack: AsyncExitStack | None = None
        self._tg: anyio.abc.TaskGroup | None = None
        self._device_scopes: set[anyio.CancelScope] = set()
        self._ctx = _Context(self)
        self.log = log.bind(component=device_name)

    @property
    def device_name(self) -> str:
        return self.property.device_name

    # -- async context manager -------------------------------------------------------
    async def __aenter__(self) -> Self:
        if self._stack is not None:  # entered before
            raise StateError("__aenter__", self.state, ["a component not yet entered"])
        stack = self._stack = AsyncExitStack()
        self._tg = await stack.enter_async_context(anyio.create_task_group())
        self._observers.bind(self._tg)
        try:
            with anyio.fail_after(self.open_timeout):
                await self.device.open(self._ctx)
            self._set_state(S.INITIALIZED)
            if self.auto_init:
                await self.init()
        except BaseException:
            await self._shutdown()
            await stack.aclose()
            raise
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self._shutdown()
        assert self._stack is not None
        await self._stack.aclose()

    async def _shutdown(self) -> None:
        """Finalize whatever the state; used on context exit."""
        if self.state is not S.FINALIZED:
            with anyio.CancelScope(shield=True):
                await self._close_device()
            self._set_state(S.FINALIZED)
        # Async observers get EXIT_DRAIN_S to handle what was published; what is left is
        # counted and logged (observer_stats.abandoned) before the tasks are cancelled.
        await self._observers.drain(EXIT_DRAIN_S)
        if self._tg is not None:
            self._tg.cancel_scope.cancel()

    async def _run_device_task(
        self, func: Callable[..., Coroutine[Any, Any, Any]], args: tuple[Any, ...]
    ) -> None:
        with anyio.CancelScope() as scope:
            self._device_scopes.add(scope)
            try:
                await func(*args)
            finally:
                self._device_scopes.discard(scope)

    def _task_group(self) -> anyio.abc.TaskGroup:
        if self._tg is None:
            raise StateError("start_soon", self.state, ["inside 'async with component'"])
        return self._tg

    # -- state machine ---------------------------------------------------------------
    def _require(self, operation: str, *allowed: ComponentState) -> None:
        if self.state not in allowed:
            raise StateError(operation, self.state, allowed)

    def _set_state(self, state: ComponentState) -> None:
        if state is not self.state:
            old = self.state
            self.log.info("state_changed", old=str(old), new=str(state))
            self.state = state
            STATE_CHANGES.value += 1
            self._events_changed()
            listener = self._observers.listener
            if listener is not None:
                listener.on_state(self, old, state)

    # -- listener (a recorder, a live view) --------------------------------------------
    @property
    def listener(self) -> ComponentListener | None:
        """The :class:`~openel_async.listeners.ComponentListener` told of this component's
        commands, readings and state changes (None: nobody)."""
        return self._observers.listener

    def set_listener(self, listener: ComponentListener | None) -> None:
        """Attach ``listener`` (None detaches). One listener per component: attaching a
        second one raises BadParameterError (detach the first, or fan out in the listener)."""
        current = self._observers.listener
        if listener is not None and current is not None and current is not listener:
            raise BadParameterError(
                "listener", listener, f"None: {self.device_name} already has {current!r}"
            )
        LISTENING.count += (listener is not None) - (current is not None)
        LISTENING.changes += 1
        self._observers.listener = listener

    async def init(self) -> None:
        """Init: Initialized -> Active."""
        self._require("init", S.INITIALIZED)
        try:
            await self.device.init()
        except HALError:
            raise
        except Exception as exc:
            raise HALError(f"{self.device_name}: init failed: {exc}") from exc
        self._set_state(S.ACTIVE)
        await self._on_active()
        await self._run_active_hooks()

    async def re_init(self) -> None:
        """ReInit: reset the error condition and return to Active (refused while an e-stop
        is latched: :meth:`release_estop` first)."""
        self._require("re_init", S.ERROR)
        if self.estop_latched:
            raise HALError(
                f"{self.device_name}: re_init refused: the e-stop is not released "
                "(release_estop first)"
            )
        self._before_reset()
        try:
            await self.device.reset()
        except Exception as exc:
            self.log.warning("re_init_failed", error=str(exc))
            if isinstance(exc, HALError):
                raise
            raise HALError(f"{self.device_name}: re_init failed: {exc}") from exc
        self.last_fault = None
        self._set_state(S.ACTIVE)
        await self._on_active()
        await self._run_active_hooks()

    def add_active_hook(self, hook: Callable[[HALComponent], Awaitable[None]]) -> None:
        """Await ``hook(component)`` each time the component becomes Active (``init`` and
        ``re_init``), before they return: a rig applies its limits and arms the device's
        watchdog this way. A hook that raises fails the ``init``/``re_init`` with the
        component left Active."""
        self._active_hooks = (*self._active_hooks, hook)

    async def _run_active_hooks(self) -> None:
        for hook in self._active_hooks:
            await hook(self)

    async def estop(self) -> None:
        """E-stop: latch (``re_init`` is refused until :meth:`release_estop`) and put the
        device into its protocol's emergency state (:class:`~openel_async.safety.EmergencyStop`:
        the device reports :attr:`~openel_async.device.ErrorId.ESTOP`). A device without one
        is faulted with ESTOP here, so that no command reaches it any more. Refused only in
        Initializing and Finalized."""
        self._require("estop", S.INITIALIZED, S.ACTIVE, S.ERROR)
        self.estop_latched = True
        self.log.warning("estop")
        device = self.device
        if isinstance(device, EmergencyStop):
            await device.estop()
        if self.state is S.ACTIVE:  # the device did not fault it (yet): no more commands
            self._fault(ErrorId.ESTOP, "e-stop")

    def release_estop(self) -> None:
        """Release a latched e-stop: ``re_init`` recovers the component again."""
        if self.estop_latched:
            self.estop_latched = False
            self.log.warning("estop_released")

    async def finalize(self) -> None:
        """Finalize: quit the component (Active or Error -> Finalized)."""
        self._require("finalize", S.ACTIVE, S.ERROR)
        await self._close_device()
        self._set_state(S.FINALIZED)

    async def _close_device(self) -> None:
        self._before_close()
        for scope in tuple(self._device_scopes):  # driver tasks end with the component
            scope.cancel()
        try:
            with anyio.move_on_after(self.open_timeout):
                await self.device.close()
        except Exception as exc:
            self.log.warning("device_close_failed", error=str(exc))

    # Hooks for subclasses.
    async def _on_active(self) -> None:
        pass

    def _before_reset(self) -> None:
        pass

    def _before_close(self) -> None:
        pass

    def _on_target_reached(self) -> None:
        pass

    def _on_fault(self, error: DeviceFaultError) -> None:
        pass

    # -- observers -------------------------------------------------------------------
    def add_observer(self, observer: object) -> None:
        """AddObserver: register a HALObserver (plain or async methods) or ObserverQueue.

        A method that takes one more argument gets the notice (EventNotice/ErrorNotice,
        with its ``missed`` count). Refused (BadParameterError naming ``observer``): None,
        a class, an observer already registered, an object without notify_event or
        notify_error, or one whose method cannot be called with (source, id).
        """
        self._require("add_observer", S.ACTIVE)
        self._observers.add(observer)
        self._events_changed()

    def remove_observer(self, observer: object) -> None:
        """RemoveObserver."""
        self._require("remove_observer", S.ACTIVE)
        self._observers.remove(observer)
        self._events_changed()

    @property
    def observers(self) -> tuple[object, ...]:
        return self._observers.observers

    @property
    def observer_stats(self) -> ObserverStats:
        """Delivery to the observers: notifications published, failures, and every notice
        dropped on the way to an async observer (mailbox overflow, exit)."""
        stats = self._observers.stats()
        fast = self._ctx.port.published
        return replace(stats, published=stats.published + fast) if fast else stats

    def _events_changed(self) -> None:
        """The state or the observers changed: the event port's fast paths are set again,
        here while the observers are few (:data:`_EAGER_REFRESH`: registering costs
        O(observers), so that the next event pays nothing for it), otherwise by the next
        event (:class:`_EventPort`: registering N observers stays O(N) in all)."""
        port = self._ctx.port
        if len(self._observers) <= _EAGER_REFRESH:
            port.stale = False
            self._refresh_events()
        else:
            port.set(None, None)
            port.stale = True

    def _refresh_events(self) -> None:
        """Set the event port's fast path (:class:`_EventPort`) for the state and the
        observers now."""
        state = self.state
        port = self._ctx.port
        if state is _NOTIFY_ACTIVE or state is _NOTIFY_ERROR:
            observers = self._observers
            direct = observers.direct_for("notify_event")
            # Plain observers only: no mailbox to look for.
            port.set(direct, None if direct is not None else observers.mailbox_puts("notify_event"))
        else:
            port.set(None, None)

    def _publish_event(self, event_id: int) -> None:
        state = self.state
        if state is _NOTIFY_ACTIVE or state is _NOTIFY_ERROR:
            observers = self._observers
            direct = observers.direct.get("notify_event")
            if direct is not None:  # plain observers only: called here, one frame less
                observers.published += 1
                methods, with_notice = direct
                if with_notice:
                    notice = EventNotice(self, event_id)
                    for method in methods:
                        try:
                            method(self, event_id, notice)
                        except Exception:
                            observers.failed(method)
                    return
                for method in methods:
                    try:
                        method(self, event_id)
                    except Exception:
                        observers.failed(method)
                return
            if "notify_event" in observers.wants_notice:
                notice = EventNotice(self, event_id)
                observers.publish("notify_event", self, event_id, notice=notice)
            else:
                observers.publish("notify_event", self, event_id)
        else:
            self._observers.unpublished += 1
            self.log.debug("event_dropped", event_id=event_id, state=str(self.state))

    def _publish_error(self, error_id: int) -> None:
        state = self.state
        if state is _NOTIFY_ACTIVE or state is _NOTIFY_ERROR:
            observers = self._observers
            if "notify_error" in observers.wants_notice:
                notice = ErrorNotice(self, error_id)
                observers.publish("notify_error", self, error_id, notice=notice)
            else:
                observers.publish("notify_error", self, error_id)
        else:
            self._observers.unpublished += 1
            self.log.debug("error_dropped", error_id=error_id, state=str(self.state))

    def _fault(
        self, error_id: int, reason: str, code: ReturnCode = ReturnCode.HAL_ERROR
    ) -> DeviceFaultError:
        """Move to Error (from Active) and notify error observers."""
        error = DeviceFaultError(f"{self.device_name}: {reason}", error_id=error_id, code=code)
        if self.state is S.ACTIVE:
            self.last_fault = error
            self._set_state(S.ERROR)
            self.log.error("device_fault", error_id=int(error_id), reason=reason, code=code.name)
            self._on_fault(error)
        if self.state in (S.ACTIVE, S.ERROR):
            self._publish_error(error_id)
        else:
            self.log.warning(
                "fault_outside_operation",
                error_id=int(error_id),
                reason=reason,
                state=str(self.state),
            )
        return error

    def _fault_from(self, exc: BaseException) -> DeviceFaultError:
        if isinstance(exc, NotConnectedError):
            return self._fault(ErrorId.DISCONNECTED, str(exc), ReturnCode.HAL_NO_CONNECTED)
        if isinstance(exc, TimeoutError):
            return self._fault(ErrorId.TIMEOUT, f"timeout: {exc}")
        return self._fault(
            ErrorId.DISCONNECTED, f"link failure: {exc!r}", ReturnCode.HAL_NO_CONNECTED
        )

    # -- profile and time ------------------------------------------------------------
    def get_profile(self) -> Property:
        """GetProfile: the component's Property (id, device name, function list)."""
        self._require("get_profile", S.ACTIVE)
        return self.property

    def get_time(self) -> int:
        """GetTime: the component's clock in integer nanoseconds.

        Raises HALError(HAL_ERROR) for a component without time, as the spec says.
        """
        self._require("get_time", S.ACTIVE)
        if not self.device.has_time:
            raise HALError(f"{self.device_name} has no time attribute")
        return self.clock.now_ns()

    @property
    def kind(self) -> DeviceKind | None:
        return self.hal_id.device_kind

    @property
    def profile_id(self) -> int:
        """HAL4RT ``profileId``: the id of the kind of the device (``hal_id.device_kind_id``)."""
        return self.hal_id.device_kind_id

    @property
    def component_name(self) -> str:
        """HAL4RT ``componentName`` (the device name: by default Hal + profile + vendor +
        product, §4.4)."""
        return self.property.device_name

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.device_name!r}, {self.hal_id}, state={self.state})"
