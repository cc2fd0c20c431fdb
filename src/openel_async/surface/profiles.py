"""Dispatch tables of the surface layer: per device kind, function_name -> operation.

A :class:`KindProfile` lists the operations of one device kind (spec §7.4.5: Motor,
sensors). A synchronous operation returns its results; an asynchronous one returns the
:class:`Motion` whose end the surface reports with ``completed``. An operation may also
have a ``run_nowait`` twin that does the same without suspending (``get_value_nowait``,
``set_value_nowait``...) for components that need no I/O; it raises WouldBlockError,
before any effect, when the component has no synchronous path. Device characteristics
profiles can later build such tables from their own definitions; :data:`DEFAULT_PROFILES`
covers the plain components (``Actuator`` as Motor, ``Sensor`` by its device kind).
"""

from __future__ import annotations

import re
from collections.abc import Awaitable, Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

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


# -- Motor (an Actuator) ---------------------------------------------------------------
# Each Set* reads and checks its arguments first (refusals have no effect), then sends
# the command through set_value or, without suspending, set_value_nowait.
def _setpoint(request: Request, name: str) -> Callable[[CommandMessage], tuple[float, Request]]:
    def parse(command: CommandMessage) -> tuple[float, Request]:
        return argument(command, name, DataType.FLOAT), request

    return parse


def _speed(command: CommandMessage) -> tuple[float, Request]:
    speed = argument(command, "speed", DataType.FLOAT)
    if argument(command, "tmAcc", DataType.FLOAT, required=False) is not None:
        raise NotImplementedHALError(
            "SetSpeed: tmAcc is not supported (the device ramps at its own acceleration limit)"
        )
    return speed, Request.VELOCITY


def _control_mode(command: CommandMessage) -> tuple[float, Request]:
    mode = argument(command, "mode", DataType.INT)
    if mode != 0:
        raise NotImplementedHALError(
            f"SetControlMode: mode {mode} is entered by SetPosition (1), SetSpeed (2) or "
            "SetTorque (3); only 0 (HALMOTOR_READY_TO_CONTROL) is set directly"
        )
    return 0.0, Request.NO_EXCITE


def _set_op(
    name: str,
    parse: Callable[[CommandMessage], tuple[float, Request]],
    arguments: tuple[tuple[str, DataType], ...],
) -> Operation:
    async def run(component: HALComponent, command: CommandMessage) -> Motion:
        assert isinstance(component, Actuator)
        value, request = parse(command)
        return await component.set_value(value, request)

    def nowait(component: HALComponent, command: CommandMessage) -> Motion:
        assert isinstance(component, Actuator)
        value, request = parse(command)
        return component.set_value_nowait(value, request)

    return Operation(name, run, False, arguments, run_nowait=nowait)


def _get_control_mode(component: HALComponent, command: CommandMessage) -> ResultList:
    assert isinstance(component, Actuator)
    motion = component.motion
    return ResultList.of(mode=0 if motion is None else int(motion.request))


def _get_op(name: str, request: Request, result: str) -> Operation:
    async def run(component: HALComponent, command: CommandMessage) -> ResultList:
        assert isinstance(component, Actuator)
        return ResultList.of(**{result: await component.get_value(request)})

    def nowait(component: HALComponent, command: CommandMessage) -> ResultList:
        assert isinstance(component, Actuator)
        return ResultList.of(**{result: component.get_value_nowait(request)})

    return Operation(name, run, run_nowait=nowait)


# -- Sensors -----------------------------------------------------------------------------
async def _get_values(component: HALComponent, command: CommandMessage) -> ResultList:
    assert isinstance(component, Sensor)
    if component.device.has_time:
        timed = await component.get_timed_value()
        return ResultList.of(values=list(timed.values), time_ns=timed.time_ns)
    return ResultList.of(values=list(await component.get_value()))


def _get_values_nowait(component: HALComponent, command: CommandMessage) -> ResultList:
    assert isinstance(component, Sensor)
    if component.device.has_time:
        timed = component.get_timed_value_nowait()
        return ResultList.of(values=list(timed.values), time_ns=timed.time_ns)
    return ResultList.of(values=list(component.get_value_nowait()))


def _get_units(component: HALComponent, command: CommandMessage) -> ResultList:
    assert isinstance(component, Sensor)
    return ResultList.of(units=list(component.units) or [""])


def _get_kind(component: HALComponent, command: CommandMessage) -> ResultList:
    return ResultList.of(sensor_kind=component.hal_id.device_kind_id)


def _not_implemented(name: str, what: str) -> Operation:
    def now(component: HALComponent, command: CommandMessage) -> ResultList:
        raise NotImplementedHALError(f"{command.function_name}: {what}")

    return _op(name, now)


# -- Every component ---------------------------------------------------------------------
async def _reset(component: HALComponent, command: CommandMessage) -> None:
    await component.re_init()


def _get_state(component: HALComponent, command: CommandMessage) -> ResultList:
    fault = component.last_fault
    return ResultList.of(
        state=str(component.state),
        error_id=0 if fault is None else fault.error_id,
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
    if isinstance(component, Sensor):
        values["units"] = list(component.units) or [""]
    return ResultList.of(**values)


def _get_time(component: HALComponent, command: CommandMessage) -> ResultList:
    return ResultList.of(time_ns=component.get_time())


COMMON = (
    Operation("Reset", _reset, description="ReInit: leave Error and return to Active"),
    _op("GetState", _get_state, description="state, error_id and message of the last fault"),
    _op("GetProfile", _get_profile, description="identity, limits, units"),
    _op("GetTime", _get_time, description="the component's clock, ns"),
)

MOTOR_OPERATIONS = (
    _set_op(
        "SetPosition", _setpoint(Request.POSITION, "position"), (("position", DataType.FLOAT),)
    ),
    _set_op("SetSpeed", _speed, (("speed", DataType.FLOAT), ("tmAcc", DataType.FLOAT))),
    _set_op("SetTorque", _setpoint(Request.TORQUE, "torque"), (("torque", DataType.FLOAT),)),
    _set_op("SetControlMode", _control_mode, (("mode", DataType.INT),)),
    _op("GetControlMode", _get_control_mode),
    _get_op("GetPosition", Request.POSITION_ACTUAL, "position"),
    _get_op("GetSpeed", Request.VELOCITY_ACTUAL, "speed"),
    _get_op("GetTorque", Request.TORQUE_ACTUAL, "torque"),
    _not_implemented("SetOrigin", "the Actuator API has no origin"),
    *COMMON,
)

SENSOR_OPERATIONS = (
    _op("GetSensorKind", _get_kind),
    Operation("GetValueOfMeasurement", _get_values, run_nowait=_get_values_nowait),
    _op("GetUnitOfMeasurement", _get_units),
    _not_implemented("SetUnitOfMeasurement", "units are fixed SI units"),
    _not_implemented("SetScaleFactor", "values are in SI units"),
    _not_implemented("GetScaleFactor", "values are in SI units"),
    _not_implemented("SetOrigin", "the Sensor API has no origin"),
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
