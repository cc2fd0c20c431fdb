"""HAL4RT Direction Sensor (§7.4.5.14): the WMM through pygeomag, checked on NOAA's
published WMM2025 test values, and the heading of the sim and MuJoCo magnetometers."""

from __future__ import annotations

import datetime as dt
import math
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import anyio
import mujoco
import pytest

from openel_async import (
    Actuator,
    BadParameterError,
    ComponentState,
    HALError,
    Request,
    StateError,
    VirtualClock,
)
from openel_async.direction import DirectionSensor, MagneticModel, heading_deg
from openel_mujoco import MujocoSim
from openel_mujoco.devices import geomagnetic_field_enu, set_geomagnetic_field
from openel_sim import SimEncoder, SimMotor
from openel_sim.sensors import SimMagnetometer

pytestmark = pytest.mark.timeout(20)

TEST_VALUES = Path(__file__).with_name("WMM2025_TEST_VALUES.txt")
ROWS = [
    tuple(float(x) for x in line.split())
    for line in TEST_VALUES.read_text().splitlines()
    if line.strip() and not line.startswith("#")
]
TOKYO = (35.6812, 139.7671, 40.0)


def off(a: float, b: float) -> float:
    """Angular distance of two headings (degrees)."""
    return abs((a - b + 180.0) % 360.0 - 180.0)


def test_the_official_table_is_complete() -> None:
    assert len(ROWS) == 12 and all(len(r) == 11 for r in ROWS)


@pytest.mark.parametrize("row", ROWS, ids=lambda r: f"{r[0]}-{r[1]:g}km-{r[2]:g}-{r[3]:g}")
def test_model_matches_the_published_wmm2025_test_values(row: tuple[float, ...]) -> None:
    date, height_km, lat, lon, x, y, z, h, f, inc, dec = row
    lon = lon - 360 if lon > 180 else lon  # the table gives 240 E
    field = MagneticModel().field(lat, lon, height_km * 1000, date)
    # The table is rounded to 0.1 nT and 0.01 degree.
    for ours, published in ((field.x, x), (field.y, y), (field.z, z), (field.h, h), (field.f, f)):
        assert ours == pytest.approx(published, abs=0.05 + 1e-6)
    assert field.i == pytest.approx(inc, abs=0.005 + 1e-6)
    assert field.d == pytest.approx(dec, abs=0.005 + 1e-6)


@pytest.fixture
async def compass() -> AsyncIterator[DirectionSensor]:
    async with DirectionSensor(SimMagnetometer(), frame="FRD", clock=VirtualClock()) as sensor:
        yield sensor


async def test_getters_give_the_model_at_the_place_and_date_set(
    compass: DirectionSensor,
) -> None:
    date, height_km, lat, lon, x, y, z, h, f, inc, dec = ROWS[8]  # 2027.5, -80, 240
    compass.set_latitude(lat)
    compass.set_longitude(lon - 360)
    compass.set_altitude(height_km * 1000)
    compass.set_date(date)
    got = (compass.get_x(), compass.get_y(), compass.get_z(), compass.get_h(), compass.get_f())
    assert got == pytest.approx((x, y, z, h, f), abs=0.05 + 1e-6)
    assert compass.get_i() == pytest.approx(inc, abs=0.006)
    assert compass.get_d() == pytest.approx(dec, abs=0.006)
    # A date as a datetime.date: the start of that day, 2027-07-02 is day 182 of 365.
    compass.set_date(dt.date(2027, 7, 2))
    assert compass.date == pytest.approx(2027 + 182 / 365, abs=1e-12)
    compass.set_date(dt.datetime(2027, 7, 2, 12, tzinfo=dt.UTC))
    assert compass.date == pytest.approx(2027 + 182.5 / 365, abs=1e-12)
    assert compass.get_d() == pytest.approx(dec, abs=0.006)


async def test_no_date_yet_is_an_error(compass: DirectionSensor) -> None:
    with pytest.raises(HALError, match="set_date"):
        compass.get_d()


@pytest.mark.parametrize(
    "date",
    [2024.999, 2030.001, dt.date(2031, 1, 1), dt.date(2024, 12, 31), math.nan, math.inf,
     "2026", None, True],
)  # fmt: skip
async def test_a_date_outside_the_model_is_refused_and_changes_nothing(
    compass: DirectionSensor, date: Any
) -> None:
    compass.set_date(2026.0)
    before = compass.get_d()
    with pytest.raises(BadParameterError, match="date") as err:
        compass.set_date(date)
    assert "2025..2030" in str(err.value) and err.value.parameter == "date"
    assert compass.date == 2026.0 and compass.get_d() == before
    with pytest.raises(BadParameterError, match="date"):
        MagneticModel().field(0.0, 0.0, 0.0, date)


@pytest.mark.parametrize(
    ("setter", "value"),
    [("set_latitude", 90.01), ("set_latitude", -91), ("set_latitude", math.nan),
     ("set_longitude", 180.5), ("set_longitude", -math.inf), ("set_longitude", "1"),
     ("set_altitude", -1500.0), ("set_altitude", 900_000.0), ("set_altitude", math.nan)],
)  # fmt: skip
async def test_bad_place_is_refused_and_changes_nothing(
    compass: DirectionSensor, setter: str, value: Any
) -> None:
    compass.set_date(2026.0)
    compass.set_latitude(10.0)
    compass.set_longitude(20.0)
    compass.set_altitude(100.0)
    before = compass.field()
    with pytest.raises(BadParameterError, match=setter.removeprefix("set_")):
        getattr(compass, setter)(value)
    assert (compass.latitude, compass.longitude, compass.altitude) == (10.0, 20.0, 100.0)
    assert compass.field() == before


@pytest.mark.parametrize("psi", [0.0, 30.0, 135.0, 250.0, 359.0])
async def test_sim_magnetometer_heading_corrected_by_the_declination(psi: float) -> None:
    model = MagneticModel()
    field = model.field(*TOKYO, 2026.25)
    device = SimMagnetometer(field_ned_nt=(field.x, field.y, field.z), mount_yaw=math.radians(psi))
    async with DirectionSensor(device, frame="FRD", clock=VirtualClock()) as compass:
        compass.set_latitude(TOKYO[0])
        compass.set_longitude(TOKYO[1])
        compass.set_altitude(TOKYO[2])
        compass.set_date(2026.25)
        assert compass.get_d() == pytest.approx(field.d) and field.d < -7  # west in Tokyo
        magnetic = await compass.get_magnetic_heading()
        assert off(magnetic, psi - field.d) < 1e-9
        assert off(await compass.get_heading(), psi) < 1e-9


async def test_heading_follows_a_yawing_motor_on_the_virtual_clock() -> None:
    clock = VirtualClock()
    motor = SimMotor()
    field = MagneticModel().field(*TOKYO, 2026.0)
    device = SimMagnetometer(motor, field_ned_nt=(field.x, field.y, field.z))
    async with (
        clock.autojump(),
        Actuator(motor, clock=clock) as yaw,
        DirectionSensor(device, frame="FRD", clock=clock) as compass,
    ):
        compass.set_latitude(TOKYO[0])
        compass.set_longitude(TOKYO[1])
        compass.set_date(2026.0)
        assert off(await compass.get_heading(), 0.0) < 1e-3
        motion = await yaw.set_value(math.radians(90.0), Request.POSITION)
        with anyio.fail_after(5):
            await motion
        assert off(await compass.get_heading(), 90.0) < 0.1


def _mujoco_model(yaw_deg: float) -> mujoco.MjModel:
    xml = f"""
    <mujoco model="compass">
      <option timestep="0.002" gravity="0 0 0"/>
      <worldbody>
        <body name="robot" euler="0 0 {yaw_deg}">
          <geom type="box" size="0.1 0.05 0.02" mass="1"/>
          <site name="imu"/>
        </body>
      </worldbody>
      <sensor><magnetometer name="mag" site="imu"/></sensor>
    </mujoco>
    """
    return mujoco.MjModel.from_xml_string(xml)


@pytest.mark.parametrize("yaw", [0.0, 45.0, 90.0, 200.0, -60.0])
async def test_mujoco_magnetometer_heading(yaw: float) -> None:
    # The world frame is ENU: a body yawed by `yaw` (counter-clockwise from east) has its
    # x axis at heading 90 - yaw (clockwise from north).
    field = MagneticModel().field(*TOKYO, 2026.5)
    model = _mujoco_model(yaw)
    set_geomagnetic_field(model, field)
    assert tuple(model.opt.magnetic) == pytest.approx(geomagnetic_field_enu(field))
    sim = MujocoSim(model, sensors=["mag"])
    async with sim, DirectionSensor(sim.sensor("mag"), clock=sim.clock) as compass:
        compass.set_latitude(TOKYO[0])
        compass.set_longitude(TOKYO[1])
        compass.set_altitude(TOKYO[2])
        compass.set_date(2026.5)
        with anyio.fail_after(10):
            await sim.clock.sleep(0.01)
            heading = await compass.get_heading()
        want = (90.0 - yaw) % 360
        assert off(heading, want) < 1e-6
        # The reading is the WMM field: |B| = F (tesla).
        assert math.hypot(*await compass.get_value()) == pytest.approx(field.f * 1e-9)


def test_heading_of_no_horizontal_field_is_an_error() -> None:
    with pytest.raises(HALError, match="undefined"):
        heading_deg(0.0, 0.0, 5.0)


async def test_bad_devices_and_frames_are_refused() -> None:
    with pytest.raises(BadParameterError, match="frame"):
        DirectionSensor(SimMagnetometer(), frame="NED")  # type: ignore[arg-type]
    with pytest.raises(BadParameterError, match="device"):
        DirectionSensor(SimEncoder(SimMotor()))  # one value, and not a compass


async def test_operations_need_the_active_state() -> None:
    compass = DirectionSensor(SimMagnetometer(), frame="FRD", clock=VirtualClock())
    async with compass:
        compass.set_date(2026.0)
        await compass.finalize()
        with pytest.raises(StateError):
            compass.get_f()
        with pytest.raises(StateError):
            await compass.get_heading()


@pytest.mark.parametrize(
    ("setter", "value"),
    [("set_latitude", 10.0), ("set_longitude", 20.0), ("set_altitude", 100.0),
     ("set_date", 2026.0)],
)  # fmt: skip
async def test_setters_need_the_active_state_as_every_operation(setter: str, value: float) -> None:
    """HAL4RT §7.4.5.1: outside Active only Init (Initialized) or Reset and Exit (Error)
    are callable; the setters were accepted in any state (issue 21 point 19)."""
    compass = DirectionSensor(SimMagnetometer(), frame="FRD", clock=VirtualClock())
    before = (compass.latitude, compass.longitude, compass.altitude, compass.date)
    with pytest.raises(StateError) as never_entered:
        getattr(compass, setter)(value)
    assert never_entered.value.operation == setter
    async with compass:
        await compass.finalize()
        with pytest.raises(StateError) as finalized:
            getattr(compass, setter)(value)
        assert finalized.value.operation == setter
        assert finalized.value.state is ComponentState.FINALIZED
        assert finalized.value.allowed == (ComponentState.ACTIVE,)
    assert (compass.latitude, compass.longitude, compass.altitude, compass.date) == before
