"""Device characteristics profiles (HAL4RT §7.4.5.1): a device's kind, commands and
parameters with units, as data.

:func:`profile_of` builds the profile of a driver's device class (or instance) from what it
declares: ``info`` (kind, vendor, product), the kind's HAL4RT commands (Motor, Sensor, or a
kind's own), ``supported_requests``, ``limits``, ``linear``, ``velocity_ramp``, ``units``,
and the vendor functions of ``info.functions``. ``DeviceProfile.to_dict()`` is plain JSON
data: ``openel-async devices --profile`` prints it and the surface layer dispatches on it.

Command ids are this project's (HAL4RT names the commands but numbers none): 0x00xx common
to every component, 0x01xx Motor, 0x02xx Sensor, 0x03xx-0x0Fxx kind-specific
(:func:`register_kind_commands`): 0x0301-0x030B the GPS Sensor's operations and
0x0401-0x040B the Direction Sensor's, each in the order of the spec's operation table
(§7.4.5.13, §7.4.5.14), this project's extensions of a kind from 0x0381 / 0x0481; 0x1000 +
i the device's i-th vendor function. A kind command named like a common one (the GPS
Sensor's ``GetTime``, the fix time) keeps the spec's name; the common one is then listed as
``Hal`` + name (``HalGetTime``, OpenEL's C name).

The Device Characteristics Profile Definition (§7.4.5.1, "a register to have
componentName, vendorId, productId, instanceId and profileId") is each profile's instance
register: :meth:`DeviceProfile.register_instance` ... :attr:`DeviceProfile.instances`,
one :class:`ProfileInstance` per instance of the device; ``DeviceRegistry.create``
(HalCreate) registers the component it creates.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from .device import ActuatorDevice, Device, SensorDevice
from .errors import BadParameterError
from .ids import DeviceKind, HALId, check_u32, component_name, profile_name
from .requests import Request
from .sensor_kinds import HAL4RT_KIND_NAMES

if TYPE_CHECKING:
    from .component import HALComponent

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
    check_u32("kind", kind)
    names: set[str] = set()
    for command in commands:
        if not isinstance(command, Command):
            raise BadParameterError("commands", command, "a sequence of Command")
        if not 0x300 <= command.id < VENDOR_COMMAND_BASE:
            raise BadParameterError("commands", command, "command ids in 0x0300..0x0FFF")
        if command.name in names:
            raise BadParameterError("commands", command, "commands with distinct names")
        names.add(command.name)
    KIND_COMMANDS[int(kind)] = tuple(commands)


def _deg(name: str) -> Parameter:
    return _out(name, "float", "deg")


GPS_COMMANDS = (
    Command("GetLatitude", 0x301, (_deg("latitude"),), "get_latitude", description="N positive"),
    Command("GetLongitude", 0x302, (_deg("longitude"),), "get_longitude", description="E positive"),
    Command("GetAccuracy", 0x303, (_out("accuracy", "float", "m"),), "get_accuracy"),
    Command("GetDOP", 0x304, (_out("DOP", "float"),), "get_dop", description="HDOP"),
    Command(
        "GetAltitude",
        0x305,
        (_out("altitude", "float", "m"),),
        "get_altitude",
        description="above the WGS-84 ellipsoid",
    ),
    Command(
        "GetTime",
        0x306,
        (_out("time", "float", "ms"),),
        "get_fix_time",
        description="UTC time of the fix, ms since 1970-01-01",
    ),
    Command("GetSpeed", 0x307, (_out("speed", "float", "m/s"),), "get_speed"),
    Command("GetCourse", 0x308, (_deg("course"),), "get_course", description="true, [0, 360)"),
    Command(
        "GetSignalStrength",
        0x309,
        (_out("signal_strength", "float", "dB-Hz"),),
        "get_signal_strength",
    ),
    Command(
        "GetAngle",
        0x30A,
        (_deg("angle"),),
        "get_angle",
        description="heading to the SetTarget position, clockwise from true north",
    ),
    Command("SetPeriod", 0x30B, (_p("period", "float", "ms"),), "set_period"),
    Command(
        "SetTarget",
        0x381,
        (_p("latitude", "float", "deg"), _p("longitude", "float", "deg")),
        "set_target",
        description="extension: the GPS position of GetAngle and GetDistance",
    ),
    Command(
        "GetDistance",
        0x382,
        (_out("distance", "float", "m"),),
        "get_distance",
        description="extension: great-circle distance to the SetTarget position",
    ),
    Command(
        "IsStale",
        0x383,
        (_out("stale", "bool"),),
        "is_stale",
        description="extension: the receiver reports no fix now",
    ),
)
"""HAL4RT's GPS Sensor operations (§7.4.5.13), in its table's order, then extensions."""

DIRECTION_COMMANDS = (
    Command("SetLatitude", 0x401, (_p("latitude", "float", "deg"),), "set_latitude"),
    Command("SetLongitude", 0x402, (_p("longitude", "float", "deg"),), "set_longitude"),
    Command(
        "SetAltitude",
        0x403,
        (_p("altitude", "float", "m"),),
        "set_altitude",
        description="above the WGS-84 ellipsoid",
    ),
    Command("SetDate", 0x404, (_p("date", "float", "year"),), "set_date", description="decimal"),
    Command("GetF", 0x405, (_out("F", "float", "nT"),), "get_f", description="total intensity"),
    Command("GetH", 0x406, (_out("H", "float", "nT"),), "get_h", description="horizontal"),
    Command("GetX", 0x407, (_out("X", "float", "nT"),), "get_x", description="north component"),
    Command("GetY", 0x408, (_out("Y", "float", "nT"),), "get_y", description="east component"),
    Command("GetZ", 0x409, (_out("Z", "float", "nT"),), "get_z", description="down component"),
    Command("GetI", 0x40A, (_deg("I"),), "get_i", description="inclination, down positive"),
    Command("GetD", 0x40B, (_deg("D"),), "get_d", description="declination, east positive"),
    Command(
        "GetHeading",
        0x481,
        (_deg("heading"),),
        "get_heading",
        description="extension: heading from true north of a level magnetometer",
    ),
    Command(
        "GetMagneticHeading",
        0x482,
        (_deg("heading"),),
        "get_magnetic_heading",
        description="extension: heading from magnetic north",
    ),
)
"""HAL4RT's Direction Sensor operations (§7.4.5.14), in its table's order, then extensions."""

register_kind_commands(DeviceKind.GPS, GPS_COMMANDS)
register_kind_commands(DeviceKind.COMPASS, DIRECTION_COMMANDS)


def common_name(name: str) -> str:
    """The name of a common command in a kind that has its own command of that name."""
    return f"Hal{name}"


@dataclass(frozen=True, slots=True)
class ProfileInstance:
    """One entry of the Device Characteristics Profile Definition (§7.4.5.1): an instance
    of the profile's device, by the five attributes the spec lists."""

    component_name: str
    vendor_id: int
    product_id: int
    instance_id: int
    profile_id: int

    def __post_init__(self) -> None:
        if not isinstance(self.component_name, str) or not self.component_name:
            raise BadParameterError("component_name", self.component_name, "a non-empty string")
        for name in ("vendor_id", "product_id", "instance_id", "profile_id"):
            check_u32(name, getattr(self, name))

    @classmethod
    def of(cls, component: HALComponent) -> ProfileInstance:
        """The entry of a component (its ``component_name`` and ``hal_id``)."""
        hal_id = getattr(component, "hal_id", None)
        name = getattr(component, "component_name", None)
        if not isinstance(hal_id, HALId) or not isinstance(name, str):
            raise BadParameterError("component", component, "a HALComponent")
        return cls(
            name, hal_id.vendor_id, hal_id.product_id, hal_id.instance_id, hal_id.device_kind_id
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "component_name": self.component_name,
            "vendor_id": self.vendor_id,
            "product_id": self.product_id,
            "instance_id": self.instance_id,
            "profile_id": self.profile_id,
        }


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
    _instances: dict[int, ProfileInstance] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )

    def command(self, name_or_id: str | int) -> Command:
        for command in self.commands:
            if name_or_id in (command.name, command.id):
                return command
        raise BadParameterError("command", name_or_id, f"a command of {self.component_name}")

    # -- the Device Characteristics Profile Definition: the instance register -------------
    @property
    def instances(self) -> tuple[ProfileInstance, ...]:
        """Every registered instance, by instance id."""
        return tuple(self._instances[i] for i in sorted(self._instances))

    def register_instance(self, instance: ProfileInstance | HALComponent) -> ProfileInstance:
        """Register an instance of this profile's device (a ``ProfileInstance``, or a
        component whose ``hal_id`` and ``component_name`` give it).

        BadParameterError naming ``instance`` when its profile id, vendor id or product id
        are not this profile's, naming ``instance_id`` when another instance has that id
        (registering the same entry again is allowed and changes nothing).
        """
        entry = instance if isinstance(instance, ProfileInstance) else ProfileInstance.of(instance)
        key = (entry.profile_id, entry.vendor_id, entry.product_id)
        mine = (self.kind_id, self.vendor_id, self.product_id)
        if key != mine:
            raise BadParameterError(
                "instance",
                instance,
                f"an instance of {self.profile_name} (profile id 0x{mine[0]:X}, vendor id "
                f"0x{mine[1]:X}, product id 0x{mine[2]:X}); it has 0x{key[0]:X}, "
                f"0x{key[1]:X}, 0x{key[2]:X}",
            )
        existing = self._instances.get(entry.instance_id)
        if existing is not None and existing != entry:
            raise BadParameterError(
                "instance_id",
                entry.instance_id,
                f"an instance id not yet registered for {self.profile_name}: it is "
                f"{existing.component_name!r}'s",
            )
        self._instances[entry.instance_id] = entry
        return entry

    def unregister_instance(self, instance_id: int) -> ProfileInstance:
        """Remove the instance ``instance_id`` from the register; returns its entry."""
        entry = self.instance(instance_id)
        del self._instances[entry.instance_id]
        return entry

    def instance(self, instance_id: int) -> ProfileInstance:
        """The registered instance ``instance_id``; BadParameterError when there is none."""
        entry = None if isinstance(instance_id, bool) else self._instances.get(instance_id)
        if entry is None:
            registered = sorted(self._instances) or "none"
            raise BadParameterError(
                "instance_id", instance_id, f"a registered instance id ({registered})"
            )
        return entry

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
            "instances": [i.to_dict() for i in self.instances],
        }


def _renamed(command: Command, name: str) -> Command:
    return Command(
        name,
        command.id,
        command.parameters,
        command.method,
        command.synchronous,
        command.supported,
        command.description,
    )


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
    kind_commands = KIND_COMMANDS.get(kind, ())
    own = {c.name for c in kind_commands}
    commands = [_renamed(c, common_name(c.name)) if c.name in own else c for c in commands]
    commands += kind_commands
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
