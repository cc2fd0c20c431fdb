"""``openel-async record plot``: the demos' joint plot (commanded dashed vs actual solid, one
subplot per joint, :func:`openel_async.plots.plot_joint_trajectories`) from a recording's
``/joint_states``."""

from __future__ import annotations

import math
import os
from pathlib import Path

from ..plots import plot_joint_trajectories
from .reader import Recording
from .schemas import JOINT_STATES_TOPIC

__all__ = ["joint_series", "plot_recording"]


def joint_series(
    recording: Recording,
) -> tuple[list[str], list[float], list[list[float]], list[list[float]]]:
    """(joint names, times in s from the first sample, commanded rows, actual rows) of the
    recording's joint states; a joint missing from a sample, or an actual value that could not
    be read, is NaN."""
    samples = recording.topic(JOINT_STATES_TOPIC)
    names: list[str] = []
    for sample in samples:
        for joint in sample["joints"]:
            if joint["name"] not in names:
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


def plot_recording(
    recording: Recording, out_dir: str | os.PathLike[str], *, stem: str | None = None
) -> list[Path]:
    """Write ``<stem>_joints.png`` (stem: the recording's file name) in ``out_dir``; the
    paths written."""
    names, times, commanded, actual = joint_series(recording)
    stem = stem or recording.path.stem
    out = Path(out_dir) / f"{stem}_joints.png"
    tmp = out.with_name(out.stem + ".tmp.png")
    try:
        plot_joint_trajectories(
            tmp, times, commanded, actual, names, title=f"{stem}: commanded vs actual (recorded)"
        )
        tmp.replace(out)
    finally:
        tmp.unlink(missing_ok=True)
    return [out]
