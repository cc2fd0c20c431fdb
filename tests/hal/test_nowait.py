"""The synchronous fast path: set_value_nowait/get_value_nowait and the Sensor's nowait reads.

Every ``*_nowait`` operation is checked against its async twin on the simulated devices (same
result, same errors, same events at the same virtual times), then the cases that only the fast
path has: WouldBlockError for a device that needs to wait, the ``has_nowait`` subclass rule, and
the async operations running without suspending on a device that has a synchronous path.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import anyio
import anyio.lowlevel
import pytest

from openel_async import (
    Actuator,
    ActuatorBank,
    ActuatorDevice,
    ActuatorLimits,
    BadParameterError,
    ComponentState,
    DeviceFaultError,
    ErrorId,
    EventId,
    HALError,
    Motion,
    NotConnectedError,
    NotImplementedHALError,
    Outcome,
    Reading,
    Request,
    ReturnCode,
    Sensor,
    SensorDevice,
    StateError,
    SupersededError,
    VirtualClock,
    WouldBlockError,
)
from openel_async.device import DeviceContext, has_nowait
from openel_async.testing import ComponentStack, EventRecorder
from openel_sim import SimEncoder, SimIMU, SimMotor, SimTemperature

COMPLETED = EventId.COMPLETED


# -- devices used by the tests -------------------------------------------------------------


class AsyncOnlyServo(ActuatorDevice):
    """A device that must wait for every command and reading (a bus): no synchronous path."""

    limits = ActuatorLimits((-2.0, 2.0), 3.0, 1.0)
    reports_completion = True

    def __init__(self) -> None:
        self.position = 0.0
        self.commands: list[tuple[Request, float]] = []
        self.reads: list[Request] = []

    async def command(self, request: Request, value: float) -> None:
        await anyio.lowlevel.checkpoint()  # a real send suspends
        self.commands.append((request, value))
        if request is Request.POSITION:
            self.position = value

    async def read(self, request: Request) -> float:
        await anyio.lowlevel.checkpoint()
        self.reads.append(request)
        return self.position if request is Request.POSITION_ACTUAL else 0.0


class AsyncOnlySensor(SensorDevice):
    """A sensor that must wait for every reading: no synchronous path."""

    units = ("m", "m")

    def __init__(self) -> None:
        self.reads = 0

    async def read(self) -> Reading:
        await anyio.lowlevel.checkpoint()
        self.reads += 1
        return Reading((1.0, 2.0), 42)


class RecordingMotor(SimMotor):
    """Overrides only the async ``command``: the synchronous path must not bypass it."""

    def __init__(self) -> None:
        super().__init__()
        self.recorded: list[tuple[Request, float]] = []

    async def command(self, request: Request, value: float) -> None:
        self.recorded.append((request, value))
        await super().command(request, value)


class RecordingReadMotor(SimMotor):
    """Overrides only the async ``read``."""

    def __init__(self) -> None:
        super().__init__()
        self.read_log: list[Request] = []

    async def read(self, request: Request) -> float:
        self.read_log.append(request)
        return await super().read(request)


class TwoPathMotor(SimMotor):
    """Overrides both twins: which one the framework takes is visible in ``paths``."""

    def __init__(self) -> None:
        super().__init__()
        self.paths: list[str] = []

    async def command(self, request: Request, value: float) -> None:
        self.paths.append("command")
        await super().command(request, value)

    def command_nowait(self, request: Request, value: float) -> None:
        self.paths.append("command_nowait")
        super().command_nowait(request, value)

    async def read(self, request: Request) -> float:
        self.paths.append("read")
        return await super().read(request)

    def read_nowait(self, request: Request) -> float:
        self.paths.append("read_nowait")
        return super().read_nowait(request)


class RecordingEncoder(SimEncoder):
    """Overrides only the async ``read`` of a sensor."""

    def __init__(self, motor: SimMotor) -> None:
        super().__init__(motor)
        self.async_reads = 0

    async def read(self) -> Reading:
        self.async_reads += 1
        return await super().read()


class FailingMotor(SimMotor):
    """A SimMotor whose synchronous calls raise ``failure`` while it is set."""

    def __init__(self) -> None:
        super().__init__()
        self.failure: BaseException | None = None

    def command_nowait(self, request: Request, value: float) -> None:
        if self.failure is not None:
            raise self.failure
        super().command_nowait(request, value)

    def read_nowait(self, request: Request) -> float:
        if self.failure is not None:
            raise self.failure
        return super().read_nowait(request)


class ConstantSensor(SensorDevice):
    """A sensor with a synchronous path returning fixed values (possibly non-finite)."""

    units = ("x", "y")

    def __init__(self, values: Sequence[float], *, has_time: bool = True) -> None:
        self.values = values
        self.has_time = has_time

    async def read(self) -> Reading:
        return self.read_nowait()

    def read_nowait(self) -> Reading:
        return Reading(self.values, 7)


# -- nowait == async on the simulated devices -----------------------------------------------


def _script() -> list[tuple[float, Request, float]]:
    """(delay s, request, value): a mix of modes, superseded targets and reached ones."""
    return [
        (0.0, Request.POSITION, 1.0),
        (0.1, Request.POSITION, -0.5),  # supersedes the first before arrival
        (2.0, Request.VELOCITY, 1.5),  # after the -0.5 target was reached
        (0.5, Request.TORQUE, -0.1),
        (0.3, Request.NO_EXCITE, 0.0),  # completes at once
        (1.0, Request.POSITION, 0.25),
    ]


async def test_set_value_nowait_matches_set_value_motions_and_events(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    fast_motor, slow_motor = SimMotor(), SimMotor()
    fast = await hal_components.actuator(fast_motor)
    slow = await hal_components.actuator(slow_motor)
    events = EventRecorder(virtual_clock)
    fast.add_observer(events)
    slow.add_observer(events)
    fast_motions: list[Motion] = []
    slow_motions: list[Motion] = []
    for delay, request, value in _script():
        await virtual_clock.sleep(delay)
        now = virtual_clock.now_ns()
        fast_motions.append(fast.set_value_nowait(value, request))
        slow_motions.append(await slow.set_value(value, request))
        assert virtual_clock.now_ns() == now  # neither waited
        assert fast.motion is fast_motions[-1] and slow.motion is slow_motions[-1]
        for req in (Request.POSITION, Request.VELOCITY, Request.TORQUE):
            assert fast.get_value_nowait(req) == await slow.get_value(req)  # commanded
    await virtual_clock.sleep(3.0)

    def key(m: Motion) -> tuple[object, ...]:
        return (m.request, m.target, m.sequence, m.issued_ns, m.outcome, m.reached_ns)

    assert [key(m) for m in fast_motions] == [key(m) for m in slow_motions]
    outcomes = [m.outcome for m in fast_motions]
    assert outcomes == [
        Outcome.SUPERSEDED,
        Outcome.REACHED,
        Outcome.REACHED,
        Outcome.REACHED,
        Outcome.REACHED,
        Outcome.REACHED,
    ]
    with pytest.raises(SupersededError):
        await fast_motions[0]
    for motion in fast_motions[1:]:
        await motion

    def timeline(source: Actuator) -> list[tuple[str, int, int]]:
        return [(r.kind, r.id, r.time_ns) for r in events.records if r.source is source]

    assert timeline(fast) == timeline(slow)
    assert [ident for _, ident, _ in timeline(fast)] == [COMPLETED] * 5
    assert fast.completed_count == slow.completed_count == 5
    assert fast_motor.commands == slow_motor.commands == len(_script())
    assert fast.get_value_nowait(Request.POSITION_ACTUAL) == pytest.approx(0.25)


async def test_set_value_nowait_completes_exactly_like_set_value(
    sim_actuator: Actuator, hal_events: EventRecorder, virtual_clock: VirtualClock
) -> None:
    start = virtual_clock.now_ns()
    motion = sim_actuator.set_value_nowait(1.0)
    assert (motion.request, motion.target, motion.issued_ns) == (Request.POSITION, 1.0, start)
    assert motion.outcome is Outcome.PENDING
    record = await hal_events.wait_for("event", COMPLETED)
    # 1 rad at 2 rad/s, 10 rad/s^2: 0.2 s ramp up, 0.3 s cruise, 0.2 s ramp down
    assert record.time_ns - start == 700_000_000
    assert record.source is sim_actuator
    await motion
    assert (motion.outcome, motion.reached_ns) == (Outcome.REACHED, record.time_ns)


async def test_no_excite_nowait_completes_inside_the_call(
    sim_actuator: Actuator, hal_events: EventRecorder
) -> None:
    sim_actuator.set_value_nowait(1.5, Request.VELOCITY)
    assert sim_actuator.get_value_nowait(Request.VELOCITY) == 1.5
    motion = sim_actuator.set_value_nowait(0.0, Request.NO_EXCITE)
    assert motion.outcome is Outcome.REACHED
    # the observer heard of it before the call returned (no await in between)
    assert hal_events.count("event", COMPLETED, source=sim_actuator) == 1
    assert sim_actuator.get_value_nowait(Request.VELOCITY) == 0.0
    assert sim_actuator.get_value_nowait(Request.TORQUE) == 0.0


async def test_get_value_nowait_matches_get_value_during_a_move(
    sim_actuator: Actuator, virtual_clock: VirtualClock
) -> None:
    await sim_actuator.set_value(1.0)
    seen = []
    for _ in range(8):
        await virtual_clock.sleep(0.1)
        for request in Request:
            if request is Request.NO_EXCITE:
                continue
            fast = sim_actuator.get_value_nowait(request)
            assert fast == await sim_actuator.get_value(request)
            assert fast == sim_actuator.get_value_nowait(int(request))  # int codes too
            if request is Request.POSITION_ACTUAL:
                seen.append(fast)
    assert seen == sorted(seen) and seen[0] > 0.0 and seen[-1] == pytest.approx(1.0)


@pytest.mark.parametrize(
    ("value", "request_code", "parameter"),
    [
        (math.nan, Request.POSITION, "value"),
        (math.inf, Request.POSITION, "value"),
        (-math.inf, Request.VELOCITY, "value"),
        ("1.0", Request.POSITION, "value"),
        (None, Request.POSITION, "value"),
        (True, Request.POSITION, "value"),
        (4.0, Request.POSITION, "value"),  # beyond the +-pi position limits
        (2.5, Request.VELOCITY, "value"),  # beyond 2 rad/s
        (-3.0, Request.TORQUE, "value"),  # beyond 2 Nm
        (0.1, 4, "request"),
        (0.1, Request.POSITION_ACTUAL, "request"),
        (0.1, "POSITION", "request"),
    ],
)
async def test_bad_input_is_refused_alike_and_changes_nothing(
    sim_actuator: Actuator,
    sim_motor: SimMotor,
    hal_events: EventRecorder,
    value: object,
    request_code: object,
    parameter: str,
) -> None:
    motion = sim_actuator.set_value_nowait(0.5)
    commands = sim_motor.commands
    with pytest.raises(BadParameterError) as fast:
        sim_actuator.set_value_nowait(value, request_code)  # type: ignore[arg-type]
    with pytest.raises(BadParameterError) as slow:
        await sim_actuator.set_value(value, request_code)  # type: ignore[arg-type]
    assert fast.value.parameter == slow.value.parameter == parameter
    assert str(fast.value) == str(slow.value)
    assert fast.value.code is ReturnCode.HAL_BAD_PARAMETER
    assert sim_motor.commands == commands  # nothing reached the device
    assert sim_actuator.state is ComponentState.ACTIVE
    assert sim_actuator.motion is motion
    assert sim_actuator.get_value_nowait(Request.POSITION) == 0.5
    await motion  # the running command completes as if nothing happened
    assert hal_events.count("event", COMPLETED) == 1 and not hal_events.errors


@pytest.mark.parametrize("code", [0, 4, 8, "x", Request.NO_EXCITE, 1.0])
async def test_get_value_nowait_bad_request_codes(sim_actuator: Actuator, code: object) -> None:
    with pytest.raises(BadParameterError) as fast:
        sim_actuator.get_value_nowait(code)  # type: ignore[arg-type]
    with pytest.raises(BadParameterError) as slow:
        await sim_actuator.get_value(code)  # type: ignore[arg-type]
    assert fast.value.parameter == slow.value.parameter == "request"


async def test_unsupported_request_is_not_implemented_not_would_block(
    hal_components: ComponentStack,
) -> None:
    class PositionOnly(SimMotor):
        supported_requests = frozenset({Request.POSITION})

    motor = PositionOnly()
    actuator = await hal_components.actuator(motor)
    with pytest.raises(NotImplementedHALError) as fast:
        actuator.set_value_nowait(0.1, Request.VELOCITY)
    with pytest.raises(NotImplementedHALError) as slow:
        await actuator.set_value(0.1, Request.VELOCITY)
    for error in (fast.value, slow.value):
        assert not isinstance(error, WouldBlockError)
        assert error.code is ReturnCode.HAL_NOT_IMPLEMENTED
    assert motor.commands == 0 and actuator.motion is None
    assert actuator.set_value_nowait(0.1).target == 0.1  # the supported one goes through


# -- sensors ----------------------------------------------------------------------------------


async def test_sensor_nowait_reads_match_the_async_ones(
    sim_actuator: Actuator, hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    motor = sim_actuator.device
    assert isinstance(motor, SimMotor)
    sensors = [
        await hal_components.sensor(SimEncoder(motor)),
        await hal_components.sensor(SimIMU(motor, radius=0.1)),
        await hal_components.sensor(SimTemperature(motor, heating=50.0)),
    ]
    await sim_actuator.set_value(1.0, Request.VELOCITY)
    for _ in range(5):
        await virtual_clock.sleep(0.05)
        now = virtual_clock.now_ns()
        for sensor in sensors:
            fast = sensor.get_value_nowait()
            assert fast == await sensor.get_value()
            timed = sensor.get_timed_value_nowait()
            assert timed == await sensor.get_timed_value()
            assert timed.values == fast and timed.time_ns == now
            assert type(fast) is tuple and len(fast) == len(sensor.units)
    encoder, imu, _ = sensors
    assert encoder.get_value_nowait()[0] == pytest.approx(0.2, abs=0.002)  # 0.05 + 0.15 rad
    assert imu.get_value_nowait()[5] == pytest.approx(1.0)  # gyro z


async def test_noisy_sensor_nowait_and_async_draw_the_same_sequence(
    hal_components: ComponentStack,
) -> None:
    motor = SimMotor()
    fast = await hal_components.sensor(SimIMU(motor, noise=0.1, seed=5))
    slow = await hal_components.sensor(SimIMU(motor, noise=0.1, seed=5))
    fast_values = [fast.get_value_nowait() for _ in range(5)]
    slow_values = [await slow.get_value() for _ in range(5)]
    assert fast_values == slow_values and len(set(fast_values)) == 5


async def test_sensor_value_checks_are_the_same(hal_components: ComponentStack) -> None:
    # A non-finite value is a device fault (as for an actuator's reading): Error state.
    bad = await hal_components.sensor(ConstantSensor([1.0, math.nan]))
    with pytest.raises(DeviceFaultError, match="non-finite") as fast:
        bad.get_value_nowait()
    assert bad.state is ComponentState.ERROR and fast.value.error_id == ErrorId.DEVICE_ERROR
    await bad.re_init()
    with pytest.raises(DeviceFaultError, match="non-finite") as slow:
        await bad.get_value()
    assert type(fast.value) is type(slow.value) is DeviceFaultError
    await bad.re_init()
    with pytest.raises(DeviceFaultError, match="non-finite"):
        bad.get_timed_value_nowait()
    assert bad.state is ComponentState.ERROR and bad.last_fault is not None

    timeless = await hal_components.sensor(ConstantSensor([1.0, 2.0], has_time=False))
    assert timeless.get_value_nowait() == (1.0, 2.0)  # a list from the device becomes a tuple
    with pytest.raises(HALError, match="no time attribute"):
        timeless.get_timed_value_nowait()
    with pytest.raises(HALError, match="no time attribute"):
        await timeless.get_timed_value()

    timed = await hal_components.sensor(ConstantSensor((1.0, 2.0)))
    assert timed.get_timed_value_nowait() == ((1.0, 2.0), 7)  # the device's own time
    assert await timed.get_timed_value() == ((1.0, 2.0), 7)


# -- async operations take the synchronous path ----------------------------------------------


async def test_async_operations_do_not_suspend_on_a_device_with_a_sync_path(
    sim_actuator: Actuator, sim_encoder: Sensor
) -> None:
    # A checkpoint inside a cancelled scope raises at once: getting through proves no suspension.
    finished = False
    with anyio.CancelScope() as scope:
        scope.cancel()
        motion = await sim_actuator.set_value(0.3)
        position = await sim_actuator.get_value(Request.POSITION_ACTUAL)
        commanded = await sim_actuator.get_value(Request.POSITION)
        values = await sim_encoder.get_value()
        timed = await sim_encoder.get_timed_value()
        finished = True
    assert finished
    assert motion.target == 0.3 and commanded == 0.3 and position == 0.0
    assert values == timed.values == (0.0,)


async def test_async_operations_use_the_nowait_twin_when_the_class_defines_both(
    hal_components: ComponentStack,
) -> None:
    motor = TwoPathMotor()
    actuator = await hal_components.actuator(motor)
    motor.paths.clear()  # _on_active reads the position through the async read
    await actuator.set_value(0.2)
    await actuator.get_value(Request.POSITION_ACTUAL)
    actuator.set_value_nowait(0.3)
    actuator.get_value_nowait(Request.VELOCITY_ACTUAL)
    assert motor.paths == ["command_nowait", "read_nowait"] * 2


async def test_async_set_value_suspends_on_a_device_without_a_sync_path(
    hal_components: ComponentStack,
) -> None:
    device = AsyncOnlyServo()
    actuator = await hal_components.actuator(device)
    with anyio.CancelScope() as scope:
        scope.cancel()
        await actuator.set_value(0.3)
    assert scope.cancelled_caught  # the device's send suspended and was cancelled
    assert device.commands == []


# -- WouldBlockError ------------------------------------------------------------------------


async def test_actuator_without_a_sync_path_raises_would_block(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    device = AsyncOnlyServo()
    actuator = await hal_components.actuator(device)
    events = EventRecorder(virtual_clock)
    actuator.add_observer(events)
    reads = len(device.reads)
    with pytest.raises(WouldBlockError, match="set_value") as info:
        actuator.set_value_nowait(0.5)
    assert isinstance(info.value, NotImplementedHALError)
    assert info.value.code is ReturnCode.HAL_NOT_IMPLEMENTED
    assert actuator.device_name in str(info.value)
    for request in (Request.POSITION_ACTUAL, Request.VELOCITY_ACTUAL, Request.TORQUE_ACTUAL):
        with pytest.raises(WouldBlockError, match="get_value"):
            actuator.get_value_nowait(request)
    # nothing was sent or read, nothing changed
    assert device.commands == [] and len(device.reads) == reads
    assert actuator.motion is None and actuator.state is ComponentState.ACTIVE
    assert not events.records
    # the commanded value needs no device: it is answered without waiting
    assert actuator.get_value_nowait(Request.POSITION) == 0.0
    # the async operations work
    motion = await actuator.set_value(0.5)
    assert device.commands == [(Request.POSITION, 0.5)]
    assert await actuator.get_value(Request.POSITION_ACTUAL) == 0.5
    assert actuator.get_value_nowait(Request.POSITION) == 0.5
    assert actuator.motion is motion
    # bad input is still refused on the sync call, but WouldBlockError comes first
    with pytest.raises(WouldBlockError):
        actuator.set_value_nowait(math.nan)


async def test_sensor_without_a_sync_path_raises_would_block(
    hal_components: ComponentStack,
) -> None:
    device = AsyncOnlySensor()
    sensor = await hal_components.sensor(device)
    with pytest.raises(WouldBlockError, match="get_value") as info:
        sensor.get_value_nowait()
    assert info.value.code is ReturnCode.HAL_NOT_IMPLEMENTED
    with pytest.raises(WouldBlockError):
        sensor.get_timed_value_nowait()
    assert device.reads == 0 and sensor.state is ComponentState.ACTIVE
    assert await sensor.get_value() == (1.0, 2.0)
    assert await sensor.get_timed_value() == ((1.0, 2.0), 42)
    assert device.reads == 2


def test_device_defaults_refuse_with_would_block() -> None:
    servo, sensor = AsyncOnlyServo(), AsyncOnlySensor()
    with pytest.raises(WouldBlockError, match="AsyncOnlyServo"):
        servo.command_nowait(Request.POSITION, 0.0)
    with pytest.raises(WouldBlockError, match="AsyncOnlyServo"):
        servo.read_nowait(Request.POSITION_ACTUAL)
    with pytest.raises(WouldBlockError, match="AsyncOnlySensor"):
        sensor.read_nowait()
    with pytest.raises(WouldBlockError):
        AsyncOnlySensor.read_values_many_nowait([sensor])
    assert AsyncOnlySensor.read_values_many_nowait([]) == []


# -- the has_nowait subclass rule -----------------------------------------------------------


def test_has_nowait_follows_the_defining_classes() -> None:
    class Base(ActuatorDevice):
        async def command(self, request: Request, value: float) -> None:
            pass

        def command_nowait(self, request: Request, value: float) -> None:
            pass

        async def read(self, request: Request) -> float:
            return 0.0

    class OnlyAsync(Base):  # overrides the async twin only: the sync one would bypass it
        async def command(self, request: Request, value: float) -> None:
            pass

    class Again(OnlyAsync):  # ... until a subclass of it defines the sync twin again
        def command_nowait(self, request: Request, value: float) -> None:
            pass

    class OnlySync(Base):  # a faster sync twin of the inherited async one is fine
        def command_nowait(self, request: Request, value: float) -> None:
            pass

    def check(device: ActuatorDevice | SensorDevice) -> bool:
        return has_nowait(device, "command_nowait", "command")

    assert check(Base()) and check(Again()) and check(OnlySync())
    assert not check(OnlyAsync())
    assert not has_nowait(Base(), "read_nowait", "read")  # only the refusing default
    assert not check(AsyncOnlyServo()) and not has_nowait(AsyncOnlySensor(), "read_nowait", "read")
    motor = SimMotor()
    assert check(motor) and has_nowait(motor, "read_nowait", "read")
    assert not check(RecordingMotor()) and has_nowait(RecordingMotor(), "read_nowait", "read")
    assert check(RecordingReadMotor()) and not has_nowait(
        RecordingReadMotor(), "read_nowait", "read"
    )
    assert not has_nowait(RecordingEncoder(motor), "read_nowait", "read")
    for sensor in (SimEncoder(motor), SimIMU(motor), SimTemperature(motor)):
        assert has_nowait(sensor, "read_nowait", "read")


async def test_subclass_overriding_only_async_command_is_not_bypassed(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    motor = RecordingMotor()
    actuator = await hal_components.actuator(motor)
    events = EventRecorder(virtual_clock)
    actuator.add_observer(events)
    with pytest.raises(WouldBlockError):
        actuator.set_value_nowait(0.4)
    assert motor.recorded == [] and motor.commands == 0 and actuator.motion is None
    motion = await actuator.set_value(0.4)
    assert motor.recorded == [(Request.POSITION, 0.4)] and motor.commands == 1
    await motion
    assert events.count("event", COMPLETED, source=actuator) == 1
    # its reads have a sync path: they are allowed
    assert actuator.get_value_nowait(Request.POSITION_ACTUAL) == pytest.approx(0.4)


async def test_subclass_overriding_only_async_read_is_not_bypassed(
    hal_components: ComponentStack,
) -> None:
    motor = RecordingReadMotor()
    actuator = await hal_components.actuator(motor)
    motor.read_log.clear()
    actuator.set_value_nowait(0.1)  # commands have a sync path
    with pytest.raises(WouldBlockError):
        actuator.get_value_nowait(Request.POSITION_ACTUAL)
    assert motor.read_log == []
    assert actuator.get_value_nowait(Request.POSITION) == 0.1  # commanded: no device read
    assert await actuator.get_value(Request.POSITION_ACTUAL) == 0.0  # the move starts now
    assert motor.read_log == [Request.POSITION_ACTUAL]

    encoder = RecordingEncoder(motor)
    sensor = await hal_components.sensor(encoder)
    with pytest.raises(WouldBlockError):
        sensor.get_value_nowait()
    with pytest.raises(WouldBlockError):
        sensor.get_timed_value_nowait()
    assert encoder.async_reads == 0
    await sensor.get_value()
    await sensor.get_timed_value()
    assert encoder.async_reads == 2


# -- link faults ----------------------------------------------------------------------------

LINK_FAULTS: list[tuple[Callable[[], BaseException], ErrorId, ReturnCode]] = [
    (lambda: NotConnectedError("cable pulled"), ErrorId.DISCONNECTED, ReturnCode.HAL_NO_CONNECTED),
    (lambda: TimeoutError("no answer"), ErrorId.TIMEOUT, ReturnCode.HAL_ERROR),
    (lambda: OSError(5, "I/O error"), ErrorId.DISCONNECTED, ReturnCode.HAL_NO_CONNECTED),
    (lambda: anyio.BrokenResourceError(), ErrorId.DISCONNECTED, ReturnCode.HAL_NO_CONNECTED),
]


@pytest.mark.parametrize(("make", "error_id", "code"), LINK_FAULTS)
@pytest.mark.parametrize("operation", ["set_value", "get_value"])
async def test_link_fault_on_the_sync_path_faults_like_the_async_one(
    hal_components: ComponentStack,
    virtual_clock: VirtualClock,
    make: Callable[[], BaseException],
    error_id: ErrorId,
    code: ReturnCode,
    operation: str,
) -> None:
    fast_motor, slow_motor = FailingMotor(), FailingMotor()
    fast = await hal_components.actuator(fast_motor)
    slow = await hal_components.actuator(slow_motor)
    events = EventRecorder(virtual_clock)
    fast.add_observer(events)
    slow.add_observer(events)
    pending = (fast.set_value_nowait(1.0), await slow.set_value(1.0))
    await virtual_clock.sleep(0.1)
    fast_motor.failure, slow_motor.failure = make(), make()
    with pytest.raises(DeviceFaultError) as fast_info:
        if operation == "set_value":
            fast.set_value_nowait(0.0)
        else:
            fast.get_value_nowait(Request.POSITION_ACTUAL)
    # the error observers heard of it inside the call
    assert [(r.kind, r.id, r.source) for r in events.records] == [("error", error_id, fast)]
    with pytest.raises(DeviceFaultError) as slow_info:
        if operation == "set_value":
            await slow.set_value(0.0)
        else:
            await slow.get_value(Request.POSITION_ACTUAL)
    for info, component in ((fast_info, fast), (slow_info, slow)):
        error = info.value
        assert (error.error_id, error.code) == (error_id, code)
        assert type(error.__cause__) is type(fast_motor.failure)
        assert component.state is ComponentState.ERROR and component.last_fault is error
    assert str(fast_info.value).replace(fast.device_name, "") == str(slow_info.value).replace(
        slow.device_name, ""
    )
    assert [(r.kind, r.id, r.time_ns) for r in events.records if r.source is slow] == [
        (r.kind, r.id, r.time_ns) for r in events.records if r.source is fast
    ]
    for motion in pending:  # the motion that was running failed with the fault
        assert motion.outcome is Outcome.FAULTED
        with pytest.raises(DeviceFaultError):
            await motion
    with pytest.raises(StateError):
        fast.set_value_nowait(0.0)
    # recovery
    fast_motor.failure = None
    await fast.re_init()
    assert fast.state is ComponentState.ACTIVE
    motion = fast.set_value_nowait(0.0)
    await motion
    assert events.count("event", COMPLETED, source=fast) == 1


async def test_disconnected_sim_devices_fault_through_nowait(
    sim_actuator: Actuator,
    sim_motor: SimMotor,
    sim_encoder: Sensor,
    hal_events: EventRecorder,
) -> None:
    encoder = sim_encoder.device
    assert isinstance(encoder, SimEncoder)
    sim_encoder.add_observer(hal_events)
    sim_motor.connected = False  # the link drops silently; the next call finds out
    with pytest.raises(DeviceFaultError) as info:
        sim_actuator.set_value_nowait(0.5)
    assert info.value.code is ReturnCode.HAL_NO_CONNECTED
    assert isinstance(info.value.__cause__, NotConnectedError)
    assert sim_actuator.state is ComponentState.ERROR
    assert encoder.connected  # the encoder's own link is fine ...
    encoder.disconnect()  # ... until it drops too
    with pytest.raises(DeviceFaultError):
        sim_encoder.get_timed_value_nowait()
    assert sim_encoder.state is ComponentState.ERROR
    assert [(r.kind, r.id, r.source) for r in hal_events.records] == [
        ("error", ErrorId.DISCONNECTED, sim_actuator),
        ("error", ErrorId.DISCONNECTED, sim_encoder),
    ]
    with pytest.raises(StateError) as state:
        sim_encoder.get_value_nowait()
    assert state.value.operation == "get_value_nowait"


async def test_other_device_errors_propagate_without_a_fault(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    motor = FailingMotor()
    actuator = await hal_components.actuator(motor)
    events = EventRecorder(virtual_clock)
    actuator.add_observer(events)
    motion = actuator.set_value_nowait(1.0)
    motor.failure = HALError("refused by the drive")
    with pytest.raises(HALError, match="refused") as fast:
        actuator.set_value_nowait(0.0)
    with pytest.raises(HALError, match="refused") as slow:
        await actuator.set_value(0.0)
    with pytest.raises(HALError, match="refused"):
        actuator.get_value_nowait(Request.POSITION_ACTUAL)
    assert fast.value is slow.value is motor.failure  # not wrapped
    assert actuator.state is ComponentState.ACTIVE and not events.errors
    assert actuator.motion is motion and motion.outcome is Outcome.PENDING
    motor.failure = None
    await motion


# -- state errors ---------------------------------------------------------------------------


async def test_state_errors_outside_active_name_the_operation(
    hal_components: ComponentStack, sim_motor: SimMotor
) -> None:
    actuator = await hal_components.actuator(sim_motor, auto_init=False)
    encoder = await hal_components.sensor(SimEncoder(sim_motor), auto_init=False)

    def check(state: ComponentState) -> None:
        cases: list[tuple[str, Callable[[], object]]] = [
            ("set_value_nowait", lambda: actuator.set_value_nowait(0.1)),
            ("get_value_nowait", lambda: actuator.get_value_nowait(Request.POSITION)),
            ("get_value_nowait", lambda: actuator.get_value_nowait(Request.POSITION_ACTUAL)),
            ("get_value_nowait", encoder.get_value_nowait),
            ("get_timed_value_nowait", encoder.get_timed_value_nowait),
        ]
        for operation, call in cases:
            with pytest.raises(StateError) as info:
                call()
            assert info.value.operation == operation
            assert info.value.state is state
            assert info.value.allowed == (ComponentState.ACTIVE,)
            assert info.value.code is ReturnCode.HAL_ERROR
            assert f"{operation}()" in str(info.value) and str(state) in str(info.value)

    check(ComponentState.INITIALIZED)
    assert sim_motor.commands == 0
    await actuator.init()
    await encoder.init()
    actuator.set_value_nowait(0.1)
    assert encoder.get_value_nowait() == (0.0,)

    sim_motor.inject_fault()
    device = encoder.device
    assert isinstance(device, SimEncoder)
    device.disconnect()
    with pytest.raises(DeviceFaultError):
        encoder.get_value_nowait()
    check(ComponentState.ERROR)

    await actuator.finalize()
    await encoder.finalize()
    check(ComponentState.FINALIZED)
    assert sim_motor.commands == 1


# -- a device that reports the target reached from inside command_nowait --------------------


class SnapServo(ActuatorDevice):
    """Reaches every target at once and says so from inside ``command_nowait``."""

    limits = ActuatorLimits((-1.0, 1.0), 1.0, 1.0)
    supported_requests = frozenset({Request.POSITION, Request.NO_EXCITE})
    reports_completion = True

    def __init__(self) -> None:
        self.position = 0.0
        self.ctx: DeviceContext | None = None

    async def open(self, ctx: DeviceContext) -> None:
        self.ctx = ctx

    async def command(self, request: Request, value: float) -> None:
        self.command_nowait(request, value)

    def command_nowait(self, request: Request, value: float) -> None:
        if request is Request.POSITION:
            self.position = value
        assert self.ctx is not None
        self.ctx.target_reached()

    async def read(self, request: Request) -> float:
        return self.read_nowait(request)

    def read_nowait(self, request: Request) -> float:
        return self.position if request is Request.POSITION_ACTUAL else 0.0


async def test_reached_inside_command_nowait_completes_the_command_being_sent(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    events = EventRecorder(virtual_clock)
    actuator = await hal_components.actuator(SnapServo())
    actuator.add_observer(events)
    first = actuator.set_value_nowait(0.2)
    assert first.outcome is Outcome.REACHED
    second = await actuator.set_value(0.4)  # the async call takes the same path
    assert second.outcome is Outcome.REACHED and first.outcome is Outcome.REACHED
    stop = actuator.set_value_nowait(0.0, Request.NO_EXCITE)  # completes once, not twice
    assert stop.outcome is Outcome.REACHED
    assert [r.id for r in events.records] == [COMPLETED] * 3
    assert actuator.completed_count == 3


async def test_reached_inside_command_nowait_while_streaming_through_a_bank(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    events = EventRecorder(virtual_clock)
    actuators = [await hal_components.actuator(SnapServo()) for _ in range(3)]
    for actuator in actuators:
        actuator.add_observer(events)
    bank = ActuatorBank(actuators)
    for k in range(1, 4):
        bank.set_values_nowait([0.1 * k, -0.1 * k, 0.05 * k])
        motions = bank.motions
        assert all(m is not None and m.outcome is Outcome.REACHED for m in motions)
        assert [m.target for m in motions if m is not None] == pytest.approx(
            [0.1 * k, -0.1 * k, 0.05 * k]
        )
    assert len(events.records) == 9 and {r.id for r in events.records} == {COMPLETED}
    assert [a.completed_count for a in actuators] == [3, 3, 3]


class LateReportServo(AsyncOnlyServo):
    """A bus device whose status frame for the previous target arrives during the next send."""

    def __init__(self) -> None:
        super().__init__()
        self.ctx: DeviceContext | None = None

    async def open(self, ctx: DeviceContext) -> None:
        self.ctx = ctx

    async def command(self, request: Request, value: float) -> None:
        assert self.ctx is not None
        self.ctx.target_reached()  # the previous target: reached before this one was sent
        await super().command(request, value)


async def test_reached_during_an_awaited_send_is_the_previous_target(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    events = EventRecorder(virtual_clock)
    actuator = await hal_components.actuator(LateReportServo())
    actuator.add_observer(events)
    first = await actuator.set_value(0.5)
    assert first.outcome is Outcome.PENDING
    second = await actuator.set_value(0.7)
    assert first.outcome is Outcome.REACHED and second.outcome is Outcome.PENDING
    assert [r.id for r in events.records] == [COMPLETED]
