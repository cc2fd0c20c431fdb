"""openel-async: the OpenEL 3.2 / HAL4RT hardware abstraction on anyio.

Components are async objects: ``await actuator.set_value(...)`` returns once the
device accepted the target, and reaching it is posted as event 1 (COMPLETED).
"""

import sys as _sys
from typing import TYPE_CHECKING

from .lazy import lazy_exports

if "structlog" in _sys.modules:  # the application uses structlog: route it to logging now,
    from . import _logging  # noqa: F401  unless it configured it (else: at the first log)
if TYPE_CHECKING:
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

# Each name loads its module on first use (PEP 562): ``import openel_async`` costs nothing,
# and a process that uses a few modules (the CLI parsing its options, the recorder's writer
# process) loads only those.
_LAZY = {
    "Actuator": "actuator",
    "CompletionPolicy": "actuator",
    "ActuatorBank": "banks",
    "SensorBank": "banks",
    "Clock": "clock",
    "MonotonicClock": "clock",
    "VirtualClock": "clock",
    "default_clock": "clock",
    "Motion": "completion",
    "Outcome": "completion",
    "ComponentState": "component",
    "HALComponent": "component",
    "ActuatorDevice": "device",
    "ActuatorLimits": "device",
    "Device": "device",
    "DeviceContext": "device",
    "DeviceInfo": "device",
    "ErrorId": "device",
    "Reading": "device",
    "SensorDevice": "device",
    "ValueSource": "device",
    "VelocityRamp": "device",
    "DirectionSensor": "direction",
    "BadParameterError": "errors",
    "DeviceFaultError": "errors",
    "HALError": "errors",
    "MotionCancelledError": "errors",
    "NotConnectedError": "errors",
    "NotImplementedHALError": "errors",
    "NullParameterError": "errors",
    "OutOfMemoryError": "errors",
    "ReturnCode": "errors",
    "StateError": "errors",
    "SupersededError": "errors",
    "VirtualClockStalledError": "errors",
    "WouldBlockError": "errors",
    "GPSSensor": "gps",
    "EXTENSION_KIND_IDS": "ids",
    "DeviceKind": "ids",
    "HALId": "ids",
    "Property": "ids",
    "component_name": "ids",
    "Motor": "motor",
    "MotorControlMode": "motor",
    "ErrorNotice": "observers",
    "EventNotice": "observers",
    "HALObserver": "observers",
    "Notice": "observers",
    "ObserverQueue": "observers",
    "TimerObserver": "observers",
    "TimerTick": "observers",
    "DriverInfo": "registry",
    "EventId": "requests",
    "Request": "requests",
    "SensingActuatorDevice": "sensing",
    "SensingMotor": "sensing",
    "Sensor": "sensor",
    "TimedValue": "sensor",
    "AccelerationSensor": "sensor_kinds",
    "Encoder": "sensor_kinds",
    "ForceSensor": "sensor_kinds",
    "GyroSensor": "sensor_kinds",
    "HumiditySensor": "sensor_kinds",
    "TemperatureSensor": "sensor_kinds",
    "TorqueSensor": "sensor_kinds",
    "EventTimer": "timer",
    "TimerState": "timer",
    "TimerStats": "timer",
}


__getattr__, __dir__ = lazy_exports(__name__, _LAZY)


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
