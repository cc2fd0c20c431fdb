"""The e-stop of a served rig over Zenoh (``openel-async estop``).

``openel-async serve`` declares two queryables beside the surface layer's (docs/remote.md,
"E-stop"):

| key expression                     | what                                                  |
|------------------------------------|-------------------------------------------------------|
| ``openel/<ns>/rig/estop``           | e-stop every component of the rig at once             |
| ``openel/<ns>/rig/estop/release``   | release it: ``re_init`` recovers the components again |

A query (its payload is ignored) is moved into the event loop like every query of the
server (a bounded inbox, one ``call_soon_threadsafe`` per batch), where one task runs
:meth:`Rig.estop <openel_async.rig.Rig.estop>` (every component concurrently, each one in
its protocol's emergency state, in Error with ``ErrorId.ESTOP`` and latched) or
:meth:`Rig.release_estop <openel_async.rig.Rig.release_estop>`, then replies with a
:class:`~openel_zenoh.wire.EstopReply`: the return code and the state of every component
after it. E-stop queries that arrive together are answered by one e-stop.

:class:`RigEstopServer` serves them; :func:`estop_rig` (a session of its own) and
:meth:`RemoteSurface.estop_rig <openel_zenoh.client.RemoteSurface.estop_rig>` send them.
"""

from __future__ import annotations

import asyncio
import contextlib
from typing import TYPE_CHECKING, Any, cast

import anyio
import anyio.abc
import zenoh

from openel_async.component import ComponentState, HALComponent
from openel_async.errors import BadParameterError, HALError, NotConnectedError, ReturnCode
from openel_async.logs import get_logger

from . import wire
from .bridge import ThreadInbox
from .keys import Keys
from .rigservice import RigQueryService, reply

if TYPE_CHECKING:
    from openel_async.rig import Rig

log = get_logger(__name__)

DEFAULT_TIMEOUT_S = 5.0
"""How long :func:`estop_rig` waits for the server, then for its reply (a rig's e-stop
is bounded by its ``safety.exit_timeout``, 2 s by default)."""
INBOX_SIZE = 1024


def component_state(component: HALComponent) -> wire.RigComponentState:
    fault = component.last_fault
    error_id = (
        fault.error_id if fault is not None and component.state is ComponentState.ERROR else 0
    )
    return wire.RigComponentState(
        component.device_name, str(component.state), int(error_id), component.estop_latched
    )


class RigEstopServer(RigQueryService[bool]):
    """Serve the e-stop of ``rig`` on ``session`` under ``openel/<namespace>/rig/``
    (``async with``; enter it before the SurfaceServer, whose liveliness token tells
    clients that the server is up). A query's kind: whether it asks for the release."""

    inbox_size = INBOX_SIZE

    def __init__(self, rig: Rig, session: zenoh.Session, namespace: str = "default") -> None:
        super().__init__(session)
        self.rig = rig
        self.keys = Keys(namespace)
        self.estops = 0
        """E-stops run on request (coalesced queries count once)."""
        self.releases = 0

    def queryables(self) -> list[tuple[str, bool]]:
        return [(self.keys.rig_estop, False), (self.keys.rig_estop_release, True)]

    def refuse(self, kind: bool, query: zenoh.Query, code: ReturnCode, text: str) -> None:
        """An error reply without the components' states (any thread: touches no component)."""
        reply(query, wire.encoder.encode(wire.EstopReply(int(code), text, kind, [])))

    # -- the event loop --------------------------------------------------------------------
    async def serve(self, inbox: ThreadInbox[tuple[bool, zenoh.Query]]) -> None:
        while True:
            batch = await inbox.wait()
            while batch:  # consecutive queries of one kind: one e-stop (release) answers them
                release = batch[0][0]
                count = 1
                while count < len(batch) and batch[count][0] == release:
                    count += 1
                run, batch = batch[:count], batch[count:]
                await self._answer(release, [query for _, query in run])

    async def _answer(self, release: bool, queries: list[zenoh.Query]) -> None:
        code, message = 0, ""
        try:
            if release:
                log.warning("rig_estop_release_requested", queries=len(queries))
                self.releases += 1
                self.rig.release_estop()
            else:
                log.warning("rig_estop_requested", queries=len(queries))
                self.estops += 1
                await self.rig.estop()  # shielded and bounded: it ends even when cancelled
        except HALError as exc:
            code, message = int(exc.code), str(exc)
        except Exception as exc:  # a bug: the clients still get an answer
            log.exception("rig_estop_failed", release=release)
            code, message = int(ReturnCode.HAL_ERROR), repr(exc)
        states = [component_state(c) for c in self.rig.components.values()]
        payload = wire.encoder.encode(wire.EstopReply(code, message, release, states))
        for query in queries:
            reply(query, payload)


# -- client ------------------------------------------------------------------------------------


async def wait_server(session: zenoh.Session, keys: Keys, timeout: float) -> None:  # noqa: ASYNC109
    """Wait until the server's liveliness token is seen; TimeoutError after ``timeout`` s."""
    loop = asyncio.get_running_loop()
    seen = anyio.Event()

    def on_sample(sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.PUT:
            with contextlib.suppress(RuntimeError):  # a closed loop: nobody waits
                loop.call_soon_threadsafe(seen.set)

    subscriber = session.liveliness().declare_subscriber(
        keys.server_alive, zenoh.handlers.Callback(on_sample, indirect=False), history=True
    )
    try:
        with anyio.move_on_after(timeout):
            await seen.wait()
    finally:
        with contextlib.suppress(zenoh.ZError):
            cast(Any, subscriber).undeclare()
    if not seen.is_set():
        raise TimeoutError(f"no server within {timeout} s")


async def query_estop(
    session: zenoh.Session,
    keys: Keys,
    *,
    release: bool = False,
    timeout: float = DEFAULT_TIMEOUT_S,  # noqa: ASYNC109
    attachment: bytes | None = None,
) -> wire.EstopReply:
    """One ``rig/estop`` (``rig/estop/release``) query, its reply; TimeoutError without one
    within ``timeout`` s (a server that serves no rig e-stop never answers)."""
    key = keys.rig_estop_release if release else keys.rig_estop
    loop = asyncio.get_running_loop()
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
        ok = reply.ok
        if ok is not None:
            value: bytes | BaseException = ok.payload.to_bytes()
        else:
            err = reply.err
            value = NotConnectedError(
                f"{key}: {err.payload.to_string() if err is not None else 'error reply'}"
            )
        with contextlib.suppress(RuntimeError):
            loop.call_soon_threadsafe(settle, value)

    def on_done() -> None:
        if not replied:
            with contextlib.suppress(RuntimeError):
                loop.call_soon_threadsafe(
                    settle, TimeoutError(f"{key}: no reply within {timeout} s")
                )

    session.get(
        key,
        zenoh.handlers.Callback(on_reply, on_done, indirect=False),
        payload=b"",
        attachment=attachment,
        timeout=timeout,
        consolidation=zenoh.ConsolidationMode.NONE,
    )
    with anyio.move_on_after(timeout + 1.0):  # even if Zenoh never ends the query
        result = await future
    if not future.done():
        raise TimeoutError(f"{key}: no reply and no end of query within {timeout + 1.0} s")
    if isinstance(result, BaseException):
        raise result
    return wire.estop_decoder.decode(result)


async def estop_rig(
    session: zenoh.Session,
    namespace: str = "default",
    *,
    release: bool = False,
    timeout: float = DEFAULT_TIMEOUT_S,  # noqa: ASYNC109
) -> wire.EstopReply:
    """E-stop (``release=True``: release) the rig served in ``namespace``: waits up to
    ``timeout`` s for the server's liveliness token, then up to ``timeout`` s for the reply
    of one query. The reply's ``return_code`` is not checked: nonzero means some component
    failed (every one was tried; ``components`` says how each was left). TimeoutError: no
    server, or it did not answer."""
    if isinstance(timeout, bool) or not isinstance(timeout, int | float) or not timeout > 0:
        raise BadParameterError("timeout", timeout, "a number of seconds > 0")
    keys = Keys(namespace)
    await wait_server(session, keys, timeout)
    return await query_estop(session, keys, release=release, timeout=timeout)


def describe(state: wire.RigComponentState, release: bool = False) -> str:
    """One line for a component: ``MOTOR_1 Error (e-stop, error 8)``."""
    notes: list[str] = []
    if state.latched:
        notes.append("e-stop")
    elif release and state.state == ComponentState.ERROR.value:
        notes.append("released")
    if state.error_id:
        notes.append(f"error {state.error_id}")
    if state.latched and state.state != ComponentState.ERROR.value:
        notes.append("not in Error")
    return f"{state.name} {state.state}" + (f" ({', '.join(notes)})" if notes else "")
