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

from __future__ import annotations

from typing import TYPE_CHECKING

from openel_async.lazy import lazy_exports

if TYPE_CHECKING:
    from collections.abc import Mapping

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

DEVICE_PATHS: dict[str, str] = {
    "joint": "openel_mujoco.devices:MujocoJoint",
    "effector": "openel_mujoco.effectors:MujocoEffector",
    "sensor": "openel_mujoco.devices:MujocoSensor",
    "encoder": "openel_mujoco.devices:MujocoEncoder",
    "gyro": "openel_mujoco.devices:MujocoGyro",
    "accelerometer": "openel_mujoco.devices:MujocoAccelerometer",
    "force": "openel_mujoco.devices:MujocoForceSensor",
    "torque": "openel_mujoco.devices:MujocoTorqueSensor",
    "magnetometer": "openel_mujoco.devices:MujocoMagnetometer",
}
"""The driver's device classes by the name a rig file's ``device`` gives, as
``"module:Class"`` (imported on first use: ``openel-async devices`` and a rig without a MuJoCo
bus do not load MuJoCo)."""

# The names below load their module (and MuJoCo) on first use.
_LAZY = {
    "LockstepClock": "clock",
    "EffectorSpec": "description",
    "JointSpec": "description",
    "Pacing": "description",
    "SensorSpec": "description",
    "SimDescription": "description",
    "MujocoAccelerometer": "devices",
    "MujocoEncoder": "devices",
    "MujocoEventId": "devices",
    "MujocoForceSensor": "devices",
    "MujocoGyro": "devices",
    "MujocoJoint": "devices",
    "MujocoMagnetometer": "devices",
    "MujocoSensor": "devices",
    "MujocoTorqueSensor": "devices",
    "sensor_kind": "devices",
    "sensor_units": "devices",
    "EffectorKind": "effectors",
    "MujocoEffector": "effectors",
    "effector_kind": "effectors",
    "SHIPPED_MODELS": "models",
    "ControlMode": "models",
    "ModelLoadError": "models",
    "control_mode": "models",
    "find_id": "models",
    "load_model": "models",
    "set_control_mode": "models",
    "TrajectoryRecorder": "recorder",
    "render_snapshot": "render",
    "AttachedSimulation": "rigbus",
    "MujocoBusKind": "rigbus",
    "MujocoBusOptions": "rigbus",
    "mujoco_buses": "rigbus",
    "with_simulation": "rigbus",
    "MujocoSim": "sim",
    "PacingStats": "sim",
}


def _devices() -> Mapping[str, type]:
    from openel_async.registry import lazy_classes

    return lazy_classes(DEVICE_PATHS)


def _driver() -> DriverInfo:
    from openel_async.registry import DriverInfo, lazy_bus_kinds

    return DriverInfo(
        name="mujoco",
        description="MuJoCo physics: model joints (HAL4RT Motors) and other actuators (adhesion, "
        "tendon, site) as actuators, MuJoCo sensors as sensors: jointpos (Encoder), gyro, "
        "accelerometer, force, torque, magnetometer (Direction) and the others (lockstep or "
        "real-time pacing)",
        devices=_devices(),
        buses=lazy_bus_kinds({"mujoco": "openel_mujoco.rigbus:bus_kind"}),
    )


__getattr__, __dir__ = lazy_exports(__name__, _LAZY, {"DEVICES": _devices, "DRIVER": _driver})

__all__ = [
    "DEVICES",
    "DEVICE_PATHS",
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
