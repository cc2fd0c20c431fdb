"""Simulated CAN drives in a child process, reached through a socket pair per bus.

The benchmark process and the peers' process exchange CAN frames as datagrams in the
layout of Linux's ``struct can_frame`` (16 bytes: the id with the EFF/RTR/ERR flags, the
length, 3 padding bytes, 8 data bytes) over ``AF_UNIX``/``SOCK_SEQPACKET`` socket pairs.
:class:`SocketPairBus` is the python-can bus on either end: a ``send`` is one non-blocking
``send`` system call and a ``recv`` one ``recv`` after a ``select``, as python-can's
``socketcan`` interface does on a real adapter, so a :class:`~openel_can.CanBus` over it
runs as on ``socketcan``: a reader thread, inline sends (``send_mode="inline"``).

Running the drives in another process keeps their CPU time out of the benchmark process
(a python-can ``virtual`` bus connects only threads of one process, whose peers would
also contend with the host for the GIL). ``python -m benchmarks.can_peers FD_ODRIVE FD_CIA402
--odrive 1,2 --cia402 5,6`` serves :class:`~openel_can.sim.odrive.SimODrive` peers on the
first socket and :class:`~openel_can.sim.cia402.SimCia402Drive` peers on the second,
prints ``ready`` and serves until its stdin is closed; :class:`CanPeersProcess` starts it.
"""

from __future__ import annotations

import argparse
import logging
import select
import socket
import struct
import subprocess
import sys
from collections.abc import Sequence
from contextlib import AsyncExitStack
from types import TracebackType
from typing import Any

import anyio
import can
import structlog

from openel_can import CanBus
from openel_can.sim.cia402 import SimCia402Drive
from openel_can.sim.odrive import SimODrive

FRAME = struct.Struct("=IB3x8s")
"""Linux ``struct can_frame``: can_id (with flags), len, padding, data."""
EFF_FLAG = 0x8000_0000
RTR_FLAG = 0x4000_0000
ERR_FLAG = 0x2000_0000
START_TIMEOUT_S = 20.0


class SocketPairBus(can.BusABC):
    """A python-can bus on one end of a ``SOCK_SEQPACKET`` socket pair (one frame per datagram)."""

    def __init__(self, sock: socket.socket, channel: str = "socketpair", **kwargs: Any) -> None:
        self._sock = sock
        sock.setblocking(False)
        super().__init__(channel=channel, **kwargs)
        self.channel_info = f"socket pair {channel}"

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        can_id = msg.arbitration_id
        if msg.is_extended_id:
            can_id |= EFF_FLAG
        if msg.is_remote_frame:
            can_id |= RTR_FLAG
        if msg.is_error_frame:
            can_id |= ERR_FLAG
        try:
            self._sock.send(FRAME.pack(can_id, msg.dlc, bytes(msg.data)))
        except BlockingIOError as exc:  # the CanBus retries a full buffer
            raise can.CanOperationError("Transmit buffer full") from exc
        except OSError as exc:
            raise can.CanOperationError(f"send failed: {exc}") from exc

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        try:
            data = self._sock.recv(FRAME.size)
        except BlockingIOError:
            if timeout == 0:
                return None, False
            readable, _, _ = select.select([self._sock], [], [], timeout)
            if not readable:
                return None, False
            try:
                data = self._sock.recv(FRAME.size)
            except BlockingIOError:
                return None, False
        except OSError as exc:
            raise can.CanOperationError(f"recv failed: {exc}") from exc
        if not data:
            raise can.CanOperationError("the other end closed the socket pair")
        can_id, dlc, payload = FRAME.unpack(data)
        msg = can.Message(
            arbitration_id=can_id & 0x1FFF_FFFF,
            is_extended_id=bool(can_id & EFF_FLAG),
            is_remote_frame=bool(can_id & RTR_FLAG),
            is_error_frame=bool(can_id & ERR_FLAG),
            dlc=dlc,
            data=payload[:dlc],
            check=False,
        )
        return msg, False

    def fileno(self) -> int:
        return self._sock.fileno()

    def shutdown(self) -> None:
        super().shutdown()
        self._sock.close()


def host_bus(stack: AsyncExitStack, sock: socket.socket, name: str) -> CanBus:
    """A :class:`CanBus` on the host's end of a pair (inline sends, a reader thread); the
    python-can bus is shut down when ``stack`` closes, after the CanBus."""
    bus = SocketPairBus(sock, channel=name)
    stack.callback(bus.shutdown)
    return CanBus(bus, name=name, send_mode="inline")


# -- the peers' process --------------------------------------------------------------------------


async def serve(odrive_fd: int, cia_fd: int, odrives: Sequence[int], drives: Sequence[int]) -> None:
    sock_a = socket.socket(fileno=odrive_fd)
    sock_b = socket.socket(fileno=cia_fd)
    bus_a, bus_b = SocketPairBus(sock_a, "odrive"), SocketPairBus(sock_b, "cia402")
    try:
        async with (
            CanBus(bus_a, name="peers-odrive", send_mode="inline") as can_a,
            CanBus(bus_b, name="peers-cia402", send_mode="inline") as can_b,
            anyio.create_task_group() as tg,
        ):
            for node in odrives:
                await tg.start(SimODrive(node).run, can_a)
            for node in drives:
                await tg.start(SimCia402Drive(node).run, can_b)
            print("ready", flush=True)
            await anyio.wait_readable(sys.stdin.fileno())  # EOF: the benchmark is done
            tg.cancel_scope.cancel()
    finally:
        bus_a.shutdown()
        bus_b.shutdown()


def _ids(text: str) -> list[int]:
    return [int(part) for part in text.split(",") if part.strip()]


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.can_peers")
    parser.add_argument("odrive_fd", type=int)
    parser.add_argument("cia_fd", type=int)
    parser.add_argument("--odrive", type=_ids, default=[])
    parser.add_argument("--cia402", type=_ids, default=[])
    args = parser.parse_args(argv)
    # The peers' buses go down when the benchmark closes its ends first: not worth a warning.
    structlog.configure(
        wrapper_class=structlog.make_filtering_bound_logger(logging.ERROR),
        logger_factory=structlog.PrintLoggerFactory(sys.stderr),
    )
    anyio.run(serve, args.odrive_fd, args.cia_fd, args.odrive, args.cia402, backend="asyncio")


class CanPeersProcess:
    """``with CanPeersProcess(odrives, drives) as (odrive_sock, cia_sock):`` the simulated
    drives in a child process; the host's ends of the two socket pairs."""

    def __init__(self, odrives: Sequence[int], drives: Sequence[int]) -> None:
        self.odrives = tuple(odrives)
        self.drives = tuple(drives)
        self.process: subprocess.Popen[str] | None = None

    def __enter__(self) -> tuple[socket.socket, socket.socket]:
        host_a, peer_a = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        host_b, peer_b = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        fds = (peer_a.fileno(), peer_b.fileno())
        try:
            proc = self.process = subprocess.Popen(
                [
                    sys.executable,
                    "-m",
                    "benchmarks.can_peers",
                    *map(str, fds),
                    "--odrive",
                    ",".join(map(str, self.odrives)),
                    "--cia402",
                    ",".join(map(str, self.drives)),
                ],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                text=True,
                pass_fds=fds,
            )
        finally:
            peer_a.close()
            peer_b.close()
        assert proc.stdout is not None
        ready, _, _ = select.select([proc.stdout], [], [], START_TIMEOUT_S)
        line = proc.stdout.readline().strip() if ready else ""
        if line != "ready":
            self.__exit__(None, None, None)
            host_a.close()
            host_b.close()
            raise RuntimeError(f"the CAN peers' process did not start (exit {proc.poll()})")
        return host_a, host_b

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        proc, self.process = self.process, None
        if proc is None:
            return
        if proc.stdin is not None:
            proc.stdin.close()
        try:
            proc.wait(timeout=START_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        if proc.stdout is not None:
            proc.stdout.close()


if __name__ == "__main__":
    main()
