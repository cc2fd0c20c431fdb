"""Goal and path tolerances, axis faults, goal timeouts and finalized actuators."""

from __future__ import annotations

import pytest

from openel_async import (
    BadParameterError,
    ComponentState,
    DeviceFaultError,
    EventTimer,
    Request,
    VirtualClock,
)
from openel_async.motion import (
    AxisFaultError,
    AxisGroup,
    AxisStateError,
    GoalTimeoutError,
    GroupOutcome,
    PathToleranceError,
    Tolerances,
)
from openel_async.testing import ComponentStack

from .rigs import LIMITS, RecordingMotor, RigFactory

MS = 1_000_000


async def test_a_stuck_axis_violates_the_path_tolerance(make_rig: RigFactory) -> None:
    rig = await make_rig(tolerances=Tolerances(goal=1e-3, path=0.02))
    motion = await rig.group.move_to([1.0, 1.5, -1.0])
    await rig.sleep(0.5)
    rig.motors[1].set_stuck()
    stuck_at = rig.clock.now_ns()
    with pytest.raises(PathToleranceError) as info:
        await motion
    error = info.value
    assert error.axis == 1 and error.axis_name == "joint1"
    assert error.tolerance == 0.02
    assert error.deviation is not None and -0.03 < error.deviation < -0.02  # it lags behind
    assert "axis 1 (joint1)" in str(error) and "path tolerance 0.02" in str(error)
    assert motion.outcome is GroupOutcome.ABORTED
    assert error.time_ns == motion.finished_ns and error.time_ns is not None
    assert 0 < error.time_ns - stuck_at < 100 * MS
    # Streaming stopped at once: every axis holds its last setpoint.
    assert not rig.group.moving
    for motor in rig.motors:
        assert motor.setpoints[-1][0] < error.time_ns
    sent = [len(m.setpoints) for m in rig.motors]
    await rig.sleep(0.2)
    assert [len(m.setpoints) for m in rig.motors] == sent
    assert await rig.actuators[0].get_value(Request.POSITION_ACTUAL) == pytest.approx(
        rig.motors[0].setpoints[-1][1]
    )


async def test_path_tolerance_is_per_axis(make_rig: RigFactory) -> None:
    # Only axis 0 is checked: axis 2 getting stuck goes unnoticed until the goal check.
    tolerances = [Tolerances(path=0.02), Tolerances(), Tolerances(goal=1e-3)]
    rig = await make_rig(tolerances=tolerances, goal_time=0.05)
    motion = await rig.group.move_to([0.5, 0.5, 0.5])
    await rig.sleep(0.2)
    rig.motors[2].set_stuck()
    with pytest.raises(GoalTimeoutError) as info:
        await motion
    assert info.value.axis == 2


async def test_an_axis_fault_mid_move_aborts_and_the_others_hold(make_rig: RigFactory) -> None:
    rig = await make_rig()
    motion = await rig.group.move_to([1.0, -1.0, 0.5])
    await rig.sleep(0.4)
    rig.motors[2].inject_fault(reason="overcurrent")
    faulted_at = rig.clock.now_ns()
    with pytest.raises(AxisFaultError) as info:
        await motion
    error = info.value
    assert error.axis == 2 and error.axis_name == "joint2"
    assert isinstance(error.cause, DeviceFaultError) and "overcurrent" in str(error)
    assert error.time_ns is not None and 0 <= error.time_ns - faulted_at <= MS
    assert rig.actuators[2].state is ComponentState.ERROR
    holding = [m.setpoints[-1] for m in rig.motors]
    await rig.sleep(0.3)
    assert [m.setpoints[-1] for m in rig.motors] == holding
    # The healthy axes come to rest on their last setpoint; the group moves again
    # once the faulted axis is re-initialized.
    for actuator, (_, setpoint) in zip(rig.actuators[:2], holding[:2], strict=True):
        assert await actuator.get_value(Request.POSITION_ACTUAL) == pytest.approx(setpoint)
    with pytest.raises(AxisStateError) as state_info:
        await rig.group.move_to([0.0, 0.0, 0.0])
    assert state_info.value.axis == 2 and state_info.value.state is ComponentState.ERROR
    await rig.actuators[2].re_init()
    again = await rig.group.move_to([0.0, 0.0, 0.0])
    await again
    assert again.outcome is GroupOutcome.SUCCEEDED


async def test_goal_timeout_names_the_axis_that_did_not_arrive(make_rig: RigFactory) -> None:
    # Axis 1's drive is far weaker than the trajectory: it falls behind its setpoints.
    motors = [RecordingMotor(), RecordingMotor(max_acceleration=0.5), RecordingMotor()]
    rig = await make_rig(motors=motors, goal_time=0.1)
    motion = await rig.group.move_to([0.5, 0.5, 0.5])
    with pytest.raises(GoalTimeoutError) as info:
        await motion
    error = info.value
    assert error.axis == 1 and error.axis_name == "joint1"
    assert error.deviation is not None and error.deviation < -1e-3
    assert error.tolerance == 1e-3
    assert error.time_ns is not None
    assert 100 * MS < error.time_ns - motion.planned_end_ns <= 102 * MS
    assert "0.1 s after the trajectory ended" in str(error)


async def test_a_slow_axis_succeeds_within_the_goal_time(make_rig: RigFactory) -> None:
    motors = [RecordingMotor(), RecordingMotor(max_acceleration=0.5)]
    rig = await make_rig(motors=motors, goal_time=5.0, tolerances=Tolerances(goal=1e-2))
    motion = await rig.group.move_to([0.5, 0.5])
    await motion
    assert motion.finished_ns is not None and motion.finished_ns > motion.planned_end_ns + 10 * MS
    actual = await rig.actuators[1].get_value(Request.POSITION_ACTUAL)
    assert actual == pytest.approx(0.5, abs=1e-2)


async def test_a_finalized_actuator_cannot_join_a_group(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    actuators = [await hal_components.actuator(RecordingMotor()) for _ in range(3)]
    await actuators[1].finalize()
    timer = EventTimer(1, clock=virtual_clock)
    with pytest.raises(BadParameterError) as info:
        AxisGroup(actuators, timer=timer, limits=LIMITS)
    assert info.value.parameter == "actuators[1]"
    assert "not Finalized" in str(info.value)


async def test_a_finalized_axis_refuses_moves_and_changes_nothing(make_rig: RigFactory) -> None:
    rig = await make_rig()
    await (await rig.group.move_to([0.2, 0.2, 0.2]))
    await rig.actuators[1].finalize()
    sent = [len(m.setpoints) for m in rig.motors]
    with pytest.raises(AxisStateError) as info:
        await rig.group.move_to([0.0, 0.0, 0.0])
    assert info.value.axis == 1 and info.value.axis_name == "joint1"
    assert info.value.state is ComponentState.FINALIZED
    assert "Finalized, not Active" in str(info.value)
    await rig.sleep(0.1)
    assert not rig.group.moving
    assert [len(m.setpoints) for m in rig.motors] == sent
    assert rig.group.commanded == (0.2, 0.2, 0.2)


async def test_an_axis_finalized_mid_move_aborts_the_motion(make_rig: RigFactory) -> None:
    rig = await make_rig()
    motion = await rig.group.move_to([1.0, 1.0, 1.0])
    await rig.sleep(0.3)
    await rig.actuators[0].finalize()
    with pytest.raises(AxisFaultError) as info:
        await motion
    assert info.value.axis == 0 and "Finalized" in str(info.value)
    assert info.value.cause is None


class _BrokenReadMotor(RecordingMotor):
    """A motor whose synchronous read raises a driver's own exception once ``broken``."""

    broken = False

    def read_nowait(self, request: Request) -> float:
        if self.broken and request is Request.POSITION_ACTUAL:
            raise RuntimeError("driver bug")
        return super().read_nowait(request)


async def test_a_driver_exception_in_the_bank_read_names_its_axis(make_rig: RigFactory) -> None:
    """The actual positions are read in one bank read per tick (devices read without I/O):
    a driver's exception there (no device fault: the axis stays Active) still aborts
    naming the axis whose read raised, with the exception as its cause."""
    broken = _BrokenReadMotor()
    rig = await make_rig(
        motors=[RecordingMotor(), broken, RecordingMotor()], tolerances=Tolerances(path=0.5)
    )
    motion = await rig.group.move_to([0.5, 0.5, 0.5])
    await rig.sleep(0.1)
    broken.broken = True
    with pytest.raises(AxisFaultError) as info:
        await motion
    error = info.value
    assert error.axis == 1 and error.axis_name == "joint1"
    assert isinstance(error.cause, RuntimeError) and "driver bug" in str(error)
    assert rig.actuators[1].state is ComponentState.ACTIVE
