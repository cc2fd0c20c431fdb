"""What the jog UI does to a rig, without the UI: the components' live values and states, a
jog of the selected axis within its position limits at a chosen step and velocity, enable and
disable, the rig's e-stop, and a log of events, errors and state changes.

A :class:`Jogger` lives inside an opened :class:`~openel_async.rig.Rig` and a task group
(:meth:`Jogger.run` or ``async with Jogger(rig) as jogger``). Every device call it makes is
bounded by :data:`CALL_TIMEOUT_S`; a failure is logged (:attr:`Jogger.log`), never raised to
the UI.

A jog moves the axis by ``step`` from where the previous jog of it was going (its actual
position when none is), clamped to the device's position limits (which include the rig file's
``limits``): an axis of an :class:`~openel_async.motion.AxisGroup` is moved by the group (its
other axes keep their setpoints) with its velocity limited to ``velocity``; any other axis by
position setpoints streamed every :data:`JOG_PERIOD_S` at ``velocity``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import time
from collections import deque
from collections.abc import Awaitable
from dataclasses import dataclass, field
from types import TracebackType
from typing import Self

import anyio
import anyio.abc

from openel_async.logs import get_logger

from ..actuator import Actuator
from ..component import ComponentState, HALComponent
from ..device import ErrorId
from ..errors import HALError
from ..motion import AxisGroup, PreemptedError
from ..requests import EventId, Request
from ..rig import Rig
from ..sensor import Sensor
from .controls import STEPS, VELOCITIES, JogControls, LogEntry

__all__ = [
    "CALL_TIMEOUT_S",
    "HISTORY",
    "JOG_PERIOD_S",
    "STEPS",
    "VELOCITIES",
    "Jogger",
    "LogEntry",
    "Row",
]

log = get_logger(__name__)

CALL_TIMEOUT_S = 1.0
"""The bound of every device call the jogger makes (a read, a command, an e-stop)."""
JOG_PERIOD_S = 0.02
"""The period of the position setpoints streamed to an axis outside a group."""
HISTORY = 240
"""Values kept per component for its plot (a minute at the UI's 4 reads a second)."""

_ACTIVE = ComponentState.ACTIVE
_ERROR = ComponentState.ERROR


@dataclass(slots=True)
class Row:
    """What the UI shows of one component."""

    name: str
    component: HALComponent
    kind: str
    """``actuator`` or ``sensor``."""
    units: str
    values: tuple[float, ...] = ()
    """The last values read (an actuator: its actual position)."""
    target: float | None = None
    """The target of the running (or last) jog."""
    history: deque[float] = field(default_factory=lambda: deque(maxlen=HISTORY))
    """The first value of every read, oldest first (the plot)."""
    plotted: bool = False
    read_error: str | None = None

    @property
    def state(self) -> str:
        return str(self.component.state)

    @property
    def limits(self) -> tuple[float, float] | None:
        """The position limits of an actuator (None: a sensor)."""
        if isinstance(self.component, Actuator):
            low, high = self.component.device.limits.position
            return (low, high)
        return None


def _error_name(error_id: int) -> str:
    try:
        return ErrorId(error_id).name
    except ValueError:
        return f"error {error_id}"


def _event_name(event_id: int) -> str:
    try:
        return EventId(event_id).name
    except ValueError:
        return f"event {event_id}"


class _Observer:
    """Every component's events and errors into the log (COMPLETED is only counted)."""

    def __init__(self, jogger: Jogger) -> None:
        self._jogger = jogger

    def notify_event(self, source: object, event_id: int) -> None:
        if event_id == EventId.COMPLETED:
            self._jogger.completed += 1
            return
        self._jogger.note("info", f"{_name(source)}: {_event_name(event_id)}")

    def notify_error(self, source: object, error_id: int) -> None:
        self._jogger.note("error", f"{_name(source)}: {_error_name(error_id)}")


def _name(source: object) -> str:
    return source.device_name if isinstance(source, HALComponent) else repr(source)


class Jogger(JogControls[Row]):
    """The jog session of an opened rig (see the module docstring)."""

    def __init__(
        self,
        rig: Rig,
        *,
        step: float = 0.05,
        velocity: float = 0.5,
        call_timeout: float = CALL_TIMEOUT_S,
    ) -> None:
        super().__init__(step=step, velocity=velocity)
        self.rig = rig
        self.call_timeout = call_timeout
        self.rows = [
            Row(
                name,
                c,
                "actuator" if isinstance(c, Actuator) else "sensor",
                ", ".join(c.units) if isinstance(c, Sensor) else "",
            )
            for name, c in rig.components.items()
        ]
        self.selected = next((i for i, r in enumerate(self.rows) if self.can_jog(r.component)), 0)
        self._states = {r.name: r.component.state for r in self.rows}
        self._observer = _Observer(self)
        self._observed: list[HALComponent] = []
        self._streams: dict[str, anyio.CancelScope] = {}
        self._polling = False

    # -- lifetime ---------------------------------------------------------------------------
    async def __aenter__(self) -> Self:
        tg = anyio.create_task_group()
        await tg.__aenter__()
        self._tg = tg
        for row in self.rows:
            self._observe(row.component)
        shown = [r for r in self.rows if r.kind == "actuator"] or self.rows
        for row in shown[:4]:  # the first four axes (or components) plotted
            row.plotted = True
        simulated = " (simulated)" if self.rig.simulated else ""
        self.note("info", f"rig {self.rig.spec.source}{simulated}: {len(self.rows)} components")
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> bool | None:
        assert self._tg is not None
        self._tg.cancel_scope.cancel()
        for component in self._observed:
            if component.state is _ACTIVE and component in self.rig.components.values():
                with contextlib.suppress(HALError):
                    component.remove_observer(self._observer)
        result = await self._tg.__aexit__(exc_type, exc, tb)
        self._tg = None
        return result

    def _observe(self, component: HALComponent) -> None:
        if component in self._observed or component.state is not _ACTIVE:
            return
        try:
            component.add_observer(self._observer)
        except HALError as exc:
            self.note("warning", f"{component.device_name}: not observed: {exc}")
            return
        self._observed.append(component)

    # -- plots and state ----------------------------------------------------------------------
    def toggle_plot(self) -> bool:
        row = self.row
        row.plotted = not row.plotted
        return row.plotted

    @property
    def title(self) -> str:
        """The rig file (and whether it is simulated): the UI's subtitle."""
        return f"{self.rig.spec.source}{' (simulated)' if self.rig.simulated else ''}"

    @property
    def estopped(self) -> bool:
        return self.rig.estopped

    def jogs(self, row: object) -> bool:
        """Whether ``row`` (one of :attr:`rows`) is an axis that takes a position."""
        return isinstance(row, Row) and self.can_jog(row.component)

    @staticmethod
    def can_jog(component: HALComponent) -> bool:
        return (
            isinstance(component, Actuator)
            and Request.POSITION in component.device.supported_requests
        )

    def group_of(self, name: str) -> tuple[AxisGroup, int] | None:
        for group in self.rig.groups.values():
            if name in group.axis_names:
                return group, group.axis_names.index(name)
        return None

    # -- polling ----------------------------------------------------------------------------
    async def poll(self) -> None:
        """Read every Active component's values once (each bounded), note state changes."""
        if self._polling:  # the previous poll is still waiting for a device
            return
        self._polling = True
        try:
            async with anyio.create_task_group() as tg:
                for row in self.rows:
                    self._note_state(row)
                    if row.component.state is _ACTIVE:
                        tg.start_soon(self._read, row)
        finally:
            self._polling = False

    def _note_state(self, row: Row) -> None:
        state = row.component.state
        old = self._states[row.name]
        if state is old:
            return
        self._states[row.name] = state
        fault = getattr(row.component, "last_fault", None)
        reason = f": {fault}" if state is _ERROR and fault is not None else ""
        level = "error" if state is _ERROR else "info"
        self.note(level, f"{row.name}: {old} -> {state}{reason}")
        row.target = None  # the next jog starts from where the axis is
        if state is _ACTIVE:
            self._observe(row.component)

    async def _read(self, row: Row) -> None:
        component = row.component
        try:
            with anyio.fail_after(self.call_timeout):
                if isinstance(component, Actuator):
                    values: tuple[float, ...] = (
                        await component.get_value(Request.POSITION_ACTUAL),
                    )
                elif isinstance(component, Sensor):
                    values = await component.get_value()
                else:
                    return
        except (HALError, TimeoutError, OSError) as exc:
            message = str(exc) or type(exc).__name__
            if row.read_error != message:
                self.note("warning", f"{row.name}: read failed: {message}")
            row.read_error = message
            return
        row.read_error = None
        row.values = values
        if values:
            row.history.append(values[0])

    # -- commands ---------------------------------------------------------------------------
    def jog(self, direction: int) -> float | None:
        """Jog the selected axis by ``direction`` (+1 or -1) steps; returns the target (None:
        refused, logged). The motion runs in the jogger's task group."""
        row = self.row
        axis = row.component
        if not isinstance(axis, Actuator) or not self.can_jog(axis):
            self.note("warning", f"{row.name}: not an axis that takes a position")
            return None
        if axis.state is not _ACTIVE:
            hint = " (e-stopped: r releases)" if axis.estop_latched else " (e enables)"
            self.note("warning", f"{row.name} is {axis.state}: not jogged{hint}")
            return None
        step = self.next_target(
            row.name, direction, row.target, row.values, axis.device.limits.position
        )
        if step is None:
            return None
        base, target = step
        row.target = target
        found = self.group_of(row.name)
        if found is not None:
            group, index = found
            self.start_soon(lambda: self._group_jog(row, group, index, target))
        else:
            self._start_stream(row, axis, base, target)
        return target

    def _start_stream(self, row: Row, axis: Actuator, base: float, target: float) -> None:
        previous = self._streams.pop(row.name, None)
        start = base
        if previous is not None:
            previous.cancel()
        scope = anyio.CancelScope()
        self._streams[row.name] = scope
        self.start_soon(lambda: self._stream(row, axis, scope, start, target, self.velocity))

    async def _stream(
        self,
        row: Row,
        axis: Actuator,
        scope: anyio.CancelScope,
        start: float,
        target: float,
        velocity: float,
    ) -> None:
        """Position setpoints from ``start`` to ``target`` at ``velocity``, one every
        :data:`JOG_PERIOD_S` (on the monotonic clock, as a person sees it)."""
        steps = max(1, math.ceil(abs(target - start) / (velocity * JOG_PERIOD_S)))
        began = time.monotonic()
        with scope:
            try:
                for i in range(1, steps + 1):
                    with anyio.fail_after(self.call_timeout):
                        await axis.set_value(start + (target - start) * i / steps, Request.POSITION)
                    delay = began + i * JOG_PERIOD_S - time.monotonic()
                    if i < steps and delay > 0:
                        await anyio.sleep(delay)
            except (HALError, TimeoutError, OSError) as exc:
                row.target = None
                self.note("error", f"{row.name}: jog failed: {exc or type(exc).__name__}")
        if self._streams.get(row.name) is scope:
            del self._streams[row.name]

    async def _group_jog(self, row: Row, group: AxisGroup, index: int, target: float) -> None:
        targets = list(group.commanded)
        distance = abs(target - targets[index])
        targets[index] = target
        limits = [
            dataclasses.replace(lim, max_velocity=min(lim.max_velocity, self.velocity))
            for lim in group.limits
        ]
        try:
            with anyio.fail_after(self.call_timeout):
                motion = await group.move_to(targets, limits)
            # the move takes distance / velocity and its ramps; its goal check is the group's
            with anyio.fail_after(2.0 * distance / self.velocity + 5.0 + self.call_timeout):
                await motion
        except PreemptedError:  # the next jog took over
            pass
        except HALError as exc:
            row.target = None
            self.note("error", f"{row.name}: jog failed ({group.name}): {exc}")
        except TimeoutError:
            row.target = None
            self.note("error", f"{row.name}: jog failed ({group.name}): no answer")

    async def stop(self) -> None:
        """Stop every jog: streams end at their last setpoint, groups brake (bounded)."""
        for scope in self._streams.values():
            scope.cancel()
        self._streams.clear()
        for group in self.rig.groups.values():
            if group.moving:
                try:
                    with anyio.fail_after(self.call_timeout):
                        await group.stop()
                except (HALError, TimeoutError):
                    group.hold()
        self.note("info", "jog stopped")

    async def disable(self) -> None:
        """Take the torque off the selected axis (NO_EXCITE) where the device allows it."""
        row = self.row
        axis = row.component
        if not isinstance(axis, Actuator):
            self.note("warning", f"{row.name}: a sensor: nothing to disable")
            return
        if axis.state is not _ACTIVE:
            self.note("warning", f"{row.name} is {axis.state}: not disabled")
            return
        if Request.NO_EXCITE not in axis.device.supported_requests:
            self.note("warning", f"{row.name}: the device cannot take its torque off")
            return
        self._cancel_stream(row.name)
        found = self.group_of(row.name)
        if found is not None:
            found[0].hold()
        await self._call(row.name, "disable", axis.set_value(0.0, Request.NO_EXCITE))
        row.target = None
        self.note("info", f"{row.name}: disabled (no torque)")

    async def enable(self) -> None:
        """Enable the selected component: ``re_init`` from Error, or hold the actual position
        (which excites a disabled axis)."""
        row = self.row
        component = row.component
        if component.state is _ERROR:
            if component.estop_latched:
                self.note("warning", f"{row.name}: e-stopped: r releases the e-stop first")
                return
            if await self._call(row.name, "re_init", component.re_init()):
                self.note("info", f"{row.name}: re-initialized")
            return
        if not isinstance(component, Actuator) or component.state is not _ACTIVE:
            self.note("warning", f"{row.name} is {component.state}: nothing to enable")
            return
        if not self.can_jog(component):
            self.note("warning", f"{row.name}: takes no position to hold")
            return
        self._cancel_stream(row.name)

        async def hold() -> None:
            assert isinstance(component, Actuator)
            position = await component.get_value(Request.POSITION_ACTUAL)
            await component.set_value(position, Request.POSITION)
            row.target = position

        if await self._call(row.name, "enable", hold()):
            self.note("info", f"{row.name}: enabled (holding {row.target:g})")

    async def estop(self) -> None:
        """E-stop the whole rig (:meth:`Rig.estop`): every jog ends first."""
        for scope in self._streams.values():
            scope.cancel()
        self._streams.clear()
        for group in self.rig.groups.values():
            group.hold()
        try:
            await self.rig.estop()  # bounded per component by the rig's exit_timeout
        except HALError as exc:
            self.note("error", f"E-STOP: {exc}")
            return
        self.note("error", "E-STOP: every component is in its emergency state")

    async def release(self) -> None:
        """Release the e-stop and re-initialize every component in Error."""
        self.rig.release_estop()
        for row in self.rows:
            if row.component.state is _ERROR:
                await self._call(row.name, "re_init", row.component.re_init())
        self.note("info", "e-stop released, components re-initialized")

    def _cancel_stream(self, name: str) -> None:
        scope = self._streams.pop(name, None)
        if scope is not None:
            scope.cancel()

    async def _call(self, name: str, what: str, call: Awaitable[object]) -> bool:
        try:
            with anyio.fail_after(self.call_timeout):
                await call
        except (HALError, TimeoutError, OSError) as exc:
            self.note("error", f"{name}: {what} failed: {exc or type(exc).__name__}")
            return False
        return True
