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


def test_colours_are_those_of_every_plot_of_the_project(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Issue 21 point 16: actual solid C0, commanded dashed C1, as the demos and
    ``record plot`` draw them (this plot had them the other way round)."""
    from matplotlib.colors import to_hex
    from matplotlib.figure import Figure

    figures: list[Figure] = []
    save = Figure.savefig

    def keep(self: Figure, *args: object, **kwargs: object) -> None:
        figures.append(self)
        save(self, *args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(Figure, "savefig", keep)
    times = [0.0, 0.5, 1.0]
    plot_joint_trajectories(tmp_path / "p.png", times, [[0.0]] * 3, [[0.1]] * 3, ["a"])
    lines = {line.get_label(): line for line in figures[0].axes[0].get_lines()}
    assert (to_hex(lines["actual"].get_color()), lines["actual"].get_linestyle()) == (
        to_hex("C0"),
        "-",
    )
    assert (to_hex(lines["commanded"].get_color()), lines["commanded"].get_linestyle()) == (
        to_hex("C1"),
        "--",
    )
