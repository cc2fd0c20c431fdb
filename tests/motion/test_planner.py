"""The ruckig planner alone: plans start exactly at their start state, end exactly on
their targets, respect the limits, and stop without leaving position limits."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from openel_async import BadParameterError
from openel_async.motion import AxisLimits, KinematicState, Planner

LIMITS = [AxisLimits(1.0, 4.0, 40.0), AxisLimits(2.0, 10.0, 100.0)]
BOUNDS = [(-3.0, 3.0), (-3.0, 3.0)]
DT_NS = 1_000_000


def planner(synchronization: str = "phase") -> Planner:
    return Planner(2, BOUNDS, [np.inf, np.inf], synchronization)


def sampled(plan_sample: object, start_ns: int, end_ns: int) -> np.ndarray:
    sample = plan_sample  # a bound Plan.sample
    assert callable(sample)
    return np.array([sample(t).position for t in range(start_ns, end_ns + DT_NS, DT_NS)])


def test_a_plan_ends_exactly_on_its_targets() -> None:
    start = KinematicState([0.0, 0.0], [0.0, 0.0], [0.0, 0.0])
    plan = planner().move(5_000, start, [1.0, -0.3], LIMITS)
    assert plan.sample(plan.end_ns).position == [1.0, -0.3]
    assert plan.sample(plan.end_ns + 10**9).velocity == [0.0, 0.0]
    assert plan.sample(5_000).position == pytest.approx([0.0, 0.0])
    assert plan.sample(0).position == pytest.approx([0.0, 0.0])  # before the start: clamped


state_values = st.floats(-1.0, 1.0, allow_nan=False)


@settings(max_examples=100, derandomize=True, database=None, deadline=None)
@given(
    position=st.tuples(st.floats(-2.0, 2.0), st.floats(-2.0, 2.0)),
    velocity=st.tuples(state_values, state_values),
    acceleration=st.tuples(st.floats(-4.0, 4.0), st.floats(-4.0, 4.0)),
    targets=st.tuples(st.floats(-2.0, 2.0), st.floats(-2.0, 2.0)),
    synchronization=st.sampled_from(["phase", "time"]),
)
def test_from_any_state_a_move_is_continuous_and_within_the_limits(
    position: tuple[float, float],
    velocity: tuple[float, float],
    acceleration: tuple[float, float],
    targets: tuple[float, float],
    synchronization: str,
) -> None:
    start = KinematicState(list(position), list(velocity), list(acceleration))
    try:
        plan = planner(synchronization).move(0, start, list(targets), LIMITS)
    except BadParameterError as exc:  # would overshoot a position limit: refused
        assert "position limits" in str(exc)
        return
    first = plan.sample(0)
    assert first.position == pytest.approx(position, abs=1e-9)
    assert first.velocity == pytest.approx(velocity, abs=1e-9)
    assert first.acceleration == pytest.approx(acceleration, abs=1e-9)
    assert plan.sample(plan.end_ns).position == list(targets)
    p = sampled(plan.sample, 0, plan.end_ns + 3 * DT_NS)
    dt = DT_NS / 1e9
    jerk = np.diff(p, n=3, axis=0) / dt**3
    caps = np.array([lim.max_jerk for lim in LIMITS])
    assert np.all(np.abs(jerk) <= caps * (1 + 1e-6) + 1e-3)
    extrema = np.abs(p).max(axis=0)
    assert np.all(extrema <= 3.0 + 1e-9)


def test_brake_stops_together_unless_that_leaves_a_position_limit() -> None:
    # Synchronized: the slow axis 1 is stretched to axis 0's braking time.
    free = planner().brake(0, KinematicState([0.0, 0.0], [1.0, 0.1], [0.0, 0.0]), LIMITS)
    end = free.sample(free.end_ns)
    assert end.velocity == [0.0, 0.0]
    assert end.position[1] > 0.01
    # Near its limit, that stretch would cross it: each axis brakes on its own instead.
    near = planner().brake(0, KinematicState([0.0, 2.99], [1.0, 0.1], [0.0, 0.0]), LIMITS)
    end = near.sample(near.end_ns)
    assert end.velocity == [0.0, 0.0]
    assert 2.99 < end.position[1] < 3.0
    assert end.position[0] == pytest.approx(free.sample(free.end_ns).position[0])


def test_waypoint_through_velocities() -> None:
    start = KinematicState([0.0, 0.0], [0.0, 0.0], [0.0, 0.0])
    points: list[tuple[list[float], float | None]] = [
        ([1.0, 1.0], 2.0),
        ([2.0, 0.0], 4.0),
        ([2.5, 0.0], 5.0),
    ]
    plan = planner("time").waypoints(0, start, points, LIMITS)
    assert plan.waypoint_times == pytest.approx([2.0, 4.0, 5.0])
    at_first = plan.sample(2_000_000_000)
    # Axis 0 goes on up: passes at the smaller neighbouring average speed (0.5 m/s);
    # axis 1 reverses: passes at rest.
    assert at_first.velocity == pytest.approx([0.5, 0.0], abs=1e-9)
    assert at_first.acceleration == pytest.approx([0.0, 0.0], abs=1e-9)
    at_second = plan.sample(4_000_000_000)
    assert at_second.velocity[1] == pytest.approx(0.0, abs=1e-9)  # axis 1 stops there
