"""openel_sim: simulated OpenEL devices in pure Python (the ``sim`` driver)."""

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

DRIVER = DriverInfo(
    name="sim",
    description="Simulated devices in pure Python: motor, pan-tilt camera head, encoder, IMU, gyro, accelerometer, "
    "force, torque, temperature, humidity, magnetometer",
    devices={
        "motor": SimMotor,
        "pan_tilt_head": SimPanTiltHead,
        "encoder": SimEncoder,
        "imu": SimIMU,
        "gyro": SimGyro,
        "accelerometer": SimAccelerometer,
        "force": SimForceSensor,
        "torque": SimTorqueSensor,
        "temperature": SimTemperature,
        "humidity": SimHumidity,
        "magnetometer": SimMagnetometer,
    },
)

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
