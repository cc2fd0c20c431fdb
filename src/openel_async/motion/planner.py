"""Jerk-limited, time-synchronized trajectories with ruckig, as chains of segments.

A :class:`Plan` is a chain of ruckig trajectories rooted at a clock time. It is
computed once, when a motion is requested (ruckig's offline ``calculate``), and
sampled at each tick's deadline with ``Trajectory.at_time``: a late or skipped tick
samples the plan where it should be at that time instead of drifting, and the
commanded state (position, velocity, acceleration) at any sample time is exact, which
is what a preempting motion starts from.

The community edition of ruckig has no intermediate waypoints (they need ruckig Pro
or its cloud API, which this module never calls): :meth:`Planner.waypoints` chains
one trajectory per segment, passing through each intermediate waypoint at a velocity
chosen by a heuristic so that velocity and acceleration stay continuous.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from itertools import repeat
from operator import add, mul
from typing import NamedTuple

from ruckig import (
    ControlInterface,
    InputParameter,
    Result,
    Ruckig,
    RuckigError,
    Synchronization,
    Trajectory,
)

from ..clock import NS_PER_S
from ..errors import BadParameterError
from .errors import TrajectoryError
from .params import AxisLimits

TIME_EPS = 1e-9
"""Seconds: slack when comparing a planned duration with a requested one."""
POSITION_EPS = 1e-9
"""Slack of the position-limit check of planned trajectories."""
BOUNDS_MARGIN = 1e-9
"""Relative widening (times 1 + |position|) of :meth:`Plan.position_bounds`: far more than
the rounding between ruckig's extrema and the positions ``at_time`` evaluates (a few ulp)."""


class KinematicState(NamedTuple):
    """Commanded position, velocity and acceleration of every axis."""

    position: list[float]
    velocity: list[float]
    acceleration: list[float]


END_CORRECTION_MIN = 1e-12
"""End errors below this are left alone (their effect is below float noise)."""
END_CORRECTION_WINDOW_S = 0.25
"""The end error is blended in over at most this last part of a segment (seconds)."""


def _phase_range(
    duration: float, p: float, v: float, a: float, j: float, low: float, high: float
) -> tuple[float, float]:
    """``(low, high)`` widened by the positions of one constant-jerk phase over
    ``[0, duration]``: its ends and wherever its velocity crosses zero."""
    times = [0.0, duration]
    if j != 0.0:
        times.append(-a / j)  # where the velocity is extremal (a double root)
        disc = a * a - 2.0 * j * v
        if disc > 0.0:
            root = math.sqrt(disc)
            times += [(-a - root) / j, (-a + root) / j]
    elif a != 0.0:
        times.append(-v / a)
    for t in times:
        if 0.0 <= t <= duration:
            x = p + t * (v + t * (a / 2 + t * j / 6))  # ruckig's integrate()
            if x < low:
                low = x
            if x > high:
                high = x
    return low, high


def trajectory_range(trajectory: Trajectory) -> tuple[list[float], list[float]]:
    """Per axis, the smallest and largest position of ``trajectory`` over its duration.

    Computed from ruckig's profiles (each axis' brake pre-phases and seven constant-jerk
    phases, then its final state held to the end) with the formula ``at_time`` evaluates,
    checking every phase's ends and every zero of its velocity. Not
    ``Trajectory.position_extrema``: the community edition skips the velocity zeros of
    constant-acceleration phases and can miss an overshoot entirely (ruckig issue #215).
    """
    duration = trajectory.duration
    lows: list[float] = []
    highs: list[float] = []
    sections = trajectory.profiles
    if len(sections) != 1:
        raise TrajectoryError(f"a trajectory of {len(sections)} sections (expected one)")
    for profile in sections[0]:
        p, v, a, j, t = profile.p, profile.v, profile.a, profile.j, profile.t
        low = high = p[0]
        brake = profile.brake
        elapsed = 0.0
        if brake.duration > 0.0:
            for k in (0, 1):
                if brake.t[k] > 0.0:
                    low, high = _phase_range(
                        brake.t[k], brake.p[k], brake.v[k], brake.a[k], brake.j[k], low, high
                    )
            elapsed = brake.duration
        for k in range(7):
            low, high = _phase_range(t[k], p[k], v[k], a[k], j[k], low, high)
            elapsed += t[k]
        # After its profile an axis keeps its final velocity and acceleration.
        tail = max(0.0, duration - elapsed) + TIME_EPS
        low, high = _phase_range(tail, p[7], v[7], a[7], 0.0, low, high)
        lows.append(low)
        highs.append(high)
    return lows, highs


@dataclass(frozen=True, slots=True)
class _Piece:
    start_s: float
    """Offset of this segment from the plan's start."""
    end_s: float
    trajectory: Trajectory
    correction: list[float] | None = None
    """Per axis, exact target minus ruckig's end position (None: none needed)."""
    blend_s: float = 0.0
    """Offset in the segment from which the correction is blended in (to its end)."""


def _piece(start_s: float, trajectory: Trajectory, target: list[float] | None) -> _Piece:
    """A segment; with a target, ruckig's small end error (~1e-8) is blended out.

    The community ruckig reaches its target position to about 1e-8. Jumping to the
    exact target at the end would be a step that finite differences at 1 kHz see as a
    jerk of ~10 units; instead the error is added over the last ``w`` = up to 0.25 s of
    the segment with a quintic smoothstep (zero velocity and acceleration at both ends),
    which keeps the start state exact and adds a jerk of 60 x error / w³ (~4e-5 for 1e-8
    over 0.25 s); before that window a tick samples ruckig's positions as they are.
    """
    duration = trajectory.duration
    correction: list[float] | None = None
    if target is not None and duration > 0:
        end, _, _ = trajectory.at_time(duration)
        errors = [goal - reached for goal, reached in zip(target, end, strict=True)]
        if max(abs(e) for e in errors) >= END_CORRECTION_MIN:
            correction = errors
    blend_s = max(0.0, duration - END_CORRECTION_WINDOW_S)
    return _Piece(start_s, start_s + duration, trajectory, correction, blend_s)


class Plan:
    """A chain of ruckig trajectories that starts at ``start_ns`` on the group's clock."""

    __slots__ = (
        "_cursor",
        "_final",
        "_only",
        "_pieces",
        "duration",
        "end_ns",
        "start_ns",
        "waypoint_times",
    )

    def __init__(self, start_ns: int, pieces: list[_Piece], final_position: list[float]) -> None:
        self.start_ns = start_ns
        self._pieces = pieces
        self.duration = pieces[-1].end_s if pieces else 0.0
        """Seconds from ``start_ns`` to the end of the last segment."""
        self.end_ns = start_ns + round(self.duration * NS_PER_S)
        self.waypoint_times = tuple(p.end_s for p in pieces)
        """Offset (s) at which each segment ends: the planned time of each waypoint."""
        zeros = [0.0] * len(final_position)
        self._final = KinematicState(list(final_position), zeros, list(zeros))
        self._cursor = 0
        self._only = pieces[0] if len(pieces) == 1 else None
        """The segment of a one-segment plan (a move, a stop): no search per sample."""

    @property
    def final_position(self) -> list[float]:
        return self._final.position

    def sampler(self) -> Callable[[int], list[float]]:
        """:meth:`positions` as a call of one argument, for times before ``end_ns`` (what a
        streaming tick calls: a one-segment plan is evaluated with no lookup)."""
        piece = self._only
        if piece is None:
            return self.positions
        start_ns = self.start_ns
        at_time = piece.trajectory.at_time
        correction = piece.correction
        blend_s = piece.blend_s
        span = piece.end_s - piece.start_s - blend_s

        def positions(t_ns: int) -> list[float]:
            local = (t_ns - start_ns) / NS_PER_S
            if local < 0.0:
                local = 0.0
            p: list[float] = at_time(local)[0]
            if correction is not None and local > blend_s:
                x = min(1.0, (local - blend_s) / span)
                s0 = x * x * x * (10.0 + x * (-15.0 + 6.0 * x))
                p = list(map(add, p, map(mul, correction, repeat(s0))))
            return p

        return positions

    def position_bounds(self) -> tuple[list[float], list[float]]:
        """Per axis, a lower and an upper bound of every position :meth:`positions` returns.

        From each segment's exact position range (:func:`trajectory_range`), widened by the magnitude of the segment's end correction (blended in
        with a factor in [0, 1]) and by :data:`BOUNDS_MARGIN` for rounding; the final
        position included. What lies within a device's limits for the whole plan need not
        be checked sample by sample.
        """
        lows = list(self._final.position)
        highs = list(lows)
        for piece in self._pieces:
            correction = piece.correction
            piece_lows, piece_highs = trajectory_range(piece.trajectory)
            for axis, (low, high) in enumerate(zip(piece_lows, piece_highs, strict=True)):
                slack = 0.0 if correction is None else abs(correction[axis])
                low -= slack
                high += slack
                if low < lows[axis]:
                    lows[axis] = low
                if high > highs[axis]:
                    highs[axis] = high
        lows = [x - BOUNDS_MARGIN * (1.0 + abs(x)) for x in lows]
        highs = [x + BOUNDS_MARGIN * (1.0 + abs(x)) for x in highs]
        return lows, highs

    def _locate(self, t_ns: int) -> tuple[_Piece, float]:
        """The segment that holds clock time ``t_ns`` (before the end) and the offset in it."""
        elapsed = max(0.0, (t_ns - self.start_ns) / NS_PER_S)
        pieces = self._pieces
        i = self._cursor
        if elapsed < pieces[i].start_s:
            i = 0
        last = len(pieces) - 1
        while i < last and elapsed >= pieces[i].end_s:
            i += 1
        self._cursor = i
        piece = pieces[i]
        return piece, elapsed - piece.start_s

    def sample(self, t_ns: int) -> KinematicState:
        """The commanded state at clock time ``t_ns`` (the final state from the end on).

        Meant for non-decreasing times (a cursor remembers the current segment), but
        correct for any time.
        """
        if t_ns >= self.end_ns:
            return self._final
        piece, local = self._locate(t_ns)
        p, v, a = piece.trajectory.at_time(local)
        correction = piece.correction
        if correction is not None and local > piece.blend_s:
            span = piece.end_s - piece.start_s - piece.blend_s
            x = min(1.0, (local - piece.blend_s) / span)
            x2 = x * x
            s0 = x2 * x * (10.0 + x * (-15.0 + 6.0 * x))
            s1 = 30.0 * x2 * (1.0 - x) * (1.0 - x) / span
            s2 = 60.0 * x * (1.0 - x) * (1.0 - 2.0 * x) / (span * span)
            p = list(map(add, p, map(mul, correction, repeat(s0))))
            v = list(map(add, v, map(mul, correction, repeat(s1))))
            a = list(map(add, a, map(mul, correction, repeat(s2))))
        return KinematicState(p, v, a)

    def positions(self, t_ns: int) -> list[float]:
        """``sample(t_ns).position`` (the same floats) without the velocity and
        acceleration corrections: what a tick streams."""
        if t_ns >= self.end_ns:
            return self._final.position
        piece = self._only
        if piece is not None:
            local = (t_ns - self.start_ns) / NS_PER_S
            if local < 0.0:
                local = 0.0
        else:
            piece, local = self._locate(t_ns)
        p: list[float] = piece.trajectory.at_time(local)[0]
        correction = piece.correction
        if correction is not None and local > piece.blend_s:
            x = min(1.0, (local - piece.blend_s) / (piece.end_s - piece.start_s - piece.blend_s))
            s0 = x * x * x * (10.0 + x * (-15.0 + 6.0 * x))
            p = list(map(add, p, map(mul, correction, repeat(s0))))
        return p


class Planner:
    """Plans the trajectories of one group of ``dofs`` axes.

    ``bounds`` are the position limits of the axes' devices; a planned trajectory that
    would leave them (an overshoot when starting at speed) is refused.
    ``synchronization``: ``"phase"`` (default) makes a move from rest to rest a straight
    line in joint space when ruckig can (every axis a scaled copy of the slowest one;
    ruckig falls back to time synchronization otherwise); ``"time"``: all axes start
    and arrive together, each with its own profile shape.
    """

    def __init__(
        self,
        dofs: int,
        bounds: Sequence[tuple[float, float]],
        velocity_caps: Sequence[float],
        synchronization: str = "phase",
    ) -> None:
        if synchronization not in ("phase", "time"):
            raise BadParameterError("synchronization", synchronization, "'phase' or 'time'")
        self.dofs = dofs
        self.bounds = tuple(bounds)
        self.velocity_caps = tuple(velocity_caps)
        self._sync = Synchronization.Phase if synchronization == "phase" else Synchronization.Time
        self._ruckig = Ruckig(dofs)

    # -- building blocks ---------------------------------------------------------------
    def _input(self, start: KinematicState, limits: Sequence[AxisLimits]) -> InputParameter:
        inp = InputParameter(self.dofs)
        inp.current_position = start.position
        inp.current_velocity = start.velocity
        inp.current_acceleration = start.acceleration
        inp.max_velocity = [
            min(lim.max_velocity, cap) for lim, cap in zip(limits, self.velocity_caps, strict=True)
        ]
        inp.max_acceleration = [lim.max_acceleration for lim in limits]
        inp.max_jerk = [lim.max_jerk for lim in limits]
        inp.synchronization = self._sync
        return inp

    def _calculate(self, inp: InputParameter, what: str) -> Trajectory:
        trajectory = Trajectory(self.dofs)
        try:
            result = self._ruckig.calculate(inp, trajectory)
        except RuckigError as exc:
            reason = " ".join(str(exc).split("\n")[:2]).strip() or type(exc).__name__
            raise TrajectoryError(f"ruckig could not plan {what}: {reason}") from exc
        if result not in (Result.Working, Result.Finished):
            raise TrajectoryError(f"ruckig could not plan {what}: {result}")
        return trajectory

    def _check_bounds(self, trajectory: Trajectory, parameter: str, value: object) -> None:
        lows, highs = trajectory_range(trajectory)
        for axis, (reach_low, reach_high, (low, high)) in enumerate(
            zip(lows, highs, self.bounds, strict=True)
        ):
            if reach_low < low - POSITION_EPS or reach_high > high + POSITION_EPS:
                raise BadParameterError(
                    parameter,
                    value,
                    f"a motion that keeps axis {axis} within its position limits "
                    f"[{low}, {high}] (from the current state the trajectory would reach "
                    f"[{reach_low:.6g}, {reach_high:.6g}])",
                )

    # -- motions -------------------------------------------------------------------------
    def move(
        self,
        start_ns: int,
        start: KinematicState,
        targets: list[float],
        limits: Sequence[AxisLimits],
        duration: float | None = None,
    ) -> Plan:
        """A synchronized move from ``start`` to ``targets`` at rest.

        ``duration``: the move takes exactly this long (BAD_PARAMETER if the limits do
        not allow it); None: as fast as the limits allow.
        """
        inp = self._input(start, limits)
        inp.target_position = targets
        if duration is not None:
            inp.minimum_duration = duration
        trajectory = self._calculate(inp, "the move")
        if duration is not None and trajectory.duration > duration + TIME_EPS:
            raise BadParameterError(
                "duration",
                duration,
                f"at least {trajectory.duration:.6g} s (the fastest synchronized move "
                "under the limits from the current state)",
            )
        self._check_bounds(trajectory, "targets", targets)
        return Plan(start_ns, [_piece(0.0, trajectory, targets)], targets)

    def brake(self, start_ns: int, start: KinematicState, limits: Sequence[AxisLimits]) -> Plan:
        """Bring every axis to rest, jerk-limited, all axes stopping together.

        Falls back to each axis braking on its own (shortest stopping distance) if the
        synchronized stop would leave a position limit.
        """
        inp = self._input(start, limits)
        inp.control_interface = ControlInterface.Velocity
        inp.target_velocity = [0.0] * self.dofs
        inp.target_acceleration = [0.0] * self.dofs
        trajectory = self._calculate(inp, "the stop")
        try:
            self._check_bounds(trajectory, "stop", None)
        except BadParameterError:
            inp.synchronization = Synchronization.No
            trajectory = self._calculate(inp, "the stop")
        end, _, _ = trajectory.at_time(trajectory.duration)
        return Plan(start_ns, [_piece(0.0, trajectory, None)], end)

    def waypoints(
        self,
        start_ns: int,
        start: KinematicState,
        points: Sequence[tuple[list[float], float | None]],
        limits: Sequence[AxisLimits],
    ) -> Plan:
        """Pass through each ``(positions, time)`` in turn, ending at rest on the last.

        Each segment is one time-synchronized ruckig trajectory (all axes leave and
        reach a waypoint together). A timed waypoint is reached exactly at its time
        from the start (BAD_PARAMETER naming the waypoint if the limits do not allow
        it); an untimed one as early as the limits allow.

        Through velocity at an intermediate waypoint, per axis: zero where the axis
        reverses (or does not move) there; else the smaller of the average speeds of
        its two neighbouring segments (estimated from their timing, or from a
        rest-to-rest move when untimed), capped by the velocity limit, with zero
        acceleration. Velocity and acceleration are thus continuous through the path.
        When a timed segment cannot be done with that through velocity, it is
        retried ending at rest there.
        """
        estimates = self._segment_estimates(start, points, limits)
        count = len(points)
        through = [
            self._through_velocity(
                points[i - 1][0] if i > 0 else start.position,
                points[i][0],
                points[i + 1][0],
                estimates[i],
                estimates[i + 1],
                limits,
            )
            if i < count - 1
            else [0.0] * self.dofs
            for i in range(count)
        ]
        pieces: list[_Piece] = []
        state = start
        elapsed = 0.0
        zeros = [0.0] * self.dofs
        for i, (positions, at) in enumerate(points):
            parameter = f"waypoints[{i}].time"
            requested = None if at is None else at - elapsed
            if requested is not None and requested <= TIME_EPS:
                raise BadParameterError(
                    parameter,
                    at,
                    f"a time after {elapsed:.6g} s (when the path reaches waypoint {i - 1})",
                )
            velocity = through[i]
            trajectory = self._segment(state, positions, velocity, requested, limits, i)
            if requested is not None and trajectory.duration > requested + TIME_EPS:
                if any(velocity):
                    velocity = zeros
                    trajectory = self._segment(state, positions, velocity, requested, limits, i)
                if trajectory.duration > requested + TIME_EPS:
                    raise BadParameterError(
                        parameter,
                        at,
                        f"at least {elapsed + trajectory.duration:.6g} s (the fastest the "
                        "limits allow to reach it)",
                    )
            self._check_bounds(trajectory, f"waypoints[{i}]", positions)
            pieces.append(_piece(elapsed, trajectory, positions))
            elapsed += trajectory.duration
            state = KinematicState(list(positions), list(velocity), list(zeros))
        return Plan(start_ns, pieces, list(points[-1][0]))

    def _segment(
        self,
        state: KinematicState,
        positions: list[float],
        velocity: list[float],
        duration: float | None,
        limits: Sequence[AxisLimits],
        index: int,
    ) -> Trajectory:
        inp = self._input(state, limits)
        inp.target_position = positions
        inp.target_velocity = velocity
        if duration is not None:
            inp.minimum_duration = duration
        try:
            return self._calculate(inp, f"the segment to waypoints[{index}]")
        except TrajectoryError:
            if not any(velocity):
                raise
            inp.target_velocity = [0.0] * self.dofs
            return self._calculate(inp, f"the segment to waypoints[{index}]")

    def _segment_estimates(
        self,
        start: KinematicState,
        points: Sequence[tuple[list[float], float | None]],
        limits: Sequence[AxisLimits],
    ) -> list[float]:
        """Rough duration of each segment: its timing, else a rest-to-rest move."""
        out: list[float] = []
        previous_time: float | None = 0.0
        previous = start
        for i, (positions, at) in enumerate(points):
            if at is not None and previous_time is not None and at > previous_time:
                out.append(at - previous_time)
            else:
                inp = self._input(previous, limits)
                inp.target_position = positions
                out.append(self._calculate(inp, f"the segment to waypoints[{i}]").duration)
            previous_time = at
            zeros = [0.0] * self.dofs
            previous = KinematicState(list(positions), zeros, list(zeros))
        return out

    def _through_velocity(
        self,
        before: list[float],
        here: list[float],
        after: list[float],
        t_in: float,
        t_out: float,
        limits: Sequence[AxisLimits],
    ) -> list[float]:
        out: list[float] = []
        for axis in range(self.dofs):
            d_in = here[axis] - before[axis]
            d_out = after[axis] - here[axis]
            if d_in * d_out <= 0 or t_in <= 0 or t_out <= 0:
                out.append(0.0)
                continue
            speed = min(abs(d_in) / t_in, abs(d_out) / t_out)
            cap = min(limits[axis].max_velocity, self.velocity_caps[axis])
            out.append(math.copysign(min(speed, cap), d_in))
        return out
