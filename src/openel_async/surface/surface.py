"""The HAL4RT surface layer (spec §7.4.2-7.4.3) over a set of components.

``execute(device)`` parses each command message, selects the component by device kind
and logical id, and runs the operation its kind's dispatch table names. A synchronous
operation's results come back in the message; an asynchronous one (SetPosition,
SetSpeed...) returns a surface-chosen ``command_id`` at once and the application's
``completed(command_id, status)`` is called when the command ends. Component events go to
the applications that ``subscribe``d to their device kind and event type; component
errors go to every attached application. Details stay available by id for a while (the
most recent ``details_size``).

Every command's results start with ``return_code`` (INT, a ReturnCode) and, when it is
not HAL_OK, ``message`` (STRING). A refused command is logged once and never stops the
surface.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
from collections import OrderedDict, deque
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from types import TracebackType
from typing import Any, Self

import anyio
import anyio.abc

from openel_async.logs import get_logger
from openel_async.wakeup import Wakeup

from ..completion import Motion
from ..component import ComponentState, HALComponent
from ..device import ErrorId
from ..errors import (
    BadParameterError,
    DeviceFaultError,
    HALError,
    MotionCancelledError,
    ReturnCode,
    StateError,
    SupersededError,
    WouldBlockError,
)
from ..requests import EventId
from .application import Delivery
from .messages import (
    CommandMessage,
    DataType,
    Device,
    Parameter,
    ResultList,
    command_unchecked,
    device_unchecked,
    results_unchecked,
)
from .profiles import (
    DEFAULT_PROFILES,
    KindProfile,
    NowRun,
    Operation,
    argument,
    kind_of,
    normalize_kind,
)

log = get_logger(__name__)

LOGICAL_ID = "logical_id"
"""The argument that selects the component among those of a device kind (INT)."""
ANY_EVENT = "*"
"""``subscribe``'s event_type for every event of the kind."""
PLANS_SIZE = 256
"""Devices whose component and operation ``execute_nowait`` keeps (then all are dropped)."""


@dataclass(frozen=True)
class SurfaceEntry:
    """A component as the surface layer addresses it."""

    device_kind: str
    logical_id: int
    component: HALComponent


@dataclass(frozen=True)
class Subscription:
    subscribe_id: int
    device_kind: str
    event_type: str
    application: object
    exclude: frozenset[str] = frozenset()
    """Event types not delivered (with '*': every event but these)."""

    def wants(self, device_kind: str, event_type: str) -> bool:
        return (
            self.device_kind == device_kind
            and (self.event_type == event_type or self.event_type == ANY_EVENT)
            and event_type not in self.exclude
        )


def event_type_name(event_id: int) -> str:
    try:
        return EventId(event_id).name
    except ValueError:
        return f"EVENT_{event_id}"


def error_type_name(error_id: int) -> str:
    try:
        return ErrorId(error_id).name
    except ValueError:
        return f"ERROR_{error_id}"


def status_of(motion: Motion, error: BaseException | None) -> ReturnCode:
    """The ``completed`` status of a finished command."""
    if error is None:
        return ReturnCode.HAL_OK
    if isinstance(error, HALError):
        if isinstance(error, SupersededError | MotionCancelledError):
            return ReturnCode.HAL_ERROR
        return error.code
    return ReturnCode.HAL_ERROR


_HAL_OK = Parameter(DataType.INT, "return_code", int(ReturnCode.HAL_OK))


HANDOVER_AFTER = 0.01
"""Seconds after which a command still pending is awaited by its component's watcher task
(a command ended silently, superseded by another party or cancelled at finalize, is then
reported at once); until then its end is seen through the component's notifications."""


class _MotionWatcher:
    """Reports the end of the commands of one component, in order.

    A component has at most one pending Motion (a new command supersedes the previous),
    so the motions end in the order they were accepted. Most end with a notification to
    the surface, which observes the component: reached (COMPLETED, posted right after the
    Motion is reached), faulted (notify_error, after it is faulted), superseded by the
    next command through the surface (:meth:`add`); those are reported from there
    (:meth:`settle`), without a task step. A command still pending after HANDOVER_AFTER
    is awaited by the task (:meth:`run`), which also sees the silent ends.
    """

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self.pending: deque[tuple[str, Motion, Delivery]] = deque()
        self.wakeup = Wakeup()  # reused: no new event (and backend lookup) per command
        self.loop = loop
        self.timer: asyncio.TimerHandle | None = None
        self.checked: Motion | None = None
        """The head still pending when the timer was armed (handed over if it still is)."""
        self.watching = False
        """The task awaits the pending motions (until none is left)."""

    def add(self, command_id: str, motion: Motion, delivery: Delivery) -> None:
        self.settle()  # the previous command (superseded by this one) first
        self.pending.append((command_id, motion, delivery))
        if not self.watching and self.timer is None:
            self.checked = self.pending[0][1]
            self.timer = self.loop.call_later(HANDOVER_AFTER, self._check)

    def settle(self) -> None:
        """Report the commands that ended, oldest first, up to the first still pending."""
        pending = self.pending
        while pending and pending[0][1].done():
            command_id, motion, delivery = pending.popleft()
            delivery.call("completed", command_id, status_of(motion, motion.error()))

    def _check(self) -> None:
        self.timer = None
        self.settle()
        if not self.pending or self.watching:
            return
        head = self.pending[0][1]
        if head is self.checked:  # pending for HANDOVER_AFTER at least: the task awaits it
            self.watching = True
            self.wakeup.set()
        else:
            self.checked = head
            self.timer = self.loop.call_later(HANDOVER_AFTER, self._check)

    def close(self) -> None:
        if self.timer is not None:
            self.timer.cancel()
            self.timer = None

    async def run(self) -> None:
        while True:
            while not self.watching:
                await self.wakeup.wait()
            while self.pending:
                motion = self.pending[0][1]
                if not motion.done():
                    with contextlib.suppress(HALError):  # reported by settle, from the motion
                        await motion
                self.settle()
            self.watching = False


def failure(command: CommandMessage, code: ReturnCode, message: str) -> CommandMessage:
    """``command`` with results return_code=code and message."""
    return CommandMessage(
        command.function_name,
        command.command_id,
        command.arguments,
        ResultList(
            (
                Parameter(DataType.INT, "return_code", int(code)),
                Parameter(DataType.STRING, "message", message),
            )
        ),
    )


class Surface:
    """The surface layer over components that are already Active (``async with``)."""

    def __init__(
        self,
        components: Sequence[HALComponent],
        *,
        profiles: Mapping[str, KindProfile] | None = None,
        details_size: int = 4096,
        name: str = "surface",
    ) -> None:
        self.profiles = {normalize_kind(k): p for k, p in (profiles or DEFAULT_PROFILES).items()}
        self.name = name
        self.details_size = details_size
        self.entries: list[SurfaceEntry] = []
        self._by_kind: dict[str, list[SurfaceEntry]] = {}
        self._by_component: dict[int, SurfaceEntry] = {}
        for component in components:
            kind = kind_of(component)
            key = normalize_kind(kind)
            if key not in self.profiles:
                raise BadParameterError(
                    "components", component, f"a kind among {sorted(self.profiles)}"
                )
            same = self._by_kind.setdefault(key, [])
            entry = SurfaceEntry(kind, len(same), component)  # §7.4.3: logical ids 0, 1, ...
            same.append(entry)
            self.entries.append(entry)
            self._by_component[id(component)] = entry
        self._command_count = 0
        self._watchers: dict[int, _MotionWatcher] = {}
        self._plans: dict[int, tuple[Device, CommandMessage, SurfaceEntry, NowRun]] = {}
        self._event_ids = itertools.count(1)
        self._error_ids = itertools.count(1)
        self._subscribe_ids = itertools.count(1)
        self._subscriptions: dict[int, Subscription] = {}
        self._event_details: OrderedDict[str, ResultList] = OrderedDict()
        self._error_details: OrderedDict[str, ResultList] = OrderedDict()
        self._deliveries: dict[int, Delivery] = {}
        self._identity: dict[int, tuple[Parameter, ...]] = {}
        self._event_codes: dict[int, tuple[Parameter, ...]] = {}
        self._attached: dict[int, object] = {}
        self._tg: anyio.abc.TaskGroup | None = None
        self.refused = 0
        """Commands answered with a return code other than HAL_OK."""

    # -- lifecycle ---------------------------------------------------------------------
    async def __aenter__(self) -> Self:
        self._tg = await anyio.create_task_group().__aenter__()
        for entry in self.entries:
            if entry.component.state is not ComponentState.ACTIVE:
                await self._tg.__aexit__(None, None, None)
                raise StateError("Surface", entry.component.state, [ComponentState.ACTIVE])
            entry.component.add_observer(self)
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> bool | None:
        for entry in self.entries:
            if entry.component.state is ComponentState.ACTIVE and self in entry.component.observers:
                entry.component.remove_observer(self)
        for watcher in self._watchers.values():
            watcher.close()
        assert self._tg is not None
        self._tg.cancel_scope.cancel()
        return await self._tg.__aexit__(exc_type, exc, tb)

    def _delivery(self, application: object) -> Delivery:
        delivery = self._deliveries.get(id(application))
        if delivery is None:
            if self._tg is None:
                raise StateError("Surface", "not entered", ["inside 'async with surface'"])
            delivery = self._deliveries[id(application)] = Delivery(application, self._tg)
        return delivery

    def attach(self, application: object) -> None:
        """Receive notify_error for every component (and completed for its own commands)."""
        self._delivery(application)
        self._attached[id(application)] = application

    def detach(self, application: object) -> None:
        """Stop every notification to ``application`` and drop its subscriptions."""
        self._attached.pop(id(application), None)
        for sid in [
            s.subscribe_id for s in self._subscriptions.values() if s.application is application
        ]:
            del self._subscriptions[sid]
        self._deliveries.pop(id(application), None)

    # -- addressing --------------------------------------------------------------------
    def kinds(self) -> list[str]:
        return sorted({e.device_kind for e in self.entries})

    def resolve(self, device_kind: str, logical_id: int | None) -> SurfaceEntry:
        entries = self._by_kind.get(normalize_kind(device_kind))
        if not entries:
            raise BadParameterError("device_kind", device_kind, f"one of {self.kinds()}")
        if logical_id is None:
            if len(entries) == 1:
                return entries[0]
            raise BadParameterError(
                LOGICAL_ID,
                None,
                f"one of 0..{len(entries) - 1} ({len(entries)} {entries[0].device_kind} components)",
            )
        if not 0 <= logical_id < len(entries):
            raise BadParameterError(
                LOGICAL_ID, logical_id, f"one of 0..{len(entries) - 1} for {entries[0].device_kind}"
            )
        return entries[logical_id]

    def entry_of(self, component: HALComponent) -> SurfaceEntry:
        return self._by_component[id(component)]

    # -- Command interface (Table 7.5) ---------------------------------------------------
    async def execute(self, device: Device, application: object | None = None) -> Device:
        """execute(): run each command message; the messages come back with results."""
        if not isinstance(device, Device):
            raise BadParameterError("device", device, "a Device message")
        done = [
            await self.execute_command(device.device_kind, c, application) for c in device.commands
        ]
        return Device(device.device_kind, tuple(done))

    def execute_nowait(self, device: Device, application: object | None = None) -> Device:
        """execute() without suspending, for a Device of one command whose operation has a
        synchronous path on its component (a simulated motor's GetPosition, SetPosition...).

        Raises WouldBlockError, with nothing done, when it cannot (more than one command,
        an operation without ``run_nowait``, a component that needs I/O); use
        :meth:`execute` then. Refusals (bad arguments...) are answers, as in execute().

        The component and operation of a Device are looked up once per Device object (a
        server decodes the same bytes to the same immutable Device: a client's reads);
        the reply is built from the checked request without checking it again.
        """
        plan = self._plans.get(id(device))
        if plan is None or plan[0] is not device:
            if not isinstance(device, Device):
                raise BadParameterError("device", device, "a Device message")
            if len(device.commands) != 1:
                raise WouldBlockError("execute_nowait runs one command message at a time")
            command = device.commands[0]
            try:
                entry, operation = self._target(device.device_kind, command)
            except HALError as exc:
                done = self._refuse(device.device_kind, self._numbered(command), exc.code, str(exc))
                return Device(device.device_kind, (done,))
            if operation.run_nowait is None:
                raise WouldBlockError(f"{command.function_name} has no synchronous path")
            plan = (device, command, entry, operation.run_nowait)
            if len(self._plans) >= PLANS_SIZE:
                self._plans.clear()
            self._plans[id(device)] = plan
        _, command, entry, nowait = plan
        command_id = f"c{self._command_count + 1}"
        numbered = command_unchecked(
            command.function_name, command_id, command.arguments, command.results
        )
        try:
            outcome: Any = nowait(entry.component, numbered)
        except WouldBlockError:
            raise  # nothing was done: the caller runs execute()
        except HALError as exc:
            self._command_count += 1
            done = self._refuse(device.device_kind, numbered, exc.code, str(exc))
            return device_unchecked(device.device_kind, (done,))
        except Exception as exc:
            self._command_count += 1
            log.exception("surface_operation_failed", function=command.function_name)
            done = self._refuse(device.device_kind, numbered, ReturnCode.HAL_ERROR, repr(exc))
            return device_unchecked(device.device_kind, (done,))
        self._command_count += 1
        done = self._answer(numbered, outcome, entry, application)
        return device_unchecked(device.device_kind, (done,))

    async def execute_command(
        self, device_kind: str, command: CommandMessage, application: object | None = None
    ) -> CommandMessage:
        command = self._numbered(command)
        try:
            entry, operation = self._target(device_kind, command)
            outcome: Any = await operation.run(entry.component, command)
        except HALError as exc:
            return self._refuse(device_kind, command, exc.code, str(exc))
        except Exception as exc:  # a component raising something else: still an answer
            log.exception("surface_operation_failed", function=command.function_name)
            return self._refuse(device_kind, command, ReturnCode.HAL_ERROR, repr(exc))
        return self._answer(command, outcome, entry, application)

    def _numbered(self, command: CommandMessage) -> CommandMessage:
        """``command`` with the next surface-chosen command_id."""
        self._command_count += 1
        return CommandMessage(
            command.function_name, f"c{self._command_count}", command.arguments, command.results
        )

    def _target(self, device_kind: str, command: CommandMessage) -> tuple[SurfaceEntry, Operation]:
        logical_id = argument(command, LOGICAL_ID, DataType.INT, required=False)
        entry = self.resolve(device_kind, logical_id)
        profile = self.profiles[normalize_kind(entry.device_kind)]
        return entry, profile.operation(command.function_name)

    def _answer(
        self,
        command: CommandMessage,
        outcome: object,
        entry: SurfaceEntry,
        application: object | None,
    ) -> CommandMessage:
        """The executed command with its results (an accepted Motion is watched)."""
        if isinstance(outcome, Motion):
            self._watch(command.command_id, outcome, entry, application)
            results: tuple[Parameter, ...] = (_HAL_OK,)
        elif isinstance(outcome, ResultList):
            results = (_HAL_OK, *outcome.parameters)
        else:
            results = (_HAL_OK,)
        # every part was checked (the request's, the results') or is ours (the command id)
        return command_unchecked(
            command.function_name,
            command.command_id,
            command.arguments,
            results_unchecked(results),
        )

    def _refuse(
        self, device_kind: str, command: CommandMessage, code: ReturnCode, message: str
    ) -> CommandMessage:
        self.refused += 1
        log.warning(
            "command_refused",
            device_kind=device_kind,
            function=command.function_name,
            code=code.name,
            reason=message,
        )
        return failure(command, code, message)

    def _watch(
        self, command_id: str, motion: Motion, entry: SurfaceEntry, application: object | None
    ) -> None:
        """Call ``completed`` when ``motion`` ends: at once when it already has (after the
        component's earlier commands), else when the component tells of its end or the
        component's watcher sees it (:class:`_MotionWatcher`)."""
        if application is None:
            return
        delivery = self._delivery(application)
        watcher = self._watchers.get(id(entry.component))
        if motion.done():
            if watcher is not None:
                watcher.settle()
            delivery.call("completed", command_id, status_of(motion, motion.error()))
            return
        if watcher is None:
            assert self._tg is not None
            watcher = self._watchers[id(entry.component)] = _MotionWatcher(
                asyncio.get_running_loop()
            )
            self._tg.start_soon(watcher.run)
        watcher.add(command_id, motion, delivery)

    # -- Event interface (Table 7.6) ------------------------------------------------------
    def subscribe(
        self,
        device_kind: str,
        event_type: str,
        application: object,
        *,
        exclude: Iterable[str] = (),
    ) -> int:
        """Register ``application`` for events ``event_type`` ('*' for all) of a device kind,
        but those whose type is in ``exclude`` (a client that learns of COMPLETED through
        ``completed`` subscribes to '*' excluding COMPLETED: no event, detail or notice is
        made for it)."""
        if isinstance(exclude, str):
            raise BadParameterError("exclude", exclude, "a collection of event type names")
        excluded = frozenset(exclude)
        for name in excluded:
            if not isinstance(name, str) or not name:
                raise BadParameterError("exclude", name, "an event type name (COMPLETED...)")
        if normalize_kind(device_kind) not in self._by_kind:
            raise BadParameterError("device_kind", device_kind, f"one of {self.kinds()}")
        if not isinstance(event_type, str) or not event_type:
            raise BadParameterError(
                "event_type",
                event_type,
                "an event type name (COMPLETED, LIMIT_REACHED, EVENT_<n>) or '*'",
            )
        self._delivery(application)
        sid = next(self._subscribe_ids)
        self._subscriptions[sid] = Subscription(
            sid, normalize_kind(device_kind), event_type, application, excluded
        )
        return sid

    def unsubscribe(self, subscribe_id: int) -> None:
        if self._subscriptions.pop(subscribe_id, None) is None:
            raise BadParameterError(
                "subscribe_id", subscribe_id, f"one of {sorted(self._subscriptions)}"
            )

    def get_event_detail(self, event_id: str) -> ResultList:
        found = self._event_details.get(event_id)
        if found is None:
            raise BadParameterError(
                "event_id", event_id, f"one of the last {self.details_size} events' ids"
            )
        return found

    def get_error_detail(self, error_id: str) -> ResultList:
        found = self._error_details.get(error_id)
        if found is None:
            raise BadParameterError(
                "error_id", error_id, f"one of the last {self.details_size} errors' ids"
            )
        return found

    def _remember(self, table: OrderedDict[str, ResultList], key: str, detail: ResultList) -> None:
        table[key] = detail
        if len(table) > self.details_size:
            table.popitem(last=False)

    # -- HALObserver of the components ----------------------------------------------------
    def notify_event(self, source: HALComponent, event_id: int) -> None:
        entry = self._by_component.get(id(source))
        if entry is None:
            return
        watcher = self._watchers.get(id(source))
        if watcher is not None and watcher.pending:  # COMPLETED: a command reached
            watcher.settle()
        key = normalize_kind(entry.device_kind)
        event_type = event_type_name(event_id)
        targets = [s for s in self._subscriptions.values() if s.wants(key, event_type)]
        if not targets:
            return
        eid = f"e{next(self._event_ids)}"
        # The component's identity parameters are built once; per event only the code
        # (cached per code) and the time are new.
        head = self._identity.get(id(source))
        if head is None:
            head = self._identity[id(source)] = (
                Parameter(DataType.STRING, "device_kind", entry.device_kind),
                Parameter(DataType.INT, "logical_id", entry.logical_id),
                Parameter(DataType.STRING, "device_name", source.device_name),
            )
        code = self._event_codes.get(event_id)
        if code is None:
            code = self._event_codes[event_id] = (
                Parameter(DataType.INT, "event_code", int(event_id)),
                Parameter(DataType.STRING, "event_type", event_type),
            )
        self._remember(
            self._event_details,
            eid,
            ResultList((*head, *code, Parameter(DataType.INT, "time_ns", source.clock.now_ns()))),
        )
        for s in targets:
            self._delivery(s.application).call("notify_event", eid, event_type, s.subscribe_id)

    def notify_error(self, source: HALComponent, error_id: int) -> None:
        entry = self._by_component.get(id(source))
        if entry is None:
            return
        watcher = self._watchers.get(id(source))
        if watcher is not None and watcher.pending:  # a fault: its command faulted
            watcher.settle()
        rid = f"r{next(self._error_ids)}"
        fault: DeviceFaultError | None = source.last_fault
        error_type = error_type_name(error_id)
        self._remember(
            self._error_details,
            rid,
            ResultList.of(
                device_kind=entry.device_kind,
                logical_id=entry.logical_id,
                device_name=source.device_name,
                error_code=int(error_id),
                error_type=error_type,
                state=str(source.state),
                faulted=source.state is ComponentState.ERROR,
                return_code=int(fault.code) if fault is not None else int(ReturnCode.HAL_ERROR),
                message=str(fault) if fault is not None else "",
                time_ns=source.clock.now_ns(),
            ),
        )
        for application in tuple(self._attached.values()):
            self._delivery(application).call("notify_error", rid, error_type)
