"""Replay: the recorded commands, at their recorded times, reproduce the recorded final
positions on the sim rig."""

from __future__ import annotations

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
    assert "max final position difference 0" in text
    assert cli_main(["replay", str(out), "--rig", "nonsense"]) == 2
    assert "--rig" in capsys.readouterr().err
