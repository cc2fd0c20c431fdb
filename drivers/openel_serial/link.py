"""One serial port on pyserial-asyncio-fast: open without blocking, bytes to a callback.

:class:`SerialLink` opens the port with ``serial.serial_for_url`` in a worker thread
(``clock.run_in_thread``: the event loop never waits on ``open()``/``tcsetattr``, and
simulated time does not pass meanwhile) and hands the open ``serial.Serial`` to
``serial_asyncio_fast.connection_for_serial``, whose transport reads whenever the fd is
readable and passes the bytes to ``on_data`` in the event loop's thread, with no task of
ours in between. A read or write error or EOF (an unplugged USB adapter, a closed pty
master) ends the transport; ``on_lost`` is then called once with the reason. That is an
expected, handled event: the transports here (:class:`QuietSerialTransport` and its
subclass) do not also report an I/O error to the event loop's exception handler, as the
library's ``_fatal_error`` does ("Fatal write error on serial transport", logged at ERROR
with a traceback by asyncio's default handler, and raised after the test by anyio's pytest
plugin). Writes are buffered by the transport and never block.

Hot path: for a port with a file descriptor (every POSIX tty), the transport reads and
writes that descriptor with ``os.read``/``os.write`` itself (:class:`FdSerialTransport`)
instead of through ``serial.Serial.read``/``write``, whose ``select`` call and timeout
objects cost about 7 µs per request/reply on top of the system calls; errors and
end of file end the transport exactly as pyserial's own messages would.
"""

from __future__ import annotations

import asyncio
import os
from collections.abc import Callable, Mapping
from typing import Any

import anyio
import serial
import serial_asyncio_fast

from openel_async.clock import run_in_thread
from openel_async.logs import get_logger
from openel_serial.errors import PortDisconnectedError

__all__ = ["FdSerialTransport", "QuietSerialTransport", "SerialLink"]

log = get_logger(__name__)

READ_SIZE = 4096
"""Bytes asked for per read (the library's default is 1024): the replies to a SYNC READ
of up to 160 servos (25 bytes each) in one read, decoded in one pass."""
CLOSE_TIMEOUT_S = 2.0
"""Bound on waiting for the transport to close the port (a worker thread does it)."""


class QuietSerialTransport(serial_asyncio_fast.SerialTransport):
    """pyserial-asyncio-fast's transport, for which a port failing under a write is a
    disconnect, not a crash.

    The library reports a write error (and, on Windows, a poll error) through
    ``_fatal_error``, which passes it to ``loop.call_exception_handler`` before aborting
    the transport. A vanished port is expected and handled (the protocol's
    ``connection_lost`` gets the error, :class:`SerialLink` reports it through
    ``on_lost``), so an ``OSError`` (``serial.SerialException`` is one) only aborts the
    transport here. Any other exception is a bug and still goes to the handler.
    """

    def _fatal_error(
        self, exc: BaseException, message: str = "Fatal error on serial transport"
    ) -> None:
        if isinstance(exc, OSError):
            self._abort(exc)  # connection_lost(exc): the link reports the loss
            return
        super()._fatal_error(exc, message)


class FdSerialTransport(QuietSerialTransport):
    """pyserial-asyncio-fast's transport, reading and writing the port's fd directly.

    Only the two I/O primitives differ from the base class (buffering, flow control,
    closing and ``connection_lost`` are its own): a read error raises the transport's
    ``SerialException("read failed: ...")``, end of file
    ``SerialException("device reports readiness to read but returned no data ...")``,
    a write error ``SerialException("write failed: ...")``, like pyserial's.
    """

    def __init__(
        self,
        loop: asyncio.AbstractEventLoop,
        protocol: asyncio.Protocol,
        serial_instance: serial.Serial,
    ) -> None:
        super().__init__(loop, protocol, serial_instance)
        self._fd: int = serial_instance.fileno()
        self._max_read_size = READ_SIZE

    def _read_ready(self) -> None:
        try:
            data = os.read(self._fd, self._max_read_size)
        except (BlockingIOError, InterruptedError):
            return  # spurious wake-up
        except OSError as exc:
            self._close(exc=serial.SerialException(f"read failed: {exc}"))
            return
        if not data:
            self._close(
                exc=serial.SerialException(
                    "device reports readiness to read but returned no data "
                    "(device disconnected or multiple access on port?)"
                )
            )
            return
        self._protocol.data_received(data)

    def _write_data(self, data: bytes | bytearray | memoryview) -> None:
        try:
            written = os.write(self._fd, data)
        except (BlockingIOError, InterruptedError):
            written = 0
        except OSError as exc:
            error = serial.SerialException(f"write failed: {exc}")
            self._fatal_error(error, "Fatal write error on serial transport")
            return
        if written == len(data):
            if self._closing:
                self._close()
            return
        self._write_buffer.append(data[written:])  # the rest when the fd is writable
        self._maybe_pause_protocol()
        self._ensure_writer()


def _transport_for(
    loop: asyncio.AbstractEventLoop, protocol: asyncio.Protocol, port: serial.Serial
) -> serial_asyncio_fast.SerialTransport:
    """The fd transport for a port with a file descriptor, else the library's own (both
    quiet about a vanished port)."""
    try:
        port.fileno()
    except (AttributeError, OSError, ValueError, serial.SerialException):
        return QuietSerialTransport(loop, protocol, port)
    return FdSerialTransport(loop, protocol, port)


def _fileno_of(port: serial.Serial) -> int | None:
    try:
        return int(port.fileno())
    except (AttributeError, OSError, ValueError, serial.SerialException):
        return None


class _Protocol(asyncio.Protocol):
    def __init__(self, link: SerialLink, generation: int, closed: anyio.Event) -> None:
        self._link = link
        self._generation = generation
        self._closed = closed

    def data_received(self, data: bytes) -> None:
        self._link._data(self._generation, data)

    def connection_lost(self, exc: Exception | None) -> None:
        self._closed.set()  # the transport released the port
        self._link._lost(self._generation, exc)


class SerialLink:
    """A serial port (a device path or a pyserial URL) with callbacks for data and loss.

    ``on_data(data)`` and ``on_lost(reason)`` run in the event loop's thread and must
    not raise. ``on_lost`` is called for a failure, not for :meth:`close`.
    """

    def __init__(
        self,
        url: str,
        *,
        baudrate: int,
        on_data: Callable[[bytes], None],
        on_lost: Callable[[str], None],
        serial_options: Mapping[str, Any] | None = None,
    ) -> None:
        self.url = url
        self.baudrate = baudrate
        self.serial_options = dict(serial_options or {})
        self._on_data = on_data
        self._on_lost = on_lost
        self._transport: asyncio.Transport | None = None
        self._fileno: int | None = None
        self._generation = 0
        self._closed: anyio.Event | None = None
        self.opens = 0
        self.bytes_in = 0
        self.bytes_out = 0
        self.lost_reason: str | None = None
        self._log = log.bind(port=url)

    @property
    def is_open(self) -> bool:
        transport = self._transport
        return transport is not None and not transport.is_closing()

    async def open(self) -> None:
        """Open the port; raise :class:`PortDisconnectedError` when it cannot be opened."""
        if self._transport is not None:
            await self.close()
        options = {"baudrate": self.baudrate, **self.serial_options}
        try:
            # Not cancellable: a port opened by the thread after a cancel would leak.
            port = await run_in_thread(lambda: serial.serial_for_url(self.url, **options))
        except (OSError, ValueError) as exc:  # SerialException is an OSError
            raise PortDisconnectedError(self.url, f"cannot open: {exc}") from exc
        self._generation += 1
        generation = self._generation
        closed = anyio.Event()
        loop = asyncio.get_running_loop()
        transport = _transport_for(loop, _Protocol(self, generation, closed), port)
        self._transport = transport
        self._fileno = _fileno_of(port)
        self._closed = closed
        self.lost_reason = None
        self.opens += 1
        self._log.info("serial_port_opened", baudrate=self.baudrate, generation=generation)

    def fileno(self) -> int | None:
        """The open port's file descriptor (None when closed or when it has none).

        For a writer that must not wait for the event loop (a host-side watchdog thread
        sending a torque-off while the loop is stalled): ``os.write`` on it bypasses the
        transport's buffer.
        """
        transport = self._transport
        if transport is None or transport.is_closing():
            return None
        return self._fileno

    def write(self, data: bytes) -> None:
        """Queue ``data`` for sending (never blocks); raise if the port is not open."""
        transport = self._transport
        if transport is None or transport.is_closing():
            raise PortDisconnectedError(self.url, self.lost_reason or "not open")
        transport.write(data)
        self.bytes_out += len(data)

    async def close(self) -> None:
        """Close the port (pending output is dropped) and wait until it is released."""
        transport, closed = self._transport, self._closed
        self._transport = None
        self._fileno = None
        if transport is None:
            return
        self._generation += 1  # callbacks of the old transport are ignored from now on
        if not transport.is_closing():
            transport.abort()
        if closed is not None:
            with anyio.CancelScope(shield=True), anyio.move_on_after(CLOSE_TIMEOUT_S):
                await closed.wait()
        self._log.info("serial_port_closed")

    # -- transport callbacks (event loop thread) -----------------------------------
    def _data(self, generation: int, data: bytes) -> None:
        if generation != self._generation:
            return
        self.bytes_in += len(data)
        try:
            self._on_data(data)
        except Exception:  # a bug in a handler must not stop the transport's reader
            self._log.exception("serial_data_handler_failed")

    def _lost(self, generation: int, exc: Exception | None) -> None:
        if generation != self._generation:
            return  # our own close()
        # The transport ended by itself: a read/write error or EOF.
        self._transport = None
        self._fileno = None
        self._closed = None
        reason = f"port lost: {exc}" if exc is not None else "port closed by the transport"
        self.lost_reason = reason
        self._log.warning("serial_port_lost", reason=reason)
        try:
            self._on_lost(reason)
        except Exception:
            self._log.exception("serial_lost_handler_failed")
