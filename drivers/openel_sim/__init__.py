"""openel_sim: simulated OpenEL devices in pure Python (the ``sim`` driver)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from openel_async.lazy import lazy_exports

if TYPE_CHECKING:
    from openel_async.registry import DriverInfo

    from .motor import SimMotor
    from .pan_tilt import SimPanTiltHead
    from .sensors import (
        SimAccelerometer,
        SimEncoder,
        SimForceSensor,
        SimGyro,
        SimHumidity,
        SimIMU,
        SimMagnetometer,
        SimTemperature,
        SimTorqueSensor,
    )

# The names below load their module on first use (a rig of two motors imports no sensor).
_LAZY = {
    "SimMotor": "motor",
    "SimPanTiltHead": "pan_tilt",
    "SimAccelerometer": "sensors",
    "SimEncoder": "sensors",
    "SimForceSensor": "sensors",
    "SimGyro": "sensors",
    "SimHumidity": "sensors",
    "SimIMU": "sensors",
    "SimMagnetometer": "sensors",
    "SimTemperature": "sensors",
    "SimTorqueSensor": "sensors",
}


def _driver() -> DriverInfo:
    from openel_async.registry import DriverInfo, lazy_classes

    return DriverInfo(
        name="sim",
        description="Simulated devices in pure Python: motor, pan-tilt camera head, encoder, IMU, gyro, accelerometer, "
        "force, torque, temperature, humidity, magnetometer",
        devices=lazy_classes(
            {
                "motor": "openel_sim.motor:SimMotor",
                "pan_tilt_head": "openel_sim.pan_tilt:SimPanTiltHead",
                "encoder": "openel_sim.sensors:SimEncoder",
                "imu": "openel_sim.sensors:SimIMU",
                "gyro": "openel_sim.sensors:SimGyro",
                "accelerometer": "openel_sim.sensors:SimAccelerometer",
                "force": "openel_sim.sensors:SimForceSensor",
                "torque": "openel_sim.sensors:SimTorqueSensor",
                "temperature": "openel_sim.sensors:SimTemperature",
                "humidity": "openel_sim.sensors:SimHumidity",
                "magnetometer": "openel_sim.sensors:SimMagnetometer",
            }
        ),
    )


__getattr__, __dir__ = lazy_exports(__name__, _LAZY, {"DRIVER": _driver})

__all__ = [
    "DRIVER",
    "SimAccelerometer",
    "SimEncoder",
    "SimForceSensor",
    "SimGyro",
    "SimHumidity",
    "SimIMU",
    "SimMagnetometer",
    "SimMotor",
    "SimPanTiltHead",
    "SimTemperature",
    "SimTorqueSensor",
]
