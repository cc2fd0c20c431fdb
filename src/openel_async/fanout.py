"""Fan-out of notifications from one publisher to many observers.

Plain observer methods run inline, isolated by try/except. An observer with any async
method gets a bounded mailbox and a task of its own, so a slow or raising observer
never delays the publisher (a control loop) or the other observers. Order is kept per
observer; the observer list is copied on write so adding or removing observers while
a notification is being delivered is safe.
"""

from __future__ import annotations

import inspect
from collections import deque
from collections.abc import Callable
from typing import Any

import anyio
import anyio.abc
import structlog

from .errors import BadParameterError
from .observers import observer_methods

log = structlog.get_logger(__name__)


class _Mailbox:
    """The queue and task that deliver to one observer with async methods."""

    def __init__(self, fanout: Fanout, observer: object, size: int) -> None:
        self.fanout = fanout
        self.owner = fanout.owner
        self.observer = observer
        self.size = size
        self.items: deque[tuple[Callable[..., Any], tuple[Any, ...]]] = deque()
        self.wakeup = anyio.Event()
        self.dropped = 0
        self.overflowing = False
        self.closed = False
        self.idle = anyio.Event()
        self.idle.set()

    def put(self, method: Callable[..., Any], args: tuple[Any, ...]) -> None:
        if len(self.items) >= self.size:
            self.items.popleft()
            self.dropped += 1
            if not self.overflowing:  # once per episode: the publisher is a hot path
                self.overflowing = True
                log.warning(
                    "observer_mailbox_overflow",
                    owner=self.owner,
                    observer=repr(self.observer),
                    dropped_total=self.dropped,
                )
        self.items.append((method, args))
        if self.idle.is_set():
            self.idle = anyio.Event()
        self.wakeup.set()

    async def run(self) -> None:
        while True:
            while self.items:
                method, args = self.items.popleft()
                self.overflowing = False
                try:
                    result = method(*args)
                    if inspect.isawaitable(result):
                        await result
                except Exception:
                    self.fanout.failures += 1
                    log.exception("observer_failed", owner=self.owner, observer=repr(self.observer))
            self.idle.set()
            if self.closed:
                return
            self.wakeup = anyio.Event()
            if self.items:
                continue
            await self.wakeup.wait()


class _Subscriber:
    __slots__ = ("mailbox", "methods", "observer")

    def __init__(self, observer: object, methods: dict[str, Any], mailbox: _Mailbox | None):
        self.observer = observer
        self.methods = methods
        self.mailbox = mailbox


def _same(a: object, b: object) -> bool:
    if inspect.ismethod(a) and inspect.ismethod(b):
        return a.__self__ is b.__self__ and a.__func__ is b.__func__
    return a is b


def _is_async(func: object) -> bool:
    return inspect.iscoroutinefunction(func) or inspect.iscoroutinefunction(
        getattr(type(func), "__call__", None)  # noqa: B004 - async __call__ objects
    )


class Fanout:
    """Observer list of one publisher; ``publish`` never blocks and never raises."""

    def __init__(self, owner: str, kinds: tuple[str, ...], *, mailbox_size: int = 1024) -> None:
        self.owner = owner
        self.kinds = kinds
        self.mailbox_size = mailbox_size
        self._subscribers: tuple[_Subscriber, ...] = ()
        self._task_group: anyio.abc.TaskGroup | None = None
        self.failures = 0
        """Observer calls that raised, inline or in a mailbox task."""

    def __len__(self) -> int:
        return len(self._subscribers)

    def __contains__(self, observer: object) -> bool:
        return any(_same(s.observer, observer) for s in self._subscribers)

    @property
    def observers(self) -> tuple[object, ...]:
        return tuple(s.observer for s in self._subscribers)

    def bind(self, task_group: anyio.abc.TaskGroup | None) -> None:
        """Give the task group that hosts mailbox tasks (None when the owner closes)."""
        self._task_group = task_group
        if task_group is not None:
            for sub in self._subscribers:
                if sub.mailbox is not None:
                    sub.mailbox.closed = False  # reopened by a new owner context
                    task_group.start_soon(sub.mailbox.run)

    def add(self, observer: object) -> None:
        if observer is None:
            raise BadParameterError("observer", observer, "an observer, not None")
        if observer in self:
            raise BadParameterError("observer", observer, "an observer not yet registered")
        methods = observer_methods(observer, self.kinds)
        is_async = any(_is_async(m) for m in methods.values())
        mailbox = _Mailbox(self, observer, self.mailbox_size) if is_async else None
        self._subscribers = (*self._subscribers, _Subscriber(observer, methods, mailbox))
        if mailbox is not None and self._task_group is not None:
            self._task_group.start_soon(mailbox.run)

    def remove(self, observer: object) -> None:
        for sub in self._subscribers:
            if _same(sub.observer, observer):
                self._subscribers = tuple(s for s in self._subscribers if s is not sub)
                if sub.mailbox is not None:
                    # Let what was queued before removal arrive, then end the task.
                    sub.mailbox.closed = True
                    sub.mailbox.wakeup.set()
                return
        raise BadParameterError("observer", observer, "an observer registered with this publisher")

    def close(self) -> None:
        """End every mailbox task after it delivered what it holds."""
        for sub in self._subscribers:
            if sub.mailbox is not None:
                sub.mailbox.closed = True
                sub.mailbox.wakeup.set()

    def publish(self, kind: str, *args: Any) -> None:
        for sub in self._subscribers:
            method = sub.methods.get(kind)
            if method is None:
                continue
            if sub.mailbox is not None:
                sub.mailbox.put(method, args)
                continue
            try:
                method(*args)
            except Exception:
                self.failures += 1
                log.exception("observer_failed", owner=self.owner, observer=repr(sub.observer))

    def discard_pending(self) -> int:
        """Drop what async observers have not received yet; returns how many."""
        dropped = 0
        for sub in self._subscribers:
            if sub.mailbox is not None:
                dropped += len(sub.mailbox.items)
                sub.mailbox.items.clear()
        return dropped

    async def wait_delivered(self) -> None:
        """Wait until every async observer has processed what was published so far."""
        for sub in self._subscribers:
            if sub.mailbox is not None:
                await sub.mailbox.idle.wait()

    def dropped(self) -> int:
        return sum(s.mailbox.dropped for s in self._subscribers if s.mailbox is not None)
