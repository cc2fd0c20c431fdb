"""apps/arm2_square.py end to end, in lockstep: one square, synchronized corners, files."""

from __future__ import annotations

import io
from dataclasses import replace
from pathlib import Path

import anyio
import numpy as np
import pytest
import structlog
from msgspec.structs import replace as replace_struct

from openel_apps.arm2_square import (
    RIG,
    LapTooFastError,
    PlanarArm,
    SquareOptions,
    arm2_rig,
    min_lap_s,
    open_sim,
    plan_square,
    run_square,
)
from openel_apps.arm_demo import ArmOptions, arrival_spread, arrival_ticks, save_snapshot
from openel_async.app import LiveLine
from openel_async.cli import main as cli_main
from openel_async.motion import TrajectorySamples

from .conftest import assert_snapshot_written_or_explained, is_png, load


@pytest.fixture(autouse=True)
def _reset_logging() -> object:
    yield
    structlog.reset_defaults()  # the CLI's main() configures structlog for the process


@pytest.mark.render
async def test_one_square_in_lockstep(tmp_path: Path) -> None:
    options = ArmOptions(duration=6.0, realtime=False, out_dir=tmp_path, live=False, period_ms=2.0)
    sim = open_sim(realtime=False)
    stream = io.StringIO()
    with anyio.fail_after(40):
        result = await run_square(
            sim, options=options, square=SquareOptions(lap_s=6.0), live=LiveLine(stream)
        )
    assert "off-edge" in stream.getvalue()  # the live progress line

    # Every edge ended at its corner, all joints' setpoints arriving on the same tick (or the
    # next: a setpoint a few 1e-8 rad from the target counts as not arrived yet).
    assert [a.corner for a in result.arrivals] == [2, 3, 4, 1]
    assert all(a.outcome == "succeeded" for a in result.arrivals)
    assert all(a.setpoint_spread_ticks <= 1 for a in result.arrivals)
    assert result.approach_spread_ticks <= 1
    # ... and the physics followed: at each corner every joint was within its goal tolerance
    # by 50 ms after the last setpoint, the tip within 1 mm of the corner.
    assert max(a.settled_after_s for a in result.arrivals) <= 0.05
    assert max(a.tip_error_m for a in result.arrivals) < 1e-3

    # The tip (tip_pos sensor, read at every 2 ms tick) stayed close to the square's edges.
    assert result.deviation_samples >= 0.9 * 6.0 / 0.002
    assert 0.0 < result.max_deviation_m < 3e-3
    assert result.rms_deviation_m < 1e-3
    assert result.square_sim_s == pytest.approx(6.0, abs=0.1)
    assert result.timer_missed == 0

    # Files: the joint plot and the tip-path plot are PNGs; the snapshot is one or was skipped
    # with the reason in the summary.
    assert is_png(result.artifacts.plot)
    assert result.artifacts.plot == tmp_path / "arm2_square_joints.png"
    assert all(is_png(path) for _, path in result.artifacts.extra)
    assert_snapshot_written_or_explained(result.artifacts)
    text = "\n".join(result.lines())
    assert "corners reached    4/4" in text
    assert "tip deviation      max" in text


def test_the_app_runs_from_the_command_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    app = load("arm2_square")
    assert callable(app.main)
    code = cli_main(
        ["--log-level", "warning", "run", "apps/arm2_square.py", "--virtual", "--no-live",
         "--out", str(tmp_path), "--duration", "4"]
    )  # fmt: skip
    out = capsys.readouterr().out
    assert code == 0, out
    assert "summary (MuJoCo arm2 square, lockstep)" in out
    assert "square             1 lap of a 15 cm square, 4 s per lap, elbow up" in out
    # The files are listed under their directory (no heading without files below it).
    files = out[out.index("\nfiles in ") :].splitlines()[1:]
    assert files[0] == f"files in {tmp_path.resolve()}/"
    assert "  joint plot         arm2_square_joints.png" in files
    assert "  tip path plot      arm2_square_tip.png" in files
    assert is_png(tmp_path / "arm2_square_joints.png")


def test_bad_options_are_refused_with_a_message(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert cli_main(["run", "apps/arm2_square.py", "--side", "0.5", "--out", str(tmp_path)]) == 2
    assert "error: --side 0.5 --center 0.35 0 --elbow up: the square leaves the arm's reach: " in (
        capsys.readouterr().err
    )
    assert cli_main(["run", "apps/arm2_square.py", "--duration", "0"]) == 2
    assert not list(tmp_path.iterdir())  # nothing ran, nothing written


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--period-ms", "nan"], "--period-ms nan: a whole multiple of the 1 ms physics step"),
        (["--period-ms", "1.5"], "--period-ms 1.5: a whole multiple of the 1 ms physics step"),
        (["--duration", "inf"], "--duration inf: a number of seconds > 0 and at most 600"),
        (["--laps", "121"], "--laps 121: from 1, with --laps x --duration at most 600 s"),
        (["--points", "0"], "--points 0: from 1 to 1000"),
        (["--points", "100000"], "--points 100000: from 1 to 1000"),
        (["--center", "nan", "0"], "--center nan 0: two finite numbers of m"),
        (["--virtual", "--realtime"], "argument --realtime: not allowed with argument --virtual"),
    ],
)
def test_every_option_is_checked_before_the_model_loads(
    args: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out_dir = tmp_path / "out"
    assert cli_main(["run", "apps/arm2_square.py", *args, "--out", str(out_dir)]) == 2
    assert message in capsys.readouterr().err
    assert not out_dir.exists()


def test_a_lap_too_fast_names_the_option_and_the_shortest_lap(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Issue 21 point 5: not the planner's ``waypoints[0].time=0.015625 is not allowed``."""
    assert cli_main(["run", "arm2", "--duration", "1", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    last = err.strip().splitlines()[-1]
    assert last.startswith("openel-async run arm2: error: --duration 1: a lap takes at least ")
    shortest = float(last.split("at least ")[1].split(" s ")[0])
    assert 2.0 < shortest < 4.0 and "waypoints" not in err
    assert not (tmp_path / "out").exists()  # nothing ran


def test_the_shortest_lap_is_the_planners_limit() -> None:
    sim = open_sim(realtime=False)
    arm = PlanarArm.from_model(sim.model)
    square = SquareOptions()
    shortest = min_lap_s(arm, square)
    plan_square(arm, replace(square, lap_s=shortest))  # plans
    with pytest.raises(LapTooFastError, match=rf"a lap takes at least {shortest:.2f} s"):
        plan_square(arm, replace(square, lap_s=shortest - 0.1))


def test_an_out_that_is_a_file_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    existing = tmp_path / "file.png"
    existing.write_bytes(b"mine")
    assert cli_main(["run", "apps/arm2_square.py", "--out", str(existing)]) == 2
    assert "exists and is not a directory" in capsys.readouterr().err
    assert existing.read_bytes() == b"mine"


async def test_a_snapshot_without_rendering_is_skipped_with_the_reason(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("MUJOCO_GL", "disable")
    path, reason = await save_snapshot(open_sim(realtime=False), tmp_path / "scene.png")
    assert path is None
    assert reason == "rendering disabled (MUJOCO_GL=disable)"
    assert not (tmp_path / "scene.png").exists()


def test_arrival_ticks_find_the_tick_each_axis_reaches_its_target() -> None:
    commanded = np.array(
        [[0.0, 0.0, 5.0], [0.5, 0.2, 5.0], [0.9, 0.6, 5.0], [1.0, 0.9, 5.0], [1.0, 1.0, 5.0]]
    )
    n = len(commanded)
    samples = TrajectorySamples(
        time_ns=np.arange(n, dtype=np.int64) * 1_000_000,
        motion_id=np.full(n, 3, dtype=np.int64),
        commanded=commanded,
        velocity=np.zeros_like(commanded),
        acceleration=np.zeros_like(commanded),
        actual=None,
    )
    assert arrival_ticks(samples, 3) == [3, 4, None]  # the third axis did not move
    assert arrival_spread(samples, 3) == 1
    assert arrival_ticks(samples, 4) == []


async def test_lockstep_runs_are_deterministic(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("MUJOCO_GL", "disable")  # no snapshots: faster, and not under test here
    results = []
    for run in range(2):
        options = ArmOptions(
            4.0, realtime=False, out_dir=tmp_path / str(run), live=False, period_ms=2.0
        )
        with anyio.fail_after(30):
            results.append(
                await run_square(
                    open_sim(realtime=False), options=options, square=SquareOptions(lap_s=4.0)
                )
            )
    first, second = results
    assert first.tip_path == second.tip_path  # bit for bit
    assert first.max_deviation_m == second.max_deviation_m
    assert first.sim_time_s == second.sim_time_s
    assert first.artifacts.snapshot is None
    assert first.artifacts.snapshot_skipped == "rendering disabled (MUJOCO_GL=disable)"


def test_the_tip_plot_legend_covers_no_data() -> None:
    """Issue 21 point 16: the legend sat in the top-left corner, over a corner of the square."""
    from openel_apps.arm2_square import SquareResult, tip_path_figure

    corners = [(0.25, 0.05), (0.40, 0.05), (0.40, 0.20), (0.25, 0.20)]
    path = [(x + 0.001, y - 0.001) for x, y in corners]
    result = SquareResult("lockstep", 2.0, 5.0, 1, 0.15, "up", corners, tip_path=path)
    fig = tip_path_figure(result)
    fig.canvas.draw()  # type: ignore[no-untyped-call]
    ax = fig.axes[0]
    legend = ax.get_legend().get_window_extent()
    for line in ax.get_lines():
        for point in ax.transData.transform(line.get_xydata()):
            assert not legend.contains(*point), line.get_label()


# -- the rig ------------------------------------------------------------------------------------

RIG_TEXT = RIG.read_text()


def _rig_copy(tmp_path: Path, old: str, new: str) -> Path:
    """A copy of the shipped rig with ``old`` replaced by ``new``."""
    assert old in RIG_TEXT
    path = tmp_path / "my-arm2.yaml"
    path.write_text(RIG_TEXT.replace(old, new))
    return path


@pytest.mark.parametrize("rig", ["arm2.yaml", "arm6.yaml"])
def test_the_shipped_rigs_check(rig: str, capsys: pytest.CaptureFixture[str]) -> None:
    path = RIG.parent / rig
    assert cli_main(["rig", "check", str(path)]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"{path}: ok (1 bus, ")
    assert "1 timer, 1 group)" in out
    assert cli_main(["rig", "show", str(path)]) == 0
    assert "MuJoCo model arm" in capsys.readouterr().out


def test_the_app_runs_on_the_rig_it_is_given(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A changed group limit and a lockstep bus: the run uses them (and --sim changes
    nothing on a MuJoCo bus); --period-ms overrides the rig's timer."""
    rig = _rig_copy(tmp_path, "max_velocity: 2.5", "max_velocity: 1.5")
    rig.write_text(rig.read_text().replace("pacing: realtime", "pacing: lockstep"))
    out_dir = tmp_path / "out"
    argv = ["run", "--rig", str(rig), "--sim", "arm2", "--no-live", "--out", str(out_dir),
            "--duration", "4", "--period-ms", "4"]  # fmt: skip
    assert cli_main(argv) == 0  # no --virtual: the rig's lockstep
    out = capsys.readouterr().out
    assert "summary (MuJoCo arm2 square, lockstep)" in out
    assert "  rig                my-arm2.yaml, AxisGroup arm2 at most 1.5 rad/s, 15 " in out
    assert "AxisGroup period 4 ms" in out
    assert "corners reached    4/4" in out
    assert "  on exit            hold: shoulder done, elbow done" in out


def test_the_rigs_joint_limits_narrow_the_plan(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rig = _rig_copy(
        tmp_path,
        "{name: shoulder, driver: mujoco, device: joint, bus: arm2}",
        "{name: shoulder, driver: mujoco, device: joint, bus: arm2, limits: {position: [-0.1, 0.1]}}",
    )
    out_dir = tmp_path / "out"
    assert cli_main(["run", "--rig", str(rig), "arm2", "--virtual", "--out", str(out_dir)]) == 2
    err = capsys.readouterr().err
    assert "the square leaves the arm's reach: " in err
    assert "outside its range [-0.1000, +0.1000]" in err
    assert not out_dir.exists()  # refused before anything ran


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ("{name: tip_pos, driver: mujoco, device: sensor, bus: arm2}",
         "{name: tip, driver: mujoco, device: sensor, bus: arm2, params: {sensor: tip_pos}}",
         "rig my-arm2.yaml has no component 'tip_pos' (the app takes it by name)"),
        ("  arm2:\n    axes", "  arm:\n    axes", "rig my-arm2.yaml has no group 'arm2'"),
        ("[shoulder, elbow]", "[elbow, shoulder]", "group 'arm2' moves elbow, shoulder; the app "
         "needs shoulder, elbow, in this order"),
        ("period_ms: 2", "period_ms: 2.5", "rig my-arm2.yaml: timer arm2-sync period_ms 2.5: a "
         "whole multiple of the 1 ms physics step"),
    ],
)  # fmt: skip
def test_a_rig_without_what_the_app_takes_is_refused(
    old: str, new: str, message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rig = _rig_copy(tmp_path, old, new)
    assert cli_main(["run", "--rig", str(rig), "arm2", "--virtual", "--out", str(tmp_path)]) == 2
    assert message in capsys.readouterr().err


def test_the_pacing_flags_override_the_rigs() -> None:
    rig = arm2_rig()
    assert rig.options.pacing == "realtime"  # the shipped rig: as openel-async demo
    assert open_sim(rig=rig).pacing == "realtime"
    assert open_sim(rig=rig, realtime=False).pacing == "lockstep"  # --virtual
    lockstep = replace(rig, options=replace_struct(rig.options, pacing="lockstep"))
    assert open_sim(rig=lockstep).pacing == "lockstep"
    assert open_sim(rig=lockstep, realtime=True).pacing == "realtime"  # --realtime
