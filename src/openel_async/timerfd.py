"""A minimal ctypes binding of Linux timerfd (Python 3.11 has no os.timerfd_create).

An absolute CLOCK_MONOTONIC deadline armed on a timerfd wakes the event loop through
epoll with microsecond precision, where asyncio's own timers round up to whole
milliseconds (epoll_wait's timeout unit).

The timerfd stays registered with the loop's selector between waits (one reader callback
that resolves the waiting future), rather than registered and unregistered around every
wait as ``anyio.wait_readable`` does: two ``epoll_ctl`` calls and anyio's bookkeeping less
per tick, which halved the process CPU time of a 1 kHz timer's wake-up (issue 27). Needs
the asyncio backend, as the clocks do.
"""

from __future__ import annotations

import functools
import os
import sys
from collections.abc import Callable
from types import EllipsisType
from typing import TYPE_CHECKING, NoReturn

from .lazy import first_use

if TYPE_CHECKING:
    import asyncio
    import ctypes

CLOCK_MONOTONIC = 1
TFD_TIMER_ABSTIME = 1
TFD_NONBLOCK = os.O_NONBLOCK
TFD_CLOEXEC = getattr(os, "O_CLOEXEC", 0o2000000)

# ctypes, libc and asyncio are loaded at the first use of a timerfd (available(), a
# Timerfd, a wait), not with the module: the clocks import it, and a program that never
# waits on real time (an app printing its --help) loads neither.


@functools.cache
def _itimerspec() -> type[ctypes.Structure]:
    """``struct itimerspec`` (made on first use: ctypes is imported then)."""
    import ctypes

    class Timespec(ctypes.Structure):
        _fields_ = (("tv_sec", ctypes.c_long), ("tv_nsec", ctypes.c_long))

    class Itimerspec(ctypes.Structure):
        _fields_ = (("it_interval", Timespec), ("it_value", Timespec))

    return Itimerspec


def _load_libc() -> ctypes.CDLL | None:
    if not sys.platform.startswith("linux"):
        return None
    import ctypes
    import ctypes.util

    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        libc.timerfd_create.argtypes = (ctypes.c_int, ctypes.c_int)
        libc.timerfd_create.restype = ctypes.c_int
        spec = ctypes.POINTER(_itimerspec())
        libc.timerfd_settime.argtypes = (ctypes.c_int, ctypes.c_int, spec, spec)
        libc.timerfd_settime.restype = ctypes.c_int
    except (OSError, AttributeError):
        return None
    return libc


_libc: ctypes.CDLL | EllipsisType | None = ...
"""libc with the timerfd calls declared; None where timerfd is unavailable; ``...`` until
first needed (:func:`_bound_libc`)."""


def _bound_libc() -> ctypes.CDLL | None:
    """:data:`_libc`, loaded on the first call."""
    global _libc
    if _libc is ...:
        _libc = _load_libc()
    return _libc


def available() -> bool:
    """True where timerfd can be used (Linux with a libc that exports it)."""
    return _bound_libc() is not None


def _raise_errno() -> NoReturn:
    import ctypes

    err = ctypes.get_errno()
    raise OSError(err, os.strerror(err))


_running_loop: Callable[[], asyncio.AbstractEventLoop] = first_use(
    globals(), "_running_loop", "asyncio", "get_running_loop"
)
"""``asyncio.get_running_loop``, bound at the first wait (asyncio imported then)."""


class Timerfd:
    """One timerfd on CLOCK_MONOTONIC, re-armed with an absolute deadline per wait."""

    def __init__(self) -> None:
        self._fd: int | None = None  # set first: __del__ runs even when __init__ raises
        bound = _bound_libc()
        if bound is None:
            raise OSError("timerfd is not available on this platform")
        import ctypes

        fd = bound.timerfd_create(CLOCK_MONOTONIC, TFD_NONBLOCK | TFD_CLOEXEC)
        if fd < 0:
            _raise_errno()
        self._fd = fd
        # What each arm takes, bound once: the call, the struct passed by reference and
        # its it_value field (a view into the struct, set in place).
        self._settime = bound.timerfd_settime
        self._spec = _itimerspec()()
        self._spec_ref = ctypes.byref(self._spec)
        self._value = self._spec.it_value
        self._loop: asyncio.AbstractEventLoop | None = None
        """The loop the fd is registered with (a reader), None when not registered."""
        self._waiter: asyncio.Future[None] | None = None

    def fileno(self) -> int:
        if self._fd is None:
            raise ValueError("timerfd is closed")
        return self._fd

    @property
    def registered(self) -> bool:
        """Whether the fd is registered with an event loop (from a wait until it expires
        with nobody waiting, or is closed)."""
        return self._loop is not None

    def arm_absolute(self, deadline_ns: int) -> None:
        """Fire once at ``deadline_ns`` of CLOCK_MONOTONIC (time.monotonic_ns)."""
        value = self._value
        value.tv_sec, value.tv_nsec = divmod(max(deadline_ns, 1), 1_000_000_000)
        if self._settime(self.fileno(), TFD_TIMER_ABSTIME, self._spec_ref, None):
            _raise_errno()

    async def wait_until(self, deadline_ns: int) -> None:
        """Sleep until the deadline; cancellable like any anyio wait."""
        self.arm_absolute(deadline_ns)
        fd = self.fileno()
        loop = _running_loop()
        if self._loop is not loop:
            self._unregister()
            loop.add_reader(fd, self._on_readable)
            self._loop = loop
        while True:
            future = self._waiter = loop.create_future()
            try:
                await future
            finally:
                self._waiter = None
            try:
                os.read(fd, 8)  # the expiration count; reading it re-arms readability
                return
            except BlockingIOError:  # spurious wake-up
                continue

    def _on_readable(self) -> None:
        waiter = self._waiter
        if waiter is None:
            # Expired with nobody waiting (a wait cancelled while armed): unregister, or
            # the level-triggered reader would run on every loop pass; the next wait
            # registers again.
            self._unregister()
        elif not waiter.done():
            waiter.set_result(None)

    def _unregister(self) -> None:
        loop, self._loop = self._loop, None
        if loop is not None and self._fd is not None and not loop.is_closed():
            loop.remove_reader(self._fd)

    def close(self) -> None:
        if self._fd is not None:
            self._unregister()
            fd, self._fd = self._fd, None
            os.close(fd)

    def __del__(self) -> None:
        self.close()


class TimerfdCall:
    """``callback()`` at an absolute CLOCK_MONOTONIC deadline, called by the asyncio event
    loop itself when its timerfd becomes readable (a reader callback: no task, no wake-up of
    a sleeping task, one loop pass per call); re-armed at the deadline ``callback`` returns
    (an int), else closed. The timerfd stays registered with the loop between calls."""

    __slots__ = ("_callback", "_fd", "_loop")

    def __init__(
        self,
        loop: asyncio.AbstractEventLoop,
        deadline_ns: int,
        callback: Callable[[], int | None],
    ) -> None:
        self._loop = loop
        self._callback = callback
        self._fd: Timerfd | None = Timerfd()
        self._fd.arm_absolute(deadline_ns)
        loop.add_reader(self._fd.fileno(), self._fire)

    def _fire(self) -> None:
        fd = self._fd
        if fd is None:
            return
        try:
            os.read(fd.fileno(), 8)  # the expiration count
        except BlockingIOError:  # spurious wake-up
            return
        try:
            again = self._callback()
        except BaseException:
            self.cancel()
            raise
        if again is None:
            self.cancel()
        elif self._fd is not None:  # not cancelled by the callback
            self._fd.arm_absolute(again)

    def cancel(self) -> None:
        fd, self._fd = self._fd, None
        if fd is not None:
            self._loop.remove_reader(fd.fileno())
            fd.close()
