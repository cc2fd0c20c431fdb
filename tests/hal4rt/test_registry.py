"""Identity (§7.4.5.1): profile id, component name, vendor-name rule, reserved product ids,
the Device Kind ID registry (HalCreate) and device characteristics profiles."""

from __future__ import annotations

import json
import math

import pytest

from openel_async import (
    Actuator,
    BadParameterError,
    DeviceKind,
    Encoder,
    HALId,
    Motor,
    NotImplementedHALError,
    Request,
)
from openel_async.cli import main
from openel_async.device import ActuatorDevice, DeviceInfo
from openel_async.device_profile import profile_of
from openel_async.device_registry import DeviceRegistry
from openel_async.ids import EXTENSION_KIND_IDS, check_product_id, component_name
from openel_async.registry import discover_drivers
from openel_async.sensing import SensingActuatorDevice, SensingMotor
from openel_async.testing import ComponentStack
from openel_sim import SimEncoder, SimMotor


def test_gps_id_is_in_the_extension_range_and_fits_int32() -> None:
    # int(): a range tests an exact int in O(1) but walks all 16 M ids for an IntEnum member
    assert int(DeviceKind.GPS) in EXTENSION_KIND_IDS
    assert EXTENSION_KIND_IDS[-1] < 2**31
    assert all(int(k) not in EXTENSION_KIND_IDS for k in DeviceKind if k is not DeviceKind.GPS)


async def test_profile_id_and_component_name(hal_components: ComponentStack) -> None:
    motor = await hal_components.enter(Motor(SimMotor(), clock=hal_components.clock))
    assert motor.profile_id == DeviceKind.MOTOR
    assert motor.component_name == "HalMotorOpenELSimMotor" == motor.get_profile().device_name
    assert component_name("Gps", "Acme", "G1") == "HalGpsAcmeG1"


@pytest.mark.parametrize("vendor", ["A", "acme", "Abcdefghijklmnopq", "Ac-me", ""])
def test_vendor_name_rule(vendor: str) -> None:
    with pytest.raises(BadParameterError) as info:
        component_name("Motor", vendor, "X")
    assert info.value.parameter == "vendor_name"


@pytest.mark.parametrize("product", [0, 0xFFFF_FFFF])
def test_reserved_product_ids_are_refused(product: int) -> None:
    with pytest.raises(BadParameterError) as info:
        check_product_id(product)
    assert info.value.parameter == "product_id"

    class Reserved(SimMotor):
        info = DeviceInfo(DeviceKind.MOTOR, 0x0E1, product, "OpenEL", "Reserved")

    registry = DeviceRegistry()
    with pytest.raises(BadParameterError):
        registry.register(Reserved)
    assert len(registry) == 0
    with pytest.raises(BadParameterError):
        registry.create(HALId(DeviceKind.MOTOR, 0x0E1, product, 1))


def test_registry_refuses_a_key_twice() -> None:
    registry = DeviceRegistry()
    registry.register(SimMotor, driver="sim")

    class Clone(SimMotor):
        pass

    with pytest.raises(BadParameterError, match="SimMotor of driver 'sim'"):
        registry.register(Clone)


async def test_hal_create_builds_the_component_of_the_kind(
    hal_components: ComponentStack,
) -> None:
    registry = DeviceRegistry.from_drivers()
    hal_id = HALId(DeviceKind.MOTOR, 0x0E1, 0x100, 7)
    motor = registry.create(hal_id, component_options={"clock": hal_components.clock})
    assert type(motor) is Motor and motor.hal_id == hal_id
    await hal_components.enter(motor)
    assert isinstance(motor, Actuator)
    await (await motor.set_position(1.0))
    device = motor.device
    assert isinstance(device, SimMotor)
    encoder = registry.create(
        HALId(DeviceKind.ROTARY_ANGLE, 0x0E1, 0x200, 1),
        device,
        component_options={"clock": hal_components.clock},
    )
    assert type(encoder) is Encoder
    await hal_components.enter(encoder)
    assert (await encoder.get_value())[0] == pytest.approx(1.0, abs=2 * math.pi / 4096)
    with pytest.raises(NotImplementedHALError):
        registry.create(HALId(DeviceKind.MOTOR, 0x0E1, 0x999, 1))


def test_profile_lists_commands_with_ids_and_units() -> None:
    profile = profile_of(SimMotor())
    assert profile.kind_name == "Motor" and profile.role == "actuator"
    set_speed = profile.command("SetSpeed")
    assert set_speed.id == 0x104 and not set_speed.synchronous
    assert [(p.name, p.unit) for p in set_speed.parameters] == [
        ("speed", "scale/s"),
        ("tmAcc", "s"),
    ]
    assert profile.command(0x105).name == "SetTorque"
    assert profile.attributes["velocity_ramp"] is True
    assert profile.attributes["position_limits"] == [-math.pi, math.pi]
    assert profile.command("inject_fault").id == 0x1000
    ids = [c.id for c in profile.commands]
    assert len(ids) == len(set(ids))
    sensor = profile_of(SimEncoder)
    assert sensor.kind_name == "Encoder" and sensor.attributes["units"] == ["rad"]
    assert sensor.command("SetUnitOfMeasurement").method == "set_unit_of_measurement"
    json.dumps(profile.to_dict())  # plain data


def test_unsupported_modes_are_marked_in_the_profile() -> None:
    class VelocityOnly(SimMotor):
        supported_requests = frozenset({Request.NO_EXCITE, Request.VELOCITY})

    profile = profile_of(VelocityOnly)
    assert not profile.command("SetPosition").supported
    assert profile.command("SetSpeed").supported


def component_class_of(device_class: type) -> type:
    if issubclass(device_class, SensingActuatorDevice):
        return SensingMotor
    return Motor if issubclass(device_class, ActuatorDevice) else Encoder


def test_every_profile_command_names_a_method_of_its_component() -> None:
    registry = DeviceRegistry.from_drivers()
    assert len(registry) >= 5
    for entry in registry:
        if not issubclass(entry.device_class, ActuatorDevice) and entry.kind_id == DeviceKind.GPS:
            continue  # GPS: its own helper's class
        cls = component_class_of(entry.device_class)
        for command in entry.profile.commands:
            if command.id < 0x300:
                assert hasattr(cls, command.method), (entry.key, command.name)


def test_cli_devices_profile_prints_json(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["devices", "--profile"]) == 0
    document = json.loads(capsys.readouterr().out)
    motor = document["devices"]["sim.motor"]
    assert motor["kind_id"] == 1 and motor["component_name"] == "HalMotorOpenELSimMotor"
    assert {"SetPosition", "SetSpeed", "GetControlMode"} <= {c["name"] for c in motor["commands"]}
    assert document["devices"]["sim.magnetometer"]["kind_id"] == DeviceKind.COMPASS
    registered = {f"{d.name}.{n}" for d in discover_drivers() if d.info for n in d.info.devices}
    assert registered == set(document["devices"]) | set(document["not_registered"])


def test_device_profile_definition_is_an_instance_register() -> None:
    """§7.4.5.1 Device Characteristics Profile Definition: "a register to have
    componentName, vendorId, productId, instanceId and profileId" (issue 21 point 19)."""
    from openel_async.device_profile import ProfileInstance

    registry = DeviceRegistry()
    entry = registry.register(SimMotor, driver="sim")
    profile = entry.profile
    assert profile.instances == ()
    first = registry.create(HALId(DeviceKind.MOTOR, 0x0E1, 0x100, 3))  # HalCreate registers
    second = registry.create(
        HALId(DeviceKind.MOTOR, 0x0E1, 0x100, 1), component_options={"device_name": "pan"}
    )
    assert profile.instances == (
        ProfileInstance("pan", 0x0E1, 0x100, 1, DeviceKind.MOTOR),
        ProfileInstance("HalMotorOpenELSimMotor", 0x0E1, 0x100, 3, DeviceKind.MOTOR),
    )
    got = profile.instance(3)
    assert (got.component_name, got.vendor_id, got.product_id, got.instance_id) == (
        first.component_name,
        0x0E1,
        0x100,
        3,
    )
    assert got.profile_id == first.profile_id == DeviceKind.MOTOR
    assert profile.register_instance(second) == profile.instance(1)  # again: no change
    data = json.loads(json.dumps(profile.to_dict()))
    assert data["instances"] == [
        {
            "component_name": "pan",
            "vendor_id": 0x0E1,
            "product_id": 0x100,
            "instance_id": 1,
            "profile_id": 1,
        },
        {
            "component_name": "HalMotorOpenELSimMotor",
            "vendor_id": 0x0E1,
            "product_id": 0x100,
            "instance_id": 3,
            "profile_id": 1,
        },
    ]
    # Another device under a registered instance id, or of another profile, is refused.
    with pytest.raises(BadParameterError) as taken:
        registry.create(
            HALId(DeviceKind.MOTOR, 0x0E1, 0x100, 3), component_options={"device_name": "tilt"}
        )
    assert taken.value.parameter == "instance_id" and "HalMotorOpenELSimMotor" in str(taken.value)
    with pytest.raises(BadParameterError) as other:
        profile.register_instance(ProfileInstance("x", 0x0E1, 0x200, 5, DeviceKind.ROTARY_ANGLE))
    assert other.value.parameter == "instance"
    assert profile.unregister_instance(1).component_name == "pan"
    assert [i.instance_id for i in profile.instances] == [3]
    for missing in (1, True):
        with pytest.raises(BadParameterError) as absent:
            profile.instance(missing)
        assert absent.value.parameter == "instance_id"
    with pytest.raises(BadParameterError):
        profile.unregister_instance(1)


@pytest.mark.parametrize(
    ("field", "value"),
    [("component_name", ""), ("vendor_id", -1), ("product_id", 2**32), ("instance_id", 1.5),
     ("profile_id", True)],
)  # fmt: skip
def test_a_profile_instance_refuses_bad_fields(field: str, value: object) -> None:
    from openel_async.device_profile import ProfileInstance

    fields: dict[str, object] = {
        "component_name": "pan",
        "vendor_id": 0x0E1,
        "product_id": 0x100,
        "instance_id": 1,
        "profile_id": 1,
    }
    with pytest.raises(BadParameterError) as info:
        ProfileInstance(**{**fields, field: value})  # type: ignore[arg-type]
    assert info.value.parameter == field
