"""profile.inside: the shortcut of clip_to_limits for a profile that stays within the limits
never says "inside" of a profile that leaves them (sampled densely)."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from openel_async import Request
from openel_sim import SimMotor
from openel_sim.profile import (
    Segment,
    clip_to_limits,
    end_time,
    evaluate,
    inside,
    ramp,
    trapezoid,
)

PROPERTY = settings(max_examples=100, derandomize=True, database=None, deadline=None)
finite = st.floats(min_value=-5.0, max_value=5.0, allow_nan=False, allow_infinity=False)
positive = st.floats(min_value=0.05, max_value=50.0, allow_nan=False, allow_infinity=False)


@PROPERTY
@given(finite, finite, finite, positive, positive, finite, positive)
def test_inside_agrees_with_the_exact_crossing_search(
    p0: float, v0: float, target: float, vmax: float, amax: float, low: float, width: float
) -> None:
    high = low + width
    for segments in (
        trapezoid(0, p0, v0, target, vmax, amax),
        ramp(0, p0, v0, target, amax),
    ):
        if inside(segments, low, high):
            end = end_time(segments) + 1_000_000
            for i in range(401):
                position = evaluate(segments, end * i // 400)[0]
                assert low <= position <= high
            assert clip_to_limits(segments, low, high) == (segments, None)


def test_a_move_within_the_limits_is_inside_and_one_past_them_is_not() -> None:
    assert inside(trapezoid(0, 0.0, 0.0, 1.0, 1.0, 5.0), -2.0, 2.0)
    assert not inside(trapezoid(0, 0.0, 0.0, 3.0, 1.0, 5.0), -2.0, 2.0)
    assert not inside(trapezoid(0, 0.0, -1.0, 1.0, 1.0, 1.0), -0.4, 2.0)  # turns at -0.5
    assert clip_to_limits(trapezoid(0, 0.0, 0.0, 3.0, 1.0, 5.0), -2.0, 2.0)[1] is not None


@PROPERTY
@given(
    st.floats(min_value=-1.0, max_value=1.0),
    st.floats(min_value=-2.0, max_value=2.0),
    st.floats(min_value=-1.2, max_value=1.2),
)
def test_a_position_command_skips_the_crossing_search_only_when_it_finds_none(
    p0: float, v0: float, target: float
) -> None:
    """SimMotor's shortcut for position moves (extremes inside the limits by a margin) sets
    the same profile and arrival time as the exact search would."""
    motor = SimMotor(position_limits=(-1.0, 1.0), max_velocity=2.0, max_acceleration=10.0)
    motor._segments = [Segment(0, p0, v0, 0.0, None)]
    motor.command_nowait(Request.POSITION, target)
    segments, limit_ns = clip_to_limits(trapezoid(0, p0, v0, target, 2.0, 10.0), -1.0, 1.0)
    assert motor.segments == segments
    assert motor._limit_ns == limit_ns
    if limit_ns is None:
        assert motor._arrival_ns == end_time(segments)
