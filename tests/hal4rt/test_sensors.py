"""HAL4RT Sensor operations (§7.4.5.5) and sensor kinds (§7.4.5.6-7.4.5.12) on the virtual clock."""

from __future__ import annotations

import math

import numpy as np
import pytest

from openel_async import (
    AccelerationSensor,
    BadParameterError,
    DeviceKind,
    Encoder,
    ForceSensor,
    GyroSensor,
    HumiditySensor,
    Motor,
    NotImplementedHALError,
    Reading,
    Sensor,
    SensorBank,
    SensorDevice,
    TemperatureSensor,
    TorqueSensor,
    VirtualClock,
)
from openel_async.device import DeviceInfo
from openel_async.errors import DeviceFaultError
from openel_async.sensor_kinds import HAL4RT_KIND_NAMES, sensor_class
from openel_async.testing import ComponentStack
from openel_sim import (
    SimAccelerometer,
    SimEncoder,
    SimForceSensor,
    SimGyro,
    SimHumidity,
    SimIMU,
    SimMagnetometer,
    SimMotor,
    SimTemperature,
    SimTorqueSensor,
)


class Fixed(SensorDevice):
    """Returns the values it is given, in the units it is given."""

    info = DeviceInfo(DeviceKind.TEMPERATURE, 0x0E1, 0x7002, "Test", "Fixed")

    def __init__(self, values: tuple[float, ...], units: tuple[str, ...]) -> None:
        self.values = values
        self.units = units

    async def read(self) -> Reading:
        return self.read_nowait()

    def read_nowait(self) -> Reading:
        return Reading(self.values)


async def sensor_of(
    stack: ComponentStack, device: SensorDevice, cls: type[Sensor] = Sensor
) -> Sensor:
    return await stack.enter(cls(device, clock=stack.clock))


@pytest.mark.parametrize(
    ("si", "unit", "raw", "expected"),
    [
        ("rad", "deg", math.pi, 180.0),
        ("rad/s", "deg/s", 1.0, math.degrees(1.0)),
        ("m/s^2", "g", 9.80665, 1.0),
        ("m/s^2", "standard_gravity", 19.6133, 2.0),
        ("K", "degC", 300.0, 26.85),
        ("K", "degF", 273.15, 32.0),
        ("Pa", "hPa", 101325.0, 1013.25),
        ("T", "nT", 4.8e-5, 48000.0),
        ("N*m", "N*mm", 0.5, 500.0),
        ("percent", "dimensionless", 45.0, 0.45),
    ],
)
async def test_unit_of_measurement_converts(
    hal_components: ComponentStack, si: str, unit: str, raw: float, expected: float
) -> None:
    sensor = await sensor_of(hal_components, Fixed((raw,), (si,)))
    sensor.set_unit_of_measurement([unit])
    assert sensor.get_unit_of_measurement() == (unit,)
    assert sensor.units == (unit,)
    assert (await sensor.get_value_of_measurement())[0] == pytest.approx(expected, rel=1e-12)
    assert sensor.get_value_nowait()[0] == pytest.approx(expected, rel=1e-12)
    assert (await sensor.get_timed_value()).values[0] == pytest.approx(expected, rel=1e-12)
    sensor.set_unit_of_measurement([si])  # back to the identity: the fast path
    assert await sensor.get_value() == (raw,)


async def test_formula_of_origin_scale_and_unit(hal_components: ComponentStack) -> None:
    """value = unit(scale * (raw - origin)), per value (docs/psm.md §8.1)."""
    sensor = await sensor_of(hal_components, Fixed((310.0, 2.0, 5.0), ("K", "rad", "m")))
    sensor.set_origin([300.0, 1.0, 0.0])
    sensor.set_scale_factor([2.0, 1.0, -1.0])
    sensor.set_unit_of_measurement(["degC", "deg", "mm"])
    values = await sensor.get_value()
    assert values[0] == pytest.approx(2.0 * (310.0 - 300.0) - 273.15)
    assert values[1] == pytest.approx(math.degrees(1.0))
    assert values[2] == pytest.approx(-5000.0)
    assert sensor.get_scale_factor() == (2.0, 1.0, -1.0)
    assert sensor.get_origin() == (300.0, 1.0, 0.0)


@pytest.mark.parametrize(
    ("operation", "argument", "parameter"),
    [
        ("set_unit_of_measurement", ["m", "deg"], "units[0]"),  # metres for an angle
        ("set_unit_of_measurement", ["deg", "furlongs_per_fortnight_x"], "units[1]"),
        ("set_unit_of_measurement", ["deg"], "units"),
        ("set_unit_of_measurement", "deg", "units"),
        ("set_scale_factor", [1.0, 0.0], "values[1]"),
        ("set_scale_factor", [math.nan, 1.0], "values[0]"),
        ("set_scale_factor", [1.0], "values"),
        ("set_origin", [1.0, 2.0, 3.0], "values"),
        ("set_origin", [math.inf, 0.0], "values[0]"),
        ("set_origin", None, "values"),
    ],
)
async def test_bad_settings_are_refused_and_nothing_changes(
    hal_components: ComponentStack, operation: str, argument: object, parameter: str
) -> None:
    sensor = await sensor_of(hal_components, Fixed((1.0, 2.0), ("rad", "rad/s")))
    sensor.set_unit_of_measurement(["deg", "rad/s"])
    before = (
        sensor.units,
        sensor.get_scale_factor(),
        sensor.get_origin(),
        await sensor.get_value(),
    )
    with pytest.raises(BadParameterError) as info:
        getattr(sensor, operation)(argument)
    assert info.value.parameter == parameter
    after = (sensor.units, sensor.get_scale_factor(), sensor.get_origin(), await sensor.get_value())
    assert after == before


async def test_a_device_without_units_cannot_be_configured(hal_components: ComponentStack) -> None:
    sensor = await sensor_of(hal_components, Fixed((1.0,), ()))
    with pytest.raises(NotImplementedHALError):
        sensor.set_scale_factor([2.0])
    assert await sensor.get_value() == (1.0,)


async def test_a_reading_of_another_length_is_a_fault_once_configured(
    hal_components: ComponentStack,
) -> None:
    device = Fixed((1.0, 2.0), ("rad", "rad"))
    sensor = await sensor_of(hal_components, device)
    sensor.set_origin([1.0, 1.0])
    device.values = (1.0,)
    with pytest.raises(DeviceFaultError, match="returned 1 values"):
        await sensor.get_value()


@pytest.mark.parametrize("count", [1, 2, 3, 4])
async def test_a_converted_reading_is_checked_like_a_plain_one(
    hal_components: ComponentStack, count: int
) -> None:
    """The converted read path (length, conversion and finite check in one call) gives
    finite floats or a fault, for every unrolled value count and the general one."""
    device = Fixed((1.0,) * count, ("rad",) * count)
    sensor = await sensor_of(hal_components, device)
    sensor.set_unit_of_measurement(["deg"] * count)
    sensor.set_origin([1.0] * count)
    device.values = tuple(range(2, 2 + count))  # ints
    values = await sensor.get_value()
    assert values == pytest.approx(tuple(math.degrees(i - 1.0) for i in range(2, 2 + count)))
    device.values = tuple(np.float64(2.0) for _ in range(count))  # NumPy scalars
    for got in (await sensor.get_value(), sensor.get_value_nowait()):
        assert all(type(v) is float for v in got) and got[0] == pytest.approx(math.degrees(1.0))
    sensor.set_scale_factor([1e307] * count)
    device.values = (1e307,) * count  # finite raw values, converted past the float range
    with pytest.raises(DeviceFaultError, match="non-finite"):
        sensor.get_value_nowait()


@pytest.mark.parametrize("raw", [(math.nan, 1.0, 1.0), (1.0, "x", 1.0), (1.0, 2.0)])
async def test_a_bad_reading_is_a_fault_once_converted(
    hal_components: ComponentStack, raw: tuple[float, ...]
) -> None:
    device = Fixed((1.0, 1.0, 1.0), ("m/s^2",) * 3)
    sensor = await sensor_of(hal_components, device)
    sensor.set_unit_of_measurement(["g"] * 3)
    device.values = raw
    with pytest.raises(DeviceFaultError):
        await sensor.get_value()


async def test_sensor_bank_applies_each_sensors_settings(hal_components: ComponentStack) -> None:
    a = await sensor_of(hal_components, Fixed((300.0,), ("K",)))
    b = await sensor_of(hal_components, Fixed((math.pi,), ("rad",)))
    bank = SensorBank([a, b])
    assert bank.get_values_nowait() == ((300.0,), (math.pi,))
    b.set_unit_of_measurement(["deg"])
    values = bank.get_values_nowait()
    assert values[0] == (300.0,) and values[1][0] == pytest.approx(180.0)
    a.set_unit_of_measurement(["degC"])
    assert (await bank.get_values())[0][0] == pytest.approx(26.85)


async def test_get_sensor_kind(hal_components: ComponentStack) -> None:
    sensor = await sensor_of(hal_components, SimEncoder(SimMotor()), Encoder)
    assert sensor.get_sensor_kind() == DeviceKind.ROTARY_ANGLE == sensor.sensor_kind


@pytest.mark.parametrize(
    ("cls", "make", "units"),
    [
        (Encoder, lambda m: SimEncoder(m), ("rad",)),
        (GyroSensor, lambda m: SimGyro(m), ("rad/s",) * 3),
        (AccelerationSensor, lambda m: SimAccelerometer(m, radius=0.1), ("m/s^2",) * 3),
        (AccelerationSensor, lambda m: SimIMU(m), ("m/s^2",) * 3 + ("rad/s",) * 3),
        (ForceSensor, lambda m: SimForceSensor(m, lever_arm=0.2), ("N",)),
        (TorqueSensor, lambda m: SimTorqueSensor(m), ("N*m",)),
        (TemperatureSensor, lambda m: SimTemperature(m), ("K",)),
        (HumiditySensor, lambda m: SimHumidity(), ("percent",)),
    ],
)
async def test_every_kind_on_the_sim(
    hal_components: ComponentStack, cls: type[Sensor], make: object, units: tuple[str, ...]
) -> None:
    device = SimMotor()
    motor = await hal_components.enter(Motor(device, clock=hal_components.clock))
    sensor = await sensor_of(hal_components, make(device), cls)  # type: ignore[operator]
    assert sensor_class(sensor.get_sensor_kind()) is cls
    assert HAL4RT_KIND_NAMES[sensor.get_sensor_kind()] == cls.__name__
    assert sensor.units == units and len(await sensor.get_value()) == len(units)
    await motor.set_torque(0.5)


async def test_sim_gyro_force_torque_follow_the_motor(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    device = SimMotor()
    motor = await hal_components.enter(Motor(device, clock=virtual_clock))
    gyro = await sensor_of(hal_components, SimGyro(device), GyroSensor)
    torque = await sensor_of(hal_components, SimTorqueSensor(device), TorqueSensor)
    force = await sensor_of(hal_components, SimForceSensor(device, lever_arm=0.25), ForceSensor)
    await (await motor.set_speed(1.0))  # 1 rad/s: the default scale is 2 pi per revolution
    assert (await gyro.get_value())[2] == pytest.approx(1.0)
    await motor.set_torque(0.5)
    await virtual_clock.sleep(0.01)
    assert (await torque.get_value())[0] == pytest.approx(0.5)
    assert (await force.get_value())[0] == pytest.approx(2.0)


async def test_sim_humidity_falls_as_the_air_warms(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    same = SimTemperature(ambient=298.15)
    warmer = SimTemperature(ambient=308.15)  # 10 K above the air the humidity is given for
    await sensor_of(hal_components, same, TemperatureSensor)
    await sensor_of(hal_components, warmer, TemperatureSensor)
    at_ambient = await sensor_of(hal_components, SimHumidity(same, humidity=50.0), HumiditySensor)
    warm = await sensor_of(hal_components, SimHumidity(warmer, humidity=50.0), HumiditySensor)
    assert (await at_ambient.get_value())[0] == pytest.approx(50.0)
    assert 27.0 < (await warm.get_value())[0] < 29.0  # e_s(25 C) / e_s(35 C) = 0.565


async def test_sim_magnetometer_reads_the_field_in_the_sensor_frame(
    hal_components: ComponentStack,
) -> None:
    device = SimMotor()
    motor = await hal_components.enter(Motor(device, clock=hal_components.clock, scale_factor=360))
    magnetometer = SimMagnetometer(device, field_ned_nt=(20_000.0, 5_000.0, 40_000.0))
    compass = await sensor_of(hal_components, magnetometer)
    assert compass.get_sensor_kind() == DeviceKind.COMPASS
    compass.set_unit_of_measurement(["nT", "nT", "nT"])
    x, y, z = await compass.get_value()
    assert (x, y, z) == pytest.approx((20_000.0, 5_000.0, 40_000.0))
    declination = math.atan2(5_000.0, 20_000.0)
    await (await motor.set_position(90.0))  # yaw 90 degrees: facing east
    x, y, z = await compass.get_value()
    assert (x, y) == pytest.approx((5_000.0, -20_000.0))
    heading = math.degrees(math.atan2(-y, x) + declination)
    assert heading == pytest.approx(90.0)


async def test_kind_class_refuses_a_device_of_another_kind() -> None:
    with pytest.raises(BadParameterError) as info:
        GyroSensor(SimEncoder(SimMotor()))
    assert info.value.parameter == "device"
