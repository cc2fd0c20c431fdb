"""The lifecycle and configuration of a served rig over Zenoh (``openel-async serve``;
docs/remote.md, "Lifecycle and configuration"; the model is openel_zenoh.lifecycle).

| key expression                  | payload                                  | reply             |
|---------------------------------|------------------------------------------|-------------------|
| ``openel/<ns>/rig/lifecycle``    | :class:`~openel_zenoh.wire.LifecycleRequest` | ``LifecycleReply`` |
| ``openel/<ns>/rig/conf``         | :class:`~openel_zenoh.wire.ConfRequest`      | ``ConfReply``      |

Queries are moved into the event loop through a bounded inbox (one ``call_soon_threadsafe``
per batch) and handled one at a time, in order, by one task: an activation, deactivation
or reset is bounded (``lifecycle.CALL_TIMEOUT_S`` per device call). Enter
:class:`RigLifecycleServer` before the SurfaceServer (whose liveliness token tells clients
that the server is up) and give the SurfaceServer its ``lifecycle.admit``.
"""

from __future__ import annotations

import contextlib
from types import TracebackType
from typing import Any, Self, cast

import anyio
import anyio.abc
import msgspec
import zenoh

from openel_async.errors import HALError, ReturnCode
from openel_async.logs import get_logger
from openel_async.rtc.configuration import ConfigurationError
from openel_async.surface import Surface

from . import wire
from .bridge import ThreadInbox
from .keys import Keys
from .lifecycle import Hosted, ServedLifecycle

log = get_logger(__name__)

INBOX_SIZE = 256
ACTIONS = ("get", "activate", "deactivate", "reset")


def _reply(query: zenoh.Query, payload: bytes) -> None:
    try:
        query.reply(query.key_expr, payload)
    except zenoh.ZError as exc:
        log.warning("lifecycle_reply_failed", error=str(exc))
    finally:
        cast(Any, query).drop()


def lifecycle_component(hosted: Hosted) -> wire.LifecycleComponent:
    component = hosted.component
    return wire.LifecycleComponent(
        hosted.name, str(hosted.state), str(component.state), component.estop_latched
    )


def conf_reply(
    hosted: Hosted, code: int = 0, message: str = "", constraint: str = ""
) -> wire.ConfReply:
    configuration = hosted.configuration
    return wire.ConfReply(
        code,
        message,
        hosted.name,
        [
            wire.ConfParameter(p.name, p.type, p.constraint_text or "", p.unit or "")
            for p in configuration.parameters.values()
        ],
        configuration.active_set,
        [wire.ConfSet(s, configuration.texts(s)) for s in configuration.set_names],
        constraint,
    )


class RigLifecycleServer:
    """Serve the lifecycle and configuration of ``surface``'s components on ``session``
    under ``openel/<namespace>/rig/`` (``async with``); :attr:`lifecycle` is the model."""

    def __init__(
        self, surface: Surface, session: zenoh.Session, namespace: str = "default"
    ) -> None:
        self.lifecycle = ServedLifecycle(surface)
        self.session = session
        self.keys = Keys(namespace)
        self._declared: list[Any] = []
        self._inbox: ThreadInbox[tuple[str, zenoh.Query]] | None = None
        self._tg: anyio.abc.TaskGroup | None = None

    async def __aenter__(self) -> Self:
        inbox = self._inbox = ThreadInbox(INBOX_SIZE, on_drop=self._refuse_dropped)
        tg = anyio.create_task_group()
        await tg.__aenter__()
        self._tg = tg
        try:
            for kind, key in (("lifecycle", self.keys.rig_lifecycle), ("conf", self.keys.rig_conf)):
                self._declared.append(
                    self.session.declare_queryable(
                        key,
                        zenoh.handlers.Callback(self._on_query(inbox, kind), indirect=False),
                        complete=True,
                    )
                )
            tg.start_soon(self._worker, inbox)
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
        self.lifecycle.close()
        for entity in self._declared:
            with contextlib.suppress(zenoh.ZError):
                cast(Any, entity).undeclare()
        self._declared.clear()
        if self._inbox is not None:
            self._inbox.close()
            for kind, query in self._inbox.take_all():
                self._refuse(kind, query, ReturnCode.HAL_NO_CONNECTED, "server shutting down")
        if self._tg is not None:
            self._tg.cancel_scope.cancel()
            await self._tg.__aexit__(None, None, None)
            self._tg = None

    # -- Zenoh threads ---------------------------------------------------------------------
    @staticmethod
    def _on_query(inbox: ThreadInbox[tuple[str, zenoh.Query]], kind: str) -> Any:
        def on_query(query: zenoh.Query) -> None:
            inbox.put((kind, query))

        return on_query

    def _refuse_dropped(self, item: tuple[str, zenoh.Query]) -> None:
        self._refuse(item[0], item[1], ReturnCode.HAL_NO_MEMORY, "server busy: dropped")

    @staticmethod
    def _refuse(kind: str, query: zenoh.Query, code: ReturnCode, text: str) -> None:
        """An error reply naming no component (any thread: touches none)."""
        reply: wire.LifecycleReply | wire.ConfReply = (
            wire.LifecycleReply(int(code), text, [])
            if kind == "lifecycle"
            else wire.ConfReply(int(code), text)
        )
        _reply(query, wire.encoder.encode(reply))

    # -- the event loop --------------------------------------------------------------------
    async def _worker(self, inbox: ThreadInbox[tuple[str, zenoh.Query]]) -> None:
        while True:
            for kind, query in await inbox.wait():
                payload = query.payload
                data = payload.to_bytes() if payload else b""
                try:
                    if kind == "lifecycle":
                        answer: wire.LifecycleReply | wire.ConfReply = await self.handle_lifecycle(
                            wire.lifecycle_request_decoder.decode(data)
                        )
                    else:
                        answer = self.handle_conf(wire.conf_request_decoder.decode(data))
                except (msgspec.ValidationError, msgspec.DecodeError) as exc:
                    self._refuse(
                        kind, query, ReturnCode.HAL_BAD_PARAMETER, f"a {kind} request: {exc}"
                    )
                    continue
                except Exception as exc:  # a bug: the client still gets an answer
                    log.exception("lifecycle_request_failed", kind=kind)
                    self._refuse(kind, query, ReturnCode.HAL_ERROR, repr(exc))
                    continue
                _reply(query, wire.encoder.encode(answer))

    async def handle_lifecycle(self, request: wire.LifecycleRequest) -> wire.LifecycleReply:
        """Do ``request`` (every component named, in order, each tried); the reply."""
        lifecycle = self.lifecycle
        if request.action not in ACTIONS:
            return wire.LifecycleReply(
                int(ReturnCode.HAL_BAD_PARAMETER),
                f"action {request.action!r}: one of {', '.join(ACTIONS)}",
                [],
            )
        code, message = 0, ""
        try:
            hosted = lifecycle.names(request.names)
        except HALError as exc:
            return wire.LifecycleReply(int(exc.code), str(exc), [])
        if request.action != "get":
            if not request.names:
                return wire.LifecycleReply(
                    int(ReturnCode.HAL_BAD_PARAMETER), f"{request.action}: name the components", []
                )
            operation = {
                "activate": lifecycle.activate,
                "deactivate": lifecycle.deactivate,
                "reset": lifecycle.reset,
            }[request.action]
            for one in hosted:
                try:
                    await operation(one.name)
                except HALError as exc:
                    if not code:
                        code, message = int(exc.code), str(exc)
                except TimeoutError:
                    if not code:
                        code = int(ReturnCode.HAL_NO_CONNECTED)
                        message = f"{one.name}: {request.action}: the device did not answer"
        return wire.LifecycleReply(code, message, [lifecycle_component(h) for h in hosted])

    def handle_conf(self, request: wire.ConfRequest) -> wire.ConfReply:
        lifecycle = self.lifecycle
        try:
            hosted = lifecycle.find(request.name)
        except HALError as exc:
            return wire.ConfReply(int(exc.code), str(exc))
        if request.value is None:
            if request.parameter and request.parameter not in hosted.configuration.parameters:
                known = ", ".join(hosted.configuration.parameters) or "none"
                return conf_reply(
                    hosted,
                    int(ReturnCode.HAL_BAD_PARAMETER),
                    f"{hosted.name}: unknown parameter {request.parameter!r}: {known}",
                )
            return conf_reply(hosted)
        try:
            lifecycle.configure(hosted.name, request.set_name, request.parameter, request.value)
        except ConfigurationError as exc:
            message = str(exc) if str(exc).startswith(hosted.name) else f"{hosted.name}: {exc}"
            return conf_reply(
                hosted, int(ReturnCode.HAL_BAD_PARAMETER), message, exc.constraint or ""
            )
        except HALError as exc:
            return conf_reply(hosted, int(exc.code), str(exc))
        return conf_reply(hosted)
