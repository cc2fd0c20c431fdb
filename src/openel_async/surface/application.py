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
from dataclasses import dataclass, replace
from typing import Any, Protocol, TypeAlias, runtime_checkable

import anyio
import anyio.abc
import structlog

from ..errors import BadParameterError, ReturnCode

log = structlog.get_logger(__name__)

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


class ApplicationQueue:
    """A bounded, async-iterable ApplicationBase: never blocks, never loses a notice untold."""

    def __init__(self, maxsize: int = 1024, *, name: str = "application") -> None:
        if isinstance(maxsize, bool) or not isinstance(maxsize, int) or maxsize < 1:
            raise BadParameterError("maxsize", maxsize, "an int >= 1")
        self.maxsize = maxsize
        self.name = name
        self._items: deque[SurfaceNotice] = deque()
        self._wakeup: anyio.Event | None = None
        self._missed = 0
        self.missed_total = 0
        self._closed = False

    def completed(self, command_id: str, status: ReturnCode) -> None:
        self.put_nowait(Completed(command_id, ReturnCode(status)))

    def notify_event(self, event_id: str, event_type: str, subscribe_id: int) -> None:
        self.put_nowait(EventNotification(event_id, event_type, subscribe_id))

    def notify_error(self, error_id: str, error_type: str) -> None:
        self.put_nowait(ErrorNotification(error_id, error_type))

    def put_nowait(self, notice: SurfaceNotice) -> None:
        if self._closed:
            return
        if len(self._items) >= self.maxsize:
            self._items.popleft()
            if self._missed == 0:
                log.warning("application_queue_overflow", queue=self.name, maxsize=self.maxsize)
            self._missed += 1
            self.missed_total += 1
        self._items.append(notice)
        if self._wakeup is not None:
            self._wakeup.set()
            self._wakeup = None

    def report_missed(self, count: int) -> None:
        """Count notices lost before reaching this queue (e.g. on a network link)."""
        if count > 0:
            self._missed += count
            self.missed_total += count

    def close(self) -> None:
        self._closed = True
        if self._wakeup is not None:
            self._wakeup.set()
            self._wakeup = None

    def __len__(self) -> int:
        return len(self._items)

    def get_nowait(self) -> SurfaceNotice:
        if not self._items:
            raise anyio.WouldBlock
        notice = self._items.popleft()
        if self._missed:
            missed, self._missed = self._missed, 0
            log.warning("application_queue_missed", queue=self.name, missed=missed)
            notice = replace(notice, missed=missed)
        return notice

    async def get(self) -> SurfaceNotice:
        while not self._items:
            if self._closed:
                raise anyio.EndOfStream
            if self._wakeup is None:
                self._wakeup = anyio.Event()
            await self._wakeup.wait()
        return self.get_nowait()

    def drain(self) -> list[SurfaceNotice]:
        out: list[SurfaceNotice] = []
        while self._items:
            out.append(self.get_nowait())
        return out

    def __aiter__(self) -> ApplicationQueue:
        return self

    async def __anext__(self) -> SurfaceNotice:
        try:
            return await self.get()
        except anyio.EndOfStream:
            raise StopAsyncIteration from None


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
