"""Piecewise constant-acceleration motion profiles, evaluated in closed form.

A simulated motor's state is a list of segments; evaluating position, velocity and
acceleration at any time is O(segments) with no integration error, so simulated
time can leap (virtual clock) without losing accuracy.
"""

from __future__ import annotations

import math
from math import ceil, sqrt
from typing import NamedTuple

NS = 1e-9


class Segment(NamedTuple):
    """Constant acceleration ``a`` from (p0, v0) at ``start_ns`` until ``end_ns``."""

    start_ns: int
    p0: float
    v0: float
    a: float
    end_ns: int | None
    """None: the segment lasts forever."""

    def at(self, t_ns: int) -> tuple[float, float, float]:
        dt = (t_ns - self.start_ns) * NS
        return self.p0 + self.v0 * dt + 0.5 * self.a * dt * dt, self.v0 + self.a * dt, self.a

    def end_state(self) -> tuple[float, float]:
        assert self.end_ns is not None
        p, v, _ = self.at(self.end_ns)
        return p, v


def hold(start_ns: int, position: float) -> list[Segment]:
    return [Segment(start_ns, position, 0.0, 0.0, None)]


def _chain(start_ns: int, p: float, v: float, phases: list[tuple[float, float]]) -> list[Segment]:
    """Segments from (p, v) through phases of (velocity at the phase's end, duration in s).

    Durations are whole nanoseconds, rounded up, and each phase's acceleration is derived
    from its rounded duration, so every phase ends exactly at its velocity and |a| never
    exceeds the planned acceleration.
    """
    segments: list[Segment] = []
    append = segments.append
    new = tuple.__new__  # Segment(...) without the NamedTuple's Python-level __new__
    ceil = math.ceil
    t = start_ns
    for v_end, duration in phases:
        if duration <= 0:
            continue
        steps = max(1, ceil(duration / NS - 1e-6))
        dt = steps * NS
        a = (v_end - v) / dt
        end = t + steps
        append(new(Segment, (t, p, v, a, end)))
        # The segment's end state, as Segment.at(end) computes it.
        p = p + v * dt + 0.5 * a * dt * dt
        v = v_end
        t = end
    return segments


Plan = tuple[
    int, float, float, float, int, float, float, float, int, float, float, float, int, float
]
"""A position move in closed form, as one flat tuple (no segment objects):
``(t0, p0, v0, a1, t1, p1, v1, a2, t2, p2, v2, a3, t3, target)``: three constant-acceleration
phases, [t0, t1) from (p0, v0) at a1, [t1, t2) from (p1, v1) at a2 and [t2, t3) from (p2, v2)
at a3 (a phase the move does not need has zero length), then at rest at ``target`` from t3
(the arrival time). :func:`plan_segments` gives its segments, :func:`evaluate_plan` its state."""


def plan_trapezoid(
    start_ns: int, p0: float, v0: float, target: float, vmax: float, amax: float
) -> Plan:
    """:func:`trapezoid` as a :data:`Plan` (the simulated motor's per-command path)."""
    d = target - p0
    if -1e-12 < d < 1e-12 and -1e-12 < v0 < 1e-12:
        t = start_ns
        return (t, target, 0.0, 0.0, t, target, 0.0, 0.0, t, target, 0.0, 0.0, t, target)
    # Direction: toward the target from where braking now would stop us.
    stop = p0 + v0 * (v0 if v0 >= 0.0 else -v0) / (2 * amax)
    s = 1.0 if target >= stop else -1.0
    if v0 > vmax:
        v0 = vmax
    elif v0 < -vmax:
        v0 = -vmax
    peak_sq = amax * s * d + v0 * v0 / 2
    peak = s * sqrt(peak_sq if peak_sq > 0.0 else 0.0)
    cruise = 0.0
    if (peak if peak >= 0.0 else -peak) > vmax:
        peak = s * vmax
        d1 = (peak * peak - v0 * v0) / (2 * s * amax)
        d3 = s * peak * peak / (2 * amax)
        cruise = (d - d1 - d3) / peak
    # Three phases (accelerate or brake to the peak, cruise, brake to rest), unrolled.
    # Durations are whole nanoseconds, rounded up, and each phase's acceleration is derived
    # from its rounded duration, so every phase ends exactly at its velocity and |a| never
    # exceeds the planned acceleration.
    t1 = start_ns
    p1 = p0
    v1 = v0
    a1 = 0.0
    duration = (peak - v0) / (s * amax)
    if duration > 0:
        steps = ceil(duration / NS - 1e-6)
        if steps < 1:
            steps = 1
        dt = steps * NS
        a1 = (peak - v0) / dt
        t1 = start_ns + steps
        p1 = p0 + v0 * dt + 0.5 * a1 * dt * dt
        v1 = peak
    t2 = t1
    p2 = p1
    v2 = v1
    a2 = 0.0
    if cruise > 0:
        steps = ceil(cruise / NS - 1e-6)
        if steps < 1:
            steps = 1
        dt = steps * NS
        a2 = (peak - v1) / dt
        t2 = t1 + steps
        p2 = p1 + v1 * dt + 0.5 * a2 * dt * dt
        v2 = peak
    t3 = t2
    a3 = 0.0
    duration = (peak if peak >= 0.0 else -peak) / amax
    if duration > 0:
        steps = ceil(duration / NS - 1e-6)
        if steps < 1:
            steps = 1
        a3 = (0.0 - v2) / (steps * NS)
        t3 = t2 + steps
    # The last state is exactly the target (closing the float error of the closed form).
    return (start_ns, p0, v0, a1, t1, p1, v1, a2, t2, p2, v2, a3, t3, target)


def plan_segments(plan: Plan) -> list[Segment]:
    """The segments of a :data:`Plan` (its phases of non-zero length, then the rest)."""
    t0, p0, v0, a1, t1, p1, v1, a2, t2, p2, v2, a3, t3, target = plan
    segments = [
        Segment(start, p, v, a, end)
        for start, p, v, a, end in (
            (t0, p0, v0, a1, t1),
            (t1, p1, v1, a2, t2),
            (t2, p2, v2, a3, t3),
        )
        if end > start
    ]
    segments.append(Segment(t3, target, 0.0, 0.0, None))
    return segments


def evaluate_plan(plan: Plan, t_ns: int) -> tuple[float, float, float]:
    """Position, velocity and acceleration of a :data:`Plan` at ``t_ns`` (clamped to its
    start): the same as :func:`evaluate` of its segments."""
    t0, p0, v0, a1, t1, p1, v1, a2, t2, p2, v2, a3, t3, target = plan
    if t_ns < t0:
        t_ns = t0
    if t_ns < t1:
        dt = (t_ns - t0) * NS
        return p0 + v0 * dt + 0.5 * a1 * dt * dt, v0 + a1 * dt, a1
    if t_ns < t2:
        dt = (t_ns - t1) * NS
        return p1 + v1 * dt + 0.5 * a2 * dt * dt, v1 + a2 * dt, a2
    if t_ns < t3:
        dt = (t_ns - t2) * NS
        return p2 + v2 * dt + 0.5 * a3 * dt * dt, v2 + a3 * dt, a3
    return target, 0.0, 0.0


def trapezoid(
    start_ns: int, p0: float, v0: float, target: float, vmax: float, amax: float
) -> list[Segment]:
    """Time-optimal move to ``target`` at rest under |v| <= vmax, |a| <= amax."""
    return plan_segments(plan_trapezoid(start_ns, p0, v0, target, vmax, amax))


def ramp(start_ns: int, p0: float, v0: float, v1: float, amax: float) -> list[Segment]:
    """Reach velocity ``v1`` at |a| = amax, then cruise."""
    dv = v1 - v0
    segments = _chain(start_ns, p0, v0, [(v1, abs(dv) / amax)]) if dv else []
    if segments:
        p, _ = segments[-1].end_state()
        end = segments[-1].end_ns
        assert end is not None
        return [*segments, Segment(end, p, v1, 0.0, None)]
    return [Segment(start_ns, p0, v1, 0.0, None)]


def accelerate(start_ns: int, p0: float, v0: float, a: float, vmax: float) -> list[Segment]:
    """Constant acceleration ``a`` until |v| = vmax, then cruise (a torque-limited drive)."""
    if a == 0:
        return [Segment(start_ns, p0, v0, 0.0, None)]
    v_end = math.copysign(vmax, a)
    duration = (v_end - v0) / a
    if duration <= 0:
        return [Segment(start_ns, p0, v_end, 0.0, None)]
    return ramp(start_ns, p0, v0, v_end, abs(a))


def evaluate(segments: list[Segment], t_ns: int) -> tuple[float, float, float]:
    """Position, velocity and acceleration at ``t_ns`` (clamped to the first segment)."""
    for seg in segments:
        end_ns = seg[4]
        if end_ns is None or t_ns < end_ns:
            start_ns = seg[0]
            dt = ((t_ns if t_ns > start_ns else start_ns) - start_ns) * NS
            a = seg[3]
            return seg[1] + seg[2] * dt + 0.5 * a * dt * dt, seg[2] + a * dt, a
    last = segments[-1]
    return last.at(t_ns)


def end_time(segments: list[Segment]) -> int:
    """When the last finite segment ends (the profile's arrival time)."""
    for seg in reversed(segments):  # in time order: the last finite one ends last
        end_ns = seg[4]
        if end_ns is not None:
            return end_ns
    return segments[0].start_ns


def inside(segments: list[Segment], low: float, high: float) -> bool:
    """Whether the profile certainly stays strictly inside (low, high): every segment's
    ends and velocity-zero point are (a finite segment's position is a parabola, so those
    are its extremes), and the last one is at rest.  False when unsure, not only when it
    leaves: :func:`clip_to_limits` then looks for the crossing exactly."""
    for start_ns, p0, v0, a, end_ns in segments:
        if not low < p0 < high:
            return False
        if end_ns is None:
            if v0 != 0.0 or a != 0.0:
                return False
            continue
        dt = (end_ns - start_ns) * NS
        v1 = v0 + a * dt
        p1 = p0 + v0 * dt + 0.5 * a * dt * dt
        if not low < p1 < high:
            return False
        if v0 * v1 < 0.0:  # turns inside the segment: its farthest point
            turn = p0 - v0 * v0 / (2.0 * a)
            if not low < turn < high:
                return False
    return True


def clip_to_limits(
    segments: list[Segment], low: float, high: float
) -> tuple[list[Segment], int | None]:
    """Stop the profile where it first leaves [low, high]; returns the stop time too."""
    if inside(segments, low, high):  # the common case, without solving for a crossing
        return segments, None
    out: list[Segment] = []
    for seg in segments:
        hit = _first_crossing(seg, low, high)
        if hit is None:
            out.append(seg)
            continue
        t_hit, limit = hit
        if t_hit > seg.start_ns:
            out.append(Segment(seg.start_ns, seg.p0, seg.v0, seg.a, t_hit))
        out.append(Segment(t_hit, limit, 0.0, 0.0, None))
        return out, t_hit
    return out, None


def _first_crossing(seg: Segment, low: float, high: float) -> tuple[int, float] | None:
    # Already on (or past) a limit and heading outward: stop right away.
    heading = seg.v0 if seg.v0 != 0 else seg.a
    if seg.p0 >= high and heading > 0:
        return seg.start_ns, high
    if seg.p0 <= low and heading < 0:
        return seg.start_ns, low
    best: tuple[float, float] | None = None
    span = None if seg.end_ns is None else (seg.end_ns - seg.start_ns) * NS
    for limit in (low, high):
        if not math.isfinite(limit):
            continue
        # p0 + v0 t + a t^2 / 2 = limit, earliest t in (0, span]
        a, b, c = 0.5 * seg.a, seg.v0, seg.p0 - limit
        roots: list[float] = []
        if abs(a) < 1e-15:
            if abs(b) > 1e-15:
                roots = [-c / b]
        else:
            disc = b * b - 4 * a * c
            if disc >= 0:
                sq = math.sqrt(disc)
                roots = [(-b - sq) / (2 * a), (-b + sq) / (2 * a)]
        for t in roots:
            moving_out = (seg.v0 + seg.a * t) * (1 if limit == high else -1) > 0
            if (
                t > 1e-12
                and (span is None or t <= span)
                and moving_out
                and (best is None or t < best[0])
            ):
                best = (t, limit)
    if best is None:
        return None
    return seg.start_ns + max(1, round(best[0] / NS)), best[1]
