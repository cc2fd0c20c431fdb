"""The openel-async command line: demo, devices, run, logging."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from openel_apps.twoaxis import run_demo
from openel_async.cli import main
from openel_async.cli.logs import reset_logging
from openel_async.registry import discover_drivers


@pytest.fixture(autouse=True)
def _reset_logging() -> Iterator[None]:
    """main() configures structlog for the process; undo it after each test."""
    yield
    reset_logging()


def test_devices_lists_the_sim_driver(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["devices"]) == 0
    out = capsys.readouterr().out
    assert "sim" in out and "openel_sim.motor.SimMotor" in out


def test_registry_finds_every_driver_package() -> None:
    names = {entry.name for entry in discover_drivers()}
    assert {"sim", "mujoco", "can", "serial"} <= names
    sim = next(e for e in discover_drivers() if e.name == "sim")
    assert sim.info is not None and "motor" in sim.info.devices


def test_virtual_demo_prints_a_summary(capsys: pytest.CaptureFixture[str]) -> None:
    code = main(
        ["demo", "--bus", "sim", "--virtual", "--duration", "2", "--no-live", "--inject-fault"]
    )
    assert code == 0
    out = capsys.readouterr().out
    assert "timer ticks        200 (missed 0)" in out
    assert (
        "errors             1: MOTOR_2 error 1 (device error: injected over-temperature trip)"
        in out
    )
    assert "recoveries         1" in out
    assert "final positions    MOTOR_1 +0.0000 rad, MOTOR_2 +0.0000 rad" in out


async def test_demo_scenario_drives_both_axes_in_step() -> None:
    summary = await run_demo(duration_s=3.0, period_ms=10.0, virtual=True)
    assert summary.ticks == 300
    # Both axes are commanded on every tick the application handled; the tick due at
    # the very end may be discarded by stop_timer before the async observer runs.
    assert summary.setpoints in (2 * 299, 2 * 300)
    assert summary.errors == [] and summary.recoveries == 0
    assert summary.completed_events >= 2  # at least the two homing moves
    assert summary.sensor_reads == 2 * 30
    assert summary.max_sensor_skew_us == 0.0  # read on one clock, one instant
    assert summary.max_tracking_error_rad < 0.05


def test_bad_arguments_are_refused(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["demo", "--duration", "0"]) == 2
    assert main(["demo", "--virtual", "--bus", "can"]) in (2,)
    assert main(["demo", "--inject-fault"]) == 2  # the MuJoCo arm has no fault to inject
    assert "--inject-fault needs --bus sim or --bus can" in capsys.readouterr().err
    assert main(["demo", "--virtual", "--duration", "1"]) == 2  # a 1 s lap of the square
    assert "error: --duration 1: a lap takes at least " in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["demo", "--bus", "carrier-pigeon"])


def test_the_default_demo_is_the_mujoco_arm(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = main(["demo", "--virtual", "--no-live", "--out", str(tmp_path)])  # lockstep
    out = capsys.readouterr().out
    assert code == 0, out
    assert "summary (MuJoCo arm2 square, lockstep)" in out
    assert "corners reached    4/4" in out
    assert "square             1 lap of a 15 cm square, 5 s per lap" in out  # --duration: 5 s lap
    assert f"files in {tmp_path.resolve()}/" in out
    assert (tmp_path / "arm2_square_joints.png").read_bytes()[:4] == b"\x89PNG"


def test_the_demo_runs_the_arm6_pick_and_place(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = main(["demo", "--app", "arm6", "--virtual", "--no-live", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "summary (MuJoCo arm6 pick and place, lockstep)" in out
    assert "box                picked and carried" in out
    assert "motions            7/7 succeeded" in out
    assert f"files in {tmp_path.resolve()}/" in out  # a heading with the files below it
    assert "  joint plot         arm6_pick_place_joints.png" in out
    assert (tmp_path / "arm6_pick_place_joints.png").read_bytes()[:4] == b"\x89PNG"


def test_demo_app_options_are_checked(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["demo", "--app", "arm6", "--bus", "sim", "--virtual"]) == 2
    assert "--app needs --bus mujoco" in capsys.readouterr().err
    assert main(["demo", "--app", "arm6", "--virtual", "--duration", "1", "--no-live"]) == 2
    assert "openel-async demo: error: --duration 1: the sequence takes at least" in (
        capsys.readouterr().err
    )
    assert main(["demo", "--app", "arm7"]) == 2
    assert "no app named 'arm7' (registered: arm2, arm6, " in capsys.readouterr().err
    # asked for by name, the app does not fall back to the sim demo when MuJoCo cannot load
    monkeypatch.setitem(sys.modules, "openel_mujoco", None)
    assert main(["demo", "--app", "arm6", "--virtual", "--no-live"]) == 1
    captured = capsys.readouterr()
    assert "MuJoCo cannot run --app arm6: ModuleNotFoundError" in captured.err
    assert "summary" not in captured.out


@pytest.mark.parametrize("failure", ["import", "model"])
def test_the_demo_falls_back_to_the_sim_demo_without_mujoco(
    failure: str, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from openel_apps import arm_demo
    from openel_mujoco import ModelLoadError

    if failure == "import":
        monkeypatch.setitem(sys.modules, "openel_mujoco", None)  # import raises ImportError
    else:

        def broken(model: str, *, pacing: str) -> None:
            raise ModelLoadError(f"model file not found: {model}.xml")

        monkeypatch.setattr("openel_mujoco.MujocoSim", broken)
        assert arm_demo.open_arm_sim  # the app's loader imports MujocoSim when it runs
    code = main(["demo", "--virtual", "--duration", "1", "--no-live"])
    captured = capsys.readouterr()
    assert code == 0
    assert "summary (simulated devices, openel_sim)" in captured.out
    assert "mujoco_unavailable" in captured.err
    expected = "ModuleNotFoundError" if failure == "import" else "ModelLoadError: model file not"
    assert expected in captured.err


def test_run_rejects_a_file_without_main(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    app = tmp_path / "noapp.py"
    app.write_text("x = 1\n")
    assert main(["run", str(app)]) == 2
    assert "async def main(argv)" in capsys.readouterr().err
    assert main(["run", str(tmp_path / "missing.py")]) == 2


def test_run_passes_arguments_to_an_app(tmp_path: Path) -> None:
    app = tmp_path / "hello.py"
    app.write_text(
        "async def main(argv: list[str]) -> int:\n"
        "    return 0 if argv == ['--answer', '42'] else 3\n"
    )
    assert main(["run", str(app), "--answer", "42"]) == 0
    assert main(["run", str(app)]) == 3


def test_json_logs_go_to_stderr_as_json_lines() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "openel_async.cli", "--log-format", "json", "demo",
         "--bus", "sim", "--virtual", "--duration", "0.2", "--no-live", "-v"],
        capture_output=True, text=True, timeout=60, check=True,
    )  # fmt: skip
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert lines
    records = [json.loads(line) for line in lines]
    assert any(r["event"] == "state_changed" and r["new"] == "Active" for r in records)
    assert all("level" in r and "timestamp" in r for r in records)
    assert not any(r["level"] == "debug" for r in records)
    assert "summary (simulated devices, openel_sim)" in result.stdout
