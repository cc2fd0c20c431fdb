"""CanBus: one python-can bus shared by every node driver on it.

A :class:`CanBus` owns one ``can.BusABC`` (any python-can interface: socketcan, pcan,
kvaser, virtual ...) and runs, in its own task group:

* **one reader** per bus, handing frames to the event loop, where they are dispatched
  by arbitration id to every :class:`NodePort` registered for that id (one bounded
  memory object stream per port: a full port drops the batch and counts it, the reader
  never waits for a slow node; or a port ``handler`` called in the loop). Three forms:

  - python-can ``virtual`` (the simulations and tests): no thread. The bus's receive
    queue is hooked (:mod:`openel_can.virtual_rx`) so that a frame put on it, from any
    thread, schedules one drain in the loop (a write to an eventfd the loop watches, on
    Linux; ``call_soon_threadsafe`` elsewhere), which takes
    every queued frame under one lock and dispatches them as one batch; an idle check
    every ``poll_interval`` notices a bus shut down under it.
  - ``socketcan`` (and any bus with a ``fileno()`` given ``read_mode="loop"``): no thread
    either. The socket is watched by the event loop (``loop.add_reader``); when it is
    readable the loop takes every queued frame with non-blocking ``recv(0)`` (up to
    ``max_batch``) and dispatches them as one batch; the same idle check. While a SYNC
    producer runs on the bus (:class:`~openel_can.CanSync`) it reads the socket once per
    cycle instead (:meth:`CanBus.read_now`), at the tick, one wake-up a cycle.
  - any other interface (or ``read_mode="thread"``): **one reader thread** per bus object (started on entry and
    after each reopen, joined on exit), looping on a blocking ``recv`` of at most
    ``poll_interval`` for the first frame, then non-blocking ``recv(0)`` for whatever
    else is queued (up to ``max_batch``), and handing each batch to the loop with
    ``loop.call_soon_threadsafe``; one wake-up serves every batch queued before the loop
    runs it (they are dispatched as one).

  Either way at most ``rx_buffer`` frames wait for the loop; beyond that frames are
  dropped and counted (``stats.rx_overflow``, logged). python-can's ``Notifier`` is not
  used: its thread dies silently when ``recv`` raises, whereas here a failing ``recv``
  ends the reader, is reported to every port (``on_bus_error``: the drivers fault
  their components with ``ErrorId.BUS_ERROR``) and recovered from with exponential
  backoff: the bus is reopened when the ``CanBus`` knows how to open it (interface
  kwargs or a ``bus_factory``), else ``recv`` is retried on the same object; the first
  ``recv`` that does not raise brings the bus back up, a new reader starts, and
  ``re_init`` of the components succeeds. Frames read before the failure are
  dispatched first, in order.
* **sends that never block the event loop**. On interfaces whose ``send(msg,
  timeout=0)`` cannot block (``virtual``; ``socketcan``, which polls the socket and
  raises "Transmit buffer full" otherwise) ``NodePort.send`` sends inline when nothing
  is queued, saving a task hop. Otherwise, and when the interface does not take the
  frame at once, the frame goes to a bounded queue (``NodePort.send`` waits at most
  ``send_timeout`` for room, then raises ``TimeoutError``) drained in batches by **one
  sender** task: inline with ``timeout=0`` and a backoff retry of a full transmit
  buffer, or, on every other interface (whose ``send`` may block), in a worker thread
  with ``send(msg, timeout=send_timeout)``. Frames leave in call order. A send that
  keeps failing for ``send_timeout`` takes the bus down like a failed ``recv`` (frames
  queued meanwhile are dropped and counted: a CAN command is worthless late). After 64
  inline sends in a row ``send`` yields to the loop once, so a sending loop cannot
  starve the readers. Frames are sent as :class:`TxMessage` (a ``can.Message`` whose
  deep copy, made by the ``virtual`` interface for every receiver, is cheap).
* optionally a SYNC producer (CANopen, COB-ID 0x080) every ``sync_period`` seconds.
* on demand the host's CANopen heartbeat (:meth:`CanBus.produce_heartbeat`: COB-ID
  0x700 + host node id, state Operational), fed to the drives' heartbeat consumers
  (0x1016) by a task of the bus in the event loop: a stalled loop stops it. A beat is
  sent inline when nothing is queued (like ``NodePort.send``), else queued.

Use it as an async context manager and create the node drivers with it::

    async with CanBus(interface="socketcan", channel="can0") as bus:
        async with Actuator(ODriveAxis(bus, node_id=3)) as axis:
            ...
"""

from __future__ import annotations

import asyncio
import contextlib
import copy
import math
import os
import threading
import time
from collections import deque
from collections.abc import Callable, Coroutine, Iterable
from contextlib import AsyncExitStack
from dataclasses import dataclass
from enum import Enum
from types import TracebackType
from typing import Any, Final, Literal, Self, TypeVar

import anyio
import anyio.abc
import anyio.lowlevel
import can
from anyio.streams.memory import MemoryObjectReceiveStream, MemoryObjectSendStream

from openel_async.clock import run_in_thread
from openel_async.errors import BadParameterError, NotConnectedError
from openel_async.logs import get_logger

from .virtual_rx import WakingQueue, hook_virtual_bus, virtual_sender

__all__ = ["BusState", "BusStats", "CanBus", "NodePort", "ReadMode", "SendMode", "TxMessage"]

log = get_logger(__name__)

_T = TypeVar("_T")
SendMode = Literal["auto", "inline", "thread"]
ReadMode = Literal["auto", "loop", "thread"]
#: Interfaces read in the event loop through their ``fileno()`` by ``read_mode="auto"``.
FD_READ_BUSES: Final = frozenset({"SocketcanBus"})
#: Interfaces whose ``send(msg, timeout=0)`` returns at once (see the module docstring).
NONBLOCKING_SEND_BUSES: Final = frozenset({"VirtualBus", "SocketcanBus"})
EXTENDED_FLAG: Final = 1 << 31
"""Routing key flag of a 29-bit identifier (11-bit ids route by their plain value)."""
_INLINE_RETRY_S: Final = 0.0005
_INLINE_RETRY_MAX_S: Final = 0.01
_DROP_LOG_EVERY: Final = 1000
_INLINE_YIELD_EVERY: Final = 64
"""Inline sends in a row before ``send`` yields to the event loop once (fairness)."""


class TxMessage(can.Message):
    """The ``can.Message`` a :class:`NodePort` sends: built and deep-copied field by field.

    python-can's ``virtual`` interface deep-copies every frame for every receiving bus;
    ``can.Message.__deepcopy__`` calls the keyword constructor and ``copy.deepcopy`` of
    the data bytearray (several µs a frame). This one copies the slots directly and gives
    the receivers plain ``can.Message`` objects, equal field by field, with their own
    data. Interfaces that do not copy (socketcan, ...) never call it.
    """

    __slots__ = ()

    @classmethod
    def frame(cls, arbitration_id: int, data: bytes, extended: bool, remote: bool) -> TxMessage:
        """``TxMessage(arbitration_id=..., data=..., is_extended_id=..., is_remote_frame=...,
        check=False)`` without the keyword constructor (the send path's hot spot)."""
        msg = _new_message(cls)
        msg.timestamp = 0.0
        msg.arbitration_id = arbitration_id
        msg.is_extended_id = extended
        msg.is_remote_frame = remote
        msg.is_error_frame = False
        msg.channel = None
        msg.data = bytearray() if remote else bytearray(data)
        msg.dlc = len(msg.data)
        msg.is_fd = False
        msg.is_rx = True
        msg.bitrate_switch = False
        msg.error_state_indicator = False
        return msg

    def __deepcopy__(self, memo: dict[int, Any] | None) -> can.Message:
        dup = _new_message(can.Message)
        channel = self.channel
        if not (channel is None or isinstance(channel, str | int)):
            channel = copy.deepcopy(channel, memo)
        dup.channel = channel
        dup.timestamp = self.timestamp
        dup.arbitration_id = self.arbitration_id
        dup.is_extended_id = self.is_extended_id
        dup.is_remote_frame = self.is_remote_frame
        dup.is_error_frame = self.is_error_frame
        dup.dlc = self.dlc
        dup.data = bytearray(self.data)
        dup.is_fd = self.is_fd
        dup.is_rx = self.is_rx
        dup.bitrate_switch = self.bitrate_switch
        dup.error_state_indicator = self.error_state_indicator
        return dup


_new_message = can.Message.__new__


class BusState(Enum):
    CLOSED = "closed"
    UP = "up"
    DOWN = "down"

    def __str__(self) -> str:
        return self.value


@dataclass
class BusStats:
    """Counters of one CanBus (monotonic; read them any time)."""

    rx_frames: int = 0
    """Frames received (including unrouted and error frames)."""
    rx_batches: int = 0
    tx_frames: int = 0
    tx_dropped: int = 0
    """Frames dropped because the bus was down or the send kept failing."""
    tx_retries: int = 0
    unrouted: int = 0
    """Frames no port registered for."""
    error_frames: int = 0
    overflow_frames: int = 0
    """Frames dropped because a port's queue was full (summed over ports)."""
    rx_overflow: int = 0
    """Frames the reader dropped because ``rx_buffer`` frames were already waiting for
    the event loop (the loop fell that far behind the bus)."""
    bus_errors: int = 0
    """Transitions to DOWN."""
    recoveries: int = 0
    """Transitions back to UP."""


class NodePort:
    """A node's attachment to a :class:`CanBus`: its received frames and its send path.

    Iterate it (``async for batch in port``) to receive batches of ``can.Message`` for
    the arbitration ids it registered; the iteration ends when the port is detached or
    the bus closes. Counters: ``received`` and ``dropped`` (queue overflow) are kept by
    the bus, ``malformed`` by the driver (frames it could not decode and dropped).

    A port attached with a ``handler`` has no queue: the bus calls ``handler(frames)``
    in the event loop as each batch is dispatched (it must not block; an exception it
    raises is logged and its frames counted in ``dropped``). Such a port cannot be
    iterated. It saves a queue and a task wake-up per batch on request/answer paths.
    """

    def __init__(
        self,
        bus: CanBus,
        ids: frozenset[int],
        name: str,
        queue_size: int,
        on_bus_error: Callable[[str], None] | None,
        handler: Callable[[list[can.Message]], None] | None = None,
    ) -> None:
        self.bus = bus
        self.ids = ids
        self.name = name
        self.on_bus_error = on_bus_error
        self.received = 0
        self.dropped = 0
        self.malformed = 0
        self.handler = handler
        send, receive = anyio.create_memory_object_stream[list[can.Message]](queue_size)
        self._send: MemoryObjectSendStream[list[can.Message]] = send
        self._receive: MemoryObjectReceiveStream[list[can.Message]] = receive
        self.attached = True

    # -- receive ------------------------------------------------------------------------
    def __aiter__(self) -> NodePort:
        return self

    def _check_queued(self) -> None:
        if self.handler is not None:
            raise RuntimeError(f"port {self.name!r} delivers to its handler: it has no queue")

    async def __anext__(self) -> list[can.Message]:
        self._check_queued()
        try:
            return await self._receive.receive()
        except (anyio.EndOfStream, anyio.ClosedResourceError):
            self._receive.close()
            raise StopAsyncIteration from None

    async def receive(self) -> list[can.Message]:
        """The next batch; raises ``anyio.EndOfStream`` once detached."""
        self._check_queued()
        try:
            return await self._receive.receive()
        except anyio.ClosedResourceError:
            raise anyio.EndOfStream from None

    def receive_nowait(self) -> list[can.Message]:
        """The next batch if one is queued; raises ``anyio.WouldBlock`` otherwise."""
        self._check_queued()
        try:
            return self._receive.receive_nowait()
        except anyio.ClosedResourceError:
            raise anyio.EndOfStream from None

    def _deliver(self, frames: list[can.Message]) -> None:
        self.received += len(frames)
        handler = self.handler
        if handler is not None:
            try:
                handler(frames)
            except Exception as exc:  # a driver's bug must not kill the dispatcher
                self.dropped += len(frames)
                self.bus.log.exception("port_handler_failed", port=self.name, error=repr(exc))
            return
        try:
            self._send.send_nowait(frames)
        except anyio.WouldBlock:
            self.dropped += len(frames)
            self.bus.stats.overflow_frames += len(frames)
            if self.dropped // _DROP_LOG_EVERY != (self.dropped - len(frames)) // _DROP_LOG_EVERY:
                self.bus.log.warning("port_overflow", port=self.name, dropped=self.dropped)
        except (anyio.BrokenResourceError, anyio.ClosedResourceError):
            pass  # detached meanwhile

    # -- send ---------------------------------------------------------------------------
    async def send(
        self,
        arbitration_id: int,
        data: bytes = b"",
        *,
        remote: bool = False,
        extended: bool = False,
    ) -> None:
        """Send one frame (inline when possible, else through the send queue).

        Returns once the frame is sent or queued (CAN has no delivery acknowledgement);
        waits at most ``send_timeout`` for room in the queue. Raises
        :class:`NotConnectedError` while the bus is down and :class:`TimeoutError` when
        the queue stays full.
        """
        msg = TxMessage.frame(arbitration_id, data, extended, remote)
        bus = self.bus  # send_message, without a second coroutine on the inline path
        if bus._try_inline(msg):
            if bus._inline_streak >= _INLINE_YIELD_EVERY:
                bus._inline_streak = 0
                await anyio.lowlevel.checkpoint()
            return
        await bus._enqueue(msg)

    def try_send_frame(self, msg: TxMessage) -> bool:
        """Send ``msg`` (a frame built once with :meth:`TxMessage.frame` and kept, never
        changed afterwards) inline if the interface allows and nothing is queued: True
        when sent; False when it was not sent (then ``await send_frame(msg)``). For request/
        answer paths that send the same request again and again (an SDO upload's
        initiate). Raises :class:`NotConnectedError` while the bus is down."""
        return self.bus._try_inline(msg)

    async def send_frame(self, msg: TxMessage) -> None:
        """:meth:`send` of a frame built once (see :meth:`try_send_frame`)."""
        bus = self.bus
        if bus._try_inline(msg):
            if bus._inline_streak >= _INLINE_YIELD_EVERY:
                bus._inline_streak = 0
                await anyio.lowlevel.checkpoint()
            return
        await bus._enqueue(msg)

    def send_nowait(
        self, arbitration_id: int, data: bytes = b"", *, extended: bool = False
    ) -> bool:
        """Send one frame without suspending, for synchronous code (a timer observer): inline
        when possible, else queued for the sender task behind the frames already queued
        (frames leave in call order). Returns False when the queue is full: the frame is
        dropped and counted (``stats.tx_dropped``). Raises :class:`NotConnectedError`
        while the bus is down."""
        msg = TxMessage.frame(arbitration_id, data, extended, False)
        bus = self.bus
        if bus._try_inline(msg):
            return True
        return bus._queue_nowait(msg)

    def send_frame_nowait(self, msg: TxMessage) -> bool:
        """:meth:`send_nowait` of a frame built once (see :meth:`try_send_frame`): a
        producer's frame that never changes (a SYNC)."""
        bus = self.bus
        if bus._try_inline(msg):
            return True
        return bus._queue_nowait(msg)

    def send_all_nowait(self, frames: Iterable[tuple[int, bytes]]) -> int:
        """:meth:`send_nowait` of each ``(arbitration_id, data)`` (11-bit data frames), in
        order, the bus's state looked at once: a burst from synchronous code (the RPDOs of
        a :class:`~openel_can.CanSync` tick). Returns how many were sent or queued; the
        others were dropped and counted (the queue full). Raises
        :class:`NotConnectedError` while the bus is down (nothing sent)."""
        return self.bus._send_all_nowait(frames)

    def close(self) -> None:
        """Detach from the bus (same as ``bus.detach(port)``)."""
        self.bus.detach(self)

    def __repr__(self) -> str:
        return f"NodePort({self.name!r}, ids={len(self.ids)}, attached={self.attached})"


class CanBus:
    """One python-can bus, its reader, its sender and its recovery (module docstring).

    Give exactly one of: ``bus`` (an open ``can.BusABC``; it is not shut down at exit and
    cannot be reopened, so recovery retries ``recv`` on it), ``bus_factory`` (a callable
    opening a new bus, used at entry and for every reopen), or python-can keyword
    arguments (``interface="socketcan", channel="can0", bitrate=...``).
    """

    def __init__(
        self,
        bus: can.BusABC | None = None,
        *,
        bus_factory: Callable[[], can.BusABC] | None = None,
        name: str | None = None,
        port_queue_size: int = 64,
        tx_queue_size: int = 256,
        send_mode: SendMode = "auto",
        read_mode: ReadMode = "auto",
        send_timeout: float = 0.2,
        poll_interval: float = 0.05,
        max_batch: int = 512,
        rx_buffer: int = 8192,
        reconnect_backoff: tuple[float, float] = (0.02, 1.0),
        sync_period: float | None = None,
        **bus_kwargs: Any,
    ) -> None:
        given = sum(x is not None for x in (bus, bus_factory)) + bool(bus_kwargs)
        if given != 1:
            raise BadParameterError(
                "bus", bus, "exactly one of bus=, bus_factory= or python-can keyword arguments"
            )
        if bus is not None and not isinstance(bus, can.BusABC):
            raise BadParameterError("bus", bus, "a can.BusABC")
        for pname, value in (("port_queue_size", port_queue_size), ("tx_queue_size", tx_queue_size), ("max_batch", max_batch), ("rx_buffer", rx_buffer)):  # fmt: skip
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise BadParameterError(pname, value, "an int >= 1")
        for pname, fvalue in (("send_timeout", send_timeout), ("poll_interval", poll_interval)):
            if not (math.isfinite(fvalue) and fvalue > 0):
                raise BadParameterError(pname, fvalue, "a finite number of seconds > 0")
        low, high = reconnect_backoff
        if not (math.isfinite(low) and math.isfinite(high) and 0 < low <= high):
            raise BadParameterError(
                "reconnect_backoff", reconnect_backoff, "(min, max) seconds with 0 < min <= max"
            )
        if sync_period is not None and not (math.isfinite(sync_period) and sync_period > 0):
            raise BadParameterError("sync_period", sync_period, "None or seconds > 0")
        if send_mode not in ("auto", "inline", "thread"):
            raise BadParameterError("send_mode", send_mode, "'auto', 'inline' or 'thread'")
        if read_mode not in ("auto", "loop", "thread"):
            raise BadParameterError("read_mode", read_mode, "'auto', 'loop' or 'thread'")
        if bus_kwargs:
            kwargs = dict(bus_kwargs)

            def open_from_kwargs() -> can.BusABC:
                return can.Bus(**kwargs)

            bus_factory = open_from_kwargs
        self._given_bus = bus
        self._factory = bus_factory
        self.name = name or str(
            bus_kwargs.get("channel", "") or (bus.channel_info if bus else "can")
        )
        self.port_queue_size = port_queue_size
        self.tx_queue_size = tx_queue_size
        self.send_mode: SendMode = send_mode
        self.read_mode: ReadMode = read_mode
        self.send_timeout = send_timeout
        self.poll_interval = poll_interval
        self.max_batch = max_batch
        self.rx_buffer = rx_buffer
        self.reconnect_backoff = (low, high)
        self.sync_period = sync_period
        self._tg: anyio.abc.TaskGroup | None = None
        self._hb_node: int | None = None
        self._hb_owners: dict[int, float] = {}
        """id(owner) -> heartbeat period wanted (see :meth:`produce_heartbeat`)."""
        self._hb_running = False
        self.stats = BusStats()
        self.log = log.bind(bus=self.name)
        self.state = BusState.CLOSED
        self.last_error: str | None = None
        """Why the bus last went down."""
        self.last_retry_error: str | None = None
        self._bus: can.BusABC | None = None
        self._inline = False
        self._send_fn: Callable[[can.Message, float | None], None] | None = None
        """``send`` of the python-can bus (:func:`virtual_sender`'s on a virtual bus)."""
        self._routes: dict[int, tuple[NodePort, ...]] = {}
        self._ports: list[NodePort] = []
        self._stack: AsyncExitStack | None = None
        self._tx_send: MemoryObjectSendStream[can.Message] | None = None
        self._tx_receive: MemoryObjectReceiveStream[can.Message] | None = None
        self._up = anyio.Event()
        self._down = anyio.Event()
        self._io_lock = anyio.Lock()
        self._tx_pending = 0
        """Frames queued for the sender task or being sent by it."""
        self._tx_drained: anyio.Event | None = None
        """Set by the sender when nothing is pending any more (while the bus closes)."""
        self._shared: dict[object, Any] = {}
        self._entered = False
        self._loop: asyncio.AbstractEventLoop | None = None
        # Reader thread -> event loop hand-off (see _post_batch / _drain_rx).
        self._rx_queue: deque[list[can.Message]] = deque()
        self._rx_wake_pending = False
        self._rx_posted = 0
        """Frames handed to the loop (written by the reader thread only)."""
        self._rx_taken = 0
        """Frames the loop took from the hand-off (written by the loop only)."""
        self._rx_overflow = 0
        """Frames dropped by the reader thread (written by the reader thread only)."""
        self.reader_threads = 0
        """Reader threads started (one per bus object: a reopen starts a new one)."""
        self.reads_in_loop = 0
        """Bus objects read in the event loop without a thread (python-can ``virtual``, or
        through their ``fileno()``: ``socketcan``, ``read_mode="loop"``)."""
        self._virtual_rx: WakingQueue | None = None
        self._virtual_wake_pending = False
        self._virtual_wake_fd: int | None = None
        """Linux: the eventfd that wakes the loop for a virtual-bus drain (its reader)."""
        self._virtual_fd_lock = threading.Lock()
        """Held to write ``_virtual_wake_fd`` and to close it: never a closed (reused) fd."""
        self._virtual_failed: anyio.Event | None = None
        self._virtual_failure = ""
        self._inline_streak = 0
        self._read_now: Callable[[float], None] | None = None
        """The descriptor reader's :meth:`read_now` while the bus is read in the loop
        through its ``fileno()`` (None otherwise)."""
        self.reads_on_demand = 0
        """Reads made by :meth:`read_now` (a cyclic producer's ticks)."""

    # -- lifecycle ------------------------------------------------------------------------
    async def __aenter__(self) -> Self:
        if self._entered:
            raise RuntimeError("a CanBus can be entered only once")
        self._entered = True
        try:
            self._loop = asyncio.get_running_loop()
        except RuntimeError:
            raise RuntimeError("CanBus needs anyio on the asyncio backend") from None
        self._bus = await self._open()
        self._inline = self._choose_inline(self._bus)
        self._send_fn = virtual_sender(self._bus, TxMessage) or self._bus.send
        stack = AsyncExitStack()
        try:
            send, receive = anyio.create_memory_object_stream[can.Message](self.tx_queue_size)
            self._tx_send, self._tx_receive = send, receive
            stack.push_async_callback(self._shutdown_bus)
            tg = await stack.enter_async_context(anyio.create_task_group())
            stack.callback(tg.cancel_scope.cancel)
            self._set_up()
            await tg.start(self._reader)  # reading once entered
            tg.start_soon(self._sender)
            if self.sync_period is not None:
                tg.start_soon(self._sync_producer, self.sync_period)
            self._tg = tg
            stack.callback(setattr, self, "_tg", None)
        except BaseException:
            await stack.aclose()
            raise
        self._stack = stack
        self.log.info(
            "bus_open",
            interface=type(self._bus).__name__,
            send="inline" if self._inline else "thread",
        )
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self._drain_tx()
        self.state = BusState.CLOSED
        for port in list(self._ports):
            self.detach(port)
        if self._tx_send is not None:
            self._tx_send.close()
        assert self._stack is not None
        await self._stack.aclose()
        if self._tx_receive is not None:
            self._tx_receive.close()
        self._up.set()  # release waiters: they see CLOSED
        self._down.set()
        self.log.info("bus_closed", **self._stats_dict())

    async def _drain_tx(self) -> None:
        """Let the frames queued before the close go out (at most ``send_timeout``): a
        drive's last command (IDLE, quick stop, disable) must reach it. What is still queued
        then counts as dropped and is logged."""
        if self.state is not BusState.UP or not self._tx_pending:
            return
        self._tx_drained = anyio.Event()
        # Shielded (a cancelled run still sends its last commands), bounded by the deadline
        # inside the shield.
        with anyio.CancelScope(shield=True), anyio.move_on_after(self.send_timeout):
            await self._tx_drained.wait()
        if self._tx_pending:
            self.stats.tx_dropped += self._tx_pending
            self.log.warning("tx_not_drained_at_close", dropped=self._tx_pending)

    def _stats_dict(self) -> dict[str, int]:
        s = self.stats
        return {
            "rx": s.rx_frames,
            "tx": s.tx_frames,
            "tx_dropped": s.tx_dropped,
            "bus_errors": s.bus_errors,
        }

    async def _open(self) -> can.BusABC:
        if self._given_bus is not None:
            return self._given_bus
        assert self._factory is not None
        return await run_in_thread(self._factory)

    async def _shutdown_bus(self) -> None:
        bus, self._bus = self._bus, None
        if bus is None or bus is self._given_bus:
            return
        with anyio.CancelScope(shield=True):
            try:
                await run_in_thread(bus.shutdown)
            except Exception as exc:
                self.log.warning("bus_shutdown_failed", error=repr(exc))

    def _choose_inline(self, bus: can.BusABC) -> bool:
        if self.send_mode == "auto":
            return type(bus).__name__ in NONBLOCKING_SEND_BUSES
        return self.send_mode == "inline"

    @property
    def bus(self) -> can.BusABC | None:
        """The python-can bus in use (None while closed or being reopened)."""
        return self._bus

    @property
    def is_up(self) -> bool:
        return self.state is BusState.UP

    @property
    def reopenable(self) -> bool:
        return self._factory is not None

    async def wait_up(self, timeout: float) -> None:  # noqa: ASYNC109 - a bound, by contract
        """Wait until the bus is up; NotConnectedError after ``timeout`` seconds or if closed."""
        with anyio.move_on_after(timeout):
            while self.state is BusState.DOWN:
                await self._up.wait()
        if self.state is not BusState.UP:
            raise NotConnectedError(
                f"CAN bus {self.name} is {self.state}"
                + (f": {self.last_error}" if self.last_error else "")
            )

    def read_now(self, hold_s: float) -> bool:
        """Take every frame the bus holds now (dispatched before this returns), and leave
        the next ones in the socket for the next call, for at most ``hold_s`` seconds.

        For a cyclic producer that reads once per cycle (:class:`~openel_can.CanSync`: the
        TPDOs answering a SYNC are read at the next tick, just before the next SYNC),
        instead of one event-loop wake-up per frame. Only on a bus read in the event loop
        through its ``fileno()`` (``socketcan``, ``read_mode="loop"``): the descriptor's
        reader is unregistered until the hold runs out with no call since, then
        registered again (a stopped or stalled producer leaves the bus read as before,
        within ``hold_s``). False, nothing read, on any other bus (read by a thread or as
        python-can ``virtual``: each batch is read when it arrives).
        """
        read = self._read_now
        if read is None:
            return False
        read(hold_s)
        return True

    def start_soon(self, func: Callable[[], Coroutine[Any, Any, object]], name: str) -> None:
        """Run ``func()`` as a task of the bus: in the event loop, cancelled when the bus
        closes (a keep-alive shared by the bus's devices, as the heartbeat producer).
        Raises NotConnectedError unless the bus is entered."""
        if self._tg is None:
            raise NotConnectedError(f"CAN bus {self.name}: not entered")
        self._tg.start_soon(func, name=name)

    # -- ports ----------------------------------------------------------------------------
    def shared(self, key: object, factory: Callable[[], _T]) -> _T:
        """A per-bus singleton (e.g. the SDO client of a node, shared by its devices)."""
        try:
            value: _T = self._shared[key]
        except KeyError:
            value = self._shared[key] = factory()
        return value

    def attach(
        self,
        ids: Iterable[int],
        *,
        name: str = "node",
        queue_size: int | None = None,
        on_bus_error: Callable[[str], None] | None = None,
        extended: bool = False,
        handler: Callable[[list[can.Message]], None] | None = None,
    ) -> NodePort:
        """Register a port receiving the frames of ``ids`` (11-bit unless ``extended``).

        Several ports may register the same id; each gets every such frame.
        ``on_bus_error(reason)`` is called (in the event loop) whenever the bus goes down.
        With ``handler``, batches are handed to ``handler(frames)`` in the event loop
        instead of being queued (see :class:`NodePort`).
        """
        if self.state is BusState.CLOSED:
            raise NotConnectedError(f"CAN bus {self.name} is not open (use 'async with')")
        limit = 0x1FFF_FFFF if extended else 0x7FF
        keys: set[int] = set()
        for arb_id in ids:
            if isinstance(arb_id, bool) or not isinstance(arb_id, int) or not 0 <= arb_id <= limit:
                raise BadParameterError("ids", arb_id, f"arbitration ids in 0..{limit:#x}")
            keys.add(arb_id | EXTENDED_FLAG if extended else arb_id)
        port = NodePort(
            self,
            frozenset(keys),
            name,
            queue_size or self.port_queue_size,
            on_bus_error,
            handler,
        )
        self._ports.append(port)
        routes = dict(self._routes)
        for key in keys:
            routes[key] = (*routes.get(key, ()), port)
        self._routes = routes  # swapped whole: the dispatcher never sees a half-built map
        return port

    def detach(self, port: NodePort) -> None:
        if not port.attached:
            return
        port.attached = False
        if port in self._ports:
            self._ports.remove(port)
        routes = dict(self._routes)
        for key in port.ids:
            remaining = tuple(p for p in routes.get(key, ()) if p is not port)
            if remaining:
                routes[key] = remaining
            else:
                routes.pop(key, None)
        self._routes = routes
        port._send.close()  # a receiver waiting now ends its iteration
        port._receive.close()

    # -- send -----------------------------------------------------------------------------
    async def send_message(self, msg: can.Message) -> None:
        """Send or queue a frame (see :meth:`NodePort.send`).

        Inline-send interfaces with nothing queued send at once (``timeout=0``), saving
        the hop to the sender task; anything else, and a frame the interface does not
        take at once, goes through the queue, so frames always leave in call order.
        """
        if self._try_inline(msg):
            if self._inline_streak >= _INLINE_YIELD_EVERY:
                self._inline_streak = 0
                await anyio.lowlevel.checkpoint()
            return
        await self._enqueue(msg)

    def _try_inline(self, msg: can.Message) -> bool:
        """Send ``msg`` at once if the interface allows and nothing is queued (True: sent).

        Raises NotConnectedError unless the bus is up. Counts consecutive inline sends:
        the caller yields once every ``_INLINE_YIELD_EVERY`` (a loop of sends that never
        suspend would starve the readers).
        """
        if self.state is not BusState.UP or self._tx_send is None:
            raise self._not_up()
        if self._inline and not self._tx_pending:
            send = self._send_fn
            assert send is not None
            try:
                send(msg, 0.0)
            except Exception:  # buffer full or failing: the sender retries with backoff
                return False
            self.stats.tx_frames += 1
            self._inline_streak += 1
            return True
        return False

    def _not_up(self) -> NotConnectedError:
        return NotConnectedError(
            f"CAN bus {self.name} is {self.state}"
            + (f": {self.last_error}" if self.last_error else "")
        )

    def _send_all_nowait(self, frames: Iterable[tuple[int, bytes]]) -> int:
        """:meth:`NodePort.send_all_nowait`: :meth:`_try_inline`, else :meth:`_queue_nowait`,
        of each frame, without a call per frame for either."""
        if self.state is not BusState.UP or self._tx_send is None:
            raise self._not_up()
        send = self._send_fn if self._inline else None
        new = TxMessage.frame
        stats = self.stats
        taken = 0
        for arbitration_id, data in frames:
            msg = new(arbitration_id, data, False, False)
            if send is not None and not self._tx_pending:
                try:
                    send(msg, 0.0)
                except Exception:  # buffer full or failing: queued, the sender retries
                    pass
                else:
                    stats.tx_frames += 1
                    self._inline_streak += 1
                    taken += 1
                    continue
            taken += self._queue_nowait(msg)
        return taken

    def _queue_nowait(self, msg: can.Message) -> bool:
        """Queue a producer's frame (heartbeat, SYNC) for the sender task, counted as pending
        like any other (the sender counts it down); dropped and counted when the queue is
        full (False)."""
        assert self._tx_send is not None
        try:
            self._tx_send.send_nowait(msg)
        except anyio.WouldBlock:
            self.stats.tx_dropped += 1
            return False
        self._tx_pending += 1
        return True

    async def _enqueue(self, msg: can.Message) -> None:
        """Queue ``msg`` for the sender task (waits at most ``send_timeout`` for room)."""
        tx = self._tx_send
        assert tx is not None
        self._tx_pending += 1
        try:
            tx.send_nowait(msg)
        except anyio.WouldBlock:
            try:
                with anyio.fail_after(self.send_timeout):
                    await tx.send(msg)
            except BaseException:
                self._tx_pending -= 1
                raise

    async def _sender(self) -> None:
        assert self._tx_receive is not None
        receive = self._tx_receive
        max_batch = self.max_batch
        async with receive:
            async for first in receive:
                batch = [first]
                while len(batch) < max_batch:
                    try:
                        batch.append(receive.receive_nowait())
                    except (anyio.WouldBlock, anyio.EndOfStream):
                        break
                try:
                    if self.state is not BusState.UP:
                        self.stats.tx_dropped += len(batch)
                    elif self._inline:
                        await self._send_inline(batch)
                    else:
                        await self._send_threaded(batch)
                finally:
                    self._tx_pending -= len(batch)
                    if not self._tx_pending and self._tx_drained is not None:
                        self._tx_drained.set()

    async def _send_inline(self, batch: list[can.Message]) -> None:
        bus = self._bus
        send = self._send_fn
        assert bus is not None and send is not None
        stats = self.stats
        for i, msg in enumerate(batch):
            try:
                send(msg, 0.0)
                stats.tx_frames += 1
                continue
            except Exception as exc:  # buffer full or a failing bus: retry with backoff
                failure: Exception = exc
            deadline = time.monotonic() + self.send_timeout
            delay = _INLINE_RETRY_S
            while True:
                stats.tx_retries += 1
                await anyio.sleep(delay)
                if self.state is not BusState.UP or self._bus is not bus:
                    stats.tx_dropped += len(batch) - i
                    return
                try:
                    send(msg, 0.0)
                    stats.tx_frames += 1
                    break
                except Exception as exc:
                    failure = exc
                if time.monotonic() >= deadline:
                    stats.tx_dropped += len(batch) - i
                    self._set_down(f"send failed for {self.send_timeout} s: {failure!r}")
                    return
                delay = min(delay * 2, _INLINE_RETRY_MAX_S)

    async def _send_threaded(self, batch: list[can.Message]) -> None:
        bus = self._bus
        assert bus is not None
        timeout = self.send_timeout

        sent = [0]  # frames the thread has sent: the ones before a failure went out

        def send_all() -> None:
            for msg in batch:
                bus.send(msg, timeout)
                sent[0] += 1

        async with self._io_lock:
            try:
                await run_in_thread(send_all)
            except Exception as exc:
                self.stats.tx_dropped += len(batch) - sent[0]
                self._set_down(f"send failed: {exc!r}")
            finally:
                self.stats.tx_frames += sent[0]

    def produce_heartbeat(self, node_id: int, period: float, owner: object) -> None:
        """Send the host's heartbeat (COB-ID 0x700 + ``node_id``, NMT state Operational)
        every ``period`` seconds while ``owner`` (e.g. a drive whose heartbeat consumer
        watches the host) needs it; with several owners the shortest period wins. One host
        node id per bus. The producer is a task of the bus in the event loop, so the
        heartbeat stops when the loop stalls (the drives' consumers then trip)."""
        if isinstance(node_id, bool) or not isinstance(node_id, int) or not 1 <= node_id <= 127:
            raise BadParameterError("node_id", node_id, "a CANopen node id in 1..127")
        if not (math.isfinite(period) and period > 0):
            raise BadParameterError("period", period, "seconds > 0")
        if self._hb_node is not None and self._hb_node != node_id and self._hb_owners:
            raise BadParameterError(
                "node_id",
                node_id,
                f"the host node id already produced on this bus ({self._hb_node})",
            )
        if self._tg is None:
            raise NotConnectedError(f"CAN bus {self.name}: not entered")
        self._hb_node = node_id
        self._hb_owners[id(owner)] = period
        if not self._hb_running:
            self._hb_running = True
            self._tg.start_soon(self._heartbeat_producer)

    def release_heartbeat(self, owner: object) -> None:
        """``owner`` no longer needs the host heartbeat (the producer stops with the last)."""
        self._hb_owners.pop(id(owner), None)

    async def _heartbeat_producer(self) -> None:
        try:
            next_at = time.monotonic()
            while self._hb_owners and self._hb_node is not None:
                # NMT state Operational; inline when nothing is queued (no sender-task hop
                # per beat), else behind the queued frames.
                msg = TxMessage.frame(0x700 + self._hb_node, b"\x05", False, False)
                if (
                    self.state is BusState.UP
                    and self._tx_send is not None
                    and not self._try_inline(msg)
                ):
                    self._queue_nowait(msg)
                period = min(self._hb_owners.values())
                now = time.monotonic()
                next_at = max(next_at + period, now)  # after a stall: no burst of late beats
                await anyio.sleep(next_at - now)
        finally:
            self._hb_running = False

    async def _sync_producer(self, period: float) -> None:
        """CANopen SYNC (COB-ID 0x080, no data) every ``period`` seconds, on absolute deadlines."""
        next_at = time.monotonic()
        sync = can.Message(arbitration_id=0x080, data=b"", is_extended_id=False, check=False)
        while True:
            next_at += period
            await anyio.sleep(max(0.0, next_at - time.monotonic()))
            if self.state is BusState.UP and self._tx_send is not None:
                self._queue_nowait(sync)

    # -- receive --------------------------------------------------------------------------
    def _recv_batch(self, bus: can.BusABC) -> list[can.Message]:
        """Reader thread: one blocking recv (bounded), then drain what is queued."""
        first = bus.recv(self.poll_interval)
        if first is None:
            return []
        batch = [first]
        recv = bus.recv
        limit = self.max_batch
        while len(batch) < limit:
            try:
                msg = recv(0.0)
            except Exception:
                break  # the next call reports it
            if msg is None:
                break
            batch.append(msg)
        return batch

    async def _reader(
        self, *, task_status: anyio.abc.TaskStatus[None] = anyio.TASK_STATUS_IGNORED
    ) -> None:
        started = task_status  # reported once the first reader is reading
        while True:
            if self.state is BusState.DOWN:
                await self._recover()
            bus = self._bus
            assert bus is not None
            reason = None
            if self.read_mode != "thread":
                reason = await self._run_in_loop(bus, started)
                if reason is None and self._reads_fd(bus):
                    reason = await self._run_fd_in_loop(bus, started)
            if reason is None:
                reason = await self._run_reader_thread(bus, started)
            started = anyio.TASK_STATUS_IGNORED
            self._drain_rx()  # frames read before the failure go out first
            self._set_down(reason)

    # python-can's virtual interface: read in the event loop when the sender wakes it.
    async def _run_in_loop(
        self, bus: can.BusABC, task_status: anyio.abc.TaskStatus[None]
    ) -> str | None:
        """Read ``bus`` in the loop until it fails (the failure); None if not possible."""
        failed = self._virtual_failed = anyio.Event()
        self._virtual_wake_pending = False  # a wake-up lost with an earlier reader's fd
        rx = hook_virtual_bus(bus, self.rx_buffer, self._wake_virtual)
        if rx is None:
            return None
        self._virtual_rx = rx
        self.reads_in_loop += 1
        loop = self._loop
        assert loop is not None
        fd = self._open_wake_fd(loop)
        task_status.started()
        try:
            self._wake_virtual()  # frames queued before the hook
            while not failed.is_set():
                with anyio.move_on_after(self.poll_interval):
                    await failed.wait()
                # Idle check, as a reader thread's bounded recv would: a bus shut down
                # by its owner raises on recv.
                self._drain_virtual(probe=True)
        finally:
            self._virtual_rx = None
            rx.unhook()
            if fd is not None:
                with contextlib.suppress(Exception):  # the loop may be closing
                    loop.remove_reader(fd)
                with self._virtual_fd_lock:  # a sender past unhook may still be waking
                    self._virtual_wake_fd = None
                    os.close(fd)
                # A wake-up written and never read is gone with the fd: not pending any
                # more (else a later reader's senders would never wake it again).
                self._virtual_wake_pending = False
        return self._virtual_failure

    def _open_wake_fd(self, loop: asyncio.AbstractEventLoop) -> int | None:
        """An eventfd watched by the loop (Linux): a sender's wake-up is one 8-byte write
        and the loop's one read, where ``call_soon_threadsafe`` allocates a handle,
        writes the loop's self-pipe and the loop reads it twice (the second read ends in
        an exception). None where there is no eventfd (then ``call_soon_threadsafe``)."""
        eventfd = getattr(os, "eventfd", None)
        if eventfd is None:
            return None
        fd: int = eventfd(0, os.EFD_NONBLOCK | os.EFD_CLOEXEC)
        try:
            loop.add_reader(fd, self._virtual_fd_ready, fd)
        except (NotImplementedError, OSError):  # a loop without add_reader
            os.close(fd)
            return None
        self._virtual_wake_fd = fd
        return fd

    def _virtual_fd_ready(self, fd: int) -> None:
        """Event loop: the eventfd is readable (a sender woke us): reset it, drain."""
        try:  # noqa: SIM105 - contextlib.suppress costs a context manager per wake-up
            os.eventfd_read(fd)
        except BlockingIOError:  # read already (a spurious wake-up)
            pass
        self._drain_virtual()

    # socketcan (read_mode "auto"), any bus with a file descriptor (read_mode "loop").
    def _reads_fd(self, bus: can.BusABC) -> bool:
        if self.read_mode == "auto" and type(bus).__name__ not in FD_READ_BUSES:
            return False
        try:
            return bus.fileno() >= 0
        except (NotImplementedError, OSError, ValueError):
            return False

    async def _run_fd_in_loop(
        self, bus: can.BusABC, task_status: anyio.abc.TaskStatus[None]
    ) -> str:
        """Read ``bus`` in the loop when its descriptor is readable, until it fails."""
        loop = self._loop
        assert loop is not None
        failed = anyio.Event()
        broken = False  # failed is set (read per cycle: a plain flag)
        outcome: list[str] = []
        fd = bus.fileno()

        def drain() -> None:
            nonlocal broken
            if broken:
                return
            frames: list[can.Message] = []
            recv = bus.recv
            limit = self.max_batch
            try:
                while len(frames) < limit:
                    msg = recv(0.0)
                    if msg is None:
                        break
                    frames.append(msg)
                else:
                    loop.call_soon(drain)  # more queued: let other tasks run first
            except Exception as exc:
                outcome.append(f"receive failed: {exc!r}")
                broken = True
                failed.set()
                with contextlib.suppress(Exception):
                    loop.remove_reader(fd)
            if frames:
                self._dispatch(frames)

        # read_now(): the reader unregistered until ``held_until`` (loop time), each call
        # moving it on; release() registers it again once a hold ran out (``check``, due
        # at ``check_at``).
        held = False
        held_until = 0.0
        check: asyncio.TimerHandle | None = None
        check_at = 0.0

        def release() -> None:
            nonlocal held, check, check_at
            check = None
            if not held or broken:
                return
            if loop.time() < held_until:  # held on by a read since: look again then
                check_at = held_until
                check = loop.call_at(check_at, release)
                return
            held = False
            loop.add_reader(fd, drain)
            drain()

        def read_now(hold_s: float) -> None:
            nonlocal held, held_until, check, check_at
            self.reads_on_demand += 1
            drain()
            if broken:
                return
            held_until = loop.time() + hold_s
            if not held:
                held = True
                loop.remove_reader(fd)
            if check is None or held_until < check_at:  # a shorter hold than before
                if check is not None:
                    check.cancel()
                check_at = held_until
                check = loop.call_at(check_at, release)

        loop.add_reader(fd, drain)
        self.reads_in_loop += 1
        self._read_now = read_now
        task_status.started()
        try:
            while not failed.is_set():
                with anyio.move_on_after(self.poll_interval):
                    await failed.wait()
                drain()  # idle check: a bus shut down under us raises on recv
        finally:
            self._read_now = None
            held = False
            if check is not None:
                check.cancel()
            with contextlib.suppress(Exception):  # the descriptor may be closed already
                loop.remove_reader(fd)
        return outcome[0]

    def _wake_virtual(self) -> None:
        """Any thread (a frame was put on the bus's queue): schedule one drain."""
        if self._virtual_wake_pending:
            return
        self._virtual_wake_pending = True
        if self._virtual_wake_fd is not None:
            with self._virtual_fd_lock:
                fd = self._virtual_wake_fd
                if fd is not None:  # not closed meanwhile
                    os.eventfd_write(fd, 1)
                    return
        loop = self._loop
        assert loop is not None
        with contextlib.suppress(RuntimeError):  # the loop is closed
            loop.call_soon_threadsafe(self._drain_virtual)

    def _drain_virtual(self, probe: bool = False) -> None:
        """Event loop: take what is queued, then one dispatch.

        Without python-can filters the frames are taken from the queue directly (one
        lock for the batch); with filters, by non-blocking ``recv(0)`` each. ``probe``:
        one ``recv(0)`` first even if nothing is queued (it raises on a closed bus).
        """
        if not probe:
            self._virtual_wake_pending = False  # before reading: a frame put later wakes again
        rx, bus, failed = self._virtual_rx, self._bus, self._virtual_failed
        if rx is None or bus is None or failed is None or failed.is_set():
            return  # the bus went down or was closed meanwhile
        if rx.overflow != self.stats.rx_overflow:
            dropped = rx.overflow - self.stats.rx_overflow
            self.stats.rx_overflow += dropped
            self.log.warning("rx_overflow", dropped=dropped, total=self.stats.rx_overflow)
        frames: list[can.Message] = []
        recv = bus.recv
        limit = self.max_batch
        queued = rx.queue  # checked without the lock: a frame put later wakes us again
        try:
            if probe:
                msg = recv(0.0)
                if msg is not None:
                    frames.append(msg)
            if bus.filters is None:
                frames += rx.take(limit - len(frames))
            else:
                while queued and len(frames) < limit:
                    msg = recv(0.0)  # None: a frame the filters rejected
                    if msg is not None:
                        frames.append(msg)
            if queued and len(frames) >= limit and not self._virtual_wake_pending:
                # Let other tasks run; the rest in the next drain.
                self._virtual_wake_pending = True
                assert self._loop is not None
                self._loop.call_soon(self._drain_virtual)
        except Exception as exc:
            self._virtual_failure = f"receive failed: {exc!r}"
            failed.set()
        if frames:
            self._dispatch(frames)

    async def _run_reader_thread(
        self, bus: can.BusABC, task_status: anyio.abc.TaskStatus[None]
    ) -> str:
        """Run one reader thread on ``bus`` until its ``recv`` fails; the failure.

        The thread is stopped and joined when this task is cancelled (bus closing):
        ``recv`` is bounded by ``poll_interval``, so the join is too.
        """
        stop = threading.Event()
        ended = anyio.Event()
        outcome: list[str] = []

        def finished(reason: str) -> None:
            outcome.append(reason)
            ended.set()

        thread = threading.Thread(
            target=self._read_loop,
            args=(bus, stop, finished),
            name=f"can-reader-{self.name}",
            daemon=True,
        )
        thread.start()
        self.reader_threads += 1
        task_status.started()
        try:
            await ended.wait()
        finally:
            stop.set()
            with anyio.CancelScope(shield=True):
                await run_in_thread(thread.join)
        return outcome[0]

    def _read_loop(
        self, bus: can.BusABC, stop: threading.Event, finished: Callable[[str], None]
    ) -> None:
        """Reader thread: receive batches and hand them to the loop until stopped or failed."""
        loop = self._loop
        assert loop is not None
        reason = "reader stopped"
        try:
            while not stop.is_set():
                try:
                    batch = self._recv_batch(bus)
                except Exception as exc:
                    reason = f"receive failed: {exc!r}"
                    break
                if batch:
                    self._post_batch(loop, batch)
        finally:
            with contextlib.suppress(RuntimeError):  # the loop is closed: nobody waits
                loop.call_soon_threadsafe(finished, reason)

    def _post_batch(self, loop: asyncio.AbstractEventLoop, batch: list[can.Message]) -> None:
        """Reader thread: queue ``batch`` for the loop; wake it unless a wake-up is pending.

        At most ``rx_buffer`` frames wait for the loop; a batch beyond that is dropped and
        counted (``stats.rx_overflow``). One ``call_soon_threadsafe`` serves every batch
        queued before the loop runs it, so a busy loop takes them all in one dispatch.
        """
        count = len(batch)
        if self._rx_posted - self._rx_taken + count > self.rx_buffer:
            self._rx_overflow += count  # published (and logged) by the loop's next drain
        else:
            self._rx_posted += count
            self._rx_queue.append(batch)
        if not self._rx_wake_pending:
            self._rx_wake_pending = True
            with contextlib.suppress(RuntimeError):  # the loop is closed
                loop.call_soon_threadsafe(self._drain_rx)

    def _drain_rx(self) -> None:
        """Event loop: dispatch every batch the reader thread queued, in order, as one."""
        self._rx_wake_pending = False  # before taking: a batch queued after this wakes again
        if self._rx_overflow != self.stats.rx_overflow:
            dropped = self._rx_overflow - self.stats.rx_overflow
            self.stats.rx_overflow += dropped
            self.log.warning("rx_overflow", dropped=dropped, total=self.stats.rx_overflow)
        queue = self._rx_queue
        if not queue:
            return
        frames = queue.popleft()  # ours now: the reader thread never touches a posted batch
        while queue:
            frames.extend(queue.popleft())
        self._rx_taken += len(frames)
        self._dispatch(frames)

    def _dispatch(self, batch: list[can.Message]) -> None:
        stats = self.stats
        stats.rx_frames += len(batch)
        stats.rx_batches += 1
        routes = self._routes
        if len(batch) == 1:  # the request/answer case: no per-port lists to build
            msg = batch[0]
            if msg.is_error_frame:
                stats.error_frames += 1
                return
            key = msg.arbitration_id | EXTENDED_FLAG if msg.is_extended_id else msg.arbitration_id
            targets = routes.get(key)
            if targets is None:
                stats.unrouted += 1
                return
            for port in targets:  # each port gets a list of its own
                port._deliver(batch if len(targets) == 1 else [msg])
            return
        per_port: dict[NodePort, list[can.Message]] = {}
        for msg in batch:
            if msg.is_error_frame:
                stats.error_frames += 1
                continue
            key = msg.arbitration_id | EXTENDED_FLAG if msg.is_extended_id else msg.arbitration_id
            ports = routes.get(key)
            if ports is None:
                stats.unrouted += 1
                continue
            for port in ports:
                frames = per_port.get(port)
                if frames is None:
                    per_port[port] = [msg]
                else:
                    frames.append(msg)
        for port, frames in per_port.items():
            port._deliver(frames)

    # -- faults and recovery --------------------------------------------------------------
    def _set_down(self, reason: str) -> None:
        if self.state is not BusState.UP:
            return
        self.state = BusState.DOWN
        self.last_error = reason
        self.stats.bus_errors += 1
        self._up = anyio.Event()
        self._down.set()
        self.log.warning("bus_down", reason=reason)
        for port in list(self._ports):
            callback = port.on_bus_error
            if callback is None:
                continue
            try:
                callback(reason)
            except Exception as exc:  # a driver's bug must not kill the reader
                self.log.exception("bus_error_callback_failed", port=port.name, error=repr(exc))

    def _set_up(self) -> None:
        recovered = self.state is BusState.DOWN
        self.state = BusState.UP
        self._down = anyio.Event()
        self._up.set()
        if recovered:
            self.stats.recoveries += 1
            self.log.info("bus_recovered", after=self.last_error)

    async def _recover(self) -> None:
        """Reopen (when possible) or re-probe the bus with exponential backoff until it works."""
        delay, longest = self.reconnect_backoff
        attempt = 0
        while True:
            await anyio.sleep(delay)
            delay = min(delay * 2, longest)
            attempt += 1
            try:
                async with self._io_lock:
                    if self._factory is not None:
                        await self._reopen()
                    bus = self._bus
                    assert bus is not None
                    first = await run_in_thread(bus.recv, 0.0)
            except Exception as exc:
                self.last_retry_error = f"attempt {attempt}: {exc!r}"
                self.log.debug("bus_recover_failed", attempt=attempt, error=repr(exc))
                continue
            self._set_up()
            if first is not None:
                self._dispatch([first])
            return

    async def _reopen(self) -> None:
        assert self._factory is not None
        old, self._bus = self._bus, None
        if old is not None:
            try:
                await run_in_thread(old.shutdown)
            except Exception as exc:
                self.log.debug("bus_shutdown_failed", error=repr(exc))
        try:
            self._bus = await run_in_thread(self._factory)
        except BaseException:
            self._bus = old  # keep an object to shut down at exit (already shut: harmless)
            raise
        self._inline = self._choose_inline(self._bus)
        self._send_fn = virtual_sender(self._bus, TxMessage) or self._bus.send

    def __repr__(self) -> str:
        return f"CanBus({self.name!r}, state={self.state}, ports={len(self._ports)})"
