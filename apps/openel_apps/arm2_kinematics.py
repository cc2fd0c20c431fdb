"""The kinematics of the 2-DoF MuJoCo arm (``arm2``) and the geometry of the square its tip
traces (:mod:`.arm2_square`).

- :class:`PlanarArm`: the analytic forward and inverse kinematics of the arm's two hinges
  (both about z, so the tip moves in the horizontal plane of the shoulder); the link lengths,
  shoulder position and joint ranges are read from the model;
- :func:`square_corners`, :func:`edge_waypoints`: the square and the timed IK waypoints of
  one of its edges; :func:`distance_to_polygon`: the tip's distance from its outline.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

from openel_async.motion import Waypoint

from .arm_demo import UnreachableError, line_waypoints

if TYPE_CHECKING:
    import mujoco

__all__ = [
    "DEFAULT_CENTER_M",
    "DEFAULT_POINTS",
    "DEFAULT_SIDE_M",
    "Elbow",
    "PlanarArm",
    "distance_to_polygon",
    "distance_to_segment",
    "edge_waypoints",
    "square_corners",
]

Elbow = Literal["up", "down"]
DEFAULT_SIDE_M = 0.15
DEFAULT_CENTER_M = (0.35, 0.0)
DEFAULT_POINTS = 16
"""IK waypoints per edge: with 16 per 0.15 m edge the chord between two stays well under a
millimetre from the edge."""


@dataclass(frozen=True, slots=True)
class PlanarArm:
    """Forward and inverse kinematics of a planar two-link arm (angles in rad, lengths in m).

    ``shoulder`` turns link 1 (length ``link1``) about the base at ``base``; ``elbow`` turns
    link 2 (``link2``) relative to link 1; at zero both links point along +x.
    """

    link1: float
    link2: float
    base: tuple[float, float] = (0.0, 0.0)
    shoulder_range: tuple[float, float] = (-math.pi, math.pi)
    elbow_range: tuple[float, float] = (-math.pi, math.pi)

    @classmethod
    def from_model(cls, model: mujoco.MjModel) -> PlanarArm:
        """The geometry of the shipped ``arm2`` model (bodies ``link1``/``link2``, site ``tip``,
        joints ``shoulder``/``elbow``)."""
        base = model.body("link1").pos
        return cls(
            link1=float(model.body("link2").pos[0]),
            link2=float(model.site("tip").pos[0]),
            base=(float(base[0]), float(base[1])),
            shoulder_range=_range(model, "shoulder"),
            elbow_range=_range(model, "elbow"),
        )

    @property
    def reach(self) -> tuple[float, float]:
        """Smallest and largest distance of the tip from the shoulder."""
        return abs(self.link1 - self.link2), self.link1 + self.link2

    def forward(self, shoulder: float, elbow: float) -> tuple[float, float]:
        """Tip position for the joint angles."""
        x0, y0 = self.base
        a = shoulder + elbow
        return (
            x0 + self.link1 * math.cos(shoulder) + self.link2 * math.cos(a),
            y0 + self.link1 * math.sin(shoulder) + self.link2 * math.sin(a),
        )

    def inverse(self, x: float, y: float, elbow: Elbow = "up") -> tuple[float, float]:
        """Joint angles ``(shoulder, elbow)`` that put the tip on ``(x, y)``.

        ``elbow="up"``: the elbow lies to the left of the line from the shoulder to the tip,
        seen from above (counter-clockwise side; elbow angle <= 0); ``"down"``: to the right
        (elbow angle >= 0).  Raises :class:`UnreachableError` when the point is out of reach or
        needs a joint outside its range.
        """
        if elbow not in ("up", "down"):
            raise ValueError(f"elbow must be 'up' or 'down', not {elbow!r}")
        dx, dy = x - self.base[0], y - self.base[1]
        r2 = dx * dx + dy * dy
        l1, l2 = self.link1, self.link2
        low, high = self.reach
        r = math.sqrt(r2)
        tol = 1e-12
        if r > high + tol or r < low - tol:
            raise UnreachableError(
                f"point ({x:.4f}, {y:.4f}) m is out of reach: {r:.4f} m from the shoulder, "
                f"the tip reaches {low:.4f} to {high:.4f} m"
            )
        c2 = min(1.0, max(-1.0, (r2 - l1 * l1 - l2 * l2) / (2.0 * l1 * l2)))
        q2 = math.acos(c2)
        if elbow == "up":
            q2 = -q2
        q1 = math.atan2(dy, dx) - math.atan2(l2 * math.sin(q2), l1 + l2 * math.cos(q2))
        q1 = math.atan2(math.sin(q1), math.cos(q1))  # (-pi, pi]
        for name, value, (lo, hi) in (
            ("shoulder", q1, self.shoulder_range),
            ("elbow", q2, self.elbow_range),
        ):
            if not lo <= value <= hi:
                raise UnreachableError(
                    f"point ({x:.4f}, {y:.4f}) m needs {name} = {value:+.4f} rad, outside its "
                    f"range [{lo:+.4f}, {hi:+.4f}] (elbow {elbow}); try the other elbow"
                )
        return q1, q2


def _range(model: mujoco.MjModel, joint: str) -> tuple[float, float]:
    j = model.joint(joint)
    if not bool(j.limited[0]):
        return (-math.pi, math.pi)
    return float(j.range[0]), float(j.range[1])


# -- the square ---------------------------------------------------------------------------------


def square_corners(
    center: tuple[float, float] = DEFAULT_CENTER_M, side: float = DEFAULT_SIDE_M
) -> list[tuple[float, float]]:
    """The four corners, counter-clockwise seen from above, from the (-x, -y) one."""
    cx, cy = center
    h = side / 2.0
    return [(cx - h, cy - h), (cx + h, cy - h), (cx + h, cy + h), (cx - h, cy + h)]


def edge_waypoints(
    arm: PlanarArm,
    start: tuple[float, float],
    end: tuple[float, float],
    *,
    duration: float,
    points: int = DEFAULT_POINTS,
    elbow: Elbow = "up",
) -> list[Waypoint]:
    """``points`` timed waypoints along the straight edge ``start`` -> ``end`` (the last one is
    ``end`` at ``duration``), as joint angles; minimum-jerk spacing in time."""
    return line_waypoints(
        lambda p: arm.inverse(p[0], p[1], elbow), start, end, duration=duration, points=points
    )


def distance_to_segment(
    p: tuple[float, float], a: tuple[float, float], b: tuple[float, float]
) -> float:
    ax, ay = a
    vx, vy = b[0] - ax, b[1] - ay
    wx, wy = p[0] - ax, p[1] - ay
    length2 = vx * vx + vy * vy
    t = 0.0 if length2 == 0 else max(0.0, min(1.0, (wx * vx + wy * vy) / length2))
    return math.hypot(wx - t * vx, wy - t * vy)


def distance_to_polygon(p: tuple[float, float], corners: Sequence[tuple[float, float]]) -> float:
    """Distance from ``p`` to the closed polygon's edges (its outline, not its area)."""
    n = len(corners)
    return min(distance_to_segment(p, corners[i], corners[(i + 1) % n]) for i in range(n))
