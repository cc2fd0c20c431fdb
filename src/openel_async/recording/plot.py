"""``openel-async record plot``: the demos' joint plot from a recording's ``/joint_states``.

It looks like the plots the demos write (``TrajectoryRecorder.plot`` of ``openel_mujoco``):
one subplot per joint, the actual position solid in the first colour of the cycle (``C0``),
the commanded one dashed in the second (``C1``), the y axis labelled with the name the
recording shows for the joint (its channel's ``label``, else the component's name) and its
unit, the legend where it covers the fewest points (``loc="best"``). A joint that barely
moves keeps a y span of at least :data:`MIN_SPAN` (0.1 rad, 1 cm), centred on its values, so
that noise does not look like motion. matplotlib's ``Figure`` is used directly (no pyplot, no
global backend change).
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import TYPE_CHECKING

from .reader import Recording
from .schemas import JOINT_STATES_TOPIC

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = [
    "ACTUAL_STYLE",
    "COMMANDED_STYLE",
    "MIN_SPAN",
    "joint_figure",
    "joint_series",
    "plot_recording",
]

ACTUAL_STYLE = {"color": "C0", "linestyle": "-", "linewidth": 1.2}
"""The actual position's line, as in the demos' plots."""
COMMANDED_STYLE = {"color": "C1", "linestyle": "--", "linewidth": 1.0}
"""The commanded position's line, as in the demos' plots."""
MIN_SPAN = {"rad": 0.1, "m": 0.01}
"""The smallest y span of a joint's subplot, by unit (others: the rad one)."""


def joint_series(
    recording: Recording,
) -> tuple[list[str], list[float], list[list[float]], list[list[float]]]:
    """(joint names, times in s from the first sample, commanded rows, actual rows) of the
    recording's joint states (a component whose channel says it is no joint is left out,
    from a recording made before joint states held joints only); a joint missing from a
    sample, or a value that is not known, is NaN."""
    samples = recording.topic(JOINT_STATES_TOPIC)
    excluded = {
        c.metadata.get("component")
        for c in recording.channels.values()
        if c.metadata.get("joint") == "false"
    }
    names: list[str] = []
    for sample in samples:
        for joint in sample["joints"]:
            if joint["name"] not in names and joint["name"] not in excluded:
                names.append(joint["name"])
    if not samples or not names:
        raise ValueError(f"{recording.path}: no joint states to plot ({JOINT_STATES_TOPIC})")
    t0 = samples[0]["time_ns"]
    times, commanded, actual = [], [], []
    for sample in samples:
        by_name = {j["name"]: j for j in sample["joints"]}
        times.append((sample["time_ns"] - t0) / 1e9)
        commanded.append([_num(by_name.get(n, {}).get("commanded")) for n in names])
        actual.append([_num(by_name.get(n, {}).get("position")) for n in names])
    return names, times, commanded, actual


def _num(value: object) -> float:
    return float(value) if isinstance(value, int | float) else math.nan


def _component_metadata(recording: Recording) -> dict[str, dict[str, str]]:
    return {
        c.metadata["component"]: c.metadata
        for c in recording.channels.values()
        if "component" in c.metadata
    }


def joint_figure(recording: Recording, *, title: str | None = None) -> Figure:
    """The joint plot of ``recording`` (see the module docstring), not saved."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    names, times, commanded, actual = joint_series(recording)
    metadata = _component_metadata(recording)
    fig = Figure(figsize=(8, 1.8 + 1.6 * len(names)))
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(names), 1, sharex=True, squeeze=False)
    for j, name in enumerate(names):
        ax = axes[j][0]
        meta = metadata.get(name, {})
        unit = meta.get("unit", "rad")
        act = [row[j] for row in actual]
        cmd = [row[j] for row in commanded]
        if any(not math.isnan(v) for v in act):  # no entry for a curve that is not there
            ax.plot(times, act, label="actual", **ACTUAL_STYLE)
        if any(not math.isnan(v) for v in cmd):
            ax.plot(times, cmd, label="commanded", **COMMANDED_STYLE)
        ax.set_ylabel(f"{meta.get('label', name)} [{unit}]")
        ax.grid(True, alpha=0.3)
        values = [v for v in (*act, *cmd) if not math.isnan(v)]
        span = MIN_SPAN.get(unit, MIN_SPAN["rad"])
        if values and max(values) - min(values) < span:
            centre = (max(values) + min(values)) / 2
            ax.set_ylim(centre - span / 2, centre + span / 2)
    axes[0][0].legend(loc="best", fontsize="small")
    axes[-1][0].set_xlabel("time [s]")
    fig.suptitle(title or f"{recording.path.stem}: commanded vs actual (recorded)")
    fig.tight_layout()
    return fig


def plot_recording(
    recording: Recording, out_dir: str | os.PathLike[str], *, stem: str | None = None
) -> list[Path]:
    """Write ``<stem>_joints.png`` (stem: the recording's file name) in ``out_dir``; the
    paths written."""
    stem = stem or recording.path.stem
    fig = joint_figure(recording, title=f"{stem}: commanded vs actual (recorded)")
    out = Path(out_dir) / f"{stem}_joints.png"
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.stem + ".tmp.png")
    try:
        fig.savefig(tmp, dpi=110)
        tmp.replace(out)
    finally:
        tmp.unlink(missing_ok=True)
    return [out]
