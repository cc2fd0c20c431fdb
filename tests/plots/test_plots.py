"""The trajectory plot writes a real PNG and refuses malformed data."""

from __future__ import annotations

from pathlib import Path

import pytest

from openel_async.plots import plot_joint_trajectories


def test_writes_a_png(tmp_path: Path) -> None:
    times = [i * 0.01 for i in range(100)]
    commanded = [[t, -t] for t in times]
    actual = [[t * 0.9, -t * 0.9] for t in times]
    out = plot_joint_trajectories(
        tmp_path / "sub" / "plot.png", times, commanded, actual, ["a", "b"]
    )
    data = out.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    assert len(data) > 5_000


def test_refuses_mismatched_shapes(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="one row per sample"):
        plot_joint_trajectories(tmp_path / "p.png", [0.0, 1.0], [[0.0]], [[0.0], [1.0]], ["a"])
    with pytest.raises(ValueError, match="2 values"):
        plot_joint_trajectories(tmp_path / "p.png", [0.0], [[0.0]], [[0.0]], ["a", "b"])
    with pytest.raises(ValueError, match="no samples"):
        plot_joint_trajectories(tmp_path / "p.png", [], [], [], ["a"])
