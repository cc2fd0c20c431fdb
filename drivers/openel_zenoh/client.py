"""RemoteSurface: the surface layer of a server, used over Zenoh.

The same operations as :class:`openel_async.surface.Surface` (``execute``, ``subscribe``,
``unsubscribe``, ``get_event_detail``, ``get_error_detail``) as one Zenoh query each, every
query bounded by ``timeout``. The server's notices for this client arrive numbered on one
stream and are handed to the applications (``completed`` to the one that executed the
command, ``notify_event`` to the subscriber, ``notify_error`` to every attached one); a gap
in the numbering (notices dropped on the way) is logged, counted in ``missed_total`` and
reported to applications that have ``report_missed`` (as :class:`ApplicationQueue`).

A query waits for its reply in one of two ways (docs/remote.md, "Threads"). Polled: the
reply comes through a Zenoh channel (no Python on Zenoh's thread) that the loop polls
between zero-timeout passes (other tasks and I/O run between them, and each pass yields
the core and the GIL to a ready thread) for at most ``busy_wait`` seconds, so a fast
reply is seen within microseconds of its arrival, at the price of the loop thread's CPU
for that time; a reply slower than that (a miss) is awaited by a worker thread blocked
in the channel's ``recv``. Sleeping: a Zenoh callback hands the reply to the sleeping
loop with one ``call_soon_threadsafe``. After consecutive misses the next 1, 2, 4... up
to 256 queries of the same lane sleep, so replies slower than the budget (a LAN, a
device that needs I/O) cost almost no spinning; executes of asynchronous commands
(SetPosition...), which a server accepts on a slower path than it answers reads, have
a lane of their own (:class:`Backoff`); ``busy_wait=0`` always sleeps. ``busy_wait``
is in [0, 0.01] s; a hit resets its lane's backoff, so replies that steadily come within it are spun for on
every query (at 1 kHz, replies of 0.2-0.5 ms: up to about half a core); use
``busy_wait=0`` when a control loop shares the event loop or CPU matters more than latency.

Every execute carries its send time and a time to live of half the timeout (selector
parameters ``sent_us`` and ``ttl_us``, docs/wire.md "Freshness"): a command that reaches the
server later than that -- held up by a partition, retransmitted when the client may have
given up on it -- is refused there (``HAL_NO_CONNECTED``) instead of executed late.

The server's presence is followed through its liveliness token: ``on_server`` listeners
hear of it leaving and coming back; when it comes back, subscriptions are made again
(their local ids stay the same) and commands still awaiting completion end with
``HAL_NO_CONNECTED``.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import time
import uuid
from collections.abc import Callable, Collection, Iterable
from types import TracebackType
from typing import Any, Literal, Self, cast

import anyio
import anyio.abc
import msgspec
import zenoh

from openel_async.clock import run_in_thread
from openel_async.errors import BadParameterError, NotConnectedError, ReturnCode, check_code
from openel_async.logs import get_logger
from openel_async.surface import compact, xml_psm
from openel_async.surface.application import Delivery
from openel_async.surface.messages import CommandMessage, Device, ResultList
from openel_async.surface.profiles import DEFAULT_PROFILES

from . import wire
from .bridge import ThreadInbox
from .keys import Keys

log = get_logger(__name__)

DEFAULT_TIMEOUT_S = 2.0
DEFAULT_BUSY_WAIT_S = 0.0005
"""How long a query's reply is polled for before the loop sleeps (see the module doc)."""
MAX_SLEEPING_QUERIES = 256
"""After consecutive busy-wait misses, at most this many queries sleep before one polls."""
_yield_cpu: Callable[[], None] = getattr(os, "sched_yield", lambda: None)
"""Gives this core (and the GIL) to a ready thread, if any (Unix; elsewhere nothing)."""
QUERY_THREADS = 32
"""Worker threads one RemoteSurface may have blocked on replies after busy-wait misses."""
_NO_CONSOLIDATION = zenoh.ConsolidationMode.NONE
DETAILS_SIZE = 4096
Encoding = Literal["compact", "xml"]
ASYNCHRONOUS_FUNCTIONS = frozenset(
    name
    for profile in DEFAULT_PROFILES.values()
    for name, operation in profile.operations.items()
    if not operation.synchronous
)
"""The asynchronous operations of the default dispatch tables (SetPosition, SetSpeed...)."""


COMMANDS_LANE = "commands"
"""The busy-wait lane of executes of asynchronous commands only (see :class:`Backoff`)."""


class Backoff:
    """The busy-wait backoff of one lane of queries: after a miss, the next 1, 2, 4... (at
    most MAX_SLEEPING_QUERIES) queries of the lane sleep; a hit resets it. Lanes keep
    replies of different speeds apart: a server answers a read on its fast path and
    accepts a command (SetPosition) on its event loop, and misses of the slower kind
    must not make the faster one sleep."""

    __slots__ = ("sleepers_left", "sleepers_next")

    def __init__(self) -> None:
        self.sleepers_left = 0
        """Queries of this lane that will sleep before the next one polls."""
        self.sleepers_next = 1
        """How many sleep after the next miss."""


class RemoteSurface:
    """``async with RemoteSurface(session, namespace) as remote``: a server's surface layer."""

    def __init__(
        self,
        session: zenoh.Session,
        namespace: str = "default",
        *,
        timeout: float = DEFAULT_TIMEOUT_S,
        client_id: str | None = None,
        encoding: Encoding = "compact",
        asynchronous: Collection[str] = ASYNCHRONOUS_FUNCTIONS,
        busy_wait: float = DEFAULT_BUSY_WAIT_S,
    ) -> None:
        if not timeout > 0:
            raise BadParameterError("timeout", timeout, "a number of seconds > 0")
        if (
            isinstance(busy_wait, bool)
            or not isinstance(busy_wait, (int, float))
            or not 0.0 <= busy_wait <= 0.01
        ):
            raise BadParameterError("busy_wait", busy_wait, "seconds in [0, 0.01] (0: never)")
        if encoding not in ("compact", "xml"):
            raise BadParameterError("encoding", encoding, "'compact' or 'xml'")
        self.session = session
        self.keys = Keys(namespace)
        self.timeout = float(timeout)
        self.client_id = client_id or uuid.uuid4().hex
        self.keys.client_alive(self.client_id)  # checks the id
        self.encoding: Encoding = encoding
        self.busy_wait = float(busy_wait)
        """Seconds a query's reply is polled for on the loop before it sleeps (0: never)."""
        self.busy_hits = 0
        """Replies seen while busy-waiting."""
        self.busy_misses = 0
        """Busy-waits that ran out before the reply."""
        self._backoffs: dict[str, Backoff] = {}
        self.asynchronous = frozenset(asynchronous)
        """The function names whose ``completed`` follows later (the server's asynchronous
        operations); a reply to any other command expects none."""
        self._attachment = self.client_id.encode()
        self._ttl_us = max(1, int(self.timeout * 500_000))
        """An execute's time to live: half the timeout (the other half bounds the error of
        the server's age estimate and the reply's way back)."""
        self.server_alive = False
        self._was_lost = False
        self.missed_total = 0
        self._next_index = 0
        self._tg: anyio.abc.TaskGroup | None = None
        self._deliveries: dict[int, Delivery] = {}
        self._attached: dict[int, Delivery] = {}
        self._pending: dict[str, Delivery] = {}
        self._early: dict[str, ReturnCode] = {}
        self._subscriptions: dict[int, tuple[str, str, Delivery, int, list[str]]] = {}
        """local id -> (device_kind, event_type, delivery, remote id)"""
        self._by_remote: dict[int, int] = {}
        self._local_ids = iter(range(1, 1 << 62))
        self._event_details: dict[str, ResultList] = {}
        self._error_details: dict[str, ResultList] = {}
        self._listeners: list[Callable[[bool], None]] = []
        self._declared: list[Any] = []
        self._up = anyio.Event()

    # -- lifecycle -----------------------------------------------------------------------
    async def __aenter__(self) -> Self:
        self._loop = asyncio.get_running_loop()
        self._limiter = anyio.CapacityLimiter(QUERY_THREADS)
        # Notices are handled in the loop callback that receives them (no task switch).
        self._notices: ThreadInbox[bytes] = ThreadInbox(65536, drain=self._on_notice_batches)
        self._presence: ThreadInbox[bool] = ThreadInbox(64)
        tg = anyio.create_task_group()
        await tg.__aenter__()
        self._tg = tg
        try:
            self._declared.append(
                self.session.declare_subscriber(
                    self.keys.notices(self.client_id),
                    zenoh.handlers.Callback(self._on_notices, indirect=False),
                )
            )
            self._declared.append(
                self.session.liveliness().declare_subscriber(
                    self.keys.server_alive,
                    zenoh.handlers.Callback(self._on_presence, indirect=False),
                    history=True,
                )
            )
            self._declared.append(
                self.session.liveliness().declare_token(self.keys.client_alive(self.client_id))
            )
            tg.start_soon(self._follow_server)
        except BaseException:
            await self._close()
            raise
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self._close()

    async def _close(self) -> None:
        for entity in reversed(self._declared):
            with contextlib.suppress(zenoh.ZError):
                cast(Any, entity).undeclare()
        self._declared.clear()
        if self._tg is not None:
            self._tg.cancel_scope.cancel()
            await self._tg.__aexit__(None, None, None)
            self._tg = None

    async def wait_server(self, timeout: float | None = None) -> None:  # noqa: ASYNC109
        """Wait until the server's liveliness token is seen (TimeoutError after ``timeout``)."""
        with anyio.fail_after(self.timeout if timeout is None else timeout):
            while not self.server_alive:
                await self._up.wait()

    @property
    def awaiting_completion(self) -> int:
        """Asynchronous commands whose ``completed`` has not arrived yet."""
        return len(self._pending)

    def on_server(self, listener: Callable[[bool], None]) -> Callable[[], None]:
        """Call ``listener(alive)`` when the server leaves (False) or comes back (True)."""
        self._listeners.append(listener)
        return lambda: self._listeners.remove(listener) if listener in self._listeners else None

    # -- Zenoh threads -----------------------------------------------------------------
    def _on_notices(self, sample: zenoh.Sample) -> None:
        self._notices.put(sample.payload.to_bytes())

    def _on_presence(self, sample: zenoh.Sample) -> None:
        self._presence.put(sample.kind == zenoh.SampleKind.PUT)

    # -- queries -------------------------------------------------------------------------
    async def query(
        self, key: str, payload: bytes, parameters: str = "", *, lane: str = ""
    ) -> bytes:
        """One Zenoh query, its first reply's payload; TimeoutError/NotConnectedError.
        ``parameters``: the selector's (``sent_us=...;ttl_us=...``), none by default.
        ``lane``: which replies' busy-wait misses make this one sleep (see :class:`Backoff`;
        execute() puts asynchronous commands in a lane of their own).

        Polled (the reply through a Zenoh channel, for at most ``busy_wait`` s; a miss
        then awaited by a worker thread blocked in the channel's ``recv``) unless
        ``busy_wait`` is 0 or recent misses say the replies are slower than that; else
        sleeping (a Zenoh callback hands the reply to the loop). Zenoh's own timeout ends
        the query; ``timeout + 1`` s bounds the wait even if it never does.
        """
        if self.busy_wait > 0.0:
            backoff = self._backoffs.get(lane)
            if backoff is None:
                backoff = self._backoffs[lane] = Backoff()
            if backoff.sleepers_left == 0:
                return await self._query_polled(key, payload, parameters, backoff)
            backoff.sleepers_left -= 1
        return await self._query_sleeping(key, payload, parameters)

    @staticmethod
    def _reply_value(key: str, reply: zenoh.Reply) -> bytes | BaseException:
        ok = reply.ok
        if ok is not None:
            return ok.payload.to_bytes()
        err = reply.err
        text = err.payload.to_string() if err is not None else "error reply"
        return NotConnectedError(f"{key}: {text}")

    async def _query_polled(
        self, key: str, payload: bytes, parameters: str, backoff: Backoff
    ) -> bytes:
        replies = self.session.get(
            f"{key}?{parameters}" if parameters else key,
            payload=payload,
            attachment=self._attachment,
            timeout=self.timeout,
            consolidation=_NO_CONSOLIDATION,
        )
        try:
            reply = await self._poll(replies, backoff)
            if reply is None:  # a miss: a worker thread waits (recv releases the GIL)
                with anyio.move_on_after(self.timeout + 1.0):
                    reply = await anyio.to_thread.run_sync(
                        replies.recv, abandon_on_cancel=True, limiter=self._limiter
                    )
        except zenoh.ZError:  # the channel is empty and closed: the query ended unanswered
            raise TimeoutError(f"{key}: no reply within {self.timeout} s") from None
        if reply is None:
            raise TimeoutError(f"{key}: no reply and no end of query within {self.timeout + 1.0} s")
        value = self._reply_value(key, reply)
        if isinstance(value, BaseException):
            raise value
        return value

    async def _query_sleeping(self, key: str, payload: bytes, parameters: str = "") -> bytes:
        """The reply (or, without one, the end of the query) handed to the sleeping loop
        with one ``call_soon_threadsafe`` from Zenoh's callback; a loop timer
        ``timeout + 1`` s later bounds the wait even if Zenoh never calls back."""
        loop = self._loop
        future: asyncio.Future[bytes | BaseException] = loop.create_future()
        replied = False

        def settle(value: bytes | BaseException) -> None:
            if not future.done():
                future.set_result(value)

        def on_reply(reply: zenoh.Reply) -> None:
            nonlocal replied
            if replied:
                return
            replied = True
            value = self._reply_value(key, reply)
            with contextlib.suppress(RuntimeError):  # a closed loop: nobody waits
                loop.call_soon_threadsafe(settle, value)

        def on_done() -> None:
            if replied:  # the reply is on its way to the loop
                return
            with contextlib.suppress(RuntimeError):
                loop.call_soon_threadsafe(
                    settle, TimeoutError(f"{key}: no reply within {self.timeout} s")
                )

        self.session.get(
            f"{key}?{parameters}" if parameters else key,
            zenoh.handlers.Callback(on_reply, on_done, indirect=False),
            payload=payload,
            attachment=self._attachment,
            timeout=self.timeout,
            consolidation=_NO_CONSOLIDATION,
        )
        guard = loop.call_later(
            self.timeout + 1.0,
            settle,
            TimeoutError(f"{key}: no reply and no end of query within {self.timeout + 1.0} s"),
        )
        try:
            result = await future
        finally:
            guard.cancel()
        if isinstance(result, BaseException):
            raise result
        return result

    async def _poll(
        self, replies: zenoh.handlers.Handler[zenoh.Reply], backoff: Backoff
    ) -> zenoh.Reply | None:
        """The reply if it comes within ``busy_wait`` s, polled between zero-timeout passes
        of the loop (other tasks and I/O run between them); None: a miss, after which the
        next 1, 2, 4... (at most MAX_SLEEPING_QUERIES) queries of its lane sleep instead."""
        clock = time.perf_counter
        spin_until = clock() + self.busy_wait
        try_recv = replies.try_recv
        yield_cpu = _yield_cpu
        # Polling is the point: the reply channel has no loop-side wake-up.
        while (reply := try_recv()) is None and clock() < spin_until:
            yield_cpu()  # a thread ready on this core (Zenoh's, with the reply) runs first
            if (reply := try_recv()) is not None:  # it often came while this thread yielded:
                break  # seen now rather than after a loop pass
            await asyncio.sleep(0)
        if reply is not None:
            self.busy_hits += 1
            backoff.sleepers_next = 1
            return reply
        self.busy_misses += 1
        backoff.sleepers_left = backoff.sleepers_next
        backoff.sleepers_next = min(2 * backoff.sleepers_next, MAX_SLEEPING_QUERIES)
        return None

    def _delivery(self, application: object) -> Delivery:
        found = self._deliveries.get(id(application))
        if found is None:
            if self._tg is None:
                raise BadParameterError("RemoteSurface", "closed", "inside 'async with'")
            found = self._deliveries[id(application)] = Delivery(application, self._tg)
        return found

    async def execute(
        self, device: Device, application: object | None = None, *, encoding: Encoding | None = None
    ) -> Device:
        """execute(): the Device message with results; ``application`` gets ``completed``
        for its asynchronous commands (those named in ``asynchronous``)."""
        encoding = encoding or self.encoding
        if encoding == "xml":
            delivery = self._delivery(application) if application is not None else None
            reply = xml_psm.device_from_xml(
                await self.query(
                    self.keys.execute,
                    xml_psm.to_xml(device, declaration=False),
                    self.execute_parameters(),
                    lane=self.lane_of(device),
                )
            )
            self._expect_completions(reply, delivery)
            return reply
        return await self.execute_compact(
            compact.encode(device), application, lane=self.lane_of(device)
        )

    def lane_of(self, device: Device) -> str:
        """The busy-wait lane of an execute: ``commands`` when every command of it is
        asynchronous (a server answers those on a slower path than reads), else the
        default lane."""
        for command in device.commands:
            if command.function_name not in self.asynchronous:
                return ""
        return COMMANDS_LANE

    async def execute_compact(
        self, payload: bytes, application: object | None = None, *, lane: str = ""
    ) -> Device:
        """execute() of a Device message already in the compact encoding (a caller that
        sends the same message often encodes it once); the reply is decoded and checked.
        ``lane``: see :meth:`query` (:meth:`lane_of` tells a Device's)."""
        delivery = self._delivery(application) if application is not None else None
        reply = compact.device_from_compact(
            await self.query(self.keys.execute, payload, self.execute_parameters(), lane=lane)
        )
        self._expect_completions(reply, delivery)
        return reply

    def execute_parameters(self) -> str:
        """An execute's selector parameters: its send time and time to live (docs/wire.md)."""
        return f"sent_us={time.monotonic_ns() // 1000};ttl_us={self._ttl_us}"

    def _expect_completions(self, reply: Device, delivery: Delivery | None) -> None:
        """Route the coming ``completed`` of each accepted asynchronous command."""
        if delivery is None:
            return
        for command in reply.commands:
            if command.function_name not in self.asynchronous:
                continue
            results = command.results
            if results is None or not results.parameters:
                continue
            head = results.parameters[0]
            if head.name != "return_code" or head.value != 0:
                continue
            early = self._early.pop(command.command_id, None)
            if early is not None:
                delivery.call("completed", command.command_id, early)
            else:
                self._pending[command.command_id] = delivery

    async def execute_command(
        self, device_kind: str, command: CommandMessage, application: object | None = None
    ) -> CommandMessage:
        reply = await self.execute(Device(device_kind, (command,)), application)
        return reply.commands[0]

    async def components(self) -> list[wire.ComponentInfo]:
        """The served components. The query carries this client's protocol version: a server
        that speaks another refuses it (BadParameterError naming both versions)."""
        payload = await self.query(self.keys.components, wire.encoder.encode(wire.PROTOCOL_VERSION))
        try:
            reply = wire.components_decoder.decode(payload)
        except (msgspec.ValidationError, msgspec.DecodeError):
            answer = wire.answer_decoder.decode(payload)  # a refusal
            check_code(answer.return_code, answer.message)
            raise
        return reply.components

    async def estop_rig(self, release: bool = False) -> wire.EstopReply:
        """E-stop every component of the served rig at once (``release=True``: release the
        e-stop, so that ``re_init`` recovers them): one query (``openel-async serve`` only;
        openel_zenoh.estop). The reply's return_code is not checked: nonzero means some
        component failed (every one was tried); ``components`` says how each was left."""
        key = self.keys.rig_estop_release if release else self.keys.rig_estop
        return wire.estop_decoder.decode(await self.query(key, b""))

    async def lifecycle(self, action: str, names: list[str] | None = None) -> wire.LifecycleReply:
        """The RTC lifecycle of the served components (``openel-async serve`` only;
        openel_zenoh.lifecycle): ``get`` their states, ``activate``, ``deactivate`` or
        ``reset`` those named. The reply's return_code is not checked."""
        payload = wire.encoder.encode(wire.LifecycleRequest(action, list(names or [])))
        return wire.lifecycle_decoder.decode(await self.query(self.keys.rig_lifecycle, payload))

    async def conf(self, request: wire.ConfRequest) -> wire.ConfReply:
        """Read or set a served component's configuration (``openel-async serve`` only).
        The reply's return_code is not checked."""
        payload = wire.encoder.encode(request)
        return wire.conf_decoder.decode(await self.query(self.keys.rig_conf, payload))

    async def _answer(self, key: str, payload: bytes) -> wire.Answer:
        answer = wire.answer_decoder.decode(await self.query(key, payload))
        check_code(answer.return_code, answer.message)
        return answer

    async def subscribe(
        self,
        device_kind: str,
        event_type: str,
        application: object,
        *,
        exclude: Iterable[str] = (),
    ) -> int:
        """Surface.subscribe on the server: events ``event_type`` ('*': all) of a device
        kind but those of ``exclude``. A server that predates ``exclude`` sends those too:
        an application that excludes a type should still ignore it."""
        delivery = self._delivery(application)
        excluded = sorted(exclude)
        answer = await self._answer(
            self.keys.subscribe,
            wire.subscribe_payload(device_kind, event_type, excluded),
        )
        local = next(self._local_ids)
        self._subscriptions[local] = (
            device_kind,
            event_type,
            delivery,
            answer.subscribe_id,
            excluded,
        )
        self._by_remote[answer.subscribe_id] = local
        return local

    async def unsubscribe(self, subscribe_id: int) -> None:
        found = self._subscriptions.pop(subscribe_id, None)
        if found is None:
            raise BadParameterError(
                "subscribe_id", subscribe_id, f"one of {sorted(self._subscriptions)}"
            )
        self._by_remote.pop(found[3], None)
        if self.server_alive:
            await self._answer(self.keys.unsubscribe, wire.encoder.encode(found[3]))

    def attach(self, application: object) -> None:
        """``application`` gets notify_error for every component of the server."""
        delivery = self._delivery(application)
        self._attached[id(application)] = delivery

    def detach(self, application: object) -> None:
        self._attached.pop(id(application), None)

    async def get_event_detail(self, event_id: str) -> ResultList:
        found = self._event_details.get(event_id)
        if found is not None:
            return found
        answer = await self._answer(self.keys.event_detail, wire.encoder.encode(event_id))
        assert answer.detail is not None
        return answer.detail

    async def get_error_detail(self, error_id: str) -> ResultList:
        found = self._error_details.get(error_id)
        if found is not None:
            return found
        answer = await self._answer(self.keys.error_detail, wire.encoder.encode(error_id))
        assert answer.detail is not None
        return answer.detail

    def cached_event_detail(self, event_id: str) -> ResultList | None:
        return self._event_details.get(event_id)

    def cached_error_detail(self, error_id: str) -> ResultList | None:
        return self._error_details.get(error_id)

    # -- notices ---------------------------------------------------------------------------
    @staticmethod
    def _remember(table: dict[str, ResultList], key: str, detail: ResultList) -> None:
        table[key] = detail
        if len(table) > DETAILS_SIZE:
            del table[next(iter(table))]

    def _report_missed(self, count: int) -> None:
        self.missed_total += count
        log.warning(
            "notices_missed", client=self.client_id, missed=count, missed_total=self.missed_total
        )
        seen: set[int] = set()
        for delivery in [
            *self._attached.values(),
            *(s[2] for s in self._subscriptions.values()),
            *self._pending.values(),
        ]:
            if id(delivery) in seen:
                continue
            seen.add(id(delivery))
            report = getattr(delivery.application, "report_missed", None)
            if callable(report):
                report(count)

    def _on_notice_batches(self, payloads: list[bytes]) -> None:
        if self._tg is None:  # closed
            return
        for payload in payloads:
            try:
                batch = wire.batch_decoder.decode(payload)
            except (msgspec.ValidationError, msgspec.DecodeError) as exc:
                log.warning("bad_notice_batch", error=str(exc))
                continue
            if batch.first_index < self._next_index:
                self._next_index = batch.first_index  # a restarted server numbers from 0
            gap = batch.first_index - self._next_index
            if gap > 0:
                self._report_missed(gap)
            self._next_index = batch.first_index + len(batch.notices)
            for notice in batch.notices:
                try:
                    self._deliver(notice)
                except Exception:  # one bad notice must not lose the rest of the batch
                    log.exception("notice_delivery_failed")

    def _deliver(self, notice: wire.Notice) -> None:
        if isinstance(notice, wire.CompletedNotice):
            status = (
                ReturnCode(notice.status)
                if notice.status in ReturnCode._value2member_map_
                else ReturnCode.HAL_ERROR
            )
            delivery = self._pending.pop(notice.command_id, None)
            if delivery is None:
                self._early[notice.command_id] = status
                if len(self._early) > DETAILS_SIZE:
                    del self._early[next(iter(self._early))]
                return
            delivery.call("completed", notice.command_id, status)
        elif isinstance(notice, wire.EventNotice):
            self._remember(self._event_details, notice.event_id, notice.detail)
            local = self._by_remote.get(notice.subscribe_id)
            if local is None:
                return
            subscription = self._subscriptions[local]
            subscription[2].call("notify_event", notice.event_id, notice.event_type, local)
        else:
            self._remember(self._error_details, notice.error_id, notice.detail)
            for delivery in tuple(self._attached.values()):
                delivery.call("notify_error", notice.error_id, notice.error_type)

    # -- server presence -----------------------------------------------------------------
    async def _follow_server(self) -> None:
        while True:
            for alive in await self._presence.wait():
                if alive == self.server_alive:
                    continue
                self.server_alive = alive
                log.info("server_presence", namespace=self.keys.namespace, alive=alive)
                if alive:
                    self._next_index = 0
                    if self._was_lost:
                        await self._resubscribe()
                    self._up.set()
                    self._up = anyio.Event()
                else:
                    self._was_lost = True
                    pending, self._pending = self._pending, {}
                    for command_id, delivery in pending.items():
                        delivery.call("completed", command_id, ReturnCode.HAL_NO_CONNECTED)
                for listener in tuple(self._listeners):
                    try:
                        listener(alive)
                    except Exception:
                        log.exception("server_listener_failed")

    async def _resubscribe(self) -> None:
        self._by_remote.clear()
        for local, (kind, event_type, delivery, _, excluded) in list(self._subscriptions.items()):
            try:
                answer = await self._answer(
                    self.keys.subscribe,
                    wire.subscribe_payload(kind, event_type, excluded),
                )
            except Exception as exc:
                log.warning(
                    "resubscribe_failed", device_kind=kind, event_type=event_type, error=str(exc)
                )
                continue
            self._subscriptions[local] = (kind, event_type, delivery, answer.subscribe_id, excluded)
            self._by_remote[answer.subscribe_id] = local


async def open_session(config: zenoh.Config) -> zenoh.Session:
    """``zenoh.open`` off the event loop (it connects and may wait)."""
    return await run_in_thread(zenoh.open, config)


async def close_session(session: zenoh.Session) -> None:
    await run_in_thread(session.close)
