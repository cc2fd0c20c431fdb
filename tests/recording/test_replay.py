"""Replay: the recorded commands, at their recorded times, reproduce the recorded final
positions on the sim rig."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from openel_async.cli import main as cli_main
from openel_async.recording import read_recording
from openel_async.recording.replay import (
    recorded_commands,
    recorded_final_positions,
    replay,
    sim_rig,
)

from .conftest import MOTOR_OPTIONS, TARGETS, scenario


async def test_replay_on_the_sim_rig_reproduces_final_positions(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    await scenario(path)
    recording = read_recording(path)
    recorded = recorded_final_positions(recording)
    assert recorded == pytest.approx({f"AXIS_{i}": t[2] for i, t in enumerate(TARGETS)})
    assert len(recorded_commands(recording)) == 6
    sent: list[float] = []
    result = await replay(
        recording, sim_rig(**MOTOR_OPTIONS), on_command=lambda c: sent.append(c.value)
    )
    assert result.commands == 6 and not result.refused
    assert sorted(sent) == sorted(t for targets in TARGETS for t in targets)
    assert result.final_positions == pytest.approx(recorded, abs=1e-9)
    assert result.max_final_error < 1e-9
    # The replay ran on the recorded timing: from the first command to the last record.
    assert result.duration_s == pytest.approx(1.8, abs=0.02)


async def test_replay_with_slower_motors_misses_the_recorded_positions(tmp_path: Path) -> None:
    """The comparison can fail: motors too slow for the recorded timing end elsewhere."""
    path = tmp_path / "run.mcap"
    await scenario(path)
    recording = read_recording(path)
    result = await replay(
        recording, sim_rig(max_velocity=0.2, max_acceleration=1.0), settle_timeout_s=0.0
    )
    assert result.max_final_error > 0.05


def test_replay_cli_on_the_demo(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "demo.mcap"
    args = ["demo", "--bus", "sim", "--virtual", "--duration", "2", "--no-live"]
    assert cli_main([*args, "--record", str(out)]) == 0
    capsys.readouterr()
    options = ["--option", "max_velocity=3.0", "--option", "max_acceleration=40.0"]
    assert cli_main(["replay", str(out), *options]) == 0
    text = capsys.readouterr().out
    assert "0 refused" in text
    assert "max final position difference 0 rad" in text
    assert "MOTOR_1          final +0.000000 rad (recorded +0.000000 rad)" in text
    assert cli_main(["replay", str(out), "--rig", "nonsense"]) == 2
    assert "--rig" in capsys.readouterr().err


def _cli(capsys: pytest.CaptureFixture[str], *args: str) -> subprocess.CompletedProcess[str]:
    """``openel-async ARGS`` run in this process: its exit status and what it printed."""
    capsys.readouterr()
    code = cli_main(list(args))
    out, err = capsys.readouterr()
    return subprocess.CompletedProcess(["openel-async", *args], code, out, err)


@pytest.mark.parametrize(
    ("option", "message"),
    [
        (
            "max_velocty=3",
            "openel-async replay: --option: 'max_velocty' is not an option of the motor "
            "SimMotor (did you mean max_velocity? it takes inertia, initial_position, ",
        ),
        (
            "max_velocity=abc",
            "openel-async replay: --option: max_velocity='abc' is not allowed: expected a "
            "number (default max_velocity=2.0)",
        ),
        (
            "max_velocity=-1",
            "openel-async replay: --option: max_velocity=-1.0 is not allowed: expected a "
            "finite value > 0",
        ),
        ("max_velocity", "openel-async replay: --option: 'max_velocity' is not KEY=VALUE"),
    ],
)
def test_replay_options_are_checked_before_anything_runs(
    tmp_path: Path, option: str, message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """A misspelt, mistyped, refused or malformed --option: one line naming --option, exit
    status 2, before the recording is read or anything is replayed (it printed a 56-line
    ExceptionGroup with status 1; a malformed one was reported as --rig)."""
    path = tmp_path / "run.mcap"
    path.write_bytes(b"not read: the options come first")
    result = _cli(capsys, "replay", str(path), "--option", option)
    assert result.returncode == 2, result.stderr
    assert result.stderr.startswith(message), result.stderr
    assert len(result.stderr.splitlines()) == 1 and "Traceback" not in result.stderr


def test_a_file_that_is_not_mcap_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "notes.mcap"
    path.write_text("hello\n")
    result = _cli(capsys, "record", "info", str(path))
    assert result.returncode == 1
    assert result.stderr == (
        f"openel-async record info: {path}: not an MCAP file (it does not begin with the "
        "MCAP magic)\n"
    )
    assert result.stdout == ""
    missing = tmp_path / "missing.mcap"
    result = _cli(capsys, "record", "plot", str(missing))
    assert result.returncode == 2
    assert result.stderr == f"openel-async record plot: {missing}: no such file\n"


def test_replay_lines_say_units_and_labels() -> None:
    """Final positions with their unit; a component named after its device's class shows
    its device's own name (the recorded channel's label)."""
    from openel_async.recording.replay import ReplayResult

    result = ReplayResult(
        commands=3,
        final_positions={"HalMotorMuJoCoShoulder": 0.615, "RAIL": 0.25},
        recorded_final_positions={"HalMotorMuJoCoShoulder": 0.615, "RAIL": 0.25},
        units={"HalMotorMuJoCoShoulder": "rad", "RAIL": "m"},
        labels={"HalMotorMuJoCoShoulder": "shoulder"},
    )
    assert result.lines()[1:] == [
        "  shoulder         final +0.615000 rad (recorded +0.615000 rad)",
        "  RAIL             final +0.250000 m (recorded +0.250000 m)",
        "max final position difference 0",
    ]
