"""A served rig from the shell (``openel-async ls``, ``get``, ``set``, ``watch``, ``reset``,
``activate``, ``deactivate``, ``conf``):
the served namespaces discovered, components addressed by name, every wait bounded.

:func:`discover` finds the namespaces served on a session from the servers' liveliness
tokens (``openel/*/alive/server``): it waits (bounded) for the first token, then asks for
the complete set with one liveliness query, so a wrong namespace is answered with the ones
that exist rather than with a timeout. :class:`RigShell` holds one session and a
:class:`~openel_zenoh.client.RemoteSurface` per namespace it talks to; components are named
by their rig name (``MOTOR_1``), by kind and logical id (``Motor[0]``), either one
prefixed by the namespace (``twoaxis/MOTOR_1``) when several rigs are served.

The command line is ``openel_zenoh.shell_commands``; this module imports zenoh.
"""

from __future__ import annotations

import asyncio
import contextlib
import re
from collections.abc import Mapping
from dataclasses import dataclass
from types import TracebackType
from typing import Any, Self, cast

import anyio
import anyio.abc
import zenoh

from openel_async.errors import BadParameterError, HALError, NotConnectedError, ReturnCode
from openel_async.logs import get_logger
from openel_async.surface import ApplicationQueue, Completed
from openel_async.surface.messages import CommandMessage, Device, ResultList

from . import wire
from .client import RemoteSurface, close_session, open_session
from .keys import check_chunk

log = get_logger(__name__)

SERVERS = "openel/*/alive/server"
"""The liveliness tokens of every served namespace."""
DEFAULT_TIMEOUT_S = 2.0

_KIND_ID = re.compile(r"(?P<kind>[A-Za-z][A-Za-z0-9_]*)\[(?P<id>\d+)\]")


class NoRigError(NotConnectedError):
    """No rig is served (in the namespace asked for) at the endpoints given."""

    def __init__(self, message: str, served: list[str]) -> None:
        super().__init__(message)
        self.served = served


class NotCompletedError(HALError):
    """An accepted command whose ``completed`` did not come within the wait."""


def namespace_of(key: str) -> str | None:
    """``lab`` of ``openel/lab/alive/server``."""
    parts = key.split("/")
    if len(parts) == 4 and parts[0] == "openel" and parts[2:] == ["alive", "server"]:
        return parts[1]
    return None


async def discover(
    session: zenoh.Session,
    *,
    timeout: float,  # noqa: ASYNC109
    wanted: str | None = None,
) -> list[str]:
    """The namespaces served on ``session``, sorted: waits up to ``timeout`` s for a first
    server token, then, unless it is ``wanted``'s, makes one liveliness query for the
    complete set (bounded by ``timeout`` too), so that a namespace nobody serves is told
    without waiting for the timeout. An empty list: no server within the timeout."""
    loop = asyncio.get_running_loop()
    seen: set[str] = set()
    changed = anyio.Event()

    def add(namespace: str) -> None:
        seen.add(namespace)
        changed.set()

    def on_sample(sample: zenoh.Sample) -> None:
        namespace = namespace_of(str(sample.key_expr))
        if sample.kind == zenoh.SampleKind.PUT and namespace is not None:
            with contextlib.suppress(RuntimeError):  # a closed loop: nobody waits
                loop.call_soon_threadsafe(add, namespace)

    subscriber = session.liveliness().declare_subscriber(
        SERVERS, zenoh.handlers.Callback(on_sample, indirect=False), history=True
    )
    try:
        with anyio.move_on_after(timeout):
            while not seen:  # connected to a server at least
                await changed.wait()
                changed = anyio.Event()
        if not seen or (wanted is not None and wanted in seen):
            return sorted(seen)
        await _query_tokens(session, timeout, seen)
    finally:
        with contextlib.suppress(zenoh.ZError):
            cast(Any, subscriber).undeclare()
    return sorted(seen)


async def _query_tokens(session: zenoh.Session, timeout: float, seen: set[str]) -> None:  # noqa: ASYNC109
    """Add to ``seen`` the namespace of every server token one liveliness query finds."""
    loop = asyncio.get_running_loop()
    done = anyio.Event()
    found: list[str] = []

    def on_reply(reply: zenoh.Reply) -> None:
        ok = reply.ok
        namespace = namespace_of(str(ok.key_expr)) if ok is not None else None
        if namespace is not None:
            found.append(namespace)

    def on_done() -> None:
        with contextlib.suppress(RuntimeError):
            loop.call_soon_threadsafe(done.set)

    session.liveliness().get(
        SERVERS, zenoh.handlers.Callback(on_reply, on_done, indirect=False), timeout=timeout
    )
    with anyio.move_on_after(timeout + 1.0):  # even if Zenoh never ends the query
        await done.wait()
    seen.update(found)


def checked(command: CommandMessage) -> ResultList:
    """The results of an executed command; a HALError with its return code and the
    component's own message when it is not HAL_OK."""
    results = command.results
    code = results.get("return_code") if results is not None else None
    if results is None or code is None:
        raise NotConnectedError(f"{command.function_name}: the reply carries no return_code")
    if code.value != ReturnCode.HAL_OK:
        message = results.get("message")
        status = (
            ReturnCode(code.value)
            if code.value in ReturnCode._value2member_map_
            else ReturnCode.HAL_ERROR
        )
        text = str(message.value) if message is not None else status.name
        raise HALError(text, code=status)
    return results


@dataclass(frozen=True)
class Target:
    """A served component: its namespace and what the server's ``components`` says."""

    namespace: str
    info: wire.ComponentInfo

    @property
    def name(self) -> str:
        return self.info.device_name

    @property
    def kind(self) -> str:
        return self.info.device_kind

    @property
    def logical_id(self) -> int:
        return self.info.logical_id

    @property
    def address(self) -> str:
        """``Motor[0]``: the surface layer's address of the component."""
        return f"{self.kind}[{self.logical_id}]"

    @property
    def is_motor(self) -> bool:
        return self.kind in ("Motor", "Actuator")


def find(name: str, listing: Mapping[str, list[wire.ComponentInfo]]) -> Target:
    """The component ``name`` names among ``listing`` (namespace -> components): its rig
    name or ``Kind[id]``, optionally ``NAMESPACE/`` before it. BadParameterError naming the
    components there are when none or several match."""
    namespace, _, local = name.rpartition("/")
    spaces = [namespace] if namespace else sorted(listing)
    if namespace and namespace not in listing:
        raise BadParameterError("NAME", name, f"a served namespace: {', '.join(sorted(listing))}")
    address = _KIND_ID.fullmatch(local)
    matches: list[Target] = []
    for space in spaces:
        for info in listing[space]:
            if address is not None:
                hit = info.device_kind.lower() == address[
                    "kind"
                ].lower() and info.logical_id == int(address["id"])
            else:
                hit = info.device_name == local
            if hit:
                matches.append(Target(space, info))
    if not matches and address is None:  # a name typed in the wrong case
        matches = [
            Target(space, info)
            for space in spaces
            for info in listing[space]
            if info.device_name.lower() == local.lower()
        ]
    if len(matches) == 1:
        return matches[0]
    if matches:
        raise BadParameterError(
            "NAME", name, f"one of {', '.join(f'{t.namespace}/{t.name}' for t in matches)}"
        )
    names = [
        f"{s}/{i.device_name}" if len(listing) > 1 else i.device_name
        for s in spaces
        for i in listing[s]
    ]
    shown = ", ".join(names[:24]) + (f" (and {len(names) - 24} more)" if len(names) > 24 else "")
    raise BadParameterError("NAME", name, f"a served component: {shown or 'none served'}")


class RigShell:
    """A Zenoh session with the served rigs (``async with``): discovery, one
    RemoteSurface per namespace used, components by name."""

    def __init__(
        self,
        config: zenoh.Config,
        *,
        namespace: str | None = None,
        timeout: float = DEFAULT_TIMEOUT_S,
        where: str = "",
    ) -> None:
        if namespace is not None:
            check_chunk("namespace", namespace)
        if not timeout > 0:
            raise BadParameterError("timeout", timeout, "a number of seconds > 0")
        self.config = config
        self.namespace = namespace
        self.timeout = float(timeout)
        self.where = where
        """The endpoints, for messages."""
        self.session: zenoh.Session | None = None
        self._tg: anyio.abc.TaskGroup | None = None
        self._closing = anyio.Event()
        self._remotes: dict[str, RemoteSurface] = {}
        self._namespaces: list[str] | None = None

    async def __aenter__(self) -> Self:
        self.session = await open_session(self.config)
        tg = anyio.create_task_group()
        await tg.__aenter__()
        self._tg = tg
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        try:
            self._closing.set()  # the RemoteSurfaces close, each in its task
            if self._tg is not None:  # whatever ends the block propagates unwrapped
                await self._tg.__aexit__(None, None, None)
                self._tg = None
        finally:
            if self.session is not None:
                with anyio.CancelScope(shield=True):
                    await close_session(self.session)
                self.session = None

    def _session(self) -> zenoh.Session:
        if self.session is None:
            raise BadParameterError("RigShell", "closed", "inside 'async with'")
        return self.session

    async def namespaces(self) -> list[str]:
        """The namespaces to talk to: ``namespace`` if given and served, else every one
        served. NoRigError (naming those served) otherwise."""
        if self._namespaces is None:
            served = await discover(self._session(), timeout=self.timeout, wanted=self.namespace)
            at = f" at {self.where}" if self.where else ""
            if self.namespace is not None:
                if self.namespace not in served:
                    others = f"; served: {', '.join(served)}" if served else ""
                    waited = "" if served else f" (waited {self.timeout:g} s)"
                    raise NoRigError(
                        f"no rig served{at} in namespace {self.namespace!r}{waited}{others}",
                        served,
                    )
                served = [self.namespace]
            elif not served:
                raise NoRigError(f"no rig served{at} (waited {self.timeout:g} s)", served)
            self._namespaces = served
        return self._namespaces

    async def remote(self, namespace: str) -> RemoteSurface:
        """The RemoteSurface of ``namespace`` (opened on first use, in a task of the
        shell's, so that any task may ask for it)."""
        found = self._remotes.get(namespace)
        if found is None:
            if self._tg is None:
                raise BadParameterError("RigShell", "closed", "inside 'async with'")
            found = RemoteSurface(self._session(), namespace, timeout=self.timeout)
            await self._tg.start(self._hold, found)
            self._remotes[namespace] = found
        return found

    async def _hold(
        self, remote: RemoteSurface, *, task_status: anyio.abc.TaskStatus[None]
    ) -> None:
        async with remote:
            task_status.started()
            await self._closing.wait()

    async def listing(self) -> dict[str, list[wire.ComponentInfo]]:
        """namespace -> its components (the server's ``components``), the namespaces
        queried concurrently."""
        spaces = await self.namespaces()
        for space in spaces:
            await self.remote(space)
        out: dict[str, list[wire.ComponentInfo]] = {}

        async def one(space: str) -> None:
            out[space] = await self._remotes[space].components()

        async with anyio.create_task_group() as tg:
            for space in spaces:
                tg.start_soon(one, space)
        return {space: out[space] for space in spaces}

    async def target(self, name: str) -> Target:
        return find(name, await self.listing())

    async def targets(self, names: list[str]) -> list[Target]:
        listing = await self.listing()
        return [find(name, listing) for name in names]

    async def execute(
        self,
        target: Target,
        function: str,
        arguments: Mapping[str, object] | None = None,
        application: object | None = None,
    ) -> CommandMessage:
        """One command message to ``target``; the reply's command (its return code is not
        checked)."""
        command = CommandMessage.call(
            function, "", logical_id=target.logical_id, **dict(arguments or {})
        )
        remote = await self.remote(target.namespace)
        reply = await remote.execute(Device(target.kind, (command,)), application)
        return reply.commands[0]

    async def call(
        self, target: Target, function: str, arguments: Mapping[str, object] | None = None
    ) -> ResultList:
        """The results of one command, or the HALError its return code names."""
        return checked(await self.execute(target, function, arguments))

    async def command(
        self,
        target: Target,
        function: str,
        arguments: Mapping[str, object],
        *,
        wait: float | None = None,
    ) -> tuple[str, int]:
        """An asynchronous command (SetPosition...): its command id and, with ``wait``
        (seconds), the ``completed`` status (a ReturnCode's value), else -1 once accepted.
        HALError when it is refused, NotCompletedError when it does not complete in time."""
        app = ApplicationQueue(16, name="shell")
        command = await self.execute(target, function, arguments, app if wait else None)
        checked(command)
        if not wait:
            return command.command_id, -1
        with anyio.move_on_after(wait):
            while True:
                notice = await app.get()
                if isinstance(notice, Completed) and notice.command_id == command.command_id:
                    return command.command_id, int(notice.status)
        raise NotCompletedError(f"{target.name}: {function} not completed within {wait:g} s")

    async def lifecycle(
        self, namespace: str, action: str, names: list[str] | None = None
    ) -> wire.LifecycleReply:
        """The RTC lifecycle of ``namespace``'s components (openel_zenoh.lifecycle): ``get``,
        ``activate``, ``deactivate`` or ``reset``. NotConnectedError when the server has
        none (no reply)."""
        remote = await self.remote(namespace)
        try:
            return await remote.lifecycle(action, names)
        except TimeoutError:
            raise NotConnectedError(
                f"{namespace}: no lifecycle served (openel/{namespace}/rig/lifecycle: no reply)"
            ) from None

    async def conf(self, namespace: str, request: wire.ConfRequest) -> wire.ConfReply:
        """A configuration query of ``namespace`` (openel_zenoh.lifecycle)."""
        remote = await self.remote(namespace)
        try:
            return await remote.conf(request)
        except TimeoutError:
            raise NotConnectedError(
                f"{namespace}: no configuration served (openel/{namespace}/rig/conf: no reply)"
            ) from None
