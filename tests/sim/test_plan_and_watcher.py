"""The flat plan of a position move (profile.plan_trapezoid) is the trapezoid's segments, and
SimMotor's watcher posts COMPLETED at each arrival, from idle or while re-planning."""

from __future__ import annotations

import anyio
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from openel_async import Actuator, Request, VirtualClock
from openel_sim import SimMotor
from openel_sim.profile import evaluate, evaluate_plan, plan_segments, plan_trapezoid, trapezoid

PROPERTY = settings(max_examples=100, derandomize=True, database=None, deadline=None)
finite = st.floats(min_value=-5.0, max_value=5.0, allow_nan=False, allow_infinity=False)
positive = st.floats(min_value=0.05, max_value=50.0, allow_nan=False, allow_infinity=False)


@PROPERTY
@given(finite, finite, finite, positive, positive, st.integers(0, 10**12))
def test_a_plan_evaluates_exactly_as_its_segments(
    p0: float, v0: float, target: float, vmax: float, amax: float, start: int
) -> None:
    plan = plan_trapezoid(start, p0, v0, target, vmax, amax)
    segments = plan_segments(plan)
    assert segments == trapezoid(start, p0, v0, target, vmax, amax)
    times = {start - 1, start, plan[12] + 1_000}
    for seg in segments:
        times.update({seg.start_ns - 1, seg.start_ns, seg.start_ns + 1})
    for t in sorted(times):
        assert evaluate_plan(plan, t) == evaluate(segments, t)


def test_a_hold_plan_is_one_resting_segment() -> None:
    plan = plan_trapezoid(5, 1.0, 0.0, 1.0, 2.0, 10.0)
    assert plan_segments(plan) == trapezoid(5, 1.0, 0.0, 1.0, 2.0, 10.0)
    assert evaluate_plan(plan, 0) == evaluate_plan(plan, 99) == (1.0, 0.0, 0.0)


@pytest.mark.anyio
async def test_completed_at_each_arrival_from_idle_and_after_an_earlier_replan() -> None:
    clock = VirtualClock()
    async with clock.autojump(), Actuator(SimMotor(), clock=clock) as actuator:
        motor = actuator.device
        assert isinstance(motor, SimMotor)
        with anyio.fail_after(10):
            for target in (0.5, -0.5, 0.25):  # each from idle: the watcher had nothing due
                motion = await actuator.set_value(target, Request.POSITION)
                arrival = motor.segments[-1].start_ns
                await motion
                assert motion.reached_ns == arrival == clock.now_ns()
            far = await actuator.set_value(2.0, Request.POSITION)  # the watcher sleeps till...
            near = await actuator.set_value(0.3, Request.POSITION)  # ...an arrival now earlier
            arrival = motor.segments[-1].start_ns
            await near
            assert near.reached_ns == arrival
            assert far.done() and not near.error()
            await clock.sleep(0.01)
        assert actuator.completed_count == 4  # one per final target, the superseded one none
