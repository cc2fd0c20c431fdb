"""Device characteristics profiles (HAL4RT §7.4.5.1): a device's kind, commands and
parameters with units, as data.

:func:`profile_of` builds the profile of a driver's device class (or instance) from what it
declares: ``info`` (kind, vendor, product), the kind's HAL4RT commands (Motor, Sensor, or a
kind's own), ``supported_requests``, ``limits``, ``linear``, ``velocity_ramp``, ``units``,
and the vendor functions of ``info.functions``. ``DeviceProfile.to_dict()`` is plain JSON
data: ``openel-async devices --profile`` prints it and the surface layer dispatches on it.

Command ids are this project's (HAL4RT names the commands but numbers none): 0x00xx common
to every component, 0x01xx Motor, 0x02xx Sensor, 0x03xx-0x0Fxx kind-specific (GPS,
Direction: :func:`register_kind_commands`), 0x1000 + i the device's i-th vendor function.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from .device import ActuatorDevice, Device, SensorDevice
from .errors import BadParameterError
from .ids import HALId, component_name, profile_name
from .requests import Request
from .sensor_kinds import HAL4RT_KIND_NAMES

VENDOR_COMMAND_BASE = 0x1000


@dataclass(frozen=True, slots=True)
class Parameter:
    """One argument (``in``) or result (``out``) of a command."""

    name: str
    type: str
    """``float``, ``int``, ``str``, ``bool``, ``list[float]``, ``list[str]``."""
    unit: str = ""
    """The unit of a number: SI (``rad``, ``N*m``), ``scale`` (the Motor's scale factor
    unit), ``scale/s``, ``s``, or empty for none."""
    direction: str = "in"

    def to_dict(self) -> dict[str, str]:
        return {
            "name": self.name,
            "type": self.type,
            "unit": self.unit,
            "direction": self.direction,
        }


@dataclass(frozen=True, slots=True)
class Command:
    """One command of a device kind: HAL4RT name, id, parameters, Python method."""

    name: str
    id: int
    parameters: tuple[Parameter, ...] = ()
    method: str = ""
    """The Python method of the component that runs it."""
    synchronous: bool = True
    """False: it returns a Motion whose end is event 1 (COMPLETED)."""
    supported: bool = True
    """False: the device does not implement it (HAL_NOT_IMPLEMENTED)."""
    description: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "id": self.id,
            "method": self.method,
            "synchronous": self.synchronous,
            "supported": self.supported,
            "parameters": [p.to_dict() for p in self.parameters],
            "description": self.description,
        }


def _p(name: str, type_: str, unit: str = "", direction: str = "in") -> Parameter:
    return Parameter(name, type_, unit, direction)


def _out(name: str, type_: str, unit: str = "") -> Parameter:
    return Parameter(name, type_, unit, "out")


COMMON_COMMANDS = (
    Command("Init", 0x01, (), "init", description="Initialized -> Active"),
    Command("ReInit", 0x02, (), "re_init", description="Error -> Active (HAL4RT Reset)"),
    Command("Finalize", 0x03, (), "finalize", description="-> Finalized (HAL4RT Exit)"),
    Command(
        "GetProfile", 0x04, (_out("profile", "Property"),), "get_profile", description="Property"
    ),
    Command("GetTime", 0x05, (_out("time", "int", "ns"),), "get_time"),
    Command("AddObserver", 0x06, (_p("observer", "HALObserver"),), "add_observer"),
    Command("RemoveObserver", 0x07, (_p("observer", "HALObserver"),), "remove_observer"),
)

_MOTOR_MODE = "MotorControlMode"


def motor_commands(
    supported: frozenset[Request] = frozenset(Request), linear: bool = False
) -> tuple[Command, ...]:
    """The Motor's commands (HAL4RT §7.4.5.4 and OpenEL's SetValue/GetValue)."""
    force = "N" if linear else "N*m"
    si_position = "m" if linear else "rad"
    return (
        Command("SetControlMode", 0x101, (_p("mode", _MOTOR_MODE),), "set_control_mode", False),
        Command("GetControlMode", 0x102, (_out("mode", _MOTOR_MODE),), "get_control_mode"),
        Command(
            "SetPosition",
            0x103,
            (_p("position", "float", "scale"),),
            "set_position",
            False,
            Request.POSITION in supported,
        ),
        Command(
            "SetSpeed",
            0x104,
            (_p("speed", "float", "scale/s"), _p("tmAcc", "float", "s")),
            "set_speed",
            False,
            Request.VELOCITY in supported,
        ),
        Command(
            "SetTorque",
            0x105,
            (_p("torque", "float", force),),
            "set_torque",
            False,
            Request.TORQUE in supported,
        ),
        Command("GetPosition", 0x106, (_out("position", "float", "scale"),), "get_position"),
        Command("GetSpeed", 0x107, (_out("speed", "float", "scale/s"),), "get_speed"),
        Command("GetTorque", 0x108, (_out("torque", "float", force),), "get_torque"),
        Command("SetOrigin", 0x109, (_p("position", "float", si_position),), "set_origin"),
        Command(
            "SetValue",
            0x10A,
            (_p("value", "float", "SI"), _p("command", "int")),
            "set_value",
            False,
            description="OpenEL Actuator SetValue (request codes 0-3)",
        ),
        Command(
            "GetValue",
            0x10B,
            (_p("command", "int"), _out("value", "float", "SI")),
            "get_value",
            description="OpenEL Actuator GetValue (request codes 1-3, 5-7)",
        ),
    )


SENSOR_COMMANDS = (
    Command("GetSensorKind", 0x201, (_out("sensor_kind", "int"),), "get_sensor_kind"),
    Command(
        "GetValueOfMeasurement",
        0x202,
        (_out("values", "list[float]", "units"),),
        "get_value_of_measurement",
    ),
    Command("SetUnitOfMeasurement", 0x203, (_p("units", "list[str]"),), "set_unit_of_measurement"),
    Command(
        "GetUnitOfMeasurement", 0x204, (_out("units", "list[str]"),), "get_unit_of_measurement"
    ),
    Command("SetScaleFactor", 0x205, (_p("values", "list[float]"),), "set_scale_factor"),
    Command("GetScaleFactor", 0x206, (_out("values", "list[float]"),), "get_scale_factor"),
    Command("SetOrigin", 0x207, (_p("values", "list[float]", "SI"),), "set_origin"),
    Command("GetValue", 0x208, (_out("values", "list[float]", "units"),), "get_value"),
    Command(
        "GetTimedValue",
        0x209,
        (_out("values", "list[float]", "units"), _out("time", "int", "ns")),
        "get_timed_value",
    ),
)

_RENAMED_FOR_MOTOR = {
    "SetScaleFactor": ("SensorSetScaleFactor", "set_measurement_scale_factor"),
    "GetScaleFactor": ("SensorGetScaleFactor", "get_measurement_scale_factor"),
    "SetOrigin": ("SensorSetOrigin", "set_measurement_origin"),
    "GetValue": ("", ""),  # the actuator's GetValue: the Sensor's is GetValueOfMeasurement
}


def sensing_commands() -> tuple[Command, ...]:
    """The Sensor commands of a component that is also a Motor (``SensingMotor``): the ones
    whose names clash with the Motor's are renamed (``SensorSetOrigin``...)."""
    out = []
    for command in SENSOR_COMMANDS:
        name, method = _RENAMED_FOR_MOTOR.get(command.name, (command.name, command.method))
        if name:
            out.append(Command(name, command.id, command.parameters, method, command.synchronous))
    return tuple(out)


KIND_COMMANDS: dict[int, tuple[Command, ...]] = {}
"""Kind-specific commands (GPS, Direction), added to every device of that kind."""


def register_kind_commands(kind: int, commands: tuple[Command, ...]) -> None:
    """Declare the commands of a device kind beyond Sensor's (ids 0x0300-0x0FFF)."""
    for command in commands:
        if not 0x300 <= command.id < VENDOR_COMMAND_BASE:
            raise BadParameterError("commands", command, "command ids in 0x0300..0x0FFF")
    KIND_COMMANDS[int(kind)] = tuple(commands)


@dataclass(frozen=True)
class DeviceProfile:
    """A device's characteristics profile; :meth:`to_dict` is its data form."""

    kind_id: int
    kind_name: str
    """HAL4RT's class name (Motor, Encoder, GyroSensor...), else the profile name."""
    profile_name: str
    vendor_id: int
    product_id: int
    vendor_name: str
    product_name: str
    component_name: str
    device_class: str
    role: str
    """``actuator`` or ``sensor``."""
    commands: tuple[Command, ...]
    attributes: Mapping[str, Any] = field(default_factory=dict)
    """Kind-specific data: limits, linear, velocity_ramp, units..."""

    def command(self, name_or_id: str | int) -> Command:
        for command in self.commands:
            if name_or_id in (command.name, command.id):
                return command
        raise BadParameterError("command", name_or_id, f"a command of {self.component_name}")

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind_id": self.kind_id,
            "kind_name": self.kind_name,
            "profile_name": self.profile_name,
            "vendor_id": self.vendor_id,
            "product_id": self.product_id,
            "vendor_name": self.vendor_name,
            "product_name": self.product_name,
            "component_name": self.component_name,
            "device_class": self.device_class,
            "role": self.role,
            "attributes": dict(self.attributes),
            "commands": [c.to_dict() for c in self.commands],
        }


def _number(value: float) -> float | str:
    """JSON has no infinity: unbounded limits are written as strings."""
    return value if math.isfinite(value) else ("inf" if value > 0 else "-inf")


def profile_of(device: Device | type[Device], hal_id: HALId | None = None) -> DeviceProfile:
    """The characteristics profile of a device class or instance (instance attributes,
    such as limits set by the constructor, win over the class's)."""
    cls = device if isinstance(device, type) else type(device)
    if not (isinstance(cls, type) and issubclass(cls, Device)):
        raise BadParameterError("device", device, "a Device subclass or instance")
    info = device.info
    kind = int(hal_id.device_kind_id if hal_id is not None else info.kind)
    profile = profile_name(kind)
    commands: list[Command] = list(COMMON_COMMANDS)
    attributes: dict[str, Any] = {"has_time": bool(device.has_time)}
    if issubclass(cls, ActuatorDevice):
        role = "actuator"
        supported = frozenset(device.supported_requests)  # type: ignore[union-attr]
        linear = bool(device.linear)  # type: ignore[union-attr]
        limits = device.limits  # type: ignore[union-attr]
        commands += motor_commands(supported, linear)
        attributes.update(
            linear=linear,
            velocity_ramp=bool(device.velocity_ramp),  # type: ignore[union-attr]
            reports_completion=bool(device.reports_completion),  # type: ignore[union-attr]
            supported_modes=sorted(int(r) for r in supported),
            position_limits=[_number(limits.position[0]), _number(limits.position[1])],
            velocity_limit=_number(limits.velocity),
            torque_limit=_number(limits.torque),
            units={
                "position": "m" if linear else "rad",
                "velocity": "m/s" if linear else "rad/s",
                "torque": "N" if linear else "N*m",
            },
            scale_factor_default=1.0 if linear else 2 * math.pi,
        )
        sensor_units = getattr(device, "sensor_units", None)
        if sensor_units is not None:  # also a sensor (SensingActuatorDevice)
            commands += sensing_commands()
            attributes["sensor_kind"] = int(getattr(device, "sensor_kind", 0))
            attributes["sensor_units"] = list(sensor_units)
    elif issubclass(cls, SensorDevice):
        role = "sensor"
        commands += SENSOR_COMMANDS
        attributes["units"] = list(device.units)  # type: ignore[union-attr]
    else:
        role = "device"
    commands += KIND_COMMANDS.get(kind, ())
    commands += getattr(device, "profile_commands", ())
    commands += [
        Command(name, VENDOR_COMMAND_BASE + i, (), name, description="vendor function")
        for i, name in enumerate(info.functions)
    ]
    return DeviceProfile(
        kind_id=kind,
        kind_name=HAL4RT_KIND_NAMES.get(kind, profile),
        profile_name=profile,
        vendor_id=hal_id.vendor_id if hal_id is not None else info.vendor_id,
        product_id=hal_id.product_id if hal_id is not None else info.product_id,
        vendor_name=info.vendor_name,
        product_name=info.product_name,
        component_name=component_name(profile, info.vendor_name, info.product_name),
        device_class=f"{cls.__module__}.{cls.__qualname__}",
        role=role,
        commands=tuple(commands),
        attributes=attributes,
    )
