"""openel_mujoco: MuJoCo physics as an OpenEL device layer (the ``mujoco`` driver).

Build a simulation, take its joints and sensors as devices, wrap them in components on the
simulation's clock, and run the simulation while the application runs (actuators that do not
drive one joint, such as a suction cup or a tendon gripper, are ``sim.effector(name)``)::

    sim = MujocoSim("arm2")                               # lockstep pacing by default
    async with sim, Actuator(sim.actuator("shoulder"), clock=sim.clock) as shoulder, \\
            Sensor(sim.sensor("imu_gyro"), clock=sim.clock) as gyro:
        await (await shoulder.set_value(1.0))             # COMPLETED from the physics
        print(await gyro.get_timed_value())

See ``docs/mujoco.md`` for the mapping description, pacing modes, events and instability.
"""

from openel_async.registry import DriverInfo

from .clock import LockstepClock
from .description import EffectorSpec, JointSpec, Pacing, SensorSpec, SimDescription
from .devices import (
    MujocoAccelerometer,
    MujocoEncoder,
    MujocoEventId,
    MujocoForceSensor,
    MujocoGyro,
    MujocoJoint,
    MujocoMagnetometer,
    MujocoSensor,
    MujocoTorqueSensor,
    sensor_kind,
    sensor_units,
)
from .effectors import EffectorKind, MujocoEffector, effector_kind
from .models import (
    SHIPPED_MODELS,
    ControlMode,
    ModelLoadError,
    control_mode,
    find_id,
    load_model,
    set_control_mode,
)
from .recorder import TrajectoryRecorder
from .render import render_snapshot
from .rigbus import (
    AttachedSimulation,
    MujocoBusKind,
    MujocoBusOptions,
    mujoco_buses,
    with_simulation,
)
from .sim import MujocoSim, PacingStats

DEVICES: dict[str, type] = {
    "joint": MujocoJoint,
    "effector": MujocoEffector,
    "sensor": MujocoSensor,
    "encoder": MujocoEncoder,
    "gyro": MujocoGyro,
    "accelerometer": MujocoAccelerometer,
    "force": MujocoForceSensor,
    "torque": MujocoTorqueSensor,
    "magnetometer": MujocoMagnetometer,
}
"""The driver's device classes by the name a rig file's ``device`` gives."""

DRIVER = DriverInfo(
    name="mujoco",
    description="MuJoCo physics: model joints (HAL4RT Motors) and other actuators (adhesion, "
    "tendon, site) as actuators, MuJoCo sensors as sensors: jointpos (Encoder), gyro, "
    "accelerometer, force, torque, magnetometer (Direction) and the others (lockstep or "
    "real-time pacing)",
    devices=DEVICES,
    buses={"mujoco": MujocoBusKind(DEVICES)},
)

__all__ = [
    "DEVICES",
    "DRIVER",
    "SHIPPED_MODELS",
    "AttachedSimulation",
    "ControlMode",
    "EffectorKind",
    "EffectorSpec",
    "JointSpec",
    "LockstepClock",
    "ModelLoadError",
    "MujocoAccelerometer",
    "MujocoBusKind",
    "MujocoBusOptions",
    "MujocoEffector",
    "MujocoEncoder",
    "MujocoEventId",
    "MujocoForceSensor",
    "MujocoGyro",
    "MujocoJoint",
    "MujocoMagnetometer",
    "MujocoSensor",
    "MujocoSim",
    "MujocoTorqueSensor",
    "Pacing",
    "PacingStats",
    "SensorSpec",
    "SimDescription",
    "TrajectoryRecorder",
    "control_mode",
    "effector_kind",
    "find_id",
    "load_model",
    "mujoco_buses",
    "render_snapshot",
    "sensor_kind",
    "sensor_units",
    "set_control_mode",
    "with_simulation",
]
