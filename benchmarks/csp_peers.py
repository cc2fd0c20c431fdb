"""The canopen_csp benchmark's simulated CiA 402 drives, in a child process.

``python -m benchmarks.csp_peers FD 1,2,3,4`` serves
:class:`~openel_can.sim.cia402.SimCia402Drive` peers on one end of an
``AF_UNIX``/``SOCK_SEQPACKET`` socket pair (:class:`benchmarks.can_peers.SocketPairBus`, one
CAN frame per datagram, as on ``socketcan``), prints ``ready``, and serves until its stdin is
closed; then it prints one line: the CPU seconds the process used and the time
(the kernel's receive timestamp, ``SO_TIMESTAMPNS``, in ns of CLOCK_REALTIME) of each SYNC
frame (COB-ID 0x080): when the master's ``send`` put it on the socket pair, the "wire".
It measures the master that sent the SYNC and nothing of the drives' own work (nor how late
the drives' process read it), which stays out of the master's process (its CPU time and
its GIL). :class:`CspPeersProcess` starts it.
"""

from __future__ import annotations

import logging
import os
import select
import socket
import struct
import subprocess
import sys
import time
from collections.abc import Sequence
from types import TracebackType
from typing import Any

import anyio
import can
import structlog

from openel_can import CanBus
from openel_can.sim.cia402 import SimCia402Drive

from .can_peers import EFF_FLAG, FRAME, RTR_FLAG, SocketPairBus

SYNC_COB_ID = 0x080
SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)
"""Linux: the kernel stamps each received datagram (a ``struct timespec`` in a cmsg)."""
_TIMESPEC = struct.Struct("@ll")
_CMSG_SPACE = socket.CMSG_SPACE(_TIMESPEC.size)
START_TIMEOUT_S = 20.0
SEND_BUFFER = 8 << 20
REALTIME_PRIORITY = 10
"""SCHED_FIFO priority of the master process during a round (when permitted)."""


class _StampingBus(SocketPairBus):
    """Keeps the kernel's timestamp of each SYNC frame (``SO_TIMESTAMPNS``: taken when the
    master's ``send`` queued the datagram, CLOCK_REALTIME), whatever the drives' process
    was doing then: the frame's time on the wire, as a socketcan adapter stamps it."""

    def __init__(self, sock: socket.socket, **kwargs: Any) -> None:
        sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
        super().__init__(sock, **kwargs)
        self._raw = sock
        self.sync_stamps: list[int] = []

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        sock = self._raw
        try:
            data, ancdata, _, _ = sock.recvmsg(FRAME.size, _CMSG_SPACE)
        except BlockingIOError:
            if timeout == 0:
                return None, False
            readable, _, _ = select.select([sock], [], [], timeout)
            if not readable:
                return None, False
            try:
                data, ancdata, _, _ = sock.recvmsg(FRAME.size, _CMSG_SPACE)
            except BlockingIOError:
                return None, False
        except OSError as exc:
            raise can.CanOperationError(f"recv failed: {exc}") from exc
        if not data:
            raise can.CanOperationError("the other end closed the socket pair")
        can_id, dlc, payload = FRAME.unpack(data)
        stamp = 0
        for level, kind, value in ancdata:
            if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS:
                seconds, nanoseconds = _TIMESPEC.unpack(value[: _TIMESPEC.size])
                stamp = seconds * 1_000_000_000 + nanoseconds
        if can_id & 0x1FFF_FFFF == SYNC_COB_ID:
            self.sync_stamps.append(stamp or time.time_ns())
        msg = can.Message(
            arbitration_id=can_id & 0x1FFF_FFFF,
            is_extended_id=bool(can_id & EFF_FLAG),
            is_remote_frame=bool(can_id & RTR_FLAG),
            dlc=dlc,
            data=payload[:dlc],
            check=False,
        )
        return msg, False


async def serve(fd: int, drives: Sequence[int]) -> None:
    raw = _StampingBus(socket.socket(fileno=fd), channel="csp-peers")
    try:
        async with (
            CanBus(raw, name="csp-peers", send_mode="inline") as bus,
            anyio.create_task_group() as tg,
        ):
            for node in drives:
                await tg.start(SimCia402Drive(node).run, bus)
            print("ready", flush=True)
            await anyio.wait_readable(sys.stdin.fileno())  # EOF: the master is done
            tg.cancel_scope.cancel()
    finally:
        raw.shutdown()
    stamps = " ".join(map(str, raw.sync_stamps))
    print(f"{time.process_time():.6f} {stamps}", flush=True)


def main(argv: Sequence[str] | None = None) -> None:
    args = sys.argv[1:] if argv is None else list(argv)
    fd, drives = int(args[0]), [int(n) for n in args[1].split(",")]
    structlog.configure(
        wrapper_class=structlog.make_filtering_bound_logger(logging.ERROR),
        logger_factory=structlog.PrintLoggerFactory(sys.stderr),
    )
    anyio.run(serve, fd, drives, backend="asyncio")


def _grow_send_buffer(sock: socket.socket, size: int = SEND_BUFFER) -> None:
    """A datagram costs ~1 KiB of the sender's buffer (the default, ~200 KiB, holds ~270
    frames): beyond the system limit where the process may (SO_SNDBUFFORCE)."""
    force = getattr(socket, "SO_SNDBUFFORCE", 32)
    try:
        sock.setsockopt(socket.SOL_SOCKET, force, size)
    except OSError:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, size)


def realtime_permitted() -> bool:
    """This process may run at SCHED_FIFO (tried and undone)."""
    try:
        old = os.sched_getscheduler(0), os.sched_getparam(0)
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(REALTIME_PRIORITY))
        os.sched_setscheduler(0, old[0], old[1])
    except (OSError, AttributeError):
        return False
    return True


class CspPeersProcess:
    """``with CspPeersProcess(nodes) as peers:`` the drives in a child process;
    ``peers.bus()`` is a python-can bus on the master's end of the socket pair (one only);
    after the block ``peers.sync_stamps_ns`` and ``peers.cpu_s`` hold what the child saw."""

    def __init__(self, drives: Sequence[int]) -> None:
        self.drives = tuple(drives)
        self.process: subprocess.Popen[str] | None = None
        self.sync_stamps_ns: list[int] = []
        self.cpu_s = 0.0
        self._sock: socket.socket | None = None
        self._affinity: set[int] = set()
        self._realtime = False

    def _pin(self, child: int) -> None:
        """The drives on the last CPU, this process (the master) on the others, at
        real-time priority (when permitted; :attr:`realtime` says): the drives
        are other devices on a real bus, and a drive process woken by every frame the master
        sends would otherwise be scheduled on the master's CPU (the kernel places a wakee
        near its waker) and take it from the master mid-cycle. Undone at exit."""
        cpus = sorted(os.sched_getaffinity(0))
        self._affinity = set(cpus)
        if len(cpus) >= 2:
            os.sched_setaffinity(child, {cpus[-1]})
            os.sched_setaffinity(0, set(cpus[:-1]))
        # The master (this thread, and the threads it starts from now on: canopen-py's
        # notifier) at real-time priority, as a CANopen master on Linux runs: its wake-ups
        # then do not wait behind the other work of a shared machine (both masters alike).
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(REALTIME_PRIORITY))
            self._realtime = True
        except (OSError, AttributeError):  # not permitted: measured at normal priority
            self._realtime = False

    def bus(self) -> SocketPairBus:
        assert self._sock is not None, "enter the CspPeersProcess first"
        return SocketPairBus(self._sock, channel="csp-master")

    def __enter__(self) -> CspPeersProcess:
        host, peer = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        for sock in (host, peer):  # room for a burst while the other side is descheduled
            _grow_send_buffer(sock)
        try:
            proc = self.process = subprocess.Popen(
                [
                    sys.executable,
                    "-m",
                    "benchmarks.csp_peers",
                    str(peer.fileno()),
                    ",".join(map(str, self.drives)),
                ],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                text=True,
                pass_fds=(peer.fileno(),),
            )
        finally:
            peer.close()
        self._sock = host
        self._pin(proc.pid)
        assert proc.stdout is not None
        ready, _, _ = select.select([proc.stdout], [], [], START_TIMEOUT_S)
        line = proc.stdout.readline().strip() if ready else ""
        if line != "ready":
            self.__exit__(None, None, None)
            raise RuntimeError(f"the CSP drives' process did not start (exit {proc.poll()})")
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        proc, self.process = self.process, None
        if proc is None:
            return
        if self._affinity:
            os.sched_setaffinity(0, self._affinity)
        if self._realtime:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        assert proc.stdin is not None and proc.stdout is not None
        proc.stdin.close()
        ready, _, _ = select.select([proc.stdout], [], [], START_TIMEOUT_S)
        line = proc.stdout.readline().split() if ready else []
        try:
            proc.wait(timeout=START_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        proc.stdout.close()
        if self._sock is not None:
            self._sock.close()
            self._sock = None
        if line:
            self.cpu_s = float(line[0])
            self.sync_stamps_ns = [int(x) for x in line[1:]]


if __name__ == "__main__":
    main()
