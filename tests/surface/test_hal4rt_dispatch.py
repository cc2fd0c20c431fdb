"""The surface dispatches the HAL4RT Motor and Sensor operations to the component's own:
a Motor's (scale factor, origin, control mode, SetSpeed with tmAcc) and a Sensor's per-value
unit, scale factor and origin; a plain Actuator answers NOT_IMPLEMENTED for what it lacks."""

from __future__ import annotations

import math

import anyio
import pytest

from openel_async import (
    Actuator,
    Motor,
    MotorControlMode,
    Request,
    ReturnCode,
    TemperatureSensor,
    VirtualClock,
    WouldBlockError,
)
from openel_async.device import Device as Device_
from openel_async.device_profile import profile_of
from openel_async.surface import ApplicationQueue, CommandMessage, Completed, Device, Surface
from openel_async.surface.profiles import DEFAULT_PROFILES
from openel_async.testing import ComponentStack
from openel_sim import SimEncoder, SimMotor, SimTemperature

_BAD = ReturnCode.HAL_BAD_PARAMETER
_NULL = ReturnCode.HAL_NULL_PARAMETER
_NOT_IMPLEMENTED = ReturnCode.HAL_NOT_IMPLEMENTED


def _call(kind: str, name: str, **arguments: object) -> Device:
    return Device(kind, (CommandMessage.call(name, "", **arguments),))


def _results(device: Device) -> dict[str, object]:
    results = device.commands[0].results
    assert results is not None
    return results.as_dict()


async def _motor(stack: ComponentStack, *, native_ramp: bool = True) -> Motor:
    device = SimMotor(max_velocity=4.0, max_acceleration=40.0, native_ramp=native_ramp)
    return await stack.enter(Motor(device, clock=stack.clock, scale_factor=360))


async def test_motor_position_and_origin_are_in_the_motors_units(
    hal_components: ComponentStack,
) -> None:
    motor = await _motor(hal_components)
    app = ApplicationQueue()
    async with Surface([motor]) as surface:
        reply = await surface.execute(_call("Motor", "SetPosition", position=90.0), app)
        assert _results(reply) == {"return_code": 0}
        with anyio.fail_after(5):
            assert await app.get() == Completed(reply.commands[0].command_id, ReturnCode.HAL_OK)
        assert await motor.get_value() == pytest.approx(math.pi / 2)  # SI on the device
        position = _results(await surface.execute(_call("Motor", "GetPosition")))["position"]
        assert position == pytest.approx(90.0)
        # SetOrigin: here reads 0.25 rad (HAL4RT gives it in rad), i.e. 0.25 * 360 / 2 pi deg.
        done = await surface.execute(_call("Motor", "SetOrigin", position=0.25))
        assert _results(done) == {"return_code": 0}
        assert motor.origin == pytest.approx(math.pi / 2 - 0.25)
        reading = _results(await surface.execute(_call("Motor", "GetPosition")))["position"]
        assert reading == pytest.approx(math.degrees(0.25))
        # Left out, the position is 0.
        await surface.execute(_call("Motor", "SetOrigin"))
        assert _results(await surface.execute(_call("Motor", "GetPosition")))[
            "position"
        ] == pytest.approx(0.0, abs=1e-9)
        profile = _results(await surface.execute(_call("Motor", "GetProfile")))
        assert profile["scale_factor"] == 360.0 and profile["origin"] == motor.origin


async def test_motor_nowait_paths_convert_as_the_motor_does(
    hal_components: ComponentStack,
) -> None:
    motor = await _motor(hal_components)
    async with Surface([motor]) as surface:
        await motor.set_origin(0.5)
        await (await motor.set_position(30.0))
        for name in ("GetPosition", "GetSpeed", "GetTorque"):
            now = _results(surface.execute_nowait(_call("Motor", name)))
            assert now == _results(await surface.execute(_call("Motor", name)))
        assert _results(surface.execute_nowait(_call("Motor", "GetPosition")))[
            "position"
        ] == pytest.approx(30.0)
        surface.execute_nowait(_call("Motor", "SetPosition", position=-20.0))
        nowait_target = motor.motion.target  # type: ignore[union-attr]
        await motor.set_position(-20.0)
        assert nowait_target == motor.motion.target  # type: ignore[union-attr]
        surface.execute_nowait(_call("Motor", "SetSpeed", speed=45.0))
        assert motor.motion.target == pytest.approx(math.radians(45.0))  # type: ignore[union-attr]
        assert motor.get_control_mode() is MotorControlMode.SPEED
        # Out of the limits: nothing done, and execute() answers in degrees.
        before = motor.motion
        with pytest.raises(WouldBlockError):
            surface.execute_nowait(_call("Motor", "SetPosition", position=500.0))
        assert motor.motion is before
        refused = _results(await surface.execute(_call("Motor", "SetPosition", position=500.0)))
        assert refused["return_code"] == ReturnCode.HAL_BAD_PARAMETER
        assert "position=500.0" in str(refused["message"])
        assert "a position in [" in str(refused["message"]) and "151.3" in str(refused["message"])


@pytest.mark.parametrize("native_ramp", [True, False])
async def test_set_speed_with_tm_acc_ramps_and_completes_through_completed(
    hal_components: ComponentStack, virtual_clock: VirtualClock, native_ramp: bool
) -> None:
    motor = await _motor(hal_components, native_ramp=native_ramp)
    app = ApplicationQueue()
    async with Surface([motor]) as surface:
        with pytest.raises(WouldBlockError):  # the ramp reads the actual speed first
            surface.execute_nowait(_call("Motor", "SetSpeed", speed=60.0, tmAcc=0.5), app)
        assert motor.motion is None  # nothing done
        t0 = virtual_clock.now_ns()
        reply = await surface.execute(_call("Motor", "SetSpeed", speed=60.0, tmAcc=0.5), app)
        assert _results(reply) == {"return_code": 0}
        assert virtual_clock.now_ns() == t0  # accepted at once
        with anyio.fail_after(5):
            assert await app.get() == Completed(reply.commands[0].command_id, ReturnCode.HAL_OK)
        motion = motor.motion
        assert motion is not None and motion.reached_ns is not None
        took = motion.reached_ns - motion.issued_ns
        if native_ramp:  # the device ramps: reached in tmAcc
            assert took == 500_000_000
        else:  # the framework's last setpoint at tmAcc, then the device's own acceleration
            assert 500_000_000 <= took < 501_000_000
        speed = _results(await surface.execute(_call("Motor", "GetSpeed")))["speed"]
        assert speed == pytest.approx(60.0, abs=1e-6)
        mode = _results(await surface.execute(_call("Motor", "GetControlMode")))["mode"]
        assert mode == MotorControlMode.SPEED


async def test_motor_set_control_mode_enters_the_mode_without_a_jump(
    hal_components: ComponentStack,
) -> None:
    motor = await _motor(hal_components)
    app = ApplicationQueue()
    async with Surface([motor]) as surface:
        assert _results(await surface.execute(_call("Motor", "GetControlMode")))["mode"] == 0
        await (await motor.set_position(45.0))
        with pytest.raises(WouldBlockError):
            surface.execute_nowait(_call("Motor", "SetControlMode", mode=2))
        reply = await surface.execute(_call("Motor", "SetControlMode", mode=2), app)
        assert _results(reply) == {"return_code": 0}
        with anyio.fail_after(5):
            assert await app.get() == Completed(reply.commands[0].command_id, ReturnCode.HAL_OK)
        assert motor.get_control_mode() is MotorControlMode.SPEED
        assert motor.motion is not None and motor.motion.target == 0.0  # the actual speed
        assert _results(await surface.execute(_call("Motor", "GetControlMode")))["mode"] == 2
        await surface.execute(_call("Motor", "SetControlMode", mode=0))
        assert motor.get_control_mode() is MotorControlMode.READY_TO_CONTROL


class _VelocityOnly(SimMotor):
    supported_requests = frozenset({Request.NO_EXCITE, Request.VELOCITY})


@pytest.mark.parametrize(
    ("component", "command", "code", "fragment"),
    [
        ("motor", _call("Motor", "SetSpeed", speed=1.0, tmAcc=-1.0), _BAD, "tmAcc=-1.0"),
        ("motor", _call("Motor", "SetSpeed", speed=1.0, tmAcc=math.inf), _BAD, "tmAcc=inf"),
        ("motor", _call("Motor", "SetSpeed", speed=1.0, tmAcc=1), _BAD, "tmAcc.data_type_id=1"),
        ("motor", _call("Motor", "SetControlMode", mode=7), _BAD, "mode=7"),
        ("motor", _call("Motor", "SetControlMode", mode=1.0), _BAD, "mode.data_type_id=2"),
        ("motor", _call("Motor", "SetControlMode"), _NULL, "'mode' is missing"),
        ("motor", _call("Motor", "SetOrigin", position=1), _BAD, "position.data_type_id=1"),
        ("motor", _call("Motor", "SetOrigin", position=math.nan), _BAD, "position=nan"),
        ("velocity_motor", _call("Motor", "SetControlMode", mode=1), _NOT_IMPLEMENTED, "POSITION"),
        (
            "actuator",
            _call("Motor", "SetSpeed", speed=1.0, tmAcc=0.5),
            _NOT_IMPLEMENTED,
            "tmAcc > 0",
        ),
        ("actuator", _call("Motor", "SetSpeed", speed=1.0, tmAcc=-0.5), _BAD, "tmAcc=-0.5"),
        ("actuator", _call("Motor", "SetControlMode", mode=1), _NOT_IMPLEMENTED, "plain Actuator"),
        ("actuator", _call("Motor", "SetControlMode", mode=9), _BAD, "mode=9"),
        ("actuator", _call("Motor", "SetOrigin", position=0.0), _NOT_IMPLEMENTED, "no origin"),
    ],
)
async def test_motor_commands_are_refused_with_the_matching_code(
    hal_components: ComponentStack,
    component: str,
    command: Device,
    code: ReturnCode,
    fragment: str,
) -> None:
    if component == "actuator":
        target: Actuator = await hal_components.actuator(SimMotor())
    elif component == "velocity_motor":
        target = await hal_components.enter(Motor(_VelocityOnly(), clock=hal_components.clock))
    else:
        target = await _motor(hal_components)
    origin = target.origin if isinstance(target, Motor) else None
    async with Surface([target]) as surface:
        for run in ("execute", "execute_nowait"):
            if run == "execute":
                reply = await surface.execute(command)
            else:
                try:
                    reply = surface.execute_nowait(command)
                except WouldBlockError:
                    continue
            results = _results(reply)
            assert results["return_code"] == code, results
            assert fragment in str(results["message"])
        assert target.motion is None  # nothing sent
        if isinstance(target, Motor):
            assert target.origin == origin


async def test_plain_actuator_keeps_si_and_tm_acc_zero(hal_components: ComponentStack) -> None:
    axis = await hal_components.actuator(SimMotor(max_velocity=4.0, max_acceleration=40.0))
    async with Surface([axis]) as surface:
        reply = await surface.execute(_call("Motor", "SetSpeed", speed=1.0, tmAcc=0.0))
        assert _results(reply) == {"return_code": 0}
        assert axis.motion is not None and axis.motion.request is Request.VELOCITY
        assert axis.motion.target == 1.0
        assert _results(await surface.execute(_call("Motor", "GetControlMode")))["mode"] == 2
        surface.execute_nowait(_call("Motor", "SetControlMode", mode=0))
        assert _results(await surface.execute(_call("Motor", "GetControlMode")))["mode"] == 0


async def test_sensor_unit_scale_factor_and_origin(hal_components: ComponentStack) -> None:
    motor = SimMotor()
    thermometer = await hal_components.enter(
        TemperatureSensor(SimTemperature(motor), clock=hal_components.clock)
    )
    encoder = await hal_components.sensor(SimEncoder(motor))
    kind = "TemperatureSensor"
    async with Surface([thermometer, encoder]) as surface:
        assert _results(await surface.execute(_call(kind, "GetSensorKind"))) == {
            "return_code": 0,
            "sensor_kind": 0x8,
        }
        set_unit = await surface.execute(_call(kind, "SetUnitOfMeasurement", units=["degC"]))
        assert _results(set_unit) == {"return_code": 0}
        assert _results(await surface.execute(_call(kind, "GetUnitOfMeasurement")))["units"] == (
            "degC",
        )
        reading = _results(await surface.execute(_call(kind, "GetValueOfMeasurement")))
        assert reading["values"] == (pytest.approx(25.0),)
        assert (
            _results(surface.execute_nowait(_call(kind, "SetOrigin", values=[293.15])))[
                "return_code"
            ]
            == 0
        )
        await surface.execute(_call(kind, "SetScaleFactor", values=[2.0]))
        assert _results(await surface.execute(_call(kind, "GetScaleFactor")))["values"] == (2.0,)
        reading = _results(surface.execute_nowait(_call(kind, "GetValueOfMeasurement")))
        assert reading["values"] == (pytest.approx(2.0 * (298.15 - 293.15) - 273.15),)
        assert thermometer.get_origin() == (293.15,)
        # The Encoder kind (a plain Sensor) has the same operations.
        await surface.execute(_call("Encoder", "SetUnitOfMeasurement", units=["deg"]))
        assert encoder.units == ("deg",)


class _NoUnits(SimEncoder):
    units = ()  # type: ignore[assignment]


@pytest.mark.parametrize(
    ("command", "code", "fragment"),
    [
        (CommandMessage.call("SetUnitOfMeasurement", "", units=["m"]), _BAD, "units[0]='m'"),
        (
            CommandMessage.call("SetUnitOfMeasurement", "", units="degC"),
            _BAD,
            "units.data_type_id=3",
        ),
        (CommandMessage.call("SetUnitOfMeasurement", "", units=["K", "K"]), _BAD, "units=("),
        (CommandMessage.call("SetScaleFactor", "", values=[0.0]), _BAD, "values[0]=0.0"),
        (CommandMessage.call("SetScaleFactor", "", values=[1, 2]), _BAD, "values.data_type_id=11"),
        (CommandMessage.call("SetScaleFactor", ""), _NULL, "'values' is missing"),
        (CommandMessage.call("SetOrigin", "", values=[math.inf]), _BAD, "values[0]=inf"),
        (CommandMessage.call("SetOrigin", "", values=[1.0, 2.0]), _BAD, "values=(1.0, 2.0)"),
    ],
)
async def test_sensor_commands_are_refused_and_change_nothing(
    hal_components: ComponentStack, command: CommandMessage, code: ReturnCode, fragment: str
) -> None:
    thermometer = await hal_components.enter(
        TemperatureSensor(SimTemperature(SimMotor()), clock=hal_components.clock)
    )
    async with Surface([thermometer]) as surface:
        before = (thermometer.units, thermometer.get_scale_factor(), thermometer.get_origin())
        results = _results(await surface.execute(Device("TemperatureSensor", (command,))))
        assert results["return_code"] == code
        assert fragment in str(results["message"])
        after = (thermometer.units, thermometer.get_scale_factor(), thermometer.get_origin())
        assert after == before


async def test_a_sensor_without_units_answers_not_implemented(
    hal_components: ComponentStack,
) -> None:
    sensor = await hal_components.sensor(_NoUnits(SimMotor()))
    async with Surface([sensor]) as surface:
        for name in ("SetUnitOfMeasurement", "SetScaleFactor", "SetOrigin"):
            argument = {"units": ["rad"]} if name == "SetUnitOfMeasurement" else {"values": [1.0]}
            results = _results(await surface.execute(_call("Encoder", name, **argument)))
            assert results["return_code"] == ReturnCode.HAL_NOT_IMPLEMENTED
            assert "declares no units" in str(results["message"])


def test_surface_operations_follow_the_device_characteristics_profile() -> None:
    """Every profile command the surface offers has the profile's id, mode and arguments."""
    expected: dict[str, tuple[type[Device_], set[str]]] = {
        "Motor": (SimMotor, {"SetSpeed", "SetOrigin", "SetControlMode", "GetControlMode"}),
        "TemperatureSensor": (SimTemperature, {"SetUnitOfMeasurement", "SetOrigin"}),
    }
    for kind, (device_class, names) in expected.items():
        profile = profile_of(device_class)
        operations = DEFAULT_PROFILES[kind].operations
        offered = [c for c in profile.commands if c.name in operations]
        assert names <= {c.name for c in offered}
        for command in offered:
            operation = operations[command.name]
            assert operation.command_id == command.id
            assert operation.synchronous == command.synchronous
            inputs = [p.name for p in command.parameters if p.direction == "in"]
            assert [name for name, _ in operation.arguments] == inputs
