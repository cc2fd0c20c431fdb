"""SurfaceServer: a Surface served over Zenoh (queryables, a notice stream per client,
liveliness).

Queries arrive on Zenoh's threads and are moved into the event loop through a bounded
inbox, one ``call_soon_threadsafe`` per batch, handled in that loop callback. Each client
(named by the query's attachment) has a bounded queue of its own and at most one query
executing at a time, so its commands run in order. A query of an idle client that can be
answered without suspending (every request but execute; an execute whose one command has
a synchronous path on its component, such as a simulated motor's GetPosition or
SetPosition) is answered right there, at most one per client per batch; the others go to
the client's queue, which workers take round robin, so a flooding client is refused
(``HAL_NO_MEMORY``, counted in ``refused_busy``) while the others keep being served. A
malformed, oversized or invalid message gets an answer with the matching return code
and is logged once.

On a :class:`~openel_zenoh.gate.GatedEventLoop` (``openel-async serve``), a plain read
(``THREAD_READS``: GetPosition...) of a client with nothing earlier pending is answered on
Zenoh's thread itself while the loop is parked in ``select``, the loop's gate taken so
that no loop code runs meanwhile: the read is exactly what a loop callback would have
done, without waking the loop (docs/remote.md, "Threads").

Notices for a client (completed, notify_event, notify_error) are numbered and published
from the loop: the first of a loop turn at once, the others of that turn in one batch at its
end; the outbound buffer is bounded, and whatever it drops leaves a gap in the numbering
that the client reports.

An execute may carry its send time and a time to live (the selector parameters ``sent_us``
and ``ttl_us``, docs/wire.md "Freshness"): the server estimates how late it arrived against
the fastest query of that client seen so far (so the two clocks need not agree) and refuses
it, executing nothing, when it is older than its time to live -- a command held up by a
partition and retransmitted after the client gave up on it never moves anything.

Client state is bounded: a client is known by its liveliness token (a ``ZenohClient``
declares one; its state goes when the token goes) or, without one, for as long as it is
active -- a client that has sent nothing for ``client_idle_timeout`` and has nothing queued
is forgotten (its subscriptions with it). At most ``max_clients`` are known at once: a new
one first displaces the least recently active idle client without a token; when every slot
is held by a live or busy client, it is refused with ``HAL_NO_MEMORY`` (``refused_clients``).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from threading import get_ident
from types import TracebackType
from typing import Any, Self, cast

import anyio
import anyio.abc
import msgspec
import zenoh

from openel_async.errors import BadParameterError, HALError, ReturnCode, WouldBlockError
from openel_async.logs import get_logger
from openel_async.surface import Surface, compact, xml_psm
from openel_async.surface.messages import CommandMessage, DataType, Device, Parameter, ResultList
from openel_async.wakeup import Wakeup

from . import wire
from .bridge import ThreadInbox
from .freshness import DelayBaseline, freshness
from .gate import LoopGate, enter_as_loop, exit_loop, gate_of, needs_wake, work_marker
from .keys import Keys
from .links import ClientLink
from .payloads import DecodedPayloads, is_xml

log = get_logger(__name__)

MAX_CLIENTS = 256
"""Clients a server keeps state for (a notice publisher, subscriptions, a queue) by default."""
CLIENT_IDLE_TIMEOUT = 60.0
"""Seconds after which an idle client without a liveliness token is forgotten (default)."""
CLIENT_QUEUE = 32
"""Queries one client may have waiting; more are refused with HAL_NO_MEMORY."""
INBOX_SIZE = 4096
WORKERS = 4
ANONYMOUS = "anonymous"
THREAD_READS = frozenset(
    {"GetPosition", "GetSpeed", "GetTorque", "GetValueOfMeasurement", "GetState"}
)
"""The execute functions a GatedEventLoop's server may answer on Zenoh's thread."""
THREAD_READ_MAX_BYTES = 1024
"""Larger execute payloads (and XML ones) are never decoded on Zenoh's thread."""


def _nothing() -> None:
    """A loop callback that only wakes the loop (it runs what a gated section scheduled)."""


@dataclass
class _Request:
    kind: str
    client: str
    payload: bytes
    query: zenoh.Query
    device: Device | None = None
    """The execute payload, once decoded."""
    xml: bool = False
    received: float = 0.0
    """When it arrived (time.monotonic, on Zenoh's thread)."""
    sent: float | None = None
    """When the client sent it, on the client's clock (seconds; the ``sent_us`` parameter)."""
    ttl: float = 0.0
    """How long after ``sent`` it may still be executed (the ``ttl_us`` parameter)."""
    deadline: float = math.inf
    """When it becomes stale, on this server's clock (set once its client is known)."""


@dataclass
class _Client:
    name: str
    queue: deque[_Request] = field(default_factory=deque)
    busy: bool = False
    link: ClientLink | None = None
    alive: bool = False
    """Its liveliness token is up (it is forgotten when the token goes, not when idle)."""
    last_active: float = 0.0
    """When it last sent a query (the loop's clock)."""
    baseline: DelayBaseline = field(default_factory=DelayBaseline)
    """How fast its queries arrive at best (freshness.py): the age of each is measured
    against it."""

    def idle(self) -> bool:
        return not self.busy and not self.queue


class _TooManyClientsError(Exception):
    """Every client slot is held by a live or busy client."""


def _drop(query: zenoh.Query) -> None:
    """Finalize a query (the querier's get ends once every queryable dropped it)."""
    cast(Any, query).drop()


def _drop_later(query: zenoh.Query) -> None:
    """:func:`_drop` as a loop callback (which must not raise)."""
    try:
        _drop(query)
    except Exception as exc:
        log.warning("query_drop_failed", error=str(exc))


def _undeclare(entity: object) -> None:
    with contextlib.suppress(zenoh.ZError):
        cast(Any, entity).undeclare()


def _result_code(exc: BaseException) -> tuple[int, str]:
    if isinstance(exc, HALError):
        return int(exc.code), str(exc)
    return int(ReturnCode.HAL_ERROR), repr(exc)


class SurfaceServer:
    """Serve ``surface`` on ``session`` under ``openel/<namespace>/`` (``async with``)."""

    def __init__(
        self,
        surface: Surface,
        session: zenoh.Session,
        namespace: str = "default",
        *,
        max_clients: int = MAX_CLIENTS,
        client_idle_timeout: float = CLIENT_IDLE_TIMEOUT,
        admit: Callable[[Device], Device | None] | None = None,
    ) -> None:
        if isinstance(max_clients, bool) or not isinstance(max_clients, int) or max_clients < 1:
            raise BadParameterError("max_clients", max_clients, "an int >= 1")
        if not client_idle_timeout > 0:
            raise BadParameterError("client_idle_timeout", client_idle_timeout, "seconds > 0")
        self.surface = surface
        self.session = session
        self.keys = Keys(namespace)
        self.admit = admit
        """Called with every execute's Device before it runs (not the plain reads answered
        on Zenoh's thread): None runs it, a Device is the reply instead (nothing executed;
        openel_zenoh.lifecycle refuses the commands of INACTIVE components this way)."""
        self.max_clients = max_clients
        self.client_idle_timeout = client_idle_timeout
        self.clients: dict[str, _Client] = {}
        self.refused_clients = 0
        """Queries refused because every client slot was taken (HAL_NO_MEMORY)."""
        self.forgotten_clients = 0
        """Clients without a token forgotten (idle too long, or displaced by a new one)."""
        self.refused_busy = 0
        self.refused_bad = 0
        self.refused_stale = 0
        """Executes refused because they arrived older than their time to live."""
        self.served = 0
        self.served_on_zenoh_thread = 0
        """Reads answered on Zenoh's thread through the loop's gate (a GatedEventLoop)."""
        self._gate: LoopGate | None = None
        self._ready: deque[_Client] = deque()
        self._work = Wakeup()  # reused: no anyio.Event per request served by the worker
        self._declared: list[Any] = []
        self._tg: anyio.abc.TaskGroup | None = None
        self._inbox: ThreadInbox[_Request] | None = None
        self._alive: ThreadInbox[tuple[str, bool]] | None = None
        self._flush_queue: list[ClientLink] = []
        self._loop: asyncio.AbstractEventLoop | None = None
        self.loop_thread = 0
        """The thread id of the loop (set on entry)."""
        self._payloads = DecodedPayloads()

    async def __aenter__(self) -> Self:
        self._loop = asyncio.get_running_loop()
        self.loop_thread = get_ident()
        self._gate = gate_of(self._loop)
        self._inbox = ThreadInbox(INBOX_SIZE, on_drop=self._refuse_dropped, drain=self._on_requests)
        self._alive = ThreadInbox(1024)
        tg = anyio.create_task_group()
        await tg.__aenter__()
        self._tg = tg
        try:
            for kind in (
                "execute",
                "subscribe",
                "unsubscribe",
                "event_detail",
                "error_detail",
                "components",
            ):
                key = getattr(self.keys, kind)
                self._declared.append(
                    self.session.declare_queryable(
                        key,
                        zenoh.handlers.Callback(self._on_query(kind), indirect=False),
                        complete=True,
                    )
                )
            self._declared.append(
                self.session.liveliness().declare_subscriber(
                    self.keys.clients_alive,
                    zenoh.handlers.Callback(self._on_client_alive, indirect=False),
                    history=True,
                )
            )
            tg.start_soon(self._watch_clients)
            tg.start_soon(self._expire_clients)
            for _ in range(WORKERS):
                tg.start_soon(self._worker)
            self._token = self.session.liveliness().declare_token(self.keys.server_alive)
        except BaseException:
            await self._close()
            raise
        log.info(
            "surface_server_started",
            namespace=self.keys.namespace,
            components=len(self.surface.entries),
        )
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self._close()

    async def _close(self) -> None:
        token = getattr(self, "_token", None)
        for entity in [*self._declared, *([token] if token is not None else [])]:
            _undeclare(entity)
        self._declared.clear()
        for client in self.clients.values():
            if client.link is not None:
                client.link.close()
                self.surface.detach(client.link)
        if self._alive is not None:
            self._alive.close()
        if self._inbox is not None:
            self._inbox.close()
            for request in self._inbox.take_all():
                self._answer_error(request, ReturnCode.HAL_NO_CONNECTED, "server shutting down")
        if self._tg is not None:
            self._tg.cancel_scope.cancel()
            await self._tg.__aexit__(None, None, None)
            self._tg = None

    # -- Zenoh threads ---------------------------------------------------------------------
    def _on_query(self, kind: str) -> Any:
        inbox = self._inbox
        assert inbox is not None
        here = self._answer_here if kind == "execute" and self._gate is not None else None

        def on_query(query: zenoh.Query) -> None:
            payload = query.payload
            attachment = query.attachment
            client = attachment.to_bytes().decode("utf-8", "replace") if attachment else ANONYMOUS
            request = _Request(
                kind,
                client,
                payload.to_bytes() if payload else b"",
                query,
                received=time.monotonic(),
            )
            if kind == "execute":
                parameters = query.parameters
                if not parameters.is_empty():
                    request.sent, request.ttl = freshness(parameters)
            if here is not None:
                try:
                    if here(request):
                        return
                except Exception:  # a bug: the loop path still answers the query
                    log.exception("read_on_zenoh_thread_failed", client=client)
            inbox.put(request)

        return on_query

    def _answer_here(self, request: _Request) -> bool:
        """Answer a plain read on this (Zenoh's) thread if the loop is parked in ``select``
        (its gate taken: no loop callback or task runs meanwhile, see gate.py); False:
        nothing done (the loop path answers). Once the read ran this returns True whatever
        fails afterwards: a read is run, counted and answered once."""
        gate = self._gate
        loop = self._loop
        assert gate is not None and loop is not None
        if len(request.payload) > THREAD_READ_MAX_BYTES or is_xml(request.payload):
            return False  # XML is parsed on the loop only
        try:  # outside the gate: decoding touches nothing shared
            device = self._decoded(request)
        except Exception:  # the loop path answers and logs it
            return False
        if len(device.commands) != 1 or device.commands[0].function_name not in THREAD_READS:
            return False
        if not gate.try_enter():
            return False
        outcome: Device | tuple[ReturnCode, str] | None = None
        wake = True
        try:
            before = work_marker(loop)
            outcome = self._read_in_gate(request, device, loop)
            wake = needs_wake(loop, before)
        except Exception:
            if outcome is None:
                raise  # nothing ran: the loop path answers
            log.exception("read_on_zenoh_thread_failed", client=request.client)
        finally:
            gate.leave()
        if outcome is not None:
            self._answer_read(request, outcome)
        if wake:  # the read scheduled work on the loop (an observer...): run it now
            with contextlib.suppress(RuntimeError):  # a closed loop
                loop.call_soon_threadsafe(_nothing)
        return outcome is not None

    def _read_in_gate(
        self, request: _Request, device: Device, loop: asyncio.AbstractEventLoop
    ) -> Device | tuple[ReturnCode, str] | None:
        """The result of ``device`` (one THREAD_READS command) or its failure, run as a
        loop callback would run it (the loop set as this thread's running loop) and
        counted; None: nothing ran, because the client has earlier requests pending (they
        are answered first), the read would block, or the loop is in debug mode now
        (asyncio then refuses its non-thread-safe methods off the loop's thread)."""
        inbox = self._inbox
        if self._tg is None or inbox is None or len(inbox) or loop.get_debug():
            return None
        client = self.clients.get(request.client)
        if client is None or client.busy or client.queue:
            return None
        client.last_active = loop.time()  # the gate is held: the loop is not running
        if self._stale(client, request):
            self.served += 1
            self.refused_stale += 1
            log.warning("stale_command_refused", client=request.client, kind=request.kind)
            return ReturnCode.HAL_NO_CONNECTED, self._stale_message(request)
        enter_as_loop(loop)
        try:
            done = self.surface.execute_nowait(device, client.link)
        except WouldBlockError:
            return None
        except Exception as exc:  # execute_nowait answers refusals itself: a bug
            log.exception("request_failed", kind=request.kind, client=request.client)
            self.served += 1
            code, message = _result_code(exc)
            return ReturnCode(code), message
        finally:
            exit_loop()
        self.served += 1
        self.served_on_zenoh_thread += 1
        return done

    def _answer_read(self, request: _Request, outcome: Device | tuple[ReturnCode, str]) -> None:
        """Reply to a read that ran on Zenoh's thread (already counted); never raises: a
        failure to encode becomes an error reply, a failure to reply is logged."""
        try:
            if isinstance(outcome, Device):
                try:
                    payload = self._encoded(request, outcome)
                except Exception as exc:
                    log.exception("reply_encoding_failed", kind=request.kind, client=request.client)
                    outcome = (ReturnCode.HAL_ERROR, repr(exc))
            if not isinstance(outcome, Device):
                payload = self._execute_failure(request.payload, *outcome)
            self._reply(request, payload)
        except Exception:
            log.exception("reply_failed", kind=request.kind, client=request.client)
            with contextlib.suppress(Exception):
                _drop(request.query)

    def _on_client_alive(self, sample: zenoh.Sample) -> None:
        assert self._alive is not None
        client = self.keys.client_of_alive_key(str(sample.key_expr))
        self._alive.put((client, sample.kind == zenoh.SampleKind.PUT))

    def _refuse_dropped(self, request: _Request) -> None:
        self.refused_busy += 1
        self._answer_error(request, ReturnCode.HAL_NO_MEMORY, "server busy: request dropped")

    # -- the event loop ------------------------------------------------------------------------
    def _client(self, name: str) -> _Client:
        """The state of client ``name``, made on its first query or token (displacing the
        least recently active idle client without a token when every slot is taken);
        _TooManyClientsError when no slot can be freed."""
        now = self._now()
        client = self.clients.get(name)
        if client is None:
            if len(self.clients) >= self.max_clients:
                self._displace()
            client = self.clients[name] = _Client(name)
            if name != ANONYMOUS:
                try:
                    client.link = ClientLink(self, name)
                    self.surface.attach(client.link)
                except (BadParameterError, zenoh.ZError) as exc:
                    log.warning("client_link_failed", client=name, error=str(exc))
        client.last_active = now
        return client

    def _now(self) -> float:
        return self._loop.time() if self._loop is not None else 0.0

    def _displace(self) -> None:
        idle = [c for c in self.clients.values() if not c.alive and c.idle()]
        if not idle:
            self.refused_clients += 1
            if self.refused_clients == 1 or self.refused_clients % 1000 == 0:
                log.warning(
                    "clients_full", max_clients=self.max_clients, refused=self.refused_clients
                )
            raise _TooManyClientsError
        self._forget(min(idle, key=lambda c: c.last_active))

    def _forget(self, client: _Client) -> None:
        """Drop a client's state: its notice publisher, its subscriptions, its queue."""
        self.clients.pop(client.name, None)
        if client.link is not None:
            client.link.close()
            self.surface.detach(client.link)
        for request in client.queue:
            _drop(request.query)
        client.queue.clear()
        if not client.alive:
            self.forgotten_clients += 1

    async def _expire_clients(self) -> None:
        """Forget, every half timeout, the clients without a token idle for the timeout."""
        while True:
            await anyio.sleep(self.client_idle_timeout / 2)
            deadline = self._now() - self.client_idle_timeout
            for client in list(self.clients.values()):
                if not client.alive and client.idle() and client.last_active <= deadline:
                    log.debug("client_expired", client=client.name)
                    self._forget(client)

    async def _watch_clients(self) -> None:
        assert self._alive is not None
        while True:
            for name, alive in await self._alive.wait():
                if alive:
                    try:
                        self._client(name).alive = True
                    except _TooManyClientsError:
                        log.warning("client_refused", client=name, max_clients=self.max_clients)
                        continue
                    log.info("client_joined", client=name)
                    continue
                client = self.clients.get(name)
                if client is not None:
                    log.info("client_left", client=name)
                    self._forget(client)

    def _on_requests(self, requests: list[_Request]) -> None:
        """A batch of queries, in the loop callback that received it (never suspends)."""
        answered: set[str] = set()
        for request in requests:
            try:
                try:
                    client = self._client(request.client)
                except _TooManyClientsError:
                    self._answer_error(
                        request,
                        ReturnCode.HAL_NO_MEMORY,
                        f"server full: {self.max_clients} clients known, none idle",
                    )
                    continue
                if self._stale(client, request):
                    self._refuse_stale(request)
                    continue
                if (
                    not client.busy
                    and not client.queue
                    and client.name not in answered
                    and self._serve_now(request)
                ):
                    answered.add(client.name)
                    continue
                self._enqueue(client, request)
            except Exception:  # a bug here must not lose the other queries of the batch
                log.exception("request_dispatch_failed", kind=request.kind)
                self._answer_error(request, ReturnCode.HAL_ERROR, "server error")
        if self._ready:
            self._work.set()

    def _enqueue(self, client: _Client, request: _Request) -> None:
        if len(client.queue) >= CLIENT_QUEUE:
            self.refused_busy += 1
            if self.refused_busy == 1 or self.refused_busy % 1000 == 0:
                log.warning("client_flooding", client=client.name, refused_total=self.refused_busy)
            self._answer_error(
                request,
                ReturnCode.HAL_NO_MEMORY,
                f"server busy: more than {CLIENT_QUEUE} requests queued for this client",
            )
            return
        client.queue.append(request)
        if not client.busy and len(client.queue) == 1:
            self._ready.append(client)

    async def _worker(self) -> None:
        while True:
            while not self._ready:
                await self._work.wait()
            client = self._ready.popleft()
            if not client.queue or client.busy:
                continue
            request = client.queue.popleft()
            client.busy = True
            try:
                await self._serve(request)
            finally:
                client.busy = False
                if client.queue:
                    self._ready.append(client)
                    self._work.set()

    def schedule_flush(self, link: ClientLink) -> None:
        """Publish ``link``'s notices once this event-loop turn is over (so that the
        notices of one turn go in one batch): one loop callback, no task."""
        if not self._flush_queue and self._loop is not None:
            self._loop.call_soon(self._flush)
        self._flush_queue.append(link)

    def _flush(self) -> None:
        links, self._flush_queue = self._flush_queue, []
        for link in links:
            try:
                link.flush()
            except Exception:  # a loop callback must not raise
                log.exception("notice_flush_failed", client=link.client)

    # -- requests --------------------------------------------------------------------------------
    def _reply(self, request: _Request, payload: bytes) -> None:
        try:
            request.query.reply(request.query.key_expr, payload)
        except zenoh.ZError as exc:
            log.warning("reply_failed", kind=request.kind, error=str(exc))
        finally:
            loop = self._loop
            if loop is not None and get_ident() == self.loop_thread:
                # Dropped from the loop's thread it costs tens of microseconds (in Zenoh's
                # callback 1-2): after what this turn scheduled (the command's motion)
                loop.call_soon(_drop_later, request.query)
            else:
                _drop(request.query)

    def _answer_error(self, request: _Request, code: ReturnCode, message: str) -> None:
        if request.kind == "execute":
            payload = self._execute_failure(request.payload, code, message)
        else:
            payload = wire.encoder.encode(wire.Answer(int(code), message))
        self._reply(request, payload)

    def _execute_failure(self, payload: bytes, code: ReturnCode, message: str) -> bytes:
        """A Device reply carrying the failure, in the request's encoding."""
        reply = Device(
            "unknown",
            (
                CommandMessage(
                    "execute",
                    "",
                    None,
                    ResultList(
                        (
                            Parameter(DataType.INT, "return_code", int(code)),
                            Parameter(DataType.STRING, "message", message),
                        )
                    ),
                ),
            ),
        )
        return xml_psm.to_xml(reply) if is_xml(payload) else compact.encode(reply)

    def _serve_now(self, request: _Request) -> bool:
        """Answer ``request`` without suspending if it can be; False: nothing was done."""
        try:
            if request.kind == "execute":
                device = self._decoded(request)
                client = self.clients.get(request.client)
                app = client.link if client is not None else None
                refused = self.admit(device) if self.admit is not None else None
                try:
                    done = refused or self.surface.execute_nowait(device, app)
                except WouldBlockError:
                    return False
                payload = self._encoded(request, done)
            else:
                payload = wire.encoder.encode(self._small(request))
        except Exception as exc:
            self._refused(request, exc)
            return True
        self.served += 1
        self._reply(request, payload)
        return True

    def _decoded(self, request: _Request) -> Device:
        if request.device is None:
            request.device, request.xml = self._payloads.decode(request.payload)
        return request.device

    @staticmethod
    def _encoded(request: _Request, device: Device) -> bytes:
        if request.xml:
            return xml_psm.to_xml(device, declaration=False)
        return compact.encode(device)

    def _refused(self, request: _Request, exc: Exception) -> None:
        self.served += 1
        if isinstance(exc, BadParameterError):
            self.refused_bad += 1
            log.warning(
                "request_refused", kind=request.kind, client=request.client, reason=str(exc)
            )
            self._answer_error(request, exc.code, str(exc))
            return
        log.error("request_failed", kind=request.kind, client=request.client, exc_info=exc)
        code, message = _result_code(exc)
        self._answer_error(request, ReturnCode(code), message)

    async def _serve(self, request: _Request) -> None:
        if time.monotonic() > request.deadline:  # it waited in its client's queue too long
            self._refuse_stale(request)
            return
        try:
            if request.kind == "execute":
                device = self._decoded(request)
                client = self.clients.get(request.client)
                app = client.link if client is not None else None
                refused = self.admit(device) if self.admit is not None else None
                done = refused or await self.surface.execute(device, app)
                payload = self._encoded(request, done)
            else:
                payload = wire.encoder.encode(self._small(request))
        except Exception as exc:
            self._refused(request, exc)
            return
        self.served += 1
        self._reply(request, payload)

    def _stale(self, client: _Client, request: _Request) -> bool:
        """Whether ``request`` (an execute with a send time) arrived older than its time to
        live (freshness.py); sets its ``deadline``."""
        sent = request.sent
        if sent is None or not (sent == sent and request.ttl > 0):  # none, NaN, no ttl
            return False
        request.deadline = client.baseline.deadline(request.received, sent, request.ttl)
        return request.deadline < request.received

    def _stale_message(self, request: _Request) -> str:
        late = time.monotonic() - request.deadline + request.ttl
        return (
            f"stale command: {late:.3f} s old, over its time to live of {request.ttl:.3f} s "
            "(delayed on the way or in the queue); not executed"
        )

    def _refuse_stale(self, request: _Request) -> None:
        self.refused_stale += 1
        self.served += 1
        message = self._stale_message(request)
        log.warning("stale_command_refused", client=request.client, reason=message)
        self._answer_error(request, ReturnCode.HAL_NO_CONNECTED, message)

    def _small(self, request: _Request) -> Any:
        surface = self.surface
        client = self.clients.get(request.client)
        try:
            if request.kind == "components":
                if request.payload:  # the client's protocol version
                    version = wire.protocol_decoder.decode(request.payload)
                    if version != wire.PROTOCOL_VERSION:
                        raise BadParameterError(
                            "protocol",
                            version,
                            f"protocol version {wire.PROTOCOL_VERSION} (this server's)",
                        )
                return wire.ComponentsReply(
                    wire.PROTOCOL_VERSION,
                    [
                        wire.ComponentInfo(
                            e.device_kind,
                            e.logical_id,
                            e.component.device_name,
                            str(e.component.state),
                        )
                        for e in surface.entries
                    ],
                )
            if request.kind == "subscribe":
                if client is None or client.link is None:
                    raise BadParameterError(
                        "client", request.client, "a named client (the query's attachment)"
                    )
                sub = wire.subscribe_decoder.decode(request.payload)
                sid = surface.subscribe(
                    sub.device_kind, sub.event_type, client.link, exclude=sub.exclude
                )
                return wire.Answer(0, subscribe_id=sid)
            text = (
                msgspec.msgpack.decode(request.payload, type=str)
                if request.kind != "unsubscribe"
                else None
            )
            if request.kind == "unsubscribe":
                surface.unsubscribe(msgspec.msgpack.decode(request.payload, type=int))
                return wire.Answer(0)
            if request.kind == "event_detail":
                return wire.Answer(0, detail=surface.get_event_detail(text or ""))
            return wire.Answer(0, detail=surface.get_error_detail(text or ""))
        except (msgspec.ValidationError, msgspec.DecodeError) as exc:
            raise BadParameterError(
                "payload", f"<{len(request.payload)} bytes>", f"a {request.kind} request ({exc})"
            ) from None
