"""Pseudo-terminal plumbing of the simulated serial peers (every protocol's).

* :class:`PtyPort`: the device end of a pty pair, reached by the driver through a stable
  symlink (like a udev ``/dev/serial/by-id`` link); unplugging closes the master (the
  driver's reads fail with EIO, as for a vanished USB adapter), plugging in again creates a
  new pty behind the same path. :meth:`PtyPort.baudrate` reads the bit rate the driver set
  on its end (a pty keeps the termios settings though it sends bytes at any speed).
* :class:`PtyPeer`: the lifecycle a peer shares (a pty, a task group, one serving task,
  plug/unplug); a peer implements ``_serve``.
* :class:`PeerThread`: hosts a peer on an event loop of its own, in a thread, so that it
  keeps answering (and its clock deciding) while the host's loop is blocked.

Peers wait on the master fd with ``anyio.wait_readable``/``wait_writable`` and use
non-blocking ``os.read``/``os.write``: they never block the event loop they run on.
"""

from __future__ import annotations

import array
import contextlib
import fcntl
import os
import shutil
import sys
import tempfile
import termios
import threading
import tty
from collections.abc import Callable
from contextlib import AbstractAsyncContextManager, AbstractContextManager, AsyncExitStack
from pathlib import Path
from types import TracebackType
from typing import Any, Final, Generic, Self, TypeVar, cast

import anyio
import anyio.abc
import anyio.from_thread
import anyio.to_thread

from openel_async.clock import Clock, default_clock

__all__ = ["WRITE_TIMEOUT_S", "PeerThread", "PtyPeer", "PtyPort"]

WRITE_TIMEOUT_S: Final = 1.0
"""Bound on a peer's wait to write a reply while the pty buffer is full."""
_TCGETS2: Final = 0x802C542A if sys.platform.startswith("linux") else None
"""Linux's ioctl reading ``struct termios2`` (any bit rate, as pyserial sets it)."""
_TERMIOS2_WORDS: Final = 11
"""``struct termios2`` in 32-bit words: 4 flags, c_line + c_cc[19], c_ispeed, c_ospeed."""
_SPEEDS: Final = {
    getattr(termios, f"B{rate}"): rate
    for rate in (
        *(1200, 2400, 4800, 9600, 19_200, 38_400, 57_600, 115_200, 230_400, 460_800),
        *(500_000, 921_600, 1_000_000, 2_000_000, 3_000_000, 4_000_000),
    )
    if hasattr(termios, f"B{rate}")
}


# -- the pty ------------------------------------------------------------------------------


class PtyPort:
    """The device end of a pty pair, reached by the driver through the symlink ``path``.

    The peer keeps its own slave fd open so the master never sees a hang-up while
    the driver has the port closed. ``path`` defaults to a link in a new temporary
    directory, removed by :meth:`remove`.
    """

    def __init__(self, path: str | Path | None = None) -> None:
        self._tmpdir: Path | None = None
        if path is None:
            self._tmpdir = Path(tempfile.mkdtemp(prefix="openel-pty-"))
            path = self._tmpdir / "tty"
        self.path = Path(path)
        self._master: int | None = None
        self._slave: int | None = None
        self.tty_name: str | None = None
        self.bytes_in = 0
        self.bytes_out = 0
        self.dropped_out = 0

    @property
    def is_open(self) -> bool:
        return self._master is not None

    def open(self) -> None:
        """Create a new pty pair (raw mode) and point ``path`` at its slave."""
        if self._master is not None:
            raise RuntimeError(f"pty {self.path} is already open")
        master, slave = os.openpty()
        tty.setraw(slave)  # no echo, no line discipline: bytes pass unchanged
        os.set_blocking(master, False)
        self._master, self._slave = master, slave
        self.tty_name = os.ttyname(slave)
        tmp_link = self.path.with_name(self.path.name + ".new")
        with contextlib.suppress(FileNotFoundError):
            tmp_link.unlink()
        tmp_link.symlink_to(self.tty_name)
        os.replace(tmp_link, self.path)  # atomic: the path always names some pty

    def baudrate(self) -> int | None:
        """The bit rate the driver set on its end (the tty's termios settings, which a pty
        keeps though it sends bytes at any speed); None when closed or unknown."""
        fd = self._slave
        if fd is None:
            return None
        try:
            if _TCGETS2 is not None:
                words = array.array("I", bytes(4 * _TERMIOS2_WORDS))
                fcntl.ioctl(fd, _TCGETS2, words)
                return int(words[-1])  # c_ospeed
            speed = termios.tcgetattr(fd)[5]
        except OSError:
            return None
        return _SPEEDS.get(speed)

    def close(self) -> None:
        """Close the pty (the driver's end sees EIO: the device is gone)."""
        master, slave = self._master, self._slave
        self._master = self._slave = None
        if master is not None:
            anyio.notify_closing(master)  # wakes a task waiting on it
            os.close(master)
        if slave is not None:
            os.close(slave)

    def remove(self) -> None:
        """Close and delete the link (and the temporary directory)."""
        self.close()
        with contextlib.suppress(FileNotFoundError):
            self.path.unlink()
        if self._tmpdir is not None:
            shutil.rmtree(self._tmpdir, ignore_errors=True)

    def _fd(self) -> int:
        if self._master is None:
            raise anyio.ClosedResourceError(f"pty {self.path} is closed")
        return self._master

    async def read(self, size: int = 4096) -> bytes:
        """Wait for bytes from the driver (raises ClosedResourceError once closed)."""
        while True:
            fd = self._fd()
            try:
                data = os.read(fd, size)
            except BlockingIOError:
                await anyio.wait_readable(fd)
                continue
            self.bytes_in += len(data)
            return data

    async def write(self, data: bytes) -> None:
        """Write every byte, waiting (bounded) while the pty buffer is full."""
        view = memoryview(data)
        with anyio.move_on_after(WRITE_TIMEOUT_S):
            while view:
                fd = self._fd()
                try:
                    written = os.write(fd, view)
                except BlockingIOError:
                    await anyio.wait_writable(fd)
                    continue
                self.bytes_out += written
                view = view[written:]
        self.dropped_out += len(view)

    def write_nowait(self, data: bytes) -> int:
        """Write what fits now and drop the rest, like a UART nobody reads; returns bytes written."""
        fd = self._fd()
        try:
            written = os.write(fd, data)
        except BlockingIOError:
            written = 0
        self.bytes_out += written
        self.dropped_out += len(data) - written
        return written


class PtyPeer:
    """Lifecycle shared by the peers: a pty, a task group and one serving task."""

    def __init__(self, path: str | Path | None, clock: Clock | None) -> None:
        self.pty = PtyPort(path)
        self.clock: Clock = clock or default_clock()
        self._stack: AsyncExitStack | None = None
        self._tg: anyio.abc.TaskGroup | None = None
        self._scope: anyio.CancelScope | None = None
        self.plugs = 0

    @property
    def path(self) -> str:
        """The tty path the driver opens (a symlink that survives unplug/plug)."""
        return str(self.pty.path)

    @property
    def plugged(self) -> bool:
        return self.pty.is_open

    async def __aenter__(self) -> Self:
        stack = AsyncExitStack()
        stack.callback(self.pty.remove)
        self._tg = await stack.enter_async_context(anyio.create_task_group())
        stack.callback(self._tg.cancel_scope.cancel)
        self._stack = stack
        try:
            self.plug()
        except BaseException:
            await stack.aclose()
            raise
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        stack, self._stack = self._stack, None
        if self._scope is not None:
            self._scope.cancel()
        if stack is not None:
            await stack.aclose()

    def plug(self) -> None:
        """Connect the device: a new pty behind ``path``, served by a new task."""
        if self._tg is None:
            raise RuntimeError("enter the peer ('async with') first")
        if self.pty.is_open:
            return
        self.pty.open()
        self.plugs += 1
        self._scope = anyio.CancelScope()
        self._tg.start_soon(self._run, self._scope)

    def unplug(self) -> None:
        """Disconnect the device: close the pty master (the driver gets EIO)."""
        if self._scope is not None:
            self._scope.cancel()
            self._scope = None
        self.pty.close()

    async def _run(self, scope: anyio.CancelScope) -> None:
        # ClosedResourceError/OSError: unplugged while waiting on the fd.
        with scope, contextlib.suppress(anyio.ClosedResourceError, OSError):
            await self._serve()

    async def _serve(self) -> None:
        raise NotImplementedError


P = TypeVar("P", bound=PtyPeer)
T = TypeVar("T")


class PeerThread(Generic[P]):
    """Hosts ``peer`` on an event loop of its own, in a thread (``async with``).

    The peer then keeps serving its pty, and its clock keeps deciding (a watchdog's
    expiry, a move's end), while the event loop that entered it is blocked -- as a real
    device does while the host stalls. Entering and leaving wait in a worker thread (the
    caller's loop is not blocked); :meth:`call` runs a function in the peer's thread
    (``plug``/``unplug``, fault injection, reading a servo's state consistently).
    """

    def __init__(self, peer: P) -> None:
        self.peer = peer
        self._portal_cm: AbstractContextManager[anyio.from_thread.BlockingPortal] | None = None
        self._portal: anyio.from_thread.BlockingPortal | None = None
        self._peer_cm: AbstractContextManager[P] | None = None
        self.thread: threading.Thread | None = None

    async def __aenter__(self) -> Self:
        await anyio.to_thread.run_sync(self._enter)
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await anyio.to_thread.run_sync(self._exit)

    def _enter(self) -> None:
        name = f"sim-peer {type(self.peer).__name__} {self.peer.path}"
        self._portal_cm = anyio.from_thread.start_blocking_portal(name=name)
        self._portal = self._portal_cm.__enter__()
        try:
            peer = cast("AbstractAsyncContextManager[P]", self.peer)
            self._peer_cm = self._portal.wrap_async_context_manager(peer)
            self._peer_cm.__enter__()
            self.thread = self._portal.call(threading.current_thread)
        except BaseException:
            self._portal_cm.__exit__(None, None, None)
            self._portal = self._portal_cm = self._peer_cm = None
            raise

    def _exit(self) -> None:
        peer_cm, portal_cm = self._peer_cm, self._portal_cm
        self._peer_cm = self._portal_cm = self._portal = None
        try:
            if peer_cm is not None:
                peer_cm.__exit__(None, None, None)
        finally:
            if portal_cm is not None:
                portal_cm.__exit__(None, None, None)

    async def call(self, func: Callable[..., T], *args: Any) -> T:
        """``func(*args)`` in the peer's thread (waited for in a worker thread)."""
        portal = self._portal
        if portal is None:
            raise RuntimeError("enter the PeerThread ('async with') first")
        return await anyio.to_thread.run_sync(portal.call, func, *args)
