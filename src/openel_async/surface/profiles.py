"""Dispatch tables of the surface layer: per device kind, function_name -> operation.

A :class:`KindProfile` lists the operations of one device kind (spec §7.4.5: Motor,
sensors). A synchronous operation returns its results; an asynchronous one returns the
:class:`Motion` whose end the surface reports with ``completed``. Device characteristics
profiles can later build such tables from their own definitions; :data:`DEFAULT_PROFILES`
covers the plain components (``Actuator`` as Motor, ``Sensor`` by its device kind).
"""

from __future__ import annotations

import re
from collections.abc import Awaitable, Callable, Mapping
from dataclasses import dataclass, field

from ..actuator import Actuator
from ..completion import Motion
from ..component import HALComponent
from ..errors import BadParameterError, NotImplementedHALError, NullParameterError
from ..ids import DeviceKind
from ..requests import Request
from ..sensor import Sensor
from .messages import CommandMessage, DataType, ResultList

SyncRun = Callable[[HALComponent, CommandMessage], Awaitable[ResultList | None]]
AsyncRun = Callable[[HALComponent, CommandMessage], Awaitable[Motion]]


@dataclass(frozen=True)
class Operation:
    """One function_name of a device kind."""

    name: str
    run: SyncRun | AsyncRun
    synchronous: bool = True
    arguments: tuple[tuple[str, DataType], ...] = ()
    """The arguments it reads (name, data type), for documentation and listing."""
    description: str = ""


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


def normalize_kind(name: str) -> str:
    """Device kind names compare without case, spaces, '_' or '-' ('Gyro sensor' = 'GyroSensor')."""
    return re.sub(r"[\s_\-]", "", name).lower()


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


# -- Motor (an Actuator) ---------------------------------------------------------------
def _set(request: Request, name: str) -> AsyncRun:
    async def run(component: HALComponent, command: CommandMessage) -> Motion:
        assert isinstance(component, Actuator)
        value = argument(command, name, DataType.FLOAT)
        return await component.set_value(value, request)

    return run


async def _set_speed(component: HALComponent, command: CommandMessage) -> Motion:
    assert isinstance(component, Actuator)
    speed = argument(command, "speed", DataType.FLOAT)
    if argument(command, "tmAcc", DataType.FLOAT, required=False) is not None:
        raise NotImplementedHALError(
            "SetSpeed: tmAcc is not supported (the device ramps at its own acceleration limit)"
        )
    return await component.set_value(speed, Request.VELOCITY)


async def _set_control_mode(component: HALComponent, command: CommandMessage) -> Motion:
    assert isinstance(component, Actuator)
    mode = argument(command, "mode", DataType.INT)
    if mode != 0:
        raise NotImplementedHALError(
            f"SetControlMode: mode {mode} is entered by SetPosition (1), SetSpeed (2) or "
            "SetTorque (3); only 0 (HALMOTOR_READY_TO_CONTROL) is set directly"
        )
    return await component.set_value(0.0, Request.NO_EXCITE)


async def _get_control_mode(component: HALComponent, command: CommandMessage) -> ResultList:
    assert isinstance(component, Actuator)
    motion = component.motion
    return ResultList.of(mode=0 if motion is None else int(motion.request))


def _get(request: Request, name: str) -> SyncRun:
    async def run(component: HALComponent, command: CommandMessage) -> ResultList:
        assert isinstance(component, Actuator)
        return ResultList.of(**{name: await component.get_value(request)})

    return run


# -- Sensors -----------------------------------------------------------------------------
async def _get_values(component: HALComponent, command: CommandMessage) -> ResultList:
    assert isinstance(component, Sensor)
    if component.device.has_time:
        timed = await component.get_timed_value()
        return ResultList.of(values=list(timed.values), time_ns=timed.time_ns)
    return ResultList.of(values=list(await component.get_value()))


async def _get_units(component: HALComponent, command: CommandMessage) -> ResultList:
    assert isinstance(component, Sensor)
    return ResultList.of(units=list(component.units) or [""])


async def _get_kind(component: HALComponent, command: CommandMessage) -> ResultList:
    return ResultList.of(sensor_kind=component.hal_id.device_kind_id)


def _not_implemented(what: str) -> SyncRun:
    async def run(component: HALComponent, command: CommandMessage) -> ResultList:
        raise NotImplementedHALError(f"{command.function_name}: {what}")

    return run


# -- Every component ---------------------------------------------------------------------
async def _reset(component: HALComponent, command: CommandMessage) -> None:
    await component.re_init()


async def _get_state(component: HALComponent, command: CommandMessage) -> ResultList:
    fault = component.last_fault
    return ResultList.of(
        state=str(component.state),
        error_id=0 if fault is None else fault.error_id,
        message="" if fault is None else str(fault),
    )


async def _get_profile(component: HALComponent, command: CommandMessage) -> ResultList:
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
    if isinstance(component, Sensor):
        values["units"] = list(component.units) or [""]
    return ResultList.of(**values)


async def _get_time(component: HALComponent, command: CommandMessage) -> ResultList:
    return ResultList.of(time_ns=component.get_time())


COMMON = (
    Operation("Reset", _reset, description="ReInit: leave Error and return to Active"),
    Operation("GetState", _get_state, description="state, error_id and message of the last fault"),
    Operation("GetProfile", _get_profile, description="identity, limits, units"),
    Operation("GetTime", _get_time, description="the component's clock, ns"),
)

MOTOR_OPERATIONS = (
    Operation(
        "SetPosition", _set(Request.POSITION, "position"), False, (("position", DataType.FLOAT),)
    ),
    Operation(
        "SetSpeed", _set_speed, False, (("speed", DataType.FLOAT), ("tmAcc", DataType.FLOAT))
    ),
    Operation("SetTorque", _set(Request.TORQUE, "torque"), False, (("torque", DataType.FLOAT),)),
    Operation("SetControlMode", _set_control_mode, False, (("mode", DataType.INT),)),
    Operation("GetControlMode", _get_control_mode),
    Operation("GetPosition", _get(Request.POSITION_ACTUAL, "position")),
    Operation("GetSpeed", _get(Request.VELOCITY_ACTUAL, "speed")),
    Operation("GetTorque", _get(Request.TORQUE_ACTUAL, "torque")),
    Operation("SetOrigin", _not_implemented("the Actuator API has no origin")),
    *COMMON,
)

SENSOR_OPERATIONS = (
    Operation("GetSensorKind", _get_kind),
    Operation("GetValueOfMeasurement", _get_values),
    Operation("GetUnitOfMeasurement", _get_units),
    Operation("SetUnitOfMeasurement", _not_implemented("units are fixed SI units")),
    Operation("SetScaleFactor", _not_implemented("values are in SI units")),
    Operation("GetScaleFactor", _not_implemented("values are in SI units")),
    Operation("SetOrigin", _not_implemented("the Sensor API has no origin")),
    *COMMON,
)

SENSOR_KIND_NAMES: dict[int, str] = {
    DeviceKind.ROTARY_ANGLE: "Encoder",
    DeviceKind.GYRO: "GyroSensor",
    DeviceKind.ACCEL: "AccelerationSensor",
    DeviceKind.FORCE: "ForceSensor",
    DeviceKind.TORQUE: "TorqueSensor",
    DeviceKind.TEMPERATURE: "TemperatureSensor",
    DeviceKind.HUMIDITY: "HumiditySensor",
    DeviceKind.COMPASS: "DirectionSensor",
    DeviceKind.DISTANCE: "DistanceSensor",
    DeviceKind.CO2: "CO2Sensor",
    DeviceKind.COLOR: "ColorSensor",
    DeviceKind.TOUCH: "TouchSensor",
    DeviceKind.CURRENT: "CurrentSensor",
}


def _table(operations: tuple[Operation, ...]) -> dict[str, Operation]:
    return {op.name: op for op in operations}


DEFAULT_PROFILES: dict[str, KindProfile] = {
    "Motor": KindProfile("Motor", Actuator, _table(MOTOR_OPERATIONS)),
    "Actuator": KindProfile("Actuator", Actuator, _table(MOTOR_OPERATIONS)),
    "Sensor": KindProfile("Sensor", Sensor, _table(SENSOR_OPERATIONS)),
    **{
        name: KindProfile(name, Sensor, _table(SENSOR_OPERATIONS))
        for name in SENSOR_KIND_NAMES.values()
    },
}


def kind_of(component: HALComponent) -> str:
    """The surface device kind of a plain component: Motor, Encoder, GyroSensor..."""
    if isinstance(component, Actuator):
        return "Motor" if component.hal_id.device_kind_id == DeviceKind.MOTOR else "Actuator"
    if isinstance(component, Sensor):
        return SENSOR_KIND_NAMES.get(component.hal_id.device_kind_id, "Sensor")
    raise BadParameterError("component", component, "an Actuator or a Sensor")
