"""Dispatch tables of the surface layer: per device kind, function_name -> operation.

A :class:`KindProfile` lists the operations of one device kind (spec §7.4.5: Motor,
sensors). A synchronous operation returns its results; an asynchronous one returns the
:class:`Motion` whose end the surface reports with ``completed``. An operation may also
have a ``run_nowait`` twin that does the same without suspending (``get_value_nowait``,
``set_value_nowait``...) for components that need no I/O; it raises WouldBlockError,
before any effect, when the component has no synchronous path. The tables take their
names, command ids, synchronous flags and arguments from the device characteristics profiles
(``device_profile``); :data:`DEFAULT_PROFILES` covers every component class: ``Actuator``
and ``Motor`` (with a ``SensingMotor``'s Sensor operations) as Motor, ``Sensor`` by its
device kind, with the GPS Sensor's and the Direction Sensor's own operations.
"""

from __future__ import annotations

import inspect
import math
import re
from collections.abc import Awaitable, Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any

from ..actuator import Actuator
from ..completion import Motion
from ..component import HALComponent
from ..device_profile import (
    COMMON_COMMANDS,
    DIRECTION_COMMANDS,
    GPS_COMMANDS,
    SENSOR_COMMANDS,
    common_name,
    motor_commands,
    sensing_commands,
)
from ..device_profile import Command as ProfileCommand
from ..direction import DirectionSensor
from ..errors import BadParameterError, NotImplementedHALError, NullParameterError, WouldBlockError
from ..gps import GPSSensor
from ..ids import DeviceKind
from ..motor import TWO_PI, Motor
from ..requests import Request
from ..sensing import SensingMotor
from ..sensor import Sensor
from .messages import (
    CommandMessage,
    DataType,
    Parameter,
    ResultList,
    results_unchecked,
    with_value,
)

SyncRun = Callable[[HALComponent, CommandMessage], Awaitable[ResultList | None]]
AsyncRun = Callable[[HALComponent, CommandMessage], Awaitable[Motion]]
NowRun = Callable[[HALComponent, CommandMessage], ResultList | Motion | None]


@dataclass(frozen=True)
class Operation:
    """One function_name of a device kind."""

    name: str
    run: SyncRun | AsyncRun
    synchronous: bool = True
    arguments: tuple[tuple[str, DataType], ...] = ()
    """The arguments it reads (name, data type), for documentation and listing."""
    description: str = ""
    run_nowait: NowRun | None = None
    """The same without suspending; WouldBlockError (nothing done) when the component
    needs I/O for it. None: the operation always suspends (Reset)."""
    command_id: int | None = None
    """The command id of the device characteristics profile (device_profile), if it has one."""


def now_and_async(now: NowRun) -> tuple[SyncRun, NowRun]:
    """An operation that never suspends, as its ``run`` and ``run_nowait``."""

    async def run(component: HALComponent, command: CommandMessage) -> Any:
        return now(component, command)

    return run, now


def _op(
    name: str,
    now: NowRun,
    synchronous: bool = True,
    arguments: tuple[tuple[str, DataType], ...] = (),
    description: str = "",
) -> Operation:
    run, nowait = now_and_async(now)
    return Operation(name, run, synchronous, arguments, description, nowait)


@dataclass(frozen=True)
class KindProfile:
    """The operations of one device kind and the component type that implements them."""

    device_kind: str
    component_type: type[HALComponent]
    operations: Mapping[str, Operation] = field(default_factory=dict)

    def operation(self, function_name: str) -> Operation:
        found = self.operations.get(function_name)
        if found is None:
            raise NotImplementedHALError(
                f"{self.device_kind} has no function {function_name!r}; "
                f"implemented: {', '.join(sorted(self.operations))}"
            )
        return found


_KIND_SEPARATORS = re.compile(r"[\s_\-]")
_NORMALIZED: dict[str, str] = {}


def normalize_kind(name: str) -> str:
    """Device kind names compare without case, spaces, '_' or '-' ('Gyro sensor' = 'GyroSensor')."""
    found = _NORMALIZED.get(name)
    if found is None:
        found = _KIND_SEPARATORS.sub("", name).lower()
        if len(_NORMALIZED) < 1024:  # names from the network: the cache stays bounded
            _NORMALIZED[name] = found
    return found


def argument(command: CommandMessage, name: str, data_type: DataType, *, required: bool = True):  # type: ignore[no-untyped-def]
    """The value of argument ``name``; NULL_PARAMETER when missing, BAD_PARAMETER when typed wrong."""
    parameter = command.argument(name)
    if parameter is None:
        if required:
            raise NullParameterError(f"{command.function_name}: argument {name!r} is missing")
        return None
    if parameter.data_type_id != data_type:
        raise BadParameterError(
            f"{name}.data_type_id", parameter.data_type_id, f"{int(data_type)} ({data_type.name})"
        )
    return parameter.value


# -- Names, ids and argument types from the device characteristics profile ---------------
_DATA_TYPE_OF: dict[str, DataType] = {
    "float": DataType.FLOAT,
    "int": DataType.INT,
    "str": DataType.STRING,
    "bool": DataType.BOOL,
    "list[float]": DataType.FLOAT_LIST,
    "list[str]": DataType.STRING_LIST,
    "MotorControlMode": DataType.INT,
}
"""The message data type of each parameter type of device_profile."""

_MOTOR_COMMANDS = {c.name: c for c in motor_commands()}
_SENSOR_COMMANDS = {c.name: c for c in SENSOR_COMMANDS}


def _declared(command: ProfileCommand) -> tuple[tuple[str, DataType], ...]:
    return tuple((p.name, _DATA_TYPE_OF[p.type]) for p in command.parameters if p.direction == "in")


def _profiled(
    command: ProfileCommand, run: SyncRun | AsyncRun, run_nowait: NowRun | None
) -> Operation:
    """The operation of a profile command: its name, id, synchronous flag and arguments."""
    return Operation(
        command.name,
        run,
        command.synchronous,
        _declared(command),
        command.description or command.method,
        run_nowait,
        command.id,
    )


def _arguments(
    command: CommandMessage, declared: tuple[tuple[str, DataType], ...], *optional: str
) -> dict[str, Any]:
    """Every declared argument, each checked against its data type (None: optional, left out)."""
    return {
        name: argument(command, name, data_type, required=name not in optional)
        for name, data_type in declared
    }


# -- Motor (an Actuator; a Motor adds its HAL4RT operations) -----------------------------
# A Motor's Set*/Get* go through its own names (scale factor and origin); a plain Actuator's
# through set_value/get_value in SI units. The run_nowait twins convert with the Motor's
# public scale factor and origin, exactly as Motor does; a Motor refusing the converted
# target gets WouldBlockError (nothing done) so that execute() answers with the Motor's
# own message, in its units.
def _per_si(motor: Motor) -> float:
    """Motor position units per rad (rotary) or per metre (linear)."""
    scale = motor.scale_factor
    return scale if motor.device.linear else scale / TWO_PI


def _motor_nowait(motor: Motor, request: Request, target: float) -> Motion:
    try:
        return motor.set_value_nowait(target, request)
    except BadParameterError as exc:
        raise WouldBlockError(
            f"{motor.device_name}: refused in SI units ({exc}); execute() tells it in the "
            "Motor's units"
        ) from None


def _tm_acc(value: float | None) -> float:
    if value is None:
        return 0.0
    if not (math.isfinite(value) and value >= 0.0):
        raise BadParameterError("tmAcc", value, "a finite number of seconds >= 0")
    return value


def _set_position() -> Operation:
    declared = _declared(_MOTOR_COMMANDS["SetPosition"])

    async def run(component: HALComponent, command: CommandMessage) -> Motion:
        position = _arguments(command, declared)["position"]
        if isinstance(component, Motor):
            return await component.set_position(position)
        assert isinstance(component, Actuator)
        return await component.set_value(position, Request.POSITION)

    def nowait(component: HALComponent, command: CommandMessage) -> Motion:
        position = _arguments(command, declared)["position"]
        if isinstance(component, Motor):
            target = position / _per_si(component) + component.origin
            return _motor_nowait(component, Request.POSITION, target)
        assert isinstance(component, Actuator)
        return component.set_value_nowait(position, Request.POSITION)

    return _profiled(_MOTOR_COMMANDS["SetPosition"], run, nowait)


def _set_speed() -> Operation:
    declared = _declared(_MOTOR_COMMANDS["SetSpeed"])

    def parse(component: HALComponent, command: CommandMessage) -> tuple[float, float]:
        values = _arguments(command, declared, "tmAcc")
        tm_acc = _tm_acc(values["tmAcc"])
        if tm_acc > 0.0 and not isinstance(component, Motor):
            raise NotImplementedHALError(
                f"SetSpeed: tmAcc > 0 needs a Motor; {component.device_name} is a plain "
                "Actuator (tmAcc 0 or left out: the device's own acceleration)"
            )
        return values["speed"], tm_acc

    async def run(component: HALComponent, command: CommandMessage) -> Motion:
        speed, tm_acc = parse(component, command)
        if isinstance(component, Motor):
            return await component.set_speed(speed, tm_acc)
        assert isinstance(component, Actuator)
        return await component.set_value(speed, Request.VELOCITY)

    def nowait(component: HALComponent, command: CommandMessage) -> Motion:
        speed, tm_acc = parse(component, command)
        if isinstance(component, Motor):
            if tm_acc > 0.0:
                raise WouldBlockError("SetSpeed with tmAcc > 0 reads the actual speed first")
            return _motor_nowait(component, Request.VELOCITY, speed / _per_si(component))
        assert isinstance(component, Actuator)
        return component.set_value_nowait(speed, Request.VELOCITY)

    return _profiled(_MOTOR_COMMANDS["SetSpeed"], run, nowait)


def _set_torque() -> Operation:
    declared = _declared(_MOTOR_COMMANDS["SetTorque"])

    async def run(component: HALComponent, command: CommandMessage) -> Motion:
        torque = _arguments(command, declared)["torque"]
        if isinstance(component, Motor):
            return await component.set_torque(torque)
        assert isinstance(component, Actuator)
        return await component.set_value(torque, Request.TORQUE)

    def nowait(component: HALComponent, command: CommandMessage) -> Motion:
        torque = _arguments(command, declared)["torque"]
        if isinstance(component, Motor):
            return _motor_nowait(component, Request.TORQUE, torque)
        assert isinstance(component, Actuator)
        return component.set_value_nowait(torque, Request.TORQUE)

    return _profiled(_MOTOR_COMMANDS["SetTorque"], run, nowait)


_MODES = "0 (READY_TO_CONTROL), 1 (POSITION), 2 (SPEED) or 3 (TORQUE)"


def _set_control_mode() -> Operation:
    declared = _declared(_MOTOR_COMMANDS["SetControlMode"])

    def plain(component: HALComponent, command: CommandMessage) -> int:
        """The mode for a plain Actuator: only 0 is set directly."""
        mode: int = _arguments(command, declared)["mode"]
        if mode not in (0, 1, 2, 3):
            raise BadParameterError("mode", mode, _MODES)
        if mode != 0:
            raise NotImplementedHALError(
                f"SetControlMode: {component.device_name} is a plain Actuator: mode {mode} is "
                "entered by SetPosition (1), SetSpeed (2) or SetTorque (3); only 0 "
                "(HALMOTOR_READY_TO_CONTROL) is set directly"
            )
        return mode

    async def run(component: HALComponent, command: CommandMessage) -> Motion:
        if isinstance(component, Motor):
            return await component.set_control_mode(_arguments(command, declared)["mode"])
        assert isinstance(component, Actuator)
        plain(component, command)
        return await component.set_value(0.0, Request.NO_EXCITE)

    def nowait(component: HALComponent, command: CommandMessage) -> Motion:
        if isinstance(component, Motor):
            raise WouldBlockError("a Motor's SetControlMode reads the actual value first")
        assert isinstance(component, Actuator)
        plain(component, command)
        return component.set_value_nowait(0.0, Request.NO_EXCITE)

    return _profiled(_MOTOR_COMMANDS["SetControlMode"], run, nowait)


def _get_control_mode(component: HALComponent, command: CommandMessage) -> ResultList:
    if isinstance(component, Motor):
        return ResultList.of(mode=int(component.get_control_mode()))
    assert isinstance(component, Actuator)
    motion = component.motion
    return ResultList.of(mode=0 if motion is None else int(motion.request))


def _get_op(name: str, request: Request, result: str) -> Operation:
    """GetPosition / GetSpeed / GetTorque: a Motor's in its units, else SI."""
    position = request is Request.POSITION_ACTUAL
    scaled = position or request is Request.VELOCITY_ACTUAL

    def motor_value(motor: Motor, raw: float) -> float:
        if position:
            return (raw - motor.origin) * _per_si(motor)
        return raw * _per_si(motor) if scaled else raw

    async def run(component: HALComponent, command: CommandMessage) -> ResultList:
        assert isinstance(component, Actuator)
        value = await component.get_value(request)
        if isinstance(component, Motor):
            value = motor_value(component, value)
        return ResultList.of(**{result: value})

    template = Parameter(DataType.FLOAT, result, 0.0)

    def nowait(component: HALComponent, command: CommandMessage) -> ResultList:
        assert isinstance(component, Actuator)
        value = component.get_value_nowait(request)
        if isinstance(component, Motor):
            value = motor_value(component, value)
        if type(value) is float:  # what the checks would pass: built without them
            return results_unchecked((with_value(template, value),))
        return ResultList.of(**{result: value})

    return _profiled(_MOTOR_COMMANDS[name], run, nowait)


def _set_motor_origin() -> Operation:
    declared = _declared(_MOTOR_COMMANDS["SetOrigin"])

    def motor(component: HALComponent, command: CommandMessage) -> tuple[Motor, float]:
        position = _arguments(command, declared, "position")["position"]
        if not isinstance(component, Motor):
            raise NotImplementedHALError(
                f"SetOrigin: {component.device_name} is a plain Actuator (no origin); a Motor has one"
            )
        return component, 0.0 if position is None else position

    async def run(component: HALComponent, command: CommandMessage) -> None:
        target, position = motor(component, command)
        await target.set_origin(position)

    def nowait(component: HALComponent, command: CommandMessage) -> None:
        motor(component, command)
        raise WouldBlockError("SetOrigin reads the actual position first")

    return _profiled(_MOTOR_COMMANDS["SetOrigin"], run, nowait)


# -- Sensors -----------------------------------------------------------------------------
async def _get_values(component: HALComponent, command: CommandMessage) -> ResultList:
    assert isinstance(component, Sensor)
    if component.device.has_time:
        timed = await component.get_timed_value()
        return ResultList.of(values=list(timed.values), time_ns=timed.time_ns)
    return ResultList.of(values=list(await component.get_value_of_measurement()))


def _get_values_nowait(component: HALComponent, command: CommandMessage) -> ResultList:
    assert isinstance(component, Sensor)
    if component.device.has_time:
        timed = component.get_timed_value_nowait()
        return ResultList.of(values=list(timed.values), time_ns=timed.time_ns)
    return ResultList.of(values=list(component.get_value_nowait()))


def _sensor_op(name: str, now: Callable[[Sensor, dict[str, Any]], ResultList | None]) -> Operation:
    """A Sensor operation that never suspends, its arguments read from the profile's."""
    profile_command = _SENSOR_COMMANDS[name]
    declared = _declared(profile_command)

    def run_now(component: HALComponent, command: CommandMessage) -> ResultList | None:
        assert isinstance(component, Sensor)
        return now(component, _arguments(command, declared))

    run, nowait = now_and_async(run_now)
    return _profiled(profile_command, run, nowait)


def _units(units: tuple[str, ...]) -> ResultList:
    return ResultList.of(units=list(units) or [""])


SENSOR_SPECIFIC = (
    _sensor_op("GetSensorKind", lambda s, a: ResultList.of(sensor_kind=s.get_sensor_kind())),
    _profiled(_SENSOR_COMMANDS["GetValueOfMeasurement"], _get_values, _get_values_nowait),
    _sensor_op("SetUnitOfMeasurement", lambda s, a: s.set_unit_of_measurement(a["units"])),
    _sensor_op("GetUnitOfMeasurement", lambda s, a: _units(s.get_unit_of_measurement())),
    _sensor_op("SetScaleFactor", lambda s, a: s.set_scale_factor(a["values"])),
    _sensor_op("GetScaleFactor", lambda s, a: ResultList.of(values=list(s.get_scale_factor()))),
    _sensor_op("SetOrigin", lambda s, a: s.set_origin(a["values"])),
)
"""The HAL4RT Sensor operations (§7.4.5.5) of every Sensor."""


# -- A SensingMotor's Sensor side (addressed as a Motor) ---------------------------------
_SENSING_COMMANDS = {c.name: c for c in sensing_commands()}


def _sensing(component: HALComponent, name: str) -> SensingMotor:
    if not isinstance(component, SensingMotor):
        raise NotImplementedHALError(
            f"{name}: {component.device_name} is a {type(component).__name__} without a "
            "sensor; a SensingMotor (psm.md §8.3) has it"
        )
    return component


def _sensing_op(
    name: str, now: Callable[[SensingMotor, dict[str, Any]], ResultList | None]
) -> Operation:
    """A SensingMotor Sensor operation that never suspends (its profile's name and id)."""
    profile_command = _SENSING_COMMANDS[name]
    declared = _declared(profile_command)

    def run_now(component: HALComponent, command: CommandMessage) -> ResultList | None:
        return now(_sensing(component, name), _arguments(command, declared))

    run, nowait = now_and_async(run_now)
    return _profiled(profile_command, run, nowait)


async def _sensing_values(component: HALComponent, command: CommandMessage) -> ResultList:
    head = _sensing(component, command.function_name)
    if head.device.has_time:
        timed = await head.get_timed_value()
        return ResultList.of(values=list(timed.values), time_ns=timed.time_ns)
    return ResultList.of(values=list(await head.get_value_of_measurement()))


def _sensing_values_nowait(component: HALComponent, command: CommandMessage) -> ResultList:
    head = _sensing(component, command.function_name)
    if head.device.has_time:
        timed = head.get_timed_value_nowait()
        return ResultList.of(values=list(timed.values), time_ns=timed.time_ns)
    return ResultList.of(values=list(head.get_value_of_measurement_nowait()))


SENSING_OPERATIONS = (
    _sensing_op("GetSensorKind", lambda h, a: ResultList.of(sensor_kind=h.get_sensor_kind())),
    _profiled(_SENSING_COMMANDS["GetValueOfMeasurement"], _sensing_values, _sensing_values_nowait),
    _sensing_op("SetUnitOfMeasurement", lambda h, a: h.set_unit_of_measurement(a["units"])),
    _sensing_op("GetUnitOfMeasurement", lambda h, a: _units(h.get_unit_of_measurement())),
    _sensing_op("SensorSetScaleFactor", lambda h, a: h.set_measurement_scale_factor(a["values"])),
    _sensing_op(
        "SensorGetScaleFactor",
        lambda h, a: ResultList.of(values=list(h.get_measurement_scale_factor())),
    ),
    _sensing_op("SensorSetOrigin", lambda h, a: h.set_measurement_origin(a["values"])),
)
"""A SensingMotor's Sensor operations under its profile's names (``SensorSetOrigin``...);
any other Motor answers them with NOT_IMPLEMENTED."""


# -- Kind operations: the GPS Sensor's and the Direction Sensor's ------------------------
def _method_op(command: ProfileCommand, component_type: type[HALComponent]) -> Operation:
    """The profile command ``command`` as a call of its method on a ``component_type``:
    the ``in`` parameters in order as arguments, the result as the ``out`` parameter.
    A component of another class answers NOT_IMPLEMENTED."""
    declared = _declared(command)
    outputs = [(p.name, _DATA_TYPE_OF[p.type]) for p in command.parameters if p.direction == "out"]
    if len(outputs) > 1:
        raise BadParameterError("command", command, "a command with at most one out parameter")
    suspends = inspect.iscoroutinefunction(getattr(component_type, command.method))

    def bound(component: HALComponent, message: CommandMessage) -> tuple[Any, list[Any]]:
        if not isinstance(component, component_type):
            raise NotImplementedHALError(
                f"{command.name}: {component.device_name} is a {type(component).__name__}; "
                f"a {component_type.__name__} has it"
            )
        values = _arguments(message, declared)
        return getattr(component, command.method), [values[name] for name, _ in declared]

    def answer(value: object) -> ResultList | None:
        if not outputs:
            return None
        name, data_type = outputs[0]
        if data_type is DataType.FLOAT:
            value = float(value)  # type: ignore[arg-type]
        return ResultList((Parameter(int(data_type), name, value),))

    if suspends:

        async def run(component: HALComponent, message: CommandMessage) -> ResultList | None:
            method, args = bound(component, message)
            return answer(await method(*args))

        return _profiled(command, run, None)

    def now(component: HALComponent, message: CommandMessage) -> ResultList | None:
        method, args = bound(component, message)
        return answer(method(*args))

    return _profiled(command, *now_and_async(now))


GPS_OPERATIONS = tuple(_method_op(c, GPSSensor) for c in GPS_COMMANDS)
"""HAL4RT's GPS Sensor operations (§7.4.5.13) and this project's (SetTarget...)."""

DIRECTION_OPERATIONS = tuple(_method_op(c, DirectionSensor) for c in DIRECTION_COMMANDS)
"""HAL4RT's Direction Sensor operations (§7.4.5.14) and GetHeading, GetMagneticHeading."""


# -- Every component ---------------------------------------------------------------------
async def _reset(component: HALComponent, command: CommandMessage) -> None:
    await component.re_init()


def _get_state(component: HALComponent, command: CommandMessage) -> ResultList:
    fault = component.last_fault
    return ResultList.of(
        state=str(component.state),
        error_id=0 if fault is None else int(fault.error_id),
        message="" if fault is None else str(fault),
    )


def _get_profile(component: HALComponent, command: CommandMessage) -> ResultList:
    hal_id = component.hal_id
    values: dict[str, object] = {
        "device_name": component.device_name,
        "device_kind_id": hal_id.device_kind_id,
        "vendor_id": hal_id.vendor_id,
        "product_id": hal_id.product_id,
        "instance_id": hal_id.instance_id,
        "has_time": component.device.has_time,
    }
    if isinstance(component, Actuator):
        limits = component.device.limits
        values["position_limits"] = [float(limits.position[0]), float(limits.position[1])]
        values["velocity_limit"] = float(limits.velocity)
        values["torque_limit"] = float(limits.torque)
        values["supported_requests"] = sorted(int(r) for r in component.device.supported_requests)
    if isinstance(component, Motor):
        values["scale_factor"] = component.scale_factor
        values["origin"] = component.origin
    if isinstance(component, Sensor):
        values["units"] = list(component.units) or [""]
    if isinstance(component, SensingMotor):
        values["sensor_units"] = list(component.sensor_units) or [""]
    return ResultList.of(**values)


def _get_time(component: HALComponent, command: CommandMessage) -> ResultList:
    return ResultList.of(time_ns=component.get_time())


_COMMON_IDS = {c.name: c.id for c in COMMON_COMMANDS}

COMMON = (
    Operation(
        "Reset",
        _reset,
        description="ReInit: leave Error and return to Active",
        command_id=_COMMON_IDS["ReInit"],
    ),
    _op("GetState", _get_state, description="state, error_id and message of the last fault"),
    replace(
        _op("GetProfile", _get_profile, description="identity, limits, units"),
        command_id=_COMMON_IDS["GetProfile"],
    ),
    replace(
        _op("GetTime", _get_time, description="the component's clock, ns"),
        command_id=_COMMON_IDS["GetTime"],
    ),
)

MOTOR_OPERATIONS = (
    _set_position(),
    _set_speed(),
    _set_torque(),
    _set_control_mode(),
    _profiled(_MOTOR_COMMANDS["GetControlMode"], *now_and_async(_get_control_mode)),
    _get_op("GetPosition", Request.POSITION_ACTUAL, "position"),
    _get_op("GetSpeed", Request.VELOCITY_ACTUAL, "speed"),
    _get_op("GetTorque", Request.TORQUE_ACTUAL, "torque"),
    _set_motor_origin(),
    *SENSING_OPERATIONS,
    *COMMON,
)

SENSOR_OPERATIONS = (*SENSOR_SPECIFIC, *COMMON)

SENSOR_KIND_NAMES: dict[int, str] = {
    DeviceKind.ROTARY_ANGLE: "Encoder",
    DeviceKind.GYRO: "GyroSensor",
    DeviceKind.ACCEL: "AccelerationSensor",
    DeviceKind.FORCE: "ForceSensor",
    DeviceKind.TORQUE: "TorqueSensor",
    DeviceKind.TEMPERATURE: "TemperatureSensor",
    DeviceKind.HUMIDITY: "HumiditySensor",
    DeviceKind.COMPASS: "DirectionSensor",
    DeviceKind.GPS: "GPSSensor",
    DeviceKind.DISTANCE: "DistanceSensor",
    DeviceKind.CO2: "CO2Sensor",
    DeviceKind.COLOR: "ColorSensor",
    DeviceKind.TOUCH: "TouchSensor",
    DeviceKind.CURRENT: "CurrentSensor",
}


def _table(operations: tuple[Operation, ...]) -> dict[str, Operation]:
    return {op.name: op for op in operations}


def _with_kind(base: tuple[Operation, ...], kind: tuple[Operation, ...]) -> dict[str, Operation]:
    """``base`` and a kind's own operations; a base operation named like one of the kind's
    (the GPS Sensor's GetTime) is renamed as in the device profile (``HalGetTime``)."""
    own = {op.name for op in kind}
    renamed = (replace(op, name=common_name(op.name)) if op.name in own else op for op in base)
    return _table((*renamed, *kind))


_KIND_TABLES: dict[str, tuple[type[HALComponent], dict[str, Operation]]] = {
    "GPSSensor": (GPSSensor, _with_kind(SENSOR_OPERATIONS, GPS_OPERATIONS)),
    "DirectionSensor": (DirectionSensor, _with_kind(SENSOR_OPERATIONS, DIRECTION_OPERATIONS)),
}

DEFAULT_PROFILES: dict[str, KindProfile] = {
    "Motor": KindProfile("Motor", Actuator, _table(MOTOR_OPERATIONS)),
    "Actuator": KindProfile("Actuator", Actuator, _table(MOTOR_OPERATIONS)),
    "Sensor": KindProfile("Sensor", Sensor, _table(SENSOR_OPERATIONS)),
    **{
        name: KindProfile(name, Sensor, _table(SENSOR_OPERATIONS))
        for name in SENSOR_KIND_NAMES.values()
    },
    **{name: KindProfile(name, cls, table) for name, (cls, table) in _KIND_TABLES.items()},
}


def kind_of(component: HALComponent) -> str:
    """The surface device kind of a plain component: Motor, Encoder, GyroSensor..."""
    if isinstance(component, Actuator):
        return "Motor" if component.hal_id.device_kind_id == DeviceKind.MOTOR else "Actuator"
    if isinstance(component, Sensor):
        return SENSOR_KIND_NAMES.get(component.hal_id.device_kind_id, "Sensor")
    raise BadParameterError("component", component, "an Actuator or a Sensor")
