"""PolledBusPort: a half-duplex servo bus polled with one SYNC READ per cycle, any protocol.

What :class:`~openel_serial.port.DynamixelPort` and
:class:`~openel_serial.feetech_port.FeetechPort` share, once: the port's lifecycle
(``async with`` opens the :class:`~openel_serial.link.SerialLink` and starts the poller),
:meth:`PolledBusPort.reconnect`, the registry of attached servos (clients), the transaction
machinery (every request under the bus's FIFO :class:`~openel_serial.halfduplex.BusLock`,
its wait for the statuses bounded by :meth:`PolledBusPort.response_timeout`, the missing
ones asked again up to ``retries`` times), the reception callback, the e-stop's coalescing
(calls made together share one packet, sent ahead of every queued transaction) and the
poller (one SYNC READ of every polled servo per cycle, the results handed to the servos).

A protocol subclass supplies what differs: its packet codec (:meth:`encode_sync_read`,
:meth:`encode_sync_write`, the parser, the status type), the poll window
(``poll_address``, ``poll_length``) and how a polled status reaches its servo
(:meth:`deliver`), the e-stop packet, and its safety features through the hooks
(:meth:`enter_extras`, :meth:`poll_loop_tick`, :meth:`idle_timeout`, :meth:`after_poll`).
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Mapping, Sequence
from contextlib import AsyncExitStack
from dataclasses import dataclass
from types import TracebackType
from typing import Any, ClassVar, Final, Generic, Protocol, Self, TypeVar

import anyio
import anyio.lowlevel

from openel_async.clock import Clock, default_clock
from openel_async.errors import BadParameterError, HALError
from openel_async.logs import get_logger
from openel_serial.errors import PortDisconnectedError, ServoTimeoutError
from openel_serial.halfduplex import BusLock, complete, positive, wire_time
from openel_serial.link import SerialLink

__all__ = [
    "SYNC_READ_CACHE",
    "BusClient",
    "BusParser",
    "BusStats",
    "BusStatus",
    "PolledBusPort",
    "RegisterItem",
]

log = get_logger(__name__)

SYNC_READ_CACHE: Final = 64
"""SYNC READ instruction packets kept per port, by (address, length, ids)."""


class BusStatus(Protocol):
    """A decoded status packet: who answered, its error byte, the params."""

    @property
    def id(self) -> int: ...

    @property
    def error(self) -> int: ...

    @property
    def params(self) -> bytes: ...


class RegisterItem(Protocol):
    """A control-table item of any protocol: ``size`` bytes at ``address``."""

    @property
    def address(self) -> int: ...

    @property
    def size(self) -> int: ...

    def encode(self, value: int) -> bytes: ...


class BusParser(Protocol):
    """The protocol's stream parser (bytes in, messages out)."""

    def feed(self, data: bytes) -> Sequence[object]: ...

    def reset(self) -> None: ...


class BusClient(Protocol):
    """What every servo attached to a port implements (the port calls these)."""

    @property
    def polled(self) -> bool: ...

    def _poll_missed(self, error: Any) -> None: ...

    def _port_lost(self, reason: str) -> None: ...

    def _watchdog_tripped(self, reason: str) -> None: ...

    def _estopped(self, reason: str) -> None: ...


@dataclass(slots=True)
class BusStats:
    """Counters every port keeps (the protocol ports add their own)."""

    transactions: int = 0
    retries: int = 0
    timeouts: int = 0
    stray: int = 0
    """Status packets nobody waited for (late answers), dropped."""
    poll_cycles: int = 0
    poll_misses: int = 0
    reconnects: int = 0
    losses: int = 0


StatusT = TypeVar("StatusT", bound=BusStatus)
ClientT = TypeVar("ClientT", bound=BusClient)


class PolledBusPort(Generic[StatusT, ClientT]):
    """A serial port carrying one protocol's servos; ``async with`` opens it.

    ``url``: a device path or pyserial URL. ``return_delay`` (s): the servos' return delay.
    ``poll_period`` (s) paces the shared poller; 0 polls back to back. Time for the poll
    schedule and the states' timestamps comes from ``clock``.
    """

    name: ClassVar[str] = "PolledBusPort"
    """The class name in messages (``DynamixelPort`` ...)."""
    log_prefix: ClassVar[str] = "bus"
    """Prefix of the port's log events (``dxl``, ``feetech``)."""
    id_param: ClassVar[str] = "servo_id"
    """The servos' id parameter name (in :class:`BadParameterError`)."""
    max_id: ClassVar[int] = 0xFD
    status_overhead: ClassVar[int] = 0
    """Bytes of a status packet besides its params."""
    sync_read_overhead: ClassVar[int] = 0
    """Bytes of a SYNC READ packet besides its id list."""
    poll_address: ClassVar[int] = 0
    poll_length: ClassVar[int] = 0
    status_type: ClassVar[type[Any]] = object
    """The codec's status class (the parser yields instructions too: echoes)."""
    timeout_error: ClassVar[type[ServoTimeoutError]] = ServoTimeoutError
    reset_parser_per_request: ClassVar[bool] = False
    """Drop what the parser holds before each request (no delimiter but the header)."""
    has_refusals: ClassVar[bool] = False
    """Whether a status may refuse an instruction (:meth:`refused`; Dynamixel 2.0's error
    numbers); without, reception takes the statuses of the right length inline."""
    estop_broadcasts: ClassVar[bool] = False
    """A default e-stop (no ids) is one broadcast packet (every servo on the bus)."""

    stats: BusStats
    parser: BusParser

    def __init__(
        self,
        url: str,
        *,
        baudrate: int,
        return_delay: float,
        timeout_margin: float,
        retries: int,
        poll_period: float,
        clock: Clock | None,
        serial_options: Mapping[str, Any] | None,
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
        self._link = SerialLink(
            url,
            baudrate=baudrate,
            on_data=self._on_data,
            on_lost=self._on_lost,
            serial_options=serial_options,
        )
        # An uncontended acquire does not yield; a contended one queues, and release hands
        # the lock to the first waiter (FIFO); an e-stop goes first.
        self._lock = BusLock()
        self._reconnect_lock = anyio.Lock()
        self._clients: dict[int, ClientT] = {}
        self._transaction = 0
        # The exchange in flight: ids expected (and their param length), what arrived,
        # how many of those say the instruction arrived damaged, the future its task waits on.
        self._expect: set[int] | None = None
        self._replies: dict[int, StatusT] = {}
        self._garbled = 0
        self._param_length = 0
        self._waiter: asyncio.Future[None] | None = None
        self._deadline = 0.0
        self._timer: asyncio.TimerHandle | None = None
        self._sync_read_packets: dict[tuple[int, int, tuple[int, ...]], bytes] = {}
        self._last_sync_read: tuple[object, int, int, bytes] = ((), -1, -1, b"")
        self._poll_wake: anyio.Event | None = None
        self._estop_ids: set[int] = set()
        self._estop_all = False
        self._stack: AsyncExitStack | None = None
        self._entered = False
        self._log = get_logger(type(self).__module__).bind(port=url)  # the protocol module's

    # -- protocol (subclasses) -----------------------------------------------------
    def client_id(self, client: ClientT) -> int:
        """The servo id ``client`` answers to."""
        raise NotImplementedError

    def encode_sync_read(self, address: int, length: int, ids: tuple[int, ...]) -> bytes:
        """The SYNC READ packet (ValueError for an address, length or id out of range)."""
        raise NotImplementedError

    def encode_sync_write(self, address: int, length: int, data: Mapping[int, bytes]) -> bytes:
        raise NotImplementedError

    def estop_packet(self, every: bool, listed: Sequence[int]) -> bytes:
        """Torque off: every servo on the bus (``every``) or those ``listed``."""
        raise NotImplementedError

    def refused(self, status: StatusT) -> bool:
        """Whether ``status`` refuses the instruction (then it carries no params)."""
        return False

    def garbled(self, status: StatusT) -> bool:
        """Whether ``status`` says the instruction arrived damaged (sent again)."""
        return False

    def deliver(
        self, client: ClientT, status: StatusT, transaction: int, now_ns: int, later: list[Any]
    ) -> None:
        """Hand ``client`` its polled ``status``; what needs the bus goes to ``later``."""
        raise NotImplementedError

    async def after_poll(self, ids: Sequence[int], later: list[Any], started: Any) -> None:
        """After a poll cycle's dispatch (lock not held): ``later`` from :meth:`deliver`,
        ``started`` from :meth:`poll_started`."""

    def poll_started(self, ids: Sequence[int]) -> Any:
        """Called as a poll cycle starts; the result goes to :meth:`after_poll`."""
        return None

    def poll_done(self) -> None:
        """Called when a poll cycle's SYNC READ is over."""

    def poll_loop_tick(self) -> None:
        """Called at the top of every poller iteration (the event loop runs)."""

    def idle_timeout(self) -> float | None:
        """How long the idle poller may sleep (None: until woken)."""
        return None

    def enter_extras(self, stack: AsyncExitStack) -> None:
        """Register the protocol's own clean-ups (the link is open, the poller not started)."""

    # -- lifecycle -----------------------------------------------------------------
    async def __aenter__(self) -> Self:
        if self._entered:
            raise HALError(f"{self.name} {self.url} is already entered")
        self._entered = True
        stack = AsyncExitStack()
        try:
            await self._link.open()
            stack.push_async_callback(self._link.close)
            self.enter_extras(stack)
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
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
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
    def attach(self, client: ClientT) -> None:
        """Register a servo for polling and fault reports; its id must be free."""
        servo_id = self.client_id(client)
        other = self._clients.get(servo_id)
        if other is not None and other is not client:
            raise BadParameterError(
                self.id_param, servo_id, f"an id not already used on {self.url} by {other!r}"
            )
        self._clients[servo_id] = client
        self.wake_poller()

    def detach(self, client: ClientT) -> None:
        servo_id = self.client_id(client)
        if self._clients.get(servo_id) is client:
            del self._clients[servo_id]

    @property
    def clients(self) -> Mapping[int, ClientT]:
        return dict(self._clients)

    def wake_poller(self) -> None:
        if self._poll_wake is not None:
            self._poll_wake.set()

    # -- e-stop --------------------------------------------------------------------
    def check_ids(self, ids: Sequence[int]) -> None:
        """BadParameterError naming ``ids`` unless every one is a servo id."""
        for servo_id in ids:
            if isinstance(servo_id, bool) or not isinstance(servo_id, int):
                raise BadParameterError("ids", ids, f"servo ids in 0..{self.max_id}")
            if not 0 <= servo_id <= self.max_id:
                raise BadParameterError("ids", ids, f"servo ids in 0..{self.max_id}")

    async def estop(self, ids: Sequence[int] | None = None) -> None:
        """Torque off now, ahead of every queued transaction (only the exchange on the wire
        is waited for): ``ids``, or by default every attached servo (a broadcast where the
        protocol has one: every servo on the bus); with the default every attached servo is
        told (its component goes to Error with ``ErrorId.ESTOP``). Calls made together share
        one packet."""
        if ids is None and self.estop_broadcasts:
            self._estop_all = True
        else:
            targets = sorted(self._clients) if ids is None else list(ids)
            if not targets:
                return
            self.check_ids(targets)
            self._estop_ids.update(targets)
        await anyio.lowlevel.checkpoint()  # let the other e-stops of this instant join
        await self._lock.acquire(first=True)
        try:
            every, self._estop_all = self._estop_all, False
            listed, self._estop_ids = sorted(self._estop_ids), set()
            if every or listed:
                self.check_connected()
                packet = self.estop_packet(every, listed)
                self._transaction += 1
                self.stats.transactions += 1
                self._link.write(packet)
                self._log.warning(f"{self.log_prefix}_estop", ids="all" if every else listed)
        finally:
            self._lock.release()
        if ids is None:
            for client in list(self._clients.values()):
                client._estopped(f"e-stop on {self.url}: torque off")

    # -- timing --------------------------------------------------------------------
    def response_timeout(self, request_bytes: int, statuses: int, param_length: int) -> float:
        """The wait for ``statuses`` status packets of ``param_length`` params each."""
        reply_bytes = statuses * (self.status_overhead + param_length)
        return (
            wire_time(request_bytes + reply_bytes, self.baudrate)
            + statuses * self.return_delay
            + self.timeout_margin
        )

    def sync_read_timeout_error(
        self, ids: Sequence[int], missing: Sequence[int], address: int, length: int
    ) -> ServoTimeoutError:
        """The timeout error of a SYNC READ of ``ids`` that ``missing`` did not answer."""
        timeout = self.response_timeout(self.sync_read_overhead + len(ids), len(ids), length)
        return self.timeout_error(
            self.url, missing, f"SYNC READ {address}+{length}", timeout, self.retries + 1
        )

    # -- SYNC READ / SYNC WRITE ----------------------------------------------------
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
            packet = self.encode_sync_read(address, length, key[2])
            cache = self._sync_read_packets
            if len(cache) >= SYNC_READ_CACHE:
                del cache[next(iter(cache))]
            cache[key] = packet
        if type(ids) is tuple:
            self._last_sync_read = (ids, address, length, packet)
        return packet

    async def sync_read_statuses(
        self, ids: Sequence[int], address: int, length: int
    ) -> dict[int, StatusT]:
        """SYNC READ returning the statuses that arrived (missing ones retried, not raised)."""
        ids = tuple(ids)
        packet = self.sync_read_packet(ids, address, length)  # validates
        async with self._lock:
            got = await self._exchange(packet, ids, length)
            if len(got) == len(ids) and not self._garbled:
                return got  # the usual case, without the retry machinery

            def make(remaining: Sequence[int]) -> bytes:
                return self.sync_read_packet(tuple(remaining), address, length)

            return await self._retry(got, make, ids, f"SYNC READ {address}+{length}", length)

    async def sync_read_all(
        self, ids: Sequence[int], address: int, length: int
    ) -> tuple[tuple[int, ...], dict[int, StatusT]]:
        """SYNC READ: a status from every id, or the protocol's timeout error."""
        ids = tuple(ids)
        statuses = await self.sync_read_statuses(ids, address, length)
        if len(statuses) != len(ids):  # statuses holds only ids asked for
            missing = [i for i in ids if i not in statuses]
            raise self.sync_read_timeout_error(ids, missing, address, length)
        return ids, statuses

    async def sync_write(self, address: int, length: int, data: Mapping[int, bytes]) -> None:
        """SYNC WRITE ``{id: data}`` (no status packets: it is a broadcast)."""
        if not data:
            raise BadParameterError("data", data, "at least one {id: bytes} item")
        await self.send_only(self.encode_sync_write(address, length, data))

    async def sync_write_item(self, item: RegisterItem, values: Mapping[int, int]) -> None:
        """SYNC WRITE of ``item`` = ``values[id]`` on each servo."""
        await self.sync_write(
            item.address, item.size, {i: item.encode(v) for i, v in values.items()}
        )

    # -- transactions --------------------------------------------------------------
    async def send_only(self, packet: bytes) -> None:
        """Send ``packet`` under the bus lock; no status comes back."""
        async with self._lock:
            self.check_connected()
            self._transaction += 1
            self.stats.transactions += 1
            self._link.write(packet)
            # The next request may follow at once: the port sends bytes in order.
            await anyio.lowlevel.checkpoint()

    async def collect(
        self, packet: bytes, ids: Sequence[int], param_length: int, window: float
    ) -> dict[int, StatusT]:
        """Send ``packet`` (under the bus lock, once, no retry) and keep the statuses of
        ``param_length`` params that ``ids`` send within ``window`` s: a broadcast that
        every servo answers in turn (Dynamixel's broadcast PING)."""
        async with self._lock:
            return await self._exchange(packet, ids, param_length, window)

    async def unicast(self, packet: bytes, servo_id: int, what: str, param_length: int) -> StatusT:
        """One request to one servo (the lock is taken): its status, or the timeout error."""
        async with self._lock:
            return await self.unicast_locked(packet, servo_id, what, param_length)

    async def unicast_locked(
        self, packet: bytes, servo_id: int, what: str, param_length: int
    ) -> StatusT:
        """:meth:`unicast` with the lock already held."""
        statuses = await self.transact(lambda _: packet, (servo_id,), what, param_length)
        status = statuses.get(servo_id)
        if status is None:
            raise self.timeout_error(
                self.url,
                (servo_id,),
                what,
                self.response_timeout(len(packet), 1, param_length),
                self.retries + 1,
            )
        return status

    async def transact(
        self,
        make_packet: Callable[[Sequence[int]], bytes],
        ids: Sequence[int],
        what: str,
        param_length: int,
    ) -> dict[int, StatusT]:
        """Send, collect a status per id, retry the missing ones (the lock is held)."""
        got = await self._exchange(make_packet(ids), ids, param_length)
        if len(got) == len(ids) and not self._garbled:
            return got  # every status arrived, none says the instruction was damaged
        return await self._retry(got, make_packet, ids, what, param_length)

    async def _retry(
        self,
        got: dict[int, StatusT],
        make_packet: Callable[[Sequence[int]], bytes],
        ids: Sequence[int],
        what: str,
        param_length: int,
    ) -> dict[int, StatusT]:
        """The rest of a transaction whose first attempt ``got`` these statuses."""
        prefix = self.log_prefix
        result = got
        remaining = list(ids)
        for attempt in range(self.retries + 1):
            if attempt:
                self.stats.retries += 1
                self._log.debug(f"{prefix}_retry", request=what, ids=remaining, attempt=attempt)
                got = await self._exchange(make_packet(remaining), remaining, param_length)
                result.update(got)
            # The instruction was damaged on the wire and not executed: resend it.
            garbled = [i for i, s in got.items() if self.garbled(s)]
            if garbled:
                self.count_garbled(len(garbled))
                self._log.debug(f"{prefix}_crc_rejected", request=what, ids=garbled)
            remaining = [i for i in remaining if i not in got or i in garbled]
            if not remaining:
                break
        else:
            missing = [i for i in remaining if i not in result]
            if missing:
                self.stats.timeouts += 1
            self._log.warning(
                f"{prefix}_no_status" if missing else f"{prefix}_crc_rejected_every_attempt",
                request=what,
                ids=remaining,
                attempts=self.retries + 1,
            )
        return result

    def count_garbled(self, count: int) -> None:
        """Count statuses saying the instruction arrived damaged."""

    async def _exchange(
        self, packet: bytes, ids: Sequence[int], param_length: int, window: float | None = None
    ) -> dict[int, StatusT]:
        """One attempt: write ``packet`` and wait for a status from each id or the timeout
        (``window`` s, by default the statuses' own time: :meth:`response_timeout`).

        The wait is one future, completed by the reception callback when the last status
        arrived, by the port's timer at the deadline, or by a loss of the port; a
        cancellation of the caller ends it too. No cancel scope, no extra event-loop pass,
        and no timer per exchange (see :meth:`_arm_timer`).
        """
        self.check_connected()
        self._transaction += 1
        self.stats.transactions += 1
        if self.reset_parser_per_request:
            # A frame left incomplete by noise (a false header whose length byte promises
            # more) would swallow the replies; nothing else is in flight on a half-duplex
            # bus when a request starts: drop it.
            self.parser.reset()
        # Written first: what follows overlaps with the servos' processing, and no reply
        # can be handled before this task yields (the reception runs in this thread).
        self._link.write(packet)
        loop = asyncio.get_running_loop()
        waiter: asyncio.Future[None] = loop.create_future()
        replies: dict[int, StatusT] = {}
        self._replies = replies
        self._garbled = 0
        expect = self._expect = set(ids)
        self._param_length = param_length
        self._waiter = waiter
        try:
            timeout = window
            if timeout is None:
                timeout = self.response_timeout(len(packet), len(ids), param_length)
            self._arm_timer(loop, loop.time() + timeout)
            await waiter
        finally:
            self._expect = None
            self._waiter = None
        if len(replies) != len(expect):
            self.check_connected()  # lost while waiting: raise, not a timeout
        return replies

    def _arm_timer(self, loop: asyncio.AbstractEventLoop, deadline: float) -> None:
        """Make the exchange in flight time out at ``deadline`` (loop time).

        One timer serves every exchange: it is re-armed only when it would fire after
        ``deadline`` (then it is replaced) or when it fires before it (then it is set
        again for ``deadline``); so back-to-back exchanges with similar timeouts cost
        no timer each, and the wait still ends at its own deadline.
        """
        self._deadline = deadline
        timer = self._timer
        if timer is not None:
            if timer.when() <= deadline:
                return
            timer.cancel()
        self._timer = loop.call_at(deadline, self._timer_fired, loop)

    def _timer_fired(self, loop: asyncio.AbstractEventLoop) -> None:
        self._timer = None
        waiter = self._waiter
        if waiter is None:
            return  # no exchange in flight: the timer is not needed any more
        if loop.time() >= self._deadline:
            complete(waiter)  # timed out: the exchange returns what arrived
        else:
            self._timer = loop.call_at(self._deadline, self._timer_fired, loop)

    # -- reception (transport callback) ----------------------------------------------
    def _on_data(self, data: bytes) -> None:
        status_type = self.status_type
        expect = self._expect
        replies = self._replies
        length = self._param_length
        plain = not self.has_refusals
        for msg in self.parser.feed(data):
            if not isinstance(msg, status_type):
                continue  # an echo of an instruction (some half-duplex adapters)
            servo_id = msg.id
            if (
                plain
                and expect is not None
                and servo_id in expect
                and servo_id not in replies
                and len(msg.params) == length
            ):
                replies[servo_id] = msg  # the usual case, inline
            else:
                self.take_status(msg)
        self.complete_if_done()

    def take_status(self, status: StatusT) -> None:
        """Keep ``status`` if the exchange in flight waits for it, else count it stray."""
        expect = self._expect
        servo_id = status.id
        replies = self._replies
        if expect is None or servo_id not in expect or servo_id in replies:
            self.stray(servo_id)
            return
        if self.refused(status):
            if self.garbled(status):
                self._garbled += 1
        elif len(status.params) != self._param_length:
            self.stats.stray += 1  # an answer to another request
            return
        replies[servo_id] = status

    def complete_if_done(self) -> None:
        """Wake the exchange in flight if every status it waits for arrived."""
        waiter = self._waiter
        expect = self._expect
        if waiter is not None and expect is not None and len(self._replies) == len(expect):
            complete(waiter)

    def stray(self, servo_id: int) -> None:
        self.stats.stray += 1
        self._log.debug(f"{self.log_prefix}_stray_status", id=servo_id)

    def _on_lost(self, reason: str) -> None:
        self.stats.losses += 1
        if self._waiter is not None:
            complete(self._waiter)  # the waiter sees the loss at once
        for client in list(self._clients.values()):
            client._port_lost(f"{self.url}: {reason}")

    # -- poller --------------------------------------------------------------------
    def poll_ids(self) -> list[int]:
        return sorted(i for i, c in self._clients.items() if c.polled)

    async def poll_once(self) -> None:
        """One poll cycle: SYNC READ the poll window of every polled servo, then dispatch."""
        ids = self.poll_ids()
        if not ids:
            return
        started = self.poll_started(ids)
        address, length = self.poll_address, self.poll_length
        statuses = await self.sync_read_statuses(ids, address, length)
        self.poll_done()
        transaction = self._transaction
        now = self.clock.now_ns()
        self.stats.poll_cycles += 1
        later: list[Any] = []
        for servo_id in ids:
            client = self._clients.get(servo_id)
            if client is None:
                continue
            status = statuses.get(servo_id)
            if status is None:
                self.stats.poll_misses += 1
                client._poll_missed(self.sync_read_timeout_error(ids, (servo_id,), address, length))
                continue
            self.deliver(client, status, transaction, now, later)
        await self.after_poll(ids, later, started)

    async def _poll_loop(self) -> None:
        clock = self.clock
        next_ns = clock.now_ns()
        period_ns = round(self.poll_period * 1e9)
        while True:
            self.poll_loop_tick()
            if not self._link.is_open or not self.poll_ids():
                self._poll_wake = anyio.Event()
                if not self._link.is_open or not self.poll_ids():
                    idle = self.idle_timeout()
                    if idle is None:
                        await self._poll_wake.wait()
                    else:
                        with anyio.move_on_after(idle):
                            await self._poll_wake.wait()
                self._poll_wake = None
                next_ns = clock.now_ns()
                continue
            try:
                await self.poll_once()
            except (HALError, OSError) as exc:  # one failed cycle never stops the loop
                if self._link.is_open:
                    self._log.warning(f"{self.log_prefix}_poll_failed", error=str(exc))
            next_ns += period_ns
            now = clock.now_ns()
            if next_ns < now:
                next_ns = now  # overran: restart the schedule rather than burst
            await clock.sleep_until(next_ns)

    def __repr__(self) -> str:
        state = "open" if self.connected else "closed"
        return f"{self.name}({self.url!r}, {self.baudrate} bd, {state})"
