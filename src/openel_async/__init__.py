"""openel-async: the OpenEL 3.2 / HAL4RT hardware abstraction on anyio.

Components are async objects: ``await actuator.set_value(...)`` returns once the
device accepted the target, and reaching it is posted as event 1 (COMPLETED).
"""

import sys as _sys

if "structlog" in _sys.modules:  # the application uses structlog: route it to logging now,
    from . import _logging  # noqa: F401  unless it configured it (else: at the first log)
from .actuator import Actuator, CompletionPolicy
from .banks import ActuatorBank, SensorBank
from .clock import Clock, MonotonicClock, VirtualClock, default_clock
from .completion import Motion, Outcome
from .component import ComponentState, HALComponent
from .device import (
    ActuatorDevice,
    ActuatorLimits,
    Device,
    DeviceContext,
    DeviceInfo,
    ErrorId,
    Reading,
    SensorDevice,
    ValueSource,
    VelocityRamp,
)
from .direction import DirectionSensor
from .errors import (
    BadParameterError,
    DeviceFaultError,
    HALError,
    MotionCancelledError,
    NotConnectedError,
    NotImplementedHALError,
    NullParameterError,
    OutOfMemoryError,
    ReturnCode,
    StateError,
    SupersededError,
    VirtualClockStalledError,
    WouldBlockError,
)
from .gps import GPSSensor
from .ids import EXTENSION_KIND_IDS, DeviceKind, HALId, Property, component_name
from .motor import Motor, MotorControlMode
from .observers import (
    ErrorNotice,
    EventNotice,
    HALObserver,
    Notice,
    ObserverQueue,
    TimerObserver,
    TimerTick,
)
from .registry import DriverInfo
from .requests import EventId, Request
from .sensing import SensingActuatorDevice, SensingMotor
from .sensor import Sensor, TimedValue
from .sensor_kinds import (
    AccelerationSensor,
    Encoder,
    ForceSensor,
    GyroSensor,
    HumiditySensor,
    TemperatureSensor,
    TorqueSensor,
)
from .timer import EventTimer, TimerState, TimerStats

__all__ = [
    "EXTENSION_KIND_IDS",
    "AccelerationSensor",
    "Actuator",
    "ActuatorBank",
    "ActuatorDevice",
    "ActuatorLimits",
    "BadParameterError",
    "Clock",
    "CompletionPolicy",
    "ComponentState",
    "Device",
    "DeviceContext",
    "DeviceFaultError",
    "DeviceInfo",
    "DeviceKind",
    "DirectionSensor",
    "DriverInfo",
    "Encoder",
    "ErrorId",
    "ErrorNotice",
    "EventId",
    "EventNotice",
    "EventTimer",
    "ForceSensor",
    "GPSSensor",
    "GyroSensor",
    "HALComponent",
    "HALError",
    "HALId",
    "HALObserver",
    "HumiditySensor",
    "MonotonicClock",
    "Motion",
    "MotionCancelledError",
    "Motor",
    "MotorControlMode",
    "NotConnectedError",
    "NotImplementedHALError",
    "Notice",
    "NullParameterError",
    "ObserverQueue",
    "OutOfMemoryError",
    "Outcome",
    "Property",
    "Reading",
    "Request",
    "ReturnCode",
    "SensingActuatorDevice",
    "SensingMotor",
    "Sensor",
    "SensorBank",
    "SensorDevice",
    "StateError",
    "SupersededError",
    "TemperatureSensor",
    "TimedValue",
    "TimerObserver",
    "TimerState",
    "TimerStats",
    "TimerTick",
    "TorqueSensor",
    "ValueSource",
    "VelocityRamp",
    "VirtualClock",
    "VirtualClockStalledError",
    "WouldBlockError",
    "component_name",
    "default_clock",
]
