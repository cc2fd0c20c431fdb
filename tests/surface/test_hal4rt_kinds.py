"""The GPS Sensor's and the Direction Sensor's operations (HAL4RT §7.4.5.13-14) and a
SensingMotor's Sensor operations (OpenEL §7.4.1.1) through the surface's ``execute``, with
the names, ids and parameters of the device characteristics profile, and their messages
valid against the spec's XSD (issue 21 point 19)."""

from __future__ import annotations

import math

import pytest

from openel_async import DeviceInfo, DeviceKind, Motor, ReturnCode, Sensor, VirtualClock
from openel_async.device_profile import (
    DIRECTION_COMMANDS,
    GPS_COMMANDS,
    KIND_COMMANDS,
    profile_of,
)
from openel_async.direction import DirectionSensor, MagneticModel
from openel_async.gps import GPSData, GPSDevice, GPSSensor, bearing_deg, distance_m
from openel_async.sensing import SensingMotor
from openel_async.surface import CommandMessage, Device, Surface, kind_of
from openel_async.surface.profiles import DEFAULT_PROFILES
from openel_async.surface.xml_psm import from_xml, schema, to_xml
from openel_async.testing import ComponentStack
from openel_serial import NmeaGps
from openel_sim import SimMotor, SimPanTiltHead
from openel_sim.sensors import SimMagnetometer

# The operation tables of the spec, in their order: (name, in parameters, out parameters).
SPEC_GPS = [
    ("GetLatitude", [], ["latitude"]),
    ("GetLongitude", [], ["longitude"]),
    ("GetAccuracy", [], ["accuracy"]),
    ("GetDOP", [], ["DOP"]),
    ("GetAltitude", [], ["altitude"]),
    ("GetTime", [], ["time"]),
    ("GetSpeed", [], ["speed"]),
    ("GetCourse", [], ["course"]),
    ("GetSignalStrength", [], ["signal_strength"]),  # the spec's "signal strength"
    ("GetAngle", [], ["angle"]),
    ("SetPeriod", ["period"], []),
]
SPEC_DIRECTION = [
    ("SetLatitude", ["latitude"], []),
    ("SetLongitude", ["longitude"], []),
    ("SetAltitude", ["altitude"], []),  # the spec's "Altitude"
    ("SetDate", ["date"], []),
    ("GetF", [], ["F"]),
    ("GetH", [], ["H"]),
    ("GetX", [], ["X"]),
    ("GetY", [], ["Y"]),
    ("GetZ", [], ["Z"]),
    ("GetI", [], ["I"]),
    ("GetD", [], ["D"]),  # the spec's "period" is a typo
]

FIX = GPSData(
    latitude=35.6812,
    longitude=139.7671,
    accuracy=2.5,
    dop=0.9,
    altitude=79.5,
    time_ms=1_714_564_800_000.0,
    speed=5.0,
    course=90.0,
    signal_strength=41.5,
    stale=False,
    fix_quality=1,
    satellites=9,
)


class FixedGps(GPSDevice):
    """A GPS device with a fixed fix, for the surface (no serial port)."""

    info = DeviceInfo(DeviceKind.GPS, 0x0E1, 0x901, "OpenEL", "FixedGps")
    period_range_ms = (100.0, 10_000.0)

    def __init__(self) -> None:
        self.fix = FIX
        self.periods: list[float] = []

    async def read_gps(self) -> GPSData:
        return self.fix

    async def set_period(self, period_ms: float) -> None:
        self.periods.append(period_ms)
        self.period_ms = period_ms


def _call(kind: str, name: str, **arguments: object) -> Device:
    return Device(kind, (CommandMessage.call(name, "", **arguments),))


async def _run(surface: Surface, kind: str, name: str, **arguments: object) -> dict[str, object]:
    reply = await surface.execute(_call(kind, name, **arguments))
    results = reply.commands[0].results
    assert results is not None
    # Every request and answer is a valid XML PSM message that reads back equal.
    for message in (_call(kind, name, **arguments), reply):
        xml = to_xml(message)
        schema().validate(xml)
        assert from_xml(xml) == message
    return results.as_dict()


def _spec_table(commands: tuple[object, ...]) -> list[tuple[str, list[str], list[str]]]:
    return [
        (
            c.name,  # type: ignore[attr-defined]
            [p.name for p in c.parameters if p.direction == "in"],  # type: ignore[attr-defined]
            [p.name for p in c.parameters if p.direction == "out"],  # type: ignore[attr-defined]
        )
        for c in commands
    ]


@pytest.mark.parametrize(
    ("kind", "spec", "device_class", "base"),
    [
        (DeviceKind.GPS, SPEC_GPS, NmeaGps, 0x300),
        (DeviceKind.COMPASS, SPEC_DIRECTION, SimMagnetometer, 0x400),
    ],
)
def test_every_spec_operation_is_in_the_device_profile_numbered_in_the_spec_order(
    kind: int, spec: list[tuple[str, list[str], list[str]]], device_class: type, base: int
) -> None:
    profile = profile_of(device_class)
    own = [c for c in profile.commands if c.id in range(base, base + 0x100)]
    assert own == list(KIND_COMMANDS[kind])
    assert _spec_table(tuple(own[: len(spec)])) == spec
    assert [c.id for c in own[: len(spec)]] == [base + 1 + i for i in range(len(spec))]
    assert all(c.id >= base + 0x81 for c in own[len(spec) :])  # the extensions
    for command in own:
        target = GPSSensor if kind == DeviceKind.GPS else DirectionSensor
        assert hasattr(target, command.method), command.name
    names = [c.name for c in profile.commands]
    assert len(names) == len(set(names))  # one command per name
    if kind == DeviceKind.GPS:  # the spec's GetTime is the fix time; OpenEL's is HalGetTime
        assert profile.command("GetTime").id == 0x306
        assert profile.command("HalGetTime").id == 0x05
        assert profile.command("HalGetTime").method == "get_time"


def test_surface_kinds_offer_the_profile_commands_with_their_ids() -> None:
    for kind_name, commands in (
        ("GPSSensor", GPS_COMMANDS),
        ("DirectionSensor", DIRECTION_COMMANDS),
    ):
        operations = DEFAULT_PROFILES[kind_name].operations
        for command in commands:
            operation = operations[command.name]
            assert operation.command_id == command.id
            inputs = [p.name for p in command.parameters if p.direction == "in"]
            assert [name for name, _ in operation.arguments] == inputs
    assert DEFAULT_PROFILES["GPSSensor"].operations["HalGetTime"].command_id == 0x05


async def test_gps_operations_through_execute(hal_components: ComponentStack) -> None:
    device = FixedGps()
    gps = await hal_components.enter(GPSSensor(device, clock=hal_components.clock))
    assert kind_of(gps) == "GPSSensor"
    async with Surface([gps]) as surface:
        expected = {
            "GetLatitude": ("latitude", FIX.latitude),
            "GetLongitude": ("longitude", FIX.longitude),
            "GetAccuracy": ("accuracy", FIX.accuracy),
            "GetDOP": ("DOP", FIX.dop),
            "GetAltitude": ("altitude", FIX.altitude),
            "GetTime": ("time", FIX.time_ms),
            "GetSpeed": ("speed", FIX.speed),
            "GetCourse": ("course", FIX.course),
            "GetSignalStrength": ("signal_strength", FIX.signal_strength),
        }
        for name, (result, value) in expected.items():
            assert await _run(surface, "GPSSensor", name) == {"return_code": 0, result: value}
        # GetAngle: the heading to the SetTarget position (an extension sets it).
        refused = await _run(surface, "GPSSensor", "GetAngle")
        assert refused["return_code"] == ReturnCode.HAL_ERROR
        assert "set_target" in str(refused["message"])
        target = {"latitude": 35.7, "longitude": 139.8}
        assert await _run(surface, "GPSSensor", "SetTarget", **target) == {"return_code": 0}
        assert gps.target == (35.7, 139.8)
        angle = await _run(surface, "GPSSensor", "GetAngle")
        assert angle["angle"] == pytest.approx(bearing_deg(35.6812, 139.7671, 35.7, 139.8))
        distance = await _run(surface, "GPSSensor", "GetDistance")
        assert distance["distance"] == pytest.approx(distance_m(35.6812, 139.7671, 35.7, 139.8))
        assert await _run(surface, "GPSSensor", "IsStale") == {"return_code": 0, "stale": False}
        # SetPeriod(period): milliseconds; a bad one is BAD_PARAMETER naming period_ms.
        assert await _run(surface, "GPSSensor", "SetPeriod", period=200.0) == {"return_code": 0}
        assert device.periods == [200.0] and gps.period_ms == 200.0
        bad = await _run(surface, "GPSSensor", "SetPeriod", period=20.0)
        assert bad["return_code"] == ReturnCode.HAL_BAD_PARAMETER
        assert "period_ms" in str(bad["message"]) and device.periods == [200.0]
        missing = await _run(surface, "GPSSensor", "SetPeriod")
        assert missing["return_code"] == ReturnCode.HAL_NULL_PARAMETER
        # The component clock's time (OpenEL GetTime) is HalGetTime here.
        clock = await _run(surface, "GPSSensor", "HalGetTime")
        assert clock == {"return_code": 0, "time_ns": gps.get_time()}
        # The Sensor operations stay: the value vector of the fix.
        values = await _run(surface, "GPSSensor", "GetValueOfMeasurement")
        assert values["values"] == FIX.values()
        # A quantity the receiver has not given is HAL_ERROR naming it.
        device.fix = GPSData(latitude=1.0, longitude=2.0)
        speed = await _run(surface, "GPSSensor", "GetSpeed")
        assert speed["return_code"] == ReturnCode.HAL_ERROR
        assert "speed not available" in str(speed["message"])


async def test_direction_operations_through_execute(hal_components: ComponentStack) -> None:
    field = MagneticModel().field(35.6812, 139.7671, 40.0, 2026.5)
    magnetometer = SimMagnetometer(
        field_ned_nt=(field.x, field.y, field.z), mount_yaw=math.radians(30.0)
    )
    compass = await hal_components.enter(
        DirectionSensor(magnetometer, frame="FRD", clock=hal_components.clock)
    )
    assert kind_of(compass) == "DirectionSensor"
    async with Surface([compass]) as surface:
        for name, value in (
            ("SetLatitude", {"latitude": 35.6812}),
            ("SetLongitude", {"longitude": 139.7671}),
            ("SetAltitude", {"altitude": 40.0}),
            ("SetDate", {"date": 2026.5}),
        ):
            assert await _run(surface, "DirectionSensor", name, **value) == {"return_code": 0}
        assert (compass.latitude, compass.longitude, compass.altitude, compass.date) == (
            35.6812,
            139.7671,
            40.0,
            2026.5,
        )
        for letter in "FHXYZID":
            results = await _run(surface, "DirectionSensor", f"Get{letter}")
            assert results == {"return_code": 0, letter: getattr(field, letter.lower())}
        heading = await _run(surface, "DirectionSensor", "GetHeading")
        assert heading["heading"] == pytest.approx(30.0, abs=1e-6)
        magnetic = await _run(surface, "DirectionSensor", "GetMagneticHeading")
        assert magnetic["heading"] == pytest.approx((30.0 - field.d) % 360.0, abs=1e-6)
        bad = await _run(surface, "DirectionSensor", "SetDate", date=2031.0)
        assert bad["return_code"] == ReturnCode.HAL_BAD_PARAMETER and compass.date == 2026.5
        wrong_type = await _run(surface, "DirectionSensor", "SetLatitude", latitude="north")
        assert wrong_type["return_code"] == ReturnCode.HAL_BAD_PARAMETER


async def test_a_plain_sensor_of_the_kind_answers_not_implemented(
    hal_components: ComponentStack,
) -> None:
    plain = await hal_components.enter(Sensor(SimMagnetometer(), clock=hal_components.clock))
    async with Surface([plain]) as surface:
        results = await _run(surface, "DirectionSensor", "SetDate", date=2026.0)
        assert results["return_code"] == ReturnCode.HAL_NOT_IMPLEMENTED
        assert "DirectionSensor has it" in str(results["message"])
        values = await _run(surface, "DirectionSensor", "GetValueOfMeasurement")
        assert values["return_code"] == 0 and len(values["values"]) == 3  # type: ignore[arg-type]


async def test_sensing_motor_sensor_operations_through_execute(
    hal_components: ComponentStack,
) -> None:
    device = SimPanTiltHead(target=(math.radians(20.0), math.radians(5.0)))
    head = await hal_components.enter(
        SensingMotor(device, clock=hal_components.clock, scale_factor=360)
    )
    motor = await hal_components.enter(Motor(SimMotor(), clock=hal_components.clock))
    async with Surface([head, motor]) as surface:
        kind = await _run(surface, "Motor", "GetSensorKind", logical_id=0)
        assert kind == {"return_code": 0, "sensor_kind": head.get_sensor_kind()}
        units = await _run(
            surface, "Motor", "SetUnitOfMeasurement", logical_id=0, units=["deg"] * 4
        )
        assert units == {"return_code": 0} and head.sensor_units == ("deg",) * 4
        got = await _run(surface, "Motor", "GetUnitOfMeasurement", logical_id=0)
        assert got["units"] == ("deg",) * 4
        values = await _run(surface, "Motor", "GetValueOfMeasurement", logical_id=0)
        assert values["values"] == pytest.approx((0.0, 0.0, 20.0, 5.0))
        assert values["time_ns"] == head.clock.now_ns()
        scale = [1.0, 1.0, 2.0, 1.0]
        done = await _run(surface, "Motor", "SensorSetScaleFactor", logical_id=0, values=scale)
        assert done == {"return_code": 0} and head.get_measurement_scale_factor() == tuple(scale)
        read = await _run(surface, "Motor", "SensorGetScaleFactor", logical_id=0)
        assert read["values"] == tuple(scale)
        origin = [0.0, 0.0, 0.1, 0.0]
        done = await _run(surface, "Motor", "SensorSetOrigin", logical_id=0, values=origin)
        assert done == {"return_code": 0} and head.get_measurement_origin() == tuple(origin)
        assert head.get_scale_factor() == 360.0 and head.origin == 0.0  # the Motor's own
        # Without suspending too (the simulated head needs no I/O).
        now = surface.execute_nowait(_call("Motor", "GetValueOfMeasurement", logical_id=0))
        assert now.commands[0].results is not None
        # y = u(s (x - o)): 2 (20 deg - 0.1 rad), in degrees
        assert now.commands[0].results.value("values")[2] == pytest.approx(
            2 * (20.0 - math.degrees(0.1))
        )
        # A Motor without a sensor answers them with NOT_IMPLEMENTED.
        plain = await _run(surface, "Motor", "GetValueOfMeasurement", logical_id=1)
        assert plain["return_code"] == ReturnCode.HAL_NOT_IMPLEMENTED
        assert "SensingMotor" in str(plain["message"])
        profile = await _run(surface, "Motor", "GetProfile", logical_id=0)
        assert profile["sensor_units"] == ("deg",) * 4


def test_sensing_motor_profile_commands_match_the_surface() -> None:
    profile = profile_of(SimPanTiltHead)
    operations = DEFAULT_PROFILES["Motor"].operations
    for name in (
        "GetSensorKind",
        "GetValueOfMeasurement",
        "SetUnitOfMeasurement",
        "GetUnitOfMeasurement",
        "SensorSetScaleFactor",
        "SensorGetScaleFactor",
        "SensorSetOrigin",
    ):
        command = profile.command(name)
        operation = operations[name]
        assert operation.command_id == command.id
        inputs = [p.name for p in command.parameters if p.direction == "in"]
        assert [n for n, _ in operation.arguments] == inputs


def test_gps_has_its_device_kind_in_the_extension_range() -> None:
    from openel_async.ids import EXTENSION_KIND_IDS, profile_name
    from openel_async.sensor_kinds import HAL4RT_KIND_NAMES, sensor_class

    assert DeviceKind.GPS in EXTENSION_KIND_IDS and DeviceKind.GPS == 0x7F00_0001
    assert HAL4RT_KIND_NAMES[DeviceKind.GPS] == "GPSSensor"
    assert sensor_class(DeviceKind.GPS) is GPSSensor
    assert profile_name(DeviceKind.GPS) == "Gps"
    assert profile_of(FixedGps).kind_name == "GPSSensor"
    gps = GPSSensor(FixedGps(), clock=VirtualClock())
    assert kind_of(gps) == "GPSSensor" and gps.component_name == "HalGpsOpenELFixedGps"


async def test_the_xml_samples_run_on_the_kinds(hal_components: ComponentStack) -> None:
    """tests/surface/samples: a GPS and a Direction Device, as a client would send them."""
    from pathlib import Path

    from openel_async.surface.xml_psm import device_from_xml

    samples = Path(__file__).parent / "samples"
    gps = await hal_components.enter(GPSSensor(FixedGps(), clock=hal_components.clock))
    compass = await hal_components.enter(
        DirectionSensor(SimMagnetometer(), frame="FRD", clock=hal_components.clock)
    )
    async with Surface([gps, compass]) as surface:
        sent = device_from_xml((samples / "gps_get_time_result.xml").read_bytes())
        reply = await surface.execute(sent)
        got = [c.results.as_dict() for c in reply.commands if c.results is not None]
        assert got == [{"return_code": 0, "time": FIX.time_ms}, {"return_code": 0}]
        assert [r.as_dict() for r in (c.results for c in sent.commands) if r] == got
        sent = device_from_xml((samples / "direction_set_date_get_d.xml").read_bytes())
        reply = await surface.execute(sent)
        d = reply.commands[1].results
        assert d is not None and d.value("D") == compass.get_d()


def test_gps_profile_vendor_functions_are_the_devices() -> None:
    """The NMEA receiver's profile listed set_target and get_distance as its vendor
    functions: they are the GPS Sensor's kind commands (0x381, 0x382), not the device's."""
    profile = profile_of(NmeaGps)
    vendor = [c for c in profile.commands if c.id >= 0x1000]
    assert [c.name for c in vendor] == ["next_fix"]
    assert all(hasattr(NmeaGps, c.method) for c in vendor)
    assert profile.command("SetTarget").id == 0x381 and profile.command("GetDistance").id == 0x382
