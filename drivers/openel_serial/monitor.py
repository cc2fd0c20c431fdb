"""A passive monitor of a servo bus (``openel-async bus monitor RIG.yaml BUS`` on a serial
bus): the bytes heard on the line, split into packets and decoded by
:mod:`openel_serial.sniffer`, with rates and error counters; optionally a capture file.

Where the bytes come from:

* :func:`listen_port`: a second adapter on the same RS-485/TTL line (``--port``), opened and
  only read -- a serial bus cannot be shared with the driver's own adapter, so this is the
  one way to watch a running app on real hardware; the reads run in a worker thread, each
  bounded;
* :class:`TapRelay` (``--sim``): a pty between the driver and the simulated servos that
  forwards both directions and hands every chunk, in the order it passed, to the same
  decoder (it knows the direction, but the decoder is given one stream, as a second adapter
  would hear it).

``log``: a capture file of timestamped hex lines (:func:`read_capture` reads it back)::

    # openel-async bus monitor capture: serial /dev/ttyUSB1 at 1000000 baud, Feetech STS
    0.001234 ff ff 01 04 02 38 02 be

one line per chunk read (seconds since the start, then the bytes), written in a worker
thread.
"""

from __future__ import annotations

import os
import termios
import tty
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

import anyio
import anyio.abc
from anyio.streams.memory import MemoryObjectReceiveStream, MemoryObjectSendStream

from openel_async.errors import BadParameterError

from .ptypeer import PtyPeer
from .sniffer import Frame, Sniffer

__all__ = [
    "CAPTURE_HEADER",
    "SerialMonitorStats",
    "TapRelay",
    "check_capture_path",
    "listen_port",
    "monitor_stream",
    "read_capture",
]

CAPTURE_HEADER: Final = "# openel-async bus monitor capture: "
Chunk = tuple[float, bytes]
"""Bytes heard and when (seconds, the monitor's clock)."""


@dataclass
class SerialMonitorStats:
    """Counters of a serial monitor run (the CAN monitor's shape, by servo id)."""

    packets: int = 0
    bytes: int = 0
    per_id: Counter[int] = field(default_factory=Counter)
    kinds: Counter[str] = field(default_factory=Counter)
    malformed: int = 0
    checksum_errors: int = 0
    length_errors: int = 0
    dropped_bytes: int = 0
    seconds: float = 0.0

    def take(self, sniffer: Sniffer) -> None:
        c = sniffer.counters
        self.checksum_errors, self.length_errors = c.checksum_errors, c.length_errors
        self.dropped_bytes, self.malformed = c.dropped_bytes, sniffer.malformed
        self.kinds = Counter(sniffer.kinds)

    def rates(self) -> dict[int, float]:
        span = max(self.seconds, 1e-9)
        return {i: n / span for i, n in sorted(self.per_id.items())}

    def to_dict(self) -> dict[str, Any]:
        return {
            "packets": self.packets,
            "bytes": self.bytes,
            "seconds": round(self.seconds, 3),
            "malformed": self.malformed,
            "checksum_errors": self.checksum_errors,
            "length_errors": self.length_errors,
            "dropped_bytes": self.dropped_bytes,
            "kinds": dict(sorted(self.kinds.items())),
            "rates": {str(i): round(r, 2) for i, r in self.rates().items()},
        }

    def summary(self) -> str:
        span = max(self.seconds, 1e-9)
        top = sorted(self.rates().items(), key=lambda item: -item[1])[:8]
        rates = ", ".join(f"id {i} {r:.0f}/s" for i, r in top)
        return (
            f"-- {self.packets} packets in {self.seconds:.1f} s ({self.packets / span:.0f}/s, "
            f"{self.bytes / span:.0f} B/s), malformed {self.malformed}, checksum errors "
            f"{self.checksum_errors}, length errors {self.length_errors}, dropped bytes "
            f"{self.dropped_bytes}" + (f"; busiest: {rates}" if rates else "")
        )


def check_capture_path(path: str) -> str | None:
    """Why ``path`` cannot be a capture file (None: it can)."""
    if not Path(path).resolve().parent.is_dir():
        return "a file in an existing folder"
    return None


def read_capture(path: str | os.PathLike[str]) -> list[Chunk]:
    """The chunks of a capture file (comment lines skipped)."""
    out: list[Chunk] = []
    for line in Path(path).read_text(encoding="ascii").splitlines():
        if not line.strip() or line.startswith("#"):
            continue
        t, _, data = line.partition(" ")
        out.append((float(t), bytes.fromhex(data)))
    return out


def _append(path: str, lines: list[str]) -> None:
    with open(path, "a", encoding="ascii") as f:
        f.write("".join(lines))


async def monitor_stream(
    chunks: MemoryObjectReceiveStream[Chunk],
    sniffer: Sniffer,
    *,
    duration: float,
    on_frame: Callable[[Frame], None],
    on_summary: Callable[[SerialMonitorStats], None] | None = None,
    summary_every: float = 1.0,
    log: str | None = None,
    description: str = "",
) -> SerialMonitorStats:
    """Decode ``chunks`` for ``duration`` seconds: ``on_frame`` for every packet,
    ``on_summary`` every ``summary_every`` seconds; the counters at the end."""
    if not (duration > 0 and duration < float("inf")):
        raise BadParameterError("duration", duration, "a finite number of seconds > 0")
    if log is not None and (why := check_capture_path(log)) is not None:
        raise BadParameterError("log", log, why)
    stats = SerialMonitorStats()
    started = anyio.current_time()
    next_summary = started + summary_every
    pending: list[str] = []
    if log is not None:
        await anyio.to_thread.run_sync(
            Path(log).write_text, f"{CAPTURE_HEADER}{description}\n", "ascii"
        )

    def handle(t: float, data: bytes) -> None:
        stats.bytes += len(data)
        if log is not None:
            pending.append(f"{t - started:.6f} {data.hex(' ')}\n")
        for frame in sniffer.feed(data, t):
            stats.packets += 1
            if frame.servo_id is not None:
                stats.per_id[frame.servo_id] += 1
            on_frame(frame)

    async def flush() -> None:
        if log is not None and pending:
            lines = pending[:]
            pending.clear()
            with anyio.CancelScope(shield=True):
                await anyio.to_thread.run_sync(_append, log, lines)

    try:
        with anyio.move_on_after(duration):
            while True:
                with anyio.move_on_after(max(0.0, next_summary - anyio.current_time())):
                    try:
                        t, data = await chunks.receive()
                    except anyio.EndOfStream:
                        break
                    handle(t, data)
                now = anyio.current_time()
                if now >= next_summary:
                    stats.seconds = now - started
                    stats.take(sniffer)
                    await flush()
                    if on_summary is not None:
                        on_summary(stats)
                    next_summary = now + summary_every
    finally:
        stats.seconds = anyio.current_time() - started
        stats.take(sniffer)
        await flush()
    return stats


# -- sources ------------------------------------------------------------------------------


async def listen_port(
    url: str,
    baudrate: int,
    send: MemoryObjectSendStream[Chunk],
    *,
    task_status: anyio.abc.TaskStatus[None] = anyio.TASK_STATUS_IGNORED,
) -> None:
    """Read ``url`` (a second adapter on the line) until cancelled: every chunk to ``send``.
    Opened and read in worker threads, each read bounded by 50 ms; nothing is written."""
    import serial

    port = await anyio.to_thread.run_sync(
        lambda: serial.serial_for_url(url, baudrate=baudrate, timeout=0.05)
    )
    task_status.started()
    try:
        async with send:
            while True:
                data = await anyio.to_thread.run_sync(port.read, 4096)
                if data:
                    await send.send((anyio.current_time(), bytes(data)))
    finally:
        with anyio.CancelScope(shield=True):
            await anyio.to_thread.run_sync(port.close)


_RATES: Final = {
    rate: getattr(termios, f"B{rate}")
    for rate in (9600, 19_200, 38_400, 57_600, 115_200, 230_400, 460_800, 500_000, 1_000_000,
                 2_000_000, 3_000_000, 4_000_000)
    if hasattr(termios, f"B{rate}")
}  # fmt: skip


class TapRelay(PtyPeer):
    """A pty the driver opens (:attr:`path`) relayed to ``target`` (the simulated servos'
    pty): both directions forwarded, every chunk also sent to ``tap`` as it passes. The
    driver's bit rate is set on the target's tty before each chunk it sends (the simulated
    servos hear only their own rate)."""

    def __init__(self, target: str, tap: MemoryObjectSendStream[Chunk]) -> None:
        super().__init__(None, None)
        self.target = target
        self.tap = tap
        self._rate: int | None = None
        self.tapped = 0
        """Chunks the monitor could not take at once (dropped from the tap, still relayed)."""

    def _tapped(self, data: bytes) -> None:
        try:
            self.tap.send_nowait((anyio.current_time(), data))
        except anyio.WouldBlock:
            self.tapped += 1
        except (anyio.ClosedResourceError, anyio.BrokenResourceError):
            pass

    def _set_rate(self, fd: int) -> None:
        rate = self.pty.baudrate()
        if rate is None or rate == self._rate or rate not in _RATES:
            return
        attrs = termios.tcgetattr(fd)
        attrs[4] = attrs[5] = _RATES[rate]
        termios.tcsetattr(fd, termios.TCSANOW, attrs)
        self._rate = rate

    async def _serve(self) -> None:
        fd = os.open(self.target, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        try:
            tty.setraw(fd)
            async with anyio.create_task_group() as tg:
                tg.start_soon(self._from_servos, fd)
                while True:
                    data = await self.pty.read()
                    self._set_rate(fd)
                    self._tapped(data)
                    await _write_all(fd, data)
        finally:
            os.close(fd)

    async def _from_servos(self, fd: int) -> None:
        while True:
            try:
                data = os.read(fd, 4096)
            except BlockingIOError:
                await anyio.wait_readable(fd)
                continue
            self._tapped(data)
            await self.pty.write(data)


async def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    with anyio.move_on_after(1.0):
        while view:
            try:
                view = view[os.write(fd, view) :]
            except BlockingIOError:
                await anyio.wait_writable(fd)
