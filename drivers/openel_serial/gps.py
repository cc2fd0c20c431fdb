"""NmeaGps: an NMEA 0183 GPS receiver on a serial port, as an OpenEL sensor.

The receiver's lines are parsed as they arrive (in the transport's callback, no task
in between) by :class:`~openel_serial.nmea.NmeaParser`: sentences with a bad checksum
or malformed fields are counted and dropped. GGA gives the position, altitude, fix
quality, satellites and HDOP; RMC the speed and course over ground and the date.

Values (``units`` tells each one's unit):

====  ===================  ==================================================
 #    value                unit
====  ===================  ==================================================
 0    latitude             rad (``angle_unit="deg"``: deg), N positive
 1    longitude            rad (or deg), E positive
 2    altitude             m above mean sea level (GGA)
 3    speed over ground    m/s (RMC; knots on the wire)
 4    course over ground   rad (or deg), true, clockwise from north (RMC)
 5    fix quality          GGA code: 0 invalid, 1 GPS, 2 DGPS, 4 RTK fixed, ...
 6    satellites in use    count
 7    HDOP                 dimensionless
 8    UTC time of day      s since UTC midnight of the latest fix
====  ===================  ==================================================

Radians are the SI default; degrees are what most GPS users expect, hence the option.
A field the receiver leaves empty keeps its last value (0 before the first one); when
the fix is lost the receiver sends empty positions and fix quality 0: the position
values keep the last fix and value 5 says it is invalid. ``read`` raises
:class:`~openel_serial.errors.NoFixError` until a first position arrived.

The timestamp (``Reading.time_ns``) is the component clock's time when the latest
GGA/RMC sentence was received; the receiver's own UTC time is in :attr:`NmeaGps.fix`
(``utc``, a ``datetime`` once an RMC gave the date).

No valid sentence for ``stale_timeout`` seconds faults the component with
``ErrorId.TIMEOUT`` (stale fix); a vanished port with ``ErrorId.DISCONNECTED``.
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
import structlog

from openel_async.device import DeviceContext, DeviceInfo, ErrorId, Reading, SensorDevice
from openel_async.errors import BadParameterError, HALError, ReturnCode
from openel_serial import nmea
from openel_serial.errors import NoFixError, PortDisconnectedError
from openel_serial.link import SerialLink

__all__ = ["GNSS_DEVICE_KIND", "GpsFix", "NmeaGps"]

log = structlog.get_logger(__name__)

GNSS_DEVICE_KIND: Final = 0x10
"""Device kind id of the GPS: the OpenEL registry (``DeviceKind``) has no GNSS kind yet."""

VALUE_NAMES: Final = (
    "latitude",
    "longitude",
    "altitude",
    "speed",
    "course",
    "fix_quality",
    "satellites",
    "hdop",
    "utc_time_of_day",
)


@dataclass(frozen=True, slots=True)
class GpsFix:
    """The receiver's latest data, merged from GGA and RMC (angles in degrees)."""

    time_ns: int = 0
    """Component clock time at which the latest sentence was received."""
    utc_time: dt.time | None = None
    utc_date: dt.date | None = None
    latitude: float | None = None
    longitude: float | None = None
    altitude: float | None = None
    speed: float | None = None
    """m/s over ground."""
    course: float | None = None
    """degrees true."""
    fix_quality: int = 0
    satellites: int | None = None
    hdop: float | None = None
    valid: bool = False
    """RMC status A."""
    sentences: int = 0
    """GGA/RMC sentences merged so far."""

    @property
    def utc(self) -> dt.datetime | None:
        """Date and time of the fix in UTC (needs an RMC for the date)."""
        if self.utc_time is None or self.utc_date is None:
            return None
        return dt.datetime.combine(self.utc_date, self.utc_time, tzinfo=dt.UTC)

    @property
    def has_position(self) -> bool:
        return self.latitude is not None and self.longitude is not None


def _keep(new: Any, old: Any) -> Any:
    return old if new is None else new


class NmeaGps(SensorDevice):
    """A GPS receiver sending NMEA 0183 GGA and RMC sentences on ``url``."""

    info = DeviceInfo(
        kind=GNSS_DEVICE_KIND,
        vendor_name="Generic",
        product_name="NmeaGps",
    )

    def __init__(
        self,
        url: str,
        *,
        baudrate: int = 9600,
        stale_timeout: float = 2.0,
        angle_unit: Literal["rad", "deg"] = "rad",
        serial_options: Mapping[str, Any] | None = None,
    ) -> None:
        if not isinstance(url, str) or not url:
            raise BadParameterError("url", url, "a serial device path or pyserial URL")
        if isinstance(baudrate, bool) or not isinstance(baudrate, int) or baudrate <= 0:
            raise BadParameterError("baudrate", baudrate, "an int > 0 (bit/s)")
        if (
            isinstance(stale_timeout, bool)
            or not isinstance(stale_timeout, int | float)
            or not (math.isfinite(stale_timeout) and stale_timeout > 0)
        ):
            raise BadParameterError("stale_timeout", stale_timeout, "a finite number > 0 (s)")
        if angle_unit not in ("rad", "deg"):
            raise BadParameterError("angle_unit", angle_unit, "'rad' or 'deg'")
        self.url = url
        self.stale_timeout = float(stale_timeout)
        self.angle_unit = angle_unit
        self.units = (angle_unit, angle_unit, "m", "m/s", angle_unit, "1", "1", "1", "s")
        self.parser = nmea.NmeaParser()
        self.fix = GpsFix()
        self.other_sentences = 0
        self._link = SerialLink(
            url,
            baudrate=baudrate,
            on_data=self._on_data,
            on_lost=self._on_lost,
            serial_options=serial_options,
        )
        self._ctx: DeviceContext | None = None
        self._last_rx_ns = 0
        self._armed_ns = 0
        self._changed: anyio.Event | None = None
        self._faulted = False
        self._closed = False
        self._watch_scope: anyio.CancelScope | None = None
        self._log = log.bind(port=url)

    @property
    def link(self) -> SerialLink:
        return self._link

    @property
    def value_names(self) -> tuple[str, ...]:
        return VALUE_NAMES

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
    async def read(self) -> Reading:
        if not self._link.is_open:
            raise PortDisconnectedError(self.url, self._link.lost_reason or "not open")
        fix = self.fix
        if fix.latitude is None or fix.longitude is None:
            raise NoFixError(f"{self.url}: no position received yet")
        angle = math.radians if self.angle_unit == "rad" else float
        utc = fix.utc_time
        seconds = (
            0.0
            if utc is None
            else utc.hour * 3600 + utc.minute * 60 + utc.second + utc.microsecond * 1e-6
        )
        values = (
            angle(fix.latitude),
            angle(fix.longitude),
            fix.altitude or 0.0,
            fix.speed or 0.0,
            angle(fix.course or 0.0),
            float(fix.fix_quality),
            float(fix.satellites or 0),
            fix.hdop or 0.0,
            seconds,
        )
        return Reading(values, fix.time_ns)

    async def next_fix(self) -> GpsFix:
        """Wait for the next GGA or RMC sentence and return the fix it updated.

        Not bounded: wrap it in ``anyio.fail_after`` (the watchdog faults the component
        after ``stale_timeout`` but does not end this wait).
        """
        count = self.fix.sentences
        while self.fix.sentences == count:
            await self._wakeup().wait()
        return self.fix

    # -- reception (transport callback) ----------------------------------------------
    def _on_data(self, data: bytes) -> None:
        ctx = self._ctx
        if ctx is None:
            return
        sentences = self.parser.feed(data)
        if not sentences:
            return
        now = ctx.clock.now_ns()
        fix = self.fix
        merged = False
        for sentence in sentences:
            if isinstance(sentence, nmea.GGA):
                fix = replace(
                    fix,
                    utc_time=_keep(sentence.time, fix.utc_time),
                    latitude=_keep(sentence.latitude, fix.latitude),
                    longitude=_keep(sentence.longitude, fix.longitude),
                    altitude=_keep(sentence.altitude, fix.altitude),
                    fix_quality=sentence.fix_quality,
                    satellites=_keep(sentence.satellites, fix.satellites),
                    hdop=_keep(sentence.hdop, fix.hdop),
                )
            elif isinstance(sentence, nmea.RMC):
                fix = replace(
                    fix,
                    utc_time=_keep(sentence.time, fix.utc_time),
                    utc_date=_keep(sentence.date, fix.utc_date),
                    latitude=_keep(sentence.latitude, fix.latitude),
                    longitude=_keep(sentence.longitude, fix.longitude),
                    speed=_keep(sentence.speed, fix.speed),
                    course=_keep(sentence.course, fix.course),
                    valid=sentence.valid,
                )
            else:
                self.other_sentences += 1
                continue
            merged = True
            fix = replace(fix, time_ns=max(now, fix.time_ns), sentences=fix.sentences + 1)
        if not merged:
            return
        self.fix = fix
        self._last_rx_ns = now
        self._log.debug("nmea_fix", sentences=fix.sentences, quality=fix.fix_quality)
        if self._changed is not None:
            self._changed.set()

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
