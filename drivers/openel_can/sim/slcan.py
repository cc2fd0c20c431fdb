"""A simulated slcan adapter (Lawicel ASCII protocol, as CANable and USBtin speak it) on a pty.

:class:`SlcanAdapter` owns a pseudo-terminal pair. Its :attr:`~SlcanAdapter.port` (the slave,
``/dev/pts/N``) is what a host opens as it would open ``/dev/ttyACM0``: python-can's own
``slcan`` interface (``can.Bus(interface="slcan", channel=adapter.port, bitrate=1_000_000)``)
or a rig's bus ``{interface: slcan, channel: /dev/pts/N, bitrate: 1000000}``. The adapter
serves the master side on its own threads and bridges to a python-can bus (``virtual`` by
default) on which simulated drives answer, so the whole host stack (python-can's slcan
framing over pyserial, the termios of a real tty, :class:`~openel_can.bus.CanBus`'s reader
thread for non-virtual interfaces) runs as with a USB adapter.

Protocol subset (each command ends with CR, ``\\r``; ``\\r`` acknowledges, BEL ``\\a`` refuses):

* ``Sn`` (closed): bit rate n = 0..8: 10k 20k 50k 100k 125k 250k 500k 750k 1M;
* ``sxxyy`` (closed): SJA1000 BTR0/BTR1 (8 MHz CAN clock), the bit rate computed from it;
* ``O`` (needs a bit rate set by ``S``/``s``; acknowledged again when already open, as
  CANable does: python-can sends it twice); ``L``: open listen-only (host frames refused);
* ``C``: close (acknowledged when already closed too, as CANable does);
* ``V`` → ``Vhhss\\r`` hardware and software version (python-can's ``get_version``);
  ``v`` → ``vMMmm\\r`` firmware version (USBtin); ``N`` → ``Nxxxx\\r`` serial number
  (python-can's ``get_serial_number``);
* ``F`` (open) → ``Fxx\\r`` status flags (hex), cleared by reading;
* ``Zn`` (closed): timestamps off/on, 4 hex digits of milliseconds (0..EA5F) after each
  frame sent to the host;
* ``Mxxxxxxxx`` / ``mxxxxxxxx`` (closed): acceptance code / mask, stored (no filtering);
* ``tiiildd..`` standard data frame (id 000..7FF, dlc 0..8, 2 hex digits a byte),
  ``Tiiiiiiiildd..`` extended (id 00000000..1FFFFFFF), ``riiil`` / ``Riiiiiiiil`` remote
  frames (open).

A transmitted frame is answered ``z\\r`` (standard) or ``Z\\r`` (extended) as the Lawicel
CAN232/CANUSB and USBtin do. Frames received on the bus are sent to the host as ``t…``,
``T…``, ``r…``, ``R…`` lines (upper-case hex) while the channel is open. An empty line is
ignored (python-can sends one in place of an FD data bit rate). Everything else gets BEL:
an unknown command (CAN FD ``d``/``D``/``b``/``B`` included: a CAN 2.0 adapter), a wrong
length, a non-hex digit, an id or dlc out of range, a frame before ``O`` (or in listen-only
mode), ``S``/``s``/``Z``/``M``/``m`` while open, ``O`` while open listen-only
and ``L`` while open, ``O``/``L`` before a bit rate is set, ``S9`` and up (python-can maps
83.3 kbit/s to ``S9``, which CANable 1.x firmware refuses too), ``F`` while closed, and a line
longer than :data:`MAX_LINE` bytes. Each BEL is counted in :attr:`SlcanAdapter.stats`.

Bit rate mismatch: a real adapter cannot know the bus's bit rate; opened at the wrong rate,
it sees only error frames. Here the bus has a bit rate (``bitrate=``, default 1 Mbit/s) and
an adapter opened at another rate: acknowledges ``O`` (as the hardware does), forwards no
frame from the bus, and answers BEL to every frame the host transmits (where the hardware
would acknowledge it and then fail on the bus: the simulation reports it at once), setting
the bus-error and error-passive status flags.

Status flags (``F``, Lawicel bits): 0x01 receive FIFO full and 0x08 data overrun when frames
for the host were dropped because the host does not read (at most :data:`MAX_PENDING` bytes
wait for it); 0x20 error passive and 0x80 bus error after a bit rate mismatch.

Running it:

* in-process: ``with SlcanAdapter(peers=[SimODrive(0)]) as adapter: ...``. The adapter's
  threads (serial side, bus side) and the simulated ``peers``, each ``serve``-d on the bus
  channel in an event loop of their own thread, keep running while the host's event loop
  blocks. Hosted peers must run on the real clock (the default): their heartbeats and
  trajectories then follow wall time, as on a real bus.
* as a process: ``python -m openel_can.sim.slcan --odrive 0,1 --cia402 5 --bitrate 1000000``
  prints the pty path on its first stdout line and runs until SIGTERM or SIGINT; a host can
  be killed (``kill -9``) while the drives keep running. :class:`SlcanAdapterProcess` starts
  it for a test and stops it.

The pty: both sides are raw (no echo, no CR/LF translation). The adapter keeps the slave
open itself, so a host may close and reopen the port (or die) without the adapter seeing a
hangup; frames it does not read wait in the pty (then in a bounded buffer, then are dropped).
"""

from __future__ import annotations

import argparse
import errno
import functools
import logging
import os
import select
import signal
import subprocess
import sys
import threading
import time
import tty
import uuid
from collections import deque
from collections.abc import Callable, Sequence
from contextlib import ExitStack
from dataclasses import dataclass
from types import TracebackType
from typing import Any, Final, Protocol, Self, TypeVar

import anyio
import anyio.abc
import anyio.from_thread
import can

from openel_async.clock import VirtualClock
from openel_async.errors import BadParameterError
from openel_async.logs import get_logger

from ..errors import DecodeError

__all__ = [
    "BITRATES",
    "MAX_LINE",
    "MAX_PENDING",
    "SlcanAdapter",
    "SlcanAdapterProcess",
    "SlcanError",
    "SlcanStats",
    "StatusFlag",
    "decode_frame",
    "encode_frame",
    "main",
]

log = get_logger(__name__)
T = TypeVar("T")

OK: Final = b"\r"
BEL: Final = b"\a"
BITRATES: Final[dict[int, int]] = {
    0: 10_000,
    1: 20_000,
    2: 50_000,
    3: 100_000,
    4: 125_000,
    5: 250_000,
    6: 500_000,
    7: 750_000,
    8: 1_000_000,
}
"""``Sn`` → bit/s, as CANable (and python-can's ``slcan`` interface) number them."""
MAX_LINE: Final = 64
"""Longest command line accepted (an extended frame with 8 bytes is 27 characters)."""
MAX_PENDING: Final = 64 * 1024
"""Bytes for the host that may wait (beyond the pty's own buffer) before frames are dropped."""
BTR_CLOCK_HZ: Final = 8_000_000
_HEX: Final = frozenset(b"0123456789abcdefABCDEF")


class StatusFlag:
    """The bits of the ``F`` reply (Lawicel CAN232)."""

    RX_FIFO_FULL: Final = 0x01
    TX_FIFO_FULL: Final = 0x02
    ERROR_WARNING: Final = 0x04
    DATA_OVERRUN: Final = 0x08
    ERROR_PASSIVE: Final = 0x20
    ARBITRATION_LOST: Final = 0x40
    BUS_ERROR: Final = 0x80


class SlcanError(DecodeError):
    """A command line the adapter refuses (answered with BEL); a frame line that is not one."""


@dataclass
class SlcanStats:
    """What the adapter counted since it started."""

    commands: int = 0
    """Command lines received (empty lines not counted)."""
    errors: int = 0
    """BEL replies, for whatever reason."""
    refused: int = 0
    """Frames refused because the channel was closed or listen-only (counted in ``errors``)."""
    malformed: int = 0
    """Unknown or malformed commands (counted in ``errors``)."""
    bitrate_errors: int = 0
    """Frames not transmitted because of a bit rate mismatch (counted in ``errors``)."""
    to_bus: int = 0
    """Frames the host transmitted onto the bus."""
    to_host: int = 0
    """Frames received on the bus and queued for the host."""
    dropped: int = 0
    """Frames for the host dropped because it did not read (overrun)."""


# -- codec ------------------------------------------------------------------------------------
def _hex(text: bytes, what: str) -> int:
    if not text or not _HEX.issuperset(text):
        raise SlcanError(f"{what} {text!r} is not hexadecimal")
    return int(text, 16)


def decode_frame(line: bytes) -> can.Message:
    """The CAN frame of a ``t``/``T``/``r``/``R`` line (without its CR).

    Raises :class:`SlcanError` for a wrong length, a non-hex digit or an id/dlc out of range.
    """
    if not line or line[:1] not in (b"t", b"T", b"r", b"R"):
        raise SlcanError(f"{line[:1]!r} is not a frame command (t, T, r or R)")
    kind = line[:1]
    extended = kind in (b"T", b"R")
    remote = kind in (b"r", b"R")
    id_len = 8 if extended else 3
    if len(line) < 2 + id_len:
        raise SlcanError(f"frame {line!r} too short")
    arb_id = _hex(line[1 : 1 + id_len], "identifier")
    if arb_id > (0x1FFF_FFFF if extended else 0x7FF):
        raise SlcanError(f"identifier {arb_id:#x} out of range")
    dlc_char = line[1 + id_len : 2 + id_len]
    if len(dlc_char) != 1 or dlc_char not in b"012345678":
        raise SlcanError(f"data length {dlc_char!r} is not 0..8")
    dlc = int(dlc_char)
    body = line[2 + id_len :]
    if remote:
        if body:
            raise SlcanError(f"remote frame {line!r} carries data")
        data = b""
    else:
        if len(body) != 2 * dlc:
            raise SlcanError(f"frame {line!r}: {len(body)} hex digits of data for dlc {dlc}")
        if not _HEX.issuperset(body):
            raise SlcanError(f"data {body!r} is not hexadecimal")
        data = bytes.fromhex(body.decode())
    return can.Message(
        arbitration_id=arb_id,
        is_extended_id=extended,
        is_remote_frame=remote,
        dlc=dlc,
        data=data,
    )


def encode_frame(msg: can.Message, timestamp_ms: int | None = None) -> bytes:
    """The line (with its CR) carrying ``msg`` to the host; ``timestamp_ms`` (0..0xEA5F) if
    timestamps are on. Raises :class:`SlcanError` for CAN FD or an id/dlc out of range."""
    if msg.is_fd or msg.is_error_frame:
        raise SlcanError("CAN FD and error frames have no slcan (CAN 2.0) form here")
    ext = msg.is_extended_id
    if not 0 <= msg.arbitration_id <= (0x1FFF_FFFF if ext else 0x7FF):
        raise SlcanError(f"identifier {msg.arbitration_id:#x} out of range")
    if not 0 <= msg.dlc <= 8:
        raise SlcanError(f"dlc {msg.dlc} out of range 0..8")
    kind = ("R" if ext else "r") if msg.is_remote_frame else ("T" if ext else "t")
    text = f"{kind}{msg.arbitration_id:0{8 if ext else 3}X}{msg.dlc:d}"
    if not msg.is_remote_frame:
        text += bytes(msg.data[: msg.dlc]).hex().upper()
    if timestamp_ms is not None:
        text += f"{timestamp_ms % 60_000:04X}"
    return text.encode() + OK


def btr_bitrate(btr0: int, btr1: int, clock_hz: int = BTR_CLOCK_HZ) -> int:
    """The bit rate of SJA1000 bus timing registers BTR0/BTR1 for a CAN clock of ``clock_hz``
    (8 MHz: the SJA1000's 16 MHz crystal halved, python-can's ``BitTiming(f_clock=8_000_000)``);
    a time quantum is ``(BRP + 1) / clock_hz``."""
    brp = btr0 & 0x3F
    tseg1 = btr1 & 0x0F
    tseg2 = (btr1 >> 4) & 0x07
    quanta = 1 + (tseg1 + 1) + (tseg2 + 1)
    return round(clock_hz / ((brp + 1) * quanta))


# -- the adapter ------------------------------------------------------------------------------
class SimPeer(Protocol):
    """A simulated node: ``serve(channel, interface=..., task_status=...)`` until cancelled."""

    async def serve(
        self,
        channel: str,
        *,
        interface: str = ...,
        task_status: anyio.abc.TaskStatus[None] = ...,
    ) -> None: ...


class SlcanAdapter:
    """A simulated slcan adapter on a pty, bridged to ``channel`` of a python-can ``interface``.

    ``bitrate`` is the bus's bit rate (the adapter must be set to it, see the module
    docstring); ``peers`` are simulated nodes (e.g. :class:`~openel_can.sim.odrive.SimODrive`)
    run on ``channel`` in an event loop on a thread of the adapter. Start with :meth:`start`
    or ``with``; :attr:`port` is the pty to open. ``history`` command lines received are kept
    in :attr:`lines` (for tests).
    """

    def __init__(
        self,
        channel: str | None = None,
        *,
        interface: str = "virtual",
        bitrate: int = 1_000_000,
        peers: Sequence[SimPeer] = (),
        hardware_version: int = 10,
        software_version: int = 13,
        serial_number: str = "SIM1",
        history: int = 256,
    ) -> None:
        if bitrate not in BITRATES.values():
            raise BadParameterError("bitrate", bitrate, f"one of {sorted(BITRATES.values())}")
        for pname, version in (("hardware_version", hardware_version), ("software_version", software_version)):  # fmt: skip
            if not 0 <= version <= 99:
                raise BadParameterError(pname, version, "an int 0..99")
        if isinstance(history, bool) or not isinstance(history, int) or history < 1:
            raise BadParameterError("history", history, "an int >= 1")
        if len(serial_number) != 4 or not serial_number.isalnum():
            raise BadParameterError("serial_number", serial_number, "4 letters or digits")
        for peer in peers:
            if isinstance(getattr(peer, "clock", None), VirtualClock):
                raise BadParameterError(
                    "peers", peer, "peers on the real clock (the adapter runs in real time)"
                )
        self.channel = channel or f"slcan-sim-{uuid.uuid4().hex[:12]}"
        self.interface = interface
        self.bitrate = bitrate
        self.peers = tuple(peers)
        self.hardware_version = hardware_version
        self.software_version = software_version
        self.serial_number = serial_number
        self.stats = SlcanStats()
        self.lines: deque[bytes] = deque(maxlen=history)
        """The newest command lines received from the host (without CR)."""
        self.port = ""
        """The slave pty's path (``/dev/pts/N``), set by :meth:`start`."""
        # adapter state (guarded by _lock)
        self.adapter_bitrate: int | None = None
        self.is_open = False
        self.listen_only = False
        self.timestamps = False
        self.acceptance = (0x0000_0000, 0xFFFF_FFFF)
        self.flags = 0
        self._opened_ns = 0
        self._lock = threading.Lock()
        self._out_lock = threading.Lock()
        self._pending = bytearray()
        self._stop = threading.Event()
        self._master = self._slave = -1
        self._wake_r = self._wake_w = -1
        self._bus: can.BusABC | None = None
        self._threads: list[threading.Thread] = []
        self._stack = ExitStack()
        self._portal: anyio.from_thread.BlockingPortal | None = None
        self._started = False

    # -- life cycle -----------------------------------------------------------------------
    def start(self) -> Self:
        """Open the pty and the bus, start the threads and the peers (once)."""
        if self._started:
            raise RuntimeError("SlcanAdapter already started")
        self._started = True
        try:
            self._master, self._slave = os.openpty()
            tty.setraw(self._master)
            tty.setraw(self._slave)
            os.set_blocking(self._master, False)
            self.port = os.ttyname(self._slave)
            self._wake_r, self._wake_w = os.pipe()
            self._bus = can.Bus(interface=self.interface, channel=self.channel)
            for target, name in ((self._serve_serial, "serial"), (self._serve_bus, "bus")):
                thread = threading.Thread(
                    target=target, name=f"slcan-sim-{name}-{self.port}", daemon=True
                )
                thread.start()
                self._threads.append(thread)
            if self.peers:
                portal = self._stack.enter_context(anyio.from_thread.start_blocking_portal())
                self._portal = portal
                for peer in self.peers:
                    serve = functools.partial(peer.serve, interface=self.interface)
                    future, _ = portal.start_task(serve, self.channel)
                    self._stack.callback(future.cancel)  # runs before the portal exits
        except BaseException:
            self.close()
            raise
        log.info("slcan_sim_started", port=self.port, channel=self.channel, peers=len(self.peers))
        return self

    def call(self, func: Callable[..., T], *args: object) -> T:
        """Run ``func(*args)`` in the peers' event loop thread and return its result (fault
        injection on a hosted peer without racing its tasks), e.g.
        ``adapter.call(sim.inject_error)``."""
        if self._portal is None:
            raise RuntimeError("SlcanAdapter.call: no peers are running")
        return self._portal.call(func, *args)

    def close(self) -> None:
        """Stop the peers and the threads, close the bus and the pty (idempotent)."""
        self._stop.set()
        if self._wake_w >= 0:
            with _ignore_oserror():
                os.write(self._wake_w, b"x")
        self._stack.close()
        self._portal = None
        for thread in self._threads:
            thread.join(timeout=2.0)
        self._threads.clear()
        if self._bus is not None:
            self._bus.shutdown()
            self._bus = None
        for name in ("_master", "_slave", "_wake_r", "_wake_w"):
            fd = getattr(self, name)
            if fd >= 0:
                with _ignore_oserror():
                    os.close(fd)
                setattr(self, name, -1)

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    # -- host side ------------------------------------------------------------------------
    def _serve_serial(self) -> None:
        buffer = bytearray()
        overlong = False
        while not self._stop.is_set():
            with self._out_lock:
                want_write = bool(self._pending)
            readable, writable, _ = select.select(
                [self._master, self._wake_r], [self._master] if want_write else [], [], 0.5
            )
            if self._wake_r in readable:
                return
            if writable:
                with self._out_lock:
                    self._flush_locked()
            if self._master not in readable:
                continue
            try:
                data = os.read(self._master, 4096)
            except BlockingIOError:
                continue
            except OSError as exc:  # EIO: no slave open (cannot happen while we hold it)
                if exc.errno != errno.EIO:
                    raise
                time.sleep(0.01)
                continue
            for byte in data:
                if byte == 0x0D:
                    if overlong:
                        overlong = False
                        self._reply_error("malformed")
                    else:
                        self._command(bytes(buffer))
                    buffer.clear()
                elif byte == 0x0A and not buffer:
                    continue  # a LF after a CR (a host sending CRLF): ignored
                elif len(buffer) >= MAX_LINE:
                    overlong = True
                    buffer.clear()
                else:
                    buffer.append(byte)

    def _reply_error(self, kind: str) -> None:
        with self._lock:
            self.stats.errors += 1
            if kind == "refused":
                self.stats.refused += 1
            elif kind == "bitrate":
                self.stats.bitrate_errors += 1
            else:
                self.stats.malformed += 1
        self._emit(BEL, frame=False)

    def _command(self, line: bytes) -> None:
        if not line:
            return  # an empty line (python-can's "no FD data bit rate") is ignored
        self.lines.append(line)
        with self._lock:
            self.stats.commands += 1
        try:
            reply = self._execute(line)
        except _Refused:
            self._reply_error("refused")
        except _BitrateMismatch:
            self._reply_error("bitrate")
        except ValueError:  # SlcanError included
            self._reply_error("malformed")
        else:
            self._emit(reply, frame=False)

    def _execute(self, line: bytes) -> bytes:
        cmd, arg = line[:1], line[1:]
        if cmd in (b"t", b"T", b"r", b"R"):
            return self._transmit(line)
        with self._lock:
            if cmd in (b"O", b"L"):
                _expect(arg, b"")
                if self.is_open:  # again in the same mode: acknowledged, as CANable does
                    if self.listen_only != (cmd == b"L"):
                        raise SlcanError(f"{cmd!r} while open in the other mode")
                    return OK
                if self.adapter_bitrate is None:
                    raise SlcanError(f"{cmd!r} before a bit rate was set")
                self.is_open, self.listen_only = True, cmd == b"L"
                self._opened_ns = time.monotonic_ns()
                return OK
            if cmd == b"C":
                _expect(arg, b"")
                self.is_open = self.listen_only = False
                return OK
            if cmd == b"V":
                _expect(arg, b"")
                return f"V{self.hardware_version:02d}{self.software_version:02d}\r".encode()
            if cmd == b"v":
                _expect(arg, b"")
                return f"v{self.software_version:02d}00\r".encode()
            if cmd == b"N":
                _expect(arg, b"")
                return f"N{self.serial_number}\r".encode()
            if cmd == b"F":
                _expect(arg, b"")
                if not self.is_open:
                    raise SlcanError("F while closed")
                flags, self.flags = self.flags, 0
                return f"F{flags:02X}\r".encode()
            if self.is_open:
                raise SlcanError(f"{cmd!r} while open")
            if cmd == b"S":
                if len(arg) != 1 or arg[0] - 0x30 not in BITRATES:
                    raise SlcanError(f"S{arg!r}: bit rate code not 0..8")
                self.adapter_bitrate = BITRATES[arg[0] - 0x30]
                return OK
            if cmd == b"s":
                if len(arg) != 4:
                    raise SlcanError("s needs 4 hex digits (BTR0 BTR1)")
                btr = _hex(arg, "BTR")
                self.adapter_bitrate = btr_bitrate(btr >> 8, btr & 0xFF)
                return OK
            if cmd == b"Z":
                if arg not in (b"0", b"1"):
                    raise SlcanError("Z needs 0 or 1")
                self.timestamps = arg == b"1"
                return OK
            if cmd in (b"M", b"m"):
                if len(arg) != 8:
                    raise SlcanError(f"{cmd!r} needs 8 hex digits")
                value = _hex(arg, "acceptance")
                code, mask = self.acceptance
                self.acceptance = (value, mask) if cmd == b"M" else (code, value)
                return OK
        raise SlcanError(f"unknown command {line!r}")

    def _transmit(self, line: bytes) -> bytes:
        msg = decode_frame(line)
        with self._lock:
            if not self.is_open or self.listen_only:
                raise _Refused
            if self.adapter_bitrate != self.bitrate:
                self.flags |= StatusFlag.BUS_ERROR | StatusFlag.ERROR_PASSIVE
                raise _BitrateMismatch
        bus = self._bus
        if bus is None:
            raise _Refused
        try:
            bus.send(msg, timeout=0.1)
        except can.CanError:
            with self._lock:
                self.flags |= StatusFlag.TX_FIFO_FULL
            raise _Refused from None
        with self._lock:
            self.stats.to_bus += 1
        return b"Z\r" if msg.is_extended_id else b"z\r"

    def _emit(self, data: bytes, *, frame: bool) -> None:
        """Queue ``data`` for the host. Only received frames overrun: a reply to a command
        always waits its turn (the host asked for it, one command at a time), as an adapter's
        USB endpoint queues it; dropping it lost the answer to ``F`` after an overrun."""
        with self._out_lock:
            if frame and len(self._pending) + len(data) > MAX_PENDING:
                with self._lock:
                    self.stats.dropped += 1
                    self.flags |= StatusFlag.RX_FIFO_FULL | StatusFlag.DATA_OVERRUN
                return
            self._pending += data
            self._flush_locked()

    def _flush_locked(self) -> None:
        while self._pending:
            try:
                written = os.write(self._master, self._pending)
            except BlockingIOError:
                return
            except OSError:
                return  # the pty is gone: the adapter is closing
            del self._pending[:written]

    # -- bus side -------------------------------------------------------------------------
    def _serve_bus(self) -> None:
        bus = self._bus
        assert bus is not None
        while not self._stop.is_set():
            try:
                msg = bus.recv(0.05)
            except can.CanError as exc:
                log.warning("slcan_sim_bus_failed", error=repr(exc))
                return
            if msg is None or msg.is_error_frame or msg.is_fd:
                continue
            with self._lock:
                if not self.is_open:
                    continue
                if self.adapter_bitrate != self.bitrate:
                    self.flags |= StatusFlag.BUS_ERROR | StatusFlag.ERROR_PASSIVE
                    continue
                stamp = (
                    (time.monotonic_ns() - self._opened_ns) // 1_000_000
                    if self.timestamps
                    else None
                )
                self.stats.to_host += 1
            self._emit(encode_frame(msg, stamp), frame=True)


class _Refused(Exception):
    pass


class _BitrateMismatch(Exception):
    pass


def _expect(arg: bytes, expected: bytes) -> None:
    if arg != expected:
        raise SlcanError(f"unexpected argument {arg!r}")


class _ignore_oserror:
    def __enter__(self) -> None:
        return None

    def __exit__(self, exc_type: type[BaseException] | None, *rest: Any) -> bool:
        return exc_type is not None and issubclass(exc_type, OSError)


class SlcanAdapterProcess:
    """``python -m openel_can.sim.slcan ARGS`` as a context manager (for tests): entering
    starts it and waits at most ``timeout`` s for its port (:attr:`port`); leaving sends
    SIGTERM and waits (SIGKILL after ``timeout`` s). :attr:`process` is the ``Popen``."""

    def __init__(self, *args: str, timeout: float = 10.0) -> None:
        self.args = args
        self.timeout = timeout
        self.port = ""
        self.process: subprocess.Popen[bytes] | None = None

    def __enter__(self) -> Self:
        proc = self.process = subprocess.Popen(
            [sys.executable, "-m", "openel_can.sim.slcan", *self.args],
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
        )
        assert proc.stdout is not None
        try:
            if not select.select([proc.stdout], [], [], self.timeout)[0]:
                raise TimeoutError(f"the slcan adapter process printed no port in {self.timeout} s")
            self.port = proc.stdout.readline().decode().strip()
            if not self.port.startswith("/dev/"):
                raise RuntimeError(f"the slcan adapter process failed (printed {self.port!r})")
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        proc = self.process
        if proc is None:
            return
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(self.timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        if proc.stdout is not None:
            proc.stdout.close()


# -- command line ------------------------------------------------------------------------------
def _ids(text: str) -> list[int]:
    try:
        return [int(part) for part in text.split(",") if part.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected node ids like 0,1") from None


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m openel_can.sim.slcan``: an adapter with simulated drives, until a signal."""
    from .cia402 import SimCia402Drive
    from .odrive import SimODrive

    parser = argparse.ArgumentParser(
        prog="python -m openel_can.sim.slcan",
        description="A simulated slcan (Lawicel) CAN adapter on a pty with simulated drives. "
        "Prints the pty path on its first line, then runs until SIGTERM or SIGINT.",
    )
    parser.add_argument("--odrive", type=_ids, default=[], metavar="IDS", help="ODrive node ids, e.g. 0,1")  # fmt: skip
    parser.add_argument("--cia402", type=_ids, default=[], metavar="IDS", help="CiA 402 node ids, e.g. 5")  # fmt: skip
    parser.add_argument("--bitrate", type=int, default=1_000_000, help="the bus's bit rate (default 1000000)")  # fmt: skip
    parser.add_argument("--channel", default=None, help="python-can virtual channel of the bus (default: a fresh one)")  # fmt: skip
    parser.add_argument("--odrive-heartbeat", type=float, default=0.1, metavar="S", help="ODrive heartbeat period (default 0.1 s)")  # fmt: skip
    parser.add_argument("--report", action="store_true", help="after the port, print each drive's state when it changes: 'odrive 1 IDLE', 'cia402 5 OPERATION_ENABLED' (polled every 10 ms)")  # fmt: skip
    parser.add_argument("--log-level", choices=("debug", "info", "warning", "error"), default="warning", help="log level (stderr; default warning)")  # fmt: skip
    args = parser.parse_args(argv)
    # The framework logs through the standard logging module: on stderr, as stdout carries
    # the port only.
    logging.basicConfig(
        level=args.log_level.upper(), stream=sys.stderr, format="%(name)s %(levelname)s %(message)s"
    )
    peers: list[SimPeer] = []
    option = "--odrive"
    try:  # a node id out of its protocol's range is refused by the peer
        peers += [SimODrive(n, heartbeat_period=args.odrive_heartbeat) for n in args.odrive]
        option = "--cia402"
        peers += [SimCia402Drive(n) for n in args.cia402]
    except ValueError as exc:
        parser.error(f"{option}: {exc}")
    stop = threading.Event()

    def _on_signal(signum: int, frame: object) -> None:
        stop.set()

    signal.signal(signal.SIGTERM, _on_signal)
    signal.signal(signal.SIGINT, _on_signal)
    try:
        adapter = SlcanAdapter(args.channel, bitrate=args.bitrate, peers=peers)
    except BadParameterError as exc:
        parser.error(str(exc))
    with adapter:
        sys.stdout.write(adapter.port + "\n")
        sys.stdout.flush()
        shown: dict[int, str] = {}
        while not stop.wait(0.01 if args.report else 1.0):
            if args.report:
                for i, peer in enumerate(peers):
                    line = _state_line(peer)
                    if shown.get(i) != line:
                        shown[i] = line
                        sys.stdout.write(line + "\n")
                        sys.stdout.flush()
    return 0


def _state_line(peer: SimPeer) -> str:
    """``odrive 1 CLOSED_LOOP_CONTROL``, ``cia402 5 QUICK_STOP_ACTIVE`` (read from another
    thread: a snapshot of one attribute)."""
    node = getattr(peer, "node_id", "?")
    state = getattr(peer, "axis_state", None)
    if state is not None:
        return f"odrive {node} {getattr(state, 'name', state)}"
    state = getattr(peer, "power_state", None)
    return f"cia402 {node} {getattr(state, 'name', state)}"


if __name__ == "__main__":
    sys.exit(main())
