"""The rig of a MuJoCo arm app: its hardware read from a rig file (``rigs/arm2.yaml``,
``rigs/arm6.yaml``, or ``openel-async run arm2|arm6 --rig FILE``).

The app takes everything by name: its joints (one ``joint`` component each, named after the
joint), its sensors and effectors, the timer and the axis group. The rig file gives

- the MuJoCo bus (the model, its keyframe, the pacing): the app builds the simulation from
  the bus's options before the rig opens (:func:`~.arm_demo.open_arm_sim`: it plans on the
  model and takes a picture of the initial state first) and opens the rig on it
  (:func:`open_arm_rig`); ``--virtual`` and ``--realtime`` override the bus's ``pacing``;
- the timer the group streams on (``--period-ms`` overrides its ``period_ms``);
- the group: its axes (the app's joints, in order), its limits (the default limits of every
  motion; a joint's ``limits.position`` also narrows the range the app plans in), its goal
  time and synchronization. The app adds what a rig file cannot say -- the tolerances, the
  log of the whole run and whether it logs actual positions -- so it builds the
  :class:`~openel_async.motion.AxisGroup` itself from the group's entry (:func:`arm_group`),
  and the rig opens without it: one group on the joints;
- the safety: the state ``on_exit`` leaves the actuators in (the shipped rigs: ``hold``).

This module imports no MuJoCo at import time (the driver is imported when a rig loads).
"""

from __future__ import annotations

import dataclasses
from collections.abc import AsyncIterator, Sequence
from contextlib import asynccontextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from openel_async.actuator import Actuator
from openel_async.app import AppContext, AppUnavailable
from openel_async.device import ActuatorDevice
from openel_async.motion import AxisGroup, AxisLimits, Tolerances

from .arm_demo import LOG_MARGIN_S, check_period_ms

if TYPE_CHECKING:  # the rig package (yaml, msgspec) loads when a rig is: not for --help
    from openel_async.rig import GroupSpec, ResolvedRig, Rig, TimerSpec
    from openel_mujoco import MujocoBusOptions, MujocoSim

__all__ = ["RIGS", "ArmRigSpec", "arm_group", "load_arm_rig", "open_arm_rig"]

RIGS = Path(__file__).parent / "rigs"
"""The shipped rig files."""


@dataclass(frozen=True)
class ArmRigSpec:
    """An arm app's rig, checked against what the app needs and set to the run's options;
    not opened yet."""

    resolved: ResolvedRig
    """The rig to open: without the app's group, the timer at the run's period."""
    group: GroupSpec
    """The app's group (built by :func:`arm_group`)."""
    timer: TimerSpec
    """The timer the group streams on, at the run's period."""
    bus: str
    """The MuJoCo bus the joints are on."""
    options: MujocoBusOptions
    """That bus's options: the simulation to build."""

    @property
    def joints(self) -> tuple[str, ...]:
        return self.group.axes

    @property
    def period_ms(self) -> float:
        return self.timer.period_ms

    @property
    def source(self) -> str:
        """The rig file's name (``arm2.yaml``)."""
        return Path(self.resolved.spec.source).name

    @property
    def limits(self) -> list[AxisLimits]:
        """The group's limits of each axis (a velocity or acceleration the group does not
        give comes from the joint's ``limits``)."""
        g, spec = self.group, self.resolved.spec
        limits = []
        for axis in g.axes:
            joint = spec.component(axis).limits
            velocity = g.max_velocity if g.max_velocity is not None else joint.velocity
            acceleration = (
                g.max_acceleration if g.max_acceleration is not None else joint.acceleration
            )
            assert velocity is not None and acceleration is not None  # (parse_rig checks)
            limits.append(AxisLimits(velocity, acceleration, g.max_jerk))
        return limits

    def limits_text(self) -> str:
        """``AxisGroup arm2 at most 2.5 rad/s, 15 rad/s^2, 200 rad/s^3`` (per axis when
        they differ)."""
        shown = []
        for a in dict.fromkeys(self.limits):
            shown.append(
                f"{a.max_velocity:g} rad/s, {a.max_acceleration:g} rad/s^2, {a.max_jerk:g} rad/s^3"
            )
        return f"AxisGroup {self.group.name} at most {'; '.join(shown)}"

    def position_range(self, joint: str, model: tuple[float, float]) -> tuple[float, float]:
        """The range ``joint`` may be commanded in: the model's range ``model`` narrowed by
        the rig's ``limits.position`` and the joint's ``position_limits`` param.
        ValueError when nothing is left."""
        c = self.resolved.spec.component(joint)
        low, high = model
        for extra in (c.limits.position, c.params.get("position_limits")):
            if extra is not None:
                low, high = max(low, float(extra[0])), min(high, float(extra[1]))
        if not low < high:
            raise ValueError(
                f"rig {self.source}: the position limits of {joint} leave nothing of its "
                f"range [{model[0]:+.3f}, {model[1]:+.3f}] in the model"
            )
        return low, high


def load_arm_rig(
    ctx: AppContext,
    default: Path,
    *,
    group: str,
    joints: Sequence[str],
    actuators: Sequence[str] = (),
    sensors: Sequence[str] = (),
    period_ms: float | None = None,
) -> ArmRigSpec:
    """The rig of ``--rig FILE`` (``ctx.rig_spec``) or ``default``, checked for what the app
    takes by name -- the group ``group`` over ``joints`` (in order) on a timer, the joints
    on one MuJoCo bus, the other ``actuators`` and the ``sensors`` -- with its timer at
    ``period_ms`` (None: the rig's period; either is checked as ``--period-ms`` is) and
    without the group (the app builds it: :func:`arm_group`).

    AppUnavailable when the MuJoCo driver cannot load; ValueError (BadParameterError: a
    rig file that is wrong) naming what is missing."""
    try:
        from openel_mujoco import mujoco_buses
    except Exception as exc:  # ImportError: MuJoCo or the driver is not installed
        raise AppUnavailable("MuJoCo", f"{type(exc).__name__}: {exc}") from exc
    from openel_async.rig import load_rig, resolve_rig

    resolved = ctx.rig_spec if ctx.rig_spec is not None else resolve_rig(load_rig(default))
    spec = resolved.spec
    where = f"rig {Path(spec.source).name}"
    names = {c.name for c in spec.components}
    for name in (*joints, *actuators, *sensors):
        if name not in names:
            raise ValueError(f"{where} has no component {name!r} (the app takes it by name)")
        wants_sensor = name in sensors
        if issubclass(resolved.classes[name], ActuatorDevice) == wants_sensor:
            wanted = "a sensor" if wants_sensor else "an actuator"
            raise ValueError(f"{where}: the component {name!r} is not {wanted}")
    found = next((g for g in spec.groups if g.name == group), None)
    if found is None:
        raise ValueError(f"{where} has no group {group!r} (the app takes it by name)")
    if found.axes != tuple(joints):
        raise ValueError(
            f"{where}: group {group!r} moves {', '.join(found.axes)}; the app needs "
            f"{', '.join(joints)}, in this order"
        )
    buses = mujoco_buses(resolved)
    on = {spec.component(j).bus for j in joints}
    if len(on) != 1 or next(iter(on)) not in buses:
        raise ValueError(
            f"{where}: the joints {', '.join(joints)} must be on one MuJoCo bus (type: mujoco): "
            "the app plans on the arm's model"
        )
    bus = str(next(iter(on)))
    timer = next(t for t in spec.timers if t.name == found.timer)
    if period_ms is None:
        check_period_ms(timer.period_ms, f"{where}: timer {timer.name} period_ms")
    else:
        timer = dataclasses.replace(timer, period_ms=period_ms)
    adjusted = dataclasses.replace(
        spec,
        groups=tuple(g for g in spec.groups if g.name != group),
        timers=tuple(timer if t.name == timer.name else t for t in spec.timers),
    )
    return ArmRigSpec(dataclasses.replace(resolved, spec=adjusted), found, timer, bus, buses[bus])


@asynccontextmanager
async def open_arm_rig(
    rig: ArmRigSpec, sim: MujocoSim, ctx: AppContext | None = None
) -> AsyncIterator[Rig]:
    """Open ``rig`` on ``sim`` (built from its MuJoCo bus's options, not running: it runs
    while the rig is open) with ``ctx``'s ``--sim``; its components and timers are
    registered with ``ctx`` and it is kept in ``ctx.rigs`` (the run's last line says how it
    left the actuators). SIGQUIT e-stops it; at exit every actuator is left as the rig's
    ``safety.on_exit`` says."""
    from openel_async.rig import open_rig
    from openel_mujoco import with_simulation

    ctx = ctx if ctx is not None else AppContext()
    async with open_rig(
        with_simulation(rig.resolved, sim, rig.bus),
        sim=ctx.sim,
        handle_sigquit=True,
        on_component=ctx.add_component,
        on_timer=ctx.add_timer,
    ) as opened:
        ctx.rigs.append(opened)
        yield opened


def arm_group(
    opened: Rig,
    rig: ArmRigSpec,
    *,
    tolerances: Tolerances,
    planned_s: float,
    log_actual: bool = False,
) -> AxisGroup:
    """The app's AxisGroup (not entered) over the joints of ``opened``, on its timer, with
    the group's limits, goal time and synchronization from the rig and the app's
    ``tolerances``; its log holds ``planned_s`` seconds of motion plus
    :data:`~.arm_demo.LOG_MARGIN_S`."""
    axes: list[Actuator] = [opened.actuator(joint) for joint in rig.joints]
    g = rig.group
    return AxisGroup(
        axes,
        timer=opened.timer(rig.timer.name),
        limits=rig.limits,
        tolerances=tolerances,
        goal_time=g.goal_time,
        synchronization=g.synchronization,
        name=g.name,
        log_capacity=int((planned_s + LOG_MARGIN_S) * 1000.0 / rig.period_ms),
        log_actual=log_actual,
    )
