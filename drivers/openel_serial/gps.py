"""NmeaGps: an NMEA 0183 GPS receiver on a serial port, as HAL4RT's GPS sensor.

The receiver's lines are parsed as they arrive (in the transport's callback, no task
in between) by :class:`~openel_serial.nmea.NmeaParser`: sentences with a bad checksum
or malformed fields are counted and dropped. What each sentence gives:

=====  ================================================================================
GGA    position, altitude above mean sea level and geoid separation, fix quality,
       satellites used, HDOP, UTC time of the fix
RMC    position, speed and course over ground, UTC date and time, status A/V
GSA    PDOP, HDOP, VDOP
GSV    C/N0 ("SNR", dB-Hz) of the satellites in view, per talker and NMEA 4.1 signal
GST    standard deviations of the latitude and longitude errors (m)
=====  ================================================================================

:class:`NmeaGps` is a :class:`~openel_async.gps.GPSDevice`: use it with
:class:`~openel_async.gps.GPSSensor` for HAL4RT's named getters, whose values come from
:meth:`NmeaGps.read_gps` (``GPSData``, HAL4RT's units):

* latitude, longitude: degrees; altitude: metres above the WGS-84 ellipsoid, GGA's
  altitude above mean sea level plus its geoid separation (unavailable when the GGA
  has no separation field);
* accuracy: ``hypot(sigma_lat, sigma_lon)`` of the latest GST when the receiver sends
  GST, else ``HDOP * uere`` with ``uere`` (default :data:`DEFAULT_UERE_M`) the user
  equivalent range error; ``GpsFix.accuracy_source`` says which;
* dop: HDOP (GGA, else GSA); time: ms since 1970 UTC from the fix's UTC time and the
  RMC date (a GGA time earlier than the previous one by more than 12 h moves the date
  to the next day, for receivers that send GGA before RMC at midnight);
* speed: m/s (knots on the wire); course: degrees true in [0, 360);
* signal strength: mean C/N0 over the satellites tracked (GSV SNR field not empty) in
  the latest complete GSV cycle of each talker and signal id.

**No fix.** A RMC with status V (or FAA mode N) or a GGA with fix quality 0 does not
move the position, altitude, speed, course or fix time: they keep the last valid fix,
and ``stale`` says the receiver reports no fix now. ``read`` raises
:class:`~openel_serial.errors.NoFixError` until a first valid position arrived.

**Rate.** :meth:`NmeaGps.set_period` sends MediaTek's ``$PMTK220,<ms>`` (MT3333/MT3339
chipsets: Adafruit Ultimate GPS, GlobalTop PA6H, Quectel L76/L80/L86, 100..10000 ms) and
waits for its ``$PMTK001,220,<flag>`` acknowledgement (3: done). Other receiver
families (u-blox UBX-CFG-RATE, SiRF) do not understand it: no acknowledgement within
``ack_timeout`` raises ``HALError`` and the period is unchanged.

The timestamp (``Reading.time_ns``, ``GPSData.time_ns``) is the component clock's time
when the latest sentence was merged; the receiver's own UTC time is in ``GPSData.time_ms``.

No valid GGA/RMC for ``stale_timeout`` seconds faults the component with
``ErrorId.TIMEOUT`` (silent receiver); a vanished port with ``ErrorId.DISCONNECTED``.
``re_init`` reopens the port if needed and waits (up to ``stale_timeout``) for a
fresh sentence.
"""

from __future__ import annotations

import datetime as dt
import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any, Final, Literal

import anyio

from openel_async.device import DeviceContext, DeviceInfo, ErrorId
from openel_async.errors import BadParameterError, HALError, NotImplementedHALError, ReturnCode
from openel_async.gps import GPSData, GPSDevice
from openel_async.ids import DeviceKind
from openel_async.logs import get_logger
from openel_serial import nmea
from openel_serial.errors import NoFixError, PortDisconnectedError
from openel_serial.link import SerialLink

__all__ = ["DEFAULT_UERE_M", "GpsFix", "NmeaGps", "pmtk_set_period"]

log = get_logger(__name__)

DEFAULT_UERE_M: Final = 5.0
"""User equivalent range error (1 sigma, m) of a single-frequency GPS receiver without
corrections, for ``accuracy = HDOP * UERE`` when the receiver sends no GST."""

PMTK_PERIOD_RANGE_MS: Final = (100.0, 10_000.0)
"""Output periods PMTK220 accepts on MT3333/MT3339 receivers."""

_DAY: Final = dt.timedelta(days=1)
_HALF_DAY_S: Final = 12 * 3600


def pmtk_set_period(period_ms: int) -> bytes:
    """MediaTek's ``$PMTK220,<ms>*hh`` command: send a fix every ``period_ms`` ms."""
    return nmea.format_sentence("PMTK220", [str(period_ms)]).encode("ascii")


@dataclass(frozen=True, slots=True)
class GpsFix:
    """The receiver's data merged from GGA, RMC, GSA, GSV and GST (angles in degrees).

    Position, altitude, speed, course and ``fix_utc`` are those of the last valid fix.
    """

    time_ns: int = 0
    """Component clock time at which the latest sentence was merged."""
    utc_time: dt.time | None = None
    """The receiver's latest UTC time of day (any GGA/RMC, valid or not)."""
    utc_date: dt.date | None = None
    fix_utc: dt.datetime | None = None
    """UTC date and time of the last valid fix (needs the date of an RMC)."""
    latitude: float | None = None
    longitude: float | None = None
    altitude: float | None = None
    """m above mean sea level (GGA)."""
    geoid_separation: float | None = None
    """m, the geoid above the WGS-84 ellipsoid (GGA)."""
    speed: float | None = None
    """m/s over ground."""
    course: float | None = None
    """degrees true, [0, 360)."""
    fix_quality: int = 0
    satellites: int | None = None
    hdop: float | None = None
    pdop: float | None = None
    vdop: float | None = None
    latitude_sigma: float | None = None
    """m (GST)."""
    longitude_sigma: float | None = None
    """m (GST)."""
    snr: tuple[int, ...] = ()
    """C/N0 (dB-Hz) of the satellites tracked in the latest GSV cycles."""
    valid: bool = False
    """The latest GGA/RMC reported a fix (GGA quality > 0, RMC status A)."""
    sentences: int = 0
    """GGA/RMC sentences merged so far."""

    @property
    def utc(self) -> dt.datetime | None:
        """The receiver's latest UTC date and time (needs an RMC for the date)."""
        if self.utc_time is None or self.utc_date is None:
            return None
        return dt.datetime.combine(self.utc_date, self.utc_time, tzinfo=dt.UTC)

    @property
    def has_position(self) -> bool:
        return self.latitude is not None and self.longitude is not None

    @property
    def ellipsoidal_altitude(self) -> float | None:
        """m above the WGS-84 ellipsoid: MSL altitude plus geoid separation."""
        if self.altitude is None or self.geoid_separation is None:
            return None
        return self.altitude + self.geoid_separation

    @property
    def accuracy_source(self) -> Literal["gst", "hdop", None]:
        if self.latitude_sigma is not None and self.longitude_sigma is not None:
            return "gst"
        return "hdop" if self.hdop is not None else None

    @property
    def signal_strength(self) -> float | None:
        return sum(self.snr) / len(self.snr) if self.snr else None


def _keep(new: Any, old: Any) -> Any:
    return old if new is None else new


def _seconds(t: dt.time) -> float:
    return t.hour * 3600 + t.minute * 60 + t.second + t.microsecond * 1e-6


class NmeaGps(GPSDevice):
    """A GPS receiver sending NMEA 0183 sentences on ``url`` (HAL4RT GPS device)."""

    info = DeviceInfo(
        kind=DeviceKind.GPS,
        vendor_id=0x4E4D,  # "NM"
        product_id=0x1,
        vendor_name="Generic",
        product_name="NmeaGps",
        # SetTarget and GetDistance are GPS kind commands (GPSSensor's, device_profile);
        # the device's own vendor function is next_fix.
        functions=("next_fix",),
    )
    period_range_ms = PMTK_PERIOD_RANGE_MS

    def __init__(
        self,
        url: str,
        *,
        baudrate: int = 9600,
        stale_timeout: float = 2.0,
        uere: float = DEFAULT_UERE_M,
        ack_timeout: float = 1.0,
        serial_options: Mapping[str, Any] | None = None,
    ) -> None:
        if not isinstance(url, str) or not url:
            raise BadParameterError("url", url, "a serial device path or pyserial URL")
        if isinstance(baudrate, bool) or not isinstance(baudrate, int) or baudrate <= 0:
            raise BadParameterError("baudrate", baudrate, "an int > 0 (bit/s)")
        for name, value, unit in (
            ("stale_timeout", stale_timeout, "s"),
            ("uere", uere, "m"),
            ("ack_timeout", ack_timeout, "s"),
        ):
            if (
                isinstance(value, bool)
                or not isinstance(value, int | float)
                or not (math.isfinite(value) and value > 0)
            ):
                raise BadParameterError(name, value, f"a finite number > 0 ({unit})")
        self.url = url
        self.stale_timeout = float(stale_timeout)
        self.uere = float(uere)
        self.ack_timeout = float(ack_timeout)
        self.parser = nmea.NmeaParser()
        self.fix = GpsFix()
        self.period_ms: float | None = None
        self.other_sentences = 0
        self._gsv: dict[tuple[str, str | None], list[nmea.GSV]] = {}
        self._gsv_snr: dict[tuple[str, str | None], tuple[int, ...]] = {}
        self._link = SerialLink(
            url,
            baudrate=baudrate,
            on_data=self.feed,
            on_lost=self._on_lost,
            serial_options=serial_options,
        )
        self._ctx: DeviceContext | None = None
        self._last_rx_ns = 0
        self._armed_ns = 0
        self._changed: anyio.Event | None = None
        self._ack: tuple[anyio.Event, list[int]] | None = None
        self._rate_lock = anyio.Lock()
        self._faulted = False
        self._closed = False
        self._watch_scope: anyio.CancelScope | None = None
        self._log = log.bind(port=url)

    @property
    def link(self) -> SerialLink:
        return self._link

    # -- lifecycle -------------------------------------------------------------------
    async def open(self, ctx: DeviceContext) -> None:
        self._ctx = ctx
        self._log = self._log.bind(component=ctx.name)
        self._closed = False
        self._faulted = False
        self._last_rx_ns = self._armed_ns = ctx.clock.now_ns()
        await self._link.open()
        ctx.start_soon(self._watchdog)

    async def init(self) -> None:
        self._arm()

    async def reset(self) -> None:
        ctx = self._context()
        if not self._link.is_open:
            self.parser.reset()
            await self._link.open()
        # A sentence received after this point proves the receiver talks again.
        started = ctx.clock.now_ns()
        with anyio.fail_after(self.stale_timeout):
            while self._last_rx_ns < started:
                await self._wakeup().wait()
        self._arm()

    async def close(self) -> None:
        self._closed = True
        if self._watch_scope is not None:
            self._watch_scope.cancel()
        await self._link.close()

    # -- values ----------------------------------------------------------------------
    def gps_data(self) -> GPSData:
        """The latest fix in HAL4RT's units (see the module's docstring)."""
        fix = self.fix
        accuracy: float | None = None
        if fix.latitude_sigma is not None and fix.longitude_sigma is not None:
            accuracy = math.hypot(fix.latitude_sigma, fix.longitude_sigma)
        elif fix.hdop is not None:
            accuracy = fix.hdop * self.uere
        fix_utc = fix.fix_utc
        return GPSData(
            latitude=fix.latitude,
            longitude=fix.longitude,
            accuracy=accuracy,
            dop=fix.hdop,
            altitude=fix.ellipsoidal_altitude,
            time_ms=None if fix_utc is None else fix_utc.timestamp() * 1000.0,
            speed=fix.speed,
            course=fix.course,
            signal_strength=fix.signal_strength,
            stale=not fix.valid,
            fix_quality=fix.fix_quality,
            satellites=fix.satellites,
            time_ns=fix.time_ns,
        )

    async def read_gps(self) -> GPSData:
        if not self._link.is_open:
            raise PortDisconnectedError(self.url, self._link.lost_reason or "not open")
        if not self.fix.has_position:
            raise NoFixError(f"{self.url}: no position received yet")
        return self.gps_data()

    async def next_fix(self) -> GpsFix:
        """Wait for the next GGA or RMC sentence and return the fix it updated.

        Not bounded: wrap it in ``anyio.fail_after`` (the watchdog faults the component
        after ``stale_timeout`` but does not end this wait).
        """
        count = self.fix.sentences
        while self.fix.sentences == count:
            await self._wakeup().wait()
        return self.fix

    # -- rate --------------------------------------------------------------------------
    async def set_period(self, period_ms: float) -> None:
        """``$PMTK220,<ms>`` (rounded to whole ms), then wait for ``$PMTK001,220,3``."""
        low, high = self.period_range_ms
        ms = round(period_ms)
        if not low <= ms <= high:
            raise BadParameterError("period_ms", period_ms, f"{low:g}..{high:g} ms (PMTK220)")
        async with self._rate_lock:
            if not self._link.is_open:
                raise PortDisconnectedError(self.url, self._link.lost_reason or "not open")
            event, flags = self._ack = (anyio.Event(), [])
            try:
                self._link.write(pmtk_set_period(ms))
                with anyio.move_on_after(self.ack_timeout):
                    await event.wait()
            finally:
                self._ack = None
        if not flags:
            raise HALError(
                f"{self.url}: no $PMTK001 acknowledgement of PMTK220 within "
                f"{self.ack_timeout:g} s (not a MediaTek PMTK receiver?); period unchanged"
            )
        if flags[0] == 1:
            raise NotImplementedHALError(f"{self.url}: the receiver does not support PMTK220")
        if flags[0] != 3:
            raise HALError(f"{self.url}: PMTK220,{ms} refused (PMTK001 flag {flags[0]})")
        self.period_ms = float(ms)
        self._log.info("gps_period_set", period_ms=ms)

    # -- reception (transport callback) ----------------------------------------------
    def feed(self, data: bytes) -> None:
        """Bytes from the receiver (the transport's callback; also to replay a log).

        Needs the component (``open``) for the clock; before it the bytes are ignored.
        """
        ctx = self._ctx
        if ctx is None:
            return
        sentences = self.parser.feed(data)
        if not sentences:
            return
        now = ctx.clock.now_ns()
        fix = self.fix
        merged = 0
        for sentence in sentences:
            if isinstance(sentence, nmea.GGA):
                fix = self._merge_gga(fix, sentence)
                merged += 1
            elif isinstance(sentence, nmea.RMC):
                fix = self._merge_rmc(fix, sentence)
                merged += 1
            elif isinstance(sentence, nmea.GSA):
                fix = replace(
                    fix,
                    pdop=_keep(sentence.pdop, fix.pdop),
                    vdop=_keep(sentence.vdop, fix.vdop),
                    hdop=fix.hdop if fix.hdop is not None else sentence.hdop,
                )
            elif isinstance(sentence, nmea.GSV):
                snr = self._merge_gsv(sentence)
                if snr is not None:
                    fix = replace(fix, snr=snr)
            elif isinstance(sentence, nmea.GST):
                fix = replace(
                    fix,
                    latitude_sigma=sentence.latitude_sigma,
                    longitude_sigma=sentence.longitude_sigma,
                )
            else:
                self._on_other(sentence)
                continue
        fix = replace(fix, time_ns=max(now, fix.time_ns), sentences=fix.sentences + merged)
        self.fix = fix
        if merged:
            self._last_rx_ns = now
            self._log.debug("nmea_fix", sentences=fix.sentences, quality=fix.fix_quality)
        if self._changed is not None:
            self._changed.set()

    def _date_for(self, fix: GpsFix, time: dt.time) -> dt.date | None:
        """The UTC date of ``time``: midnight passed when the time of day went back by
        more than 12 h since the previous sentence."""
        date = fix.utc_date
        last = fix.utc_time
        if date is not None and last is not None and _seconds(time) < _seconds(last) - _HALF_DAY_S:
            date = date + _DAY
        return date

    def _fix_utc(self, date: dt.date | None, time: dt.time | None) -> dt.datetime | None:
        if date is None or time is None:
            return None
        return dt.datetime.combine(date, time, tzinfo=dt.UTC)

    def _merge_gga(self, fix: GpsFix, gga: nmea.GGA) -> GpsFix:
        date = fix.utc_date if gga.time is None else self._date_for(fix, gga.time)
        fix = replace(
            fix,
            utc_time=_keep(gga.time, fix.utc_time),
            utc_date=date,
            fix_quality=gga.fix_quality,
            satellites=_keep(gga.satellites, fix.satellites),
            valid=gga.fix_quality > 0,
        )
        if gga.fix_quality == 0:
            return fix  # no fix: the position and its time stay those of the last fix
        return replace(
            fix,
            fix_utc=_keep(self._fix_utc(date, gga.time), fix.fix_utc),
            latitude=_keep(gga.latitude, fix.latitude),
            longitude=_keep(gga.longitude, fix.longitude),
            altitude=_keep(gga.altitude, fix.altitude),
            geoid_separation=_keep(gga.geoid_separation, fix.geoid_separation),
            hdop=_keep(gga.hdop, fix.hdop),
        )

    def _merge_rmc(self, fix: GpsFix, rmc: nmea.RMC) -> GpsFix:
        valid = rmc.valid and rmc.mode != "N"
        fix = replace(
            fix,
            utc_time=_keep(rmc.time, fix.utc_time),
            utc_date=_keep(rmc.date, fix.utc_date),
            valid=valid,
        )
        if not valid:
            return fix
        course = None if rmc.course is None else rmc.course % 360.0
        return replace(
            fix,
            fix_utc=_keep(self._fix_utc(rmc.date, rmc.time), fix.fix_utc),
            latitude=_keep(rmc.latitude, fix.latitude),
            longitude=_keep(rmc.longitude, fix.longitude),
            speed=_keep(rmc.speed, fix.speed),
            course=_keep(course, fix.course),
        )

    def _merge_gsv(self, gsv: nmea.GSV) -> tuple[int, ...] | None:
        """Collect a GSV cycle; at its last message, the SNRs of every latest cycle."""
        key = (gsv.talker, gsv.signal_id)
        parts = self._gsv.setdefault(key, [])
        if gsv.number == 1:
            parts.clear()
        elif not parts or parts[-1].number != gsv.number - 1 or parts[-1].count != gsv.count:
            parts.clear()  # a message of the cycle was lost: wait for the next cycle
            return None
        parts.append(gsv)
        if gsv.number != gsv.count:
            return None
        self._gsv_snr[key] = tuple(
            sat.snr for part in parts for sat in part.satellites if sat.snr is not None
        )
        parts.clear()
        return tuple(snr for snrs in self._gsv_snr.values() for snr in snrs)

    def _on_other(self, sentence: nmea.Sentence) -> None:
        self.other_sentences += 1
        if (
            isinstance(sentence, nmea.RawSentence)
            and sentence.talker == "P"
            and sentence.sentence_type == "MTK001"
            and len(sentence.fields) >= 2
            and sentence.fields[0] == "220"
            and sentence.fields[1].isdigit()
            and self._ack is not None
        ):
            event, flags = self._ack
            flags.append(int(sentence.fields[1]))
            event.set()

    def _on_lost(self, reason: str) -> None:
        if self._ctx is not None:
            self._faulted = True
            self._ctx.fault(
                ErrorId.DISCONNECTED, f"{self.url}: {reason}", ReturnCode.HAL_NO_CONNECTED
            )

    def _wakeup(self) -> anyio.Event:
        """Set by the next sentence or re-arm (created here: callbacks only set it)."""
        changed = self._changed
        if changed is None or changed.is_set():
            changed = self._changed = anyio.Event()
        return changed

    def _arm(self) -> None:
        """(Re)start stale detection from now (init, re_init)."""
        self._faulted = False
        self._armed_ns = self._context().clock.now_ns()
        if self._changed is not None:
            self._changed.set()

    async def _watchdog(self) -> None:
        """Fault with TIMEOUT when no GGA/RMC arrived for ``stale_timeout``."""
        ctx = self._context()
        stale_ns = round(self.stale_timeout * 1e9)
        with anyio.CancelScope() as self._watch_scope:
            while not self._closed:
                since = max(self._last_rx_ns, self._armed_ns)
                if ctx.clock.now_ns() < since + stale_ns:
                    await ctx.clock.sleep_until(since + stale_ns)
                    continue
                if not self._faulted and self._link.is_open:
                    self._faulted = True
                    age = (ctx.clock.now_ns() - since) / 1e9
                    self._log.warning("nmea_stale_fix", age_s=round(age, 3))
                    ctx.fault(ErrorId.TIMEOUT, f"{self.url}: no NMEA sentence for {age:.2f} s")
                # Wait for a sentence or a re-arm before checking again.
                await self._wakeup().wait()

    def _context(self) -> DeviceContext:
        if self._ctx is None:
            raise HALError("NmeaGps used before open()")
        return self._ctx
