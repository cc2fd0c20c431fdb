"""Half-duplex request/reply buses on one serial link: what every servo protocol's port shares.

A servo bus (Dynamixel Protocol 2.0, Feetech SCS/STS) carries one request at a time: every
transaction runs under one :class:`BusLock` (FIFO, an e-stop may go first); its wait for
replies is bounded by :func:`wire_time` of the bytes on the wire plus the servos' return
delays and a margin, and is a future completed (:func:`complete`) by the reception callback,
a timer or the loss of the port. The protocol ports (:class:`~openel_serial.port.DynamixelPort`,
:class:`~openel_serial.feetech_port.FeetechPort`) build on these and on
:class:`~openel_serial.link.SerialLink`.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
from collections import deque
from typing import Final

import anyio
import anyio.lowlevel

from openel_async.errors import BadParameterError

__all__ = ["BITS_PER_BYTE", "BusLock", "complete", "positive", "positive_or_none", "wire_time"]

BITS_PER_BYTE: Final = 10  # 8N1: start + 8 data + stop


def wire_time(n_bytes: int, baudrate: int) -> float:
    """Seconds to send ``n_bytes`` at ``baudrate`` (8N1)."""
    return n_bytes * BITS_PER_BYTE / baudrate


class BusLock:
    """The bus's FIFO lock: ``async with lock:`` around every transaction.

    What ``anyio.Lock(fast_acquire=True)`` does, with less work per transaction: a
    caller that finds it free takes it without yielding, after the same cancellation
    check (``checkpoint_if_cancelled``: a cancelled caller is refused before anything is
    sent); otherwise it waits on a future, in arrival order, and a release hands the
    lock to the first waiter still waiting. Unlike anyio's, it does not look up the
    current task to record or check an owner (the port is its only user and always
    releases what it took, in ``__aexit__``).
    """

    __slots__ = ("_locked", "_waiters")

    def __init__(self) -> None:
        self._locked = False
        self._waiters: deque[asyncio.Future[None]] = deque()

    def locked(self) -> bool:
        return self._locked

    async def __aenter__(self) -> None:
        await self.acquire()

    async def acquire(self, *, first: bool = False) -> None:
        """Take the lock; ``first``: ahead of every waiter (an e-stop), not in arrival order."""
        if not self._locked:  # waiters only exist while it is held
            await anyio.lowlevel.checkpoint_if_cancelled()
            if not self._locked:
                self._locked = True
                return
        waiter: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        if first:
            self._waiters.appendleft(waiter)
        else:
            self._waiters.append(waiter)
        try:
            await waiter
        except BaseException:
            if waiter.done() and not waiter.cancelled():
                self.release()  # handed over, then cancelled: pass it on
            else:
                with contextlib.suppress(ValueError):
                    self._waiters.remove(waiter)
            raise

    async def __aexit__(self, *exc_info: object) -> None:
        self.release()

    def release(self) -> None:
        waiters = self._waiters
        while waiters:
            waiter = waiters.popleft()
            if not waiter.done():
                waiter.set_result(None)  # the lock stays held: it is the waiter's now
                return
        self._locked = False


def complete(waiter: asyncio.Future[None]) -> None:
    """Wake the task waiting on ``waiter`` (once; a cancelled wait stays cancelled)."""
    if not waiter.done():
        waiter.set_result(None)


def positive(name: str, value: float, *, allow_zero: bool = False) -> float:
    allowed = "a finite number " + (">= 0" if allow_zero else "> 0")
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise BadParameterError(name, value, allowed)
    if not (math.isfinite(value) and (value >= 0 if allow_zero else value > 0)):
        raise BadParameterError(name, value, allowed)
    return float(value)


def positive_or_none(name: str, value: float | None) -> float | None:
    """None, or :func:`positive` (a finite number > 0, else BadParameterError naming ``name``)."""
    return None if value is None else positive(name, value)
