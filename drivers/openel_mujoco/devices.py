"""OpenEL device-layer classes over a :class:`~openel_mujoco.sim.MujocoSim`.

:class:`MujocoJoint` maps one hinge or slide joint to an ``ActuatorDevice`` (POSITION,
VELOCITY, TORQUE and NO_EXCITE through the joint's MuJoCo actuators, or a built-in PD
controller over its motor), :class:`MujocoSensor` maps one MuJoCo sensor to a ``SensorDevice``.
Both are created by the simulation (``sim.actuator(name)``, ``sim.sensor(name)``) and read and
write its ``MjData`` directly; the simulation loop evaluates completion, limits and saturation
after every physics step and calls back into the joints.

This module gathers the public names of the modules that implement them (and keeps the
``openel_mujoco.devices:Class`` paths of the driver's devices; names imported ``as`` themselves
are public names of this module outside ``__all__``):

* :mod:`openel_mujoco.device_base`: vendor, product and event ids (:class:`MujocoEventId`),
  product names, the actuator lifecycle shared with the effectors (``SimActuatorLifecycle``);
* :mod:`openel_mujoco.joint_actuators`: which actuators drive a joint (``resolve_actuators``);
* :mod:`openel_mujoco.joints`: :class:`MujocoJoint`;
* :mod:`openel_mujoco.joint_plans`: the joints' compiled batch commands and per-step monitor
  (``monitor_plan``, ``DRIVE_PLANS``);
* :mod:`openel_mujoco.sensors`: :class:`MujocoSensor`, the device class of each HAL4RT sensor
  kind, sensor units and kinds, the geomagnetic field.
"""

from __future__ import annotations

from .device_base import (
    EFFECTOR_PRODUCT_ID,
    JOINT_PRODUCT_ID,
    KIND_PRODUCT_IDS,
    OTHER_KIND,
    SENSOR_PRODUCT_ID,
    MujocoEventId,
)
from .device_base import (
    VENDOR_ID as VENDOR_ID,
)
from .device_base import (
    VENDOR_NAME as VENDOR_NAME,
)
from .device_base import (
    SimActuatorLifecycle as SimActuatorLifecycle,
)
from .joint_actuators import resolve_actuators as resolve_actuators
from .joint_plans import (
    DRIVE_PLANS as DRIVE_PLANS,
)
from .joint_plans import (
    FloatItems as FloatItems,
)
from .joint_plans import (
    Monitor as Monitor,
)
from .joint_plans import (
    monitor_plan as monitor_plan,
)
from .joints import MujocoJoint
from .sensors import (
    SENSOR_DEVICE_CLASSES,
    MujocoAccelerometer,
    MujocoEncoder,
    MujocoForceSensor,
    MujocoGyro,
    MujocoMagnetometer,
    MujocoSensor,
    MujocoTorqueSensor,
    geomagnetic_field_enu,
    sensor_kind,
    sensor_units,
    set_geomagnetic_field,
)
from .sensors import (
    ReadPlan as ReadPlan,
)

__all__ = [
    "EFFECTOR_PRODUCT_ID",
    "JOINT_PRODUCT_ID",
    "KIND_PRODUCT_IDS",
    "OTHER_KIND",
    "SENSOR_DEVICE_CLASSES",
    "SENSOR_PRODUCT_ID",
    "MujocoAccelerometer",
    "MujocoEncoder",
    "MujocoEventId",
    "MujocoForceSensor",
    "MujocoGyro",
    "MujocoJoint",
    "MujocoMagnetometer",
    "MujocoSensor",
    "MujocoTorqueSensor",
    "geomagnetic_field_enu",
    "sensor_kind",
    "sensor_units",
    "set_geomagnetic_field",
]
