"""Connectors between an OutPort and an InPort, as OpenRTM builds them.

PUSH (``dataport.dataflow_type: push``): the InPort side holds the connector buffer
(``dataport.inport.buffer.*``); the OutPort side's publisher sends to it through the
transport link:

- ``flush``: in the writer's task, during ``write`` (which returns the receiver's
  answer: PORT_OK, SEND_FULL with ``do_nothing``, SEND_TIMEOUT when ``block`` timed out);
- ``new``: ``write`` stores in the publisher's own buffer (``dataport.outport.buffer.*``)
  and wakes the connector's sender task, which sends what ``push_policy`` picks
  (``new``: only the newest, ``all``, ``fifo``: one per wake-up, ``skip``: every
  (skip_count+1)-th); values not picked are counted (``skipped``, ON_SKIPPED);
- ``periodic``: the same, but the sender wakes at ``push_rate`` Hz on the port's clock.

PULL: the OutPort side holds the buffer (``dataport.outport.buffer.*``, OpenRTM's
OutPortPullConnector); ``write`` stores there and the InPort's ``read`` takes from it
through the link; ``is_new`` asks it how many values are unread.

Use a connector as an async context manager: entering connects both ports (and starts
the sender task of ``new``/``periodic``), leaving disconnects them. Nothing is lost
unseen: every overwritten, refused, timed-out or skipped value is counted in
:attr:`Connector.stats` and reported to the ports' listeners.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Mapping
from contextlib import AsyncExitStack
from dataclasses import dataclass
from types import TracebackType
from typing import Any, Protocol, Self

import anyio

from openel_async.logs import get_logger

from ...clock import NS_PER_S, Clock
from ..errors import PreconditionNotMetError, RTCBadParameterError
from .buffer import BufferOptions, ReadOutcome, RingBuffer
from .dataport import InPort, OutPort
from .datatypes import TimedValue, resolve_data_type
from .profile import ConnectorProfile, Dataflow, PushPolicy, Subscription
from .status import ListenerType as L
from .status import PortStatus
from .transport import PullSource, PushSink, Transport, transport_for

__all__ = ["Connector", "ConnectorInfo", "ConnectorStats", "InHalf", "OutHalf", "connect"]

log = get_logger(__name__)
_ids = itertools.count(1)


@dataclass(frozen=True, slots=True)
class ConnectorInfo:
    """Who a connector joins, and how."""

    id: str
    name: str
    out_port: str
    """``instance.port`` of the OutPort."""
    in_port: str
    data_type: str
    profile: ConnectorProfile

    @property
    def key(self) -> str:
        """A stable name of the connection (``out.instance/out.port/in.instance/in.port``),
        e.g. for a network transport's key expression."""
        return "/".join((*self.out_port.split(".", 1), *self.in_port.split(".", 1)))


@dataclass(frozen=True, slots=True)
class ConnectorStats:
    """What happened to the values of one connector."""

    written: int
    """Values the OutPort handed to the connector."""
    sent: int
    """Values the publisher handed to the link (PUSH)."""
    received: int
    """Values stored on the InPort side (PUSH) or read by the InPort (PULL)."""
    read: int
    overwritten: int
    refused: int
    """Refused because a buffer was full (do_nothing)."""
    timeouts: int
    """Writes and reads that gave up (block)."""
    skipped: int
    """Values a new/periodic publisher's push policy did not send."""


class OutHalf(Protocol):
    info: ConnectorInfo

    def offer(self, data: TimedValue) -> PortStatus | None:
        """The write without a wait (the fast path): its status, or None when it has
        to wait or call listeners, having done nothing (then :meth:`write`)."""
        ...

    async def write(self, data: TimedValue) -> PortStatus: ...


class InHalf(Protocol):
    info: ConnectorInfo
    readable: Callable[[], int]
    """Unread values waiting (0 when unknown)."""

    def poll(self) -> TimedValue | None:
        """The next unread value when one is there and no listener has to hear of it
        (the fast path), else None having done nothing (then :meth:`read`)."""
        ...

    async def read(self) -> tuple[PortStatus, ReadOutcome, TimedValue | None]: ...


_OK = PortStatus.PORT_OK
_SEND_FULL = PortStatus.SEND_FULL
_SEND_STATUS = {
    PortStatus.BUFFER_FULL: PortStatus.SEND_FULL,
    PortStatus.BUFFER_TIMEOUT: PortStatus.SEND_TIMEOUT,
}


def _after_write(
    port: InPort[Any] | OutPort[Any],
    info: ConnectorInfo,
    status: PortStatus,
    data: TimedValue,
    dropped: TimedValue | None,
) -> None:
    if not port.has_listeners:
        return
    if status is PortStatus.PORT_OK:
        if dropped is not None:
            port.notify(L.ON_BUFFER_FULL, info, data)
            port.notify(L.ON_BUFFER_OVERWRITE, info, dropped)
        port.notify(L.ON_BUFFER_WRITE, info, data)
    elif status is PortStatus.BUFFER_FULL:
        port.notify(L.ON_BUFFER_FULL, info, data)
    else:
        port.notify(L.ON_BUFFER_FULL, info, data)
        port.notify(L.ON_BUFFER_WRITE_TIMEOUT, info, data)


def _after_read(
    port: InPort[Any],
    info: ConnectorInfo,
    status: PortStatus,
    outcome: ReadOutcome,
    value: TimedValue | None,
) -> None:
    if not port.has_listeners:
        return
    if outcome is ReadOutcome.NEW:
        port.notify(L.ON_BUFFER_READ, info, value)
        return
    port.notify(L.ON_BUFFER_EMPTY, info, value)
    if status is PortStatus.BUFFER_TIMEOUT:
        port.notify(L.ON_BUFFER_READ_TIMEOUT, info)


class PushReceiver:
    """The InPort half of a PUSH connector: the connector buffer (a PushSink)."""

    def __init__(self, port: InPort[Any], info: ConnectorInfo, options: BufferOptions):
        self.port = port
        self.info = info
        self.buffer: RingBuffer[TimedValue] = RingBuffer(options, port.clock)
        self.readable: Callable[[], int] = self.buffer.readable
        self.offer_direct = self.buffer.offer
        """What a publisher in this process calls when neither port has listeners (the
        buffer's :meth:`RingBuffer.offer`: BUFFER_FULL, not SEND_FULL)."""

    def poll(self) -> TimedValue | None:
        if self.port.has_listeners:
            return None
        return self.buffer.take()

    async def put(self, data: TimedValue) -> PortStatus:
        status, dropped = await self.buffer.write(data)
        port = self.port
        if not port.has_listeners and status is PortStatus.PORT_OK:
            return status
        _after_write(port, self.info, status, data, dropped)
        if status is PortStatus.PORT_OK:
            port.notify(L.ON_RECEIVED, self.info, data)
            return status
        port.notify(
            L.ON_RECEIVER_FULL if status is PortStatus.BUFFER_FULL else L.ON_RECEIVER_TIMEOUT,
            self.info,
            data,
        )
        return _SEND_STATUS.get(status, status)

    async def read(self) -> tuple[PortStatus, ReadOutcome, TimedValue | None]:
        status, outcome, value = await self.buffer.read()
        _after_read(self.port, self.info, status, outcome, value)
        return status, outcome, value


class FlushPublisher:
    """Sends each value in the writer's task."""

    def __init__(self, port: OutPort[Any], info: ConnectorInfo, link: PushSink) -> None:
        self.port = port
        self.info = info
        self.link = link
        self.written = 0
        self.sent = 0
        # in process the link is the receiver itself: the fast path skips its put
        self._receiver = link if isinstance(link, PushReceiver) else None

    def offer(self, data: TimedValue) -> PortStatus | None:
        receiver = self._receiver
        if receiver is None or self.port.has_listeners or receiver.port.has_listeners:
            return None
        status = receiver.offer_direct(data)
        if status is None:  # full with the block policy
            return None
        self.written += 1
        self.sent += 1
        return _OK if status is _OK else _SEND_FULL

    async def write(self, data: TimedValue) -> PortStatus:
        self.written += 1
        port = self.port
        if port.has_listeners:
            port.notify(L.ON_SEND, self.info, data)
        self.sent += 1
        status = await self.link.put(data)
        if status is not PortStatus.PORT_OK and port.has_listeners:
            kind = L.ON_RECEIVER_FULL if status is PortStatus.SEND_FULL else L.ON_RECEIVER_TIMEOUT
            port.notify(kind, self.info, data)
        return status


class QueuedPublisher:
    """``new`` and ``periodic``: a buffer on the OutPort side and a sender task."""

    def __init__(
        self,
        port: OutPort[Any],
        info: ConnectorInfo,
        link: PushSink,
        options: BufferOptions,
    ) -> None:
        self.port = port
        self.info = info
        self.link = link
        self.buffer: RingBuffer[TimedValue] = RingBuffer(options, port.clock)
        profile = info.profile
        self.policy = profile.push_policy
        self.skip_count = profile.skip_count
        self.periodic = profile.subscription is Subscription.PERIODIC
        self.period_ns = max(1, round(NS_PER_S / profile.push_rate_hz))
        self._wake = anyio.Event()
        self._seen = 0
        self.written = 0
        self.sent = 0
        self.skipped = 0
        self.failed = 0

    def offer(self, data: TimedValue) -> PortStatus | None:
        if self.port.has_listeners:
            return None
        status = self.buffer.offer(data)
        if status is None:
            return None
        self.written += 1
        if status is _OK and not self.periodic:
            self._wake.set()
        return status

    async def write(self, data: TimedValue) -> PortStatus:
        self.written += 1
        status, dropped = await self.buffer.write(data)
        _after_write(self.port, self.info, status, data, dropped)
        if status is PortStatus.PORT_OK and not self.periodic:
            self._wake.set()
        return status

    def _pick(self) -> list[TimedValue]:
        buffer = self.buffer
        policy = self.policy
        if policy is PushPolicy.FIFO:
            one = buffer.take()
            return [] if one is None else [one]
        values = buffer.take_all()
        if policy is PushPolicy.ALL or not values:
            return values
        if policy is PushPolicy.NEW:
            chosen, dropped = values[-1:], values[:-1]
        else:
            chosen, dropped = [], []
            for v in values:
                (chosen if self._seen % (self.skip_count + 1) == 0 else dropped).append(v)
                self._seen += 1
        if dropped:
            self.skipped += len(dropped)
            for v in dropped:
                self.port.notify(L.ON_SKIPPED, self.info, v)
        return chosen

    async def _push(self) -> None:
        port = self.port
        for value in self._pick():
            port.notify(L.ON_SEND, self.info, value)
            self.sent += 1
            status = await self.link.put(value)
            if status is not PortStatus.PORT_OK:
                self.failed += 1
                kind = (
                    L.ON_RECEIVER_FULL if status is PortStatus.SEND_FULL else L.ON_RECEIVER_TIMEOUT
                )
                port.notify(kind, self.info, value)

    async def run(self) -> None:
        if not self.periodic:
            while True:
                await self._wake.wait()
                self._wake = anyio.Event()
                await self._push()
        clock: Clock = self.port.clock
        deadline = clock.now_ns() + self.period_ns
        while True:
            await clock.sleep_until(deadline)
            await self._push()
            deadline += self.period_ns
            now = clock.now_ns()
            if deadline <= now:  # woke a whole period late: skip, do not burst
                deadline += ((now - deadline) // self.period_ns + 1) * self.period_ns


class PullProvider:
    """The OutPort half of a PULL connector: the buffer the InPort reads (a PullSource)."""

    def __init__(self, port: OutPort[Any], info: ConnectorInfo, options: BufferOptions):
        self.port = port
        self.info = info
        self.buffer: RingBuffer[TimedValue] = RingBuffer(options, port.clock)
        self.written = 0
        self.readable: Callable[[], int] = self.buffer.readable

    def offer(self, data: TimedValue) -> PortStatus | None:
        if self.port.has_listeners:
            return None
        status = self.buffer.offer(data)
        if status is not None:
            self.written += 1
        return status

    async def write(self, data: TimedValue) -> PortStatus:
        self.written += 1
        status, dropped = await self.buffer.write(data)
        _after_write(self.port, self.info, status, data, dropped)
        return status

    async def get(self) -> tuple[PortStatus, TimedValue | None, bool]:
        status, outcome, value = await self.buffer.read()
        if outcome is ReadOutcome.NONE:
            return status, None, False
        return status, value, outcome is ReadOutcome.NEW


class PullConsumer:
    """The InPort half of a PULL connector: reads through the link."""

    def __init__(self, port: InPort[Any], info: ConnectorInfo, link: PullSource) -> None:
        self.port = port
        self.info = info
        self.link = link
        self.read_count = 0
        self.readable: Callable[[], int] = link.readable
        # in process the link is the provider itself: the fast path takes from its buffer
        self._provider = link if isinstance(link, PullProvider) else None

    def poll(self) -> TimedValue | None:
        provider = self._provider
        if provider is None or self.port.has_listeners:
            return None
        value = provider.buffer.take()
        if value is not None:
            self.read_count += 1
        return value

    async def read(self) -> tuple[PortStatus, ReadOutcome, TimedValue | None]:
        status, value, new = await self.link.get()
        if value is None:
            outcome = ReadOutcome.NONE
        else:
            outcome = ReadOutcome.NEW if new else ReadOutcome.READBACK
            self.read_count += new
        _after_read(self.port, self.info, status, outcome, value)
        return status, outcome, value


class Connector:
    """One connection from an OutPort to an InPort (see the module docstring).

    ``properties`` are OpenRTM connector properties (or a ready ConnectorProfile).
    Raises RTCBadParameterError before anything is connected when the ports are not an
    OutPort and an InPort of the same data type, or an option is bad.
    """

    def __init__(
        self,
        out_port: OutPort[Any],
        in_port: InPort[Any],
        properties: Mapping[str, object] | ConnectorProfile | None = None,
        *,
        name: str = "",
        transport: Transport | None = None,
    ) -> None:
        if not isinstance(out_port, OutPort):
            raise RTCBadParameterError("out_port", out_port, "an OutPort")
        if not isinstance(in_port, InPort):
            raise RTCBadParameterError("in_port", in_port, "an InPort")
        if out_port.data_type is not in_port.data_type:
            raise RTCBadParameterError(
                "in_port",
                in_port.full_name,
                f"an InPort of {out_port.type_name} like {out_port.full_name}, not "
                f"{in_port.type_name}",
            )
        profile = (
            properties
            if isinstance(properties, ConnectorProfile)
            else ConnectorProfile.from_properties(properties, name=name)
        )
        if profile.data_type is not None:
            declared = resolve_data_type(profile.data_type)
            if declared is not out_port.data_type:
                raise RTCBadParameterError(
                    "dataport.data_type", profile.data_type, f"{out_port.type_name} (the ports')"
                )
        self.transport = transport or transport_for(profile.interface_type)
        self.out_port = out_port
        self.in_port = in_port
        self.profile = profile
        cid = f"conn{next(_ids)}"
        self.info = ConnectorInfo(
            id=cid,
            name=name or profile.name or cid,
            out_port=out_port.full_name,
            in_port=in_port.full_name,
            data_type=out_port.type_name,
            profile=profile,
        )
        self._stack: AsyncExitStack | None = None
        self._out: FlushPublisher | QueuedPublisher | PullProvider | None = None
        self._in: PushReceiver | PullConsumer | None = None

    def __repr__(self) -> str:
        p = self.profile
        return (
            f"Connector({self.info.out_port} -> {self.info.in_port}, {p.dataflow.value}/"
            f"{p.subscription.value})"
        )

    @property
    def connected(self) -> bool:
        return self._stack is not None

    async def __aenter__(self) -> Self:
        if self._stack is not None:
            raise PreconditionNotMetError("connect", "connected", "a connector not yet entered")
        stack = AsyncExitStack()
        await stack.__aenter__()
        try:
            await self._open(stack)
        except BaseException as exc:
            await stack.__aexit__(type(exc), exc, exc.__traceback__)
            raise
        self._stack = stack
        info = self.info
        self.out_port.connectors.append(self._out)  # type: ignore[arg-type]
        self.in_port.connectors.append(self._in)  # type: ignore[arg-type]
        self.out_port.notify(L.ON_CONNECT, info)
        self.in_port.notify(L.ON_CONNECT, info)
        log.debug("port_connected", out=info.out_port, in_=info.in_port, connector=info.name)
        return self

    async def _open(self, stack: AsyncExitStack) -> None:
        p, info = self.profile, self.info
        if p.dataflow is Dataflow.PULL:
            provider = PullProvider(self.out_port, info, p.out_buffer)
            source = await stack.enter_async_context(self.transport.pull_link(info, provider))
            self._out, self._in = provider, PullConsumer(self.in_port, info, source)
            return
        receiver = PushReceiver(self.in_port, info, p.in_buffer)
        sink = await stack.enter_async_context(self.transport.push_link(info, receiver))
        self._in = receiver
        if p.subscription is Subscription.FLUSH:
            self._out = FlushPublisher(self.out_port, info, sink)
            return
        publisher = QueuedPublisher(self.out_port, info, sink, p.out_buffer)
        tg = await stack.enter_async_context(anyio.create_task_group())
        stack.callback(tg.cancel_scope.cancel)
        tg.start_soon(publisher.run)
        self._out = publisher

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> bool | None:
        stack = self._stack
        assert stack is not None
        self._stack = None
        info = self.info
        if self._out in self.out_port.connectors:
            self.out_port.connectors.remove(self._out)
        if self._in in self.in_port.connectors:
            self.in_port.connectors.remove(self._in)
        self.out_port.notify(L.ON_DISCONNECT, info)
        self.in_port.notify(L.ON_DISCONNECT, info)
        return await stack.__aexit__(exc_type, exc, tb)

    @property
    def stats(self) -> ConnectorStats:
        out, in_ = self._out, self._in
        buffers = [
            b
            for b in (getattr(out, "buffer", None), getattr(in_, "buffer", None))
            if isinstance(b, RingBuffer)
        ]
        written = getattr(out, "written", 0)
        sent = getattr(out, "sent", 0)
        if isinstance(in_, PushReceiver):
            received, read = in_.buffer.written, in_.buffer.read_count
        elif isinstance(in_, PullConsumer):
            received = read = in_.read_count
        else:
            received = read = 0
        return ConnectorStats(
            written=written,
            sent=sent,
            received=received,
            read=read,
            overwritten=sum(b.overwritten for b in buffers),
            refused=sum(b.refused for b in buffers),
            timeouts=sum(b.write_timeouts + b.read_timeouts for b in buffers),
            skipped=getattr(out, "skipped", 0),
        )


def connect(
    out_port: OutPort[Any],
    in_port: InPort[Any],
    properties: Mapping[str, object] | ConnectorProfile | None = None,
    *,
    name: str = "",
    transport: Transport | None = None,
) -> Connector:
    """A checked :class:`Connector` (enter it to connect)."""
    return Connector(out_port, in_port, properties, name=name, transport=transport)
