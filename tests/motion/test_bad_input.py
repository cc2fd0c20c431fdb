"""Bad input is refused with an error naming the parameter, and changes nothing."""

from __future__ import annotations

import math
from typing import Any

import pytest

from openel_async import BadParameterError, EventTimer, VirtualClock
from openel_async.motion import AxisGroup, AxisLimits, GroupOutcome, Tolerances
from openel_async.testing import ComponentStack

from .rigs import LIMITS, RecordingMotor, RigFactory

NAN = math.nan
INF = math.inf


@pytest.mark.parametrize(
    ("kwargs", "parameter"),
    [
        ({"max_velocity": 0.0, "max_acceleration": 1.0, "max_jerk": 1.0}, "max_velocity"),
        ({"max_velocity": 1.0, "max_acceleration": -1.0, "max_jerk": 1.0}, "max_acceleration"),
        ({"max_velocity": 1.0, "max_acceleration": 1.0, "max_jerk": NAN}, "max_jerk"),
        ({"max_velocity": INF, "max_acceleration": 1.0, "max_jerk": 1.0}, "max_velocity"),
        ({"max_velocity": True, "max_acceleration": 1.0, "max_jerk": 1.0}, "max_velocity"),
        ({"max_velocity": "1", "max_acceleration": 1.0, "max_jerk": 1.0}, "max_velocity"),
    ],
)
def test_axis_limits_must_be_finite_and_positive(kwargs: dict[str, Any], parameter: str) -> None:
    with pytest.raises(BadParameterError) as info:
        AxisLimits(**kwargs)
    assert info.value.parameter == parameter


@pytest.mark.parametrize(
    ("kwargs", "parameter"),
    [({"goal": 0.0}, "goal"), ({"goal": NAN}, "goal"), ({"path": -0.1}, "path")],
)
def test_tolerances_must_be_finite_and_positive(kwargs: dict[str, Any], parameter: str) -> None:
    with pytest.raises(BadParameterError) as info:
        Tolerances(**kwargs)
    assert info.value.parameter == parameter


@pytest.mark.parametrize(
    ("targets", "parameter", "allowed"),
    [
        ([0.1, 0.2], "targets", "3 positions (one per axis), not 2"),
        ([0.1, 0.2, 0.3, 0.4], "targets", "not 4"),
        ([0.1, NAN, 0.3], "targets[1]", "finite"),
        ([0.1, 0.2, -INF], "targets[2]", "finite"),
        ([0.1, 3.5, 0.3], "targets[1]", "the limits of axis 1, joint1"),
        ([0.1, "0.2", 0.3], "targets[1]", "finite real number"),
        ("abc", "targets", "sequence of 3 positions"),
        (1.0, "targets", "sequence of 3 positions"),
    ],
)
async def test_bad_targets_leave_the_running_motion_alone(
    make_rig: RigFactory, targets: Any, parameter: str, allowed: str
) -> None:
    rig = await make_rig()
    running = await rig.group.move_to([0.3, 0.3, 0.3])
    await rig.sleep(0.1)
    with pytest.raises(BadParameterError) as info:
        await rig.group.move_to(targets)
    assert info.value.parameter == parameter
    assert allowed in str(info.value)
    assert rig.group.current is running
    await running
    assert running.outcome is GroupOutcome.SUCCEEDED
    assert rig.group.commanded == (0.3, 0.3, 0.3)


@pytest.mark.parametrize(
    ("kwargs", "parameter"),
    [
        ({"limits": [LIMITS, LIMITS]}, "limits"),
        ({"limits": [LIMITS, LIMITS, "fast"]}, "limits[2]"),
        ({"tolerances": [Tolerances()] * 4}, "tolerances"),
        ({"duration": 0.0}, "duration"),
        ({"duration": NAN}, "duration"),
        ({"duration": 0.1}, "duration"),  # shorter than the fastest move
        ({"goal_time": -1.0}, "goal_time"),
        ({"goal_time": INF}, "goal_time"),
    ],
)
async def test_bad_move_options_are_refused(
    make_rig: RigFactory, kwargs: dict[str, Any], parameter: str
) -> None:
    rig = await make_rig()
    with pytest.raises(BadParameterError) as info:
        await rig.group.move_to([1.0, 1.0, 1.0], **kwargs)
    assert info.value.parameter == parameter
    assert not rig.group.moving
    await rig.sleep(0.01)
    assert all(m.setpoints == [] for m in rig.motors)


async def test_infeasible_duration_says_what_is_possible(make_rig: RigFactory) -> None:
    rig = await make_rig(axes=1)
    with pytest.raises(BadParameterError, match=r"duration=0.5 .* at least 0\.954167 s"):
        await rig.group.move_to([1.0], duration=0.5)


async def test_an_overshoot_beyond_a_position_limit_is_refused(make_rig: RigFactory) -> None:
    # At speed toward the +1 limit, a preempting move with a far lower acceleration
    # limit could not brake in time: it is refused and the running move goes on.
    motors = [RecordingMotor(position_limits=(-1.0, 1.0))]
    rig = await make_rig(motors=motors)
    running = await rig.group.move_to([0.99])
    await rig.sleep(0.45)
    with pytest.raises(BadParameterError, match="within its position limits") as info:
        await rig.group.move_to([0.9], AxisLimits(1.5, 1.0, 5.0))
    assert info.value.parameter == "targets"
    assert rig.group.current is running
    await running
    assert rig.group.commanded == (0.99,)


async def test_bad_group_construction(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    a, b = [await hal_components.actuator(RecordingMotor()) for _ in range(2)]
    timer = EventTimer(1, clock=virtual_clock)
    cases: list[tuple[dict[str, Any], str]] = [
        ({"actuators": [a, b, a]}, "actuators[2]"),
        ({"actuators": []}, "actuators"),
        ({"actuators": [a, "b"]}, "actuators[1]"),
        ({"actuators": a}, "actuators"),
        ({"timer": "1 ms"}, "timer"),
        ({"limits": [LIMITS]}, "limits"),
        ({"limits": None}, "limits"),
        ({"tolerances": Tolerances(), "goal_time": NAN}, "goal_time"),
        ({"synchronization": "none"}, "synchronization"),
        ({"log_capacity": -1}, "log_capacity"),
    ]
    for overrides, parameter in cases:
        kwargs: dict[str, Any] = {"actuators": [a, b], "timer": timer, "limits": LIMITS}
        kwargs.update(overrides)
        actuators = kwargs.pop("actuators")
        with pytest.raises(BadParameterError) as info:
            AxisGroup(actuators, **kwargs)
        assert info.value.parameter == parameter, overrides
    with pytest.raises(BadParameterError, match=r"it is actuators\[0\]"):
        AxisGroup([a, b, a], timer=timer, limits=LIMITS)
