"""An opened rig: its buses, components, timers and axis groups by name, and the safety the
rig file asks for -- limits applied on the host, device watchdogs armed at every init, one
call that e-stops everything, and a safe stop on every exit path."""

from __future__ import annotations

import dataclasses
import math
import signal
from collections.abc import AsyncIterator, Awaitable, Callable, Mapping
from contextlib import AbstractAsyncContextManager, AsyncExitStack, asynccontextmanager
from dataclasses import dataclass, field
from typing import TypeVar

import anyio

from openel_async.logs import get_logger

from ..actuator import Actuator
from ..clock import Clock
from ..component import HALComponent
from ..device import ActuatorLimits
from ..errors import BadParameterError, HALError
from ..motion import AxisGroup, AxisLimits
from ..positioned import did_you_mean
from ..requests import Request
from ..safety import EmergencyStop, ExitAction, Watchdog
from ..sensor import Sensor
from ..timer import EventTimer, TimerState
from .build import ResolvedRig, build_components, resolve_rig
from .spec import JointLimits, RigSpec, SafetySpec

__all__ = ["Rig", "SafeStopReport", "open_rig"]

log = get_logger(__name__)

T = TypeVar("T")


ESTOPPED = "e-stopped: left in the emergency state"
""":attr:`SafeStopReport.how` of an actuator whose e-stop was latched when the rig closed."""


@dataclass(frozen=True)
class SafeStopReport:
    """How one actuator was left when the rig closed."""

    component: str
    action: ExitAction
    outcome: str
    """``"done"``, or what went wrong (the actuator may not be in the state asked for)."""
    how: str = ""
    """What was done: the device's own safe stop, or the HAL fallback."""

    @property
    def ok(self) -> bool:
        return self.outcome == "done"


@dataclass
class Rig:
    """An opened rig (:func:`open_rig`): everything in it by name."""

    spec: RigSpec
    components: dict[str, HALComponent]
    timers: dict[str, EventTimer] = field(default_factory=dict)
    groups: dict[str, AxisGroup] = field(default_factory=dict)
    buses: dict[str, object] = field(default_factory=dict)
    """The opened bus objects (``openel_can.CanBus``, ``openel_serial.DynamixelPort``...)."""
    simulated: bool = False
    """Opened with ``sim=True``: every bus talks to simulated peers."""
    peers: dict[str, object] = field(default_factory=dict)
    """With ``sim=True``: the simulated peer of each device on a bus, by component name."""
    bus_descriptions: dict[str, str] = field(default_factory=dict)
    """What each bus is (the simulated one with ``sim=True``)."""
    exit_report: list[SafeStopReport] = field(default_factory=list)
    """Filled when the rig closes: how each actuator was left."""
    clock: Clock | None = None
    """The clock the components and timers run on (None: the default clock)."""
    left: bool = False
    """:meth:`leave_safe` ran: the actuators were left in their exit state."""

    async def leave_safe(self) -> None:
        """Leave every actuator as ``safety.on_exit`` says, now (at once, each bounded by
        ``safety.exit_timeout``): the rig's timers stop and its groups hold first. Runs once;
        the rig's exit calls it. A runner about to cancel the run (a signal) calls it before
        cancelling, while the buses still answer (``openel_async.app.run_app`` does)."""
        if self.left:
            return
        self.left = True
        for group in self.groups.values():
            group.hold()
        for timer in self.timers.values():
            if timer.state is TimerState.RUNNING:
                timer.stop_timer()
        await _leave_safe(self)

    # -- lookups ---------------------------------------------------------------------------
    def _get(self, table: Mapping[str, T], what: str, name: str) -> T:
        try:
            return table[name]
        except KeyError:
            raise BadParameterError(
                what, name, f"a {what} of the rig ({did_you_mean(name, table)})"
            ) from None

    def component(self, name: str) -> HALComponent:
        return self._get(self.components, "component", name)

    def actuator(self, name: str) -> Actuator:
        component = self.component(name)
        if not isinstance(component, Actuator):
            raise BadParameterError("actuator", name, f"an actuator ({name} is a sensor)")
        return component

    def sensor(self, name: str) -> Sensor:
        component = self.component(name)
        if not isinstance(component, Sensor):
            raise BadParameterError("sensor", name, f"a sensor ({name} is an actuator)")
        return component

    def timer(self, name: str) -> EventTimer:
        return self._get(self.timers, "timer", name)

    def group(self, name: str) -> AxisGroup:
        return self._get(self.groups, "group", name)

    @property
    def actuators(self) -> list[Actuator]:
        """The actuators in file order."""
        return [c for c in self.components.values() if isinstance(c, Actuator)]

    @property
    def sensors(self) -> list[Sensor]:
        """The sensors in file order."""
        return [c for c in self.components.values() if isinstance(c, Sensor)]

    # -- e-stop ----------------------------------------------------------------------------
    async def estop(self) -> None:
        """E-stop every component at once (each one's :meth:`HALComponent.estop`: the
        protocol's emergency state, Error with ``ErrorId.ESTOP``, latched until
        :meth:`release_estop`). Every component is tried; the first failure is raised after
        all were."""
        log.warning("rig_estop", components=len(self.components))
        failures: list[BaseException] = []

        async def one(component: HALComponent) -> None:
            try:
                with anyio.fail_after(self.spec.safety.exit_timeout):
                    await component.estop()
            except (HALError, TimeoutError, OSError) as exc:
                log.error("estop_failed", component=component.device_name, error=repr(exc))
                failures.append(exc)

        with anyio.CancelScope(shield=True):
            async with anyio.create_task_group() as tg:
                for component in self.components.values():
                    if component.state.value in ("Initialized", "Active", "Error"):
                        tg.start_soon(one, component)
        if failures:
            raise HALError(f"e-stop failed on {len(failures)} component(s): {failures[0]}")

    def release_estop(self) -> None:
        """Release the e-stop of every component: ``re_init`` recovers them again."""
        for component in self.components.values():
            component.release_estop()

    @property
    def estopped(self) -> bool:
        return any(c.estop_latched for c in self.components.values())

    # -- summary ---------------------------------------------------------------------------
    def exit_line(self) -> str:
        """``on exit: stop -- MOTOR_1 done, MOTOR_2 done`` (after the rig closed)."""
        action = self.spec.safety.on_exit.value
        if not self.exit_report:
            return f"on exit            {action}: no actuator"
        parts = [
            f"{r.component} "
            + ("e-stopped" if r.how == ESTOPPED else "done" if r.ok else f"FAILED: {r.outcome}")
            for r in self.exit_report
        ]
        return f"on exit            {action}: {', '.join(parts)}"


def _intersect(own: ActuatorLimits, joint: JointLimits) -> ActuatorLimits:
    low, high = own.position
    if joint.position is not None:
        low, high = max(low, joint.position[0]), min(high, joint.position[1])
    velocity = own.velocity if joint.velocity is None else min(own.velocity, joint.velocity)
    torque = own.torque if joint.torque is None else min(own.torque, joint.torque)
    return ActuatorLimits((low, high), velocity, torque)


def _limits_hook(joint: JointLimits) -> Callable[[HALComponent], Awaitable[None]]:
    async def apply(component: HALComponent) -> None:
        assert isinstance(component, Actuator)
        device = component.device
        limits = _intersect(device.limits, joint)
        if limits != device.limits:
            device.limits = limits

    return apply


def _watchdog_hook(timeout_s: float) -> Callable[[HALComponent], Awaitable[None]]:
    async def arm(component: HALComponent) -> None:
        device = component.device
        assert isinstance(device, Watchdog)
        await device.arm_watchdog(timeout_s)

    return arm


async def _fallback_stop(actuator: Actuator, action: ExitAction) -> str:
    """A safe stop through the HAL API for a device with no safe stop of its own."""
    supported = actuator.device.supported_requests
    if action is ExitAction.TORQUE_OFF:
        if Request.NO_EXCITE in supported:
            await actuator.set_value(0.0, Request.NO_EXCITE)
            return "NO_EXCITE"
        action = ExitAction.STOP  # the closest the device offers
    if action is ExitAction.STOP and Request.VELOCITY in supported:
        await actuator.set_value(0.0, Request.VELOCITY)
        return "velocity 0"
    if Request.POSITION in supported:
        position = await actuator.get_value(Request.POSITION_ACTUAL)
        await actuator.set_value(position, Request.POSITION)
        return "position hold"
    return "nothing the device can do"


async def _safe_stop(actuator: Actuator, safety: SafetySpec) -> SafeStopReport:
    action = safety.on_exit
    device = actuator.device
    name = actuator.device_name
    how = ""
    if actuator.estop_latched:  # the emergency state is the safest: nothing may undo it
        return SafeStopReport(name, action, "done", ESTOPPED)
    try:
        with anyio.fail_after(safety.exit_timeout):
            if isinstance(device, EmergencyStop) and actuator.state.value in ("Active", "Error"):
                await device.safe_stop(action)
                how = "device"
            elif actuator.state.value == "Active":
                how = await _fallback_stop(actuator, action)
            else:
                state = actuator.state.value
                return SafeStopReport(name, action, f"{state}, nothing sent (left as it was)")
            if isinstance(device, Watchdog) and safety.watchdog_timeout is not None:
                # The state asked for outlives the host: its watchdog must not undo it.
                await device.disarm_watchdog()
    except Exception as exc:  # every actuator is tried; the report says what failed
        log.error("safe_stop_failed", component=name, action=action.value, error=repr(exc))
        return SafeStopReport(name, action, f"{type(exc).__name__}: {exc}", how)
    log.info("safe_stop", component=name, action=action.value, how=how)
    return SafeStopReport(name, action, "done", how)


@asynccontextmanager
async def open_rig(
    spec: RigSpec | ResolvedRig,
    clock: Clock | None = None,
    *,
    sim: bool = False,
    init: bool = True,
    on_component: Callable[[HALComponent], object] | None = None,
    on_timer: Callable[[EventTimer], object] | None = None,
    handle_sigquit: bool = False,
) -> AsyncIterator[Rig]:
    """Open a rig: its buses (with ``sim=True``, against simulated peers at the same
    addresses), its components (on ``clock``; None: the clock of a bus that has one, such
    as a MuJoCo simulation, else the default clock) (entered; initialized unless ``init=False``), its timers and
    axis groups. ``on_component``/``on_timer`` are told of each before it is entered or
    started (an app context registers them with its hooks). ``handle_sigquit``: SIGQUIT
    e-stops the rig (when the rig file's ``safety.estop_on_sigquit`` allows).

    At exit, whatever ends the block (an exception, a cancellation, a signal): the groups
    hold, the timers stop, every actuator is left in ``safety.on_exit``'s state
    (:attr:`Rig.exit_report`), then components and buses close."""
    resolved = spec if isinstance(spec, ResolvedRig) else resolve_rig(spec)
    rig_spec = resolved.spec
    safety = rig_spec.safety
    rig = Rig(rig_spec, {}, simulated=sim)
    async with AsyncExitStack() as stack:
        opened: dict[str, object] = {}
        opened_options: dict[str, object] = {}
        for name, bus in resolved.buses.items():
            options = bus.options
            if sim:
                simulated = await stack.enter_async_context(
                    bus.kind.simulate(name, bus.options, bus.devices)
                )
                options = simulated.options
                rig.peers.update(simulated.peers)
                rig.bus_descriptions[name] = simulated.description
            else:
                rig.bus_descriptions[name] = bus.kind.describe(options)
            opened_options[name] = options
            opened[name] = await stack.enter_async_context(bus.kind.open(name, options))
            if clock is None:
                clock = bus.kind.clock(opened[name])
        rig.buses = opened
        if sim:  # the devices are built with the options opened (a pty path, say)
            resolved = dataclasses.replace(
                resolved,
                buses={
                    n: dataclasses.replace(b, options=opened_options[n])
                    for n, b in resolved.buses.items()
                },
            )
        rig.clock = clock
        components = build_components(resolved, clock, opened, auto_init=False)
        for component in components:
            c_spec = rig_spec.component(component.device_name)
            if isinstance(component, Actuator) and not c_spec.limits.is_empty():
                component.add_active_hook(_limits_hook(c_spec.limits))
            if safety.watchdog_timeout is not None and isinstance(component.device, Watchdog):
                component.add_active_hook(_watchdog_hook(safety.watchdog_timeout))
            rig.components[component.device_name] = component
            if on_component is not None:
                on_component(component)
        for component in components:
            await stack.enter_async_context(component)
        stack.push_async_callback(rig.leave_safe)
        if init:
            for component in components:
                await component.init()
        for t in rig_spec.timers:
            timer = EventTimer(
                t.period_ms, clock=clock, name=t.name, late_threshold_ms=t.late_threshold_ms
            )
            rig.timers[t.name] = timer
            if on_timer is not None:
                on_timer(timer)
            await _enter(stack, timer)
        for name, resolved_bus in resolved.buses.items():
            if resolved_bus.timer is not None:
                binding = resolved_bus.kind.bind_timer(
                    opened[name], resolved_bus.options, rig.timers[resolved_bus.timer]
                )
                if binding is not None:  # e.g. a CAN bus's SYNC on the timer driving it
                    await _enter(stack, binding)
        for g in rig_spec.groups:
            axes = [rig.actuator(a) for a in g.axes]
            limits = [
                AxisLimits(
                    _first(g.max_velocity, rig_spec.component(a).limits.velocity),
                    _first(g.max_acceleration, rig_spec.component(a).limits.acceleration),
                    g.max_jerk,
                )
                for a in g.axes
            ]
            group = AxisGroup(
                axes,
                timer=rig.timers[g.timer],
                limits=limits,
                goal_time=g.goal_time,
                synchronization=g.synchronization,
                name=g.name,
            )
            rig.groups[g.name] = group
            await _enter(stack, group)
        if handle_sigquit and safety.estop_on_sigquit:
            tg = anyio.create_task_group()
            await _enter(stack, tg)
            stack.callback(tg.cancel_scope.cancel)
            await tg.start(_estop_on_sigquit, rig)
        yield rig


async def _enter(stack: AsyncExitStack, cm: AbstractAsyncContextManager[object]) -> None:
    """Enter ``cm`` on ``stack``, exiting it as if its block had ended normally: an
    exception of the rig's user passes by it as it is, not wrapped in an exception group by
    its task group (the exit path runs the same)."""
    await cm.__aenter__()

    async def leave() -> None:
        await cm.__aexit__(None, None, None)

    stack.push_async_callback(leave)


def _first(*values: float | None) -> float:
    for value in values:
        if value is not None:
            return value
    return math.inf  # (never: parse_rig requires one)


async def _leave_safe(rig: Rig) -> None:
    """The exit path: every actuator in ``safety.on_exit``'s state, at once, bounded."""
    safety = rig.spec.safety
    reports: dict[str, SafeStopReport] = {}

    async def one(actuator: Actuator) -> None:
        reports[actuator.device_name] = await _safe_stop(actuator, safety)

    with anyio.CancelScope(shield=True):
        async with anyio.create_task_group() as tg:
            for actuator in rig.actuators:
                tg.start_soon(one, actuator)
    rig.exit_report = [reports[a.device_name] for a in rig.actuators]


async def _estop_on_sigquit(rig: Rig, *, task_status: anyio.abc.TaskStatus[None]) -> None:
    try:
        receiver = anyio.open_signal_receiver(signal.SIGQUIT)
        signals = receiver.__enter__()
    except (ValueError, RuntimeError, NotImplementedError):  # not the main thread
        task_status.started()
        return
    try:
        task_status.started()
        async for _ in signals:
            log.warning("sigquit_estop")
            try:
                await rig.estop()
            except HALError as exc:
                log.error("sigquit_estop_failed", error=str(exc))
    finally:
        receiver.__exit__(None, None, None)
