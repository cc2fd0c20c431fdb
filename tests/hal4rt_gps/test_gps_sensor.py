"""HAL4RT GPS Sensor (§7.4.5.13): GPSSensor over NmeaGps.

The getters are checked on real receiver output (the 49 captured sentences of
``tests/serial/test_nmea_pynmea2.py``, with their origins: u-blox ZED-F9 NMEA 4.11 with GN
talkers, u-blox NEO-M8, the u-blox protocol manual's NMEA 2.3/4.1 examples, a C-Nav3050
DGPS receiver) replayed into the driver on the virtual clock; the expected values are
computed from pynmea2's independent decoding of the same sentences. The receiver peer
(a pty) is only there for the port to open; it stays silent (``paused``) unless a test
talks to it.
"""

from __future__ import annotations

import datetime as dt
import math
from collections.abc import AsyncIterator, Iterable
from typing import Any

import anyio
import pynmea2
import pytest

from openel_async import BadParameterError, ComponentState, HALError, StateError, VirtualClock
from openel_async.gps import GPS_UNITS, GPS_VALUE_NAMES, GPSSensor, bearing_deg, distance_m
from openel_async.ids import DeviceKind
from openel_serial import NmeaGps, nmea
from openel_serial.gps import DEFAULT_UERE_M, pmtk_set_period
from openel_serial.peers import GpsPath, SimGps
from tests.serial.test_nmea_pynmea2 import REAL

pytestmark = pytest.mark.timeout(20)

ZED_F9 = REAL[0:20]  # one epoch: RMC VTG GGA GSA x4 GSV x8 GLL ZDA GBS GST PUBX
NEO_M8 = REAL[20:26]
UBLOX_MANUAL = REAL[26:34]
CNAV = REAL[34:38]
KN = 1852.0 / 3600.0


def feed(device: NmeaGps, sentences: Iterable[str]) -> None:
    device.feed("".join(s + "\r\n" for s in sentences).encode("ascii"))


def parsed(sentences: Iterable[str], kind: str) -> list[Any]:
    return [
        m
        for m in (pynmea2.parse(s) for s in sentences)
        if getattr(m, "sentence_type", None) == kind
    ]


@pytest.fixture
async def silent_peer() -> AsyncIterator[SimGps]:
    async with SimGps() as peer:
        peer.paused = True  # the tests feed the driver themselves
        yield peer


@pytest.fixture
def clock() -> VirtualClock:
    return VirtualClock()


@pytest.fixture
async def gps(silent_peer: SimGps, clock: VirtualClock) -> AsyncIterator[GPSSensor]:
    async with GPSSensor(NmeaGps(silent_peer.path), clock=clock) as sensor:
        yield sensor


async def test_zed_f9_epoch_gives_every_getter_in_hal4rt_units(
    gps: GPSSensor, clock: VirtualClock
) -> None:
    await clock.advance(250_000_000)
    feed(gps.device, ZED_F9)
    gga = parsed(ZED_F9, "GGA")[-1]
    rmc = parsed(ZED_F9, "RMC")[-1]
    gst = parsed(ZED_F9, "GST")[-1]
    # GGA (after the RMC in this epoch) sets the position.
    assert await gps.get_latitude() == pytest.approx(gga.latitude, abs=1e-12)
    assert await gps.get_longitude() == pytest.approx(gga.longitude, abs=1e-12)
    # Altitude above the ellipsoid: MSL altitude + geoid separation.
    assert await gps.get_altitude() == pytest.approx(gga.altitude + float(gga.geo_sep))
    # GST is sent: accuracy from its sigmas, not from HDOP.
    assert await gps.get_accuracy() == pytest.approx(
        math.hypot(gst.std_dev_latitude, gst.std_dev_longitude)
    )
    assert await gps.get_dop() == float(gga.horizontal_dil)
    when = dt.datetime.combine(rmc.datestamp, gga.timestamp)
    assert await gps.get_fix_time() == pytest.approx(when.timestamp() * 1000, abs=1e-3)
    assert await gps.get_speed() == pytest.approx(rmc.spd_over_grnd * KN)
    with pytest.raises(HALError, match="course not available"):
        await gps.get_course()  # the receiver left it empty (standing still)
    # Signal strength: mean C/N0 of the tracked satellites over complete GSV cycles per
    # talker and signal id; the GL cycle of this capture mixes signal ids 1 and B, so
    # neither of its signal cycles is complete and it does not count.
    snrs = [
        float(s)
        for m in parsed(ZED_F9, "GSV")
        if m.talker != "GL"
        for s in (m.snr_1, m.snr_2, m.snr_3, m.snr_4)
        if s not in (None, "")
    ]
    assert await gps.get_signal_strength() == pytest.approx(sum(snrs) / len(snrs))
    assert not await gps.is_stale()
    fix = await gps.get_fix()
    assert fix.time_ns == 250_000_000 and fix.satellites == 6 and fix.fix_quality == 1


async def test_get_value_is_the_same_quantities_in_order(
    gps: GPSSensor, clock: VirtualClock
) -> None:
    feed(gps.device, UBLOX_MANUAL[:2])  # GGA with HDOP, RMC with speed and course
    assert gps.units == GPS_UNITS and len(GPS_VALUE_NAMES) == len(GPS_UNITS)
    values = dict(zip(GPS_VALUE_NAMES, await gps.get_value(), strict=True))
    assert values["latitude"] == await gps.get_latitude()
    assert values["course"] == await gps.get_course() == 77.52
    assert values["speed"] == await gps.get_speed() == pytest.approx(0.004 * KN)
    assert values["time"] == await gps.get_fix_time()
    assert values["stale"] == 0.0 and values["fix_quality"] == 1.0
    assert values["signal_strength"] == 0.0  # no GSV yet: 0 in the vector...
    with pytest.raises(HALError, match="signal_strength not available"):
        await gps.get_signal_strength()  # ...and "not available" from the getter
    timed = await gps.get_timed_value()
    assert timed.time_ns == clock.now_ns()


async def test_accuracy_from_hdop_times_uere_without_gst(silent_peer: SimGps) -> None:
    for uere in (DEFAULT_UERE_M, 3.0):
        async with GPSSensor(NmeaGps(silent_peer.path, uere=uere), clock=VirtualClock()) as gps:
            feed(gps.device, UBLOX_MANUAL[:2])
            gga = parsed(UBLOX_MANUAL[:1], "GGA")[0]
            assert await gps.get_accuracy() == pytest.approx(float(gga.horizontal_dil) * uere)
            assert gps.device.fix.accuracy_source == "hdop"


async def test_dgps_receiver_and_gsa_dops(gps: GPSSensor) -> None:
    feed(gps.device, CNAV)
    gga = parsed(CNAV, "GGA")[0]
    rmc = parsed(CNAV, "RMC")[0]
    fix = await gps.get_fix()
    assert fix.fix_quality == 2 and fix.satellites == 11
    assert await gps.get_altitude() == pytest.approx(gga.altitude + float(gga.geo_sep))
    assert await gps.get_course() == float(rmc.true_course)
    feed(
        gps.device, ["$GNGSA,A,3,02,14,22,30,,,,,,,,,6.0,3.8,4.6,1*3A"]
    )  # a GNGSA (NMEA 4.1): PDOP and VDOP, HDOP stays GGA's
    assert gps.device.fix.pdop == 6.0 and gps.device.fix.vdop == 4.6
    assert await gps.get_dop() == float(gga.horizontal_dil)


async def test_multi_constellation_gsv_cycles(gps: GPSSensor) -> None:
    feed(gps.device, NEO_M8)  # GN position, GP and GL satellites (NMEA 4.0, no signal id)
    # Only the GL cycle is complete (GP's starts at message 3 of 3 in this capture).
    gl = [m for m in parsed(NEO_M8, "GSV") if m.talker == "GL"]
    snrs = [
        float(s) for m in gl for s in (m.snr_1, m.snr_2, m.snr_3, m.snr_4) if s not in (None, "")
    ]
    assert gps.device.fix.snr == tuple(int(s) for s in snrs)
    assert await gps.get_signal_strength() == pytest.approx(sum(snrs) / len(snrs))
    rmc = parsed(NEO_M8, "RMC")[0]
    assert await gps.get_latitude() == pytest.approx(rmc.latitude, abs=1e-12)


def _gga(lat: str, lon: str, quality: int, time: str = "120000.00") -> str:
    body = f"GPGGA,{time},{lat},{lon},{quality},08,1.0,100.0,M,40.0,M,,"
    return f"${body}*{nmea.checksum(body):02X}"


def _rmc(status: str, lat: str, lon: str, time: str = "120000.00", date: str = "010524") -> str:
    body = f"GPRMC,{time},{status},{lat},{lon},1.0,90.0,{date},,,{'A' if status == 'A' else 'N'}"
    return f"${body}*{nmea.checksum(body):02X}"


async def test_lost_fix_keeps_the_last_position_and_says_stale(gps: GPSSensor) -> None:
    a_lat, a_lon = "4807.03800,N", "01131.00000,E"
    b_lat, b_lon = "4807.10000,N", "01131.20000,E"
    feed(gps.device, [_rmc("A", a_lat, a_lon), _gga(a_lat, a_lon, 1)])
    first = await gps.get_value()
    assert first[GPS_VALUE_NAMES.index("stale")] == 0.0
    # Receivers without a fix: a void RMC with a (dead-reckoned) position, a GGA with
    # quality 0 and a position: neither moves the fix.
    feed(gps.device, [_rmc("V", b_lat, b_lon, "120001.00"), _gga(b_lat, b_lon, 0, "120001.00")])
    assert await gps.is_stale()
    stale = await gps.get_value()
    keep = ("latitude", "longitude", "altitude", "time", "speed", "course")
    for name in keep:
        i = GPS_VALUE_NAMES.index(name)
        assert stale[i] == first[i], name
    assert stale[GPS_VALUE_NAMES.index("stale")] == 1.0
    assert stale[GPS_VALUE_NAMES.index("fix_quality")] == 0.0
    assert await gps.get_latitude() == pytest.approx(48 + 7.038 / 60)
    # Each alone also refuses to move it.
    feed(gps.device, [_rmc("V", b_lat, b_lon, "120002.00")])
    feed(gps.device, [_gga(b_lat, b_lon, 0, "120002.00")])
    assert await gps.get_longitude() == pytest.approx(11 + 31 / 60)
    # The fix comes back: the position moves, no longer stale.
    feed(gps.device, [_rmc("A", b_lat, b_lon, "120003.00"), _gga(b_lat, b_lon, 1, "120003.00")])
    assert not await gps.is_stale()
    assert await gps.get_latitude() == pytest.approx(48 + 7.1 / 60)
    when = dt.datetime(2024, 5, 1, 12, 0, 3, tzinfo=dt.UTC)
    assert await gps.get_fix_time() == when.timestamp() * 1000


async def test_fix_time_crosses_midnight_when_gga_comes_before_rmc(gps: GPSSensor) -> None:
    lat, lon = "3540.87000,N", "13946.02000,E"
    feed(gps.device, [_gga(lat, lon, 1, "235959.50"), _rmc("A", lat, lon, "235959.50", "311224")])
    feed(gps.device, [_gga(lat, lon, 1, "000000.50")])  # the RMC with the new date not yet
    when = dt.datetime(2025, 1, 1, 0, 0, 0, 500_000, tzinfo=dt.UTC)
    assert await gps.get_fix_time() == when.timestamp() * 1000


async def test_no_position_yet_raises_and_kind_is_gps(gps: GPSSensor) -> None:
    assert gps.hal_id.device_kind is DeviceKind.GPS
    with pytest.raises(HALError, match="no position"):
        await gps.get_latitude()
    assert gps.state is ComponentState.ACTIVE


async def test_angle_and_distance_to_a_target(gps: GPSSensor) -> None:
    with pytest.raises(HALError, match="set_target"):
        await gps.get_angle()
    feed(gps.device, [_rmc("A", "0000.00000,N", "00000.00000,E")])
    for (lat, lon), want in (((1.0, 0.0), 0.0), ((0.0, 1.0), 90.0), ((-1.0, 0.0), 180.0)):
        gps.set_target(lat, lon)
        assert await gps.get_angle() == pytest.approx(want, abs=1e-9)
        # One degree of a great circle of the mean Earth radius.
        assert await gps.get_distance() == pytest.approx(6_371_008.8 * math.pi / 180)
    gps.set_target(0.0, -1.0)
    assert await gps.get_angle() == pytest.approx(270.0)
    # Paris -> New York, against the published great-circle values (5837 km, 291.8 deg).
    assert distance_m(48.8566, 2.3522, 40.7128, -74.0060) == pytest.approx(5_837_000, rel=2e-3)
    assert bearing_deg(48.8566, 2.3522, 40.7128, -74.0060) == pytest.approx(291.8, abs=0.1)


@pytest.mark.parametrize(
    ("latitude", "longitude", "name"),
    [(90.5, 0.0, "latitude"), (math.nan, 0.0, "latitude"), (0.0, 180.5, "longitude"),
     (0.0, -math.inf, "longitude"), ("1", 0.0, "latitude"), (True, 0.0, "latitude")],
)  # fmt: skip
async def test_bad_target_is_refused_and_changes_nothing(
    gps: GPSSensor, latitude: Any, longitude: Any, name: str
) -> None:
    gps.set_target(10.0, 20.0)
    with pytest.raises(BadParameterError, match=name):
        gps.set_target(latitude, longitude)
    assert gps.target == (10.0, 20.0)


@pytest.mark.parametrize("period", [0, -100, math.nan, math.inf, "200", True, 50, 20_000])
async def test_bad_period_is_refused_and_nothing_is_sent(
    gps: GPSSensor, silent_peer: SimGps, period: Any
) -> None:
    with pytest.raises(BadParameterError, match="period_ms"):
        await gps.set_period(period)
    assert gps.period_ms is None and silent_peer.commands == []


def test_pmtk220_matches_the_published_commands() -> None:
    # Adafruit_GPS.h PMTK_SET_NMEA_UPDATE_1HZ / _5HZ / _10HZ (MediaTek PMTK manual).
    assert pmtk_set_period(1000) == b"$PMTK220,1000*1F\r\n"
    assert pmtk_set_period(200) == b"$PMTK220,200*2C\r\n"
    assert pmtk_set_period(100) == b"$PMTK220,100*2F\r\n"


async def test_set_period_sends_pmtk220_and_the_receiver_follows() -> None:
    clock = VirtualClock()
    async with (
        SimGps(rate_hz=1.0, clock=clock) as peer,
        GPSSensor(NmeaGps(peer.path, stale_timeout=60), clock=clock) as gps,
    ):
        with anyio.fail_after(5):
            await gps.set_period(200)  # the acknowledgement comes over the pty
        assert gps.period_ms == 200.0 and peer.period_ms == 200.0
        assert peer.commands == ["$PMTK220,200*2C"]
        before = peer.epochs
        await clock.advance(2_000_000_000)
        assert peer.epochs - before == 10  # 5 Hz on the receiver's (virtual) clock
        with anyio.fail_after(5):
            await gps.set_period(1000.4)  # whole milliseconds on the wire
        assert gps.period_ms == 1000.0 and peer.commands[-1] == "$PMTK220,1000*1F"


async def test_a_receiver_that_ignores_pmtk_leaves_the_period_unchanged() -> None:
    async with (
        SimGps(pmtk=False) as peer,
        GPSSensor(NmeaGps(peer.path, ack_timeout=0.2)) as gps,
    ):
        with anyio.fail_after(5), pytest.raises(HALError, match="no \\$PMTK001"):
            await gps.set_period(500)
        assert gps.period_ms is None and peer.commands == ["$PMTK220,500*2B"]
        assert gps.state is ComponentState.ACTIVE


async def test_simulated_receiver_end_to_end_with_gsv_and_gst() -> None:
    track = GpsPath(latitude=35.6812, longitude=139.7671, altitude=40.0, speed=5.0, course=90)
    async with (
        SimGps(rate_hz=20, track=track, extended=True, sigma=(1.5, 2.0)) as peer,
        GPSSensor(NmeaGps(peer.path)) as gps,
    ):
        with anyio.fail_after(5):
            await gps.device.next_fix()
            await gps.device.next_fix()
            while gps.device.fix.latitude_sigma is None or not gps.device.fix.snr:
                await gps.device.next_fix()
        assert await gps.get_accuracy() == pytest.approx(2.5)
        assert await gps.get_signal_strength() == pytest.approx(sum(peer.snr) / len(peer.snr))
        assert await gps.get_altitude() == pytest.approx(40.0 + 39.5)
        assert await gps.get_course() == 90.0
        assert await gps.get_dop() == 0.9
        assert gps.device.fix.pdop == pytest.approx(1.44)


async def test_operations_need_the_active_state(silent_peer: SimGps) -> None:
    gps = GPSSensor(NmeaGps(silent_peer.path), clock=VirtualClock())
    async with gps:
        feed(gps.device, UBLOX_MANUAL[:2])
        await gps.finalize()
        with pytest.raises(StateError):
            await gps.get_latitude()
        with pytest.raises(StateError):
            await gps.set_period(1000)


async def test_set_target_needs_the_active_state_as_every_operation(
    silent_peer: SimGps,
) -> None:
    """HAL4RT §7.4.5.1: outside Active only Init (Initialized) or Reset and Exit (Error)
    are callable; set_target was accepted in any state (issue 21 point 19)."""
    gps = GPSSensor(NmeaGps(silent_peer.path), clock=VirtualClock())
    with pytest.raises(StateError) as before:  # never entered
        gps.set_target(1.0, 2.0)
    assert before.value.operation == "set_target"
    assert gps.target is None  # (the message for a never-entered component is its own)
    async with gps:
        gps.set_target(1.0, 2.0)
        await gps.finalize()
        for call in (lambda: gps.set_target(3.0, 4.0), lambda: gps.set_target(99.0, 0.0)):
            with pytest.raises(StateError) as after:
                call()
            assert after.value.operation == "set_target"
            assert after.value.state is ComponentState.FINALIZED
            assert after.value.allowed == (ComponentState.ACTIVE,)
        assert gps.target == (1.0, 2.0)
        for name in ("get_angle", "get_distance"):
            with pytest.raises(StateError) as getter:
                await getattr(gps, name)()
            assert getter.value.operation == name
