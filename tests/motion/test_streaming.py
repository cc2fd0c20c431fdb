"""The group's batch streaming over drivers with a synchronous command path: one
validated ActuatorBank batch per tick, no Motion per axis and tick, one COMPLETED per axis
when a motion arrives (per-setpoint events only on request, and never for a superseded
setpoint), and a failing axis named as before."""

from __future__ import annotations

from typing import Any

import pytest

from openel_async import (
    ActuatorBank,
    BadParameterError,
    ComponentState,
    EventId,
    EventNotice,
    EventTimer,
    ObserverQueue,
    Outcome,
    Request,
    VirtualClock,
)
from openel_async.motion import AxisFaultError, AxisGroup, GroupOutcome, PreemptedError
from openel_async.testing import ComponentStack, EventRecorder
from openel_sim import SimMotor

from .rigs import LIMITS, RecordingMotor, RigFactory

MS = 1_000_000


class SyncRecordingMotor(SimMotor):
    """A SimMotor that records its POSITION setpoints and keeps its synchronous path."""

    def __init__(self, **kwargs: Any) -> None:
        kwargs.setdefault("max_velocity", 20.0)
        kwargs.setdefault("max_acceleration", 1e5)
        super().__init__(**kwargs)
        self.setpoints: list[tuple[int, float]] = []
        self.fail_with: Exception | None = None

    def command_nowait(self, request: Request, value: float) -> None:
        if self.fail_with is not None:
            raise self.fail_with
        if request is Request.POSITION:
            self.setpoints.append((self._now(), value))
        super().command_nowait(request, value)

    async def command(self, request: Request, value: float) -> None:
        self.command_nowait(request, value)


class Completions:
    """Records, at each COMPLETED, the completed target and the latest setpoint sent."""

    def __init__(self, motor: SyncRecordingMotor) -> None:
        self.motor = motor
        self.seen: list[tuple[float, float]] = []

    def notify_event(self, source: Any, event_id: int) -> None:
        if event_id == EventId.COMPLETED:
            motion = source.motion
            assert motion is not None and motion.done()
            self.seen.append((motion.target, self.motor.setpoints[-1][1]))

    def notify_error(self, source: object, error_id: int) -> None:
        pass


async def _group(
    hal_components: ComponentStack,
    clock: VirtualClock,
    motors: list[SyncRecordingMotor],
    **kwargs: Any,
) -> tuple[AxisGroup, list[Any], EventTimer]:
    actuators = [
        await hal_components.actuator(m, device_name=f"joint{i}") for i, m in enumerate(motors)
    ]
    timer = EventTimer(1, clock=clock)
    return AxisGroup(actuators, timer=timer, limits=LIMITS, **kwargs), actuators, timer


async def test_a_move_streams_one_batch_per_tick_and_completes_only_the_final_target(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    motors = [SyncRecordingMotor() for _ in range(3)]
    group, actuators, timer = await _group(hal_components, virtual_clock, motors)
    completions = [Completions(m) for m in motors]
    for actuator, observer in zip(actuators, completions, strict=True):
        actuator.add_observer(observer)
    async with timer, group:
        motion = await group.move_to([0.5, -0.25, 1.0])
        await motion
        assert motion.outcome is GroupOutcome.SUCCEEDED
        ticks = len(motors[0].setpoints)
        assert ticks > 100
        # Every axis got every tick's setpoint at the same tick times.
        times = [t for t, _ in motors[0].setpoints]
        assert all([t for t, _ in m.setpoints] == times for m in motors)
        assert [m.setpoints[-1][1] for m in motors] == [0.5, -0.25, 1.0]
        for actuator, target in zip(actuators, [0.5, -0.25, 1.0], strict=True):
            latest = actuator.motion
            assert latest is not None and latest.target == target
            assert await actuator.get_value(Request.POSITION) == target
        await virtual_clock.sleep(0.1)
    # The streamed setpoints post nothing: one COMPLETED per axis, for the group's target.
    for observer, actuator, target in zip(completions, actuators, [0.5, -0.25, 1.0], strict=True):
        assert observer.seen == [(target, target)]
        assert actuator.completed_count == 1
    # The log holds what was sent, sampled from the plan at snapshot time.
    samples = group.log.snapshot()
    sent = [v for t, v in motors[1].setpoints]
    assert list(samples.commanded[: len(sent), 1]) == sent


async def test_preemption_over_the_batch_path_continues_from_the_commanded_state(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    motors = [SyncRecordingMotor() for _ in range(2)]
    group, _, timer = await _group(hal_components, virtual_clock, motors)
    async with timer, group:
        first = await group.move_to([1.0, 1.0])
        await virtual_clock.sleep(0.3)
        before = group.commanded
        second = await group.move_to([-0.5, 0.2])
        with pytest.raises(PreemptedError):
            await first
        await second
    values = [v for _, v in motors[0].setpoints]
    k = next(i for i, (_, v) in enumerate(motors[0].setpoints) if v == before[0])
    steps = [abs(b - a) for a, b in zip(values[k : k + 5], values[k + 1 : k + 6], strict=True)]
    assert max(steps) < LIMITS.max_velocity * 1e-3 * 1.01  # no jump across the switch


@pytest.mark.parametrize("failing", [0, 2])
async def test_a_driver_error_in_the_batch_names_its_axis_and_the_rest_hold(
    hal_components: ComponentStack, virtual_clock: VirtualClock, failing: int
) -> None:
    motors = [SyncRecordingMotor() for _ in range(3)]
    group, _actuators, timer = await _group(hal_components, virtual_clock, motors)
    async with timer, group:
        motion = await group.move_to([0.4, 0.4, 0.4])
        await virtual_clock.sleep(0.1)
        motors[failing].fail_with = RuntimeError("driver bug")
        with pytest.raises(AxisFaultError) as info:
            await motion
        assert info.value.axis == failing and info.value.axis_name == f"joint{failing}"
        assert isinstance(info.value.cause, RuntimeError)
        sent = [len(m.setpoints) for m in motors]
        await virtual_clock.sleep(0.05)
        assert [len(m.setpoints) for m in motors] == sent


async def test_a_link_fault_in_the_batch_names_the_axis_in_error(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    motors = [SyncRecordingMotor() for _ in range(3)]
    group, actuators, timer = await _group(hal_components, virtual_clock, motors)
    async with timer, group:
        motion = await group.move_to([0.4, 0.4, 0.4])
        await virtual_clock.sleep(0.1)
        motors[1].connected = False  # the next command raises NotConnectedError
        with pytest.raises(AxisFaultError) as info:
            await motion
        assert info.value.axis == 1
        assert actuators[1].state is ComponentState.ERROR
        assert info.value.time_ns is not None


async def test_an_observer_queue_on_two_axes_hears_one_completed_per_axis(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    """Issue 21: a 0.8 s group move flooded an observer with 800 COMPLETED events (one per
    streamed setpoint reached); the group's target is what completes, once per axis."""
    motors = [SyncRecordingMotor() for _ in range(2)]
    group, actuators, timer = await _group(hal_components, virtual_clock, motors)
    queue: ObserverQueue = ObserverQueue()
    for actuator in actuators:
        actuator.add_observer(queue)
    async with timer, group:
        motion = await group.move_to([0.6, -0.6], duration=0.8)
        await motion
        await virtual_clock.sleep(0.2)  # nothing more comes while the axes rest
        finished = motion.finished_ns
    notices = queue.drain()
    assert all(isinstance(n, EventNotice) for n in notices)
    assert sorted((n.source.device_name, n.event_id) for n in notices) == [  # type: ignore[union-attr]
        ("joint0", EventId.COMPLETED),
        ("joint1", EventId.COMPLETED),
    ]
    assert len(motors[0].setpoints) >= 800  # every setpoint streamed; none posted
    for actuator, target in zip(actuators, [0.6, -0.6], strict=True):
        latest = actuator.motion  # the final setpoint's Motion is reached, silently
        assert latest is not None and latest.outcome is Outcome.REACHED
        assert latest.target == target and not latest.posts_completed
        assert actuator.completed_count == 1
    assert finished is not None


async def test_the_group_completes_once_per_axis_over_awaited_sends(
    make_rig: RigFactory, virtual_clock: VirtualClock
) -> None:
    """The same over drivers without a synchronous path (one awaited command per axis)."""
    rig = await make_rig(2, motors=[RecordingMotor(), RecordingMotor()])
    events = EventRecorder(virtual_clock)
    for actuator in rig.actuators:
        actuator.add_observer(events)
    first = await rig.group.move_to([0.3, 0.2])
    await rig.sleep(0.2)
    second = await rig.group.move_to([-0.2, 0.4])  # preempts: the first posts nothing
    with pytest.raises(PreemptedError):
        await first
    await second
    await rig.sleep(0.1)
    assert [(r.source, r.id, r.time_ns) for r in events.records] == [
        (actuator, EventId.COMPLETED, second.finished_ns) for actuator in rig.actuators
    ]
    await rig.group.stop()  # idle: nothing
    assert len(events.records) == 2


async def test_per_setpoint_events_on_request(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    """setpoint_events=True: each setpoint an axis reaches before the next one is sent
    completes as a set_value would (only ever the latest one), and the group posts none."""
    motors = [SyncRecordingMotor() for _ in range(2)]
    group, actuators, timer = await _group(
        hal_components, virtual_clock, motors, setpoint_events=True
    )
    completions = [Completions(m) for m in motors]
    for actuator, observer in zip(actuators, completions, strict=True):
        actuator.add_observer(observer)
    async with timer, group:
        await (await group.move_to([0.5, -0.25]))
        await virtual_clock.sleep(0.1)
    for observer, actuator, target in zip(completions, actuators, [0.5, -0.25], strict=True):
        assert len(observer.seen) > 1
        assert all(done == latest for done, latest in observer.seen)
        assert observer.seen[-1][0] == target
        assert actuator.completed_count == len(observer.seen)


async def test_setpoint_events_is_a_bool(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    actuator = await hal_components.actuator(SimMotor())
    timer = EventTimer(1, clock=virtual_clock)
    with pytest.raises(BadParameterError, match="setpoint_events=1 is not allowed"):
        AxisGroup([actuator], timer=timer, limits=LIMITS, setpoint_events=1)  # type: ignore[arg-type]
    with pytest.raises(BadParameterError, match="setpoint_events='no' is not allowed"):
        ActuatorBank([actuator], setpoint_events="no")  # type: ignore[arg-type]
