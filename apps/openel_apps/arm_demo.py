"""Shared parts of the MuJoCo arm apps (``openel-async run arm2|arm6``, ``openel-async demo
[--app arm6]``).

The arm apps (:mod:`.arm2_square` and :mod:`.arm6_pick_place`) share:

- the common command-line options (``--duration``, ``--virtual`` / ``--realtime``, ``--out``,
  ``--no-live``, ``--period-ms``; the pacing and the period of the rig by default: real time
  and 2 ms in the shipped rigs, as ``openel-async demo``) and the output directory
  (``out/<app>/`` under the current directory);
- the end-of-run files: a PNG plot of commanded vs actual joint positions and a PNG snapshot of
  the scene, rendered in a worker thread and skipped with a reason when OpenGL is unavailable;
- timed straight-line paths in task space (:func:`line_waypoints`, minimum-jerk timing) for
  :meth:`AxisGroup.follow`, and :class:`UnreachableError` for the inverse kinematics;
- the synchronization analysis of an :class:`~openel_async.motion.AxisGroup` motion (on which
  tick each axis' setpoints arrive at their target);
- the timing of a run (:func:`record_times`, :func:`times_text`); its hardware comes from a
  rig file (:mod:`.arm_rig`);
- the flow of a run (:func:`run_reported`: plan, run, report, exit status), the summary printer
  and bounded waits on group motions;
- building the simulation of the rig's MuJoCo bus (:func:`open_arm_sim`:
  :class:`~openel_async.app.AppUnavailable` when MuJoCo or the model cannot load) and the
  ``openel-async demo`` options as an arm app's command line (:func:`arm_demo_args`).

This module imports neither MuJoCo nor matplotlib: the simulation objects are passed in, so the
apps can be discovered without paying for (or failing on) MuJoCo.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Literal, Protocol, TextIO, TypeVar

import anyio
import anyio.to_thread

from openel_async.app import AppContext, AppUnavailable, DemoOptions, LiveLine, atomic_output
from openel_async.errors import HALError
from openel_async.logs import get_logger
from openel_async.motion import GroupMotion, TrajectorySamples, Waypoint
from openel_async.timer import EventTimer

if TYPE_CHECKING:
    from openel_mujoco import MujocoSim, TrajectoryRecorder

    from .arm_rig import ArmRigSpec

log = get_logger(__name__)

OUT_ROOT = "out"
"""Default output root, relative to the current directory: files go to ``out/<app>/``."""
LOG_MARGIN_S = 30.0
"""Seconds of group log beyond a run's planned motion (goal settling, dwells, slow ticks)."""
RENDER_TIMEOUT_S = 60.0
"""Real-time bound on one snapshot (the first one initializes OpenGL: ~0.3-3 s)."""
PLOT_TIMEOUT_S = 60.0
PHYSICS_STEP_MS = 1.0
"""The arm models' physics step: ``--period-ms`` is a whole multiple of it."""
MAX_PERIOD_MS = 100.0
"""Longest ``--period-ms``: a coarser group period no longer follows the planned paths."""
MAX_DURATION_S = 600.0
"""Longest ``--duration`` (and square laps in all): the group's log holds the whole run, and a
lockstep run must end in minutes."""


class UnreachableError(ValueError):
    """The arm cannot put its tool on the requested point (out of reach or beyond a joint's
    range); the message says which and by how much."""


@dataclass(frozen=True, slots=True)
class ArmOptions:
    """The options every arm app takes (see :func:`add_common_arguments`)."""

    duration: float
    realtime: bool | None
    """``--realtime`` (True), ``--virtual`` (False: lockstep), or the pacing of the rig's
    MuJoCo bus (None)."""
    out_dir: Path
    live: bool
    period_ms: float | None
    """``--period-ms``, or the period of the rig's timer (None)."""

    @property
    def pacing(self) -> Literal["lockstep", "realtime"] | None:
        """The ``MujocoSim`` pacing the options ask for (None: the rig's)."""
        if self.realtime is None:
            return None
        return "realtime" if self.realtime else "lockstep"


def add_common_arguments(
    parser: argparse.ArgumentParser,
    app: str,
    *,
    duration_help: str,
    default_duration: float,
) -> None:
    """The options every arm app takes; the defaults are those of ``openel-async demo`` (the
    pacing and the period: the rig's)."""
    parser.add_argument(
        "--duration", type=float, default=default_duration, metavar="S", help=duration_help
    )
    add_pacing_arguments(parser)
    parser.add_argument(
        "--out",
        metavar="DIR",
        default=None,
        help=f"Directory for the PNG files, created if needed (default: {OUT_ROOT}/{app}/ "
        "under the current directory).",
    )
    parser.add_argument("--no-live", action="store_true", help="Print no live progress line.")
    parser.add_argument(
        "--period-ms",
        type=float,
        default=None,
        metavar="MS",
        help=f"EventTimer period of the axis group in ms, a whole number from "
        f"{PHYSICS_STEP_MS:g} to {MAX_PERIOD_MS:g} (default: the period of the rig's timer, "
        "2 in the shipped rigs).",
    )


def add_pacing_arguments(parser: argparse.ArgumentParser) -> None:
    """``--virtual`` and ``--realtime`` (mutually exclusive; the pacing of the rig's MuJoCo
    bus by default: real time in the shipped rigs), the same two flags in every shipped app
    and in ``openel-async demo``."""
    pacing = parser.add_mutually_exclusive_group()
    pacing.add_argument(
        "--virtual",
        action="store_true",
        help="Run the simulation in lockstep: as fast as the CPU allows, and deterministic.",
    )
    pacing.add_argument(
        "--realtime",
        action="store_true",
        help="Pace the simulation against the real clock (the default of the shipped rigs, "
        "whose MuJoCo bus says pacing: realtime).",
    )


def options_from(args: argparse.Namespace, app: str) -> ArmOptions:
    """Validated :class:`ArmOptions`; raises ``ValueError`` with a message for the user."""
    out_dir = output_dir(app, args.out)
    check_out_dir(out_dir)
    return ArmOptions(
        duration=check_duration(args.duration),
        realtime=True if args.realtime else (False if args.virtual else None),
        out_dir=out_dir,
        live=not args.no_live,
        period_ms=None if args.period_ms is None else check_period_ms(args.period_ms),
    )


def check_duration(duration: float) -> float:
    """``--duration``: a finite number of seconds, 0 < S <= :data:`MAX_DURATION_S`."""
    if not (math.isfinite(duration) and 0 < duration <= MAX_DURATION_S):
        raise ValueError(
            f"--duration {duration:g}: a number of seconds > 0 and at most {MAX_DURATION_S:g}"
        )
    return float(duration)


def check_period_ms(period_ms: float, name: str = "--period-ms") -> float:
    """``--period-ms`` (or the period ``name`` of a rig's timer): a whole multiple of the
    :data:`PHYSICS_STEP_MS` physics step, at most :data:`MAX_PERIOD_MS`."""
    steps = period_ms / PHYSICS_STEP_MS if math.isfinite(period_ms) else math.nan
    if not (math.isfinite(steps) and steps >= 1 and steps == round(steps)) or not (
        period_ms <= MAX_PERIOD_MS
    ):
        raise ValueError(
            f"{name} {period_ms:g}: a whole multiple of the {PHYSICS_STEP_MS:g} ms physics "
            f"step, from {PHYSICS_STEP_MS:g} to {MAX_PERIOD_MS:g} ms"
        )
    return float(period_ms)


def check_out_dir(out_dir: Path) -> None:
    """``--out``: a directory, or a path where one can be created; raises ``ValueError``
    naming the obstacle (an existing file, a parent that is a file or not writable)."""
    if out_dir.exists():
        if not out_dir.is_dir():
            raise ValueError(f"--out {out_dir}: exists and is not a directory")
        existing = out_dir
    else:
        existing = out_dir.absolute().parent
        while not existing.exists():
            existing = existing.parent
        if not existing.is_dir():
            raise ValueError(f"--out {out_dir}: {existing} is a file, not a directory")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise ValueError(f"--out {out_dir}: {existing} is not writable")


def output_dir(app: str, out: str | os.PathLike[str] | None = None) -> Path:
    """``out`` if given, else ``out/<app>`` under the current directory (not created here)."""
    return Path(out) if out is not None else Path.cwd() / OUT_ROOT / app


def display_path(path: Path) -> str:
    """``path`` relative to the current directory when it is below it, else absolute."""
    absolute = path.resolve()
    try:
        return str(absolute.relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(absolute)


# -- paths ------------------------------------------------------------------------------------


def min_jerk(tau: float) -> float:
    """Minimum-jerk progress 0 -> 1 over ``tau`` in [0, 1] (zero velocity and acceleration at
    both ends)."""
    return tau * tau * tau * (10.0 + tau * (-15.0 + 6.0 * tau))


def line_waypoints(
    inverse: Callable[[tuple[float, ...]], Sequence[float]],
    start: Sequence[float],
    end: Sequence[float],
    *,
    duration: float,
    points: int,
) -> list[Waypoint]:
    """``points`` timed waypoints along the straight line ``start`` -> ``end`` in task space,
    converted to joint angles by ``inverse``; the i-th is passed at ``i / points * duration``
    and lies at the minimum-jerk progress of that time, so the tool starts and stops smoothly
    (the last waypoint is ``end``, at ``duration``).  Raises what ``inverse`` raises
    (:class:`UnreachableError`) for a point it cannot reach."""
    if points < 1:
        raise ValueError(f"points must be >= 1, not {points}")
    if not (math.isfinite(duration) and duration > 0):
        raise ValueError(f"duration must be > 0 s, not {duration}")
    waypoints = []
    for i in range(1, points + 1):
        tau = i / points
        s = min_jerk(tau)
        point = tuple(a + s * (b - a) for a, b in zip(start, end, strict=True))
        waypoints.append(Waypoint(list(inverse(point)), time=tau * duration))
    return waypoints


# -- end-of-run files -------------------------------------------------------------------------


@dataclass
class Artifacts:
    """The files a run wrote, and why the snapshot is missing if it is."""

    plot: Path | None = None
    snapshot: Path | None = None
    snapshot_skipped: str | None = None
    extra: list[tuple[str, Path]] = field(default_factory=list)
    """Further files, with a label."""

    def files(self) -> list[tuple[str, Path]]:
        """``(label, path)`` of every file written."""
        rows = [] if self.plot is None else [("joint plot", self.plot)]
        if self.snapshot is not None:
            rows.append(("snapshot", self.snapshot))
        return rows + self.extra

    def lines(self) -> list[str]:
        """The files section of the summary: one row per file (its name, the directory is
        the section's heading: :meth:`heading`), and why the snapshot is missing."""
        rows = [f"{label:<18} {path.name}" for label, path in self.files()]
        if self.snapshot is None:
            rows.append(f"{'snapshot':<18} skipped: {self.snapshot_skipped or 'not taken'}")
        return rows

    def heading(self) -> str:
        """``files in DIR/`` (the directory of the files written), or ``files`` when there
        is none or they are in several directories."""
        folders = {path.parent for _, path in self.files()}
        if len(folders) != 1:
            return "files"
        return f"files in {display_path(folders.pop())}/"


def _rendering_disabled() -> bool:
    return os.environ.get("MUJOCO_GL", "").strip().lower() in {
        "disable",
        "disabled",
        "off",
        "false",
        "0",
    }


async def save_snapshot(
    sim: MujocoSim,
    path: Path,
    *,
    camera: str | None = "overview",
    width: int = 800,
    height: int = 600,
) -> tuple[Path | None, str | None]:
    """Render the scene to ``path`` (renderer process, bounded); ``(None, reason)`` when it cannot.

    The physics is paused meanwhile, in both pacings: a lockstep run stays deterministic, and on
    a 2-core machine a real-time run does not drop steps while the renderer process competes
    for the CPU (simulated time then resumes where it stopped).  Never raises for a
    rendering problem: a missing OpenGL context, a disabled renderer or a renderer error only
    skip the snapshot, with the reason returned (and logged).
    """
    if _rendering_disabled():
        return None, "rendering disabled (MUJOCO_GL=" + os.environ.get("MUJOCO_GL", "") + ")"
    try:
        with anyio.fail_after(RENDER_TIMEOUT_S), atomic_output(path) as partial:
            async with sim.paused():
                rendered = await sim.render_snapshot(
                    partial, width=width, height=height, camera=camera
                )
        written = None if rendered is None else path
    except TimeoutError:
        reason = f"rendering took longer than {RENDER_TIMEOUT_S:g} s"
    except Exception as exc:  # a renderer error must not lose the run's other results
        reason = f"rendering failed: {type(exc).__name__}: {exc}"
    else:
        if written is not None:
            return written, None
        reason = "no OpenGL context (headless without EGL/OSMesa? set MUJOCO_GL=egl or osmesa)"
    log.warning("snapshot_skipped", reason=reason)
    return None, reason


def _preload() -> None:
    # matplotlib's first import takes ~0.3-1 s, mostly holding the GIL: done in a worker thread
    # before the run, it cannot stall a real-time loop later (the snapshot's PNG encoder and the
    # plots use it).
    import matplotlib.backends.backend_agg
    import matplotlib.figure
    import matplotlib.image  # noqa: F401


async def preload_plotting() -> None:
    """Import matplotlib in a worker thread before a run (see :func:`save_snapshot`)."""
    with anyio.fail_after(PLOT_TIMEOUT_S):
        await anyio.to_thread.run_sync(_preload)


async def save_plot(recorder: TrajectoryRecorder, path: Path, *, title: str) -> Path:
    """``recorder.plot`` in a worker thread (matplotlib takes ~0.2-1 s); the recorder must be
    detached from the simulation (nothing appends to it meanwhile)."""
    with anyio.fail_after(PLOT_TIMEOUT_S), atomic_output(path) as partial:
        await anyio.to_thread.run_sync(lambda: recorder.plot(partial, title=title))
    return path


# -- synchronization --------------------------------------------------------------------------


def arrival_ticks(
    samples: TrajectorySamples, motion_id: int, *, eps: float = 1e-7
) -> list[int | None]:
    """Per axis, the index (in the motion's rows) of the tick from which its setpoint stays at
    the motion's final setpoint; None for an axis that did not move in the motion.

    The rows are the group log's rows of that motion (one per tick, the settling ticks
    included, which repeat the final setpoints).
    """
    import numpy as np  # (~0.2 s to import: not for an app's --help)

    rows = samples.of_motion(motion_id)
    commanded = rows.commanded
    if len(rows) == 0:
        return []
    final = commanded[-1]
    result: list[int | None] = []
    for axis in range(commanded.shape[1]):
        column = commanded[:, axis]
        if float(np.max(column) - np.min(column)) <= eps:
            result.append(None)
            continue
        away = np.nonzero(np.abs(column - final[axis]) > eps)[0]
        result.append(int(away[-1]) + 1 if away.size else 0)
    return result


def arrival_spread(samples: TrajectorySamples, motion_id: int) -> int:
    """Ticks between the first and the last axis whose setpoints arrive (0: the same tick)."""
    ticks = [t for t in arrival_ticks(samples, motion_id) if t is not None]
    return max(ticks) - min(ticks) if ticks else 0


async def finish(motion: GroupMotion, *, margin_s: float = 10.0) -> None:
    """Await a group motion, bounded in real time by twice its planned time plus a margin
    (lockstep runs faster than real time; real-time pacing needs the planned time)."""
    with anyio.fail_after(2.0 * motion.duration + margin_s):
        await motion


# -- the run ----------------------------------------------------------------------------------


class RunTimes(Protocol):
    """The timing fields of an app's result (see :func:`record_times`)."""

    pacing: str
    sim_time_s: float
    wall_time_s: float
    timer_ticks: int
    timer_missed: int


def record_times(result: RunTimes, timer: EventTimer, sim: MujocoSim) -> None:
    """Simulated and real time of the run, and the timer's ticks, into ``result``."""
    stats = timer.stats
    result.timer_ticks, result.timer_missed = stats.ticks, stats.missed_ticks
    result.sim_time_s = sim.time_ns / 1e9
    result.wall_time_s = sim.stats.wall_time_s  # lockstep: the snapshots' pauses excluded


def spread_text(ticks: int, period_ms: float) -> str:
    """``on the same tick`` or ``within 2 ticks (4 ms) of each other``."""
    if ticks == 0:
        return "on the same tick"
    unit = "tick" if ticks == 1 else "ticks"
    return f"within {ticks} {unit} ({ticks * period_ms:g} ms) of each other"


def pacing_name(pacing: str) -> str:
    """A ``MujocoSim`` pacing as the summaries say it: ``lockstep`` or ``real time``."""
    return "real time" if pacing == "realtime" else pacing


def times_text(result: RunTimes) -> str:
    """``7.12 s simulated in 0.52 s of real time (13.6x, lockstep), timer ticks ...``"""
    speed = result.sim_time_s / result.wall_time_s if result.wall_time_s > 0 else 0.0
    pacing = "real-time pacing" if result.pacing == "realtime" else result.pacing
    return (
        f"{result.sim_time_s:.2f} s simulated in {result.wall_time_s:.2f} s of real time "
        f"({speed:.1f}x, {pacing}), timer ticks {result.timer_ticks} (missed "
        f"{result.timer_missed})"
    )


R = TypeVar("R")


def open_arm_sim(
    rig: ArmRigSpec, *, realtime: bool | None = None, ctx: AppContext | None = None
) -> MujocoSim:
    """The simulation of ``rig``'s MuJoCo bus, not running (the rig runs it:
    :func:`~.arm_rig.open_arm_rig`), paced in real time (``realtime=True``), in lockstep
    (False) or as the bus says (None); its clock and, for a recorder or a live view, its
    scene are registered with ``ctx``. Raises :class:`AppUnavailable` when MuJoCo,
    ``openel_mujoco`` or the model cannot load."""
    options = rig.options
    pacing = options.pacing if realtime is None else ("realtime" if realtime else "lockstep")
    try:
        from openel_mujoco import MujocoSim

        sim = MujocoSim(options.model, pacing=pacing, **options.sim_arguments())
    except Exception as exc:  # ImportError, ModelLoadError, MuJoCo's own load errors
        raise AppUnavailable("MuJoCo", f"{type(exc).__name__}: {exc}") from exc
    if ctx is not None:
        ctx.use_clock(sim.clock)
        if ctx.hooks:  # a recorder or a live view: the arm's bodies for the 3D panel
            from openel_mujoco.foxglove_scene import MujocoScene

            ctx.add_scene(MujocoScene(sim))
    return sim


def arm_demo_args(options: DemoOptions) -> list[str]:
    """``openel-async demo`` options as an arm app's command line: only the options given
    (the app's defaults are the demo's), ``--virtual`` for lockstep; ValueError for an option
    an arm app cannot honour."""
    if options.bus not in (None, "mujoco"):
        raise ValueError("--app needs --bus mujoco (the arm apps run on MuJoCo)")
    if options.inject_fault:
        raise ValueError("--inject-fault needs --bus sim or --bus can")
    argv: list[str] = []
    if options.duration is not None:
        argv += ["--duration", repr(options.duration)]
    if options.period_ms is not None:
        argv += ["--period-ms", repr(options.period_ms)]
    if options.out is not None:
        argv += ["--out", options.out]
    if options.virtual:
        argv.append("--virtual")
    if not options.live:
        argv.append("--no-live")
    return argv


async def run_reported(
    prog: str,
    *,
    plan: Callable[[], object],
    run: Callable[[LiveLine | None], Awaitable[R]],
    report: Callable[[R], bool],
    live: bool,
) -> int:
    """The flow of an arm app; returns its exit status.

    ``plan()`` solves and checks every target before anything moves: a ``ValueError`` (bad
    option, :class:`UnreachableError`) is printed as ``<prog>: <reason>`` and gives 2.
    ``run(live_line)`` runs it: a ``HALError`` (a motion aborted: following error, fault, goal
    timeout) gives 1.  ``report(result)`` prints the summary and tells whether the run did
    what it should (0) or not (1).
    """
    try:
        plan()
    except ValueError as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return 2
    try:
        result = await run(LiveLine() if live else None)
    except HALError as exc:
        print(f"{prog}: the arm stopped: {exc}", file=sys.stderr)
        return 1
    return 0 if report(result) else 1


# -- output -----------------------------------------------------------------------------------


def print_summary(
    title: str, lines: Sequence[str], stream: TextIO | None = None, *, heading: bool = True
) -> None:
    """``summary (title)`` (or ``title`` alone when not ``heading``) and the lines below it;
    nothing when there are no lines."""
    if not lines:
        return
    out = stream or sys.stdout
    out.write(f"\nsummary ({title})\n" if heading else f"\n{title}\n")
    for line in lines:
        out.write("  " + line + "\n")
    out.flush()


def print_report(title: str, lines: Sequence[str], artifacts: Artifacts) -> None:
    """The summary, then the files the run wrote."""
    print_summary(title, lines)
    print_summary(artifacts.heading(), artifacts.lines(), heading=False)


def fmt_mm(meters: float) -> str:
    return f"{meters * 1e3:.2f} mm"


def fmt_point(point: Sequence[float]) -> str:
    return "(" + ", ".join(f"{v:+.3f}" for v in point) + ") m"
