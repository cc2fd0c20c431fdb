"""The 6-DoF MuJoCo arm (``arm6``) picks the box up with its suction cup and places it:
``apps/arm6_pick_place.py`` and ``openel-async demo --app arm6``.

The sequence: home -> above the box -> down onto it -> suction on -> lift -> move over the
place location -> down -> suction off -> up -> home.

- **Devices**: they come from the rig ``rigs/arm6.yaml`` (or ``openel-async run arm6 --rig
  FILE``), taken by name (see :mod:`.arm_rig`): the model ``arm6`` from its keyframe
  ``home`` on a MuJoCo bus, its six joints as Actuators, the model's ``suction`` adhesion
  actuator as the Actuator ``suction``, a :class:`~openel_mujoco.effectors.MujocoEffector`
  (TORQUE = adhesion force in N, NO_EXCITE = off; it posts ``HOLDING`` when the pad holds
  something), the ``tool_pos`` and ``pad_touch`` sensors as Sensors, the timer ``arm6-sync``
  and the group ``arm6`` (its limits are those of the joint-space moves).
- **Joints**: one :class:`~openel_async.motion.AxisGroup` moves the six joints together
  (setpoints streamed on an EventTimer of the simulation clock; every motion
  time-synchronized: all joints leave and arrive on the same tick).
- **Targets**: :class:`Arm6Kinematics` is a closed-form inverse kinematics for the arm with the
  tool pointing straight down (the only orientation a top-down pick needs): base yaw towards
  the point, a two-link solution for shoulder and elbow in the vertical plane, the wrist pitch
  that makes the tool vertical, and the flange roll that keeps the pad square to the world axes
  (so the box keeps its orientation).  Vertical approaches and lifts are ``follow()`` of timed
  IK waypoints on the vertical line, the transfers are ``move_to`` (joint space, at a safe
  height).
- **Suction**: switched on once the pad presses on the box (COMPLETED when the physics applies
  the force); the grip is confirmed by the effector holding the box (the ``pad_touch`` sensor
  in contact with the suction on), the carry by the box's height after the lift.
- **Output**: live progress, then a plot of commanded vs actual joint positions, snapshots of
  the scene, and a summary with the box's displacement (``out/arm6_pick_place/``).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Final

import anyio

from openel_async import Actuator, EventTimer, HALError, Request, Sensor
from openel_async.app import AppContext, AppInfo, DemoOptions, LiveLine
from openel_async.logs import get_logger
from openel_async.motion import (
    AxisGroup,
    AxisLimits,
    GroupMotion,
    KinematicState,
    Planner,
    Tolerances,
    Waypoint,
)

from .arm_demo import (
    MAX_DURATION_S,
    ArmOptions,
    Artifacts,
    UnreachableError,
    add_common_arguments,
    arm_demo_args,
    arrival_spread,
    finish,
    fmt_mm,
    fmt_point,
    line_waypoints,
    open_arm_sim,
    options_from,
    pacing_name,
    preload_plotting,
    print_report,
    record_times,
    run_reported,
    save_plot,
    save_snapshot,
    spread_text,
    times_text,
)
from .arm_rig import RIGS, ArmRigSpec, arm_group, load_arm_rig, open_arm_rig

if TYPE_CHECKING:
    import mujoco

    from openel_mujoco import MujocoEffector, MujocoSim

__all__ = [
    "APP",
    "APP_INFO",
    "RIG",
    "Arm6Kinematics",
    "PickPlacePlan",
    "PickPlaceResult",
    "SequenceTooFastError",
    "StepRecord",
    "UnreachableError",
    "arm6_rig",
    "build_parser",
    "main",
    "min_duration_s",
    "open_sim",
    "plan_pick_place",
    "report",
    "run_app",
    "run_pick_place",
]

log = get_logger(__name__)

APP: Final = "arm6_pick_place"
RIG: Final = RIGS / "arm6.yaml"
"""The app's rig: the shipped ``arm6`` model on a MuJoCo bus (``--rig FILE`` replaces it)."""
GROUP: Final = "arm6"
"""The rig's axis group the app moves the joints with."""
SUCTION: Final = "suction"
"""The rig's suction cup (an effector: TORQUE is the adhesion force)."""
TOOL: Final = "tool_pos"
"""The rig's sensor of the pad face's position (x, y, z in m)."""
TOUCH: Final = "pad_touch"
"""The rig's touch sensor of the pad (N)."""
JOINTS: Final = (
    "base_yaw",
    "shoulder_pitch",
    "elbow_pitch",
    "wrist_roll",
    "wrist_pitch",
    "flange_roll",
)
DEFAULT_DURATION_S: Final = 8.0
DEFAULT_PLACE_M: Final = (0.20, 0.40)
APPROACH_HEIGHT_M: Final = 0.08
"""Height of the tool above the box's top face before descending and after lifting."""
PRESS_M: Final = 0.003
"""How far below the box's top face the pad is commanded, so that it presses on the box
despite the arm's gravity sag (the position servos leave the tool ~2 mm low with the arm
reaching out; the contact stops it on the box)."""
SUCTION_FORCE_N: Final = 20.0
"""Adhesion force of the suction cup when on (the ``suction`` actuator's largest)."""
DWELL_S: Final = 0.25
"""Simulated seconds the arm waits after switching the suction on or off."""
MOVE_LIMITS: Final = AxisLimits(max_velocity=2.0, max_acceleration=8.0, max_jerk=80.0)
"""The limits of the joint-space moves in the shipped rig (its group's): the planning's default."""
LINE_LIMITS: Final = AxisLimits(max_velocity=2.0, max_acceleration=60.0, max_jerk=3000.0)
"""Limits of the vertical lines (timed waypoints: the timing comes from the waypoints; short
segments need brief acceleration peaks, see apps/arm2_square.py)."""
GOAL_TOLERANCE_RAD: Final = 0.01
"""Above the shoulder's gravity sag (<= 0.0053 rad with the arm stretched)."""
PATH_TOLERANCE_RAD: Final = 0.2
LINE_POINTS: Final = 8

# Share of --duration taken by each motion (the suction dwells come on top).
_SHARES: Final = {
    "above box": 0.18,
    "down": 0.09,
    "lift": 0.09,
    "move": 0.20,
    "place down": 0.09,
    "up": 0.09,
    "home": 0.26,
}


# -- kinematics ---------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Arm6Kinematics:
    """Closed-form inverse kinematics of ``arm6`` with the tool pointing straight down.

    Geometry (m): the shoulder axis is ``shoulder_height`` above the floor on the base axis;
    ``upper_arm`` from the shoulder to the elbow, ``forearm`` from the elbow to the wrist-pitch
    axis, ``tool`` from the wrist-pitch axis to the pad face (site ``tool``).  Joint ranges
    come from the model.
    """

    shoulder_height: float
    upper_arm: float
    forearm: float
    tool: float
    ranges: tuple[tuple[float, float], ...]

    @classmethod
    def from_model(cls, model: mujoco.MjModel) -> Arm6Kinematics:
        def pos(body: str) -> Sequence[float]:
            return [float(v) for v in model.body(body).pos]

        return cls(
            shoulder_height=pos("turret")[2] + pos("upper_arm")[2],
            upper_arm=pos("forearm")[2],
            forearm=pos("wrist1")[0] + pos("wrist2")[0],
            tool=pos("wrist3")[0] + pos("tool")[0] + float(model.site("tool").pos[0]),
            ranges=tuple(
                (float(model.joint(j).range[0]), float(model.joint(j).range[1])) for j in JOINTS
            ),
        )

    def tool_down(self, x: float, y: float, z: float) -> list[float]:
        """Joint angles that put the pad face centre on ``(x, y, z)`` with the tool pointing
        down and the pad square to the world axes (elbow up).  Raises
        :class:`UnreachableError`."""
        yaw = math.atan2(y, x)
        r = math.hypot(x, y)
        # wrist-pitch axis: straight above the target by the tool length
        wr, wz = r, z + self.tool - self.shoulder_height
        d = math.hypot(wr, wz)
        l1, l2 = self.upper_arm, self.forearm
        if not abs(l1 - l2) <= d <= l1 + l2:
            raise UnreachableError(
                f"tool point ({x:.3f}, {y:.3f}, {z:.3f}) m is out of reach pointing down: the "
                f"wrist would be {d:.3f} m from the shoulder, reach {abs(l1 - l2):.3f} to "
                f"{l1 + l2:.3f} m"
            )
        c = max(-1.0, min(1.0, (d * d - l1 * l1 - l2 * l2) / (2.0 * l1 * l2)))
        beta = -math.acos(c)  # forearm relative to the upper arm: elbow up
        a1 = math.atan2(wz, wr) - math.atan2(l2 * math.sin(beta), l1 + l2 * math.cos(beta))
        shoulder = math.pi / 2 - a1  # the upper arm is vertical at zero, pitch tilts forward
        elbow = -beta - math.pi / 2  # the forearm is horizontal at zero
        wrist = math.pi / 2 - shoulder - elbow  # total pitch pi/2: the tool points down
        q = [yaw, shoulder, elbow, 0.0, wrist, yaw]
        for name, value, (lo, hi) in zip(JOINTS, q, self.ranges, strict=True):
            if not lo <= value <= hi:
                raise UnreachableError(
                    f"tool point ({x:.3f}, {y:.3f}, {z:.3f}) m needs {name} = {value:+.3f} rad, "
                    f"outside its range [{lo:+.3f}, {hi:+.3f}]"
                )
        return q


# -- the rig ---------------------------------------------------------------------------------------


def arm6_rig(ctx: AppContext | None = None, period_ms: float | None = None) -> ArmRigSpec:
    """The app's rig: ``ctx``'s ``--rig FILE`` or :data:`RIG`, its timer at ``period_ms``
    (None: the rig's); ValueError for a rig without what the app takes by name,
    :class:`~openel_async.app.AppUnavailable` without MuJoCo."""
    rig = load_arm_rig(
        ctx if ctx is not None else AppContext(),
        RIG,
        group=GROUP,
        joints=JOINTS,
        actuators=(SUCTION,),
        sensors=(TOOL, TOUCH),
        period_ms=period_ms,
    )
    from openel_mujoco import MujocoEffector  # (loads: load_arm_rig imported the driver)

    if not issubclass(rig.resolved.classes[SUCTION], MujocoEffector):
        raise ValueError(
            f"rig {rig.source}: the component {SUCTION!r} is not a MuJoCo effector "
            "(device: effector): the app switches the suction with its adhesion force"
        )
    return rig


def open_sim(
    *, realtime: bool | None = None, ctx: AppContext | None = None, rig: ArmRigSpec | None = None
) -> MujocoSim:
    """The simulation of the rig's MuJoCo bus (default: :func:`arm6_rig`), not running,
    paced as ``realtime`` says (None: as the rig says); its clock (and scene, for a
    recorder or a live view) registered with ``ctx``; raises
    :class:`~openel_async.app.AppUnavailable` when MuJoCo or the model cannot load."""
    return open_arm_sim(rig if rig is not None else arm6_rig(ctx), realtime=realtime, ctx=ctx)


def kinematics(sim: MujocoSim, rig: ArmRigSpec | None = None) -> Arm6Kinematics:
    """The arm's kinematics from the model of ``sim``, each joint's range narrowed by the
    rig's position limits (none: the model's ranges)."""
    kin = Arm6Kinematics.from_model(sim.model)
    if rig is None:
        return kin
    return replace(
        kin, ranges=tuple(rig.position_range(j, r) for j, r in zip(JOINTS, kin.ranges, strict=True))
    )


# -- the run --------------------------------------------------------------------------------------


@dataclass
class StepRecord:
    name: str
    motion_id: int | None
    outcome: str
    setpoint_spread_ticks: int = 0
    tool_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    sim_s: float = 0.0


@dataclass
class PickPlaceResult:
    pacing: str
    period_ms: float
    duration_s: float
    pick_m: tuple[float, float, float]
    place_m: tuple[float, float, float]
    box_start_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    box_end_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    gripped: bool = False
    """The suction held the box once on (the effector's HOLDING: the pad touches it)."""
    carried: bool = False
    """The box was lifted with the tool (at least 3 cm off the floor after the lift)."""
    grip_force_n: float = 0.0
    steps: list[StepRecord] = field(default_factory=list)
    sim_time_s: float = 0.0
    wall_time_s: float = 0.0
    timer_ticks: int = 0
    timer_missed: int = 0
    artifacts: Artifacts = field(default_factory=Artifacts)
    rig: str = ""
    """The rig file and the group's limits (the summary's ``rig`` line)."""

    @property
    def box_moved_m(self) -> float:
        return math.dist(self.box_start_m[:2], self.box_end_m[:2])

    @property
    def place_error_m(self) -> float:
        """Horizontal distance of the box's final position from the place location."""
        return math.dist(self.box_end_m[:2], self.place_m[:2])

    @property
    def max_setpoint_spread_ticks(self) -> int:
        return max((s.setpoint_spread_ticks for s in self.steps), default=0)

    def lines(self) -> list[str]:
        motions = [s for s in self.steps if s.motion_id is not None]
        ok = sum(s.outcome == "succeeded" for s in motions)
        picked = (
            "picked and carried"
            if self.carried
            else ("gripped but not carried" if self.gripped else "NOT picked (no contact)")
        )
        lines = [
            f"sequence           {' -> '.join(s.name for s in self.steps)}",
            f"motions            {ok}/{len(motions)} succeeded (AxisGroup of 6 joints, "
            f"period {self.period_ms:g} ms), joint setpoints arrive "
            f"{spread_text(self.max_setpoint_spread_ticks, self.period_ms)}",
            *([f"rig                {self.rig}"] if self.rig else []),
            f"box                {picked}; contact force {self.grip_force_n:.1f} N with the "
            f"suction on",
            f"box moved          from {fmt_point(self.box_start_m)} to "
            f"{fmt_point(self.box_end_m)} ({self.box_moved_m * 100:.1f} cm)",
            f"place location     {fmt_point(self.place_m)}: the box is "
            f"{fmt_mm(self.place_error_m)} from it",
            f"time               {times_text(self)}",
        ]
        return lines


def _box_position(sim: MujocoSim) -> tuple[float, float, float]:
    """The box's centre from the simulation state (ground truth for the summary: the box is
    not a device)."""
    x, y, z = (float(v) for v in sim.data.body("box").xpos)
    return x, y, z


class _Progress:
    """TimerObserver: the live line, from the tool_pos sensor every ``every`` ticks."""

    def __init__(
        self, sim: MujocoSim, tool: Sensor, suction: MujocoEffector, live: LiveLine, every: int
    ) -> None:
        self.sim = sim
        self.tool = tool
        self.suction = suction
        self.live = live
        self.every = every
        self.step = "start"
        self._count = 0

    async def notify_timer(self, timer: EventTimer) -> None:
        self._count += 1
        if self._count % self.every:
            return
        x, y, z = await self.tool.get_value()
        bx, by, bz = _box_position(self.sim)
        self.live.update(
            f"{self.step:<12} tool ({x:+.3f}, {y:+.3f}, {z:+.3f}) m  "
            f"box ({bx:+.3f}, {by:+.3f}, {bz:+.3f}) m  "
            f"suction {_suction_state(self.suction)}  "
            f"t={self.sim.time_ns / 1e9:6.3f} s sim"
        )


def _suction_state(suction: MujocoEffector) -> str:
    if suction.holding:
        return "holds"
    return "on   " if suction.on else "off  "


@dataclass(frozen=True, slots=True)
class PickPlacePlan:
    """Joint targets and paths of the sequence, solved and timed before anything moves."""

    box: tuple[float, float, float]
    pick: tuple[float, float, float]
    """Where the pad face goes down to: the box's top face, pressed by ``PRESS_M``."""
    above_pick: list[float]
    above_place: list[float]
    home: list[float]
    down: list[Waypoint]
    lift: list[Waypoint]
    place_down: list[Waypoint]
    up: list[Waypoint]
    durations: dict[str, float]


class SequenceTooFastError(ValueError):
    """``--duration`` is too short for the arm's limits (the message names the shortest)."""


def plan_pick_place(
    sim: MujocoSim,
    place: tuple[float, float],
    duration: float,
    rig: ArmRigSpec | None = None,
) -> PickPlacePlan:
    """Solve every target (the box's position comes from the simulation's initial state) and
    plan every motion offline as the group will, from rest to rest, with ``rig``'s group
    limits and joint ranges (none: :data:`MOVE_LIMITS`, the model's ranges).

    Raises :class:`UnreachableError` naming ``--place`` for a point out of reach and
    :class:`SequenceTooFastError` naming ``--duration`` and the shortest sequence when
    ``duration`` is too short for the group's limits.
    """
    try:
        return _plan(sim, place, duration, rig)
    except UnreachableError as exc:
        raise UnreachableError(f"--place {place[0]:g} {place[1]:g}: {exc}") from exc
    except HALError as exc:
        shortest = min_duration_s(sim, place, rig=rig)
        if shortest is None:
            raise SequenceTooFastError(
                f"--place {place[0]:g} {place[1]:g}: the arm cannot put the box there "
                f"smoothly in any --duration up to {MAX_DURATION_S:g} s ({exc})"
            ) from exc
        raise SequenceTooFastError(
            f"--duration {duration:g}: the sequence takes at least {shortest:.2f} s of arm "
            f"motion at the arm's limits (--place {place[0]:g} {place[1]:g})"
        ) from exc


def min_duration_s(
    sim: MujocoSim,
    place: tuple[float, float],
    *,
    resolution: float = 0.05,
    rig: ArmRigSpec | None = None,
) -> float | None:
    """The shortest ``--duration`` (s, rounded up to ``resolution``) the arm's limits allow
    for ``place`` (``rig``'s, see :func:`plan_pick_place`); None when none up to
    :data:`MAX_DURATION_S` does."""

    def plans(duration: float) -> bool:
        try:
            _plan(sim, place, duration, rig)
        except HALError:
            return False
        return True

    if not plans(MAX_DURATION_S):
        return None
    low, high = 0.0, MAX_DURATION_S
    while high - low > resolution / 2:
        middle = 0.5 * (low + high)
        low, high = (low, middle) if plans(middle) else (middle, high)
    return math.ceil(high / resolution - 1e-9) * resolution


def _plan(
    sim: MujocoSim, place: tuple[float, float], duration: float, rig: ArmRigSpec | None
) -> PickPlacePlan:
    """:func:`plan_pick_place` without the messages: raises :class:`UnreachableError` and
    the planner's :class:`HALError`."""
    kin = kinematics(sim, rig)
    move_limits = rig.limits if rig is not None else [MOVE_LIMITS] * len(JOINTS)
    box = _box_position(sim)
    half = float(sim.model.geom("box").size[2])
    top = box[2] + half
    pick = (box[0], box[1], top - PRESS_M)
    above_pick = (box[0], box[1], top + APPROACH_HEIGHT_M)
    place_z = 2 * half - PRESS_M  # the carried box's bottom face on the floor
    place_at = (place[0], place[1], place_z)
    above_place = (place[0], place[1], place_z + APPROACH_HEIGHT_M)
    d = {name: share * duration for name, share in _SHARES.items()}

    def line(
        start: tuple[float, float, float], end: tuple[float, float, float], seconds: float
    ) -> list[Waypoint]:
        return line_waypoints(
            lambda p: kin.tool_down(*p), start, end, duration=seconds, points=LINE_POINTS
        )

    plan = PickPlacePlan(
        box=box,
        pick=pick,
        above_pick=kin.tool_down(*above_pick),
        above_place=kin.tool_down(*above_place),
        home=[0.0] * len(JOINTS),
        down=line(above_pick, pick, d["down"]),
        lift=line(pick, above_pick, d["lift"]),
        place_down=line(above_place, place_at, d["place down"]),
        up=line(place_at, above_place, d["up"]),
        durations=d,
    )
    planner = Planner(len(JOINTS), kin.ranges, [math.inf] * len(JOINTS))
    n = len(JOINTS)
    rest = [0.0] * n
    position = [float(v) for v in sim.data.qpos[:n]]
    moves = {"above box": plan.above_pick, "move": plan.above_place, "home": plan.home}
    paths = {"down": plan.down, "lift": plan.lift, "place down": plan.place_down, "up": plan.up}
    for name in ("above box", "down", "lift", "move", "place down", "up", "home"):
        start = KinematicState(position, rest, rest)
        if name in moves:
            position = moves[name]
            planner.move(0, start, position, move_limits, duration=d[name])
        else:
            points = [(list(w.positions), w.time) for w in paths[name]]
            planner.waypoints(0, start, points, [LINE_LIMITS] * n)
            position = points[-1][0]
    return plan


class _Sequence:
    """The steps of the run: await a group motion and record it, switch the suction."""

    def __init__(
        self,
        sim: MujocoSim,
        group: AxisGroup,
        suction: Actuator,
        tool: Sensor,
        touch: Sensor,
        progress: _Progress | None,
        result: PickPlaceResult,
    ) -> None:
        self.sim = sim
        self.group = group
        self.suction_cup = suction
        self.tool = tool
        self.touch = touch
        self.progress = progress
        self.result = result

    async def step(self, name: str, motion: GroupMotion | None = None) -> StepRecord:
        """Record step ``name``, after waiting for ``motion`` (bounded) if there is one."""
        if self.progress is not None:
            self.progress.step = name
        record = StepRecord(name, None, "done")
        if motion is not None:
            await finish(motion)
            record.motion_id = motion.id
            record.outcome = motion.outcome.name.lower()
            record.setpoint_spread_ticks = arrival_spread(self.group.log.snapshot(), motion.id)
        x, y, z = await self.tool.get_value()
        record.tool_m = (x, y, z)
        record.sim_s = self.sim.time_ns / 1e9
        self.result.steps.append(record)
        return record

    async def suction(self, force_n: float | None) -> None:
        """Suction on with ``force_n`` (waits for the force: COMPLETED), or off (None); then
        dwell for the contact to settle."""
        with anyio.fail_after(5):
            if force_n is None:
                await self.suction_cup.set_value(0.0, Request.NO_EXCITE)
            else:
                await (await self.suction_cup.set_value(force_n, Request.TORQUE))
        await self.sim.sleep(DWELL_S)


async def run_pick_place(
    sim: MujocoSim,
    *,
    options: ArmOptions,
    place: tuple[float, float] = DEFAULT_PLACE_M,
    live: LiveLine | None = None,
    ctx: AppContext | None = None,
    rig: ArmRigSpec | None = None,
) -> PickPlaceResult:
    """Run the sequence on ``sim`` (the ``arm6`` simulation of ``rig``'s MuJoCo bus, not
    running yet: the rig runs it while it is open; default rig: :func:`arm6_rig` at
    ``options``' period) and write the files.

    Raises :class:`UnreachableError` or ``ValueError`` (see :func:`plan_pick_place`) before
    anything moves.
    """
    from openel_mujoco import MujocoEffector, TrajectoryRecorder

    rig = rig if rig is not None else arm6_rig(ctx, options.period_ms)
    plan = plan_pick_place(sim, place, options.duration, rig)
    box = plan.box
    q_above_pick, q_above_place, home = plan.above_pick, plan.above_place, plan.home
    down, lift_path, place_down, up = plan.down, plan.lift, plan.place_down, plan.up
    d = plan.durations

    result = PickPlaceResult(
        pacing=sim.pacing,
        period_ms=rig.period_ms,
        duration_s=options.duration,
        pick_m=plan.pick,
        place_m=(place[0], place[1], box[2]),
        box_start_m=box,
        rig=f"{rig.source}, {rig.limits_text()}",
    )
    out_dir = options.out_dir
    out_dir.mkdir(parents=True, exist_ok=True)
    await preload_plotting()  # before the physics runs: a lockstep run stays deterministic
    # The scene before the run (also warms the renderer up before anything runs in real time).
    first, _ = await save_snapshot(sim, out_dir / f"{APP}_start.png")
    lift: Path | None = None
    async with open_arm_rig(rig, sim, ctx) as opened:  # the physics runs while it is open
        # (on the rig's joints: the devices of the components)
        recorder = TrajectoryRecorder(sim, list(JOINTS), every=max(1, round(rig.period_ms)))
        group = arm_group(
            opened,
            rig,
            tolerances=Tolerances(goal=GOAL_TOLERANCE_RAD, path=PATH_TOLERANCE_RAD),
            planned_s=options.duration + 10.0,  # the dwells and the final rest on top
        )
        timer = group.timer
        suction = opened.actuator(SUCTION)
        cup = suction.device
        assert isinstance(cup, MujocoEffector)  # (arm6_rig checks it)
        tool, touch = opened.sensor(TOOL), opened.sensor(TOUCH)
        async with group:
            progress = None
            if live is not None:
                every = max(1, round(50.0 / rig.period_ms))  # every 50 ms of simulated time
                progress = _Progress(sim, tool, cup, live, every)
                timer.add_observer(progress)
            app = _Sequence(sim, group, suction, tool, touch, progress, result)
            recorder.attach()
            try:
                await app.step("home")
                await app.step(
                    "above box", await group.move_to(q_above_pick, duration=d["above box"])
                )
                await app.step("down", await group.follow(down, LINE_LIMITS))
                await app.suction(SUCTION_FORCE_N)
                (result.grip_force_n,) = await touch.get_value()
                result.gripped = cup.holding
                await app.step("suction on")
                await app.step("lift", await group.follow(lift_path, LINE_LIMITS))
                result.carried = _box_position(sim)[2] - box[2] > 0.03
                if sim.pacing != "realtime":
                    # Rendering holds the GIL for ~0.2-0.3 s (MuJoCo's GL context and render
                    # calls), which would stall a real-time control loop holding the box.
                    lift, _ = await save_snapshot(sim, out_dir / f"{APP}_lift.png")
                await app.step("move", await group.move_to(q_above_place, duration=d["move"]))
                await app.step("down", await group.follow(place_down, LINE_LIMITS))
                await app.suction(None)
                await app.step("suction off")
                await app.step("up", await group.follow(up, LINE_LIMITS))
                await app.step("home", await group.move_to(home, duration=d["home"]))
                await sim.sleep(0.5)  # let the box come to rest
            finally:
                recorder.detach()
                if progress is not None:
                    timer.remove_observer(progress)
                if live is not None:
                    live.finish()
            record_times(result, timer, sim)
        result.box_end_m = _box_position(sim)
        log.info(
            "pick_place_done",
            carried=result.carried,
            box_from=[round(v, 4) for v in result.box_start_m],
            box_to=[round(v, 4) for v in result.box_end_m],
        )
        snapshot, skipped = await save_snapshot(sim, out_dir / f"{APP}_scene.png")
    result.artifacts = Artifacts(snapshot=snapshot, snapshot_skipped=skipped)
    for label, path in (("snapshot (start)", first), ("snapshot (lift)", lift)):
        if path is not None:
            result.artifacts.extra.append((label, path))
    result.artifacts.plot = await save_plot(
        recorder,
        out_dir / f"{APP}_joints.png",
        title=f"arm6 pick and place: commanded vs actual joint positions ({sim.pacing})",
    )
    return result


# -- command line ---------------------------------------------------------------------------------


def build_parser(prog: str = APP) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=prog,
        description="The 6-DoF MuJoCo arm picks the box with its suction cup and places it "
        "(joints synchronized by an AxisGroup). Every option is checked before the arm moves.",
    )
    add_common_arguments(
        parser,
        APP,
        duration_help=f"Seconds of arm motion for the whole sequence, the suction dwells "
        f"not counted, at most {MAX_DURATION_S:g} (default {DEFAULT_DURATION_S:g}).",
        default_duration=DEFAULT_DURATION_S,
    )
    parser.add_argument(
        "--place",
        type=float,
        nargs=2,
        default=list(DEFAULT_PLACE_M),
        metavar=("X", "Y"),
        help="Where to put the box down on the floor in m (default 0.20 0.40).",
    )
    return parser


async def main(ctx: AppContext) -> int:
    """The app ``arm6``: ``openel-async run arm6 [options]`` (``ctx.argv``)."""
    parser = build_parser(ctx.prog)
    args = parser.parse_args(ctx.argv)
    try:
        options = options_from(args, APP)
        if not all(math.isfinite(v) for v in args.place):
            raise ValueError(
                f"--place {args.place[0]:g} {args.place[1]:g}: two finite numbers of m"
            )
    except ValueError as exc:  # a bad option: argparse's message and exit status 2
        parser.error(str(exc))
    ctx.title = "MuJoCo arm6 demo"
    try:
        rig = arm6_rig(ctx, options.period_ms)
    except ValueError as exc:  # a rig without what the app takes by name
        parser.error(str(exc))
    sim = open_sim(realtime=options.realtime, ctx=ctx, rig=rig)
    place = (float(args.place[0]), float(args.place[1]))
    try:
        plan_pick_place(sim, place, options.duration, rig)
    except ValueError as exc:  # checked before anything runs
        parser.error(str(exc))
    return await run_app(sim, options, place=place, prog=ctx.prog, ctx=ctx, rig=rig)


async def run_app(
    sim: MujocoSim,
    options: ArmOptions,
    *,
    place: tuple[float, float] = DEFAULT_PLACE_M,
    prog: str = APP,
    ctx: AppContext | None = None,
    rig: ArmRigSpec | None = None,
) -> int:
    """Plan, run and report the pick and place on ``sim`` (the simulation of ``rig``'s
    MuJoCo bus, default :func:`arm6_rig`); returns the exit status (0: the box was carried;
    see :func:`~.arm_demo.run_reported`)."""
    rig = rig if rig is not None else arm6_rig(ctx, options.period_ms)

    async def run(live: LiveLine | None) -> PickPlaceResult:
        return await run_pick_place(sim, options=options, place=place, live=live, ctx=ctx, rig=rig)

    def reported(result: PickPlaceResult) -> bool:
        report(result)
        return result.carried

    return await run_reported(
        prog,
        plan=lambda: plan_pick_place(sim, place, options.duration, rig),
        run=run,
        report=reported,
        live=options.live,
    )


def report(result: PickPlaceResult) -> None:
    print_report(
        f"MuJoCo arm6 pick and place, {pacing_name(result.pacing)}",
        result.lines(),
        result.artifacts,
    )


def demo_args(options: DemoOptions) -> list[str]:
    """``openel-async demo --app arm6`` options as this app's command line (the app's
    defaults are the demo's)."""
    return arm_demo_args(options)


APP_INFO = AppInfo(
    name="arm6",
    description="the 6-DoF MuJoCo arm picks a box with its suction cup and places it "
    "elsewhere; PNG plots and snapshots",
    main=main,
    demo_args=demo_args,
    takes_rig=True,
    parser=build_parser,
)
"""The entry point ``arm6`` of the ``openel_async.apps`` group."""
