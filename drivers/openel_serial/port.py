"""DynamixelPort: one half-duplex Dynamixel Protocol 2.0 bus, many servos.

Scheduling: the bus carries one request at a time. Every transaction (an instruction
packet and the status packets it asks for) runs under one FIFO ``anyio.Lock``, so the
servos' commands and the shared poller interleave packet by packet and never collide.

Timeouts and retries: a transaction waits for its status packets for

    (instruction bytes + expected status bytes) x 10 bits / baud rate
    + number of statuses x return delay + timeout margin

(8N1 framing; the margin covers USB adapter latency and OS scheduling). Missing statuses
are requested again up to ``retries`` times (a SYNC READ asks only the servos that did
not answer), then :class:`~openel_serial.errors.DynamixelTimeoutError` is raised. A
status with an error number raises :class:`~openel_serial.errors.DynamixelStatusError`
at once (the servo answered: retrying would not help), except CRC_ERROR (the servo
received the instruction damaged and did not execute it): that instruction is sent
again like a missing status, within the same ``retries``; the alert bit raises
:class:`~openel_serial.errors.DynamixelHardwareAlert` with Hardware Error Status read.

Reception: bytes from the port feed a :class:`~openel_serial.dynamixel.PacketParser`
in the transport's callback. Garbage and corrupt packets are counted and dropped there
(``stats``); a status nobody waits for (a late answer to a timed-out request) is
counted as ``stray`` and dropped.

Polling: while servos are attached, one poller task reads Moving, Moving Status,
Present PWM/Current/Velocity/Position (addresses 122..135) of all of them with one
SYNC READ per cycle and hands each servo its :class:`PresentState`; the servos serve
their actual values from it and detect completion on it.

Bus Watchdog (98): the poller's SYNC READ is an instruction packet to every polled
servo, so it is what feeds their Bus Watchdogs -- from the event loop, never from a
thread: a stalled loop stops the polls and the servos stop by themselves.
:meth:`DynamixelPort.arm_bus_watchdog` registers a servo's timeout (refused unless
``poll_period`` is below half of it). A poll cycle that starts later than half the
shortest armed timeout after the previous one (the loop was blocked, the bus was busy) is
followed by a SYNC READ of Bus Watchdog (98) of the armed servos; those reading -1
(0xFF: expired) are told (``_watchdog_tripped``) and their components go to Error with
``ErrorId.WATCHDOG``.

E-stop: :meth:`DynamixelPort.estop` sends Torque Enable (64) = 0 to servos in one SYNC
WRITE, ahead of every queued transaction (only the exchange on the wire, bounded by its
response timeout, is waited for); concurrent calls share one packet.

Faults: a vanished port (read/write error, EOF) is reported to every attached servo,
whose component goes to Error (``ErrorId.DISCONNECTED``, ``HAL_NO_CONNECTED``);
:meth:`DynamixelPort.reconnect` (called by each servo's ``reset``) reopens it.
"""

from __future__ import annotations

import asyncio
import math
import struct
from collections.abc import Callable, Mapping, Sequence
from contextlib import AsyncExitStack
from dataclasses import dataclass
from types import TracebackType
from typing import Any, Final, Protocol, Self

import anyio
import anyio.abc
import anyio.lowlevel

from openel_async.clock import Clock, default_clock
from openel_async.errors import BadParameterError, HALError
from openel_async.logs import get_logger
from openel_serial import dynamixel as dx
from openel_serial.errors import (
    DynamixelHardwareAlert,
    DynamixelStatusError,
    DynamixelTimeoutError,
    PortDisconnectedError,
)
from openel_serial.halfduplex import BusLock, complete, positive, wire_time
from openel_serial.link import SerialLink

__all__ = [
    "DEFAULT_RETURN_DELAY",
    "POLL_ADDRESS",
    "POLL_LENGTH",
    "STATUS_OVERHEAD",
    "SYNC_READ_OVERHEAD",
    "DynamixelPort",
    "PingInfo",
    "PortStats",
    "PresentState",
    "wire_time",
]

log = get_logger(__name__)

X = dx.XSeries
POLL_ADDRESS: Final = X.MOVING.address  # 122
POLL_LENGTH: Final = X.PRESENT_POSITION.address + X.PRESENT_POSITION.size - POLL_ADDRESS  # 14
STATUS_OVERHEAD: Final = 11
"""Bytes of a status packet besides its params: header 4, id, length 2, 0x55, error, CRC 2."""
SYNC_READ_OVERHEAD: Final = 14
"""Bytes of a SYNC READ packet besides its id list: header 4, id, length 2, 0x82, address 2,
data length 2, CRC 2 (without byte stuffing)."""
DEFAULT_RETURN_DELAY: Final = 500e-6
"""The X series' factory Return Delay Time (9): 250 x 2 us."""
SYNC_READ_CACHE: Final = 64
"""SYNC READ instruction packets kept per port, by (address, length, ids)."""
_CRC_ERROR: Final = int(dx.ErrorNumber.CRC_ERROR)
_ERROR_NUMBER: Final = 0x7F


@dataclass(frozen=True, slots=True)
class PingInfo:
    model_number: int
    firmware_version: int
    error: int
    """The status error byte of the reply (bit 7: hardware alert)."""

    @property
    def alert(self) -> bool:
        return bool(self.error & dx.ALERT_BIT)


@dataclass(frozen=True, slots=True)
class PresentState:
    """One poll of one servo: raw control-table values of addresses 122..135."""

    transaction: int
    """The port's transaction number of the SYNC READ (later reads have larger ones)."""
    time_ns: int
    """The port clock's time when the status arrived."""
    moving: bool
    moving_status: int
    pwm: int
    current: int
    """Present Current (XL430: Present Load), raw units."""
    velocity: int
    position: int
    error: int = 0

    @classmethod
    def decode(cls, params: bytes, transaction: int, time_ns: int, error: int = 0) -> Self:
        moving, status, pwm, current, velocity, position = struct.unpack("<BBhhii", params)
        return cls(
            transaction, time_ns, bool(moving), status, pwm, current, velocity, position, error
        )


@dataclass(slots=True)
class PortStats:
    """Counters of one port (the parser's are read live from it)."""

    transactions: int = 0
    retries: int = 0
    timeouts: int = 0
    status_errors: int = 0
    alerts: int = 0
    stray: int = 0
    """Status packets nobody waited for (late answers), dropped."""
    poll_cycles: int = 0
    poll_misses: int = 0
    reconnects: int = 0
    losses: int = 0
    crc_rejected: int = 0
    """Statuses with CRC_ERROR: a servo received the instruction damaged (it was resent)."""


class PortClient(Protocol):
    """What a servo attached to the port implements (see :class:`DynamixelServo`)."""

    @property
    def dxl_id(self) -> int: ...

    @property
    def polled(self) -> bool: ...

    def _poll_update(self, state: PresentState) -> None: ...

    def _poll_missed(self, error: DynamixelTimeoutError) -> None: ...

    def _poll_status_error(self, error: DynamixelStatusError) -> None: ...

    def _hardware_alert(self, error: DynamixelHardwareAlert) -> None: ...

    def _port_lost(self, reason: str) -> None: ...

    def _watchdog_tripped(self, reason: str) -> None: ...

    def _estopped(self, reason: str) -> None: ...


class DynamixelPort:
    """A serial port carrying Dynamixel Protocol 2.0 servos; ``async with`` opens it.

    ``url`` is a device path (``/dev/ttyUSB0``, ``/dev/serial/by-id/...``) or a pyserial
    URL. ``return_delay`` is the servos' Return Delay Time in seconds (X-series
    default 250 x 2 us = 500 us). ``poll_period`` (s) paces the shared poller; 0 polls
    back to back. Time for the poll schedule and the states' timestamps comes from
    ``clock`` (the real clock by default: a serial bus runs in real time).
    """

    def __init__(
        self,
        url: str,
        *,
        baudrate: int = 57_600,
        return_delay: float = DEFAULT_RETURN_DELAY,
        timeout_margin: float = 0.02,
        retries: int = 2,
        poll_period: float = 0.01,
        clock: Clock | None = None,
        serial_options: Mapping[str, Any] | None = None,
        max_packet: int = 1024,
    ) -> None:
        if not isinstance(url, str) or not url:
            raise BadParameterError("url", url, "a serial device path or pyserial URL")
        if isinstance(baudrate, bool) or not isinstance(baudrate, int) or baudrate <= 0:
            raise BadParameterError("baudrate", baudrate, "an int > 0 (bit/s)")
        if isinstance(retries, bool) or not isinstance(retries, int) or retries < 0:
            raise BadParameterError("retries", retries, "an int >= 0")
        self.url = url
        self.baudrate = baudrate
        self.return_delay = positive("return_delay", return_delay, allow_zero=True)
        self.timeout_margin = positive("timeout_margin", timeout_margin)
        self.retries = retries
        self.poll_period = positive("poll_period", poll_period, allow_zero=True)
        self.clock: Clock = clock or default_clock()
        self.stats = PortStats()
        self.parser = dx.PacketParser(max_length=max_packet)
        self._link = SerialLink(
            url,
            baudrate=baudrate,
            on_data=self._on_data,
            on_lost=self._on_lost,
            serial_options=serial_options,
        )
        # An uncontended acquire does not yield (one event-loop pass less per
        # transaction); a contended one queues, and release hands the lock to the first
        # waiter (FIFO).
        self._lock = BusLock()
        self._reconnect_lock = anyio.Lock()
        self._clients: dict[int, PortClient] = {}
        self._transaction = 0
        # The exchange in flight: ids expected (and their param length), what arrived,
        # how many of those are CRC_ERROR statuses, and the future its task waits on.
        self._expect: set[int] | None = None
        self._replies: dict[int, dx.Status] = {}
        self._garbled = 0
        self._param_length = 0
        self._waiter: asyncio.Future[None] | None = None
        self._deadline = 0.0
        self._watchdog: asyncio.TimerHandle | None = None
        self._sync_read_packets: dict[tuple[int, int, tuple[int, ...]], bytes] = {}
        self._last_sync_read: tuple[object, int, int, bytes] = ((), -1, -1, b"")
        self._poll_wake: anyio.Event | None = None
        self._bus_watchdogs: dict[int, float] = {}
        """Servos whose Bus Watchdog is armed: id -> timeout (s)."""
        self._last_poll_ns: int | None = None
        self._estop_ids: set[int] = set()
        self._stack: AsyncExitStack | None = None
        self._entered = False
        self._log = log.bind(port=url)

    # -- lifecycle -----------------------------------------------------------------
    async def __aenter__(self) -> Self:
        if self._entered:
            raise HALError(f"DynamixelPort {self.url} is already entered")
        self._entered = True
        stack = AsyncExitStack()
        try:
            await self._link.open()
            stack.push_async_callback(self._link.close)
            tg = await stack.enter_async_context(anyio.create_task_group())
            stack.callback(tg.cancel_scope.cancel)  # runs first on exit: stop the poller
            tg.start_soon(self._poll_loop)
        except BaseException:
            await stack.aclose()
            self._entered = False
            raise
        self._stack = stack
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        stack, self._stack = self._stack, None
        self._entered = False
        if self._watchdog is not None:
            self._watchdog.cancel()
            self._watchdog = None
        if stack is not None:
            await stack.aclose()

    @property
    def connected(self) -> bool:
        return self._link.is_open

    @property
    def transactions(self) -> int:
        """Transactions started so far; a poll with a larger number was sent later."""
        return self._transaction

    @property
    def link(self) -> SerialLink:
        return self._link

    def check_connected(self) -> None:
        if not self._link.is_open:
            reason = self._link.lost_reason or ("not open" if self._entered else "not entered")
            raise PortDisconnectedError(self.url, reason)

    async def reconnect(self) -> None:
        """Reopen the port if it was lost (once, however many servos ask)."""
        if not self._entered:
            raise PortDisconnectedError(self.url, "enter 'async with port' first")
        async with self._reconnect_lock:
            if self._link.is_open:
                return
            async with self._lock:
                self.parser.reset()
                await self._link.open()
            self.stats.reconnects += 1
            self.wake_poller()

    # -- clients -------------------------------------------------------------------
    def attach(self, client: PortClient) -> None:
        """Register a servo for polling and fault reports; its id must be free."""
        dxl_id = client.dxl_id
        other = self._clients.get(dxl_id)
        if other is not None and other is not client:
            raise BadParameterError(
                "dxl_id", dxl_id, f"an id not already used on {self.url} by {other!r}"
            )
        self._clients[dxl_id] = client
        self.wake_poller()

    def detach(self, client: PortClient) -> None:
        if self._clients.get(client.dxl_id) is client:
            del self._clients[client.dxl_id]

    @property
    def clients(self) -> Mapping[int, PortClient]:
        return dict(self._clients)

    # -- Bus Watchdog and e-stop -------------------------------------------------------
    def arm_bus_watchdog(self, dxl_id: int, timeout_s: float) -> None:
        """Record that servo ``dxl_id``'s Bus Watchdog is armed with ``timeout_s``.

        The poller feeds it; refused (:class:`BadParameterError` naming ``timeout_s``)
        unless ``poll_period`` is below half the timeout, so that a poll reaches the
        servo at least twice per timeout while the event loop runs.
        """
        if not self.poll_period < timeout_s / 2:
            raise BadParameterError(
                "timeout_s",
                timeout_s,
                f"more than twice the poll_period of {self.url} ({self.poll_period} s): "
                "the poller feeds the Bus Watchdog",
            )
        self._bus_watchdogs[dxl_id] = float(timeout_s)

    def disarm_bus_watchdog(self, dxl_id: int) -> None:
        self._bus_watchdogs.pop(dxl_id, None)

    @property
    def bus_watchdogs(self) -> Mapping[int, float]:
        """The armed Bus Watchdogs: servo id -> timeout (s)."""
        return dict(self._bus_watchdogs)

    async def check_bus_watchdogs(self, ids: Sequence[int] | None = None) -> list[int]:
        """SYNC READ Bus Watchdog (98) of the armed servos among ``ids`` (default: all
        armed); tell those reading -1 (expired) and return their ids."""
        armed = sorted(
            i for i in (self._bus_watchdogs if ids is None else ids) if i in self._bus_watchdogs
        )
        if not armed:
            return []
        item = X.BUS_WATCHDOG
        statuses = await self.sync_read_statuses(armed, item.address, item.size)
        tripped: list[int] = []
        for dxl_id in armed:
            status = statuses.get(dxl_id)
            if status is None or status.error_number or len(status.params) != item.size:
                continue  # a silent servo is reported by the poll
            if item.decode(status.params) == dx.BUS_WATCHDOG_ERROR:
                tripped.append(dxl_id)
        for dxl_id in tripped:
            timeout = self._bus_watchdogs.get(dxl_id, math.nan)
            self._log.warning("dxl_bus_watchdog_expired", id=dxl_id, timeout_s=timeout)
            client = self._clients.get(dxl_id)
            if client is not None:
                client._watchdog_tripped(
                    f"servo {dxl_id}: Bus Watchdog expired (no instruction packet for more "
                    f"than {timeout} s): the servo stopped by itself"
                )
        return tripped

    async def estop(self, ids: Sequence[int] | None = None) -> None:
        """Torque Enable (64) = 0 on ``ids`` (default: every attached servo) in one SYNC
        WRITE, sent before any transaction waiting for the bus; with the default, every
        attached servo is told (its component goes to Error with ``ErrorId.ESTOP``).

        Calls made together (an e-stop of every component) share one packet.
        """
        targets = sorted(self._clients) if ids is None else list(ids)
        if not targets:
            return
        for dxl_id in targets:
            if isinstance(dxl_id, bool) or not isinstance(dxl_id, int):
                raise BadParameterError("ids", ids, f"servo ids in 0..{dx.MAX_ID}")
            if not 0 <= dxl_id <= dx.MAX_ID:
                raise BadParameterError("ids", ids, f"servo ids in 0..{dx.MAX_ID}")
        self._estop_ids.update(targets)
        await anyio.lowlevel.checkpoint()  # let the other e-stops of this instant join
        await self._lock.acquire(first=True)
        try:
            pending, self._estop_ids = self._estop_ids, set()
            if pending:
                self.check_connected()
                item = X.TORQUE_ENABLE
                packet = dx.encode(
                    dx.SyncWrite(
                        item.address,
                        item.size,
                        tuple(dx.SyncWriteItem(i, item.encode(0)) for i in sorted(pending)),
                    )
                )
                self._transaction += 1
                self.stats.transactions += 1
                self._link.write(packet)
                self._log.warning("dxl_estop", ids=sorted(pending))
        finally:
            self._lock.release()
        if ids is None:
            for dxl_id in targets:
                client = self._clients.get(dxl_id)
                if client is not None:
                    client._estopped(f"e-stop on {self.url}: torque off")

    def wake_poller(self) -> None:
        if self._poll_wake is not None:
            self._poll_wake.set()

    # -- timing --------------------------------------------------------------------
    def response_timeout(self, request_bytes: int, statuses: int, param_length: int) -> float:
        """The wait for ``statuses`` status packets of ``param_length`` params each."""
        reply_bytes = statuses * (STATUS_OVERHEAD + param_length)
        return (
            wire_time(request_bytes + reply_bytes, self.baudrate)
            + statuses * self.return_delay
            + self.timeout_margin
        )

    # -- public requests -----------------------------------------------------------
    async def ping(self, dxl_id: int, *, check_alert: bool = False) -> PingInfo:
        """PING: model number, firmware and the error byte (alerts not raised by default)."""
        dx.Ping(dxl_id)  # validates the id
        status = await self._unicast(dx.encode(dx.Ping(dxl_id)), dxl_id, "PING", 3, check_alert)
        model, firmware = status.ping_info()
        return PingInfo(model, firmware, status.error)

    async def read(
        self, dxl_id: int, address: int, length: int, *, check_alert: bool = True
    ) -> bytes:
        """READ ``length`` bytes at ``address``."""
        packet = dx.encode(dx.Read(dxl_id, address, length))
        status = await self._unicast(
            packet, dxl_id, f"READ {address}+{length}", length, check_alert
        )
        return status.params

    async def read_item(
        self, dxl_id: int, item: dx.ControlItem, *, check_alert: bool = True
    ) -> int:
        data = await self.read(dxl_id, item.address, item.size, check_alert=check_alert)
        return item.decode(data)

    async def write(
        self,
        dxl_id: int,
        address: int,
        data: bytes,
        *,
        ack: bool = True,
        check_alert: bool = True,
    ) -> None:
        """WRITE ``data`` at ``address``; ``ack=False`` for Status Return Level < 2."""
        packet = dx.encode(dx.Write(dxl_id, address, bytes(data)))
        if not ack:
            await self._send_only(packet)
            return
        await self._unicast(packet, dxl_id, f"WRITE {address}+{len(data)}", 0, check_alert)

    async def write_item(
        self, dxl_id: int, item: dx.ControlItem, value: int, *, ack: bool = True
    ) -> None:
        await self.write(dxl_id, item.address, item.encode(value), ack=ack)

    async def reboot(self, dxl_id: int) -> None:
        """REBOOT (the status comes before the servo restarts)."""
        await self._unicast(dx.encode(dx.Reboot(dxl_id)), dxl_id, "REBOOT", 0, False)

    async def sync_read(
        self, ids: Sequence[int], address: int, length: int, *, check_alert: bool = True
    ) -> dict[int, bytes]:
        """SYNC READ: ``{id: data}`` for every id, or raise (timeout, status error)."""
        ids = tuple(ids)
        statuses = await self._sync_read(ids, address, length)
        if len(statuses) != len(ids):  # statuses holds only ids asked for
            missing = [i for i in ids if i not in statuses]
            timeout = self.response_timeout(SYNC_READ_OVERHEAD + len(ids), len(ids), length)
            raise DynamixelTimeoutError(
                self.url, missing, f"SYNC READ {address}+{length}", timeout, self.retries + 1
            )
        refused = 0xFF if check_alert else _ERROR_NUMBER  # the alert bit is bit 7
        out: dict[int, bytes] = {}
        for dxl_id in ids:
            status = statuses[dxl_id]
            if status.error & refused:
                raise DynamixelStatusError(dxl_id, status.error, f"SYNC READ {address}+{length}")
            out[dxl_id] = status.params
        return out

    def sync_read_packet(self, ids: Sequence[int], address: int, length: int) -> bytes:
        """The SYNC READ instruction packet, built once per (address, length, ids).

        Raises :class:`BadParameterError` for an empty or repeated id list and
        :class:`ValueError` for an address, length or id out of range (nothing is cached
        then). At most ``SYNC_READ_CACHE`` packets are kept (the oldest are forgotten).
        """
        last = self._last_sync_read
        if ids is last[0] and address == last[1] and length == last[2]:
            return last[3]  # the same id tuple as last time (the usual polling loop)
        key = (address, length, ids if type(ids) is tuple else tuple(ids))
        packet = self._sync_read_packets.get(key)
        if packet is None:
            ids = key[2]
            if not ids or len(set(ids)) != len(ids):
                raise BadParameterError("ids", ids, "a non-empty sequence of distinct servo ids")
            packet = dx.encode(dx.SyncRead(address, length, ids))
            cache = self._sync_read_packets
            if len(cache) >= SYNC_READ_CACHE:
                del cache[next(iter(cache))]
            cache[key] = packet
        if type(ids) is tuple:
            self._last_sync_read = (ids, address, length, packet)
        return packet

    async def sync_read_statuses(
        self, ids: Sequence[int], address: int, length: int
    ) -> dict[int, dx.Status]:
        """SYNC READ returning the statuses that arrived (missing ones retried, not raised)."""
        return await self._sync_read(tuple(ids), address, length)

    async def _sync_read(
        self, ids: tuple[int, ...], address: int, length: int
    ) -> dict[int, dx.Status]:
        packet = self.sync_read_packet(ids, address, length)  # validates
        async with self._lock:
            got = await self._exchange(packet, ids, length)
            if len(got) == len(ids) and not self._garbled:
                return got  # the usual case, without the retry machinery

            def make(remaining: Sequence[int]) -> bytes:
                return self.sync_read_packet(remaining, address, length)

            what = f"SYNC READ {address}+{length}"
            return await self._retry(got, make, ids, what, length)

    async def sync_write(self, address: int, length: int, data: Mapping[int, bytes]) -> None:
        """SYNC WRITE ``{id: data}`` (no status packets: it is a broadcast)."""
        items = tuple(dx.SyncWriteItem(dxl_id, bytes(d)) for dxl_id, d in data.items())
        if not items:
            raise BadParameterError("data", data, "at least one {id: bytes} item")
        await self._send_only(dx.encode(dx.SyncWrite(address, length, items)))

    async def sync_write_item(self, item: dx.ControlItem, values: Mapping[int, int]) -> None:
        await self.sync_write(
            item.address, item.size, {i: item.encode(v) for i, v in values.items()}
        )

    # -- transactions --------------------------------------------------------------
    async def _send_only(self, packet: bytes) -> None:
        async with self._lock:
            self.check_connected()
            self._transaction += 1
            self.stats.transactions += 1
            self._link.write(packet)
            self._log.debug("dxl_tx", size=len(packet))
            # The next request may follow at once: the port sends bytes in order.
            await anyio.lowlevel.checkpoint()

    async def _unicast(
        self, packet: bytes, dxl_id: int, what: str, param_length: int, check_alert: bool
    ) -> dx.Status:
        if dxl_id == dx.BROADCAST_ID:
            raise BadParameterError("dxl_id", dxl_id, "a servo id (0..252), not broadcast")
        async with self._lock:
            statuses = await self._transact(lambda _: packet, (dxl_id,), what, param_length)
            status = statuses.get(dxl_id)
            if status is None:
                raise DynamixelTimeoutError(
                    self.url,
                    (dxl_id,),
                    what,
                    self.response_timeout(len(packet), 1, param_length),
                    self.retries + 1,
                )
            if status.error_number:
                self.stats.status_errors += 1
                if status.alert:
                    self.stats.alerts += 1
                    raise await self._alert(dxl_id, status.error, what)
                raise DynamixelStatusError(dxl_id, status.error, what)
            if check_alert and status.alert:
                self.stats.alerts += 1
                raise await self._alert(dxl_id, status.error, what)
            return status

    async def _alert(self, dxl_id: int, error: int, what: str) -> DynamixelHardwareAlert:
        """Build the alert exception with Hardware Error Status (lock held)."""
        item = X.HARDWARE_ERROR_STATUS
        packet = dx.encode(item.read(dxl_id))
        hardware: int | None = None
        try:
            got = await self._transact(lambda _: packet, (dxl_id,), "READ 70+1", item.size)
        except PortDisconnectedError:
            got = {}
        status = got.get(dxl_id)
        if status is not None and status.error_number == 0 and len(status.params) == item.size:
            hardware = item.decode(status.params)
        return DynamixelHardwareAlert(dxl_id, error, what, hardware)

    async def _transact(
        self,
        make_packet: Callable[[Sequence[int]], bytes],
        ids: Sequence[int],
        what: str,
        param_length: int,
    ) -> dict[int, dx.Status]:
        """Send, collect a status per id, retry the missing ones (the lock is held)."""
        got = await self._exchange(make_packet(ids), ids, param_length)
        if len(got) == len(ids) and not self._garbled:
            return got  # every status arrived, none says the instruction was damaged
        return await self._retry(got, make_packet, ids, what, param_length)

    async def _retry(
        self,
        got: dict[int, dx.Status],
        make_packet: Callable[[Sequence[int]], bytes],
        ids: Sequence[int],
        what: str,
        param_length: int,
    ) -> dict[int, dx.Status]:
        """The rest of a transaction whose first attempt ``got`` these statuses."""
        result = got
        remaining = list(ids)
        for attempt in range(self.retries + 1):
            if attempt:
                self.stats.retries += 1
                self._log.debug("dxl_retry", request=what, ids=remaining, attempt=attempt)
                got = await self._exchange(make_packet(remaining), remaining, param_length)
                result.update(got)
            # CRC_ERROR: the instruction was damaged on the wire and not executed: resend it.
            garbled = [i for i, s in got.items() if s.error & _ERROR_NUMBER == _CRC_ERROR]
            if garbled:
                self.stats.crc_rejected += len(garbled)
                self._log.debug("dxl_crc_rejected", request=what, ids=garbled)
            remaining = [i for i in remaining if i not in got or i in garbled]
            if not remaining:
                break
        else:
            missing = [i for i in remaining if i not in result]
            if missing:
                self.stats.timeouts += 1
            self._log.warning(
                "dxl_no_status" if missing else "dxl_crc_rejected_every_attempt",
                request=what,
                ids=remaining,
                attempts=self.retries + 1,
            )
        return result

    async def _exchange(
        self, packet: bytes, ids: Sequence[int], param_length: int
    ) -> dict[int, dx.Status]:
        """One attempt: write ``packet`` and wait for a status from each id or the timeout.

        The wait is one future, completed by the reception callback when the last status
        arrived, by the port's watchdog timer at the deadline, or by a loss of the port;
        a cancellation of the caller ends it too. No cancel scope, no extra event-loop
        pass, and no timer per exchange (see :meth:`_arm_watchdog`).
        """
        self.check_connected()
        self._transaction += 1
        self.stats.transactions += 1
        # Written first: what follows overlaps with the servos' processing, and no reply
        # can be handled before this task yields (the reception runs in this thread).
        self._link.write(packet)
        loop = asyncio.get_running_loop()
        waiter: asyncio.Future[None] = loop.create_future()
        replies: dict[int, dx.Status] = {}
        self._replies = replies
        self._garbled = 0
        expect = self._expect = set(ids)
        self._param_length = param_length
        self._waiter = waiter
        try:
            timeout = self.response_timeout(len(packet), len(ids), param_length)
            self._arm_watchdog(loop, loop.time() + timeout)
            await waiter
        finally:
            self._expect = None
            self._waiter = None
        if len(replies) != len(expect):
            self.check_connected()  # lost while waiting: raise, not a timeout
        return replies

    def _arm_watchdog(self, loop: asyncio.AbstractEventLoop, deadline: float) -> None:
        """Make the exchange in flight time out at ``deadline`` (loop time).

        One timer serves every exchange: it is re-armed only when it would fire after
        ``deadline`` (then it is replaced) or when it fires before it (then it is set
        again for ``deadline``); so back-to-back exchanges with similar timeouts cost
        no timer each, and the wait still ends at its own deadline.
        """
        self._deadline = deadline
        watchdog = self._watchdog
        if watchdog is not None:
            if watchdog.when() <= deadline:
                return
            watchdog.cancel()
        self._watchdog = loop.call_at(deadline, self._watchdog_fired, loop)

    def _watchdog_fired(self, loop: asyncio.AbstractEventLoop) -> None:
        self._watchdog = None
        waiter = self._waiter
        if waiter is None:
            return  # no exchange in flight: the timer is not needed any more
        if loop.time() >= self._deadline:
            complete(waiter)  # timed out: the exchange returns what arrived
        else:
            self._watchdog = loop.call_at(self._deadline, self._watchdog_fired, loop)

    # -- reception (transport callback) ----------------------------------------------
    def _on_data(self, data: bytes) -> None:
        expect = self._expect
        if expect is None:  # nobody waits: every status is stray
            for msg in self.parser.feed(data):
                if isinstance(msg, dx.Status):
                    self._stray(msg.id)
            return
        # The statuses we wait for, decoded in bulk when they come back to back: each a
        # Status with the expected param length, so only its id and error are checked.
        statuses, others = self.parser.feed_statuses(data, self._param_length)
        replies = self._replies
        for msg in statuses:
            dxl_id = msg.id
            if dxl_id in expect and dxl_id not in replies:
                replies[dxl_id] = msg
                if msg.error & _ERROR_NUMBER == _CRC_ERROR:
                    self._garbled += 1
            else:
                self._stray(dxl_id)
        length = self._param_length
        for other in others:
            if not isinstance(other, dx.Status):
                continue  # an echo of an instruction (some half-duplex adapters)
            dxl_id = other.id
            if dxl_id not in expect or dxl_id in replies:
                self._stray(dxl_id)
                continue
            error_number = other.error & _ERROR_NUMBER
            if error_number:
                if error_number == _CRC_ERROR:
                    self._garbled += 1
            elif len(other.params) != length:
                self.stats.stray += 1  # an answer to another request
                continue
            replies[dxl_id] = other
        waiter = self._waiter
        if waiter is not None and len(replies) == len(expect):
            complete(waiter)

    def _stray(self, dxl_id: int) -> None:
        self.stats.stray += 1
        self._log.debug("dxl_stray_status", id=dxl_id)

    def _on_lost(self, reason: str) -> None:
        self.stats.losses += 1
        if self._waiter is not None:
            complete(self._waiter)  # the waiter sees the loss at once
        for client in list(self._clients.values()):
            client._port_lost(f"{self.url}: {reason}")

    # -- poller --------------------------------------------------------------------
    def _poll_ids(self) -> list[int]:
        return sorted(i for i, c in self._clients.items() if c.polled)

    async def poll_once(self) -> None:
        """One poll cycle: SYNC READ 122..135 of every polled servo, then dispatch."""
        ids = self._poll_ids()
        if not ids:
            return
        start = self.clock.now_ns()
        late = self._feeding_late(ids, start)
        statuses = await self.sync_read_statuses(ids, POLL_ADDRESS, POLL_LENGTH)
        self._last_poll_ns = start
        transaction = self._transaction
        now = self.clock.now_ns()
        self.stats.poll_cycles += 1
        alerts: list[tuple[int, int]] = []
        for dxl_id in ids:
            client = self._clients.get(dxl_id)
            if client is None:
                continue
            status = statuses.get(dxl_id)
            what = f"SYNC READ {POLL_ADDRESS}+{POLL_LENGTH}"
            if status is None:
                self.stats.poll_misses += 1
                timeout = self.response_timeout(
                    SYNC_READ_OVERHEAD + len(ids), len(ids), POLL_LENGTH
                )
                client._poll_missed(
                    DynamixelTimeoutError(self.url, (dxl_id,), what, timeout, self.retries + 1)
                )
                continue
            if status.alert:
                alerts.append((dxl_id, status.error))
            elif status.error_number:
                self.stats.status_errors += 1
                client._poll_status_error(DynamixelStatusError(dxl_id, status.error, what))
            if status.error_number == 0 and len(status.params) == POLL_LENGTH:
                client._poll_update(
                    PresentState.decode(status.params, transaction, now, status.error)
                )
        for dxl_id, error in alerts:
            self.stats.alerts += 1
            async with self._lock:
                alert = await self._alert(dxl_id, error, f"SYNC READ {POLL_ADDRESS}")
            client = self._clients.get(dxl_id)
            if client is not None:
                client._hardware_alert(alert)
        if late:
            await self.check_bus_watchdogs(ids)

    def _feeding_late(self, ids: Sequence[int], start_ns: int) -> bool:
        """Whether this poll comes more than half an armed Bus Watchdog timeout after the
        previous one (a servo may have stopped by itself meanwhile)."""
        if not self._bus_watchdogs:
            return False
        last = self._last_poll_ns
        timeouts = [self._bus_watchdogs[i] for i in ids if i in self._bus_watchdogs]
        if not timeouts:
            return False
        if last is None:
            return True
        gap_s = (start_ns - last) / 1e9
        if gap_s <= min(timeouts) / 2:
            return False
        self._log.warning("dxl_bus_watchdog_feed_late", gap_s=gap_s, timeout_s=min(timeouts))
        return True

    async def _poll_loop(self) -> None:
        clock = self.clock
        next_ns = clock.now_ns()
        period_ns = round(self.poll_period * 1e9)
        while True:
            if not self._link.is_open or not self._poll_ids():
                self._poll_wake = anyio.Event()
                if not self._link.is_open or not self._poll_ids():
                    await self._poll_wake.wait()
                self._poll_wake = None
                next_ns = clock.now_ns()
                continue
            try:
                await self.poll_once()
            except (HALError, OSError) as exc:  # one failed cycle never stops the loop
                if self._link.is_open:
                    self._log.warning("dxl_poll_failed", error=str(exc))
            next_ns += period_ns
            now = clock.now_ns()
            if next_ns < now:
                next_ns = now  # overran: restart the schedule rather than burst
            await clock.sleep_until(next_ns)

    def __repr__(self) -> str:
        state = "open" if self.connected else "closed"
        return f"DynamixelPort({self.url!r}, {self.baudrate} bd, {state})"
