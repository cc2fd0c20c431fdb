"""Fan-out of notifications from one publisher to many observers.

Plain observer methods run inline, isolated by try/except. An observer with any async
method gets a bounded mailbox and a task of its own, so a slow or raising observer
never delays the publisher (a control loop) or the other observers. Order is kept per
observer. Observers are kept in a dict; ``publish`` delivers from a per-kind tuple of
targets, extended on registration while short (so that a component's first
notification pays nothing for it) and otherwise rebuilt on the first notification after
a change (registration stays O(1)), so adding or removing observers while one is being
delivered is safe. A component calls its plain observers from its own loop
(:attr:`Fanout.direct`), one call less per notice.
Mailbox tasks that wait for work wait on one shared event per publisher, set once per
notification, rather than each on an event of its own.

Nothing is lost untold: a notice a mailbox drops (overflow, :meth:`Fanout.discard_pending`,
:meth:`Fanout.abandon` at exit) is counted in :meth:`Fanout.stats`, logged, and reported
to the observer with the next notice it gets (the notice's ``missed`` field, for an
observer method that accepts the notice as an extra argument).
"""

from __future__ import annotations

import inspect
from collections import deque
from collections.abc import Callable
from dataclasses import replace
from inspect import isawaitable
from types import CoroutineType, MethodType
from typing import TYPE_CHECKING, Any

import anyio
import anyio.abc

from openel_async.logs import get_logger

from .errors import BadParameterError
from .observers import Notice, Route, observer_routes
from .stats import MailboxStats, ObserverStats
from .wakeup import Wakeup

if TYPE_CHECKING:
    from .listeners import ComponentListener

log = get_logger(__name__)

# What a mailbox holds per notification: (kind, spec arguments, notice or None). One
# tuple per publish, shared by every mailbox that receives it.
_Entry = tuple[str, tuple[Any, ...], Notice | None]
# What publish calls per observer of a kind: (method, takes the notice, mailbox, observer).
_Target = tuple[Callable[..., Any], bool, "_Mailbox | None", object]


_APPEND_LIMIT = 32
"""Observers of one kind up to which a registration extends the delivery tuple at once."""


class _Mailbox:
    """The queue and task that deliver to one observer with async methods."""

    # Slots: read once per notice by the publisher and the task (no instance dict).
    __slots__ = (
        "__weakref__",
        "abandoned",
        "busy",
        "closed",
        "delivered",
        "discarded",
        "fanout",
        "idle",
        "items",
        "missed",
        "observer",
        "overflowed",
        "owner",
        "queued",
        "routes",
        "size",
    )

    def __init__(
        self, fanout: Fanout, observer: object, routes: dict[str, Route], size: int
    ) -> None:
        self.fanout = fanout
        self.owner = fanout.owner
        self.observer = observer
        self.routes = routes
        self.size = size
        self.items: deque[_Entry] = deque()
        self.queued = 0
        self.delivered = 0
        self.overflowed = 0
        self.discarded = 0
        self.abandoned = 0
        self.missed = 0
        # Dropped since the last delivery: reported with the next notice delivered.
        self.busy = False
        self.closed = False
        self.idle: anyio.Event | None = None
        # Set when the mailbox is empty and nothing is being delivered; created only for
        # wait_idle (not on every notice).

    def put(self, entry: _Entry) -> None:
        self.queued += 1
        if len(self.items) >= self.size:
            self.items.popleft()
            self.overflowed += 1
            self.fanout.overflowed += 1
            if not self.missed:  # once per episode: the publisher is a hot path
                log.warning(
                    "observer_mailbox_overflow",
                    owner=self.owner,
                    observer=repr(self.observer),
                    size=self.size,
                    overflowed_total=self.overflowed,
                )
            self.missed += 1
        self.items.append(entry)

    def drop_all(self) -> int:
        """Empty the mailbox; the dropped notices count as missed for the next one."""
        count = len(self.items)
        self.items.clear()
        self.missed += count
        return count

    def snapshot(self) -> MailboxStats:
        return MailboxStats(
            observer=self.observer,
            queued=self.queued,
            delivered=self.delivered,
            pending=len(self.items),
            overflowed=self.overflowed,
            discarded=self.discarded,
            abandoned=self.abandoned,
        )

    async def wait_idle(self) -> None:
        """Until what the mailbox holds now was delivered (its task must be running)."""
        while self.items or self.busy:
            if self.idle is None:
                self.idle = anyio.Event()
            await self.idle.wait()

    def _set_idle(self) -> None:
        idle = self.idle
        if idle is not None:
            self.idle = None
            idle.set()

    async def run(self) -> None:
        self.busy = False  # (re)started by bind: nothing is being delivered yet
        fanout = self.fanout
        items = self.items
        popleft = items.popleft
        routes = self.routes
        wakeup = fanout.wakeup
        while True:
            while items:
                kind, args, notice = popleft()
                method, with_notice = routes[kind]
                missed = self.missed
                if missed:
                    self.missed = 0
                    log.warning(
                        "observer_missed",
                        owner=self.owner,
                        observer=repr(self.observer),
                        missed=missed,
                    )
                    if notice is not None:
                        notice = replace(notice, missed=notice.missed + missed)
                self.busy = True
                try:
                    result = method(*args, notice) if with_notice else method(*args)
                    if result is not None and (
                        type(result) is CoroutineType or isawaitable(result)
                    ):
                        await result
                except Exception:
                    fanout.failures += 1
                    log.exception("observer_failed", owner=self.owner, observer=repr(self.observer))
                self.busy = False
                self.delivered += 1
            if self.idle is not None:
                self._set_idle()
            if self.closed:
                fanout.leaving.discard(self)
                return
            # fanout.work() inlined (one coroutine frame less per notice)
            future = wakeup.arm()
            try:
                await future
            except BaseException:
                wakeup.disarm(future)
                raise


class _Subscriber:
    __slots__ = ("mailbox", "observer", "routes")

    def __init__(self, observer: object, routes: dict[str, Route], mailbox: _Mailbox | None):
        self.observer = observer
        self.routes = routes
        self.mailbox = mailbox


def _key(observer: object) -> object:
    """Identity of an observer: a bound method is the same observer each time it is taken
    from its object (``obj.method`` builds a new method object)."""
    if isinstance(observer, MethodType):
        return (id(observer.__self__), id(observer.__func__))
    return id(observer)


def _is_async(func: object) -> bool:
    return inspect.iscoroutinefunction(func) or inspect.iscoroutinefunction(
        getattr(type(func), "__call__", None)  # noqa: B004 - async __call__ objects
    )


class Fanout:
    """Observer list of one publisher; ``publish`` never blocks and never raises."""

    # Slots: a component's per-event path reads a few of these (compact, and no
    # instance dict to look them up in: it runs once per event per component).
    __slots__ = (
        "__weakref__",
        "_by_key",
        "_notice_kinds",
        "_snapshot",
        "_targets",
        "_task_group",
        "abandoned",
        "direct",
        "discarded",
        "failures",
        "kinds",
        "leaving",
        "listener",
        "mailbox_size",
        "overflowed",
        "owner",
        "published",
        "unpublished",
        "wakeup",
        "wants_notice",
    )

    def __init__(self, owner: str, kinds: tuple[str, ...], *, mailbox_size: int = 1024) -> None:
        self.owner = owner
        self.kinds = kinds
        self.mailbox_size = mailbox_size
        self._by_key: dict[object, _Subscriber] = {}
        """Registered observers in registration order, by :func:`_key`."""
        self._snapshot: tuple[_Subscriber, ...] | None = ()
        """The registered observers as a tuple (None: rebuilt when next needed)."""
        self._targets: dict[str, tuple[_Target, ...]] = dict.fromkeys(kinds, ())
        """Per kind: (method, takes the notice, mailbox) of each observer, for ``publish``;
        emptied by every change and rebuilt by the next notification."""
        self.direct: dict[str, tuple[tuple[Callable[..., Any], ...], bool]] = dict.fromkeys(
            kinds, ((), False)
        )
        """Per kind whose every observer is plain (no mailbox) and either all or none take
        the notice: (their methods, whether they take it), for a publisher's inline loop (a
        component's events: one call less per notice). A kind is absent while its observers
        are not all alike, and after a removal until ``publish`` rebuilt its targets."""
        self._notice_kinds: dict[str, int] = {}
        """Per kind, how many observers take the notice."""
        self.wakeup = Wakeup()
        """Set by the next notification for mailbox tasks waiting for work (reused: no
        anyio.Event per notification)."""
        self._task_group: anyio.abc.TaskGroup | None = None
        self.published = 0
        """Notifications published (each to every observer registered for its kind)."""
        self.failures = 0
        """Observer calls that raised, inline or in a mailbox task."""
        self.overflowed = 0
        self.discarded = 0
        self.abandoned = 0
        self.unpublished = 0
        """Notifications the owner did not publish because of its state (components)."""
        self.wants_notice: frozenset[str] = frozenset()
        """Kinds for which some observer takes the notice: publishers build it only then."""
        self.leaving: set[_Mailbox] = set()
        """Mailboxes of removed observers still delivering what was queued before."""
        self.listener: ComponentListener | None = None
        """The owner's :class:`~openel_async.listeners.ComponentListener` (components only):
        kept here so that a component needs no instance attribute of its own for it."""

    def _subscribers(self) -> tuple[_Subscriber, ...]:
        snapshot = self._snapshot
        if snapshot is None:
            snapshot = self._snapshot = tuple(self._by_key.values())
        return snapshot

    def __len__(self) -> int:
        return len(self._by_key)

    def __contains__(self, observer: object) -> bool:
        return _key(observer) in self._by_key

    @property
    def observers(self) -> tuple[object, ...]:
        return tuple(s.observer for s in self._subscribers())

    def bind(self, task_group: anyio.abc.TaskGroup | None) -> None:
        """Give the task group that hosts mailbox tasks (None when the owner closes)."""
        self._task_group = task_group
        if task_group is not None:
            for sub in self._subscribers():
                if sub.mailbox is not None:
                    sub.mailbox.closed = False  # reopened by a new owner context
                    task_group.start_soon(sub.mailbox.run)

    def add(self, observer: object) -> None:
        if observer is None:
            raise BadParameterError("observer", observer, "an observer, not None")
        key = _key(observer)
        if key in self._by_key:
            raise BadParameterError("observer", observer, "an observer not yet registered")
        routes = observer_routes(observer, self.kinds)
        is_async = any(_is_async(method) for method, _ in routes.values())
        mailbox = _Mailbox(self, observer, routes, self.mailbox_size) if is_async else None
        self._by_key[key] = _Subscriber(observer, routes, mailbox)
        self._changed(routes, 1)
        self._append_targets(key, routes, mailbox)
        if mailbox is not None and self._task_group is not None:
            self._task_group.start_soon(mailbox.run)

    def remove(self, observer: object) -> None:
        sub = self._by_key.pop(_key(observer), None)
        if sub is None:
            raise BadParameterError(
                "observer", observer, "an observer registered with this publisher"
            )
        self._changed(sub.routes, -1)
        if sub.mailbox is not None:
            # Let what was queued before removal arrive, then end the task.
            sub.mailbox.closed = True
            self._wake()
            if self._task_group is not None:
                self.leaving.add(sub.mailbox)

    def _changed(self, routes: dict[str, Route], sign: int) -> None:
        """An observer with ``routes`` was added (+1) or removed (-1): O(kinds)."""
        self._snapshot = None
        if sign < 0:  # rebuilt by the next notification of each kind
            self._targets = {}
            self.direct = {}
        counts = self._notice_kinds
        for kind, (_, wants) in routes.items():
            if wants:
                counts[kind] = counts.get(kind, 0) + sign
        self.wants_notice = frozenset(kind for kind, count in counts.items() if count > 0)

    def _append_targets(
        self, key: object, routes: dict[str, Route], mailbox: _Mailbox | None
    ) -> None:
        """A new observer: appended to the targets already built (a tuple copy, no rebuild),
        so that a publisher's first notification after registering pays nothing extra; past
        ``_APPEND_LIMIT`` observers of a kind, its targets are rebuilt when next needed."""
        targets_of = self._targets
        direct_of = self.direct
        for kind, (method, wants) in routes.items():
            targets = targets_of.get(kind)
            if targets is None:
                continue  # built when next needed
            if len(targets) >= _APPEND_LIMIT:  # copying would make N registrations O(N^2)
                del targets_of[kind]
                direct_of.pop(kind, None)
                continue
            targets_of[kind] = (*targets, (method, wants, mailbox, self._by_key[key].observer))
            direct = direct_of.get(kind)
            if direct is None:
                continue
            methods, takes_notice = direct
            if mailbox is None and (not methods or takes_notice == wants):
                direct_of[kind] = ((*methods, method), wants)
            else:
                del direct_of[kind]

    def _build_targets(self, kind: str) -> tuple[_Target, ...]:
        targets = tuple(
            (route[0], route[1], sub.mailbox, sub.observer)
            for sub in self._subscribers()
            if (route := sub.routes.get(kind)) is not None
        )
        self._targets[kind] = targets
        if targets and all(target[2] is None for target in targets):
            wants = {target[1] for target in targets}
            if len(wants) == 1:
                self.direct[kind] = (tuple(target[0] for target in targets), wants.pop())
        return targets

    def direct_for(self, kind: str) -> tuple[tuple[Callable[..., Any], ...], bool] | None:
        """:attr:`direct` of ``kind``, its targets rebuilt first if a change emptied them."""
        if kind not in self._targets:
            self._build_targets(kind)
        return self.direct.get(kind)

    def mailbox_puts(self, kind: str) -> tuple[Callable[[Any], None], ...] | None:
        """When every observer of ``kind`` has a mailbox and none takes the notice: their
        mailboxes' ``put`` in registration order, for a publisher's own loop (with
        :meth:`mailbox_entry`, and :attr:`wakeup` set first); otherwise None."""
        targets = self._targets.get(kind)
        if targets is None:
            targets = self._build_targets(kind)
        if not targets or any(mailbox is None or wants for _, wants, mailbox, _ in targets):
            return None
        return tuple(mailbox.put for _, _, mailbox, _ in targets if mailbox is not None)

    @staticmethod
    def mailbox_entry(kind: str, args: tuple[Any, ...]) -> object:
        """What :meth:`publish` puts in the mailboxes for ``kind`` with ``args`` and no
        notice (immutable: a publisher may reuse it)."""
        return (kind, args, None)

    def failed(self, method: Callable[..., Any]) -> None:
        """A plain observer's ``method`` raised (called from a :attr:`direct` loop, in the
        ``except`` block)."""
        self.failures += 1
        observer = getattr(method, "__self__", method)
        log.exception("observer_failed", owner=self.owner, observer=repr(observer))

    async def work(self) -> None:
        """Wait (a mailbox task) until the next notification or change."""
        work = self.wakeup
        work.clear()  # only a notification from now on wakes this task
        await work.wait()

    def _wake(self) -> None:
        work = self.wakeup
        if work.waiter is not None:  # a task waits (Wakeup.waiting, without a call)
            work.set()

    def close(self) -> None:
        """End every mailbox task after it delivered what it holds."""
        for sub in self._subscribers():
            if sub.mailbox is not None:
                sub.mailbox.closed = True
        self._wake()

    def publish(self, kind: str, *args: Any, notice: Notice | None = None) -> None:
        """Deliver ``observer.<kind>(*args)`` to every observer registered for ``kind``.

        ``notice`` is passed as one more argument to the methods that accept it (build it
        only when ``kind in self.wants_notice``); it is shared, never copied, except when
        a mailbox reports missed notices with it.
        """
        self.published += 1
        targets = self._targets.get(kind)
        if targets is None:
            targets = self._build_targets(kind)
        entry: _Entry | None = None
        for method, with_notice, mailbox, observer in targets:
            if mailbox is not None:
                if entry is None:
                    entry = (kind, args, notice)
                    # Wake the mailbox tasks now, not after the plain observers below: a
                    # task a plain observer wakes must not run before an async observer
                    # registered ahead of it (the registration order of delivery).
                    self._wake()
                mailbox.put(entry)
                continue
            try:
                if with_notice:
                    method(*args, notice)
                else:
                    method(*args)
            except Exception:
                self.failures += 1
                log.exception("observer_failed", owner=self.owner, observer=repr(observer))

    def discard_pending(self) -> int:
        """Drop what async observers have not received yet (StopTimer); returns how many.

        Counted as ``discarded`` and reported as ``missed`` with the next notice.
        """
        total = 0
        for sub in self._subscribers():
            mailbox = sub.mailbox
            if mailbox is not None and mailbox.items:
                count = mailbox.drop_all()
                mailbox.discarded += count
                total += count
        self.discarded += total
        return total

    def _mailboxes(self) -> list[_Mailbox]:
        """Every mailbox with a task: registered observers', then removed ones' (leaving)."""
        mailboxes = [s.mailbox for s in self._subscribers() if s.mailbox is not None]
        registered = set(mailboxes)
        return mailboxes + [m for m in self.leaving if m not in registered]

    def abandon(self) -> int:
        """What async observers still hold when the owner stops waiting for them at exit:
        the queued notices and the one whose delivery is about to be cancelled (observers
        removed but still delivering what was queued before included).

        Each observer's count is logged (warning) and added to ``abandoned``; returns the
        total.
        """
        total = 0
        for mailbox in self._mailboxes():
            count = mailbox.drop_all()
            if mailbox.busy:  # cut short by the cancellation that follows
                mailbox.busy = False
                mailbox.missed += 1
                count += 1
            if count:
                mailbox.abandoned += count
                total += count
                log.warning(
                    "observer_notices_abandoned",
                    owner=self.owner,
                    observer=repr(mailbox.observer),
                    abandoned=count,
                )
        self.leaving.clear()  # their tasks are cancelled with the owner's
        self.abandoned += total
        return total

    async def wait_delivered(self) -> None:
        """Wait until every async observer (and every removed one still delivering) has
        processed what was published so far."""
        for mailbox in self._mailboxes():
            await mailbox.wait_idle()

    async def drain(self, timeout_s: float) -> int:
        """Close the mailboxes and give async observers ``timeout_s`` seconds (shielded
        from cancellation) to handle what they hold; then :meth:`abandon` the rest.

        Returns how many notices were abandoned.
        """
        self.close()
        with anyio.CancelScope(shield=True), anyio.move_on_after(timeout_s):
            await self.wait_delivered()
        return self.abandon()

    def stats(self) -> ObserverStats:
        return ObserverStats(
            published=self.published,
            failures=self.failures,
            overflowed=self.overflowed,
            discarded=self.discarded,
            abandoned=self.abandoned,
            mailboxes=tuple(s.mailbox.snapshot() for s in self._subscribers() if s.mailbox),
            unpublished=self.unpublished,
        )
