"""AxisGroup.follow: timed and untimed waypoints, velocity continuity, infeasible times."""

from __future__ import annotations

import numpy as np
import pytest

from openel_async import BadParameterError
from openel_async.motion import GroupOutcome, KinematicState, Planner, Waypoint

from .rigs import DT, LIMITS, RigFactory, differences

PERIOD_NS = round(DT * 1e9)
SLACK = 1 + 1e-6


def row_at(times: np.ndarray, t_ns: int) -> int:
    rows = np.nonzero(times == t_ns)[0]
    assert rows.size == 1, f"no tick at {t_ns}"
    return int(rows[0])


async def test_timed_waypoints_are_reached_at_their_times(make_rig: RigFactory) -> None:
    rig = await make_rig()
    path = [
        Waypoint([0.6, 0.2, -0.3], time=0.9),
        Waypoint([1.0, 0.5, 0.3], time=1.6),
        Waypoint([0.4, 0.5, 0.0], time=2.5),
    ]
    motion = await rig.group.follow(path)
    assert motion.kind == "waypoints"
    assert motion.waypoint_times == pytest.approx([0.9, 1.6, 2.5])
    assert motion.duration == pytest.approx(2.5)
    await motion
    assert motion.outcome is GroupOutcome.SUCCEEDED
    samples = rig.group.log.snapshot().of_motion(motion.id)
    for waypoint in path:
        assert waypoint.time is not None
        row = row_at(samples.time_ns, motion.start_ns + round(waypoint.time * 1e9))
        assert samples.commanded[row] == pytest.approx(waypoint.positions, abs=1e-9)
    # Axis 0 keeps going up through the first waypoint: it passes at speed.
    first = row_at(samples.time_ns, motion.start_ns + 900_000_000)
    assert samples.velocity[first][0] > 0.1
    # Axis 1 stops at 0.5 (no move to the last waypoint) and axis 2 reverses at the
    # second waypoint: both pass it at rest.
    second = row_at(samples.time_ns, motion.start_ns + 1_600_000_000)
    assert samples.velocity[second][1] == pytest.approx(0.0, abs=1e-9)
    assert samples.velocity[second][2] == pytest.approx(0.0, abs=1e-9)
    for motor in rig.motors:
        v, a, j = differences(motor.on_grid(PERIOD_NS), DT)
        assert np.max(np.abs(v)) <= LIMITS.max_velocity * SLACK
        assert np.max(np.abs(a)) <= LIMITS.max_acceleration * SLACK + 1e-6
        assert np.max(np.abs(j)) <= LIMITS.max_jerk * SLACK + 1e-3


async def test_untimed_waypoints_flow_through_faster_than_stopping(
    make_rig: RigFactory,
) -> None:
    rig = await make_rig(axes=2)
    path = [Waypoint([0.5, 0.25]), Waypoint([1.0, 0.5]), Waypoint([1.5, 0.75])]
    motion = await rig.group.follow(path)
    await motion
    samples = rig.group.log.snapshot().of_motion(motion.id)
    passes = [motion.start_ns + round(t * 1e9) for t in motion.waypoint_times]
    for waypoint, t_ns in zip(path, passes, strict=True):
        # Planned times fall between ticks: the path is within a tick's travel of it.
        row = int(np.argmin(np.abs(samples.time_ns - t_ns)))
        near = np.abs(samples.commanded[row] - waypoint.positions)
        assert np.all(near <= LIMITS.max_velocity * DT)
    # Never slowing down to rest through the intermediate waypoints.
    first, second = (int(np.argmin(np.abs(samples.time_ns - t))) for t in passes[:2])
    assert np.min(np.abs(samples.velocity[first : second + 1, 0])) > 0.5
    # Faster than three rest-to-rest moves (planned alone, not run).
    planner = Planner(2, [(-3.2, 3.2)] * 2, [20.0] * 2)
    stops = 0.0
    here = [0.0, 0.0]
    for waypoint in path:
        leg = planner.move(
            0, KinematicState(here, [0.0, 0.0], [0.0, 0.0]), list(waypoint.positions), [LIMITS] * 2
        )
        stops += leg.duration
        here = list(waypoint.positions)
    assert motion.duration < 0.85 * stops


async def test_mixed_timed_and_untimed_waypoints(make_rig: RigFactory) -> None:
    rig = await make_rig(axes=2)
    path = [Waypoint([0.3, 0.1]), Waypoint([0.6, 0.6], time=2.0), Waypoint([0.0, 0.0])]
    motion = await rig.group.follow(path)
    assert motion.waypoint_times[1] == pytest.approx(2.0)
    assert 0 < motion.waypoint_times[0] < 2.0 < motion.waypoint_times[2]
    await motion
    samples = rig.group.log.snapshot().of_motion(motion.id)
    row = row_at(samples.time_ns, motion.start_ns + 2_000_000_000)
    assert samples.commanded[row] == pytest.approx([0.6, 0.6], abs=1e-9)


async def test_a_single_waypoint_is_a_timed_move(make_rig: RigFactory) -> None:
    rig = await make_rig(axes=2)
    motion = await rig.group.follow([Waypoint([0.4, -0.4], time=1.25)])
    await motion
    assert motion.duration == pytest.approx(1.25)
    assert rig.group.commanded == (0.4, -0.4)


@pytest.mark.parametrize(
    ("path", "parameter", "allowed"),
    [
        ([Waypoint([1.0, 1.0], time=0.2)], "waypoints[0].time", "at least"),
        (
            [Waypoint([0.2, 0.2], time=1.0), Waypoint([1.5, 0.2], time=1.3)],
            "waypoints[1].time",
            "at least",
        ),
        (
            [Waypoint([0.2, 0.2], time=1.0), Waypoint([0.4, 0.2], time=1.0)],
            "waypoints[1].time",
            "after the previous timed waypoint",
        ),
        ([Waypoint([0.2, 0.2], time=-1.0)], "waypoints[0].time", "> 0"),
        ([Waypoint([0.2, 0.2], time=float("nan"))], "waypoints[0].time", "> 0"),
        ([Waypoint([0.2])], "waypoints[0].positions", "2 positions"),
        ([Waypoint([0.2, float("inf")])], "waypoints[0].positions[1]", "finite"),
        ([Waypoint([0.2, 4.0])], "waypoints[0].positions[1]", "[-3.14"),
        ([], "waypoints", "at least one"),
        ([[0.1, 0.2]], "waypoints[0]", "a Waypoint"),
    ],
)
async def test_bad_waypoints_are_refused_before_anything_moves(
    make_rig: RigFactory, path: list[Waypoint], parameter: str, allowed: str
) -> None:
    rig = await make_rig(axes=2)
    with pytest.raises(BadParameterError) as info:
        await rig.group.follow(path)
    assert info.value.parameter == parameter
    assert allowed in str(info.value)
    assert not rig.group.moving
    await rig.sleep(0.01)
    assert all(m.setpoints == [] for m in rig.motors)
