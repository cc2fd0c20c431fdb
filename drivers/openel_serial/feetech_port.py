"""FeetechPort: one half-duplex Feetech SCS/STS bus, many servos (the STS3215 of an SO-101).

The same shape as :class:`~openel_serial.port.DynamixelPort`, on the same pieces
(:class:`~openel_serial.link.SerialLink`, :class:`~openel_serial.halfduplex.BusLock`): every
transaction (an instruction packet and the status packets it asks for) runs under the bus's
FIFO lock; the wait for the statuses is bounded by

    (instruction bytes + expected status bytes) x 10 bits / baud rate
    + number of statuses x return delay + timeout margin

and the missing ones are asked again up to ``retries`` times (a SYNC READ asks only the servos
that did not answer), then :class:`~openel_serial.errors.FeetechTimeoutError` is raised. A
status's error byte holds the servo's alarms (:class:`~openel_serial.feetech.StatusError`),
not a refusal: requests return normally and the poller reports the alarms to the servo.

Polling (the bank): while servos are attached, one task reads Present Position .. Present
Current (addresses 56..70) of all of them with ONE SYNC READ per cycle and hands each servo its
:class:`FeetechPresentState`.

Host watchdog: the STS/SCS have no bus watchdog of their own (nothing in the control table stops
a servo when the host goes silent; their protections -- 19 unloading condition, 34..36
protective/overload torque and time, 13..15 temperature and voltage limits -- are for faults,
not for communication). :meth:`FeetechPort.arm_host_watchdog` starts what the protocol allows
instead: a thread of the port that, when the poller (a task of the event loop) has not completed
a cycle for ``timeout_s``, writes a broadcast WRITE of Torque Enable (40) = 0 straight to the
port's file descriptor, so the servos go limp while the loop is stalled; the servos' components
are told (``ErrorId.WATCHDOG``) when the loop runs again. It cannot help when the host process
dies (kill -9, a crash: the servos hold their last goal with the torque on), when the USB
adapter or the cable is gone, or when the stalled code holds the GIL in C for longer than the
timeout.

E-stop: :meth:`FeetechPort.estop` writes Torque Enable (40) = 0 to every servo at once (a
broadcast WRITE to 0xFE; given ids: a SYNC WRITE), ahead of every queued transaction.

Faults: a vanished port is reported to every attached servo (``ErrorId.DISCONNECTED``);
:meth:`FeetechPort.reconnect` reopens it.
"""

from __future__ import annotations

import asyncio
import math
import os
import threading
import time
from collections.abc import Mapping, Sequence
from contextlib import AsyncExitStack
from dataclasses import dataclass
from types import TracebackType
from typing import Any, Final, Protocol, Self

import anyio
import anyio.lowlevel
import anyio.to_thread

from openel_async.clock import Clock, default_clock
from openel_async.errors import BadParameterError, HALError
from openel_async.logs import get_logger
from openel_serial import feetech as ft
from openel_serial.errors import (
    FeetechTimeoutError,
    PortDisconnectedError,
)
from openel_serial.halfduplex import BusLock, complete, positive, wire_time
from openel_serial.link import SerialLink

__all__ = [
    "DEFAULT_RETURN_DELAY",
    "POLL_ADDRESS",
    "POLL_LENGTH",
    "FeetechPingInfo",
    "FeetechPort",
    "FeetechPortStats",
    "FeetechPresentState",
]

log = get_logger(__name__)

S = ft.STS
POLL_ADDRESS: Final = S.PRESENT_POSITION.address  # 56
POLL_LENGTH: Final = S.PRESENT_CURRENT.address + S.PRESENT_CURRENT.size - POLL_ADDRESS  # 15
DEFAULT_RETURN_DELAY: Final = 500e-6
"""The STS3215's factory Return Delay (7): 250 x 2 us (LeRobot sets 0)."""
SYNC_READ_OVERHEAD: Final = 8
"""Bytes of a SYNC READ besides its id list: header 2, id, length, instruction, address,
length, checksum."""
TORQUE_OFF_BROADCAST: Final = ft.encode(ft.Write(ft.BROADCAST_ID, S.TORQUE_ENABLE.address, b"\x00"))
"""``FF FF FE 04 03 28 00 D2``: every servo on the bus, torque off (no status comes back)."""


@dataclass(frozen=True, slots=True)
class FeetechPingInfo:
    model_number: int
    error: int
    """The PING status's error byte (the servo's alarms)."""


@dataclass(frozen=True, slots=True)
class FeetechPresentState:
    """One poll of one servo: addresses 56..70, decoded (sign-magnitude applied)."""

    transaction: int
    """The port's transaction number of the SYNC READ (later reads have larger ones)."""
    time_ns: int
    position: int
    """Present Position (56), steps."""
    speed: int
    """Present Speed (58), steps/s."""
    load: int
    """Present Load (60), 0.1 % of the stall torque."""
    voltage: int
    """Present Voltage (62), 0.1 V."""
    temperature: int
    """Present Temperature (63), deg C."""
    status: int
    """Servo status (65): the alarm bits in force."""
    moving: bool
    current: int
    """Present Current (69), 6.5 mA."""
    error: int = 0
    """The status packet's error byte."""

    @classmethod
    def decode(cls, params: bytes, transaction: int, time_ns: int, error: int = 0) -> Self:
        def at(item: ft.ControlItem) -> int:
            return item.of(params, POLL_ADDRESS)

        return cls(
            transaction,
            time_ns,
            at(S.PRESENT_POSITION),
            at(S.PRESENT_SPEED),
            at(S.PRESENT_LOAD),
            at(S.PRESENT_VOLTAGE),
            at(S.PRESENT_TEMPERATURE),
            at(S.SERVO_STATUS),
            bool(at(S.MOVING)),
            at(S.PRESENT_CURRENT),
            error,
        )


@dataclass(slots=True)
class FeetechPortStats:
    transactions: int = 0
    retries: int = 0
    timeouts: int = 0
    stray: int = 0
    """Status packets nobody waited for (late answers), dropped."""
    poll_cycles: int = 0
    poll_misses: int = 0
    alarms: int = 0
    """Polled statuses with alarm bits set."""
    reconnects: int = 0
    losses: int = 0
    watchdog_trips: int = 0


class FeetechClient(Protocol):
    """What a servo attached to the port implements (see :class:`FeetechServo`)."""

    @property
    def servo_id(self) -> int: ...

    @property
    def polled(self) -> bool: ...

    def _poll_update(self, state: FeetechPresentState) -> None: ...

    def _poll_missed(self, error: FeetechTimeoutError) -> None: ...

    def _port_lost(self, reason: str) -> None: ...

    def _watchdog_tripped(self, reason: str) -> None: ...

    def _estopped(self, reason: str) -> None: ...


class HostWatchdog:
    """The port's watchdog thread (see the module docstring): fed by the poller from the
    event loop; past ``timeout_s`` without a feed it writes :data:`TORQUE_OFF_BROADCAST` to
    the port's fd (twice, in case a partial packet was on the wire) and records the trip."""

    def __init__(self, link: SerialLink, url: str) -> None:
        self._link = link
        self._url = url
        self._lock = threading.Lock()
        self._timeout: float | None = None
        self._last_feed = time.monotonic()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.tripped_after: float | None = None
        """Seconds without a feed when it last tripped (None: not tripped since cleared)."""
        self.trips = 0

    @property
    def timeout(self) -> float | None:
        return self._timeout

    def feed(self) -> None:
        self._last_feed = time.monotonic()

    def arm(self, timeout_s: float) -> None:
        with self._lock:
            self._timeout = timeout_s
            self._last_feed = time.monotonic()
            if self._thread is None:
                self._stop.clear()
                self._thread = threading.Thread(
                    target=self._run, name=f"feetech-host-watchdog {self._url}", daemon=True
                )
                self._thread.start()

    def disarm(self) -> None:
        with self._lock:
            self._timeout = None

    def take_trip(self) -> float | None:
        """The trip's duration if it tripped since the last call (then clears it)."""
        with self._lock:
            tripped, self.tripped_after = self.tripped_after, None
            if tripped is not None:
                self._last_feed = time.monotonic()  # the loop that asks is running
            return tripped

    async def stop(self) -> None:
        thread = self._thread
        self._thread = None
        self._timeout = None
        self._stop.set()
        if thread is not None:
            await anyio.to_thread.run_sync(thread.join, 1.0)

    def _run(self) -> None:
        while True:
            timeout = self._timeout
            period = 0.05 if timeout is None else max(0.001, timeout / 4)
            if self._stop.wait(period):
                return
            with self._lock:
                timeout = self._timeout
                if timeout is None or self.tripped_after is not None:
                    continue
                silent = time.monotonic() - self._last_feed
                if silent <= timeout:
                    continue
                fd = self._link.fileno()
                if fd is None:
                    continue
                try:
                    os.write(fd, TORQUE_OFF_BROADCAST * 2)
                except OSError:
                    continue  # the port is gone: the loop will see it
                self.tripped_after = silent
                self.trips += 1


class FeetechPort:
    """A serial port carrying Feetech SCS/STS servos; ``async with`` opens it.

    ``url``: a device path or pyserial URL (``/dev/ttyACM0`` for the SO-101's Waveshare
    board). ``return_delay`` (s): the servos' Return Delay (7) (factory 500 us). ``poll_period``
    (s) paces the shared poller; 0 polls back to back.
    """

    def __init__(
        self,
        url: str,
        *,
        baudrate: int = 1_000_000,
        return_delay: float = DEFAULT_RETURN_DELAY,
        timeout_margin: float = 0.02,
        retries: int = 2,
        poll_period: float = 0.01,
        clock: Clock | None = None,
        serial_options: Mapping[str, Any] | None = None,
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
        self.stats = FeetechPortStats()
        self.parser = ft.PacketParser(status=True)
        self._link = SerialLink(
            url,
            baudrate=baudrate,
            on_data=self._on_data,
            on_lost=self._on_lost,
            serial_options=serial_options,
        )
        self._lock = BusLock()
        self._reconnect_lock = anyio.Lock()
        self._clients: dict[int, FeetechClient] = {}
        self._transaction = 0
        self._expect: set[int] | None = None
        self._replies: dict[int, ft.Status] = {}
        self._param_length = 0
        self._waiter: asyncio.Future[None] | None = None
        self._poll_wake: anyio.Event | None = None
        self._estop_ids: set[int] | None = None
        self._estop_all = False
        self.watchdog = HostWatchdog(self._link, url)
        self._watchdog_ids: dict[int, float] = {}
        self._stack: AsyncExitStack | None = None
        self._entered = False
        self._log = log.bind(port=url)

    # -- lifecycle -----------------------------------------------------------------
    async def __aenter__(self) -> Self:
        if self._entered:
            raise HALError(f"FeetechPort {self.url} is already entered")
        self._entered = True
        stack = AsyncExitStack()
        try:
            await self._link.open()
            stack.push_async_callback(self._link.close)
            stack.push_async_callback(self.watchdog.stop)
            tg = await stack.enter_async_context(anyio.create_task_group())
            stack.callback(tg.cancel_scope.cancel)
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
        if stack is not None:
            await stack.aclose()

    @property
    def connected(self) -> bool:
        return self._link.is_open

    @property
    def transactions(self) -> int:
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
    def attach(self, client: FeetechClient) -> None:
        servo_id = client.servo_id
        other = self._clients.get(servo_id)
        if other is not None and other is not client:
            raise BadParameterError(
                "servo_id", servo_id, f"an id not already used on {self.url} by {other!r}"
            )
        self._clients[servo_id] = client
        self.wake_poller()

    def detach(self, client: FeetechClient) -> None:
        if self._clients.get(client.servo_id) is client:
            del self._clients[client.servo_id]
        self.disarm_host_watchdog(client.servo_id)

    @property
    def clients(self) -> Mapping[int, FeetechClient]:
        return dict(self._clients)

    def wake_poller(self) -> None:
        if self._poll_wake is not None:
            self._poll_wake.set()

    # -- host watchdog and e-stop --------------------------------------------------------
    def arm_host_watchdog(self, servo_id: int, timeout_s: float) -> None:
        """Count servo ``servo_id`` in the host watchdog with ``timeout_s`` (the shortest of
        the armed servos' applies to the port); refused (:class:`BadParameterError` naming
        ``timeout_s``) unless ``poll_period`` is below half of it."""
        if not (math.isfinite(timeout_s) and self.poll_period < timeout_s / 2):
            raise BadParameterError(
                "timeout_s",
                timeout_s,
                f"a finite number of seconds above twice the poll_period of {self.url} "
                f"({self.poll_period} s): the poller feeds the host watchdog",
            )
        self._watchdog_ids[servo_id] = float(timeout_s)
        self.watchdog.arm(min(self._watchdog_ids.values()))
        self.wake_poller()

    def disarm_host_watchdog(self, servo_id: int) -> None:
        self._watchdog_ids.pop(servo_id, None)
        if self._watchdog_ids:
            self.watchdog.arm(min(self._watchdog_ids.values()))
        else:
            self.watchdog.disarm()

    @property
    def host_watchdogs(self) -> Mapping[int, float]:
        return dict(self._watchdog_ids)

    def _check_watchdog_trip(self) -> None:
        silent = self.watchdog.take_trip()
        if silent is None:
            return
        self.stats.watchdog_trips += 1
        reason = (
            f"{self.url}: host watchdog: no poll for {silent:.3f} s (> "
            f"{self.watchdog.timeout} s): every servo's torque was turned off"
        )
        self._log.warning("feetech_host_watchdog_tripped", silent_s=silent)
        for servo_id in list(self._watchdog_ids):
            client = self._clients.get(servo_id)
            if client is not None:
                client._watchdog_tripped(reason)

    async def estop(self, ids: Sequence[int] | None = None) -> None:
        """Torque Enable (40) = 0 now, ahead of every queued transaction: a broadcast WRITE
        (every servo on the bus, attached or not) by default, a SYNC WRITE to ``ids`` when
        given. With the default every attached servo is told (its component goes to Error with
        ``ErrorId.ESTOP``). Calls made together share one packet."""
        if ids is not None:
            for servo_id in ids:
                if isinstance(servo_id, bool) or not isinstance(servo_id, int):
                    raise BadParameterError("ids", ids, f"servo ids in 0..{ft.MAX_ID}")
                if not 0 <= servo_id <= ft.MAX_ID:
                    raise BadParameterError("ids", ids, f"servo ids in 0..{ft.MAX_ID}")
        if ids is None:
            self._estop_all = True
        else:
            if self._estop_ids is None:
                self._estop_ids = set()
            self._estop_ids.update(ids)
        await anyio.lowlevel.checkpoint()  # let the other e-stops of this instant join
        await self._lock.acquire(first=True)
        try:
            every, self._estop_all = self._estop_all, False
            listed, self._estop_ids = self._estop_ids, None
            if every or listed:
                self.check_connected()
                if every:
                    packet = TORQUE_OFF_BROADCAST
                else:
                    assert listed is not None
                    item = S.TORQUE_ENABLE
                    packet = ft.encode(
                        ft.SyncWrite(
                            item.address,
                            item.size,
                            tuple(ft.SyncWriteItem(i, b"\x00") for i in sorted(listed)),
                        )
                    )
                self._transaction += 1
                self.stats.transactions += 1
                self._link.write(packet)
                self._log.warning("feetech_estop", ids="all" if every else sorted(listed or ()))
        finally:
            self._lock.release()
        if ids is None:
            for client in list(self._clients.values()):
                client._estopped(f"e-stop on {self.url}: torque off")

    # -- timing --------------------------------------------------------------------
    def response_timeout(self, request_bytes: int, statuses: int, param_length: int) -> float:
        reply_bytes = statuses * (ft.STATUS_OVERHEAD + param_length)
        return (
            wire_time(request_bytes + reply_bytes, self.baudrate)
            + statuses * self.return_delay
            + self.timeout_margin
        )

    # -- requests ------------------------------------------------------------------
    async def ping(self, servo_id: int) -> FeetechPingInfo:
        """PING, then Model Number (3) as the vendor's SDK does."""
        status = await self._unicast(ft.encode(ft.Ping(servo_id)), servo_id, "PING", 0)
        model = await self.read_item(servo_id, S.MODEL_NUMBER)
        return FeetechPingInfo(model, status.error)

    async def read(self, servo_id: int, address: int, length: int) -> bytes:
        packet = ft.encode(ft.Read(servo_id, address, length))
        status = await self._unicast(packet, servo_id, f"READ {address}+{length}", length)
        return status.params

    async def read_item(self, servo_id: int, item: ft.ControlItem) -> int:
        return item.decode(await self.read(servo_id, item.address, item.size))

    async def write(self, servo_id: int, address: int, data: bytes, *, ack: bool = True) -> int:
        """WRITE ``data`` at ``address``; returns the status's error byte (0 without ``ack``:
        Response Status Level 0, or broadcast)."""
        packet = ft.encode(ft.Write(servo_id, address, bytes(data)))
        if not ack or servo_id == ft.BROADCAST_ID:
            await self._send_only(packet)
            return 0
        status = await self._unicast(packet, servo_id, f"WRITE {address}+{len(data)}", 0)
        return status.error

    async def write_item(
        self, servo_id: int, item: ft.ControlItem, value: int, *, ack: bool = True
    ) -> int:
        return await self.write(servo_id, item.address, item.encode(value), ack=ack)

    async def write_eeprom(
        self, servo_id: int, writes: Sequence[tuple[ft.ControlItem, int]], *, ack: bool = True
    ) -> None:
        """EEPROM writes kept at power-off: Lock (55) = 0, the writes, Lock = 1, then each
        read back (HALError naming the register if the servo kept another value). The torque
        should be off (the vendor's tools do so)."""
        await self.write_item(servo_id, S.LOCK, 0, ack=ack)
        try:
            for item, value in writes:
                await self.write_item(servo_id, item, value, ack=ack)
        finally:
            await self.write_item(servo_id, S.LOCK, 1, ack=ack)
        for item, value in writes:
            got = await self.read_item(servo_id, item)
            if got != value:
                raise HALError(
                    f"servo {servo_id}: register {item.address} reads {got} after writing {value}"
                )

    async def sync_write(self, address: int, length: int, data: Mapping[int, bytes]) -> None:
        """SYNC WRITE ``{id: data}`` (no status packets)."""
        items = tuple(ft.SyncWriteItem(i, bytes(d)) for i, d in data.items())
        if not items:
            raise BadParameterError("data", data, "at least one {id: bytes} item")
        await self._send_only(ft.encode(ft.SyncWrite(address, length, items)))

    async def sync_write_item(self, item: ft.ControlItem, values: Mapping[int, int]) -> None:
        await self.sync_write(
            item.address, item.size, {i: item.encode(v) for i, v in values.items()}
        )

    async def sync_read(self, ids: Sequence[int], address: int, length: int) -> dict[int, bytes]:
        """SYNC READ: ``{id: data}`` for every id, or :class:`FeetechTimeoutError`."""
        ids = tuple(ids)
        statuses = await self.sync_read_statuses(ids, address, length)
        missing = [i for i in ids if i not in statuses]
        if missing:
            timeout = self.response_timeout(SYNC_READ_OVERHEAD + len(ids), len(ids), length)
            raise FeetechTimeoutError(
                self.url, missing, f"SYNC READ {address}+{length}", timeout, self.retries + 1
            )
        return {i: statuses[i].params for i in ids}

    async def sync_read_statuses(
        self, ids: Sequence[int], address: int, length: int
    ) -> dict[int, ft.Status]:
        """SYNC READ returning the statuses that arrived (missing ones retried, not raised)."""
        ids = tuple(ids)
        if not ids or len(set(ids)) != len(ids):
            raise BadParameterError("ids", ids, "a non-empty sequence of distinct servo ids")
        ft.SyncRead(address, length, ids)  # validates
        async with self._lock:
            result: dict[int, ft.Status] = {}
            remaining = list(ids)
            for attempt in range(self.retries + 1):
                if attempt:
                    self.stats.retries += 1
                packet = ft.encode(ft.SyncRead(address, length, tuple(remaining)))
                result.update(await self._exchange(packet, remaining, length))
                remaining = [i for i in remaining if i not in result]
                if not remaining:
                    break
            else:
                self.stats.timeouts += 1
                self._log.warning(
                    "feetech_no_status", request=f"SYNC READ {address}+{length}", ids=remaining
                )
            return result

    # -- transactions --------------------------------------------------------------
    async def _send_only(self, packet: bytes) -> None:
        async with self._lock:
            self.check_connected()
            self._transaction += 1
            self.stats.transactions += 1
            self._link.write(packet)
            await anyio.lowlevel.checkpoint()

    async def _unicast(
        self, packet: bytes, servo_id: int, what: str, param_length: int
    ) -> ft.Status:
        if not 0 <= servo_id <= ft.MAX_ID:
            raise BadParameterError("servo_id", servo_id, f"a servo id in 0..{ft.MAX_ID}")
        async with self._lock:
            for attempt in range(self.retries + 1):
                if attempt:
                    self.stats.retries += 1
                got = await self._exchange(packet, (servo_id,), param_length)
                status = got.get(servo_id)
                if status is not None:
                    return status
            self.stats.timeouts += 1
        raise FeetechTimeoutError(
            self.url,
            (servo_id,),
            what,
            self.response_timeout(len(packet), 1, param_length),
            self.retries + 1,
        )

    async def _exchange(
        self, packet: bytes, ids: Sequence[int], param_length: int
    ) -> dict[int, ft.Status]:
        """One attempt: write ``packet``, wait for a status from each id or the timeout."""
        self.check_connected()
        self._transaction += 1
        self.stats.transactions += 1
        # No delimiter but FF FF: a frame left incomplete by noise (a false header whose
        # length byte promises more) would swallow the replies. Nothing else is in flight on
        # a half-duplex bus when a request starts: drop it.
        self.parser.reset()
        self._link.write(packet)
        loop = asyncio.get_running_loop()
        waiter: asyncio.Future[None] = loop.create_future()
        replies: dict[int, ft.Status] = {}
        self._replies = replies
        self._expect = set(ids)
        self._param_length = param_length
        self._waiter = waiter
        timeout = self.response_timeout(len(packet), len(ids), param_length)
        timer = loop.call_later(timeout, complete, waiter)
        try:
            await waiter
        finally:
            timer.cancel()
            self._expect = None
            self._waiter = None
        if len(replies) != len(ids):
            self.check_connected()  # lost while waiting: raise, not a timeout
        return replies

    # -- reception (transport callback) ----------------------------------------------
    def _on_data(self, data: bytes) -> None:
        expect = self._expect
        for msg in self.parser.feed(data):
            if not isinstance(msg, ft.Status):
                continue
            if (
                expect is None
                or msg.id not in expect
                or msg.id in self._replies
                or len(msg.params) != self._param_length
            ):
                self.stats.stray += 1
                continue
            self._replies[msg.id] = msg
        waiter = self._waiter
        if waiter is not None and expect is not None and len(self._replies) == len(expect):
            complete(waiter)

    def _on_lost(self, reason: str) -> None:
        self.stats.losses += 1
        if self._waiter is not None:
            complete(self._waiter)
        for client in list(self._clients.values()):
            client._port_lost(f"{self.url}: {reason}")

    # -- poller (the bank) -----------------------------------------------------------
    def _poll_ids(self) -> list[int]:
        return sorted(i for i, c in self._clients.items() if c.polled)

    async def poll_once(self) -> None:
        """One cycle: SYNC READ 56..70 of every polled servo, then dispatch."""
        ids = self._poll_ids()
        if not ids:
            return
        statuses = await self.sync_read_statuses(ids, POLL_ADDRESS, POLL_LENGTH)
        self.watchdog.feed()
        transaction = self._transaction
        now = self.clock.now_ns()
        self.stats.poll_cycles += 1
        for servo_id in ids:
            client = self._clients.get(servo_id)
            if client is None:
                continue
            status = statuses.get(servo_id)
            if status is None:
                self.stats.poll_misses += 1
                timeout = self.response_timeout(
                    SYNC_READ_OVERHEAD + len(ids), len(ids), POLL_LENGTH
                )
                client._poll_missed(
                    FeetechTimeoutError(
                        self.url,
                        (servo_id,),
                        f"SYNC READ {POLL_ADDRESS}+{POLL_LENGTH}",
                        timeout,
                        self.retries + 1,
                    )
                )
                continue
            if status.error:
                self.stats.alarms += 1
            client._poll_update(
                FeetechPresentState.decode(status.params, transaction, now, status.error)
            )

    async def _poll_loop(self) -> None:
        clock = self.clock
        next_ns = clock.now_ns()
        period_ns = round(self.poll_period * 1e9)
        while True:
            self._check_watchdog_trip()
            if self._link.is_open:
                self.watchdog.feed()  # the event loop runs
            if not self._link.is_open or not self._poll_ids():
                self._poll_wake = anyio.Event()
                if not self._link.is_open or not self._poll_ids():
                    if self.watchdog.timeout is None:
                        await self._poll_wake.wait()
                    else:  # idle but armed: feed the host watchdog (the loop is alive)
                        with anyio.move_on_after(self.watchdog.timeout / 4):
                            await self._poll_wake.wait()
                        if self._link.is_open:
                            self.watchdog.feed()
                self._poll_wake = None
                next_ns = clock.now_ns()
                continue
            try:
                await self.poll_once()
            except (HALError, OSError) as exc:
                if self._link.is_open:
                    self._log.warning("feetech_poll_failed", error=str(exc))
            next_ns += period_ns
            now = clock.now_ns()
            if next_ns < now:
                next_ns = now
            await clock.sleep_until(next_ns)

    def __repr__(self) -> str:
        state = "open" if self.connected else "closed"
        return f"FeetechPort({self.url!r}, {self.baudrate} bd, {state})"
