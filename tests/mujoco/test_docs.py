"""The quick-start example of docs/mujoco.md runs as written."""

from __future__ import annotations

import pathlib
import re

import pytest

DOC = pathlib.Path(__file__).resolve().parents[2] / "docs" / "mujoco.md"


def test_quick_start_example_runs(
    tmp_path: pathlib.Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    blocks = re.findall(r"^```python\n(.*?)^```$", DOC.read_text(), flags=re.M | re.S)
    monkeypatch.chdir(tmp_path)
    exec(blocks[0], {"__name__": "docs_mujoco_quick_start"})
    assert (tmp_path / "arm2.png").read_bytes()[:4] == b"\x89PNG"
    assert "TimedValue(values=" in capsys.readouterr().out


def test_performance_example_runs(capsys: pytest.CaptureFixture[str]) -> None:
    """The banks-and-plain-observer control loop of the Performance section."""
    blocks = re.findall(r"^```python\n(.*?)^```$", DOC.read_text(), flags=re.M | re.S)
    (block,) = [b for b in blocks if "ActuatorBank" in b]
    exec(block, {"__name__": "docs_mujoco_performance"})
    assert "500 control steps in 0.500 s of simulated time" in capsys.readouterr().out


def test_hal4rt_example_runs(capsys: pytest.CaptureFixture[str]) -> None:
    """The Motor and GyroSensor example of the HAL4RT section."""
    blocks = re.findall(r"^```python\n(.*?)^```$", DOC.read_text(), flags=re.M | re.S)
    (block,) = [b for b in blocks if "GyroSensor" in b]
    exec(block, {"__name__": "docs_mujoco_hal4rt"})
    speed, gyro = re.search(  # type: ignore[union-attr]
        r"([\d.]+) deg/s, gyro ([\d.]+) deg/s", capsys.readouterr().out
    ).groups()
    assert abs(float(speed) - 45.0) < 1.0 and abs(float(gyro) - 45.0) < 1.0
