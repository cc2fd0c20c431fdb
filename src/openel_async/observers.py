"""Observer interfaces of OpenEL (HALObserver, TimerObserver) and ObserverQueue.

Observer methods may be plain or ``async`` functions. Each may also accept one more
positional argument after the spec's ones: the notice itself (:class:`EventNotice`,
:class:`ErrorNotice`, :class:`TimerTick`), which tells exactly which notification it is
and, in ``missed``, how many notices for this observer were dropped just before it.

An :class:`ObserverQueue` implements both interfaces with non-blocking methods and
hands the notifications to a consumer task, newest last; when it is full the oldest
entry is dropped and the consumer learns how many it missed from the ``missed`` field
of the next notice.
"""

from __future__ import annotations

import inspect
from collections import deque
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, replace
from typing import (
    TYPE_CHECKING,
    Any,
    ClassVar,
    Generic,
    Protocol,
    TypeAlias,
    TypeVar,
    runtime_checkable,
)

import anyio

from openel_async.logs import get_logger

from .errors import BadParameterError
from .wakeup import Wakeup

if TYPE_CHECKING:
    from .component import HALComponent
    from .timer import EventTimer

log = get_logger(__name__)


@runtime_checkable
class HALObserver(Protocol):
    """Receives events and errors of HAL components (plain or async methods).

    A method may take a third argument, ``notice: EventNotice | None = None`` (resp.
    ``ErrorNotice``): the notification as a value, with its ``missed`` count.
    """

    def notify_event(self, source: HALComponent, event_id: int) -> Awaitable[None] | None: ...

    def notify_error(self, source: HALComponent, error_id: int) -> Awaitable[None] | None: ...


@runtime_checkable
class TimerObserver(Protocol):
    """Receives the ticks of an EventTimer (plain or async method).

    ``notify_timer`` may take a second argument, ``tick: TimerTick | None = None``: the
    tick being delivered (index, deadline, lateness, missed counts), which an async
    observer cannot learn from ``timer.last_tick`` once it runs behind the timer.
    """

    def notify_timer(self, timer: EventTimer) -> Awaitable[None] | None: ...


# The notices are built on per-event and per-tick paths: slotted dataclasses with a plain
# __init__ (a frozen one assigns through object.__setattr__: 0.47 us per TimerTick against
# 0.11 us). They are values all the same: never assign to their fields (build a new one with
# dataclasses.replace); equal by value and hashable.


@dataclass(slots=True, unsafe_hash=True)
class EventNotice:
    """notify_event(source, event_id) as a queued value."""

    source: HALComponent
    event_id: int
    missed: int = 0
    """Notices for this observer dropped just before this one and never delivered (queue
    or mailbox overflow, ticks discarded by StopTimer, notices abandoned at exit)."""


@dataclass(slots=True, unsafe_hash=True)
class ErrorNotice:
    """notify_error(source, error_id) as a queued value."""

    source: HALComponent
    error_id: int
    missed: int = 0


@dataclass(slots=True, unsafe_hash=True)
class TimerTick:
    """One tick of an EventTimer (a value: its fields are not to be assigned)."""

    timer: EventTimer
    index: int
    """Count of periods since start; skips over missed ticks."""
    deadline_ns: int
    time_ns: int
    """Clock time at which the tick was delivered."""
    missed_ticks: int = 0
    """Periods skipped (never published) just before this tick because it was late."""
    missed: int = 0
    """Ticks published but dropped for this observer just before this one (as for
    :attr:`EventNotice.missed`)."""

    @property
    def lateness_ns(self) -> int:
        return self.time_ns - self.deadline_ns


Notice: TypeAlias = EventNotice | ErrorNotice | TimerTick


class _Counted(Protocol):
    @property
    def missed(self) -> int: ...


N = TypeVar("N", bound=_Counted)


class NoticeQueue(Generic[N]):
    """A bounded, async-iterable queue of notices that never blocks its producer and never
    loses a notice untold: when full it drops the oldest, and the next notice the consumer
    gets carries in ``missed`` how many it lost (a dataclass with a ``missed`` field).

    The base of :class:`ObserverQueue` and of the surface layer's ``ApplicationQueue``.
    """

    log_prefix: ClassVar[str] = "notice_queue"
    """Prefix of the log events (``<prefix>_overflow``, ``<prefix>_missed``)."""

    # Slots: the producer and the consumer read them once per notice (no instance dict).
    __slots__ = (
        "__weakref__",
        "_closed",
        "_items",
        "_missed",
        "_wakeup",
        "delivered",
        "maxsize",
        "missed_total",
        "name",
    )

    def __init__(self, maxsize: int = 1024, *, name: str = "queue") -> None:
        if isinstance(maxsize, bool) or not isinstance(maxsize, int) or maxsize < 1:
            raise BadParameterError("maxsize", maxsize, "an int >= 1")
        self.maxsize = maxsize
        self.name = name
        self._items: deque[N] = deque()
        self._wakeup = Wakeup()  # reused: no anyio.Event per wait
        self._missed = 0
        self.missed_total = 0
        self.delivered = 0
        self._closed = False

    # -- producer side (never blocks) -----------------------------------------------
    def put_nowait(self, notice: N) -> None:
        if self._closed:
            return
        items = self._items
        if len(items) >= self.maxsize:
            dropped = items.popleft()
            if self._missed == 0:
                log.warning(f"{self.log_prefix}_overflow", queue=self.name, maxsize=self.maxsize)
            # A dropped notice that itself reported missed ones passes them on.
            self._missed += 1 + dropped.missed
            self.missed_total += 1
        items.append(notice)
        wakeup = self._wakeup
        if wakeup.waiter is not None:  # a task waits (Wakeup.waiting, without a call)
            wakeup.set()

    def report_missed(self, count: int) -> None:
        """Count notices lost before they reached this queue (e.g. on a network link):
        the next notice reports them in ``missed``."""
        if count > 0:
            self._missed += count
            self.missed_total += count

    def close(self) -> None:
        """End iteration once the queued notices are consumed."""
        self._closed = True
        if self._wakeup.waiting:
            self._wakeup.set()

    # -- consumer side ----------------------------------------------------------------
    def __len__(self) -> int:
        return len(self._items)

    def _take(self) -> N:
        notice = self._items.popleft()
        self.delivered += 1
        if self._missed:
            missed, self._missed = self._missed, 0
            log.warning(f"{self.log_prefix}_missed", queue=self.name, missed=missed)
            notice = replace(notice, missed=notice.missed + missed)  # type: ignore[type-var]
        return notice

    def get_nowait(self) -> N:
        if not self._items:
            raise anyio.WouldBlock
        return self._take()

    async def get(self) -> N:
        """The oldest notice; waits (cancellably) while the queue is empty."""
        while not self._items:
            if self._closed:
                raise anyio.EndOfStream
            self._wakeup.clear()
            await self._wakeup.wait()
        return self._take()

    def drain(self) -> list[N]:
        """Everything queued now, oldest first."""
        out: list[N] = []
        while self._items:
            out.append(self._take())
        return out

    def __aiter__(self) -> NoticeQueue[N]:
        return self

    async def __anext__(self) -> N:
        # get() inlined: one coroutine per notice instead of two; the wait too (Wakeup.arm).
        items = self._items
        while not items:
            if self._closed:
                raise StopAsyncIteration
            wakeup = self._wakeup
            future = wakeup.arm()
            try:
                await future
            except BaseException:  # cancelled: leave the line of waiters
                wakeup.disarm(future)
                raise
        # _take() inlined too: this is the consumer's hot path.
        notice = items.popleft()
        self.delivered += 1
        if self._missed:
            missed, self._missed = self._missed, 0
            log.warning(f"{self.log_prefix}_missed", queue=self.name, missed=missed)
            notice = replace(notice, missed=notice.missed + missed)  # type: ignore[type-var]
        return notice

    def __repr__(self) -> str:
        return (
            f"{type(self).__name__}(name={self.name!r}, pending={len(self._items)}, "
            f"missed_total={self.missed_total})"
        )


class ObserverQueue(NoticeQueue[Notice]):
    """A bounded, async-iterable queue that is both a HALObserver and a TimerObserver."""

    log_prefix = "observer_queue"
    __slots__ = ()

    # Publishers pass the notice they built once for all their observers; called with
    # the spec's arguments only, the queue builds it.
    def notify_event(
        self, source: HALComponent, event_id: int, notice: EventNotice | None = None
    ) -> None:
        if notice is None:
            notice = EventNotice(source, event_id)
        items = self._items
        if self._closed or len(items) >= self.maxsize:  # the rare cases: put_nowait
            self.put_nowait(notice)
            return
        items.append(notice)  # put_nowait's common case, inlined (one call per delivery)
        wakeup = self._wakeup
        if wakeup.waiter is not None:  # a task waits (Wakeup.waiting, without a call)
            wakeup.set()

    def notify_error(
        self, source: HALComponent, error_id: int, notice: ErrorNotice | None = None
    ) -> None:
        self.put_nowait(notice if notice is not None else ErrorNotice(source, error_id))

    def notify_timer(self, timer: EventTimer, tick: TimerTick | None = None) -> None:
        if tick is None:
            tick = timer.last_tick
        if tick is not None:
            self.put_nowait(tick)

    def __aiter__(self) -> ObserverQueue:
        return self


Route: TypeAlias = tuple[Callable[..., Any], bool]
"""An observer's method for one kind, and whether it takes the notice as an extra argument."""

SPEC_PARAMETERS: dict[str, tuple[str, ...]] = {
    "notify_event": ("source", "event_id"),
    "notify_error": ("source", "error_id"),
    "notify_timer": ("timer",),
}
"""The arguments the spec gives each notify method (the notice, if taken, comes after)."""


def observer_methods(observer: Any, kinds: tuple[str, ...]) -> dict[str, Any]:
    """The notify_* methods of ``observer`` for ``kinds``; a bare callable serves one kind."""
    if isinstance(observer, type):
        name = observer.__name__
        raise BadParameterError(
            "observer", observer, f"an observer instance, not the class {name} (e.g. {name}())"
        )
    methods = {
        kind: getattr(observer, kind) for kind in kinds if callable(getattr(observer, kind, None))
    }
    if not methods and len(kinds) == 1 and callable(observer):
        methods = {kinds[0]: observer}
    if not methods:
        names = " and ".join(kinds)
        also = ", or a callable" if len(kinds) == 1 else ""
        raise BadParameterError(
            "observer", observer, f"an object with {names} (plain or async methods){also}"
        )
    return methods


def _binds(signature: inspect.Signature, count: int) -> bool:
    try:
        signature.bind(*(None,) * count)
    except TypeError:
        return False
    return True


def observer_routes(observer: Any, kinds: tuple[str, ...]) -> dict[str, Route]:
    """:func:`observer_methods`, each checked against the spec's arguments of its kind.

    A method that cannot be called with them is refused (BadParameterError naming
    ``observer``); one that can take one more positional argument gets the notice.
    Methods whose signature cannot be inspected are called with the spec's arguments.
    """
    routes: dict[str, Route] = {}
    for kind, method in observer_methods(observer, kinds).items():
        parameters = SPEC_PARAMETERS.get(kind)
        try:
            signature = inspect.signature(method)
        except (TypeError, ValueError):
            signature = None
        if parameters is None or signature is None:
            routes[kind] = (method, False)
            continue
        if not _binds(signature, len(parameters)):
            call = f"{kind}({', '.join(parameters)})"
            raise BadParameterError(
                "observer",
                observer,
                f"{call} to be callable (plus optionally the notice); its signature is {signature}",
            )
        routes[kind] = (method, _binds(signature, len(parameters) + 1))
    return routes
