"""Sensor.get_value/get_timed_value on the simulated sensors."""

from __future__ import annotations

import math

import pytest

from openel_async import Actuator, Request, Sensor, VirtualClock
from openel_async.testing import ComponentStack
from openel_sim import SimEncoder, SimIMU, SimMotor, SimTemperature
from openel_sim.sensors import STANDARD_GRAVITY


async def test_encoder_follows_the_motor_quantized(
    sim_actuator: Actuator, sim_encoder: Sensor, virtual_clock: VirtualClock
) -> None:
    await (await sim_actuator.set_value(1.0))
    values = await sim_encoder.get_value()
    step = 2 * math.pi / 4096
    assert len(values) == 1
    assert values[0] == pytest.approx(1.0, abs=step / 2)
    assert round(values[0] / step) * step == pytest.approx(values[0])
    timed = await sim_encoder.get_timed_value()
    assert timed.time_ns == sim_encoder.get_time() == virtual_clock.now_ns()
    assert timed.num == 1 and sim_encoder.units == ("rad",)


async def test_timed_values_are_on_the_component_clock(
    sim_encoder: Sensor, sim_imu: Sensor, virtual_clock: VirtualClock
) -> None:
    times = []
    for _ in range(5):
        await virtual_clock.sleep(0.01)
        a, b = await sim_encoder.get_timed_value(), await sim_imu.get_timed_value()
        assert a.time_ns == b.time_ns == virtual_clock.now_ns()
        times.append(a.time_ns)
    assert times == sorted(times) and len(set(times)) == 5


async def test_imu_reports_gravity_and_rotation(
    sim_actuator: Actuator, sim_imu: Sensor, virtual_clock: VirtualClock
) -> None:
    await (await sim_actuator.set_value(1.0, Request.VELOCITY))
    ax, ay, az, gx, gy, gz = await sim_imu.get_value()
    assert az == pytest.approx(STANDARD_GRAVITY)
    assert gz == pytest.approx(1.0)
    assert ax == pytest.approx(-1.0 * 0.1)  # centripetal at r = 0.1 m
    assert (ay, gx, gy) == (0.0, 0.0, 0.0)
    assert len(sim_imu.units) == 6


async def test_noise_is_reproducible_with_a_seed(hal_components: ComponentStack) -> None:
    motor = SimMotor()
    a = await hal_components.sensor(SimIMU(motor, noise=0.1, seed=3))
    b = await hal_components.sensor(SimIMU(motor, noise=0.1, seed=3))
    c = await hal_components.sensor(SimIMU(motor, noise=0.1, seed=4))
    va, vb, vc = await a.get_value(), await b.get_value(), await c.get_value()
    assert va == vb != vc
    assert va[2] != STANDARD_GRAVITY


async def test_temperature_rises_with_torque_and_cools(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    motor = SimMotor(max_torque=2.0, max_velocity=100.0, position_limits=(-1e6, 1e6))
    actuator = await hal_components.actuator(motor)
    thermo = await hal_components.sensor(SimTemperature(motor, heating=5.0, time_constant=10.0))
    (t0,) = await thermo.get_value()
    assert t0 == pytest.approx(298.15)
    await actuator.set_value(1.0, Request.TORQUE)
    await virtual_clock.sleep(5.0)
    (hot,) = await thermo.get_value()
    assert 298.15 < hot < 298.15 + 5.0
    await actuator.set_value(0.0, Request.NO_EXCITE)
    await virtual_clock.sleep(100.0)
    (cool,) = await thermo.get_value()
    assert cool == pytest.approx(298.15, abs=0.01)


def test_sensor_parameters_are_validated() -> None:
    from openel_async import BadParameterError

    with pytest.raises(BadParameterError, match="noise"):
        SimIMU(noise=-1.0)
    with pytest.raises(BadParameterError, match="counts_per_rev"):
        SimEncoder(SimMotor(), counts_per_rev=0)
    with pytest.raises(BadParameterError, match="time_constant"):
        SimTemperature(time_constant=0.0)
    with pytest.raises(BadParameterError, match="max_velocity"):
        SimMotor(max_velocity=math.nan)
    with pytest.raises(BadParameterError, match="initial_position"):
        SimMotor(initial_position=10.0)
