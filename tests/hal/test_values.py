"""Values from devices: what an Actuator or Sensor hands the application (issue 10).

Non-finite readings are device faults for actuators and sensors alike; sensor values are
floats; a quantity an actuator cannot measure is its estimate or the commanded value
(OpenEL 3.2 §7.4.1.7), and ``value_source`` tells which.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pytest

from openel_async import (
    Actuator,
    ActuatorBank,
    ActuatorDevice,
    BadParameterError,
    CompletionPolicy,
    ComponentState,
    DeviceFaultError,
    ErrorId,
    EventId,
    Outcome,
    Reading,
    Request,
    SensorBank,
    SensorDevice,
    ValueSource,
    VirtualClock,
)
from openel_async.testing import ComponentStack, EventRecorder

PA, VA, TA = Request.POSITION_ACTUAL, Request.VELOCITY_ACTUAL, Request.TORQUE_ACTUAL


class AsyncRegister(ActuatorDevice):
    """An actuator whose readings are whatever the test puts in ``reading`` (per code)."""

    reports_completion = True

    def __init__(self) -> None:
        self.reading: dict[Request, object] = {PA: 0.0, VA: 0.0, TA: 0.0}
        self.reads: list[Request] = []

    async def command(self, request: Request, value: float) -> None:
        pass

    async def read(self, request: Request) -> float:
        self.reads.append(request)
        return self.reading[request]  # type: ignore[return-value]


class Register(AsyncRegister):
    """The same with the synchronous path (a simulation)."""

    def command_nowait(self, request: Request, value: float) -> None:
        pass

    def read_nowait(self, request: Request) -> float:
        self.reads.append(request)
        return self.reading[request]  # type: ignore[return-value]


class OpenLoop(Register):
    """Measures position only, estimates torque (from the current), cannot tell velocity."""

    measured_requests = frozenset({PA})
    estimated_requests = frozenset({TA})


class FixedSensor(SensorDevice):
    units = ("a", "b")

    def __init__(self, values: object) -> None:
        self.values = values

    async def read(self) -> Reading:
        return self.read_nowait()

    def read_nowait(self) -> Reading:
        return Reading(self.values, 5)  # type: ignore[arg-type]


# -- point 3: a non-finite actual value is a device fault ---------------------------------


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, "1.0", None, np.float64("nan")])
@pytest.mark.parametrize("path", ["async", "nowait", "bank", "bank_async", "async_device"])
async def test_a_non_finite_actual_value_is_a_device_fault(
    hal_components: ComponentStack, virtual_clock: VirtualClock, bad: object, path: str
) -> None:
    device = AsyncRegister() if path == "async_device" else Register()
    actuator = await hal_components.actuator(device, device_name="Joint")
    events = EventRecorder(virtual_clock)
    actuator.add_observer(events)
    device.reading[VA] = bad
    with pytest.raises(DeviceFaultError, match="VELOCITY_ACTUAL") as info:
        if path == "nowait":
            actuator.get_value_nowait(VA)
        elif path == "bank":
            ActuatorBank([actuator]).get_values_nowait(VA)
        elif path == "bank_async":
            await ActuatorBank([actuator]).get_values(VA)
        else:
            await actuator.get_value(VA)
    assert "non-finite" in str(info.value) and "Joint" in str(info.value)
    assert info.value.error_id == ErrorId.DEVICE_ERROR
    assert actuator.state is ComponentState.ERROR and actuator.last_fault is info.value
    await events.wait_for("error", ErrorId.DEVICE_ERROR)


async def test_bank_faults_only_the_actuator_with_the_bad_value(
    hal_components: ComponentStack,
) -> None:
    devices = [Register(), Register(), Register()]
    actuators = [
        await hal_components.actuator(d, device_name=f"Axis{i}") for i, d in enumerate(devices)
    ]
    bank = ActuatorBank(actuators)
    devices[1].reading[PA] = math.nan
    with pytest.raises(DeviceFaultError, match="Axis1"):
        bank.get_values_nowait()
    assert [a.state for a in actuators] == [
        ComponentState.ACTIVE,
        ComponentState.ERROR,
        ComponentState.ACTIVE,
    ]


async def test_actual_values_are_floats(hal_components: ComponentStack) -> None:
    device = Register()
    actuator = await hal_components.actuator(device)
    device.reading[PA] = 2  # an int, a NumPy scalar: converted
    device.reading[VA] = np.float32(0.5)
    for value, expected in (
        (await actuator.get_value(PA), 2.0),
        (actuator.get_value_nowait(VA), 0.5),
        (ActuatorBank([actuator]).get_values_nowait(VA)[0], 0.5),
        (ActuatorBank([actuator]).get_values_nowait(PA)[0], 2.0),
    ):
        assert type(value) is float and value == expected
    assert actuator.state is ComponentState.ACTIVE


async def test_completion_watcher_faults_on_a_non_finite_reading(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    """Before, NaN never came within tolerance: the Motion stayed pending for ever."""

    class Watched(Register):
        reports_completion = False

    device = Watched()
    actuator = await hal_components.actuator(device)
    device.reading[PA] = math.nan
    motion = await actuator.set_value(0.5)
    with pytest.raises(DeviceFaultError, match="non-finite"):
        await motion
    assert motion.outcome is Outcome.FAULTED and actuator.state is ComponentState.ERROR


async def test_re_init_with_a_non_finite_position_stays_in_error(
    hal_components: ComponentStack,
) -> None:
    device = Register()
    actuator = await hal_components.actuator(device)
    device.reading[PA] = math.nan
    with pytest.raises(DeviceFaultError):
        await actuator.get_value()
    with pytest.raises(DeviceFaultError, match="POSITION_ACTUAL"):
        await actuator.re_init()  # the commanded position would be NaN
    assert actuator.state is ComponentState.ERROR
    device.reading[PA] = 0.25
    await actuator.re_init()
    assert await actuator.get_value(Request.POSITION) == 0.25


# -- point 21: sensor values are floats -----------------------------------------------------


@pytest.mark.parametrize(
    "raw",
    [(1, 2), [1, 2.5], np.array([1.0, 2.0], dtype=np.float32), (np.float64(1.0), 2), (True, 0)],
)
async def test_sensor_values_are_converted_to_float(
    hal_components: ComponentStack, raw: Sequence[float]
) -> None:
    sensor = await hal_components.sensor(FixedSensor(raw))
    expected = tuple(float(v) for v in raw)
    for values in (
        await sensor.get_value(),
        sensor.get_value_nowait(),
        (await sensor.get_timed_value()).values,
        SensorBank([sensor]).get_values_nowait()[0],
    ):
        assert values == expected and all(type(v) is float for v in values)


@pytest.mark.parametrize("raw", [("1.0", 2.0), ("ab",), None, 3.0, (1.0, None), [math.nan]])
async def test_sensor_values_that_are_not_numbers_are_a_device_fault(
    hal_components: ComponentStack, raw: object
) -> None:
    sensor = await hal_components.sensor(FixedSensor(raw))
    with pytest.raises(DeviceFaultError, match="non-numeric"):
        sensor.get_value_nowait()
    assert sensor.state is ComponentState.ERROR


# -- point 6: OpenEL §7.4.1.7, estimate or commanded value -----------------------------------


async def test_unmeasured_quantity_is_the_estimate_or_the_commanded_value(
    hal_components: ComponentStack,
) -> None:
    device = OpenLoop()
    actuator = await hal_components.actuator(device)
    device.reading[PA], device.reading[TA] = 0.1, 0.3
    device.reading[VA] = "never read"
    await actuator.set_value(1.5, Request.VELOCITY)
    assert await actuator.get_value(VA) == 1.5  # the commanded velocity
    assert actuator.get_value_nowait(VA) == 1.5
    assert await actuator.get_value(TA) == 0.3  # the device's estimate
    assert await actuator.get_value(PA) == 0.1  # measured
    assert VA not in device.reads
    assert [actuator.value_source(r) for r in (PA, VA, TA)] == [
        ValueSource.MEASURED,
        ValueSource.COMMANDED,
        ValueSource.ESTIMATED,
    ]
    assert actuator.value_source(Request.POSITION) is ValueSource.COMMANDED
    with pytest.raises(BadParameterError, match="request"):
        actuator.value_source(4)
    await actuator.set_value(0.0, Request.NO_EXCITE)
    assert await actuator.get_value(VA) == 0.0  # NO_EXCITE commands velocity 0


async def test_bank_mixes_measured_and_commanded_values(hal_components: ComponentStack) -> None:
    full, partial = Register(), OpenLoop()
    actuators = [await hal_components.actuator(d) for d in (full, partial)]
    full.reading[VA] = 0.7
    bank = ActuatorBank(actuators)
    await bank.set_values([0.2, -0.4], Request.VELOCITY)
    assert bank.get_values_nowait(VA) == (0.7, -0.4)
    assert await bank.get_values(VA) == (0.7, -0.4)
    assert VA not in partial.reads


async def test_completion_of_an_unmeasured_quantity_uses_the_commanded_value(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    """A watcher over a quantity the device cannot read compares the commanded value."""

    class Blind(OpenLoop):
        reports_completion = False

    policy = CompletionPolicy(settle_ns=20_000_000, poll_ns=5_000_000)
    actuator = await hal_components.actuator(Blind(), completion=policy)
    events = EventRecorder(virtual_clock)
    actuator.add_observer(events)
    start = virtual_clock.now_ns()
    motion = await actuator.set_value(1.0, Request.VELOCITY)
    await motion
    assert motion.reached_ns == start + policy.settle_ns
    assert events.count("event", EventId.COMPLETED) == 1


@pytest.mark.parametrize(
    ("measured", "estimated", "parameter"),
    [
        (frozenset({Request.POSITION}), frozenset(), "device.measured_requests"),
        (frozenset({PA}), frozenset({PA}), "device.estimated_requests"),
        (frozenset({PA}), {5}, "device.estimated_requests"),
        ((PA,), frozenset(), "device.measured_requests"),
    ],
)
async def test_bad_value_source_declarations_are_refused(
    measured: object, estimated: object, parameter: str
) -> None:
    device = Register()
    device.measured_requests = measured  # type: ignore[assignment]
    device.estimated_requests = estimated  # type: ignore[assignment]
    with pytest.raises(BadParameterError) as info:
        Actuator(device)
    assert info.value.parameter == parameter
