"""Property tests of the closed-form motion profiles of the simulated motor.

Phase boundaries fall on whole nanoseconds; each phase's acceleration is derived
from its rounded duration so that it ends exactly at its velocity. The property
tolerances allow one quantum (``QUANTUM_S``) on top of 1e-6; the tests at the end
pin the exact bounds (regressions of overshoot and limit bugs found here).
"""

from __future__ import annotations

import itertools
import math

import pytest
from hypothesis import event, example, given, settings
from hypothesis import strategies as st

from openel_sim.profile import (
    NS,
    Segment,
    clip_to_limits,
    end_time,
    evaluate,
    hold,
    ramp,
    trapezoid,
)

QUANTUM_S = 1e-9
"""Allowance for phase boundaries rounded to whole nanoseconds."""
TOL = 1e-6

PROPERTY = settings(max_examples=100, derandomize=True, database=None, deadline=None)

starts = st.integers(min_value=0, max_value=10**15)
positions = st.floats(min_value=-50.0, max_value=50.0, allow_nan=False, allow_infinity=False)
vmaxes = st.floats(min_value=0.05, max_value=20.0, allow_nan=False, allow_infinity=False)
amaxes = st.floats(min_value=0.05, max_value=200.0, allow_nan=False, allow_infinity=False)
fractions = st.floats(min_value=-1.0, max_value=1.0, allow_nan=False, allow_infinity=False)


# -- helpers ----------------------------------------------------------------------------------


def _check_chain(segments: list[Segment], start_ns: int) -> None:
    """Contiguous in time from ``start_ns``; only the last segment is open-ended."""
    assert segments[0].start_ns == start_ns
    for before, after in itertools.pairwise(segments):
        assert before.end_ns is not None
        assert before.end_ns == after.start_ns
        assert before.end_ns > before.start_ns
    assert segments[-1].end_ns is None


def _boundary_jumps(segments: list[Segment]) -> tuple[float, float]:
    """Largest position and velocity jump where one segment hands over to the next."""
    dp = dv = 0.0
    for before, after in itertools.pairwise(segments):
        p, v = before.end_state()
        dp = max(dp, abs(p - after.p0))
        dv = max(dv, abs(v - after.v0))
    return dp, dv


def _peak_speed(segments: list[Segment]) -> float:
    """Max |v| (reached at a segment end: velocity is linear within a segment)."""
    speeds = [abs(s.v0) for s in segments]
    speeds += [abs(s.end_state()[1]) for s in segments if s.end_ns is not None]
    return max(speeds)


def _sample_times(segments: list[Segment], count: int = 48) -> list[int]:
    start = segments[0].start_ns
    stop = end_time(segments) + 1_000_000_000
    times = {start + (stop - start) * i // count for i in range(count + 1)}
    for seg in segments:
        times.update({seg.start_ns, seg.start_ns + 1, max(start, seg.start_ns - 1)})
    return sorted(times)


def _closed_form_duration(distance: float, vmax: float, amax: float) -> float:
    """Minimum time from rest to rest over ``distance`` under vmax and amax (seconds)."""
    d = abs(distance)
    if d >= vmax * vmax / amax:  # trapezoid: reaches vmax
        return d / vmax + vmax / amax
    return 2.0 * math.sqrt(d / amax)  # triangle


# -- trapezoid -----------------------------------------------------------------------------------


@PROPERTY
@given(starts, positions, fractions, positions, vmaxes, amaxes)
@example(0, 0.0, 0.0, 1.0, 0.5, 3.0)
@example(0, 0.0, 1.0, -1.0, 1.0, 1.0)  # moving away from the target: reverse
@example(0, 0.0, 1.0, 0.25, 1.0, 1.0)  # too fast to stop short: overshoot and return
@example(5, 3.0, 0.0, 3.0, 1.0, 1.0)  # already there, at rest
def test_trapezoid_respects_limits_and_ends_at_rest_on_target(
    start: int, p0: float, v_fraction: float, target: float, vmax: float, amax: float
) -> None:
    v0 = v_fraction * vmax
    segments = trapezoid(start, p0, v0, target, vmax, amax)
    _check_chain(segments, start)

    last = segments[-1]
    assert (last.p0, last.v0, last.a) == (target, 0.0, 0.0)
    arrival = end_time(segments)
    for t in (arrival, arrival + 1, arrival + 10**12):
        assert evaluate(segments, t) == (target, 0.0, 0.0)

    # Starts from the given state.
    p, v, _ = evaluate(segments, start)
    assert p == pytest.approx(p0, abs=1e-12)
    assert v == pytest.approx(v0, abs=1e-12)

    duration_s = (arrival - start) * NS
    slack = amax * QUANTUM_S
    assert all(abs(s.a) <= amax for s in segments)
    assert _peak_speed(segments) <= vmax * (1 + 1e-9) + slack

    dp, dv = _boundary_jumps(segments)
    assert dp <= TOL + slack * duration_s
    assert dv <= TOL

    for t in _sample_times(segments):
        p, v, a = evaluate(segments, t)
        assert abs(v) <= vmax * (1 + 1e-9) + slack
        assert abs(a) <= amax


@PROPERTY
@given(starts, positions, positions, vmaxes, amaxes)
@example(0, 0.0, 1.0, 0.5, 3.0)  # trapezoid: cruises at vmax
@example(0, 0.0, 0.01, 1.0, 1.0)  # triangle: never reaches vmax
@example(0, 0.0, -1.0, 1.0, 1.0)  # exactly the triangle/trapezoid border, backwards
def test_trapezoid_from_rest_is_time_optimal(
    start: int, p0: float, target: float, vmax: float, amax: float
) -> None:
    segments = trapezoid(start, p0, 0.0, target, vmax, amax)
    if p0 == target:
        assert segments == hold(start, target)
        return
    duration_ns = end_time(segments) - start
    expected_ns = _closed_form_duration(target - p0, vmax, amax) / NS
    assert abs(duration_ns - expected_ns) <= 1_000  # within 1 µs

    # From rest it moves monotonically toward the target: no overshoot.
    low, high = min(p0, target), max(p0, target)
    eps = 1e-9 + amax * QUANTUM_S * duration_ns * NS
    for t in _sample_times(segments):
        p, v, _ = evaluate(segments, t)
        assert low - eps <= p <= high + eps
        assert v * (target - p0) >= -eps


@PROPERTY
@given(positions, fractions, positions, vmaxes, amaxes)
def test_trapezoid_with_initial_velocity_beats_stop_then_move(
    p0: float, v_fraction: float, target: float, vmax: float, amax: float
) -> None:
    """Not slower than braking to rest and then making a rest-to-rest move."""
    v0 = v_fraction * vmax
    segments = trapezoid(0, p0, v0, target, vmax, amax)
    brake_s = abs(v0) / amax
    stop = p0 + v0 * abs(v0) / (2 * amax)
    bound_s = brake_s + _closed_form_duration(target - stop, vmax, amax)
    assert end_time(segments) * NS <= bound_s + 1e-6


# -- ramp --------------------------------------------------------------------------------------


@PROPERTY
@given(starts, positions, vmaxes, fractions, fractions, amaxes)
def test_ramp_reaches_v1_at_amax_and_cruises(
    start: int, p0: float, vmax: float, f0: float, f1: float, amax: float
) -> None:
    v0, v1 = f0 * vmax, f1 * vmax
    segments = ramp(start, p0, v0, v1, amax)
    _check_chain(segments, start)
    last = segments[-1]
    assert (last.v0, last.a) == (v1, 0.0)

    if abs(v1 - v0) / amax < NS:  # a change finished within the first nanosecond
        assert all(abs(seg.a) <= amax * (1 + 1e-12) for seg in segments)
        return
    accel = segments[0]
    assert len(segments) == 2
    # The acceleration is derived from the whole-ns duration: never above amax.
    assert abs(accel.a) <= amax * (1 + 1e-12)
    expected_a = (v1 - v0) / (math.ceil(abs(v1 - v0) / amax / NS - 1e-6) * NS)
    assert accel.a == pytest.approx(expected_a, rel=1e-9)
    assert accel.end_ns is not None
    expected_ns = abs(v1 - v0) / amax / NS
    assert abs((accel.end_ns - start) - expected_ns) <= 1.0  # whole-ns boundary
    p_end, v_end = accel.end_state()
    assert v_end == pytest.approx(v1, abs=amax * QUANTUM_S + 1e-12)
    assert last.p0 == p_end  # position continuous
    # Velocity is monotone from v0 to v1 and never passes it by more than a quantum.
    lo, hi = min(v0, v1), max(v0, v1)
    for t in _sample_times(segments):
        _, v, _ = evaluate(segments, t)
        assert lo - amax * QUANTUM_S <= v <= hi + amax * QUANTUM_S
    # Far in the future: still cruising at v1 from where the ramp ended.
    far = accel.end_ns + 10**9
    p, v, a = evaluate(segments, far)
    assert (v, a) == (v1, 0.0)
    assert p == pytest.approx(p_end + v1 * 1.0, rel=1e-12, abs=1e-12)


# -- clip_to_limits --------------------------------------------------------------------------------

limits = st.tuples(
    st.floats(min_value=-20.0, max_value=-0.01, allow_nan=False),
    st.floats(min_value=0.01, max_value=20.0, allow_nan=False),
)


@st.composite
def profiles_inside(draw: st.DrawFn) -> tuple[list[Segment], float, float]:
    """A trapezoid or ramp starting strictly inside [low, high], target anywhere."""
    low, high = draw(limits)
    inside = draw(st.floats(min_value=0.001, max_value=0.999))
    p0 = low + (high - low) * inside
    if not low < p0 < high:
        p0 = (low + high) / 2
    vmax, amax = draw(vmaxes), draw(amaxes)
    v0 = draw(fractions) * vmax
    start = draw(starts)
    if draw(st.booleans()):
        target = draw(st.floats(min_value=-60.0, max_value=60.0))
        return trapezoid(start, p0, v0, target, vmax, amax), low, high
    return ramp(start, p0, v0, draw(fractions) * vmax, amax), low, high


@PROPERTY
@given(profiles_inside())
def test_clip_stops_exactly_at_the_limit_and_never_beyond(
    case: tuple[list[Segment], float, float],
) -> None:
    original, low, high = case
    clipped, stop_ns = clip_to_limits(original, low, high)
    event("stays inside" if stop_ns is None else "clipped")
    _check_chain(clipped, original[0].start_ns)

    # Never beyond the limits, anywhere on the clipped profile.
    eps = 1e-9
    for t in _sample_times(clipped) + _sample_times(original):
        p, _, _ = evaluate(clipped, t)
        assert low - eps <= p <= high + eps

    if stop_ns is None:
        # Nothing to clip: the profile is unchanged and stays inside on its own.
        assert clipped == original
        for t in _sample_times(original):
            assert low - eps <= evaluate(original, t)[0] <= high + eps
        return

    # Stopped: held at rest exactly on a limit from stop_ns on.
    last = clipped[-1]
    assert last.start_ns == stop_ns
    assert last.p0 in (low, high)
    assert (last.v0, last.a, last.end_ns) == (0.0, 0.0, None)
    assert evaluate(clipped, stop_ns + 10**12) == (last.p0, 0.0, 0.0)
    # The original reaches that limit at stop_ns (up to the whole-ns rounding)...
    p, v, _ = evaluate(original, stop_ns)
    assert abs(p - last.p0) <= abs(v) * 1e-9 + 1e-9
    # ...moving outward, and the clipped profile is the original up to then.
    assert v * (1 if last.p0 == high else -1) >= 0
    for t in _sample_times(clipped):
        if t < stop_ns:
            assert evaluate(clipped, t) == pytest.approx(evaluate(original, t), abs=1e-12)


def test_clip_of_a_profile_that_stays_inside_is_unchanged() -> None:
    segments = trapezoid(0, 0.0, 0.0, 0.5, 1.0, 1.0)
    assert clip_to_limits(segments, -1.0, 1.0) == (segments, None)
    assert clip_to_limits(segments, -math.inf, math.inf) == (segments, None)


def test_clip_stops_a_ramp_at_the_high_limit() -> None:
    segments = ramp(0, 0.0, 0.0, 2.0, 1.0)  # 2 s at 1 m/s^2, then 2 m/s
    clipped, stop_ns = clip_to_limits(segments, -1.0, 1.0)
    # 0.5 t^2 = 1 -> t = sqrt(2) s
    assert stop_ns == round(math.sqrt(2) * 1e9)
    assert clipped[-1] == Segment(stop_ns, 1.0, 0.0, 0.0, None)
    p, v, _ = evaluate(clipped, stop_ns - 1)
    assert p < 1.0
    assert v > 0


def test_clip_stops_a_cruise_at_the_low_limit() -> None:
    segments = [Segment(100, 0.0, -2.0, 0.0, None)]
    clipped, stop_ns = clip_to_limits(segments, -1.0, 1.0)
    assert stop_ns == 100 + 500_000_000
    assert clipped == [
        Segment(100, 0.0, -2.0, 0.0, stop_ns),
        Segment(stop_ns, -1.0, 0.0, 0.0, None),
    ]


# -- exact bounds (regressions of bugs found by these tests) -----------------------------------------


def test_trapezoid_peak_speed_within_exact_bound() -> None:
    segments = trapezoid(0, 0.0, 0.0, 1.0, 0.5, 3.0)
    assert _peak_speed(segments) <= 0.5 * (1 + 1e-9)


def test_trapezoid_position_continuous_within_1e6_on_a_long_cruise() -> None:
    segments = trapezoid(0, 15.0, 0.0, 0.0, 0.5, 71.0)  # 30 s cruise
    dp, _ = _boundary_jumps(segments)
    assert dp <= 1e-6


@pytest.mark.parametrize(
    "segments",
    [
        ramp(0, 1.0, 0.0, 1.0, 1.0),  # at the high limit, accelerating out
        ramp(0, 1.0, 0.5, 1.0, 1.0),  # at the high limit, moving out
        trapezoid(0, -1.0, 0.0, -2.0, 1.0, 1.0),  # at the low limit, target beyond
    ],
)
def test_clip_profile_starting_on_a_limit_moving_out(segments: list[Segment]) -> None:
    clipped, stop_ns = clip_to_limits(segments, -1.0, 1.0)
    assert stop_ns == segments[0].start_ns
    for t in _sample_times(clipped):
        assert -1.0 <= evaluate(clipped, t)[0] <= 1.0
