"""``openel-async jog --remote NAMESPACE``: the jog UI (openel_async.tui) over a served rig.

:class:`RemoteJogger` is a :class:`~openel_async.tui.session.JogSession` over a
:class:`~openel_zenoh.shell.RigShell`: the components are the server's (``components``),
their limits and supported requests from each one's GetProfile (read again every second:
``conf set`` narrows them live), their values read four times a second, their events and
errors from the server's notices (the ``watch`` path), their RTC lifecycle states from
``rig/lifecycle``. A jog streams ``SetPosition`` setpoints every ``JOG_PERIOD_S`` at the
chosen velocity within the limits the server reports; ``d`` deactivates (excitation off),
``e`` resets a component in ERROR (to INACTIVE) or activates an INACTIVE one (it holds
where it is); ``x`` is the rig's e-stop (``rig/estop``), ``r`` releases it and resets the
components in ERROR. Every call is bounded (``call_timeout``); a failure is logged, never
raised to the UI. Leaving stops the streams (each axis keeps its last setpoint); the
served rig is otherwise left as it is.

``REMOTE_JOG`` is the entry point (group ``openel_async.remote_jog``).
"""

from __future__ import annotations

import argparse
import math
import time
from collections import deque
from collections.abc import AsyncIterator
from contextlib import AbstractAsyncContextManager, asynccontextmanager
from dataclasses import dataclass, field
from types import TracebackType
from typing import Self

import anyio
import anyio.abc

from openel_async.errors import BadParameterError, HALError, NotConnectedError
from openel_async.logs import get_logger
from openel_async.requests import Request
from openel_async.surface import ApplicationQueue, ErrorNotification, EventNotification
from openel_async.tui.controls import JogControls
from openel_async.tui.jogger import HISTORY, JOG_PERIOD_S

from . import wire
from .shell import RigShell, Target, checked

log = get_logger(__name__)

CALL_TIMEOUT_S = 1.0
PROFILE_EVERY = 4
"""Polls between two reads of the profiles (the limits)."""


@dataclass(slots=True)
class RemoteRow:
    """A served component as the UI shows it."""

    name: str
    target_of: Target
    kind: str
    units: str = ""
    values: tuple[float, ...] = ()
    target: float | None = None
    history: deque[float] = field(default_factory=lambda: deque(maxlen=HISTORY))
    plotted: bool = False
    read_error: str | None = None
    hal_state: str = "Active"
    lifecycle: str | None = None
    limits: tuple[float, float] | None = None
    positioned: bool = False
    """It takes SetPosition (a jog axis)."""

    @property
    def state(self) -> str:
        if self.lifecycle == "INACTIVE" and self.hal_state == "Active":
            return "Inactive"
        return self.hal_state


class RemoteJogger(JogControls[RemoteRow]):
    """The jog session of a served rig (see the module)."""

    def __init__(
        self,
        shell: RigShell,
        namespace: str,
        *,
        step: float = 0.05,
        velocity: float = 0.5,
        call_timeout: float = CALL_TIMEOUT_S,
    ) -> None:
        super().__init__(step=step, velocity=velocity)
        self.shell = shell
        self.namespace = namespace
        self.call_timeout = call_timeout
        self.estopped = False
        self._streams: dict[str, anyio.CancelScope] = {}
        self._polling = False
        self._polls = 0
        self._has_lifecycle = True

    @property
    def title(self) -> str:
        at = f" at {self.shell.where}" if self.shell.where else ""
        return f"served rig {self.namespace!r}{at}"

    # -- lifetime ---------------------------------------------------------------------------
    async def __aenter__(self) -> Self:
        listing = await self.shell.listing()
        for info in listing[self.namespace]:
            target = Target(self.namespace, info)
            self.rows.append(
                RemoteRow(info.device_name, target, "actuator" if target.is_motor else "sensor")
            )
        await self._profiles()
        self.selected = next((i for i, r in enumerate(self.rows) if r.positioned), 0)
        shown = [r for r in self.rows if r.kind == "actuator"] or self.rows
        for row in shown[:4]:
            row.plotted = True
        tg = anyio.create_task_group()
        await tg.__aenter__()
        self._tg = tg
        await tg.start(self._notices)
        self.note("info", f"{self.title}: {len(self.rows)} components")
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> bool | None:
        assert self._tg is not None
        self._tg.cancel_scope.cancel()
        result = await self._tg.__aexit__(exc_type, exc, tb)
        self._tg = None
        return result

    async def _notices(self, *, task_status: anyio.abc.TaskStatus[None]) -> None:
        remote = await self.shell.remote(self.namespace)
        app = ApplicationQueue(4096, name=f"jog-{self.namespace}")
        remote.attach(app)
        for kind in sorted({r.target_of.kind for r in self.rows}):
            with anyio.fail_after(self.call_timeout):
                await remote.subscribe(kind, "*", app)
        task_status.started()
        while True:
            notice = await app.get()
            if isinstance(notice, EventNotification):
                if notice.event_type == "COMPLETED":
                    self.completed += 1
                    continue
                detail = remote.cached_event_detail(notice.event_id)
                level, what, extra = "info", notice.event_type, ""
            elif isinstance(notice, ErrorNotification):
                detail = remote.cached_error_detail(notice.error_id)
                level, what = "error", notice.error_type
                message = detail.get("message") if detail is not None else None
                extra = f" ({message.value})" if message is not None else ""
            else:
                continue
            name = detail.get("device_name") if detail is not None else None
            self.note(level, f"{name.value if name is not None else '?'}: {what}{extra}")

    def toggle_plot(self) -> bool:
        self.row.plotted = not self.row.plotted
        return self.row.plotted

    def jogs(self, row: object) -> bool:
        return isinstance(row, RemoteRow) and row.positioned

    # -- polling ----------------------------------------------------------------------------
    async def _profiles(self) -> None:
        async def one(row: RemoteRow) -> None:
            try:
                with anyio.fail_after(self.call_timeout):
                    results = await self.shell.call(row.target_of, "GetProfile")
            except (HALError, TimeoutError):
                return
            limits = results.get("position_limits")
            requests = results.get("supported_requests")
            units = results.get("units")
            if limits is not None and isinstance(limits.value, tuple | list):
                low, high = (float(v) for v in limits.value)
                row.limits = (low, high)
            if requests is not None and isinstance(requests.value, tuple | list):
                row.positioned = int(Request.POSITION) in requests.value
            if units is not None and isinstance(units.value, tuple | list):
                row.units = ", ".join(str(u) for u in units.value if u)

        async with anyio.create_task_group() as tg:
            for row in self.rows:
                tg.start_soon(one, row)

    async def poll(self) -> None:
        """The states, then the values of the Active components (each call bounded)."""
        if self._polling:
            return
        self._polling = True
        try:
            await self._states()
            self._polls += 1
            async with anyio.create_task_group() as tg:
                if self._polls % PROFILE_EVERY == 0:
                    tg.start_soon(self._profiles)
                for row in self.rows:
                    if row.hal_state == "Active":
                        tg.start_soon(self._read, row)
        finally:
            self._polling = False

    async def _states(self) -> None:
        remote = await self.shell.remote(self.namespace)
        try:
            with anyio.fail_after(self.call_timeout):
                infos = {i.device_name: i.state for i in await remote.components()}
        except (HALError, TimeoutError) as exc:
            self.note("warning", f"no answer from the server: {exc}")
            return
        lifecycles: dict[str, wire.LifecycleComponent] = {}
        if self._has_lifecycle:
            try:
                with anyio.fail_after(self.call_timeout):
                    reply = await self.shell.lifecycle(self.namespace, "get")
                lifecycles = {c.name: c for c in reply.components}
            except (HALError, TimeoutError):
                self._has_lifecycle = False
                self.note("warning", "the server serves no lifecycle: d and e do nothing")
        self.estopped = any(c.latched for c in lifecycles.values())
        for row in self.rows:
            before = row.state
            row.hal_state = infos.get(row.name, row.hal_state)
            found = lifecycles.get(row.name)
            row.lifecycle = found.state if found is not None else None
            if row.state != before:
                self.note(
                    "error" if row.state == "Error" else "info",
                    f"{row.name}: {before} -> {row.state}",
                )
                row.target = None

    async def _read(self, row: RemoteRow) -> None:
        function = "GetPosition" if row.kind == "actuator" else "GetValueOfMeasurement"
        try:
            with anyio.fail_after(self.call_timeout):
                results = await self.shell.call(row.target_of, function)
        except (HALError, TimeoutError) as exc:
            message = str(exc) or type(exc).__name__
            if row.read_error != message:
                self.note("warning", f"{row.name}: read failed: {message}")
            row.read_error = message
            return
        value = results.value("position" if row.kind == "actuator" else "values")
        values = tuple(float(v) for v in value) if isinstance(value, tuple | list) else (value,)
        row.read_error = None
        row.values = values
        if values:
            row.history.append(values[0])

    # -- commands ---------------------------------------------------------------------------
    def jog(self, direction: int) -> float | None:
        row = self.row
        if not row.positioned or row.limits is None:
            self.note("warning", f"{row.name}: not an axis that takes a position")
            return None
        if row.state != "Active":
            hint = " (e-stopped: r releases)" if self.estopped else " (e enables)"
            self.note("warning", f"{row.name} is {row.state}: not jogged{hint}")
            return None
        step = self.next_target(row.name, direction, row.target, row.values, row.limits)
        if step is None:
            return None
        base, target = step
        row.target = target
        previous = self._streams.pop(row.name, None)
        if previous is not None:
            previous.cancel()
        scope = anyio.CancelScope()
        self._streams[row.name] = scope
        velocity = self.velocity
        self.start_soon(lambda: self._stream(row, scope, base, target, velocity))
        return target

    async def _stream(
        self, row: RemoteRow, scope: anyio.CancelScope, start: float, target: float, velocity: float
    ) -> None:
        steps = max(1, math.ceil(abs(target - start) / (velocity * JOG_PERIOD_S)))
        began = time.monotonic()
        with scope:
            try:
                for i in range(1, steps + 1):
                    setpoint = start + (target - start) * i / steps
                    with anyio.fail_after(self.call_timeout):
                        checked(
                            await self.shell.execute(
                                row.target_of, "SetPosition", {"position": setpoint}
                            )
                        )
                    delay = began + i * JOG_PERIOD_S - time.monotonic()
                    if i < steps and delay > 0:
                        await anyio.sleep(delay)
            except (HALError, TimeoutError) as exc:
                row.target = None
                self.note("error", f"{row.name}: jog failed: {exc or type(exc).__name__}")
        if self._streams.get(row.name) is scope:
            del self._streams[row.name]

    def _cancel_streams(self) -> None:
        for scope in self._streams.values():
            scope.cancel()
        self._streams.clear()

    async def stop(self) -> None:
        self._cancel_streams()
        self.note("info", "jog stopped")

    async def _lifecycle(self, row: RemoteRow, action: str) -> bool:
        try:
            with anyio.fail_after(self.call_timeout + 2.0):  # the server bounds each call too
                reply = await self.shell.lifecycle(self.namespace, action, [row.name])
        except (HALError, TimeoutError) as exc:
            self.note("error", f"{row.name}: {action} failed: {exc or type(exc).__name__}")
            return False
        if reply.return_code != 0:
            self.note("error", f"{row.name}: {action} failed: {reply.message}")
            return False
        for state in reply.components:
            if state.name == row.name:
                row.lifecycle, row.hal_state = state.state, state.hal_state
        return True

    async def disable(self) -> None:
        """Deactivate the selected component (an actuator's excitation off)."""
        row = self.row
        self._streams.pop(row.name, anyio.CancelScope()).cancel()
        if await self._lifecycle(row, "deactivate"):
            row.target = None
            self.note("info", f"{row.name}: deactivated (no torque)")

    async def enable(self) -> None:
        """Reset a component in ERROR (to INACTIVE), or activate an INACTIVE one."""
        row = self.row
        if row.lifecycle == "ERROR" or row.hal_state == "Error":
            if self.estopped:
                self.note("warning", f"{row.name}: e-stopped: r releases the e-stop first")
            elif await self._lifecycle(row, "reset"):
                self.note("info", f"{row.name}: reset (INACTIVE: e activates)")
            return
        if await self._lifecycle(row, "activate"):
            row.target = None
            self.note("info", f"{row.name}: activated (holding)")

    async def estop(self) -> None:
        """The rig's e-stop (``rig/estop``): every jog ends first."""
        self._cancel_streams()
        remote = await self.shell.remote(self.namespace)
        try:
            with anyio.fail_after(self.call_timeout + 5.0):  # bounded by the rig's exit_timeout
                reply = await remote.estop_rig()
        except (HALError, TimeoutError) as exc:
            self.note("error", f"E-STOP: no answer: {exc or type(exc).__name__}")
            return
        if reply.return_code != 0:
            self.note("error", f"E-STOP: {reply.message}")
            return
        self.estopped = True
        self.note("error", "E-STOP: every component is in its emergency state")

    async def release(self) -> None:
        """Release the e-stop and reset every component in ERROR (to INACTIVE)."""
        remote = await self.shell.remote(self.namespace)
        try:
            with anyio.fail_after(self.call_timeout):
                await remote.estop_rig(release=True)
        except (HALError, TimeoutError) as exc:
            self.note("error", f"release failed: {exc or type(exc).__name__}")
            return
        self.estopped = False
        await self._states()
        for row in self.rows:
            if row.hal_state == "Error":
                await self._lifecycle(row, "reset")
        self.note("info", "e-stop released, components reset (INACTIVE: e activates)")


class RemoteJog:
    """The Zenoh driver's :class:`~openel_async.tui.session.RemoteJogProvider`."""

    def check(self, args: argparse.Namespace) -> str | None:
        from openel_async.cli.commands import no_such_file

        from .keys import check_chunk

        try:
            check_chunk("--remote", args.remote)
            if not (args.timeout > 0 and math.isfinite(args.timeout)):
                raise BadParameterError("--timeout", args.timeout, "a number of seconds > 0")
            for endpoint in args.connect or ():
                if "/" not in endpoint:
                    raise BadParameterError(
                        "--connect", endpoint, "a Zenoh endpoint like tcp/127.0.0.1:7447"
                    )
        except BadParameterError as exc:
            return str(exc)
        if args.config and no_such_file("openel-async jog", args.config):
            return f"--config {args.config}: no such file"
        return None

    def session(self, args: argparse.Namespace) -> AbstractAsyncContextManager[RemoteJogger]:
        return self._session(args)

    @asynccontextmanager
    async def _session(self, args: argparse.Namespace) -> AsyncIterator[RemoteJogger]:
        import zenoh

        from .shell_commands import session_config, where

        try:
            config = session_config(args)
        except zenoh.ZError as exc:
            raise BadParameterError(
                "--config", args.config, f"a Zenoh configuration: {exc}"
            ) from None
        try:
            shell = RigShell(config, namespace=args.remote, timeout=args.timeout, where=where(args))
            async with shell:
                await shell.namespaces()  # NoRigError naming those served
                async with RemoteJogger(
                    shell, args.remote, step=args.step, velocity=args.velocity
                ) as jogger:
                    yield jogger
        except zenoh.ZError as exc:
            raise NotConnectedError(f"no Zenoh session for {where(args)}: {exc}") from None


REMOTE_JOG = RemoteJog()
"""The entry point of group ``openel_async.remote_jog``."""
