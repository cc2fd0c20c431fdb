"""ActuatorBank and SensorBank: one call for many components, each keeping its own semantics.

Checked here: every value validated before any is sent (all or nothing), Motions built lazily
yet behaving like set_value's (issue time, completion, supersession, faults), COMPLETED only
for each actuator's final target while setpoints stream, the async path for devices without a
synchronous one, SensorBank batching through ``read_values_many_nowait`` with link faults landing on
the sensor that has them.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from typing import ClassVar

import anyio
import anyio.lowlevel
import numpy as np
import pytest

from openel_async import (
    Actuator,
    ActuatorBank,
    ActuatorDevice,
    ActuatorLimits,
    BadParameterError,
    ComponentState,
    DeviceContext,
    DeviceFaultError,
    ErrorId,
    EventId,
    HALError,
    Motion,
    MotionCancelledError,
    NotConnectedError,
    NotImplementedHALError,
    Outcome,
    Reading,
    Request,
    ReturnCode,
    SensorBank,
    SensorDevice,
    StateError,
    SupersededError,
    VirtualClock,
    WouldBlockError,
)
from openel_async.device import BatchCommander
from openel_async.streaming import send_targets
from openel_async.testing import ComponentStack, EventRecorder
from openel_sim import SimEncoder, SimIMU, SimMotor, SimTemperature

COMPLETED = EventId.COMPLETED


# -- devices ---------------------------------------------------------------------------------


class AsyncSimMotor(SimMotor):
    """A SimMotor behind a link that must wait: its async twins override the sync ones, so
    the framework may not take the synchronous path (``has_nowait``)."""

    def __init__(self) -> None:
        super().__init__()
        self.async_commands: list[tuple[Request, float]] = []

    async def command(self, request: Request, value: float) -> None:
        await anyio.lowlevel.checkpoint()
        self.async_commands.append((request, value))
        await super().command(request, value)

    async def read(self, request: Request) -> float:
        await anyio.lowlevel.checkpoint()
        return await super().read(request)


class InstantServo(ActuatorDevice):
    """Reaches any position at once and cannot tell: the framework detects completion."""

    limits = ActuatorLimits((-1.0, 1.0), 1.0, 1.0)
    supported_requests = frozenset({Request.POSITION})

    def __init__(self) -> None:
        self.position = 0.0
        self.commands = 0

    async def command(self, request: Request, value: float) -> None:
        self.command_nowait(request, value)

    def command_nowait(self, request: Request, value: float) -> None:
        self.commands += 1
        self.position = value

    async def read(self, request: Request) -> float:
        return self.read_nowait(request)

    def read_nowait(self, request: Request) -> float:
        return self.position if request is Request.POSITION_ACTUAL else 0.0


class BatchSensor(SensorDevice):
    """A sensor on a shared bus: one ``read_values_many_nowait`` serves the whole bank."""

    units = ("V",)
    batches: ClassVar[list[int]] = []

    def __init__(self, value: float) -> None:
        self.value = value
        self.connected = True
        self.single_reads = 0
        self.ctx: DeviceContext | None = None

    async def open(self, ctx: DeviceContext) -> None:
        self.ctx = ctx

    async def read(self) -> Reading:
        return self.read_nowait()

    def read_nowait(self) -> Reading:
        self.single_reads += 1
        if not self.connected:
            raise NotConnectedError("sensor off the bus")
        return Reading([self.value])  # a list: the component makes it a tuple

    @classmethod
    def read_values_many_nowait(cls, devices: Sequence[SensorDevice]) -> list[Sequence[float]]:
        cls.batches.append(len(devices))
        values: list[Sequence[float]] = []
        for device in devices:
            assert isinstance(device, BatchSensor)
            if not device.connected:
                raise NotConnectedError("bus error during the batch")
            values.append((device.value,))
        return values


class OtherBatchSensor(BatchSensor):
    """Same behaviour, another class: a bank mixing the two reads device by device."""


class AsyncOnlySensor(SensorDevice):
    units = ("m",)

    async def read(self) -> Reading:
        await anyio.lowlevel.checkpoint()
        return Reading((3.0,))


@pytest.fixture(autouse=True)
def _clear_batches() -> None:
    BatchSensor.batches.clear()


async def _motors(
    stack: ComponentStack, count: int, events: EventRecorder | None = None, name: str = "Axis"
) -> tuple[list[SimMotor], list[Actuator]]:
    """``count`` SimMotors and their actuators, named ``{name}0``, ``{name}1``, ..."""
    motors = [SimMotor() for _ in range(count)]
    actuators = [await stack.actuator(m, device_name=f"{name}{i}") for i, m in enumerate(motors)]
    if events is not None:
        for actuator in actuators:
            actuator.add_observer(events)
    return motors, actuators


def _commanded(actuators: Sequence[Actuator]) -> list[tuple[float, float, float]]:
    return [
        (
            a.get_value_nowait(Request.POSITION),
            a.get_value_nowait(Request.VELOCITY),
            a.get_value_nowait(Request.TORQUE),
        )
        for a in actuators
    ]


# -- construction ------------------------------------------------------------------------------


async def test_constructor_refuses_empty_foreign_and_duplicate_members(
    hal_components: ComponentStack, sim_motor: SimMotor
) -> None:
    _, (a, b) = await _motors(hal_components, 2)
    encoder = await hal_components.sensor(SimEncoder(sim_motor))
    for members in ([], [a, encoder], [a, b, a], [sim_motor]):
        with pytest.raises(BadParameterError) as info:
            ActuatorBank(members)  # type: ignore[arg-type]
        assert info.value.parameter == "actuators"
    for sensors in ([], [encoder, a], [encoder, encoder]):
        with pytest.raises(BadParameterError) as info:
            SensorBank(sensors)  # type: ignore[arg-type]
        assert info.value.parameter == "sensors"
    bank = ActuatorBank(x for x in (a, b))  # any iterable
    assert len(bank) == 2 and list(bank) == [a, b] and bank.actuators == (a, b)
    assert a.device_name in repr(bank)
    sensors_bank = SensorBank([encoder])
    assert len(sensors_bank) == 1 and list(sensors_bank) == [encoder]
    assert bank.motions == (None, None)  # no command yet


# -- set_values ------------------------------------------------------------------------------


@pytest.mark.parametrize("nowait", [True, False])
async def test_set_values_is_set_value_on_every_actuator(
    hal_components: ComponentStack, virtual_clock: VirtualClock, nowait: bool
) -> None:
    events = EventRecorder(virtual_clock)
    motors, actuators = await _motors(hal_components, 3, events)
    _, references = await _motors(hal_components, 3, events, name="Reference")
    bank = ActuatorBank(actuators)
    await virtual_clock.sleep(0.01)
    start = virtual_clock.now_ns()
    targets = [0.5, -0.25, 1.0]
    if nowait:
        result = bank.set_values_nowait(targets)  # type: ignore[func-returns-value]
    else:
        result = await bank.set_values(targets, Request.POSITION)  # type: ignore[func-returns-value]
    assert result is None
    assert virtual_clock.now_ns() == start  # no waiting on devices that need no I/O
    expected = [
        reference.set_value_nowait(t) for reference, t in zip(references, targets, strict=True)
    ]
    assert [m.commands for m in motors] == [1, 1, 1]
    assert bank.get_values_nowait(Request.POSITION) == tuple(targets)
    assert _commanded(actuators) == _commanded(references)
    motions = bank.motions
    assert all(isinstance(m, Motion) for m in motions)
    assert tuple(a.motion for a in actuators) == motions
    for motion, reference in zip(motions, expected, strict=True):
        assert motion is not None
        assert (motion.request, motion.target, motion.issued_ns, motion.outcome) == (
            reference.request,
            reference.target,
            start,
            Outcome.PENDING,
        )
    for motion in motions:
        assert motion is not None
        await motion
    for reference in expected:
        await reference
    for motion, reference, actuator in zip(motions, expected, actuators, strict=True):
        assert motion is not None and motion.outcome is Outcome.REACHED
        assert motion.reached_ns == reference.reached_ns
        completions = [r for r in events.events if r.source is actuator]
        assert [(r.id, r.time_ns) for r in completions] == [(COMPLETED, motion.reached_ns)]
    # 1 rad at 2 rad/s and 10 rad/s^2 takes 0.7 s
    last = motions[2]
    assert last is not None and last.reached_ns == start + 700_000_000
    actual = bank.get_values_nowait(Request.POSITION_ACTUAL)
    assert actual == pytest.approx(targets)
    assert actual == await bank.get_values(Request.POSITION_ACTUAL)


async def test_lazy_motions_keep_the_issue_time_and_sequence(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    _, actuators = await _motors(hal_components, 2)
    bank = ActuatorBank(actuators)
    first = actuators[0].set_value_nowait(0.1)
    issued = virtual_clock.now_ns()
    bank.set_values_nowait([1.0, -1.0])
    await virtual_clock.sleep(0.05)  # the Motions are built only now ...
    motions = bank.motions
    assert motions == bank.motions  # ... once: the same objects every time
    a, b = motions
    assert a is not None and b is not None
    assert a.issued_ns == b.issued_ns == issued  # ... with the time of the command
    assert a.sequence == first.sequence + 1
    assert first.outcome is Outcome.SUPERSEDED
    await a
    assert a.reached_ns == issued + 700_000_000


async def test_streaming_completes_only_the_final_targets(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    events = EventRecorder(virtual_clock)
    motors, actuators = await _motors(hal_components, 2, events)
    bank = ActuatorBank(actuators)
    watched: tuple[Motion | None, ...] = ()
    for k in range(1, 101):  # setpoints faster than the motors can follow: none is reached
        bank.set_values_nowait([0.01 * k, -0.01 * k])
        if k == 50:
            watched = bank.motions
        await virtual_clock.sleep(0.001)
    assert [m.commands for m in motors] == [100, 100]
    assert not events.records  # nothing completed while streaming
    for motion in watched:
        assert motion is not None and motion.outcome is Outcome.SUPERSEDED
        with pytest.raises(SupersededError):
            await motion
    final = bank.motions
    for motion in final:
        assert motion is not None
        await motion
    await virtual_clock.sleep(2.0)
    for actuator, motion, target in zip(actuators, final, (1.0, -1.0), strict=True):
        assert motion is not None and motion.target == pytest.approx(target)
        records = [(r.kind, r.id, r.time_ns) for r in events.records if r.source is actuator]
        assert records == [("event", COMPLETED, motion.reached_ns)]
        assert actuator.completed_count == 1
        assert actuator.get_value_nowait(Request.POSITION_ACTUAL) == pytest.approx(target)


async def test_streaming_to_devices_that_cannot_report_completion(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    events = EventRecorder(virtual_clock)
    devices = [InstantServo(), InstantServo()]
    actuators = [await hal_components.actuator(d) for d in devices]
    for actuator in actuators:
        actuator.add_observer(events)
    bank = ActuatorBank(actuators)
    policy = actuators[0].completion
    first: tuple[Motion | None, ...] = ()
    for k in range(1, 41):  # a new setpoint every ms: never settled for settle_ns
        bank.set_values_nowait([0.02 * k, -0.02 * k])
        if k == 1:
            first = bank.motions
        await virtual_clock.sleep(0.001)
    stream_end = virtual_clock.now_ns() - 1_000_000
    assert not events.records
    assert all(m is not None and m.outcome is Outcome.SUPERSEDED for m in first)
    final = bank.motions
    for motion in final:
        assert motion is not None
        await motion
    await virtual_clock.sleep(0.5)
    for actuator, motion in zip(actuators, final, strict=True):
        assert motion is not None and motion.outcome is Outcome.REACHED
        assert motion.reached_ns is not None
        assert motion.reached_ns - stream_end >= policy.settle_ns  # settled before completing
        assert events.count("event", COMPLETED, source=actuator) == 1
    assert [d.commands for d in devices] == [40, 40]


async def test_lazy_motion_fails_with_a_fault_and_is_cancelled_by_finalize(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    motors, actuators = await _motors(hal_components, 2)
    bank = ActuatorBank(actuators)
    bank.set_values_nowait([1.0, 1.0])  # Motions not built yet
    await virtual_clock.sleep(0.1)
    motors[0].inject_fault(error_id=9)
    await actuators[1].finalize()
    faulted, cancelled = bank.motions
    assert faulted is not None and faulted.outcome is Outcome.FAULTED
    with pytest.raises(DeviceFaultError) as info:
        await faulted
    assert info.value.error_id == 9
    assert cancelled is not None and cancelled.outcome is Outcome.CANCELLED
    with pytest.raises(MotionCancelledError):
        await cancelled


async def test_set_value_after_streaming_supersedes_the_streamed_target(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    events = EventRecorder(virtual_clock)
    _, actuators = await _motors(hal_components, 2, events)
    bank = ActuatorBank(actuators)
    bank.set_values_nowait([1.0, 1.0])
    streamed = bank.motions[0]
    direct = actuators[0].set_value_nowait(0.2)
    assert streamed is not None and streamed is not direct and bank.motions[0] is direct
    assert streamed.outcome is Outcome.SUPERSEDED and streamed.target == 1.0
    assert streamed.sequence < direct.sequence
    await direct
    await virtual_clock.sleep(1.0)
    assert events.count("event", COMPLETED, source=actuators[0]) == 1
    assert events.count("event", COMPLETED, source=actuators[1]) == 1


@pytest.mark.parametrize("path", ["batch", "per device", "awaited"])
async def test_a_bank_without_setpoint_events_completes_its_motions_silently(
    hal_components: ComponentStack, virtual_clock: VirtualClock, path: str
) -> None:
    """setpoint_events=False (an AxisGroup's bank): the streamed targets' Motions are reached
    but post no COMPLETED; the same bank's default posts one per reached target."""
    events = EventRecorder(virtual_clock)

    class OwnPath(SimMotor):  # a command path of its own: no device batch (batch_commander)
        def command_nowait(self, request: Request, value: float) -> None:
            super().command_nowait(request, value)

    kind = {"batch": SimMotor, "per device": OwnPath, "awaited": AsyncSimMotor}[path]
    actuators = [await hal_components.actuator(kind()) for _ in range(2)]
    for actuator in actuators:
        actuator.add_observer(events)
    quiet = ActuatorBank(actuators, setpoint_events=False)
    assert (quiet._streamed is not None) is (path == "batch")
    for k in (1, 2, 3):
        if path == "awaited":
            await quiet.set_values([0.1 * k, -0.1 * k])
        else:
            quiet.set_values_nowait([0.1 * k, -0.1 * k])
        await virtual_clock.sleep(0.5)
    motions = quiet.motions
    assert all(m is not None and m.outcome is Outcome.REACHED for m in motions)
    assert not any(m is not None and m.posts_completed for m in motions)
    assert events.count("event", COMPLETED) == 0
    assert [a.completed_count for a in actuators] == [0, 0]
    await (await actuators[0].set_value(0.0))  # set_value keeps its event
    loud = ActuatorBank(actuators)
    await loud.set_values([0.2, 0.2])
    await virtual_clock.sleep(0.5)
    assert events.count("event", COMPLETED, source=actuators[0]) == 2
    assert events.count("event", COMPLETED, source=actuators[1]) == 1


# -- validation: all or nothing ------------------------------------------------------------------

BAD_VALUES: list[tuple[int, object, Request]] = [
    (0, math.nan, Request.POSITION),
    (1, math.inf, Request.POSITION),
    (2, -math.inf, Request.POSITION),
    (2, 4.0, Request.POSITION),  # beyond the +-pi limits
    (1, -3.5, Request.POSITION),
    (2, "0.1", Request.POSITION),
    (1, None, Request.POSITION),
    (2, True, Request.POSITION),
    (2, 2.5, Request.VELOCITY),  # beyond 2 rad/s
    (1, math.nan, Request.VELOCITY),
    (2, -3.0, Request.TORQUE),  # beyond 2 Nm
]


@pytest.mark.parametrize("nowait", [True, False])
@pytest.mark.parametrize(("index", "bad", "request_code"), BAD_VALUES)
async def test_one_bad_value_changes_no_actuator(
    hal_components: ComponentStack,
    virtual_clock: VirtualClock,
    nowait: bool,
    index: int,
    bad: object,
    request_code: Request,
) -> None:
    events = EventRecorder(virtual_clock)
    motors, actuators = await _motors(hal_components, 3, events)
    bank = ActuatorBank(actuators)
    bank.set_values_nowait([0.1, 0.2, 0.3])
    before = bank.motions
    commanded = _commanded(actuators)
    values: list[object] = [0.5, 0.5, 0.5]
    values[index] = bad
    with pytest.raises(BadParameterError) as info:
        if nowait:
            bank.set_values_nowait(values, request_code)  # type: ignore[arg-type]
        else:
            await bank.set_values(values, request_code)  # type: ignore[arg-type]
    assert info.value.parameter == f"values[{index}]"
    assert info.value.code is ReturnCode.HAL_BAD_PARAMETER
    assert [f"Axis{j}" in str(info.value) for j in range(3)] == [j == index for j in range(3)]
    assert [m.commands for m in motors] == [1, 1, 1]  # nothing was sent, to any actuator
    assert _commanded(actuators) == commanded
    assert bank.motions == before
    assert all(m is not None and m.outcome is Outcome.PENDING for m in before)
    assert all(a.state is ComponentState.ACTIVE for a in actuators)
    for motion in before:  # the running commands complete as if nothing happened
        assert motion is not None
        await motion
    assert events.count("event", COMPLETED) == 3 and not events.errors


async def test_bad_value_before_any_motion_leaves_the_motions_unbuilt(
    hal_components: ComponentStack,
) -> None:
    motors, actuators = await _motors(hal_components, 2)
    bank = ActuatorBank(actuators)
    with pytest.raises(BadParameterError, match=r"values\[1\]"):
        bank.set_values_nowait([0.1, math.nan])
    assert bank.motions == (None, None) and [m.commands for m in motors] == [0, 0]


@pytest.mark.parametrize("nowait", [True, False])
async def test_count_request_and_support_are_checked_before_sending(
    hal_components: ComponentStack, nowait: bool
) -> None:
    class PositionOnly(SimMotor):
        supported_requests = frozenset({Request.POSITION, Request.VELOCITY})

    motors = [SimMotor(), PositionOnly()]
    actuators = [await hal_components.actuator(m) for m in motors]
    bank = ActuatorBank(actuators)

    async def call(values: Sequence[object], request: object = Request.POSITION) -> None:
        if nowait:
            bank.set_values_nowait(values, request)  # type: ignore[arg-type]
        else:
            await bank.set_values(values, request)  # type: ignore[arg-type]

    for values in ([0.1], [0.1, 0.2, 0.3], []):
        with pytest.raises(BadParameterError) as info:
            await call(values)
        assert info.value.parameter == "values"
    for request in (4, Request.POSITION_ACTUAL, "POSITION", 1.0):
        with pytest.raises(BadParameterError) as info:
            await call([0.1, 0.2], request)
        assert info.value.parameter == "request"
    with pytest.raises(NotImplementedHALError) as unsupported:
        await call([0.1, 0.2], Request.TORQUE)
    assert not isinstance(unsupported.value, WouldBlockError)
    assert [m.commands for m in motors] == [0, 0] and bank.motions == (None, None)
    # int values and int request codes are accepted like set_value accepts them
    await call([1, 0], 1)
    assert bank.get_values_nowait(1) == (1.0, 0.0)
    await call([0.5, -0.5], Request.VELOCITY)
    assert bank.get_values_nowait(Request.VELOCITY) == (0.5, -0.5)
    assert [m.commands for m in motors] == [2, 2]


@pytest.mark.parametrize("nowait", [True, False])
async def test_an_actuator_outside_active_stops_the_whole_call(
    hal_components: ComponentStack, nowait: bool
) -> None:
    motors = [SimMotor(), SimMotor()]
    first = await hal_components.actuator(motors[0], device_name="First")
    second = await hal_components.actuator(motors[1], device_name="Second", auto_init=False)
    bank = ActuatorBank([first, second])
    operation = "set_values_nowait" if nowait else "set_values"
    with pytest.raises(StateError) as info:
        if nowait:
            bank.set_values_nowait([0.1, 0.2])
        else:
            await bank.set_values([0.1, 0.2])
    assert info.value.operation == f"{operation} ({second.device_name})"
    assert info.value.state is ComponentState.INITIALIZED
    assert [m.commands for m in motors] == [0, 0] and first.motion is None
    with pytest.raises(StateError) as read_info:
        if nowait:
            bank.get_values_nowait()
        else:
            await bank.get_values()
    assert read_info.value.operation.startswith("get_values")
    assert second.device_name in read_info.value.operation
    await second.init()
    bank.set_values_nowait([0.1, 0.2])
    assert [m.commands for m in motors] == [1, 1]


async def test_get_values_reads_every_actuator(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    _, actuators = await _motors(hal_components, 3)
    bank = ActuatorBank(actuators)
    bank.set_values_nowait([1.0, 0.5, -1.0])
    actuators[2].set_value_nowait(0.2, Request.TORQUE)
    await virtual_clock.sleep(0.2)
    for request in (
        Request.POSITION,
        Request.VELOCITY,
        Request.TORQUE,
        Request.POSITION_ACTUAL,
        Request.VELOCITY_ACTUAL,
        Request.TORQUE_ACTUAL,
    ):
        each = tuple(a.get_value_nowait(request) for a in actuators)
        assert bank.get_values_nowait(request) == each
        assert bank.get_values_nowait(int(request)) == each
        assert await bank.get_values(request) == each
    assert bank.get_values_nowait() == bank.get_values_nowait(Request.POSITION_ACTUAL)
    assert bank.get_values_nowait(Request.TORQUE) == (0.0, 0.0, 0.2)
    for code in (0, 4, 8, "x"):
        with pytest.raises(BadParameterError) as info:
            bank.get_values_nowait(code)  # type: ignore[arg-type]
        assert info.value.parameter == "request"


async def test_set_values_does_not_suspend_on_devices_with_a_sync_path(
    hal_components: ComponentStack,
) -> None:
    motors, actuators = await _motors(hal_components, 2)
    bank = ActuatorBank(actuators)
    done = False
    with anyio.CancelScope() as scope:
        scope.cancel()  # any checkpoint would raise here
        await bank.set_values([0.3, 0.4])
        values = await bank.get_values(Request.POSITION)
        done = True
    assert done and values == (0.3, 0.4) and [m.commands for m in motors] == [1, 1]


# -- devices without a synchronous path ----------------------------------------------------------


async def test_bank_with_a_device_without_sync_path(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    events = EventRecorder(virtual_clock)
    fast_motor, slow_motor = SimMotor(), AsyncSimMotor()
    fast = await hal_components.actuator(fast_motor, device_name="Local")
    slow = await hal_components.actuator(slow_motor, device_name="Remote")
    for actuator in (fast, slow):
        actuator.add_observer(events)
    bank = ActuatorBank([fast, slow])
    with pytest.raises(WouldBlockError) as info:
        bank.set_values_nowait([0.5, 0.5])
    assert "Remote" in str(info.value) and "Local" not in str(info.value)
    assert "set_values" in str(info.value)
    assert info.value.code is ReturnCode.HAL_NOT_IMPLEMENTED
    with pytest.raises(WouldBlockError):
        bank.get_values_nowait(Request.POSITION_ACTUAL)
    assert bank.get_values_nowait(Request.POSITION) == (0.0, 0.0)  # commanded: no device
    # nothing was sent, not even to the actuator that could have taken it at once
    assert fast_motor.commands == slow_motor.commands == 0 and bank.motions == (None, None)

    # the async operations work, through the device's own async command
    with pytest.raises(BadParameterError, match=r"values\[1\]"):
        await bank.set_values([0.5, math.nan])
    assert slow_motor.async_commands == [] and fast_motor.commands == 0
    await bank.set_values([0.5, -0.5])
    assert slow_motor.async_commands == [(Request.POSITION, -0.5)]
    motions = bank.motions
    assert all(m is not None and m.outcome is Outcome.PENDING for m in motions)
    for motion in motions:
        assert motion is not None
        await motion
    for actuator, target in zip((fast, slow), (0.5, -0.5), strict=True):
        assert events.count("event", COMPLETED, source=actuator) == 1
        assert actuator.get_value_nowait(Request.POSITION) == target
    assert await bank.get_values(Request.POSITION_ACTUAL) == pytest.approx((0.5, -0.5))


async def test_send_targets_streams_awaited_commands_with_lazy_motions(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    """The awaited batch (an AxisGroup over devices without a synchronous path): one
    coroutine for the batch, Motions built when asked for, the same as set_value's; a
    set_value that overtakes a command during its await stays the final target."""
    events = EventRecorder(virtual_clock)
    motors = [AsyncSimMotor(), AsyncSimMotor()]
    actuators = [
        await hal_components.actuator(m, device_name=f"A{i}") for i, m in enumerate(motors)
    ]
    for actuator in actuators:
        actuator.add_observer(events)
    first = await actuators[0].set_value(0.1)
    issued = virtual_clock.now_ns()
    await send_targets(actuators, Request.POSITION, [0.5, -0.5])
    assert [m.async_commands[-1] for m in motors] == [
        (Request.POSITION, 0.5),
        (Request.POSITION, -0.5),
    ]
    assert first.outcome is Outcome.SUPERSEDED
    a, b = actuators[0].motion, actuators[1].motion
    assert a is not None and b is not None
    assert a.issued_ns == b.issued_ns == issued and a.sequence == first.sequence + 1
    await a
    await b
    assert [events.count("event", COMPLETED, source=x) for x in actuators] == [1, 1]

    async def overtake() -> None:  # runs while axis 0's command awaits its link
        await actuators[0].set_value(0.25)

    async with anyio.create_task_group() as tg:
        tg.start_soon(send_targets, actuators, Request.POSITION, [-0.25, 0.0])
        tg.start_soon(overtake)
    latest = actuators[0].motion
    assert latest is not None and latest.target == 0.25
    await latest
    assert actuators[0].get_value_nowait(Request.POSITION) == 0.25


# -- link faults ---------------------------------------------------------------------------------


async def test_link_fault_lands_on_its_own_actuator(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    events = EventRecorder(virtual_clock)
    motors, actuators = await _motors(hal_components, 3, events)
    bank = ActuatorBank(actuators)
    motors[1].connected = False
    with pytest.raises(DeviceFaultError) as info:
        bank.set_values_nowait([0.3, 0.3, 0.3])
    assert isinstance(info.value.__cause__, NotConnectedError)
    assert info.value.code is ReturnCode.HAL_NO_CONNECTED
    assert "Axis1" in str(info.value) and "Axis0" not in str(info.value)
    assert [a.state for a in actuators] == [
        ComponentState.ACTIVE,
        ComponentState.ERROR,
        ComponentState.ACTIVE,
    ]
    assert [(r.kind, r.id, r.source) for r in events.records] == [
        ("error", ErrorId.DISCONNECTED, actuators[1])
    ]
    # set_value on each actuator in order: the first got its command, the last did not
    assert [m.commands for m in motors] == [1, 0, 0]
    with pytest.raises(StateError):
        bank.set_values_nowait([0.3, 0.3, 0.3])
    motors[1].connected = True
    await actuators[1].re_init()
    bank.set_values_nowait([0.3, 0.3, 0.3])
    motors[2].connected = False
    with pytest.raises(DeviceFaultError):
        bank.get_values_nowait(Request.VELOCITY_ACTUAL)
    assert actuators[2].state is ComponentState.ERROR
    assert [r.source for r in events.errors] == [actuators[1], actuators[2]]


# -- SensorBank ----------------------------------------------------------------------------------


async def test_sensor_bank_over_mixed_device_classes(
    sim_actuator: Actuator, hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    motor = sim_actuator.device
    assert isinstance(motor, SimMotor)
    sensors = [
        await hal_components.sensor(SimEncoder(motor)),
        await hal_components.sensor(SimIMU(motor, radius=0.1)),
        await hal_components.sensor(SimTemperature(motor)),
        await hal_components.sensor(SimEncoder(motor, counts_per_rev=360)),
    ]
    bank = SensorBank(sensors)
    sim_actuator.set_value_nowait(1.0, Request.VELOCITY)
    for _ in range(4):
        await virtual_clock.sleep(0.07)
        values = bank.get_values_nowait()
        assert values == tuple(s.get_value_nowait() for s in sensors)
        assert values == await bank.get_values()
        assert [len(v) for v in values] == [1, 6, 1, 1]
        assert all(type(v) is tuple for v in values)
    assert values[1][5] == pytest.approx(1.0)  # gyro z follows the motor


async def test_sensor_bank_reads_one_class_in_one_batch(
    hal_components: ComponentStack,
) -> None:
    devices = [BatchSensor(1.0), BatchSensor(2.0), BatchSensor(3.0)]
    sensors = [await hal_components.sensor(d) for d in devices]
    bank = SensorBank(sensors)
    assert bank.get_values_nowait() == ((1.0,), (2.0,), (3.0,))
    assert await bank.get_values() == ((1.0,), (2.0,), (3.0,))
    assert BatchSensor.batches == [3, 3]
    assert [d.single_reads for d in devices] == [0, 0, 0]

    mixed = SensorBank([sensors[0], await hal_components.sensor(OtherBatchSensor(5.0))])
    assert mixed.get_values_nowait() == ((1.0,), (5.0,))
    assert BatchSensor.batches == [3, 3]  # two classes: read one by one
    assert devices[0].single_reads == 1


@pytest.mark.parametrize("faulty", [0, 1, 2])
async def test_link_fault_during_a_batch_lands_on_its_own_sensor(
    hal_components: ComponentStack, virtual_clock: VirtualClock, faulty: int
) -> None:
    events = EventRecorder(virtual_clock)
    devices = [BatchSensor(1.0), BatchSensor(2.0), BatchSensor(3.0)]
    sensors = [await hal_components.sensor(d, device_name=f"Bus{i}") for i, d in enumerate(devices)]
    for sensor in sensors:
        sensor.add_observer(events)
    bank = SensorBank(sensors)
    devices[faulty].connected = False
    with pytest.raises(DeviceFaultError) as info:
        bank.get_values_nowait()
    assert isinstance(info.value.__cause__, NotConnectedError)
    assert sensors[faulty].device_name in str(info.value)
    assert BatchSensor.batches == [3]  # the batch failed, then one by one up to the fault
    assert [d.single_reads for d in devices] == [1] * (faulty + 1) + [0] * (2 - faulty)
    assert [s.state for s in sensors] == [
        ComponentState.ERROR if i == faulty else ComponentState.ACTIVE for i in range(3)
    ]
    assert [(r.kind, r.id, r.source) for r in events.records] == [
        ("error", ErrorId.DISCONNECTED, sensors[faulty])
    ]
    with pytest.raises(StateError) as state:
        bank.get_values_nowait()
    assert sensors[faulty].device_name in state.value.operation
    devices[faulty].connected = True
    await sensors[faulty].re_init()
    assert bank.get_values_nowait() == ((1.0,), (2.0,), (3.0,))


async def test_disconnected_sim_sensor_in_a_default_batch(
    hal_components: ComponentStack, sim_motor: SimMotor, virtual_clock: VirtualClock
) -> None:
    events = EventRecorder(virtual_clock)
    encoders = [SimEncoder(sim_motor), SimEncoder(sim_motor), SimEncoder(sim_motor)]
    sensors = [
        await hal_components.sensor(e, device_name=f"Encoder{i}") for i, e in enumerate(encoders)
    ]
    for sensor in sensors:
        sensor.add_observer(events)
    bank = SensorBank(sensors)
    assert bank.get_values_nowait() == ((0.0,),) * 3
    encoders[1].disconnect()
    with pytest.raises(DeviceFaultError, match="Encoder1"):
        bank.get_values_nowait()
    assert [s.state for s in sensors] == [
        ComponentState.ACTIVE,
        ComponentState.ERROR,
        ComponentState.ACTIVE,
    ]
    assert [r.source for r in events.errors] == [sensors[1]]


async def test_sensor_bank_non_finite_values_fault_their_own_sensor(
    hal_components: ComponentStack,
) -> None:
    devices = [BatchSensor(1.0), BatchSensor(math.inf)]
    sensors = [await hal_components.sensor(d, device_name=f"Bus{i}") for i, d in enumerate(devices)]
    bank = SensorBank(sensors)
    with pytest.raises(DeviceFaultError, match="non-finite") as info:
        bank.get_values_nowait()
    assert "Bus1" in str(info.value) and "Bus0" not in str(info.value)
    assert [s.state for s in sensors] == [ComponentState.ACTIVE, ComponentState.ERROR]
    await sensors[1].re_init()
    with pytest.raises(DeviceFaultError, match="non-finite"):
        await bank.get_values()
    await sensors[1].re_init()
    devices[1].value = math.nan  # one by one (per-device reads) too
    alone = SensorBank([sensors[1], await hal_components.sensor(OtherBatchSensor(0.0))])
    with pytest.raises(DeviceFaultError, match="non-finite"):
        alone.get_values_nowait()
    assert sensors[0].state is ComponentState.ACTIVE
    assert sensors[1].state is ComponentState.ERROR


class LooseBatchSensor(BatchSensor):
    """A batch that returns its values as lists, NumPy arrays or tuples (``shape`` per device)."""

    shapes: ClassVar[dict[int, str]] = {}

    @classmethod
    def read_values_many_nowait(cls, devices: Sequence[SensorDevice]) -> list[Sequence[float]]:
        out: list[Sequence[float]] = []
        for device in devices:
            assert isinstance(device, BatchSensor)
            shape = cls.shapes.get(id(device), "tuple")
            if shape == "list":
                out.append([device.value])
            elif shape == "array":
                out.append(np.array([device.value, device.value]))
            else:
                out.append((device.value,))
        return out


@pytest.mark.parametrize(
    "shapes",
    [("list", "tuple"), ("tuple", "array"), ("array", "list"), ("tuple", "tuple")],
)
async def test_sensor_bank_returns_tuples_whatever_the_batch_returns(
    hal_components: ComponentStack, shapes: tuple[str, str]
) -> None:
    devices = [LooseBatchSensor(1.5), LooseBatchSensor(-2.5)]
    LooseBatchSensor.shapes = {id(d): shape for d, shape in zip(devices, shapes, strict=True)}
    sensors = [await hal_components.sensor(d) for d in devices]
    bank = SensorBank(sensors)
    values = bank.get_values_nowait()
    expected = tuple(
        (d.value, d.value) if shape == "array" else (d.value,)
        for d, shape in zip(devices, shapes, strict=True)
    )
    assert values == expected
    assert all(type(v) is tuple for v in values)
    devices[1].value = math.nan  # a non-finite value is found whatever the container
    with pytest.raises(HALError, match="non-finite"):
        bank.get_values_nowait()


class ShortBatchSensor(BatchSensor):
    @classmethod
    def read_values_many_nowait(cls, devices: Sequence[SensorDevice]) -> list[Sequence[float]]:
        return [(1.0,)] * (len(devices) - 1)


async def test_a_batch_with_the_wrong_count_is_an_error(hal_components: ComponentStack) -> None:
    sensors = [await hal_components.sensor(ShortBatchSensor(1.0)) for _ in range(3)]
    with pytest.raises(HALError, match="returned 2 values for 3 devices"):
        SensorBank(sensors).get_values_nowait()


async def test_sensor_bank_with_a_device_without_sync_path(
    hal_components: ComponentStack, sim_motor: SimMotor
) -> None:
    encoder = await hal_components.sensor(SimEncoder(sim_motor))
    remote = await hal_components.sensor(AsyncOnlySensor())
    bank = SensorBank([encoder, remote])
    with pytest.raises(WouldBlockError) as info:
        bank.get_values_nowait()
    assert remote.device_name in str(info.value)
    assert await bank.get_values() == ((0.0,), (3.0,))


async def test_sensor_bank_outside_active_names_the_sensor(
    hal_components: ComponentStack,
) -> None:
    devices = [BatchSensor(1.0), BatchSensor(2.0)]
    ready = await hal_components.sensor(devices[0], device_name="Ready")
    idle = await hal_components.sensor(devices[1], device_name="Idle", auto_init=False)
    bank = SensorBank([ready, idle])
    with pytest.raises(StateError) as info:
        bank.get_values_nowait()
    assert info.value.operation == "get_values_nowait (Idle)"
    assert info.value.state is ComponentState.INITIALIZED
    with pytest.raises(StateError):
        await bank.get_values()
    assert BatchSensor.batches == [] and [d.single_reads for d in devices] == [0, 0]


async def test_banks_see_a_member_leave_active_after_calls_that_skipped_the_check(
    hal_components: ComponentStack,
) -> None:
    """Banks skip their per-member Active checks while no component changed state; a member
    that leaves Active afterwards (a fault, finalize) still stops the next call."""
    devices = [BatchSensor(1.0), BatchSensor(2.0)]
    sensors = [await hal_components.sensor(d) for d in devices]
    sensor_bank = SensorBank(sensors)
    motors = [SimMotor(), SimMotor()]
    actuators = [await hal_components.actuator(m) for m in motors]
    actuator_bank = ActuatorBank(actuators)
    for _ in range(3):
        assert sensor_bank.get_values_nowait() == ((1.0,), (2.0,))
        assert actuator_bank.get_values_nowait(Request.POSITION_ACTUAL) == (0.0, 0.0)
    assert devices[1].ctx is not None
    devices[1].ctx.fault(ErrorId.DEVICE_ERROR, "brown-out")
    with pytest.raises(StateError) as info:
        sensor_bank.get_values_nowait()
    assert info.value.operation == f"get_values_nowait ({sensors[1].device_name})"
    assert info.value.state is ComponentState.ERROR
    await actuators[0].finalize()
    with pytest.raises(StateError) as read_info:
        actuator_bank.get_values_nowait(Request.POSITION_ACTUAL)
    assert actuators[0].device_name in read_info.value.operation
    with pytest.raises(StateError):
        actuator_bank.set_values_nowait([0.1, 0.2])
    assert [m.commands for m in motors] == [0, 0]


async def test_sensor_bank_over_mujoco_sensors(hal_components: ComponentStack) -> None:
    pytest.importorskip("mujoco")
    from openel_mujoco import MujocoSim

    moved, still = MujocoSim("arm2"), MujocoSim("arm2")
    names = ("imu_acc", "imu_gyro", "tip_pos", "shoulder_pos_sensor", "elbow_vel_sensor")
    sensors = [await hal_components.sensor(moved.sensor(name), clock=moved.clock) for name in names]
    others = [
        await hal_components.sensor(still.sensor(name), clock=still.clock)
        for name in ("tip_pos", "shoulder_pos_sensor")
    ]
    moved.data.ctrl[0] = 1.0  # shoulder_pos: turn the arm
    assert moved.step(150) == 150 and still.step(3) == 3
    bank = SensorBank(sensors)  # one class, one simulation: one batch
    values = bank.get_values_nowait()
    assert values == tuple(s.get_value_nowait() for s in sensors)
    assert values == tuple(moved.sensors[name].values for name in names)
    assert values[3][0] > 0.1  # the shoulder turned
    mixed = SensorBank([sensors[2], others[0], sensors[3], others[1]])  # two simulations
    assert mixed.get_values_nowait() == (
        moved.sensors["tip_pos"].values,
        still.sensors["tip_pos"].values,
        moved.sensors["shoulder_pos_sensor"].values,
        still.sensors["shoulder_pos_sensor"].values,
    )
    assert still.sensors["shoulder_pos_sensor"].values == (0.0,)
    assert await mixed.get_values() == mixed.get_values_nowait()


# -- a driver's batch command (ActuatorDevice.batch_commander) ------------------------------


class BatchServo(ActuatorDevice):
    """Reports completion; its driver commands a whole bank in one call when ``accept``."""

    limits = ActuatorLimits((-1.0, math.inf), 1.0, 1.0)  # one infinite limit
    supported_requests = frozenset({Request.POSITION, Request.VELOCITY})
    reports_completion = True
    batches: ClassVar[list[tuple[Request, tuple[float, ...]]]] = []
    accept: ClassVar[bool] = True
    connected: ClassVar[bool] = True

    def __init__(self) -> None:
        self.position = 0.0
        self.commands = 0
        self.ctx: DeviceContext | None = None

    async def open(self, ctx: DeviceContext) -> None:
        self.ctx = ctx

    async def command(self, request: Request, value: float) -> None:
        self.command_nowait(request, value)

    def command_nowait(self, request: Request, value: float) -> None:
        if not BatchServo.connected:
            raise NotConnectedError("bus down")
        self.commands += 1
        self.position = value

    async def read(self, request: Request) -> float:
        return self.read_nowait(request)

    def read_nowait(self, request: Request) -> float:
        return self.position

    @classmethod
    def batch_commander(cls, devices: Sequence[ActuatorDevice]) -> BatchCommander | None:
        servos = [d for d in devices if isinstance(d, BatchServo)]

        def command(request: Request, values: Sequence[float], /) -> bool:
            if not BatchServo.connected:
                raise NotConnectedError("bus down")
            if not BatchServo.accept:
                return False
            cls.batches.append((request, tuple(values)))
            for servo, value in zip(servos, values, strict=True):
                servo.position = value
            return True

        return command


@pytest.fixture
def _batch_servos() -> Iterator[None]:
    BatchServo.batches.clear()
    BatchServo.accept = BatchServo.connected = True
    yield
    BatchServo.accept = BatchServo.connected = True


@pytest.mark.usefixtures("_batch_servos")
async def test_a_driver_batch_streams_the_whole_bank_with_the_same_semantics(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    events = EventRecorder(virtual_clock)
    servos = [BatchServo() for _ in range(3)]
    actuators = [
        await hal_components.actuator(s, device_name=f"Servo{i}") for i, s in enumerate(servos)
    ]
    heard: list[tuple[str, Request, float]] = []

    class Listener:
        def on_command(self, component: object, request: Request, value: float, t: int) -> None:
            heard.append((getattr(component, "device_name", ""), request, value))

        def on_reading(self, *args: object) -> None: ...

        def on_state(self, *args: object) -> None: ...

    for actuator in actuators:
        actuator.add_observer(events)
    actuators[2].set_listener(Listener())  # type: ignore[arg-type]
    bank = ActuatorBank(actuators)
    bank.set_values_nowait([0.1, 0.2, 0.3])
    first = bank.motions
    await bank.set_values([0.4, 0.5, 1e300])  # an infinite limit takes any finite float
    assert BatchServo.batches == [
        (Request.POSITION, (0.1, 0.2, 0.3)),
        (Request.POSITION, (0.4, 0.5, 1e300)),
    ]
    assert [s.commands for s in servos] == [0, 0, 0]  # no command_nowait one by one
    assert [s.position for s in servos] == [0.4, 0.5, 1e300]
    assert heard == [("Servo2", Request.POSITION, 0.3), ("Servo2", Request.POSITION, 1e300)]
    assert all(m is not None and m.outcome is Outcome.SUPERSEDED for m in first)
    final = bank.motions
    assert [m.target for m in final if m is not None] == [0.4, 0.5, 1e300]
    assert bank.get_values_nowait(Request.POSITION) == (0.4, 0.5, 1e300)
    for servo in servos:
        assert servo.ctx is not None
        servo.ctx.target_reached()
    for motion in final:
        assert motion is not None
        await motion
    assert events.count("event", COMPLETED) == 3 and not events.errors


@pytest.mark.usefixtures("_batch_servos")
@pytest.mark.parametrize("bad", [math.inf, -math.inf, math.nan, -1.5, "0.1", None, True])
async def test_a_bad_value_reaches_no_batch(hal_components: ComponentStack, bad: object) -> None:
    servos = [BatchServo() for _ in range(3)]
    actuators = [await hal_components.actuator(s) for s in servos]
    bank = ActuatorBank(actuators)
    with pytest.raises(BadParameterError) as info:
        bank.set_values_nowait([0.1, bad, 0.3])  # type: ignore[list-item]
    assert info.value.parameter == "values[1]"
    assert BatchServo.batches == [] and [s.commands for s in servos] == [0, 0, 0]
    assert bank.motions == (None, None, None)


@pytest.mark.usefixtures("_batch_servos")
async def test_batch_gets_floats_and_declines_to_the_per_device_path(
    hal_components: ComponentStack,
) -> None:
    servos = [BatchServo() for _ in range(2)]
    bank = ActuatorBank([await hal_components.actuator(s) for s in servos])
    bank.set_values_nowait([1, np.float64(0.5)])  # type: ignore[list-item]
    ((_, values),) = BatchServo.batches
    assert values == (1.0, 0.5) and [type(v) for v in values] == [float, float]
    BatchServo.accept = False  # e.g. a device in another control mode
    bank.set_values_nowait([0.25, 0.75])
    assert [s.commands for s in servos] == [1, 1] and len(BatchServo.batches) == 1
    assert [s.position for s in servos] == [0.25, 0.75]
    assert [m.target for m in bank.motions if m is not None] == [0.25, 0.75]


@pytest.mark.usefixtures("_batch_servos")
async def test_a_link_fault_in_a_batch_lands_on_the_first_actuator_the_device_path_tries(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    events = EventRecorder(virtual_clock)
    servos = [BatchServo() for _ in range(2)]
    actuators = [
        await hal_components.actuator(s, device_name=f"S{i}") for i, s in enumerate(servos)
    ]
    for actuator in actuators:
        actuator.add_observer(events)
    bank = ActuatorBank(actuators)
    BatchServo.connected = False
    with pytest.raises(DeviceFaultError) as info:
        bank.set_values_nowait([0.1, 0.2])
    assert "S0" in str(info.value) and isinstance(info.value.__cause__, NotConnectedError)
    assert [a.state for a in actuators] == [ComponentState.ERROR, ComponentState.ACTIVE]
    assert [r.source for r in events.errors] == [actuators[0]]
    assert BatchServo.batches == [] and [s.commands for s in servos] == [0, 0]


async def test_mujoco_joints_stream_in_one_batch_until_a_mode_changes(
    hal_components: ComponentStack,
) -> None:
    pytest.importorskip("mujoco")
    from openel_mujoco import MujocoSim

    sim = MujocoSim("arm2")
    joints = [sim.actuator(name) for name in ("shoulder", "elbow")]
    actuators = [await hal_components.actuator(j, clock=sim.clock) for j in joints]
    bank = ActuatorBank(actuators)
    assert bank._batch is not None
    pos_acts = [j._drive_act for j in joints]
    bank.set_values_nowait([0.3, -0.2])
    assert [j.commands for j in joints] == [1, 1]
    assert [float(sim.data.ctrl[a]) for a in pos_acts] == [
        0.3 * j._drive_scale for j in [joints[0]]
    ] + [-0.2 * joints[1]._drive_scale]
    assert [j._target for j in joints] == [0.3, -0.2] and all(j.pending for j in joints)
    actuators[1].set_value_nowait(0.5, Request.VELOCITY)  # the elbow leaves POSITION
    assert joints[1]._direct is Request.VELOCITY
    bank.set_values_nowait([0.1, 0.2])  # the batch declines: per joint, the elbow switches back
    assert joints[1]._direct is Request.POSITION
    bank.set_values_nowait([0.15, 0.25])  # one batch again, planned for the new mode
    assert [j._target for j in joints] == [0.15, 0.25] and [j.commands for j in joints] == [3, 4]
    assert [float(sim.data.ctrl[j._drive_act]) for j in joints] == [
        0.15 * joints[0]._drive_scale,
        0.25 * joints[1]._drive_scale,
    ]


# -- the batch stream: each actuator settles its own state lazily (StreamBatch) ------------


@pytest.mark.usefixtures("_batch_servos")
async def test_a_streamed_actuator_settles_when_read_and_completes_only_its_latest_target(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    events = EventRecorder(virtual_clock)
    servos = [BatchServo() for _ in range(2)]
    actuators = [await hal_components.actuator(s) for s in servos]
    for actuator in actuators:
        actuator.add_observer(events)
    before = actuators[0].set_value_nowait(0.05)  # pending when the bank starts streaming
    bank = ActuatorBank(actuators)
    for k in range(1, 6):
        bank.set_values_nowait([0.1 * k, -0.1 * k])
    assert before.outcome is Outcome.SUPERSEDED  # replaced by the bank's first batch
    assert bank.get_values_nowait(Request.POSITION) == (0.5, -0.5)  # nobody asked for Motions
    assert await actuators[1].get_value(Request.POSITION) == -0.5
    built = actuators[0].motion  # asked for: built from the latest batch
    assert built is not None and built.target == 0.5
    assert built.sequence == before.sequence + 5  # one sequence number per batch
    bank.set_values_nowait([0.6, -0.6])  # supersedes the Motion built in between
    assert built.outcome is Outcome.SUPERSEDED
    with pytest.raises(SupersededError):
        await built
    for servo in servos:
        assert servo.ctx is not None
        servo.ctx.target_reached()
    final = bank.motions
    assert [m.target for m in final if m is not None] == [0.6, -0.6]
    assert all(m is not None and m.outcome is Outcome.REACHED for m in final)
    assert events.count("event", COMPLETED) == 2 and not events.errors


@pytest.mark.usefixtures("_batch_servos")
async def test_a_command_by_another_path_leaves_the_batch_stream_in_order(
    hal_components: ComponentStack,
) -> None:
    servos = [BatchServo() for _ in range(2)]
    actuators = [await hal_components.actuator(s) for s in servos]
    bank = ActuatorBank(actuators)
    bank.set_values_nowait([0.1, 0.2])
    bank.set_values_nowait([0.3, 0.4])
    own = await actuators[1].set_value(0.9)  # after two batches: a later sequence number
    assert own.outcome is Outcome.PENDING and own.sequence == 3
    assert bank.get_values_nowait(Request.POSITION) == (0.3, 0.9)
    bank.set_values_nowait([0.5, 0.6])  # every member attached again; the batch replaces it
    assert own.outcome is Outcome.SUPERSEDED
    motions = bank.motions
    assert [(m.target, m.sequence) for m in motions if m is not None] == [(0.5, 3), (0.6, 4)]
    bank.set_values_nowait([0.1, 0.2], Request.VELOCITY)  # another request: re-attached
    assert bank.get_values_nowait(Request.VELOCITY) == (0.1, 0.2)
    assert bank.get_values_nowait(Request.POSITION) == (0.5, 0.6)
    assert [m.request for m in bank.motions if m is not None] == [Request.VELOCITY] * 2
    assert all(m.outcome is Outcome.SUPERSEDED for m in motions if m is not None)


@pytest.mark.usefixtures("_batch_servos")
async def test_a_fault_reaches_the_latest_streamed_target_and_the_observers(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    events = EventRecorder(virtual_clock)
    servos = [BatchServo() for _ in range(2)]
    actuators = [await hal_components.actuator(s) for s in servos]
    for actuator in actuators:
        actuator.add_observer(events)
    bank = ActuatorBank(actuators)
    for k in range(3):
        bank.set_values_nowait([0.1 * k, 0.2 * k])
    assert servos[1].ctx is not None
    servos[1].ctx.fault(ErrorId.DEVICE_ERROR, "overcurrent")
    motion = actuators[1].motion
    assert motion is not None and motion.target == 0.4
    assert motion.outcome is Outcome.FAULTED
    assert [r.source for r in events.errors] == [actuators[1]]
    with pytest.raises(StateError):
        bank.set_values_nowait([0.0, 0.0])
    assert BatchServo.batches[-1] == (Request.POSITION, (0.2, 0.4))


async def test_sim_motors_stream_through_their_batch_and_decline_when_one_is_disconnected(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    motors = [SimMotor() for _ in range(3)]
    actuators = [
        await hal_components.actuator(m, device_name=f"M{i}") for i, m in enumerate(motors)
    ]
    bank = ActuatorBank(actuators)
    assert bank._batch is not None
    bank.set_values_nowait([0.01, 0.02, 0.03])
    final = bank.motions
    await virtual_clock.sleep(1.0)
    assert all(m is not None and m.outcome is Outcome.REACHED for m in final)
    assert [round(m.read_nowait(Request.POSITION_ACTUAL), 9) for m in motors] == [0.01, 0.02, 0.03]
    motors[2].connected = False  # the batch declines: the per-device path names M2
    with pytest.raises(DeviceFaultError) as info:
        bank.set_values_nowait([0.0, 0.0, 0.0])
    assert "M2" in str(info.value)
    assert [m.commands for m in motors] == [2, 2, 1]  # in axis order up to the fault


@pytest.mark.usefixtures("_batch_servos")
async def test_a_batch_listener_hears_each_streamed_batch_once(
    hal_components: ComponentStack,
) -> None:
    """A listener offering ``batch_listener(components)`` hears a bank's device batch in one
    call (no ``on_command`` per member); the bank asks again whenever a listener is set or
    removed anywhere: a member without a listener, or a listener without one, brings back
    the per-member calls."""
    servos = [BatchServo() for _ in range(2)]
    actuators = [
        await hal_components.actuator(s, device_name=f"Servo{i}") for i, s in enumerate(servos)
    ]
    heard: list[tuple[object, ...]] = []
    asked: list[tuple[str, ...]] = []

    class Listener:
        def __init__(self, batches: bool) -> None:
            self.batches = batches

        def on_command(self, component: object, request: Request, value: float, t: int) -> None:
            heard.append(("one", getattr(component, "device_name", ""), value))

        def on_reading(self, *args: object) -> None: ...

        def on_state(self, *args: object) -> None: ...

        def batch_listener(self, components: Sequence[object]) -> object:
            asked.append(tuple(getattr(c, "device_name", "") for c in components))
            if not self.batches or any(
                getattr(c, "listener", None) is not self for c in components
            ):
                return None  # (a tap's answer: it listens to every member, else no batch)

            def on_batch(request: Request, values: Sequence[float], t: int) -> None:
                heard.append(("batch", request, tuple(values)))

            return on_batch

    bank = ActuatorBank(actuators)
    listener = Listener(batches=True)
    actuators[0].set_listener(listener)  # type: ignore[arg-type]
    bank.set_values_nowait([0.1, 0.2])  # Servo1 has none: per member
    actuators[1].set_listener(listener)  # type: ignore[arg-type]
    bank.set_values_nowait([0.3, 0.4])
    bank.set_values_nowait([0.5, 0.6])  # asked once for both batches
    actuators[1].set_listener(None)
    actuators[1].set_listener(Listener(batches=False))  # type: ignore[arg-type]
    actuators[0].set_listener(None)
    actuators[0].set_listener(Listener(batches=False))  # type: ignore[arg-type]
    bank.set_values_nowait([0.7, 0.8])
    assert heard == [
        ("one", "Servo0", 0.1),
        ("batch", Request.POSITION, (0.3, 0.4)),
        ("batch", Request.POSITION, (0.5, 0.6)),
        ("one", "Servo0", 0.7),
        ("one", "Servo1", 0.8),
    ]
    assert asked == [("Servo0", "Servo1")] * 3
    assert [s.position for s in servos] == [0.7, 0.8]
    for actuator in actuators:
        actuator.set_listener(None)


@pytest.mark.usefixtures("_batch_servos")
async def test_a_batch_listener_hears_a_bank_read_in_one_call(
    hal_components: ComponentStack,
) -> None:
    """``get_values`` of an actual value: the members' batch listener hears the read in one
    call (the code, the values, the clock's time); without one each member's listener hears
    its value; a commanded value (POSITION) is no reading."""
    servos = [BatchServo() for _ in range(2)]
    actuators = [
        await hal_components.actuator(s, device_name=f"Servo{i}") for i, s in enumerate(servos)
    ]
    heard: list[tuple[object, ...]] = []

    class Listener:
        def __init__(self, batches: bool) -> None:
            self.batches = batches

        def on_command(self, *args: object) -> None: ...

        def on_reading(self, component: object, request: Request, values: object) -> None:
            heard.append(("one", getattr(component, "device_name", ""), request, values))

        def on_state(self, *args: object) -> None: ...

        def batch_listener(self, components: Sequence[object]) -> object:
            if not self.batches:
                return None

            def on_batch(request: Request, values: Sequence[float], t: int) -> None:
                heard.append(("batch", request, tuple(values), t))

            return on_batch

    bank = ActuatorBank(actuators)
    bank.set_values_nowait([0.1, 0.2])
    listener = Listener(batches=True)
    for actuator in actuators:
        actuator.set_listener(listener)  # type: ignore[arg-type]
    now = actuators[0].clock.now_ns()
    read = bank.get_values_nowait(Request.POSITION_ACTUAL)
    assert await bank.get_values(Request.POSITION_ACTUAL) == read
    bank.get_values_nowait(Request.POSITION)  # the commanded values: not a reading
    assert heard == [("batch", Request.POSITION_ACTUAL, read, now)] * 2
    heard.clear()
    plain = Listener(batches=False)
    for actuator in actuators:
        actuator.set_listener(None)
        actuator.set_listener(plain)  # type: ignore[arg-type]
    bank.get_values_nowait(Request.POSITION_ACTUAL)
    assert heard == [("one", f"Servo{i}", Request.POSITION_ACTUAL, (read[i],)) for i in range(2)]
    for actuator in actuators:
        actuator.set_listener(None)
