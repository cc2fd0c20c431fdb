"""HAL4RT on the MuJoCo driver: joints as Motors (control modes, set/get, origin, scale,
the native speed ramp advanced per physics step), every sensor kind MuJoCo simulates as its
HAL4RT sensor class, descriptions, device profiles and the Device Kind ID registry; all on
the lockstep clock."""

from __future__ import annotations

import math
from contextlib import AsyncExitStack
from pathlib import Path

import anyio
import mujoco
import numpy as np
import pytest

from openel_async import (
    AccelerationSensor,
    ActuatorBank,
    DeviceKind,
    DirectionSensor,
    Encoder,
    ForceSensor,
    GyroSensor,
    HALId,
    Motor,
    MotorControlMode,
    Request,
    Sensor,
    TorqueSensor,
    VirtualClock,
)
from openel_async.cli.devices_cmd import profiles_document
from openel_async.completion import Motion, Outcome
from openel_async.device_profile import profile_of
from openel_async.device_registry import DeviceRegistry, component_class
from openel_async.direction import MagneticModel
from openel_async.errors import BadParameterError, NotImplementedHALError
from openel_async.requests import EventId
from openel_async.testing import EventRecorder
from openel_mujoco import (
    DRIVER,
    MujocoAccelerometer,
    MujocoEffector,
    MujocoEncoder,
    MujocoForceSensor,
    MujocoGyro,
    MujocoJoint,
    MujocoMagnetometer,
    MujocoSensor,
    MujocoSim,
    MujocoTorqueSensor,
    SensorSpec,
    SimDescription,
)
from openel_mujoco.devices import VENDOR_ID, set_geomagnetic_field

from .conftest import MOTOR_ONLY_XML

MS = 1_000_000

SLIDE_XML = """
<mujoco model="stage">
  <option timestep="0.001" integrator="implicitfast" gravity="0 0 0"/>
  <worldbody>
    <body name="carriage">
      <joint name="rail" type="slide" axis="1 0 0" range="-0.5 0.5" damping="1"/>
      <geom type="box" size="0.05 0.05 0.02" mass="1"/>
      <site name="imu"/>
    </body>
  </worldbody>
  <actuator>
    <position name="rail_pos" joint="rail" kp="400" kv="40" group="0"/>
    <velocity name="rail_vel" joint="rail" kv="40" ctrlrange="-1 1" group="1"/>
    <motor name="rail_torque" joint="rail" ctrlrange="-50 50" group="2"/>
  </actuator>
  <sensor>
    <jointpos name="rail_pos_sensor" joint="rail"/>
    <magnetometer name="mag" site="imu"/>
  </sensor>
</mujoco>
"""


def _ramp_value(start: float, target: float, t0: int, t1: int, t: int) -> float:
    if t >= t1:
        return target
    if t <= t0:
        return start
    return start + (target - start) * ((t - t0) / (t1 - t0))


async def _done(motion: Motion) -> None:
    """A Motion's end, bounded in real time (lockstep runs the physics until then)."""
    with anyio.fail_after(20):
        await motion


async def _motor(stack: AsyncExitStack, sim: MujocoSim, joint: str, **options: float) -> Motor:
    if not sim.running:
        await stack.enter_async_context(sim)
    return await stack.enter_async_context(Motor(sim.actuator(joint), clock=sim.clock, **options))


# -- Motor: modes, commands, readings ---------------------------------------------------------


async def test_motor_modes_follow_the_commands(stack: AsyncExitStack) -> None:
    sim = MujocoSim("arm2")
    motor = await _motor(stack, sim, "shoulder")
    joint = sim.joints["shoulder"]
    assert motor.actuator_kind == DeviceKind.MOTOR
    assert motor.component_name == "HalMotorMuJoCoShoulder"
    # Wait before the first command, although the position servo holds the pose
    assert motor.get_control_mode() is MotorControlMode.READY_TO_CONTROL
    assert joint.control_mode is Request.POSITION
    await _done(await motor.set_position(0.5))
    assert motor.get_control_mode() is MotorControlMode.POSITION
    await _done(await motor.set_speed(0.4))
    assert motor.get_control_mode() is MotorControlMode.SPEED
    assert joint.control_mode is Request.VELOCITY
    await _done(await motor.set_torque(0.0))
    assert motor.get_control_mode() is MotorControlMode.TORQUE
    assert joint.control_mode is Request.TORQUE
    await motor.set_control_mode(MotorControlMode.READY_TO_CONTROL)
    assert motor.get_control_mode() is MotorControlMode.READY_TO_CONTROL
    assert joint.control_mode is Request.NO_EXCITE
    groups = [int(sim.model.actuator_group[a]) for a in joint.actuators.values()]
    disabled = int(sim.model.opt.disableactuator)
    assert all(disabled & (1 << g) for g in groups)  # every actuator of the joint disabled
    # SetControlMode(POSITION) holds where the joint is: no jump
    where = await motor.get_position()
    await motor.set_control_mode(MotorControlMode.POSITION)
    assert joint.commanded_position == pytest.approx(where, abs=1e-6)
    assert motor.get_control_mode() is MotorControlMode.POSITION


async def test_set_position_in_degrees_and_from_the_origin(stack: AsyncExitStack) -> None:
    sim = MujocoSim("arm2")
    motor = await _motor(stack, sim, "shoulder", scale_factor=360.0)
    recorder = EventRecorder(sim.clock)
    motor.add_observer(recorder)
    motion = await motor.set_position(45.0)  # degrees
    assert not motion.done()  # returns at once
    await _done(motion)
    assert recorder.count("event", EventId.COMPLETED, motor) == 1
    assert sim.joints["shoulder"].position == pytest.approx(math.pi / 4, abs=0.01)
    assert await motor.get_position() == pytest.approx(45.0, abs=0.6)
    # get_position is qpos in degrees: the device's reading, scaled
    assert await motor.get_position() == pytest.approx(
        math.degrees(sim.joints["shoulder"].position), abs=1e-9
    )
    await motor.set_origin(0.0)  # here is 0
    assert await motor.get_position() == pytest.approx(0.0, abs=1e-9)
    origin = motor.origin
    await _done(await motor.set_position(-30.0))  # 30 degrees back from the new origin
    assert sim.joints["shoulder"].commanded_position == pytest.approx(
        origin - math.radians(30.0), abs=1e-12
    )
    assert await motor.get_position() == pytest.approx(-30.0, abs=0.6)
    # speed in degrees/s
    await _done(await motor.set_speed(20.0))
    assert await motor.get_speed() == pytest.approx(20.0, abs=1.2)
    assert sim.joints["shoulder"].velocity == pytest.approx(math.radians(20.0), abs=0.02)


async def test_set_torque_and_the_actual_torque_is_qfrc_actuator(stack: AsyncExitStack) -> None:
    sim = MujocoSim("arm2")
    motor = await _motor(stack, sim, "elbow")
    await _done(await motor.set_torque(0.8))
    await sim.sleep(0.01)
    dof = sim.joints["elbow"].dof
    assert await motor.get_torque() == sim.data.qfrc_actuator[dof] == pytest.approx(0.8)
    assert motor.value_source(Request.TORQUE_ACTUAL).name == "MEASURED"
    # the torque is not scaled by the scale factor
    motor.set_scale_factor(360.0)
    assert await motor.get_torque() == sim.data.qfrc_actuator[dof]


async def test_slide_joint_is_a_linear_motor(stack: AsyncExitStack) -> None:
    sim = MujocoSim(mujoco.MjModel.from_xml_string(SLIDE_XML))
    motor = await _motor(stack, sim, "rail")
    assert sim.joints["rail"].linear and motor.scale_factor == 1.0  # 1.0 per metre
    await _done(await motor.set_position(0.2))
    assert await motor.get_position() == pytest.approx(0.2, abs=0.01)
    motor.set_scale_factor(1000.0)  # millimetres
    assert await motor.get_position() == pytest.approx(200.0, abs=10.0)
    with pytest.raises(BadParameterError) as info:
        await motor.set_position(600.0)  # the rail ends at 500 mm
    assert info.value.parameter == "position"
    assert profile_of(sim.joints["rail"]).attributes["units"]["position"] == "m"


async def test_bad_input_changes_nothing(stack: AsyncExitStack) -> None:
    sim = MujocoSim("arm2")
    motor = await _motor(stack, sim, "shoulder")
    joint = sim.joints["shoulder"]
    commands = joint.commands
    for tm_acc in (-0.1, math.nan, math.inf):
        with pytest.raises(BadParameterError) as info:
            await motor.set_speed(1.0, tm_acc)
        assert info.value.parameter == "tm_acc"
    with pytest.raises(BadParameterError) as info:
        await motor.set_speed(3.5, 0.2)  # the velocity servo's ctrlrange is +-3 rad/s
    assert info.value.parameter == "speed"
    with pytest.raises(BadParameterError) as info:
        await motor.set_control_mode(7)
    assert info.value.parameter == "mode"
    assert joint.commands == commands and not joint.ramping
    assert motor.get_control_mode() is MotorControlMode.READY_TO_CONTROL


async def test_a_joint_without_a_velocity_actuator_refuses_set_speed(
    stack: AsyncExitStack,
) -> None:
    sim = MujocoSim("arm2")
    joint = sim.actuator("shoulder", actuators={"position": "shoulder_pos"})
    assert not joint.velocity_ramp
    motor = await _motor(stack, sim, "shoulder")
    with pytest.raises(NotImplementedHALError):
        await motor.set_speed(1.0, 0.5)
    with pytest.raises(NotImplementedHALError):
        await motor.set_control_mode(MotorControlMode.TORQUE)


# -- tmAcc: the speed ramp advanced inside the lockstep loop ----------------------------------


async def _record_setpoints(sim: MujocoSim, act: int, scale: float) -> list[tuple[int, float]]:
    seen: list[tuple[int, float]] = []
    # a step hook runs after the step from the state at clock time now_ns()
    sim.add_step_hook(lambda: seen.append((sim.clock.now_ns(), float(sim.data.ctrl[act]) / scale)))
    return seen


async def test_speed_ramp_is_exact_at_every_physics_step(stack: AsyncExitStack) -> None:
    sim = MujocoSim("arm2")
    motor = await _motor(stack, sim, "shoulder")
    joint = sim.joints["shoulder"]
    act = joint.actuators["velocity"]
    await _done(await motor.set_speed(0.5))  # in SPEED mode at 0.5 rad/s
    seen = await _record_setpoints(sim, act, float(sim.model.actuator_gear[act, 0]))
    t0 = sim.clock.now_ns()
    motion = await motor.set_speed(-1.0, 0.25)
    assert joint.ramping and joint.pending and not motor.ramping  # the device's ramp
    assert motor.get_control_mode() is MotorControlMode.SPEED
    await sim.sleep(0.1)
    assert not motion.done()  # never during the ramp
    await _done(motion)
    assert motion.reached_ns is not None and motion.reached_ns >= t0 + 250 * MS
    t1 = t0 + 250 * MS
    # from the setpoint in force (0.5), not the measured velocity: no jump
    assert seen[0] == (t0, 0.5)
    for t, value in seen:
        assert value == pytest.approx(_ramp_value(0.5, -1.0, t0, t1, t), rel=0, abs=1e-12)
    assert [t for t, _ in seen] == list(range(t0, seen[-1][0] + 1, MS))
    assert seen[250] == (t1, -1.0)
    assert not joint.ramping and joint.commands == 2
    assert await motor.get_speed() == pytest.approx(-1.0, abs=0.02)


async def test_speed_ramp_from_position_mode_starts_at_the_actual_speed(
    stack: AsyncExitStack,
) -> None:
    sim = MujocoSim("arm2")
    motor = await _motor(stack, sim, "shoulder", scale_factor=360.0)
    joint = sim.joints["shoulder"]
    await _done(await motor.set_position(-60.0))
    start = joint.velocity
    t0 = sim.clock.now_ns()
    motion = await motor.set_speed(30.0, 0.5)  # deg/s, in 0.5 s
    act = joint.actuators["velocity"]
    seen = await _record_setpoints(sim, act, float(sim.model.actuator_gear[act, 0]))
    await _done(motion)
    t1 = t0 + 500 * MS
    target = math.radians(30.0)
    assert start != 0.0 and seen[0][0] == t0
    for t, value in seen:
        assert value == pytest.approx(_ramp_value(start, target, t0, t1, t), abs=1e-12)
    assert await motor.get_speed() == pytest.approx(30.0, abs=1.2)


async def test_a_command_ends_the_ramp(stack: AsyncExitStack) -> None:
    sim = MujocoSim("arm2")
    motor = await _motor(stack, sim, "shoulder")
    joint = sim.joints["shoulder"]
    ramp = await motor.set_speed(1.0, 1.0)
    await sim.sleep(0.2)
    hold = await motor.set_position(0.3)
    assert not joint.ramping and ramp.outcome is Outcome.SUPERSEDED
    await _done(hold)
    assert joint.control_mode is Request.POSITION
    # a plain velocity setpoint in the ramp's mode ends it too (and the fast path is back)
    await motor.set_speed(0.0)
    await motor.set_speed(0.8, 0.5)
    await sim.sleep(0.1)
    await motor.set_value(0.2, Request.VELOCITY)
    assert not joint.ramping
    act = joint.actuators["velocity"]
    await sim.sleep(0.05)
    assert sim.data.ctrl[act] == pytest.approx(0.2 * float(sim.model.actuator_gear[act, 0]))
    motor.set_value_nowait(0.1, Request.VELOCITY)  # one ctrl write
    assert sim.data.ctrl[act] == pytest.approx(0.1 * float(sim.model.actuator_gear[act, 0]))
    # a bank's velocity setpoints end it (the batch path declines while a ramp runs)
    await motor.set_speed(0.6, 0.5)
    await sim.sleep(0.05)
    ActuatorBank([motor]).set_values_nowait([0.3], Request.VELOCITY)
    assert not joint.ramping
    await sim.sleep(0.05)
    assert sim.data.ctrl[act] == pytest.approx(0.3 * float(sim.model.actuator_gear[act, 0]))
    # re_init-like stops end it too: finalize leaves the joint holding its position
    await motor.set_speed(0.5, 0.5)
    await motor.finalize()
    assert not joint.ramping and joint.control_mode is Request.POSITION


async def test_speed_ramp_on_the_built_in_pd(stack: AsyncExitStack) -> None:
    sim = MujocoSim(mujoco.MjModel.from_xml_string(MOTOR_ONLY_XML))
    motor = await _motor(stack, sim, "hinge")
    joint = sim.joints["hinge"]
    t0 = sim.clock.now_ns()
    motion = await motor.set_speed(1.0, 0.2)
    assert joint.uses_pd and joint.ramping
    seen: list[tuple[int, float]] = []
    sim.add_step_hook(lambda: seen.append((sim.clock.now_ns(), joint._pd_target)))
    await _done(motion)
    for t, value in seen:
        assert value == pytest.approx(_ramp_value(0.0, 1.0, t0, t0 + 200 * MS, t), abs=1e-12)
    assert joint.velocity == pytest.approx(1.0, abs=0.02)


async def _ramp_run() -> np.ndarray:
    sim = MujocoSim("arm6", keyframe="home")
    trace: list[float] = []
    async with AsyncExitStack() as stack:
        motors = [await _motor(stack, sim, j) for j in ("base_yaw", "wrist_roll")]
        sim.add_step_hook(lambda: trace.extend(sim.data.qpos.tolist()))
        await motors[0].set_speed(0.6, 0.3)
        await motors[1].set_speed(-1.0, 0.15)
        await sim.sleep(0.2)
        await motors[1].set_speed(0.5, 0.1)
        await sim.sleep(0.4)
    return np.array(trace)


async def test_ramped_runs_are_bit_identical() -> None:
    first, second = await _ramp_run(), await _ramp_run()
    assert first.size > 0 and np.array_equal(first, second)


async def test_simulation_reset_ends_the_ramp(stack: AsyncExitStack) -> None:
    sim = MujocoSim("arm2")
    motor = await _motor(stack, sim, "shoulder")
    joint = sim.joints["shoulder"]
    await motor.set_speed(1.0, 1.0)
    sim.reset()
    assert not joint.ramping and joint.control_mode is Request.POSITION
    assert sim._pre_step == []


# -- sensor kinds -------------------------------------------------------------------------------

ARM6_KINDS = [  # sensor, HAL4RT class, kind id, units
    ("imu_gyro", GyroSensor, 0x2, ("rad/s",) * 3),
    ("imu_acc", AccelerationSensor, 0x4, ("m/s^2",) * 3),
    ("wrist_force", ForceSensor, 0x7, ("N",) * 3),
    ("wrist_torque", TorqueSensor, 0x3, ("N m",) * 3),
    ("base_yaw_pos_sensor", Encoder, 0xE, ("rad",)),
    ("base_yaw_torque_sensor", TorqueSensor, 0x3, ("N m",)),
]


@pytest.mark.parametrize(("name", "cls", "kind", "units"), ARM6_KINDS)
async def test_each_sensor_kind_as_its_hal4rt_class(
    stack: AsyncExitStack, name: str, cls: type[Sensor], kind: int, units: tuple[str, ...]
) -> None:
    sim = MujocoSim("arm6", keyframe="home")
    await stack.enter_async_context(sim)
    device = sim.sensor(name)
    assert component_class(device) is cls
    sensor = await stack.enter_async_context(cls(device, clock=sim.clock))
    assert sensor.get_sensor_kind() == kind == sensor.profile_id
    assert sensor.get_unit_of_measurement() == units
    await sim.sleep(0.01)
    values = await sensor.get_value_of_measurement()
    assert values == device.values
    assert device.info.product_id == {0x2: 0x12, 0x4: 0x13, 0x7: 0x14, 0x3: 0x15, 0xE: 0x11}[kind]


async def test_units_convert_on_mujoco_sensors(stack: AsyncExitStack) -> None:
    sim = MujocoSim("arm6", keyframe="home")
    await stack.enter_async_context(sim)
    acc = await stack.enter_async_context(
        AccelerationSensor(sim.sensor("imu_acc"), clock=sim.clock)
    )
    angle = await stack.enter_async_context(
        Encoder(sim.sensor("shoulder_pitch_pos_sensor"), clock=sim.clock)
    )
    await sim.sleep(0.01)
    acc.set_unit_of_measurement(["g", "g", "g"])
    raw = sim.sensors["imu_acc"].values
    assert await acc.get_value() == pytest.approx([v / 9.80665 for v in raw], rel=1e-12)
    angle.set_unit_of_measurement(["deg"])
    (degrees,) = await angle.get_value()
    assert degrees == pytest.approx(
        math.degrees(sim.sensors["shoulder_pitch_pos_sensor"].values[0])
    )
    with pytest.raises(BadParameterError) as info:
        angle.set_unit_of_measurement(["m"])  # a length for an angle
    assert info.value.parameter == "units[0]"
    assert angle.get_unit_of_measurement() == ("deg",)


async def test_magnetometer_is_a_direction_sensor(stack: AsyncExitStack) -> None:
    model = mujoco.MjModel.from_xml_string(SLIDE_XML)
    field = MagneticModel().field(35.6812, 139.7671, 40.0, 2026.5)
    set_geomagnetic_field(model, field)
    sim = MujocoSim(model)
    await stack.enter_async_context(sim)
    device = sim.sensor("mag")
    assert device.info.kind == DeviceKind.COMPASS and device.units == ("T",) * 3
    assert component_class(device) is DirectionSensor
    compass = await stack.enter_async_context(DirectionSensor(device, clock=sim.clock))
    compass.set_latitude(35.6812)
    compass.set_longitude(139.7671)
    compass.set_altitude(40.0)
    compass.set_date(2026.5)
    await sim.sleep(0.002)
    # the site's x axis points east (world ENU): heading 90 degrees from true north
    assert await compass.get_heading() == pytest.approx(90.0, abs=1e-6)
    assert math.hypot(*(await compass.get_value())) == pytest.approx(field.f * 1e-9)


# -- descriptions ------------------------------------------------------------------------------


def test_sensor_kind_by_name_in_a_description(tmp_path: Path) -> None:
    path = tmp_path / "rig.yaml"
    path.write_text(
        "model: arm2\n"
        "sensors:\n"
        "  - imu_gyro\n"
        "  - {sensor: shoulder_pos_sensor, name: angle, kind: Encoder}\n"
        "  - {sensor: tip_pos, kind: distance}\n"
        "  - {sensor: imu_acc, kind: AccelerationSensor, units: [m/s^2, m/s^2, m/s^2]}\n"
    )
    description = SimDescription.from_yaml(path)
    kinds = [s.kind for s in description.sensors]
    assert kinds == [None, DeviceKind.ROTARY_ANGLE, DeviceKind.DISTANCE, DeviceKind.ACCEL]
    assert SimDescription.from_dict(description.to_dict()) == description
    sim = MujocoSim.from_description(description)
    assert sim.sensors["imu_gyro"].info.kind == DeviceKind.GYRO
    assert component_class(sim.sensors["angle"]) is Encoder
    assert sim.sensors["angle"].info.product_id == 0x11


@pytest.mark.parametrize("kind", ["gyroscope", "", -1, 2**32, True, 1.5, [2]])
def test_a_bad_sensor_kind_is_refused(kind: object) -> None:
    with pytest.raises(BadParameterError) as info:
        SimDescription.from_dict(
            {"model": "arm2", "sensors": [{"sensor": "imu_gyro", "kind": kind}]}
        )
    assert info.value.parameter == "kind"
    with pytest.raises(BadParameterError):
        SensorSpec("imu_gyro", kind=kind)  # type: ignore[arg-type]


# -- profiles and the registry -----------------------------------------------------------------


def test_every_mujoco_device_publishes_its_profile() -> None:
    document = profiles_document()
    assert not [k for k in document["not_registered"] if k.startswith("mujoco.")]
    devices = document["devices"]
    expected = {
        "mujoco.joint": ("Motor", 0x1, 0x1),
        "mujoco.effector": ("Motor", 0x1, 0x2),
        "mujoco.sensor": ("Kind128", 0x80, 0x10),
        "mujoco.encoder": ("Encoder", 0xE, 0x11),
        "mujoco.gyro": ("GyroSensor", 0x2, 0x12),
        "mujoco.accelerometer": ("AccelerationSensor", 0x4, 0x13),
        "mujoco.force": ("ForceSensor", 0x7, 0x14),
        "mujoco.torque": ("TorqueSensor", 0x3, 0x15),
        "mujoco.magnetometer": ("DirectionSensor", 0x5, 0x16),
    }
    for key, (kind_name, kind_id, product_id) in expected.items():
        profile = devices[key]
        assert (profile["kind_name"], profile["kind_id"], profile["product_id"]) == (
            kind_name,
            kind_id,
            product_id,
        ), key
        assert profile["vendor_id"] == VENDOR_ID and profile["vendor_name"] == "MuJoCo"
    joint = devices["mujoco.joint"]
    assert joint["attributes"]["velocity_ramp"] is True
    assert {c["name"] for c in joint["commands"]} >= {"SetSpeed", "SetControlMode", "SetOrigin"}
    assert devices["mujoco.gyro"]["attributes"]["units"] == ["rad/s"] * 3
    assert set(DRIVER.devices.values()) >= {MujocoJoint, MujocoEffector, MujocoSensor}


def test_an_instance_profile_tells_its_joint() -> None:
    sim = MujocoSim("arm2")
    profile = profile_of(sim.actuator("shoulder"))
    assert profile.component_name == "HalMotorMuJoCoShoulder"
    assert profile.attributes["velocity_limit"] == 3.0
    assert profile.attributes["supported_modes"] == [0, 1, 2, 3]
    assert profile.command("SetSpeed").supported
    limited = profile_of(sim.actuator("elbow", actuators={"position": "elbow_pos"}))
    assert not limited.command("SetSpeed").supported
    assert limited.attributes["velocity_ramp"] is False
    gyro = profile_of(sim.sensor("imu_gyro"))
    assert (gyro.kind_name, gyro.product_id) == ("GyroSensor", 0x12)


async def test_hal_create_through_the_registry(stack: AsyncExitStack) -> None:
    registry = DeviceRegistry.from_drivers()
    sim = MujocoSim("arm2")
    gyro = registry.create(HALId(DeviceKind.GYRO, VENDOR_ID, 0x12, 7), sim, "imu_gyro")
    assert isinstance(gyro, GyroSensor) and isinstance(gyro.device, MujocoGyro)
    assert sim.sensors["imu_gyro"] is gyro.device and sim.sensor("imu_gyro") is gyro.device
    motor = registry.create(HALId(DeviceKind.MOTOR, VENDOR_ID, 0x1, 3), sim, {"joint": "elbow"})
    assert isinstance(motor, Motor) and sim.joints["elbow"] is motor.device
    await stack.enter_async_context(sim)
    await stack.enter_async_context(gyro)
    await stack.enter_async_context(motor)
    assert motor.hal_id.instance_id == 3 and gyro.component_name == "HalGyroMuJoCoImuGyro"
    await _done(await motor.set_speed(1.0, 0.1))
    assert (await gyro.get_value())[2] == pytest.approx(1.0, abs=0.05)  # the elbow turns about z
    # a component's own HALId creates the same kind of device
    again = MujocoSim("arm2")
    created = registry.create_device(gyro.hal_id, again, "imu_gyro")
    assert type(created) is MujocoGyro


@pytest.mark.parametrize(
    ("cls", "sensor"),
    [
        (MujocoGyro, "imu_acc"),
        (MujocoAccelerometer, "imu_gyro"),
        (MujocoEncoder, "tip_pos"),
        (MujocoForceSensor, "imu_acc"),
        (MujocoTorqueSensor, "tip_touch"),
        (MujocoMagnetometer, "imu_gyro"),
    ],
)
def test_a_kind_class_refuses_a_sensor_of_another_kind(
    cls: type[MujocoSensor], sensor: str
) -> None:
    sim = MujocoSim("arm2")
    with pytest.raises(BadParameterError) as info:
        cls(sim, sensor)
    assert info.value.parameter == "sensor"
    assert sensor not in sim.sensors  # nothing registered on refusal


def test_a_device_cannot_be_mapped_twice() -> None:
    sim = MujocoSim("arm2")
    joint = sim.actuator("shoulder")
    mode = int(sim.model.opt.disableactuator)
    with pytest.raises(BadParameterError) as info:
        MujocoJoint(sim, {"joint": "shoulder", "name": "again", "mode": "torque"})
    assert info.value.parameter == "joint"
    assert int(sim.model.opt.disableactuator) == mode and sim.joints == {"shoulder": joint}
    sim.sensor("imu_gyro")
    with pytest.raises(BadParameterError) as info:
        MujocoGyro(sim, "imu_gyro")
    assert info.value.parameter == "name"


async def test_speed_ramp_in_realtime_pacing_follows_the_clock(stack: AsyncExitStack) -> None:
    clock = VirtualClock()
    await stack.enter_async_context(clock.autojump())
    sim = MujocoSim("arm2", pacing="realtime", clock=clock)
    motor = await _motor(stack, sim, "shoulder")
    joint = sim.joints["shoulder"]
    act = joint.actuators["velocity"]
    gear = float(sim.model.actuator_gear[act, 0])
    await clock.sleep(0.0105)  # between two physics steps
    seen: list[tuple[int, float]] = []
    # one step per wake-up at its deadline: the state stepped from is one period earlier
    sim.add_step_hook(lambda: seen.append((clock.now_ns() - MS, float(sim.data.ctrl[act]) / gear)))
    t0 = clock.now_ns()
    start = joint.velocity
    await _done(await motor.set_speed(0.7, 0.3))
    assert t0 % MS == 500_000 and seen[0][0] == t0 - 500_000
    for t, value in seen:
        assert value == pytest.approx(_ramp_value(start, 0.7, t0, t0 + 300 * MS, t), abs=1e-12)
    assert seen[-1][1] == 0.7 and sim.stats.dropped_steps == 0
