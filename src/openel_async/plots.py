"""PNG plots of commanded vs actual joint trajectories (matplotlib, headless).

matplotlib is imported on first use, with the non-interactive Agg backend, so the
framework does not pay its import time and never needs a display.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path


def plot_joint_trajectories(
    path: str | Path,
    times_s: Sequence[float],
    commanded: Sequence[Sequence[float]],
    actual: Sequence[Sequence[float]],
    joint_names: Sequence[str],
    *,
    title: str = "commanded vs actual joint positions",
    unit: str = "rad",
) -> Path:
    """One subplot per joint: commanded (dashed) and actual (solid) over time.

    ``commanded`` and ``actual`` are sample-major: one row of joint values per time.
    """
    if not (len(times_s) == len(commanded) == len(actual)):
        raise ValueError(
            f"times_s, commanded and actual must have one row per sample "
            f"(got {len(times_s)}, {len(commanded)}, {len(actual)})"
        )
    if not times_s:
        raise ValueError("no samples to plot")
    n = len(joint_names)
    for name, rows in (("commanded", commanded), ("actual", actual)):
        if any(len(row) != n for row in rows):
            raise ValueError(f"every row of {name} must have {n} values (one per joint)")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(n, 1, sharex=True, figsize=(9, 1.9 * n + 1.0), squeeze=False)
    for j, name in enumerate(joint_names):
        ax = axes[j][0]
        # The colours of every plot of the project (the demos', ``record plot``): actual solid
        # C0, commanded dashed C1.
        ax.plot(times_s, [row[j] for row in actual], "-", color="C0", label="actual", linewidth=1.2)
        ax.plot(
            times_s,
            [row[j] for row in commanded],
            "--",
            color="C1",
            label="commanded",
            linewidth=1.0,
        )
        ax.set_ylabel(f"{name}\n[{unit}]")
        ax.grid(True, alpha=0.3)
    axes[0][0].legend(loc="best", fontsize="small")
    axes[-1][0].set_xlabel("time [s]")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
