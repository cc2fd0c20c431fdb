"""openel_sim: simulated OpenEL devices in pure Python (the ``sim`` driver)."""

from openel_async.registry import DriverInfo

from .motor import SimMotor
from .sensors import SimEncoder, SimIMU, SimTemperature

DRIVER = DriverInfo(
    name="sim",
    description="Simulated devices in pure Python: motor, encoder, IMU, temperature",
    devices={
        "motor": SimMotor,
        "encoder": SimEncoder,
        "imu": SimIMU,
        "temperature": SimTemperature,
    },
)

__all__ = ["DRIVER", "SimEncoder", "SimIMU", "SimMotor", "SimTemperature"]
