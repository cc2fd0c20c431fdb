"""so101: the SO-101 arm (LeRobot's six STS3215 servos) through named poses and a pick-like
motion, on any rig with its six components: ``openel-async run so101 [--rig RIG] [--sim]``.

- **Rig**: ``rigs/so101-mujoco.yaml`` (the shipped MuJoCo model ``so101``) by default;
  ``--rig rigs/so101.yaml`` is the real arm on its serial bus (``--sim``: simulated servos).
  The app takes six components by name and nothing else: the joints ``shoulder_pan``,
  ``shoulder_lift``, ``elbow_flex``, ``wrist_flex``, ``wrist_roll`` in radians, 0 in the middle
  of each joint's range (the servo's 2048 ticks once calibrated, the MuJoCo model's zero), and
  the ``gripper``'s opening, 0 (closed) to 1 (open).
- **Motion**: one :class:`~openel_async.motion.AxisGroup` moves the five joints together
  (time-synchronized ``move_to``, setpoints streamed on an EventTimer): the rig's group
  ``so101`` when it has one (its timer, limits and goal time; the app adds its tolerances),
  else the app's own on the rig's timer ``so101-sync`` or one of its own
  (:data:`DEFAULT_LIMITS`, :data:`DEFAULT_PERIOD_MS`). The gripper moves on its own
  (POSITION, awaited COMPLETED, bounded).
- **Output**: one line per pose reached (time, largest joint error, gripper opening); on a
  MuJoCo rig, snapshots of the pick and of the end (``out/so101/``, the summary says when a
  snapshot cannot be rendered). Exit status 0 when every pose was reached.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import time
from collections.abc import Sequence
from contextlib import AsyncExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Final

import anyio

from openel_async import Actuator, EventTimer, HALError, Request
from openel_async.app import AppContext, AppInfo, AppUnavailable, DemoOptions
from openel_async.device import ActuatorDevice
from openel_async.logs import get_logger
from openel_async.motion import AxisGroup, AxisLimits, Tolerances

from .arm_demo import add_pacing_arguments, check_out_dir, display_path, output_dir, save_snapshot

if TYPE_CHECKING:  # the rig package (yaml, msgspec) loads when a rig is: not for --help
    from openel_async.rig import ResolvedRig, Rig
    from openel_mujoco import MujocoSim

__all__ = [
    "APP_INFO",
    "ARM",
    "GRIPPER",
    "POSES",
    "RIG",
    "SEQUENCE",
    "Pose",
    "PoseRecord",
    "So101Result",
    "So101Rig",
    "Step",
    "build_parser",
    "main",
    "run_so101",
    "so101_rig",
]

log = get_logger(__name__)

APP: Final = "so101"
RIG: Final = Path(__file__).parent / "rigs" / "so101-mujoco.yaml"
"""The app's default rig: the MuJoCo model ``so101`` (``--rig FILE`` replaces it)."""
ARM: Final = ("shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll")
"""The joint components the group moves, in this order (radians, 0 = mid-range)."""
GRIPPER: Final = "gripper"
"""The gripper component (POSITION = opening, 0 closed .. 1 open)."""
GROUP: Final = "so101"
"""The rig's group the app moves the joints with, when it has one."""
TIMER: Final = "so101-sync"
"""The rig's timer the app's own group streams on, when the rig has no group."""
DEFAULT_LIMITS: Final = AxisLimits(max_velocity=1.5, max_acceleration=6.0, max_jerk=60.0)
"""The group's limits when the rig has no group ``so101`` (well below the STS3215's
4.7 rad/s)."""
DEFAULT_PERIOD_MS: Final = 10.0
"""The period of the app's own timer (a rig without ``so101-sync``)."""
GOAL_TOLERANCE_RAD: Final = 0.035
"""A pose is reached when every joint is this close (2 deg): above the servos' gravity sag
(<= 0.02 rad in the model; the real STS3215 sags 1-2 deg under load) and the backlash."""
PATH_TOLERANCE_RAD: Final = 0.35
"""Following error at which a move aborts (the servos lag ~0.06 rad at 1.5 rad/s)."""
GRIPPER_TOLERANCE: Final = 0.05
"""A gripper opening is reached this close (5 % of the stroke)."""
GRIPPER_TIMEOUT_S: Final = 5.0
"""Real seconds the app waits for the gripper (closing on an object it may never arrive: the
app then reports where it stopped and goes on)."""
MOVE_MARGIN_S: Final = 10.0


@dataclass(frozen=True, slots=True)
class Pose:
    """A named arm pose: the five joints (rad) and the gripper's opening (None: as it is)."""

    joints: tuple[float, float, float, float, float]
    gripper: float | None = None


POSES: Final[dict[str, Pose]] = {
    "rest": Pose((0.0, -1.70, 1.60, 0.75, 0.0), 0.0),
    "ready": Pose((0.0, -0.50, 0.40, 1.00, 0.0), 0.2),
    "reach": Pose((0.0, 0.50, -0.20, 0.90, 0.0)),
    "above pick": Pose((0.55, -0.10, -0.07, 1.39, 0.0)),
    "at pick": Pose((0.55, 0.25, -0.07, 1.39, 0.0)),
    "above place": Pose((-0.55, -0.10, -0.07, 1.39, 1.57)),
    "at place": Pose((-0.55, 0.25, -0.07, 1.39, 1.57)),
}
"""The named poses (rad, the MuJoCo model's zero = the servos' mid-range; every one inside
the published joint ranges with a margin). At ``rest`` the arm lies folded on the table;
``ready`` stands up with the gripper forward and down; ``reach`` stretches forward; the pick
is 0.55 rad to one side (the gripper pointing down, 4 cm above the table at ``at pick``), the
place as far to the other, the wrist turned a quarter."""


@dataclass(frozen=True, slots=True)
class Step:
    """A step of the sequence: the arm to the pose ``pose`` (its gripper opening after the
    arm's move when it has one), or the gripper alone to ``gripper``."""

    name: str
    pose: str | None = None
    gripper: float | None = None


SEQUENCE: Final[tuple[Step, ...]] = (
    Step("rest", "rest"),
    Step("ready", "ready"),
    Step("reach", "reach"),
    Step("above pick", "above pick"),
    Step("open", gripper=1.0),
    Step("at pick", "at pick"),
    Step("grip", gripper=0.1),
    Step("lift", "above pick"),
    Step("above place", "above place"),
    Step("at place", "at place"),
    Step("release", gripper=1.0),
    Step("retreat", "above place"),
    Step("ready", "ready"),
    Step("rest", "rest"),
)
"""The run: rest, the poses, a pick-like motion (open above the pick, down, close, lift,
carry over, down, open, up) and back to rest."""


def _check_poses() -> None:
    for name, pose in POSES.items():  # (a programming error, caught by the tests too)
        assert len(pose.joints) == len(ARM), name
    for step in SEQUENCE:
        assert (step.pose is None) != (step.gripper is None), step
        assert step.pose is None or step.pose in POSES, step


_check_poses()


# -- the rig ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class So101Rig:
    """The rig to open (the group ``so101`` taken out: the app builds it with its
    tolerances) and how the app's group is made."""

    resolved: ResolvedRig
    limits: tuple[AxisLimits, ...]
    timer: str | None
    """The rig's timer the group streams on; None: the app's own at :data:`DEFAULT_PERIOD_MS`."""
    period_ms: float
    goal_time: float = 1.0
    synchronization: str = "phase"
    group_from_rig: bool = False
    mujoco_buses: tuple[str, ...] = ()

    @property
    def source(self) -> str:
        return Path(self.resolved.spec.source).name

    def limits_text(self) -> str:
        shown = "; ".join(
            f"{a.max_velocity:g} rad/s, {a.max_acceleration:g} rad/s^2, {a.max_jerk:g} rad/s^3"
            for a in dict.fromkeys(self.limits)
        )
        whose = f"group {GROUP}" if self.group_from_rig else "the app's group"
        return f"{whose}, at most {shown}, period {self.period_ms:g} ms"


def so101_rig(
    ctx: AppContext, *, realtime: bool | None = None, period_ms: float | None = None
) -> So101Rig:
    """The rig of ``--rig FILE`` or :data:`RIG`, checked for the six components (ValueError
    naming what is missing), its group ``so101`` taken out for the app's, its MuJoCo buses
    paced as ``realtime`` says (None: as the rig says) and the group's timer at
    ``period_ms`` (None: the rig's)."""
    from openel_async.rig import load_rig, resolve_rig

    resolved = ctx.rig_spec if ctx.rig_spec is not None else resolve_rig(load_rig(RIG))
    spec = resolved.spec
    where = f"rig {Path(spec.source).name}"
    names = {c.name for c in spec.components}
    for name in (*ARM, GRIPPER):
        if name not in names:
            raise ValueError(f"{where} has no component {name!r} (the app takes it by name)")
        if not issubclass(resolved.classes[name], ActuatorDevice):
            raise ValueError(f"{where}: the component {name!r} is not an actuator")
    group = next((g for g in spec.groups if g.name == GROUP), None)
    timers = {t.name: t for t in spec.timers}
    goal_time, synchronization = 1.0, "phase"
    if group is not None:
        if group.axes != ARM:
            raise ValueError(
                f"{where}: group {GROUP!r} moves {', '.join(group.axes)}; the app needs "
                f"{', '.join(ARM)}, in this order"
            )
        limits = []
        for axis in ARM:
            joint = spec.component(axis).limits
            velocity = group.max_velocity if group.max_velocity is not None else joint.velocity
            acceleration = (
                group.max_acceleration if group.max_acceleration is not None else joint.acceleration
            )
            assert velocity is not None and acceleration is not None  # (parse_rig checks)
            limits.append(AxisLimits(velocity, acceleration, group.max_jerk))
        timer: str | None = group.timer
        goal_time, synchronization = group.goal_time, group.synchronization
    else:
        limits = [DEFAULT_LIMITS] * len(ARM)
        timer = TIMER if TIMER in timers else None
    timer_specs = spec.timers
    if timer is None:
        period = DEFAULT_PERIOD_MS if period_ms is None else period_ms
    elif period_ms is None:
        period = timers[timer].period_ms
    else:
        period = period_ms
        timer_specs = tuple(
            dataclasses.replace(t, period_ms=period_ms) if t.name == timer else t
            for t in spec.timers
        )
    buses = dict(resolved.buses)
    mujoco = tuple(
        n for n, b in buses.items() if type(b.kind).__module__.startswith("openel_mujoco")
    )
    if realtime is not None:
        import msgspec  # (loaded with the rig already; not at import: --help)

        for name in mujoco:
            pacing = "realtime" if realtime else "lockstep"
            options = msgspec.structs.replace(buses[name].options, pacing=pacing)
            buses[name] = dataclasses.replace(buses[name], options=options)
    adjusted = dataclasses.replace(
        spec, groups=tuple(g for g in spec.groups if g.name != GROUP), timers=timer_specs
    )
    return So101Rig(
        dataclasses.replace(resolved, spec=adjusted, buses=buses),
        tuple(limits),
        timer,
        period,
        goal_time,
        synchronization,
        group is not None,
        mujoco,
    )


# -- the run ---------------------------------------------------------------------------------


@dataclass
class PoseRecord:
    """One step done: when, how close the joints came, where the gripper is."""

    index: int
    name: str
    seconds: float
    """Seconds on the rig's clock since the run started (simulated time on a MuJoCo rig)."""
    error_rad: float
    """Largest |target - actual| of the five joints (0 for a gripper step)."""
    worst_joint: str
    positions: tuple[float, ...]
    gripper: float
    gripper_target: float | None
    reached: bool

    def line(self) -> str:
        """``  4  above pick   reached at  5.12 s  max error 0.012 rad (shoulder_lift)  gripper 1.00``."""
        state = "reached" if self.reached else "MISSED "
        error = (
            f"max error {self.error_rad:.3f} rad ({self.worst_joint})"
            if self.worst_joint
            else f"gripper to {self.gripper_target:.2f}".ljust(38)
        )
        return (
            f"{self.index:3d}  {self.name:<12} {state} at {self.seconds:6.2f} s  {error:<38}"
            f"  gripper {round(self.gripper, 2) + 0.0:.2f}"
        )


@dataclass
class So101Result:
    rig: str
    steps: list[PoseRecord] = field(default_factory=list)
    snapshots: list[tuple[str, Path]] = field(default_factory=list)
    snapshot_skipped: str | None = None
    joint_ranges: dict[str, tuple[float, float]] = field(default_factory=dict)
    """The range each joint was seen in (rad), from the actual positions at each step."""
    wall_s: float = 0.0
    seconds: float = 0.0

    @property
    def ok(self) -> bool:
        return bool(self.steps) and all(s.reached for s in self.steps)


async def _actuals(axes: Sequence[Actuator]) -> list[float]:
    return [float(await a.get_value(Request.POSITION_ACTUAL)) for a in axes]


async def run_so101(
    ctx: AppContext, rig: So101Rig, *, out_dir: Path | None = None, echo: bool = True
) -> So101Result:
    """Open ``rig`` (``ctx.open_rig``), run :data:`SEQUENCE` and return what it did; each
    step's line is printed as it is reached (``echo``). On a MuJoCo rig snapshots go to
    ``out_dir`` (None: none). A motion that fails raises its HALError."""
    result = So101Result(rig=f"{rig.source}, {rig.limits_text()}")
    ctx.rig_spec = rig.resolved  # ctx.open_rig opens it (the default stays the app's rig)
    started = time.perf_counter()
    async with ctx.open_rig(default=RIG) as opened:
        axes = [opened.actuator(name) for name in ARM]
        gripper = opened.actuator(GRIPPER)
        timer = _timer(ctx, opened, rig)
        group = AxisGroup(
            axes,
            timer=timer,
            limits=rig.limits,
            tolerances=Tolerances(goal=GOAL_TOLERANCE_RAD, path=PATH_TOLERANCE_RAD),
            goal_time=max(rig.goal_time, 2.0),
            synchronization=rig.synchronization,
            name=GROUP,
        )
        sim = _simulation(opened, rig)
        clock = timer.clock
        t0 = clock.now_ns()
        async with AsyncExitStack() as stack:
            if rig.timer is None:  # the app's own timer (the group starts it)
                await stack.enter_async_context(timer)
            await stack.enter_async_context(group)
            for index, step in enumerate(SEQUENCE, start=1):
                record = await _step(index, step, group, axes, gripper, result)
                record.seconds = (clock.now_ns() - t0) / 1e9
                result.steps.append(record)
                if echo:
                    print(record.line(), flush=True)
                if not record.reached:
                    break
                if sim is not None and out_dir is not None and step.name == "grip":
                    await _snapshot(sim, out_dir / f"{APP}_pick.png", "snapshot (pick)", result)
            result.seconds = (clock.now_ns() - t0) / 1e9
        if sim is not None and out_dir is not None:
            await _snapshot(sim, out_dir / f"{APP}_scene.png", "snapshot (end)", result)
    result.wall_s = time.perf_counter() - started
    return result


def _timer(ctx: AppContext, opened: Rig, rig: So101Rig) -> EventTimer:
    if rig.timer is not None:
        return opened.timer(rig.timer)
    return ctx.add_timer(EventTimer(rig.period_ms, clock=opened.clock, name=TIMER))


def _simulation(opened: Rig, rig: So101Rig) -> MujocoSim | None:
    """The MuJoCo simulation the arm's joints are on, if they are."""
    if not rig.mujoco_buses:
        return None
    bus = opened.spec.component(ARM[0]).bus
    sim = opened.buses.get(str(bus)) if bus is not None else None
    from openel_mujoco import MujocoSim  # (loaded: the rig has a MuJoCo bus)

    return sim if isinstance(sim, MujocoSim) else None


async def _step(
    index: int,
    step: Step,
    group: AxisGroup,
    axes: Sequence[Actuator],
    gripper: Actuator,
    result: So101Result,
) -> PoseRecord:
    opening: float | None = step.gripper
    target: tuple[float, ...] | None = None
    if step.pose is not None:
        pose = POSES[step.pose]
        target = pose.joints
        motion = await group.move_to(list(target))
        with anyio.fail_after(2.0 * motion.duration + MOVE_MARGIN_S):
            await motion
        opening = pose.gripper
    gripper_ok = True
    if opening is not None:
        gripper_ok = await _move_gripper(gripper, opening)
    actual = await _actuals(axes)
    for name, value in zip(ARM, actual, strict=True):
        low, high = result.joint_ranges.get(name, (value, value))
        result.joint_ranges[name] = (min(low, value), max(high, value))
    grip = float(await gripper.get_value(Request.POSITION_ACTUAL))
    error, worst = 0.0, ""
    if target is not None:
        errors = [abs(t - a) for t, a in zip(target, actual, strict=True)]
        error = max(errors)
        worst = ARM[errors.index(error)]
    reached = error <= GOAL_TOLERANCE_RAD and gripper_ok
    return PoseRecord(index, step.name, 0.0, error, worst, tuple(actual), grip, opening, reached)


async def _move_gripper(gripper: Actuator, opening: float) -> bool:
    """The gripper to ``opening``: True once within :data:`GRIPPER_TOLERANCE`; closing on
    something it stops short of it (stalled): True as well after :data:`GRIPPER_TIMEOUT_S`
    if it closed at least halfway, False otherwise."""
    motion = await gripper.set_value(opening, Request.POSITION)
    with anyio.move_on_after(GRIPPER_TIMEOUT_S):
        await motion
    actual = float(await gripper.get_value(Request.POSITION_ACTUAL))
    if abs(actual - opening) <= GRIPPER_TOLERANCE:
        return True
    log.warning("gripper_short", target=opening, actual=round(actual, 3))
    return opening < actual < 0.5  # closing on an object: it holds it


async def _snapshot(sim: MujocoSim, path: Path, label: str, result: So101Result) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    written, skipped = await save_snapshot(sim, path)
    if written is not None:
        result.snapshots.append((label, written))
    else:
        result.snapshot_skipped = skipped


# -- command line -----------------------------------------------------------------------------


def build_parser(prog: str = APP) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=prog,
        description="The SO-101 arm through named poses (rest, ready, reach) and a pick-like "
        "motion, its five joints moved together by an AxisGroup; on the MuJoCo model "
        "(default) or any rig with the components shoulder_pan, shoulder_lift, elbow_flex, "
        "wrist_flex, wrist_roll (rad) and gripper (opening 0..1), e.g. --rig "
        "apps/openel_apps/rigs/so101.yaml [--sim].",
    )
    add_pacing_arguments(parser)
    parser.add_argument(
        "--period-ms",
        type=float,
        default=None,
        metavar="MS",
        help="Period of the AxisGroup's EventTimer in ms, 1 to 100 (default: the rig's "
        f"timer's, 10 in the shipped rig; {DEFAULT_PERIOD_MS:g} when the rig has none).",
    )
    parser.add_argument(
        "--out",
        metavar="DIR",
        default=None,
        help="Directory for the snapshots of a MuJoCo rig, created if needed (default: "
        f"out/{APP}/ under the current directory).",
    )
    return parser


async def main(ctx: AppContext) -> int:
    """The app ``so101``: ``openel-async run so101 [--rig FILE] [--sim] [options]``."""
    parser = build_parser(ctx.prog)
    args = parser.parse_args(ctx.argv)
    period = args.period_ms
    if period is not None and not (math.isfinite(period) and 1.0 <= period <= 100.0):
        parser.error(f"--period-ms {period:g}: a number of ms from 1 to 100")
    out_dir = output_dir(APP, args.out)
    try:
        check_out_dir(out_dir)
    except ValueError as exc:
        parser.error(str(exc))
    realtime = True if args.realtime else (False if args.virtual else None)
    try:
        rig = so101_rig(ctx, realtime=realtime, period_ms=period)
    except ValueError as exc:  # a rig without what the app takes by name
        parser.error(str(exc))
    except ImportError as exc:  # the default rig's driver (MuJoCo) cannot load
        raise AppUnavailable("MuJoCo", f"{type(exc).__name__}: {exc}") from exc
    ctx.title = f"SO-101 poses ({rig.source})"
    print(f"{ctx.prog}: SO-101 on {rig.source}: {rig.limits_text()}")
    result = So101Result(rig=rig.source)

    def progress() -> list[str]:
        return [record.line() for record in result.steps]

    ctx.progress = progress
    try:
        result = await run_so101(ctx, rig, out_dir=out_dir if rig.mujoco_buses else None)
    except HALError as exc:
        print(f"{ctx.prog}: a motion failed: {exc}")
        return 1
    except TimeoutError:
        print(f"{ctx.prog}: a motion did not end in time")
        return 1
    print(_summary(result))
    return 0 if result.ok else 1


def _summary(result: So101Result) -> str:
    reached = sum(s.reached for s in result.steps)
    lines = [
        f"summary (SO-101 poses, {result.rig})",
        f"  steps              {reached}/{len(SEQUENCE)} reached in {result.seconds:.2f} s "
        f"on the rig's clock ({result.wall_s:.2f} s of wall time)",
        "  joint ranges       "
        + ", ".join(
            f"{n} [{round(lo, 2) + 0.0:+.2f}, {round(hi, 2) + 0.0:+.2f}]"
            for n, (lo, hi) in result.joint_ranges.items()
        ),
    ]
    for label, path in result.snapshots:
        lines.append(f"  {label:<18} {display_path(path)}")
    if result.snapshot_skipped:
        lines.append(f"  snapshot           skipped: {result.snapshot_skipped}")
    return "\n".join(lines)


def demo_args(options: DemoOptions) -> list[str]:
    """``openel-async demo --app so101``: ``--virtual`` and ``--realtime``, ``--period-ms``
    and ``--out``; the others are refused."""
    args: list[str] = []
    for name in ("bus", "duration", "inject_fault"):
        if getattr(options, name, None) not in (None, False):
            raise ValueError(f"so101 takes no --{name.replace('_', '-')}")
    if options.virtual:
        args.append("--virtual")
    if options.period_ms is not None:
        args += ["--period-ms", f"{options.period_ms:g}"]
    if options.out is not None:
        args += ["--out", str(options.out)]
    return args


APP_INFO = AppInfo(
    name=APP,
    description="the SO-101 arm through named poses and a pick-like motion (AxisGroup), on "
    "its MuJoCo model or any rig with its six components (the real arm: rigs/so101.yaml)",
    main=main,
    demo_args=demo_args,
    takes_rig=True,
    parser=build_parser,
)
"""The entry point ``so101`` of the ``openel_async.apps`` group."""
