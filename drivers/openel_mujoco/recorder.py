"""TrajectoryRecorder: commanded vs actual joint positions over simulated time, for plots.

Synchronous and cheap: a sample reads the simulation's arrays, nothing is awaited.  Either call
:meth:`TrajectoryRecorder.sample` yourself, or attach the recorder to the simulation (``with
recorder:`` or :meth:`~TrajectoryRecorder.attach`) and it samples every ``every`` physics steps
from the simulation loop::

    recorder = TrajectoryRecorder(sim, ["shoulder", "elbow"], every=10)
    with recorder:
        ...                                   # run the application
    recorder.plot("trajectory.png")
    t, commanded, actual = recorder.arrays()

The commanded position of a joint is its position target in POSITION mode (the position
actuator's ctrl, or the built-in PD target) and NaN in the other modes.
"""

from __future__ import annotations

import csv
import os
import pathlib
from collections.abc import Sequence
from types import TracebackType
from typing import TYPE_CHECKING, Self

import numpy as np
import numpy.typing as npt

from openel_async.errors import BadParameterError

if TYPE_CHECKING:
    from .devices import MujocoJoint
    from .sim import MujocoSim

__all__ = ["TrajectoryRecorder"]

Array = npt.NDArray[np.float64]


class TrajectoryRecorder:
    """Samples (sim time, commanded positions, actual positions) of some joints of a sim."""

    def __init__(
        self,
        sim: MujocoSim,
        joints: Sequence[str] | None = None,
        *,
        every: int = 1,
        max_samples: int | None = None,
    ) -> None:
        if isinstance(every, bool) or not isinstance(every, int) or every < 1:
            raise BadParameterError("every", every, "an int >= 1 (physics steps per sample)")
        if max_samples is not None and (
            isinstance(max_samples, bool) or not isinstance(max_samples, int) or max_samples < 1
        ):
            raise BadParameterError("max_samples", max_samples, "an int >= 1 or None")
        names = list(sim.joints) if joints is None else list(joints)
        if not names:
            raise BadParameterError("joints", joints, "at least one joint (none mapped yet)")
        self.sim = sim
        self.joint_names: tuple[str, ...] = tuple(names)
        self._joints: tuple[MujocoJoint, ...] = tuple(sim.actuator(n) for n in names)
        self.every = every
        self.max_samples = max_samples
        self._times: list[float] = []
        self._commanded: list[list[float]] = []
        self._actual: list[list[float]] = []
        self._countdown = 0
        self._attached = False
        self.dropped = 0
        """Samples not taken because max_samples was reached."""

    # -- sampling --------------------------------------------------------------------------
    def sample(self) -> None:
        """Record the current state (sim time in seconds since the start or last reset)."""
        if self.max_samples is not None and len(self._times) >= self.max_samples:
            self.dropped += 1
            return
        self._times.append(self.sim.time_ns / 1e9)
        self._commanded.append([j.commanded_position for j in self._joints])
        self._actual.append([j.position for j in self._joints])

    def _on_step(self) -> None:
        self._countdown -= 1
        if self._countdown <= 0:
            self._countdown = self.every
            if self.sim.fault is None:
                self.sample()

    def attach(self) -> None:
        """Sample from the simulation loop, every ``every`` physics steps (the first now)."""
        if self._attached:
            return
        self._attached = True
        self._countdown = self.every
        self.sample()
        self.sim.add_step_hook(self._on_step)

    def detach(self) -> None:
        if self._attached:
            self._attached = False
            self.sim.remove_step_hook(self._on_step)

    def __enter__(self) -> Self:
        self.attach()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.detach()

    def clear(self) -> None:
        self._times.clear()
        self._commanded.clear()
        self._actual.clear()
        self.dropped = 0

    # -- results ---------------------------------------------------------------------------
    def __len__(self) -> int:
        return len(self._times)

    def arrays(self) -> tuple[Array, Array, Array]:
        """``(t, commanded, actual)``: shapes (n,), (n, joints), (n, joints)."""
        n, k = len(self._times), len(self._joints)
        t = np.asarray(self._times, dtype=np.float64)
        commanded = np.asarray(self._commanded, dtype=np.float64).reshape(n, k)
        actual = np.asarray(self._actual, dtype=np.float64).reshape(n, k)
        return t, commanded, actual

    @property
    def times(self) -> Array:
        return self.arrays()[0]

    @property
    def commanded(self) -> Array:
        return self.arrays()[1]

    @property
    def actual(self) -> Array:
        return self.arrays()[2]

    def to_csv(self, path: str | os.PathLike[str]) -> pathlib.Path:
        """Columns: t, then <joint>_cmd and <joint>_actual for each joint."""
        out = pathlib.Path(path)
        out.parent.mkdir(parents=True, exist_ok=True)
        header = ["t"]
        for name in self.joint_names:
            header += [f"{name}_cmd", f"{name}_actual"]
        with out.open("w", newline="", encoding="utf-8") as f:
            writer = csv.writer(f)
            writer.writerow(header)
            for t, cmd, act in zip(self._times, self._commanded, self._actual, strict=True):
                row: list[float] = [t]
                for c, a in zip(cmd, act, strict=True):
                    row += [c, a]
                writer.writerow([repr(v) for v in row])
        return out

    def plot(self, path: str | os.PathLike[str], *, title: str | None = None) -> pathlib.Path:
        """Write a PNG with one panel per joint (commanded dashed, actual solid).

        Uses a ``Figure`` with the Agg canvas directly: no pyplot, no global backend change.
        """
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        t, commanded, actual = self.arrays()
        k = len(self.joint_names)
        fig = Figure(figsize=(8, 1.8 + 1.6 * k))
        FigureCanvasAgg(fig)
        axes = fig.subplots(k, 1, sharex=True, squeeze=False)
        for i, name in enumerate(self.joint_names):
            ax = axes[i][0]
            ax.plot(t, actual[:, i], color="C0", label="actual", linewidth=1.2)
            ax.plot(t, commanded[:, i], "--", color="C1", label="commanded", linewidth=1.0)
            unit = "rad" if self._joints[i].rotational else "m"
            ax.set_ylabel(f"{name} [{unit}]")
            ax.grid(True, alpha=0.3)
        axes[0][0].legend(loc="best", fontsize="small")
        axes[-1][0].set_xlabel("simulated time [s]")
        fig.suptitle(title or f"{self.sim.name}: commanded vs actual joint positions")
        fig.tight_layout()
        out = pathlib.Path(path)
        out.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(out)
        return out
