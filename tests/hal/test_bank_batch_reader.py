"""SensorBank over a driver's batch reader (``SensorDevice.batch_reader``): one call per read,
one finiteness check per batch, and every fault still on its own sensor."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import ClassVar

import pytest

from openel_async import ComponentState, DeviceFaultError, ErrorId, Sensor, SensorBank, VirtualClock
from openel_async.device import BatchReader, DeviceContext, Reading, SensorDevice
from openel_async.errors import HALError, NotConnectedError, StateError
from openel_async.testing import ComponentStack, EventRecorder


class ReaderSensor(SensorDevice):
    """Two values per sensor; its driver reads a whole bank with one batch reader call."""

    units = ("V", "A")
    calls: ClassVar[list[str]] = []
    bus_up: ClassVar[bool] = True
    extra: ClassVar[float] = 0.0  # a value of the batch that belongs to no member

    def __init__(self, value: float) -> None:
        self.value = value
        self.ctx: DeviceContext | None = None

    async def open(self, ctx: DeviceContext) -> None:
        self.ctx = ctx

    async def read(self) -> Reading:
        return self.read_nowait()

    def read_nowait(self) -> Reading:
        ReaderSensor.calls.append("single")
        if not self.bus_up:
            raise NotConnectedError("sensor off the bus")
        return Reading((self.value, 2 * self.value))

    @classmethod
    def read_values_many_nowait(cls, devices: Sequence[SensorDevice]) -> list[Sequence[float]]:
        cls.calls.append("many")
        return super().read_values_many_nowait(devices)

    @classmethod
    def batch_reader(cls, devices: Sequence[SensorDevice]) -> BatchReader | None:
        members = [d for d in devices if isinstance(d, ReaderSensor)]

        def read() -> tuple[Sequence[float], tuple[tuple[float, ...], ...]]:
            cls.calls.append("batch")
            if not cls.bus_up:
                raise NotConnectedError("bus error during the batch")
            values = tuple((d.value, 2 * d.value) for d in members)
            return (*sum(values, ()), cls.extra), values

        return read


@pytest.fixture(autouse=True)
def _reset() -> None:
    ReaderSensor.calls.clear()
    ReaderSensor.bus_up = True
    ReaderSensor.extra = 0.0


async def _bank(components: ComponentStack, *values: float) -> tuple[SensorBank, list[Sensor]]:
    devices = [ReaderSensor(v) for v in values]
    sensors = [await components.sensor(d, device_name=f"Reader{i}") for i, d in enumerate(devices)]
    return SensorBank(sensors), list(sensors)


async def test_one_reader_call_per_read(hal_components: ComponentStack) -> None:
    bank, _ = await _bank(hal_components, 1.0, 2.0, 3.0)
    expected = ((1.0, 2.0), (2.0, 4.0), (3.0, 6.0))
    assert bank.get_values_nowait() == expected  # first call: members checked Active
    assert bank.get_values_nowait() == expected  # then the inline path
    assert await bank.get_values() == expected
    assert ReaderSensor.calls == ["batch"] * 3


async def test_a_non_finite_value_beside_the_members_costs_a_check_not_a_fault(
    hal_components: ComponentStack,
) -> None:
    bank, sensors = await _bank(hal_components, 1.0, 2.0)
    bank.get_values_nowait()
    ReaderSensor.extra = math.nan  # in the flat batch, in no member's values
    assert bank.get_values_nowait() == ((1.0, 2.0), (2.0, 4.0))
    assert {s.state for s in sensors} == {ComponentState.ACTIVE}


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
async def test_a_non_finite_member_value_faults_its_own_sensor(
    hal_components: ComponentStack, bad: float
) -> None:
    devices = [ReaderSensor(1.0), ReaderSensor(2.0), ReaderSensor(3.0)]
    sensors = [
        await hal_components.sensor(d, device_name=f"Reader{i}") for i, d in enumerate(devices)
    ]
    bank = SensorBank(sensors)
    bank.get_values_nowait()
    devices[1].value = bad
    with pytest.raises(DeviceFaultError, match="non-finite") as info:
        bank.get_values_nowait()
    assert "Reader1" in str(info.value) and "Reader0" not in str(info.value)
    assert [s.state for s in sensors] == [
        ComponentState.ACTIVE,
        ComponentState.ERROR,
        ComponentState.ACTIVE,
    ]


@pytest.mark.parametrize("first_call", [True, False])
async def test_a_link_fault_of_the_reader_lands_on_its_own_sensor(
    hal_components: ComponentStack, virtual_clock: VirtualClock, first_call: bool
) -> None:
    events = EventRecorder(virtual_clock)
    devices = [ReaderSensor(1.0), ReaderSensor(2.0)]
    sensors = [
        await hal_components.sensor(d, device_name=f"Reader{i}") for i, d in enumerate(devices)
    ]
    for sensor in sensors:
        sensor.add_observer(events)
    bank = SensorBank(sensors)
    if not first_call:
        bank.get_values_nowait()  # armed: the next read takes the inline path
    ReaderSensor.calls.clear()
    ReaderSensor.bus_up = False
    with pytest.raises(DeviceFaultError) as info:
        bank.get_values_nowait()
    assert isinstance(info.value.__cause__, NotConnectedError)
    assert "Reader0" in str(info.value)
    assert ReaderSensor.calls == ["batch", "single"]  # the batch failed, then one by one
    assert [s.state for s in sensors] == [ComponentState.ERROR, ComponentState.ACTIVE]
    assert [(r.kind, r.id, r.source) for r in events.records] == [
        ("error", ErrorId.DISCONNECTED, sensors[0])
    ]
    with pytest.raises(StateError):
        bank.get_values_nowait()


class ShortReaderSensor(ReaderSensor):
    short: ClassVar[bool] = False

    @classmethod
    def batch_reader(cls, devices: Sequence[SensorDevice]) -> BatchReader | None:
        def read() -> tuple[Sequence[float], tuple[tuple[float, ...], ...]]:
            if cls.short:
                return (1.0, 2.0), ((1.0, 2.0),)  # one sensor's values for a bank of two
            return (1.0, 2.0, 1.0, 2.0), ((1.0, 2.0), (1.0, 2.0))

        return read


@pytest.mark.parametrize("armed", [False, True])
async def test_a_reader_with_the_wrong_count_is_an_error(
    hal_components: ComponentStack, armed: bool
) -> None:
    sensors = [await hal_components.sensor(ShortReaderSensor(1.0)) for _ in range(2)]
    bank = SensorBank(sensors)
    ShortReaderSensor.short = False
    if armed:  # a good read first: the next one takes the inline path
        assert bank.get_values_nowait() == ((1.0, 2.0), (1.0, 2.0))
    ShortReaderSensor.short = True
    try:
        with pytest.raises(HALError, match="2 devices"):
            bank.get_values_nowait()
    finally:
        ShortReaderSensor.short = False
