"""Inverse kinematics of the arm apps: round trips, MuJoCo agreement, unreachable targets."""

from __future__ import annotations

import itertools
import math

import mujoco
import numpy as np
import pytest

from openel_apps.arm2_square import (
    PlanarArm,
    SquareOptions,
    UnreachableError,
    distance_to_polygon,
    edge_waypoints,
    plan_square,
    square_corners,
)
from openel_apps.arm6_pick_place import Arm6Kinematics
from openel_mujoco import load_model

ARM2 = PlanarArm.from_model(load_model("arm2"))


def test_the_arm2_geometry_comes_from_the_model() -> None:
    assert ARM2.link1 == pytest.approx(0.30)
    assert ARM2.link2 == pytest.approx(0.25)
    assert ARM2.reach == pytest.approx((0.05, 0.55))
    assert ARM2.shoulder_range == pytest.approx((-2.6, 2.6))
    assert ARM2.elbow_range == pytest.approx((-2.5, 2.5))


@pytest.mark.parametrize("elbow", ["up", "down"])
def test_forward_of_inverse_is_the_point(elbow: str) -> None:
    points = [(0.35, 0.0), (0.275, -0.075), (0.425, 0.075), (0.1, 0.3), (0.5, -0.1), (0.0, 0.2)]
    for x, y in points:
        shoulder, elbow_angle = ARM2.inverse(x, y, elbow)  # type: ignore[arg-type]
        assert ARM2.forward(shoulder, elbow_angle) == pytest.approx((x, y), abs=1e-12)
        assert (elbow_angle <= 0) if elbow == "up" else (elbow_angle >= 0)


def test_forward_kinematics_agrees_with_mujoco() -> None:
    model = load_model("arm2")
    data = mujoco.MjData(model)
    for q in [(0.0, 0.0), (0.6, -2.0), (-1.2, 1.3), (2.0, 0.4)]:
        data.qpos[:2] = q
        mujoco.mj_kinematics(model, data)
        tip = data.site("tip").xpos
        assert ARM2.forward(*q) == pytest.approx((tip[0], tip[1]), abs=1e-12)


def test_unreachable_points_raise_a_clear_error() -> None:
    with pytest.raises(UnreachableError, match=r"out of reach: 0\.6000 m .* 0\.0500 to 0\.5500"):
        ARM2.inverse(0.6, 0.0)
    with pytest.raises(UnreachableError, match="out of reach"):
        ARM2.inverse(0.01, 0.01)  # inside the inner dead zone
    # Reachable geometrically but the shoulder would leave its range: try the other elbow.
    with pytest.raises(UnreachableError, match=r"shoulder = .* outside its range .*elbow down"):
        ARM2.inverse(-0.3, -0.1, "down")
    assert ARM2.forward(*ARM2.inverse(-0.3, -0.1, "up")) == pytest.approx((-0.3, -0.1))
    with pytest.raises(ValueError, match="elbow must be"):
        ARM2.inverse(0.3, 0.0, "sideways")  # type: ignore[arg-type]


def test_the_square_is_checked_before_anything_moves() -> None:
    with pytest.raises(UnreachableError):
        plan_square(ARM2, SquareOptions(side=0.5))
    with pytest.raises(ValueError, match=r"--duration 1: a lap takes at least \d+\.\d\d s"):
        plan_square(ARM2, SquareOptions(lap_s=1.0))
    edges = plan_square(ARM2, SquareOptions())
    assert [len(edge) for edge in edges] == [16] * 4
    assert edges[0][-1].time == pytest.approx(5.0 / 4)  # the default lap: 5 s


def test_waypoints_are_dense_enough_for_straight_edges() -> None:
    """Between two waypoints the group moves (nearly) linearly in joint space: that chord stays
    within 0.2 mm of the edge with the default 16 points (a single move would bow ~1 cm)."""
    corners = square_corners()

    def chord_error(points: int) -> float:
        worst = 0.0
        for i in range(4):
            start = ARM2.inverse(*corners[i])
            edge = edge_waypoints(
                ARM2, corners[i], corners[(i + 1) % 4], duration=1.0, points=points
            )
            qs = [start, *(w.positions for w in edge)]
            for a, b in itertools.pairwise(qs):
                for t in np.linspace(0.0, 1.0, 41):
                    q = (a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]))
                    worst = max(worst, distance_to_polygon(ARM2.forward(*q), corners))
        return worst

    assert chord_error(16) < 0.2e-3
    assert chord_error(1) > 5e-3


def test_distance_to_the_square_outline() -> None:
    corners = square_corners((0.0, 0.0), 2.0)
    assert distance_to_polygon((0.0, 0.0), corners) == pytest.approx(1.0)  # centre
    assert distance_to_polygon((1.0, 0.3), corners) == pytest.approx(0.0)  # on an edge
    assert distance_to_polygon((2.0, 2.0), corners) == pytest.approx(math.sqrt(2))  # off a corner


def test_arm6_tool_down_puts_the_pad_on_the_point_pointing_down() -> None:
    model = load_model("arm6")
    kin = Arm6Kinematics.from_model(model)
    data = mujoco.MjData(model)
    for target in [(0.45, 0.0, 0.037), (0.20, 0.40, 0.037), (0.3, -0.3, 0.2), (0.0, 0.5, 0.1)]:
        q = kin.tool_down(*target)
        data.qpos[:6] = q
        mujoco.mj_kinematics(model, data)
        assert data.site("tool").xpos == pytest.approx(target, abs=1e-9)
        axes = data.site("tool").xmat.reshape(3, 3)
        assert axes[:, 0] == pytest.approx((0.0, 0.0, -1.0), abs=1e-9)  # tool axis down
        assert axes[:, 1] == pytest.approx((0.0, 1.0, 0.0), abs=1e-9)  # pad square to y
    with pytest.raises(UnreachableError, match="out of reach"):
        kin.tool_down(0.9, 0.0, 0.05)
    with pytest.raises(UnreachableError, match=r"base_yaw = \+3\.142 rad, outside its range"):
        kin.tool_down(-0.3, 0.0, 0.05)  # behind the base: beyond the base's +-2.9 rad
