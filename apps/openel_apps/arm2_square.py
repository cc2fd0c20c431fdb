"""The 2-DoF MuJoCo arm (``arm2``) traces a square with its tip: the app ``arm2``
(``openel-async run arm2``, ``apps/arm2_square.py``) and the default ``openel-async demo``.

- **Kinematics** (:mod:`.arm2_kinematics`): :class:`PlanarArm` is the analytic forward and
  inverse kinematics of the arm's two hinges (both about z, so the tip moves in the
  horizontal plane of the shoulder).
  The link lengths, shoulder position and joint ranges are read from the model.  ``inverse``
  returns the elbow-``"up"`` or ``"down"`` solution and raises :class:`UnreachableError` for a
  point out of reach or one that needs a joint beyond its range.
- **Path**: each edge of the square is one :meth:`AxisGroup.follow` of ``points`` timed
  waypoints, the inverse kinematics of points along the straight edge.  The points are spaced by
  a minimum-jerk profile in time (the tip starts and stops each edge smoothly and rests at each
  corner), and are dense enough (16 per 0.15 m edge by default, <= 1 cm apart) that what the
  group plans between two of them, nearly a straight line in joint space, stays well under a
  millimetre from the edge: the tip's deviation comes from the servos' lag, not from the path.
  A single ``move_to`` per corner would be a straight line in joint space, and the tip would
  bow up to centimetres away from the edge.
- **Synchronization**: the two joints are axes of one :class:`~openel_async.motion.AxisGroup`
  streaming POSITION setpoints on an :class:`~openel_async.EventTimer` of the simulation clock;
  at each corner both setpoints arrive on the same tick (checked from ``group.log``).
- **Measurement**: the ``tip_pos`` framepos sensor, read through an OpenEL ``Sensor`` at every
  timer tick, gives the tip's deviation from the ideal square edges.
- **Rig**: the hardware comes from ``rigs/arm2.yaml`` (or ``openel-async run arm2 --rig
  FILE``): the MuJoCo bus of the model, the joints ``shoulder`` and ``elbow``, the sensor
  ``tip_pos``, the timer ``arm2-sync`` and the group ``arm2`` (its limits are those of the
  approach; the edges use :data:`EDGE_LIMITS`), taken by name (see :mod:`.arm_rig`).

Pacing is the rig's (real time in the shipped rig, as ``openel-async demo``); lockstep
(deterministic, as fast as the CPU allows) with ``--virtual``, real time with
``--realtime``.  At the end the run writes a plot of commanded vs actual joint positions, a
plot of the tip path against the square, and a snapshot of the scene (when OpenGL is
available).
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

import anyio
import anyio.to_thread

from openel_async import EventTimer, HALError, Sensor
from openel_async.app import AppContext, AppInfo, DemoOptions, LiveLine, atomic_output
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

from .arm2_kinematics import (
    DEFAULT_CENTER_M,
    DEFAULT_POINTS,
    DEFAULT_SIDE_M,
    Elbow,
    PlanarArm,
    distance_to_polygon,
    edge_waypoints,
    square_corners,
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
    from matplotlib.figure import Figure

    from openel_mujoco import MujocoSim

__all__ = [
    "APP",
    "APP_INFO",
    "RIG",
    "CornerArrival",
    "LapTooFastError",
    "PlanarArm",
    "SquareOptions",
    "SquareResult",
    "UnreachableError",
    "arm2_rig",
    "build_parser",
    "distance_to_polygon",
    "edge_waypoints",
    "main",
    "min_lap_s",
    "open_sim",
    "plan_square",
    "planar_arm",
    "report",
    "run_app",
    "run_square",
    "square_corners",
]

log = get_logger(__name__)

APP = "arm2_square"
RIG = RIGS / "arm2.yaml"
"""The app's rig: the shipped ``arm2`` model on a MuJoCo bus (``--rig FILE`` replaces it)."""
GROUP = "arm2"
"""The rig's axis group the app moves the joints with."""
JOINTS = ("shoulder", "elbow")
"""The rig's joint components (named after the model's joints), the group's axes in order."""
TIP = "tip_pos"
"""The rig's sensor of the tip's position (x, y, z in m)."""
DEFAULT_LAP_S = 5.0
"""Default ``--duration``: seconds per lap (also the lap of ``openel-async demo``)."""
MAX_POINTS = 1000
"""Most IK waypoints per edge (``--points``)."""
EDGE_LIMITS = AxisLimits(max_velocity=3.0, max_acceleration=60.0, max_jerk=3000.0)
"""Limits of the edges.  The timing comes from the waypoints' times; the group chains one
ruckig segment per waypoint with a through velocity that is only an estimate, so short
segments need brief acceleration peaks well above the smooth profile's (~3 rad/s^2)."""
GOAL_TOLERANCE_RAD = 2e-3
PATH_TOLERANCE_RAD = 0.15
"""Following error that aborts a motion: far above the servos' lag (~0.05 rad at full speed),
so only a stuck or colliding joint trips it."""


# -- the run ------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class SquareOptions:
    """What to trace: see :func:`build_parser`."""

    lap_s: float = DEFAULT_LAP_S
    laps: int = 1
    side: float = DEFAULT_SIDE_M
    center: tuple[float, float] = DEFAULT_CENTER_M
    elbow: Elbow = "up"
    points: int = DEFAULT_POINTS


@dataclass(frozen=True, slots=True)
class CornerArrival:
    """One edge's motion, ending at a corner."""

    corner: int
    """The corner reached, 1..4; corner 1 is where the square starts (and ends)."""
    motion_id: int
    outcome: str
    setpoint_spread_ticks: int
    """Ticks between the joints' last setpoints (0: the same tick)."""
    settled_after_s: float
    """Seconds from the last setpoint until every joint was within the goal tolerance (the
    group's goal check: the motion's success)."""
    tip_error_m: float
    """Distance of the tip from the corner when the motion succeeded."""


@dataclass
class SquareResult:
    """What a run measured (the summary's source; the tests assert on it)."""

    pacing: str
    period_ms: float
    lap_s: float
    laps: int
    side_m: float
    elbow: str
    corners: list[tuple[float, float]]
    arrivals: list[CornerArrival] = field(default_factory=list)
    approach_spread_ticks: int = 0
    max_deviation_m: float = 0.0
    rms_deviation_m: float = 0.0
    max_lag_m: float = 0.0
    deviation_samples: int = 0
    tip_path: list[tuple[float, float]] = field(default_factory=list)
    square_sim_s: float = 0.0
    sim_time_s: float = 0.0
    wall_time_s: float = 0.0
    timer_ticks: int = 0
    timer_missed: int = 0
    artifacts: Artifacts = field(default_factory=Artifacts)
    rig: str = ""
    """The rig file and the group's limits (the summary's ``rig`` line)."""

    @property
    def max_setpoint_spread_ticks(self) -> int:
        spreads = [a.setpoint_spread_ticks for a in self.arrivals]
        return max([self.approach_spread_ticks, *spreads])

    def lines(self) -> list[str]:
        settle = max((a.settled_after_s for a in self.arrivals), default=0.0)
        laps = "1 lap" if self.laps == 1 else f"{self.laps} laps"
        lines = [
            f"square             {laps} of a {self.side_m * 100:.0f} cm square, {self.lap_s:g} s "
            f"per lap, elbow {self.elbow}, AxisGroup period {self.period_ms:g} ms",
            *([f"rig                {self.rig}"] if self.rig else []),
            f"corners reached    {sum(a.outcome == 'succeeded' for a in self.arrivals)}"
            f"/{len(self.arrivals)}, tip within "
            f"{fmt_mm(max((a.tip_error_m for a in self.arrivals), default=0.0))} of the corner",
            f"synchronization    joint setpoints arrive "
            f"{spread_text(self.max_setpoint_spread_ticks, self.period_ms)} at every corner",
            f"actual arrival     every joint within {GOAL_TOLERANCE_RAD * 1e3:g} mrad of the "
            f"corner at most {settle * 1e3:.0f} ms after the last setpoint",
            f"tip deviation      max {fmt_mm(self.max_deviation_m)}, "
            f"rms {fmt_mm(self.rms_deviation_m)} from the ideal edges "
            f"({self.deviation_samples} tip_pos readings)",
            f"tip lag            max {fmt_mm(self.max_lag_m)} behind the commanded point",
            f"time               square traced in {self.square_sim_s:.2f} s, " + times_text(self),
        ]
        return lines


class _TipMonitor:
    """TimerObserver: reads the tip sensor at every tick, measures, and shows progress."""

    def __init__(
        self,
        tip: Sensor,
        arm: PlanarArm,
        group: AxisGroup,
        result: SquareResult,
        live: LiveLine | None,
        sim: MujocoSim,
    ) -> None:
        self.tip = tip
        self.arm = arm
        self.group = group
        self.result = result
        self.live = live
        self.sim = sim
        self.phase = "approach corner 1"
        self.tracing = False
        self._sum_sq = 0.0
        self._last_dev = 0.0

    async def notify_timer(self, timer: EventTimer) -> None:
        x, y, _z = await self.tip.get_value()
        result = self.result
        if self.tracing:
            dev = distance_to_polygon((x, y), result.corners)
            self._last_dev = dev
            result.deviation_samples += 1
            self._sum_sq += dev * dev
            result.rms_deviation_m = math.sqrt(self._sum_sq / result.deviation_samples)
            result.max_deviation_m = max(result.max_deviation_m, dev)
            result.tip_path.append((x, y))
            cx, cy = self.arm.forward(*self.group.commanded)
            result.max_lag_m = max(result.max_lag_m, math.hypot(x - cx, y - cy))
        if self.live is not None:
            off = (
                f"off-edge {self._last_dev * 1e3:5.2f} mm (max {result.max_deviation_m * 1e3:5.2f})"
                if self.tracing
                else "off-edge    -"
            )
            self.live.update(
                f"{self.phase:<26} tip ({x:+.3f}, {y:+.3f}) m  {off}  "
                f"t={self.sim.time_ns / 1e9:6.3f} s sim"
            )


def arm2_rig(ctx: AppContext | None = None, period_ms: float | None = None) -> ArmRigSpec:
    """The app's rig: ``ctx``'s ``--rig FILE`` or :data:`RIG`, its timer at ``period_ms``
    (None: the rig's); ValueError for a rig without what the app takes by name,
    :class:`~openel_async.app.AppUnavailable` without MuJoCo."""
    return load_arm_rig(
        ctx if ctx is not None else AppContext(),
        RIG,
        group=GROUP,
        joints=JOINTS,
        sensors=(TIP,),
        period_ms=period_ms,
    )


def open_sim(
    *, realtime: bool | None = None, ctx: AppContext | None = None, rig: ArmRigSpec | None = None
) -> MujocoSim:
    """The simulation of the rig's MuJoCo bus (default: :func:`arm2_rig`), not running,
    paced as ``realtime`` says (None: as the rig says); raises
    :class:`~openel_async.app.AppUnavailable` when MuJoCo or the model cannot load."""
    return open_arm_sim(rig if rig is not None else arm2_rig(ctx), realtime=realtime, ctx=ctx)


def planar_arm(sim: MujocoSim, rig: ArmRigSpec) -> PlanarArm:
    """The arm's kinematics from the model of ``sim``, each joint's range narrowed by the
    rig's position limits."""
    arm = PlanarArm.from_model(sim.model)
    return replace(
        arm,
        shoulder_range=rig.position_range("shoulder", arm.shoulder_range),
        elbow_range=rig.position_range("elbow", arm.elbow_range),
    )


async def run_square(
    sim: MujocoSim,
    *,
    options: ArmOptions,
    square: SquareOptions = SquareOptions(),
    live: LiveLine | None = None,
    ctx: AppContext | None = None,
    rig: ArmRigSpec | None = None,
) -> SquareResult:
    """Trace the square on ``sim`` (the simulation of ``rig``'s MuJoCo bus, not running yet:
    the rig runs it while it is open; default rig: :func:`arm2_rig` at ``options``'
    period) and write the files.

    Raises :class:`UnreachableError` or ``ValueError`` (see :func:`plan_square`) before
    anything moves.
    """
    from openel_mujoco import TrajectoryRecorder

    rig = rig if rig is not None else arm2_rig(ctx, options.period_ms)
    arm = planar_arm(sim, rig)
    corners = square_corners(square.center, square.side)
    edges = plan_square(arm, square)
    start = arm.inverse(*corners[0], square.elbow)
    result = SquareResult(
        pacing=sim.pacing,
        period_ms=rig.period_ms,
        lap_s=square.lap_s,
        laps=square.laps,
        side_m=square.side,
        elbow=square.elbow,
        corners=corners,
        rig=f"{rig.source}, {rig.limits_text()}",
    )
    out_dir = options.out_dir
    await preload_plotting()  # before the physics runs: a lockstep run stays deterministic
    async with open_arm_rig(rig, sim, ctx) as opened:  # the physics runs while it is open
        # (on the rig's joints: the devices of the components)
        recorder = TrajectoryRecorder(sim, list(JOINTS), every=max(1, round(rig.period_ms)))
        group = arm_group(
            opened,
            rig,
            tolerances=Tolerances(goal=GOAL_TOLERANCE_RAD, path=PATH_TOLERANCE_RAD),
            planned_s=3.0 + square.laps * square.lap_s,
            log_actual=True,
        )
        timer = group.timer
        tip = opened.sensor(TIP)
        async with group:
            monitor = _TipMonitor(tip, arm, group, result, live, sim)
            timer.add_observer(monitor)
            recorder.attach()
            try:
                await _trace(sim, group, tip, monitor, square, corners, edges, start, result)
            finally:
                recorder.detach()
                timer.remove_observer(monitor)
                if live is not None:
                    live.finish()
            record_times(result, timer, sim)
        log.info(
            "square_traced",
            laps=square.laps,
            max_deviation_mm=round(result.max_deviation_m * 1e3, 3),
            corners=len(result.arrivals),
        )
        # The group is closed (the joints hold their last position): the snapshot shows the
        # arm on the first corner, where the square ends.
        out_dir.mkdir(parents=True, exist_ok=True)
        snapshot, skipped = await save_snapshot(sim, out_dir / f"{APP}_scene.png")
    result.artifacts = Artifacts(snapshot=snapshot, snapshot_skipped=skipped)
    result.artifacts.plot = await save_plot(
        recorder,
        out_dir / f"{APP}_joints.png",
        title=f"arm2 square: commanded vs actual joint positions ({sim.pacing})",
    )
    tip_plot = out_dir / f"{APP}_tip.png"
    with anyio.fail_after(60), atomic_output(tip_plot) as partial:
        await anyio.to_thread.run_sync(lambda: plot_tip_path(partial, result))
    result.artifacts.extra.append(("tip path plot", tip_plot))
    return result


async def _trace(
    sim: MujocoSim,
    group: AxisGroup,
    tip: Sensor,
    monitor: _TipMonitor,
    square: SquareOptions,
    corners: list[tuple[float, float]],
    edges: list[list[Waypoint]],
    start: tuple[float, float],
    result: SquareResult,
) -> None:
    """Approach the first corner, then one ``follow()`` per edge and lap."""
    approach = await group.move_to(list(start))
    await finish(approach)
    result.approach_spread_ticks = arrival_spread(group.log.snapshot(), approach.id)
    traced_from = sim.time_ns
    monitor.tracing = True
    for lap in range(square.laps):
        for i, edge in enumerate(edges):
            corner = (i + 1) % 4
            monitor.phase = f"lap {lap + 1} edge {i + 1}/4 -> corner {corner + 1}"
            motion = await group.follow(edge, EDGE_LIMITS)
            await finish(motion)
            result.arrivals.append(await _arrival(corner + 1, motion, group, tip, corners[corner]))
    monitor.tracing = False
    result.square_sim_s = (sim.time_ns - traced_from) / 1e9


async def _arrival(
    corner: int,
    motion: GroupMotion,
    group: AxisGroup,
    tip: Sensor,
    target: tuple[float, float],
) -> CornerArrival:
    samples = group.log.snapshot()
    x, y, _ = await tip.get_value()
    return CornerArrival(
        corner=corner,
        motion_id=motion.id,
        outcome=motion.outcome.name.lower(),
        setpoint_spread_ticks=arrival_spread(samples, motion.id),
        settled_after_s=max(0.0, (motion.finished_ns or 0) - motion.planned_end_ns) / 1e9,
        tip_error_m=math.hypot(x - target[0], y - target[1]),
    )


def plot_tip_path(path: Path, result: SquareResult) -> Path:
    """The ideal square and the measured tip path, seen from above, as a PNG."""
    fig = tip_path_figure(result)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    return path


def tip_path_figure(result: SquareResult) -> Figure:
    """The tip path plot's figure (Agg canvas, no pyplot)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.4, 6.0))
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    xs = [c[0] for c in [*result.corners, result.corners[0]]]
    ys = [c[1] for c in [*result.corners, result.corners[0]]]
    ax.plot(xs, ys, "--", color="0.4", linewidth=1.2, label="ideal square")
    if result.tip_path:
        ax.plot(
            [p[0] for p in result.tip_path],
            [p[1] for p in result.tip_path],
            "-",
            color="tab:red",
            linewidth=1.0,
            label=f"tip (tip_pos sensor), max deviation {result.max_deviation_m * 1e3:.2f} mm",
        )
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(True, alpha=0.3)
    # Below the axes: inside, the legend covered a corner of the square.
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), fontsize="small")
    ax.set_title(f"arm2 tip path, seen from above ({result.pacing})")
    fig.tight_layout()
    return fig


# -- command line -------------------------------------------------------------------------------


def build_parser(prog: str = "arm2_square") -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=prog,
        description="The 2-DoF MuJoCo arm traces a square with its tip (inverse kinematics, "
        "joints synchronized by an AxisGroup). Every option is checked before the arm moves.",
    )
    add_common_arguments(
        parser,
        APP,
        duration_help=f"Seconds per lap of the square, all laps together at most "
        f"{MAX_DURATION_S:g} (default {DEFAULT_LAP_S:g}).",
        default_duration=DEFAULT_LAP_S,
    )
    parser.add_argument(
        "--laps", type=int, default=1, metavar="N", help="Laps of the square (default 1)."
    )
    parser.add_argument(
        "--side",
        type=float,
        default=DEFAULT_SIDE_M,
        metavar="M",
        help=f"Side length of the square in m (default {DEFAULT_SIDE_M:g}).",
    )
    parser.add_argument(
        "--center",
        type=float,
        nargs=2,
        default=list(DEFAULT_CENTER_M),
        metavar=("X", "Y"),
        help="Centre of the square in the arm's plane in m (default 0.35 0).",
    )
    parser.add_argument(
        "--elbow",
        choices=("up", "down"),
        default="up",
        help="Inverse kinematics solution to follow (default up).",
    )
    parser.add_argument(
        "--points",
        type=int,
        default=DEFAULT_POINTS,
        metavar="N",
        help=f"Inverse kinematics waypoints per edge, from 1 to {MAX_POINTS} "
        f"(default {DEFAULT_POINTS}).",
    )
    return parser


def square_from(args: argparse.Namespace, lap_s: float) -> SquareOptions:
    if not (args.laps >= 1 and args.laps * lap_s <= MAX_DURATION_S):
        raise ValueError(
            f"--laps {args.laps}: from 1, with --laps x --duration at most "
            f"{MAX_DURATION_S:g} s (here {args.laps} x {lap_s:g} s)"
        )
    if not 1 <= args.points <= MAX_POINTS:
        raise ValueError(f"--points {args.points}: from 1 to {MAX_POINTS}")
    if not (math.isfinite(args.side) and args.side > 0):
        raise ValueError(f"--side {args.side:g}: a length in m > 0")
    if not all(math.isfinite(v) for v in args.center):
        raise ValueError(f"--center {args.center[0]:g} {args.center[1]:g}: two finite numbers of m")
    return SquareOptions(
        lap_s=lap_s,
        laps=args.laps,
        side=float(args.side),
        center=(float(args.center[0]), float(args.center[1])),
        elbow=args.elbow,
        points=args.points,
    )


class LapTooFastError(ValueError):
    """The lap is faster than the joints' limits allow (the message names ``--duration``
    and the shortest lap)."""


def _plan_edges(arm: PlanarArm, square: SquareOptions) -> list[list[Waypoint]]:
    """The four edges' waypoints, each planned offline as the group will; raises
    :class:`UnreachableError` for a point out of reach and :class:`HALError` from the
    planner when the lap is too fast."""
    corners = square_corners(square.center, square.side)
    edges = [
        edge_waypoints(
            arm,
            corners[i],
            corners[(i + 1) % 4],
            duration=square.lap_s / 4.0,
            points=square.points,
            elbow=square.elbow,
        )
        for i in range(4)
    ]
    planner = Planner(
        len(JOINTS),
        [arm.shoulder_range, arm.elbow_range],
        [math.inf] * len(JOINTS),
    )
    for i, edge in enumerate(edges):
        start = arm.inverse(*corners[i], square.elbow)
        planner.waypoints(
            0,
            KinematicState(list(start), [0.0, 0.0], [0.0, 0.0]),
            [(list(w.positions), w.time) for w in edge],
            [EDGE_LIMITS] * len(JOINTS),
        )
    return edges


def _plans(arm: PlanarArm, square: SquareOptions, lap_s: float) -> bool:
    try:
        _plan_edges(arm, replace(square, lap_s=lap_s))
    except HALError:
        return False
    return True


def min_lap_s(arm: PlanarArm, square: SquareOptions, *, resolution: float = 0.05) -> float:
    """The shortest lap (s, rounded up to ``resolution``) the joints' edge limits allow for
    ``square`` (its ``lap_s`` ignored); :data:`MAX_DURATION_S` when none does."""
    low, high = 0.0, max(resolution, square.lap_s)
    while not _plans(arm, square, high):
        low, high = high, 2.0 * high
        if high > MAX_DURATION_S:
            return MAX_DURATION_S
    while high - low > resolution / 2:
        middle = 0.5 * (low + high)
        low, high = (low, middle) if _plans(arm, square, middle) else (middle, high)
    return math.ceil(high / resolution - 1e-9) * resolution


def plan_square(arm: PlanarArm, square: SquareOptions) -> list[list[Waypoint]]:
    """The four edges' waypoints, checked before anything moves.

    Raises :class:`UnreachableError` naming ``--side`` and ``--center`` for a point out of
    reach, and :class:`LapTooFastError` naming ``--duration`` and the shortest lap when the
    lap is too fast for the group's edge limits (each edge is planned offline, as the group
    will).
    """
    try:
        return _plan_edges(arm, square)
    except UnreachableError as exc:
        cx, cy = square.center
        raise UnreachableError(
            f"--side {square.side:g} --center {cx:g} {cy:g} --elbow {square.elbow}: the square "
            f"leaves the arm's reach: {exc}"
        ) from exc
    except HALError as exc:
        shortest = min_lap_s(arm, square)
        raise LapTooFastError(
            f"--duration {square.lap_s:g}: a lap takes at least {shortest:.2f} s at the "
            f"joints' limits ({square.side * 100:g} cm square, {square.points} "
            f"{'point' if square.points == 1 else 'points'} per edge)"
        ) from exc


async def main(ctx: AppContext) -> int:
    """The app ``arm2``: ``openel-async run arm2 [options]`` (``ctx.argv``)."""
    parser = build_parser(ctx.prog)
    args = parser.parse_args(ctx.argv)
    try:
        options = options_from(args, APP)
        square = square_from(args, options.duration)
    except ValueError as exc:  # a bad option: argparse's message and exit status 2
        parser.error(str(exc))
    ctx.title = "MuJoCo arm2 demo"
    try:
        rig = arm2_rig(ctx, options.period_ms)
    except ValueError as exc:  # a rig without what the app takes by name
        parser.error(str(exc))
    sim = open_sim(realtime=options.realtime, ctx=ctx, rig=rig)
    try:
        plan_square(planar_arm(sim, rig), square)
    except ValueError as exc:  # checked before anything runs
        parser.error(str(exc))
    return await run_app(sim, options, square=square, prog=ctx.prog, ctx=ctx, rig=rig)


async def run_app(
    sim: MujocoSim,
    options: ArmOptions,
    *,
    square: SquareOptions | None = None,
    prog: str = APP,
    ctx: AppContext | None = None,
    rig: ArmRigSpec | None = None,
) -> int:
    """Plan, run and report the square on ``sim`` (the simulation of ``rig``'s MuJoCo bus,
    default :func:`arm2_rig`; default square: one lap of ``options.duration``); returns the
    exit status (0: every corner reached; see :func:`~.arm_demo.run_reported`)."""
    square = square or SquareOptions(lap_s=options.duration)
    rig = rig if rig is not None else arm2_rig(ctx, options.period_ms)

    async def run(live: LiveLine | None) -> SquareResult:
        return await run_square(sim, options=options, square=square, live=live, ctx=ctx, rig=rig)

    def reported(result: SquareResult) -> bool:
        report(result)
        return all(a.outcome == "succeeded" for a in result.arrivals)

    return await run_reported(
        prog,
        plan=lambda: plan_square(planar_arm(sim, rig), square),
        run=run,
        report=reported,
        live=options.live,
    )


def report(result: SquareResult) -> None:
    print_report(
        f"MuJoCo arm2 square, {pacing_name(result.pacing)}", result.lines(), result.artifacts
    )


def demo_args(options: DemoOptions) -> list[str]:
    """``openel-async demo`` options as this app's command line (the app's defaults are the
    demo's)."""
    return arm_demo_args(options)


APP_INFO = AppInfo(
    name="arm2",
    description="the 2-DoF MuJoCo arm traces a square with its tip (inverse kinematics, "
    "AxisGroup); PNG plots and a snapshot",
    main=main,
    demo_args=demo_args,
    takes_rig=True,
    parser=build_parser,
)
"""The entry point ``arm2`` of the ``openel_async.apps`` group."""
