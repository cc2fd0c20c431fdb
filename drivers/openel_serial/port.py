"""DynamixelPort: one half-duplex Dynamixel Protocol 2.0 bus, many servos.

A :class:`~openel_serial.busport.PolledBusPort` (the lifecycle, transactions, reception,
e-stop and poller are the base's, shared with :class:`~openel_serial.feetech_port.FeetechPort`);
this module supplies the Protocol 2.0 codec, the poll window, the status errors and hardware
alerts, CRC_ERROR resends and the Bus Watchdog.

Scheduling: the bus carries one request at a time. Every transaction (an instruction
packet and the status packets it asks for) runs under one FIFO bus lock, so the
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

import math
import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, Final, Protocol, Self

from openel_async.clock import Clock
from openel_async.errors import BadParameterError
from openel_async.logs import get_logger
from openel_serial import dynamixel as dx
from openel_serial.busport import BusClient, BusStats, PolledBusPort
from openel_serial.errors import (
    DynamixelHardwareAlert,
    DynamixelStatusError,
    DynamixelTimeoutError,
    PortDisconnectedError,
)
from openel_serial.halfduplex import complete, wire_time

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
PING_PACKET: Final = 10
"""Bytes of a PING instruction packet (header 4, id, length 2, instruction, CRC 2)."""
BROADCAST_PING_SLOT: Final = 3e-3
"""Seconds between two servos' answers to a broadcast PING (dynamixel-sdk's wait per id)."""
"""The X series' factory Return Delay Time (9): 250 x 2 us."""
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
class PortStats(BusStats):
    """Counters of one port (the parser's are read live from it)."""

    status_errors: int = 0
    alerts: int = 0
    crc_rejected: int = 0
    """Statuses with CRC_ERROR: a servo received the instruction damaged (it was resent)."""


class PortClient(BusClient, Protocol):
    """What a servo attached to the port implements (see :class:`DynamixelServo`)."""

    @property
    def dxl_id(self) -> int: ...

    def _poll_update(self, state: PresentState) -> None: ...

    def _poll_status_error(self, error: DynamixelStatusError) -> None: ...

    def _hardware_alert(self, error: DynamixelHardwareAlert) -> None: ...


class DynamixelPort(PolledBusPort[dx.Status, PortClient]):
    """A serial port carrying Dynamixel Protocol 2.0 servos; ``async with`` opens it.

    ``url`` is a device path (``/dev/ttyUSB0``, ``/dev/serial/by-id/...``) or a pyserial
    URL. ``return_delay`` is the servos' Return Delay Time in seconds (X-series
    default 250 x 2 us = 500 us). ``poll_period`` (s) paces the shared poller; 0 polls
    back to back. Time for the poll schedule and the states' timestamps comes from
    ``clock`` (the real clock by default: a serial bus runs in real time).
    """

    name: ClassVar[str] = "DynamixelPort"
    log_prefix: ClassVar[str] = "dxl"
    id_param: ClassVar[str] = "dxl_id"
    max_id: ClassVar[int] = dx.MAX_ID
    status_overhead: ClassVar[int] = STATUS_OVERHEAD
    sync_read_overhead: ClassVar[int] = SYNC_READ_OVERHEAD
    poll_address: ClassVar[int] = POLL_ADDRESS
    poll_length: ClassVar[int] = POLL_LENGTH
    status_type: ClassVar[type[Any]] = dx.Status
    timeout_error = DynamixelTimeoutError
    has_refusals: ClassVar[bool] = True

    stats: PortStats
    parser: dx.PacketParser

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
        self.stats = PortStats()
        self.parser = dx.PacketParser(max_length=max_packet)
        super().__init__(
            url,
            baudrate=baudrate,
            return_delay=return_delay,
            timeout_margin=timeout_margin,
            retries=retries,
            poll_period=poll_period,
            clock=clock,
            serial_options=serial_options,
        )
        self._bus_watchdogs: dict[int, float] = {}
        """Servos whose Bus Watchdog is armed: id -> timeout (s)."""
        self._last_poll_ns: int | None = None
        self._poll_start_ns = 0
        self._params_wanted = False
        """Whether the exchange in flight (:meth:`sync_read`'s) takes params by id."""
        self._params: dict[int, bytes] | None = None
        """Its params by id, when every status came checked in bulk with error byte 0."""

    # -- protocol ------------------------------------------------------------------
    def client_id(self, client: PortClient) -> int:
        return client.dxl_id

    def encode_sync_read(self, address: int, length: int, ids: tuple[int, ...]) -> bytes:
        return dx.encode(dx.SyncRead(address, length, ids))

    def encode_sync_write(self, address: int, length: int, data: Mapping[int, bytes]) -> bytes:
        items = tuple(dx.SyncWriteItem(dxl_id, bytes(d)) for dxl_id, d in data.items())
        return dx.encode(dx.SyncWrite(address, length, items))

    def estop_packet(self, every: bool, listed: Sequence[int]) -> bytes:
        item = X.TORQUE_ENABLE
        off = item.encode(0)
        items = tuple(dx.SyncWriteItem(i, off) for i in listed)
        return dx.encode(dx.SyncWrite(item.address, item.size, items))

    def refused(self, status: dx.Status) -> bool:
        return bool(status.error & _ERROR_NUMBER)

    def garbled(self, status: dx.Status) -> bool:
        return status.error & _ERROR_NUMBER == _CRC_ERROR

    def count_garbled(self, count: int) -> None:
        self.stats.crc_rejected += count

    # -- Bus Watchdog --------------------------------------------------------------
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

    # -- public requests -----------------------------------------------------------
    async def ping(self, dxl_id: int, *, check_alert: bool = False) -> PingInfo:
        """PING: model number, firmware and the error byte (alerts not raised by default)."""
        dx.Ping(dxl_id)  # validates the id
        status = await self._unicast(dx.encode(dx.Ping(dxl_id)), dxl_id, "PING", 3, check_alert)
        model, firmware = status.ping_info()
        return PingInfo(model, firmware, status.error)

    def broadcast_ping_window(self) -> float:
        """How long every servo of a bus takes to answer a broadcast PING: each id's turn
        comes 3 ms after the previous one (dynamixel-sdk waits the same), plus the wire
        time of a status from every id and the port's margin."""
        ids = dx.MAX_ID + 1
        return (
            ids * BROADCAST_PING_SLOT
            + wire_time(PING_PACKET + ids * (STATUS_OVERHEAD + 3), self.baudrate)
            + self.timeout_margin
        )

    async def broadcast_ping(self) -> dict[int, PingInfo]:
        """PING the broadcast id (0xFE): every servo on the bus answers in turn, in the
        order of their ids (Protocol 2.0). The answers that came within
        :meth:`broadcast_ping_window`, by id; sent once, never retried (a servo whose
        status was lost is simply absent)."""
        statuses = await self.collect(
            dx.encode(dx.Ping(dx.BROADCAST_ID)),
            range(dx.MAX_ID + 1),
            3,
            self.broadcast_ping_window(),
        )
        found = {}
        for dxl_id in sorted(statuses):
            model, firmware = statuses[dxl_id].ping_info()
            found[dxl_id] = PingInfo(model, firmware, statuses[dxl_id].error)
        return found

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
            await self.send_only(packet)
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
        """SYNC READ: ``{id: data}`` for every id, or raise (timeout, status error).

        When every status comes back in one read, each from an id asked for, with error
        byte 0 (the usual case), the reception hands the exchange the params by id
        directly (:meth:`~openel_serial.dynamixel.PacketParser.feed_bulk`: the same
        checks, no object per status); otherwise the statuses go through the retries
        and the error checks below.
        """
        ids = tuple(ids)
        packet = self.sync_read_packet(ids, address, length)  # validates
        lock = self._lock
        await lock.acquire()  # not ``async with``: two coroutines less per poll
        try:
            self._params_wanted = True
            try:
                got = await self._exchange(packet, ids, length)
            finally:
                self._params_wanted = False
                params, self._params = self._params, None
            if params is not None:
                return params
            if len(got) != len(ids) or self._garbled:

                def make(remaining: Sequence[int]) -> bytes:
                    return self.sync_read_packet(tuple(remaining), address, length)

                got = await self._retry(got, make, ids, f"SYNC READ {address}+{length}", length)
        finally:
            lock.release()
        if len(got) != len(ids):  # got holds only ids asked for
            missing = [i for i in ids if i not in got]
            raise self.sync_read_timeout_error(ids, missing, address, length)
        refused = 0xFF if check_alert else _ERROR_NUMBER  # the alert bit is bit 7
        out: dict[int, bytes] = {}
        for dxl_id in ids:
            status = got[dxl_id]
            if status.error & refused:
                raise DynamixelStatusError(dxl_id, status.error, f"SYNC READ {address}+{length}")
            out[dxl_id] = status.params
        return out

    # -- transactions --------------------------------------------------------------
    async def _unicast(
        self, packet: bytes, dxl_id: int, what: str, param_length: int, check_alert: bool
    ) -> dx.Status:
        if dxl_id == dx.BROADCAST_ID:
            raise BadParameterError("dxl_id", dxl_id, "a servo id (0..252), not broadcast")
        async with self._lock:
            status = await self.unicast_locked(packet, dxl_id, what, param_length)
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
            got = await self.transact(lambda _: packet, (dxl_id,), "READ 70+1", item.size)
        except PortDisconnectedError:
            got = {}
        status = got.get(dxl_id)
        if status is not None and status.error_number == 0 and len(status.params) == item.size:
            hardware = item.decode(status.params)
        return DynamixelHardwareAlert(dxl_id, error, what, hardware)

    # -- reception (transport callback) ----------------------------------------------
    def _on_data(self, data: bytes) -> None:
        expect = self._expect
        if expect is None:  # nobody waits: every status is stray
            for msg in self.parser.feed(data):
                if isinstance(msg, dx.Status):
                    self.stray(msg.id)
            return
        replies = self._replies
        if self._params_wanted and not replies:
            bulk = self.parser.feed_bulk(data, self._param_length)
            if bulk is not None:
                ids, errors, params = bulk
                if errors.count(0) == len(errors):  # no status refuses, none alerts
                    by_id = dict(zip(ids, params, strict=True))
                    if len(by_id) == len(expect) and expect.issuperset(by_id):
                        self._params = by_id  # every status, each from an id asked for
                        waiter = self._waiter
                        if waiter is not None:
                            complete(waiter)
                        return
                self._take_bulk(ids, errors, params)
                self.complete_if_done()
                return
        # The statuses we wait for, decoded in bulk when they come back to back: each a
        # Status with the expected param length, so only its id and error are checked.
        statuses, others = self.parser.feed_statuses(data, self._param_length)
        for msg in statuses:
            dxl_id = msg.id
            if dxl_id in expect and dxl_id not in replies:
                replies[dxl_id] = msg
                if msg.error & _ERROR_NUMBER == _CRC_ERROR:
                    self._garbled += 1
            else:
                self.stray(dxl_id)
        for other in others:
            if isinstance(other, dx.Status):  # not an echo of an instruction
                self.take_status(other)
        self.complete_if_done()

    def _take_bulk(self, ids: bytes, errors: bytes, params: tuple[bytes, ...]) -> None:
        """Statuses checked in bulk that :meth:`sync_read`'s direct path cannot take (an
        error byte set, an id not asked for or repeated): as :meth:`_on_data` takes them."""
        for dxl_id, error, data in zip(ids, errors, params, strict=True):
            self.take_status(dx.Status(dxl_id, error, data))

    # -- poller --------------------------------------------------------------------
    def poll_started(self, ids: Sequence[int]) -> bool:
        """Whether this poll comes more than half an armed Bus Watchdog timeout after the
        previous one (a servo may have stopped by itself meanwhile)."""
        start_ns = self._poll_start_ns = self.clock.now_ns()
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

    def poll_done(self) -> None:
        self._last_poll_ns = self._poll_start_ns

    def deliver(
        self, client: PortClient, status: dx.Status, transaction: int, now_ns: int, later: list[Any]
    ) -> None:
        if status.alert:
            later.append((status.id, status.error))
        elif status.error_number:
            self.stats.status_errors += 1
            what = f"SYNC READ {POLL_ADDRESS}+{POLL_LENGTH}"
            client._poll_status_error(DynamixelStatusError(status.id, status.error, what))
        if status.error_number == 0 and len(status.params) == POLL_LENGTH:
            client._poll_update(
                PresentState.decode(status.params, transaction, now_ns, status.error)
            )

    async def after_poll(self, ids: Sequence[int], later: list[Any], started: Any) -> None:
        """Hardware alerts (Hardware Error Status read), then the Bus Watchdogs when the
        poll came late."""
        for dxl_id, error in later:
            self.stats.alerts += 1
            async with self._lock:
                alert = await self._alert(dxl_id, error, f"SYNC READ {POLL_ADDRESS}")
            client = self._clients.get(dxl_id)
            if client is not None:
                client._hardware_alert(alert)
        if started:
            await self.check_bus_watchdogs(ids)
