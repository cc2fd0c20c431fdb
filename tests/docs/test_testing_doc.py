"""The examples of docs/testing.md, verbatim (test_examples.py checks that they match),
then tests of the plugin's ComponentStack beyond the examples."""

import contextlib
import math

import anyio
import pytest

from openel_async import (
    Actuator,
    ComponentState,
    DeviceKind,
    ErrorId,
    EventId,
    EventTimer,
    HALComponent,
    HALId,
    Request,
    Sensor,
    StateError,
    SupersededError,
    VirtualClock,
    VirtualClockStalledError,
)
from openel_async.app import AppContext, AppHook, AppInfo, run_app
from openel_async.testing import ComponentStack, EventRecorder
from openel_sim import SimEncoder, SimMotor, SimTemperature


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


async def test_manual_clock_beside_the_fixture_clock(virtual_clock: VirtualClock) -> None:
    rig = VirtualClock()  # manual mode
    with anyio.fail_after(1):  # one second of real time
        with pytest.raises(StateError):
            await virtual_clock.advance(10)  # auto-jump drives this clock
        async with anyio.create_task_group() as tg:
            tg.start_soon(rig.sleep_until, 10)
            await virtual_clock.sleep(5)  # auto-jump moves the fixture clock
            await rig.advance(10)  # and the rig's clock moves when told
    assert (virtual_clock.now_ns(), rig.now_ns()) == (5 * 10**9, 10)


async def test_bounds_around_a_component(hal_components: ComponentStack) -> None:
    with anyio.fail_after(1):
        actuator = await hal_components.actuator(SimMotor())
    with anyio.fail_after(1):
        await (await actuator.set_value(1.0))
    assert actuator.state is ComponentState.ACTIVE


async def test_bounded_in_real_time(virtual_clock: VirtualClock) -> None:
    with anyio.fail_after(1):  # one second of real time
        await virtual_clock.sleep(3600)  # one hour of simulated time
    assert virtual_clock.now_ns() == 3600 * 10**9


async def hello(ctx: AppContext) -> int:
    target = float(ctx.argv[0])
    clock = ctx.use_clock(VirtualClock())
    motor = ctx.add_component(Actuator(SimMotor(), device_name="MOTOR_1", clock=clock))
    async with clock.autojump(), motor:
        await (await motor.set_value(target))
        position = await motor.get_value(Request.POSITION_ACTUAL)
    print(f"{ctx.prog}: at {position:+.3f} rad after {clock.elapsed_s():.2f} s")
    return 0 if abs(position - target) < 1e-3 else 1


HELLO = AppInfo(name="hello", description="one motor to a position", main=hello)


class ComponentNames(AppHook):
    """Told of each component the app registers, before the app enters it."""

    def __init__(self) -> None:
        self.names: list[str] = []

    def component_added(self, ctx: AppContext, component: HALComponent) -> None:
        self.names.append(component.device_name)


def test_an_app_runs_to_its_exit_status(capsys: pytest.CaptureFixture[str]) -> None:
    names = ComponentNames()
    assert run_app(HELLO, ["1.0"], prog="hello", hooks=[names]) == 0
    assert "hello: at +1.000 rad after 0.70 s" in capsys.readouterr().out
    assert names.names == ["MOTOR_1"]


async def test_a_coarse_noisy_encoder(
    hal_components: ComponentStack, sim_actuator: Actuator, sim_motor: SimMotor
) -> None:
    encoder = SimEncoder(sim_motor, counts_per_rev=360, noise=1e-3, seed=7)
    sensor = await hal_components.sensor(encoder)
    await (await sim_actuator.set_value(0.5))
    (angle,) = await sensor.get_value()
    assert angle == pytest.approx(0.5, abs=2 * math.pi / 360)  # within a count: 1 degree


async def test_seconds_since_start(virtual_clock: VirtualClock) -> None:
    await virtual_clock.sleep(1.5)
    mark = virtual_clock.now_ns()
    await virtual_clock.sleep(0.25)
    assert virtual_clock.elapsed_s() == 1.75  # since start_ns (0)
    assert virtual_clock.elapsed_s(mark) == 0.25


async def test_a_clock_nothing_drives_raises() -> None:
    clock = VirtualClock(stall_timeout=0.1)  # real seconds of an otherwise idle loop
    with pytest.raises(VirtualClockStalledError, match="nothing advances this clock"):
        await clock.sleep(1.0)  # no autojump(), no advance(): an error, not a hang


# -- ComponentStack: cancel scopes of the test never interleave with components -----------


class _Probe:
    """A stand-in component recording which task enters and exits it, and when."""

    def __init__(self, name: str, log: list[tuple[str, str, object]], hold: bool = False) -> None:
        self.name = name
        self.log = log
        self.hold = hold  # wait forever in __aenter__ (until cancelled)
        self.stack = contextlib.AsyncExitStack()

    async def __aenter__(self) -> "_Probe":
        task = anyio.get_current_task().id
        await self.stack.enter_async_context(anyio.create_task_group())  # like a component
        try:
            if self.hold:
                await anyio.sleep_forever()
        except BaseException:
            self.log.append(("enter cancelled", self.name, task))
            await self.stack.aclose()
            raise
        self.log.append(("entered", self.name, task))
        return self

    async def __aexit__(self, *exc: object) -> None:
        self.log.append(("exited", self.name, anyio.get_current_task().id))
        await self.stack.aclose()


async def test_fail_after_inside_the_test_and_open_at_its_end(
    hal_components: ComponentStack,
) -> None:
    """The test ends inside the scope it entered the component in (teardown comes after)."""
    with anyio.fail_after(5):
        actuator = await hal_components.actuator(SimMotor())
        await (await actuator.set_value(1.0))


async def test_fixture_component_then_fail_after(sim_actuator: Actuator) -> None:
    """The other order: the component entered by a fixture, the bound in the test."""
    with anyio.fail_after(5):
        await (await sim_actuator.set_value(1.0))


@pytest.mark.parametrize("scope", ["fail_after", "move_on_after", "none"])
async def test_components_live_in_their_own_tasks(scope: str) -> None:
    log: list[tuple[str, str, object]] = []
    test_task = anyio.get_current_task().id
    with anyio.fail_after(5):
        async with anyio.create_task_group() as tg:
            stack = ComponentStack(tg, VirtualClock())
            first = _Probe("first", log)
            await stack.enter(first)  # type: ignore[type-var]
            if scope == "fail_after":
                with anyio.fail_after(5):
                    await stack.enter(_Probe("second", log))  # type: ignore[type-var]
            elif scope == "move_on_after":
                with anyio.move_on_after(5):
                    await stack.enter(_Probe("second", log))  # type: ignore[type-var]
            else:
                await stack.enter(_Probe("second", log))  # type: ignore[type-var]
            await stack.aclose()
    assert [(what, name) for what, name, _ in log] == [
        ("entered", "first"),
        ("entered", "second"),
        ("exited", "second"),  # last entered, first exited
        ("exited", "first"),
    ]
    tasks = {name: {task for _, n, task in log if n == name} for name in ("first", "second")}
    assert all(len(t) == 1 and test_task not in t for t in tasks.values())  # one task each
    assert tasks["first"] != tasks["second"]


async def test_an_expiring_scope_cancels_the_entering() -> None:
    log: list[tuple[str, str, object]] = []
    with anyio.fail_after(5):
        async with anyio.create_task_group() as tg:
            stack = ComponentStack(tg, VirtualClock())
            with pytest.raises(TimeoutError):
                with anyio.fail_after(0.01):
                    await stack.enter(_Probe("stuck", log, hold=True))  # type: ignore[type-var]
            await stack.enter(_Probe("next", log))  # type: ignore[type-var]
            await stack.aclose()
    assert [(what, name) for what, name, _ in log] == [
        ("enter cancelled", "stuck"),  # never entered, so never exited
        ("entered", "next"),
        ("exited", "next"),
    ]


async def test_an_error_while_entering_is_raised_to_the_caller(
    hal_components: ComponentStack,
) -> None:
    actuator = await hal_components.actuator(SimMotor())
    with pytest.raises(StateError, match="__aenter__"):
        await hal_components.enter(actuator)  # already entered
    assert actuator.state is ComponentState.ACTIVE
