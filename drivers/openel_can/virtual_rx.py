"""Wake-on-put reception for python-can's ``virtual`` interface (no reader thread).

python-can's ``VirtualBus`` delivers a frame by ``put`` into a ``queue.Queue`` of every
other bus on the channel, in the sending thread; it has no file descriptor to wait on.
:func:`hook_virtual_bus` turns that queue, in place, into a :class:`WakingQueue`: each
frame put calls ``wake()`` (in the sender's thread, any thread, after releasing the
queue's lock), so a :class:`~openel_can.bus.CanBus` can read the bus in its event loop
when told (:meth:`WakingQueue.take`, or non-blocking ``recv(0)``), instead of a thread
blocking in ``recv`` and handing frames over. That saves a thread hop per frame burst
(the sender wakes the loop directly).

The queue object stays the same (its class is switched under its mutex), so a sender
that already holds it never loses a frame. It is bounded: beyond ``limit`` queued frames
a frame is dropped and counted in ``overflow`` (python-can's own ``rx_queue_size``
would make the *sender* fail instead). :meth:`WakingQueue.unhook` makes it a plain
``queue.Queue`` again (for a bus the ``CanBus`` was given and does not own).

Only an exact ``VirtualBus`` whose queue is an unbounded ``queue.Queue`` registered on
its channel is hooked; anything else returns None and the caller uses a reader thread.

:func:`virtual_sender` is the send side: ``VirtualBus.send`` without the generic
``copy.deepcopy`` (a memo dictionary and a keep-alive list per frame) and, for the usual
unbounded ``queue.Queue`` of a receiver, without ``Queue.put``'s condition wrapper; the
receivers get the same frames, stamped the same way.
"""

from __future__ import annotations

import copy
import queue
import time
from collections.abc import Callable
from typing import Any

import can
from can.interfaces import virtual

__all__ = ["WakingQueue", "hook_virtual_bus", "virtual_sender"]


class WakingQueue(queue.Queue[Any]):
    """A ``queue.Queue`` that calls ``wake()`` after every put and drops beyond ``limit``."""

    wake: Callable[[], None] | None
    limit: int
    overflow: int

    def put(self, item: Any, block: bool = True, timeout: float | None = None) -> None:
        """Queue ``item`` (never blocks: unbounded but for ``limit``), then ``wake()``.

        ``wake`` runs after the mutex is released: it may make a system call (waking the
        event loop), and a reader must not wait for the lock meanwhile.
        """
        with self.mutex:
            wake = self.wake
            if wake is not None and len(self.queue) >= self.limit:
                self.overflow += 1
                return
            self.queue.append(item)
            self.unfinished_tasks += 1
            self.not_empty.notify()
        if wake is not None:
            wake()

    def take(self, limit: int) -> list[Any]:
        """Up to ``limit`` queued frames, oldest first, under one lock (``get_nowait`` each)."""
        with self.mutex:
            queued = self.queue
            if len(queued) == 1 and limit >= 1:
                return [queued.popleft()]
            count = min(len(queued), limit)
            return [queued.popleft() for _ in range(count)]

    def unhook(self) -> None:
        """Back to a plain ``queue.Queue`` (frames queued stay queued)."""
        with self.mutex:
            self.wake = None
            self.__class__ = queue.Queue  # type: ignore[assignment]


def hook_virtual_bus(bus: can.BusABC, limit: int, wake: Callable[[], None]) -> WakingQueue | None:
    """Make ``bus``'s receive queue a :class:`WakingQueue`; None if ``bus`` does not qualify."""
    if type(bus) is not virtual.VirtualBus:
        return None
    rx = getattr(bus, "queue", None)
    channel = getattr(bus, "channel", None)
    if type(rx) is not queue.Queue or rx.maxsize != 0 or not isinstance(channel, list):
        return None
    with virtual.channels_lock:
        if not any(q is rx for q in channel):
            return None
        with rx.mutex:
            rx.__class__ = WakingQueue
            hooked: WakingQueue = rx  # type: ignore[assignment]
            hooked.limit = limit
            hooked.overflow = 0
            hooked.wake = wake
    return hooked


def virtual_sender(
    bus: can.BusABC, fast_copy: type[can.Message]
) -> Callable[[can.Message, float | None], None] | None:
    """``bus.send`` of an exact ``VirtualBus``, done as python-can does it (every other queue
    of the channel, or also its own with ``receive_own_messages``, gets a copy stamped with
    the time, the channel and ``is_rx``), with a frame of class ``fast_copy`` copied by its
    own ``__deepcopy__`` directly; None when ``bus`` does not qualify (use ``bus.send``)."""
    if type(bus) is not virtual.VirtualBus:
        return None
    vbus: virtual.VirtualBus = bus
    channel = getattr(vbus, "channel", None)
    own = getattr(vbus, "queue", None)
    if not isinstance(channel, list) or own is None or not hasattr(vbus, "_open"):
        return None
    channel_id = vbus.channel_id
    plain = queue.Queue
    deepcopy = copy.deepcopy
    wall = time.time

    def send(msg: can.Message, timeout: float | None = None) -> None:
        if not vbus._open:
            raise can.CanOperationError("Cannot operate on a closed bus")
        timestamp = msg.timestamp if vbus.preserve_timestamps else wall()
        receive_own = vbus.receive_own_messages
        fast = type(msg) is fast_copy
        all_sent = True
        for rx in channel:
            if rx is own and not receive_own:
                continue
            dup = msg.__deepcopy__(None) if fast else deepcopy(msg)
            dup.timestamp = timestamp
            dup.channel = channel_id
            dup.is_rx = rx is not own
            if type(rx) is plain and rx.maxsize <= 0:
                with rx.mutex:  # Queue.put of an unbounded queue, without its wrapper
                    rx.queue.append(dup)
                    rx.unfinished_tasks += 1
                    rx.not_empty.notify()
                continue
            try:
                rx.put(dup, block=True, timeout=timeout)
            except queue.Full:
                all_sent = False
        if not all_sent:
            raise can.CanOperationError("Could not send message to one or more recipients")

    return send
