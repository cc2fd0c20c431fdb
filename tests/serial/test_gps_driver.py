"""NmeaGps end to end: SimGps on a pty -> pyserial-asyncio-fast -> NmeaParser -> Sensor."""

from __future__ import annotations

import datetime as dt
import math
from collections.abc import AsyncIterator

import anyio
import pytest

from openel_async import (
    BadParameterError,
    ComponentState,
    ErrorId,
    HALError,
    ReturnCode,
    Sensor,
)
from openel_async.gps import GPS_UNITS, GPS_VALUE_NAMES
from openel_async.testing import EventRecorder
from openel_serial import DRIVER, NmeaGps, NoFixError
from openel_serial.gps import DEFAULT_UERE_M
from openel_serial.peers import GpsPath, SimGps

from .conftest import WAIT_S

pytestmark = pytest.mark.timeout(20)

RATE_HZ = 20.0  # an epoch (GGA + RMC) every 50 ms keeps the tests short
TRACK = GpsPath(latitude=48.8584, longitude=2.2945, altitude=35.0, speed=4.0, course=30.0)


@pytest.fixture
async def gps() -> AsyncIterator[SimGps]:
    async with SimGps(rate_hz=RATE_HZ, track=TRACK) as peer:
        yield peer


async def next_fixes(device: NmeaGps, count: int) -> None:
    with anyio.fail_after(WAIT_S):
        for _ in range(count):
            await device.next_fix()


async def test_values_units_and_monotonic_timestamps(gps: SimGps, recorder: EventRecorder) -> None:
    device = NmeaGps(gps.path, baudrate=9600)
    async with Sensor(device) as sensor:
        sensor.add_observer(recorder)
        assert sensor.units == GPS_UNITS
        readings = []
        for _ in range(4):
            with anyio.fail_after(WAIT_S):
                fix = await device.next_fix()
                while fix.sentences % 2:  # GGA then RMC: read once both of an epoch arrived
                    fix = await device.next_fix()
            readings.append(await sensor.get_timed_value())
        times = [r.time_ns for r in readings]
        assert times == sorted(times) and len(set(times)) == len(times)
        assert all(t <= sensor.get_time() for t in times)
        values = dict(zip(GPS_VALUE_NAMES, readings[-1].values, strict=True))
        assert readings[-1].num == len(GPS_VALUE_NAMES)
        # Position on the track at the receiver's own UTC time (GPS time, not ours).
        fix = device.fix
        assert fix.utc is not None and fix.utc.date() == dt.date(2024, 5, 1)
        assert fix.fix_utc == fix.utc
        elapsed = (fix.utc - gps.start_utc).total_seconds()
        want_lat, want_lon, _ = TRACK.at(elapsed)
        assert values["latitude"] == pytest.approx(want_lat, abs=1e-6)
        assert values["longitude"] == pytest.approx(want_lon, abs=1e-6)
        assert values["altitude"] == 35.0 + 39.5  # MSL + geoid separation
        assert (values["fix_quality"], values["satellites"], values["dop"]) == (1.0, 9.0, 0.9)
        assert values["accuracy"] == pytest.approx(0.9 * DEFAULT_UERE_M)  # no GST
        assert values["speed"] == pytest.approx(4.0, abs=1e-3)  # knots on the wire, m/s out
        assert values["course"] == pytest.approx(30.0)
        assert values["time"] == pytest.approx(fix.utc.timestamp() * 1000)
        assert values["stale"] == 0.0
        # The receiver moves: later fixes are further along the track (north-east).
        assert readings[-1].values[0] > readings[0].values[0]
        assert device.parser.checksum_errors == 0 and recorder.errors == []


async def test_lost_fix_keeps_the_position_and_reads_stale(gps: SimGps) -> None:
    device = NmeaGps(gps.path)
    async with Sensor(device) as sensor:
        await next_fixes(device, 2)
        gps.fix_quality = 0
        with anyio.fail_after(WAIT_S):
            while device.fix.valid:
                await device.next_fix()
        position = device.fix.latitude, device.fix.longitude
        await next_fixes(device, 4)  # two epochs without a fix
        assert (device.fix.latitude, device.fix.longitude) == position
        values = dict(zip(GPS_VALUE_NAMES, await sensor.get_value(), strict=True))
        assert (values["latitude"], values["longitude"]) == position
        assert values["stale"] == 1.0 and values["fix_quality"] == 0.0
        assert sensor.state is ComponentState.ACTIVE


async def test_corrupted_checksums_and_garbage_are_counted_and_dropped(
    gps: SimGps, recorder: EventRecorder
) -> None:
    device = NmeaGps(gps.path)
    async with Sensor(device) as sensor:
        sensor.add_observer(recorder)
        await next_fixes(device, 1)
        merged = device.fix.sentences
        gps.corrupt_checksums = 4  # the next two epochs (GGA + RMC each)
        gps.inject_garbage(b"\x00\xff\x13noise\r\n$GPGGA,broken*00\r\n")
        # The epoch after the corrupted ones still arrives and is merged.
        with anyio.fail_after(WAIT_S):
            while gps.corrupted < 4 or device.fix.sentences < merged + 2:
                await device.next_fix()
        assert device.parser.checksum_errors == 5  # 4 corrupted + the broken GGA
        assert device.parser.malformed >= 1  # the noise line without '$'
        # Exactly the good sentences were merged: nothing corrupted slipped through.
        assert device.fix.sentences == device.parser.sentences
        assert sensor.state is ComponentState.ACTIVE and recorder.errors == []


async def test_stale_fix_faults_with_timeout_and_re_init_recovers(
    gps: SimGps, recorder: EventRecorder
) -> None:
    device = NmeaGps(gps.path, stale_timeout=0.2)
    async with Sensor(device) as sensor:
        sensor.add_observer(recorder)
        await next_fixes(device, 1)
        gps.paused = True
        await recorder.wait_for("error", ErrorId.TIMEOUT, timeout=WAIT_S)
        assert sensor.state is ComponentState.ERROR
        assert sensor.last_fault is not None and "no NMEA sentence" in str(sensor.last_fault)
        # Still silent: re_init waits up to stale_timeout for a sentence and fails.
        with pytest.raises(HALError):
            await sensor.re_init()
        assert sensor.state is ComponentState.ERROR
        gps.paused = False
        await sensor.re_init()
        assert sensor.state is ComponentState.ACTIVE
        assert len(await sensor.get_value()) == len(GPS_VALUE_NAMES)
        assert recorder.count("error", ErrorId.TIMEOUT) == 1


async def test_unplugged_receiver_faults_and_re_init_reopens(
    gps: SimGps, recorder: EventRecorder
) -> None:
    device = NmeaGps(gps.path, stale_timeout=1.0)
    async with Sensor(device) as sensor:
        sensor.add_observer(recorder)
        await next_fixes(device, 1)
        gps.unplug()
        await recorder.wait_for("error", ErrorId.DISCONNECTED, timeout=WAIT_S)
        assert sensor.last_fault is not None
        assert sensor.last_fault.code is ReturnCode.HAL_NO_CONNECTED
        gps.plug()
        await sensor.re_init()
        assert sensor.state is ComponentState.ACTIVE and device.link.opens == 2
        before = device.fix.sentences
        await next_fixes(device, 1)
        assert device.fix.sentences > before


async def test_no_position_yet_raises_no_fix() -> None:
    async with SimGps(rate_hz=RATE_HZ, fix_quality=0) as gps:
        device = NmeaGps(gps.path)
        async with Sensor(device) as sensor:
            await next_fixes(device, 2)
            assert device.fix.fix_quality == 0 and not device.fix.has_position
            with pytest.raises(NoFixError):
                await sensor.get_value()
            assert sensor.state is ComponentState.ACTIVE


def test_bad_configuration_names_the_parameter() -> None:
    with pytest.raises(BadParameterError, match="url"):
        NmeaGps("")
    with pytest.raises(BadParameterError, match="stale_timeout"):
        NmeaGps("/dev/ttyUSB0", stale_timeout=0)
    with pytest.raises(BadParameterError, match="uere"):
        NmeaGps("/dev/ttyUSB0", uere=math.nan)
    with pytest.raises(BadParameterError, match="ack_timeout"):
        NmeaGps("/dev/ttyUSB0", ack_timeout=-1)
    with pytest.raises(BadParameterError, match="baudrate"):
        NmeaGps("/dev/ttyUSB0", baudrate=-1)
    assert DRIVER.devices["nmea_gps"] is NmeaGps
