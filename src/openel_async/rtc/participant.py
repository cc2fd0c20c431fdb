"""One component in one execution context (:class:`Participant`): its state there and its
lock (:class:`Gate`, FIFO and free of checkpoints when uncontended), and :data:`HOLDING`, the
participant whose lock the current task holds.

Used by :class:`~openel_async.rtc.context_base.ExecutionContext`.
"""

from __future__ import annotations

from collections import deque
from contextvars import ContextVar

import anyio

from .context_types import LifeCycleState
from .modes import MultiModeObject
from .rtobject import RTObject

__all__ = ["HOLDING", "Gate", "Participant"]


class Gate:
    """The lock of one participant: FIFO, and free of checkpoints when uncontended (the
    cycle takes it twice per participant and cycle, without awaiting when it is free).
    Waiters are woken in arrival order and handed the gate directly, so the cycle cannot
    overtake a lifecycle call that was already waiting."""

    __slots__ = ("held", "waiters")

    def __init__(self) -> None:
        self.held = False
        self.waiters: deque[anyio.Event] = deque()

    def try_enter(self) -> bool:
        if self.held:
            return False
        self.held = True
        return True

    async def enter(self) -> None:
        if not self.held:
            self.held = True
            return
        event = anyio.Event()
        self.waiters.append(event)
        try:
            await event.wait()
        except BaseException:
            if event.is_set():
                self.leave()  # the gate was handed to us: pass it on
            else:
                self.waiters.remove(event)
            raise

    def leave(self) -> None:
        if self.waiters:
            self.waiters.popleft().set()  # hand over: the gate stays held
        else:
            self.held = False


class Participant:
    """One component in one context: its state there and its lock."""

    __slots__ = (
        "current",
        "executed",
        "gate",
        "handle",
        "modal",
        "mode_due",
        "removed",
        "rtc",
        "state",
    )

    modal: MultiModeObject | None
    """The component when it has modes."""

    def __init__(self, rtc: RTObject, handle: int) -> None:
        self.rtc = rtc
        self.handle = handle
        self.state = LifeCycleState.INACTIVE
        self.gate = Gate()
        self.modal = rtc if isinstance(rtc, MultiModeObject) else None
        self.executed = 0
        self.removed = False
        self.current: str | None = None
        """The callback running under the lock (to recognise one cut off by a timeout)."""
        self.mode_due = False
        """An immediate mode change was taken from inside a callback: on_mode_changed
        runs when that callback returns."""


HOLDING: ContextVar[Participant | None] = ContextVar("openel_rtc_holding", default=None)
"""The participant whose lock the current task holds (a component calling back into its
own context from a callback must not wait for itself)."""
