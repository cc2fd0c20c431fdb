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
from .rigservice import RigQueryService, reply

log = get_logger(__name__)

INBOX_SIZE = 256
ACTIONS = ("get", "activate", "deactivate", "reset")


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


class RigLifecycleServer(RigQueryService[str]):
    """Serve the lifecycle and configuration of ``surface``'s components on ``session``
    under ``openel/<namespace>/rig/`` (``async with``); :attr:`lifecycle` is the model. A
    query's kind: ``lifecycle`` or ``conf``."""

    inbox_size = INBOX_SIZE

    def __init__(
        self, surface: Surface, session: zenoh.Session, namespace: str = "default"
    ) -> None:
        super().__init__(session)
        self.lifecycle = ServedLifecycle(surface)
        self.keys = Keys(namespace)

    def queryables(self) -> list[tuple[str, str]]:
        return [(self.keys.rig_lifecycle, "lifecycle"), (self.keys.rig_conf, "conf")]

    async def closing(self) -> None:
        self.lifecycle.close()

    def refuse(self, kind: str, query: zenoh.Query, code: ReturnCode, text: str) -> None:
        """An error reply naming no component (any thread: touches none)."""
        answer: wire.LifecycleReply | wire.ConfReply = (
            wire.LifecycleReply(int(code), text, [])
            if kind == "lifecycle"
            else wire.ConfReply(int(code), text)
        )
        reply(query, wire.encoder.encode(answer))

    # -- the event loop --------------------------------------------------------------------
    async def serve(self, inbox: ThreadInbox[tuple[str, zenoh.Query]]) -> None:
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
                    self.refuse(
                        kind, query, ReturnCode.HAL_BAD_PARAMETER, f"a {kind} request: {exc}"
                    )
                    continue
                except Exception as exc:  # a bug: the client still gets an answer
                    log.exception("lifecycle_request_failed", kind=kind)
                    self.refuse(kind, query, ReturnCode.HAL_ERROR, repr(exc))
                    continue
                reply(query, wire.encoder.encode(answer))

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
