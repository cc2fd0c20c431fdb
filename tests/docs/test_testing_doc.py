"""The examples of docs/testing.md, verbatim (test_examples.py checks that they match)."""

import anyio
import pytest

from openel_async import (
    Actuator,
    ComponentState,
    DeviceKind,
    ErrorId,
    EventId,
    EventTimer,
    HALId,
    Request,
    Sensor,
    StateError,
    SupersededError,
    VirtualClock,
)
from openel_async.testing import ComponentStack, EventRecorder
from openel_sim import SimMotor, SimTemperature


async def test_move_completes(
    sim_actuator: Actuator, hal_events: EventRecorder, virtual_clock: VirtualClock
) -> None:
    motion = await sim_actuator.set_value(1.0, Request.POSITION)
    await motion  # 0.7 s of simulated time, a few milliseconds of real time
    assert await sim_actuator.get_value(Request.POSITION_ACTUAL) == pytest.approx(1.0)
    assert hal_events.count("event", EventId.COMPLETED) == 1
    assert hal_events.events[-1].time_ns == motion.reached_ns == virtual_clock.now_ns()


async def test_only_the_final_target_completes(
    sim_actuator: Actuator, hal_events: EventRecorder
) -> None:
    first = await sim_actuator.set_value(1.0)
    second = await sim_actuator.set_value(-1.0)
    with pytest.raises(SupersededError):
        await first
    await second
    assert hal_events.count("event", EventId.COMPLETED) == 1


async def test_fault_and_recovery(
    sim_actuator: Actuator, sim_motor: SimMotor, hal_events: EventRecorder
) -> None:
    sim_motor.inject_fault(ErrorId.DEVICE_ERROR)
    assert sim_actuator.state is ComponentState.ERROR
    assert hal_events.errors[-1].id == ErrorId.DEVICE_ERROR
    with pytest.raises(StateError):
        await sim_actuator.get_value()
    await sim_actuator.re_init()
    assert sim_actuator.state is ComponentState.ACTIVE


async def test_sensors_follow_the_motor(
    sim_actuator: Actuator,
    sim_encoder: Sensor,
    sim_imu: Sensor,
    virtual_clock: VirtualClock,
) -> None:
    await sim_actuator.set_value(0.5, Request.VELOCITY)
    await virtual_clock.sleep(1.0)  # 0.5 rad/s is reached after 50 ms
    angle = await sim_encoder.get_timed_value()
    assert angle.num == 1 and angle.time_ns == virtual_clock.now_ns()
    assert angle.values[0] == pytest.approx(0.4875, abs=2e-3)  # 4096 counts per turn
    gyro_z = (await sim_imu.get_value())[5]
    assert gyro_z == pytest.approx(0.5)


async def test_wait_for_a_device_event(sim_actuator: Actuator, hal_events: EventRecorder) -> None:
    await sim_actuator.set_value(2.0, Request.VELOCITY)  # runs into the +pi rad stop
    record = await hal_events.wait_for("event", EventId.LIMIT_REACHED)
    assert record.source is sim_actuator
    assert await sim_actuator.get_value(Request.POSITION_ACTUAL) == pytest.approx(3.14159)


async def test_components_of_my_own(
    hal_components: ComponentStack, hal_events: EventRecorder
) -> None:
    motor = SimMotor(max_velocity=1.0, initial_position=0.5)
    hal_id = HALId(DeviceKind.MOTOR, 0xE1, 0x100, instance_id=7)
    actuator = await hal_components.actuator(motor, hal_id=hal_id)
    thermometer = await hal_components.sensor(SimTemperature(motor))
    actuator.add_observer(hal_events)
    assert actuator.get_profile().id.instance_id == 7
    assert await actuator.get_value(Request.POSITION) == 0.5  # commanded = actual at Init
    assert thermometer.units == ("K",)
    await (await actuator.set_value(0.0, Request.TORQUE))
    assert hal_events.count("event", EventId.COMPLETED) == 1


async def test_timer_on_virtual_time(
    virtual_clock: VirtualClock, hal_events: EventRecorder
) -> None:
    async with EventTimer(10, clock=virtual_clock) as timer:  # 10 ms
        timer.add_observer(hal_events)
        timer.start_timer()
        await hal_events.wait_for("timer", count=100)
        timer.stop_timer()
    assert virtual_clock.now_ns() == 1_000_000_000  # exactly 100 periods
    assert timer.stats.lateness.max_ns == 0


async def test_time_moves_only_when_told() -> None:
    clock = VirtualClock()  # no autojump: manual mode
    woken: list[int] = []

    async def sleeper(deadline_ns: int) -> None:
        await clock.sleep_until(deadline_ns)
        woken.append(clock.now_ns())

    async with anyio.create_task_group() as tg:
        for deadline_ns in (30, 10, 20):
            tg.start_soon(sleeper, deadline_ns)
        await clock.advance(15)
        assert woken == [10]
        await clock.advance_to(30)
        assert woken == [10, 20, 30]


async def test_bounded_in_real_time(virtual_clock: VirtualClock) -> None:
    with anyio.fail_after(1):  # one second of real time
        await virtual_clock.sleep(3600)  # one hour of simulated time
    assert virtual_clock.now_ns() == 3600 * 10**9
