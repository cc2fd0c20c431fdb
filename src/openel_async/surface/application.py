"""The application side of the surface layer (spec Table 7.7) and its queue form.

An application implements ``completed``, ``notify_event`` and ``notify_error`` (any of
them, plain or ``async``). :class:`ApplicationQueue` implements all three without
blocking and hands the notices to a consumer; when it is full the oldest notice is
dropped and the next one the consumer gets says how many it missed, as ObserverQueue does.
"""

from __future__ import annotations

import inspect
from collections import deque
from collections.abc import Awaitable
from dataclasses import dataclass
from typing import Any, Protocol, TypeAlias, runtime_checkable

import anyio
import anyio.abc

from openel_async.logs import get_logger

from ..errors import BadParameterError, ReturnCode
from ..observers import NoticeQueue

log = get_logger(__name__)

APPLICATION_METHODS = ("completed", "notify_event", "notify_error")


@runtime_checkable
class ApplicationBase(Protocol):
    """Table 7.7: what the surface layer calls on the application (plain or async methods)."""

    def completed(self, command_id: str, status: ReturnCode) -> Awaitable[None] | None: ...

    def notify_event(
        self, event_id: str, event_type: str, subscribe_id: int
    ) -> Awaitable[None] | None: ...

    def notify_error(self, error_id: str, error_type: str) -> Awaitable[None] | None: ...


@dataclass(frozen=True, slots=True)
class Completed:
    """completed(command_id, status) as a queued value."""

    command_id: str
    status: ReturnCode
    missed: int = 0
    """Notices dropped from the queue just before this one."""


@dataclass(frozen=True, slots=True)
class EventNotification:
    """notify_event(event_id, event_type, subscribe_id) as a queued value."""

    event_id: str
    event_type: str
    subscribe_id: int
    missed: int = 0


@dataclass(frozen=True, slots=True)
class ErrorNotification:
    """notify_error(error_id, error_type) as a queued value."""

    error_id: str
    error_type: str
    missed: int = 0


SurfaceNotice: TypeAlias = Completed | EventNotification | ErrorNotification


class ApplicationQueue(NoticeQueue[SurfaceNotice]):
    """A bounded, async-iterable ApplicationBase: never blocks, never loses a notice untold
    (a :class:`~openel_async.observers.NoticeQueue`, as ObserverQueue is)."""

    log_prefix = "application_queue"

    def __init__(self, maxsize: int = 1024, *, name: str = "application") -> None:
        super().__init__(maxsize, name=name)

    def completed(self, command_id: str, status: ReturnCode) -> None:
        self.put_nowait(Completed(command_id, ReturnCode(status)))

    def notify_event(self, event_id: str, event_type: str, subscribe_id: int) -> None:
        self.put_nowait(EventNotification(event_id, event_type, subscribe_id))

    def notify_error(self, error_id: str, error_type: str) -> None:
        self.put_nowait(ErrorNotification(error_id, error_type))

    def __aiter__(self) -> ApplicationQueue:
        return self


class Delivery:
    """Calls one application's methods: plain ones inline, async ones through a bounded
    mailbox drained by a task of the surface's task group (oldest dropped when full,
    counted in ``dropped``)."""

    def __init__(self, application: object, task_group: anyio.abc.TaskGroup, size: int = 1024):
        methods = {
            name: getattr(application, name)
            for name in APPLICATION_METHODS
            if callable(getattr(application, name, None))
        }
        if not methods:
            raise BadParameterError(
                "application", application, "an object with completed, notify_event or notify_error"
            )
        self.application = application
        self.methods = methods
        self.size = size
        self.dropped = 0
        self._items: deque[tuple[Any, tuple[Any, ...]]] = deque()
        self._wakeup = anyio.Event()
        self._async = any(inspect.iscoroutinefunction(m) for m in methods.values())
        if self._async:
            task_group.start_soon(self._run)

    def call(self, name: str, *args: Any) -> None:
        method = self.methods.get(name)
        if method is None:
            return
        if self._async:
            if len(self._items) >= self.size:
                self._items.popleft()
                self.dropped += 1
                log.warning("application_mailbox_overflow", method=name, dropped=self.dropped)
            self._items.append((method, args))
            self._wakeup.set()
            return
        try:
            method(*args)
        except Exception:
            log.exception("application_method_failed", method=name)

    async def _run(self) -> None:
        while True:
            await self._wakeup.wait()
            self._wakeup = anyio.Event()
            while self._items:
                method, args = self._items.popleft()
                try:
                    result = method(*args)
                    if inspect.isawaitable(result):
                        await result
                except Exception:
                    log.exception("application_method_failed", method=method.__name__)
