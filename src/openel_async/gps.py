"""HAL4RT's GPS Sensor (§7.4.5.13): named getters in HAL4RT's units over a GPS device.

A :class:`GPSDevice` is a :class:`SensorDevice` that also gives its latest fix as a
:class:`GPSData` (``read_gps``) and can change its output period (``set_period``).
:class:`GPSSensor` is the component: ``get_latitude`` ... ``get_angle`` and
``set_period`` in the units HAL4RT names (degrees, metres, m/s, ms since 1970 UTC), and
the plain ``get_value`` vector (:data:`GPS_VALUE_NAMES`, the same quantities) for the
per-value sensor operations.

``angle`` is where HAL4RT is vague ("Get angle."): the spec's description says the GPS
measures "latitude and longitude, or heading and distance to GPS position", so ``angle``
is the heading to a GPS position set with :meth:`GPSSensor.set_target`: the initial
great-circle bearing from the fix to the target, degrees clockwise from true north in
[0, 360). :meth:`GPSSensor.get_distance` gives the distance to it (an extension).
"""

from __future__ import annotations

import math
from abc import abstractmethod
from dataclasses import dataclass
from typing import Final

from .clock import Clock
from .component import LINK_FAULTS, ComponentState
from .device import Reading, SensorDevice
from .errors import BadParameterError, HALError
from .ids import DeviceKind, HALId
from .sensor_kinds import KindSensor, register_sensor_class

__all__ = [
    "EARTH_MEAN_RADIUS_M",
    "GPS_UNITS",
    "GPS_VALUE_NAMES",
    "GPSData",
    "GPSDevice",
    "GPSSensor",
    "bearing_deg",
    "distance_m",
]

_ACTIVE = ComponentState.ACTIVE

EARTH_MEAN_RADIUS_M: Final = 6_371_008.8
"""IUGG mean radius R1 of the WGS-84 ellipsoid: the sphere of :func:`bearing_deg` and
:func:`distance_m`."""

GPS_VALUE_NAMES: Final = (
    "latitude",
    "longitude",
    "accuracy",
    "dop",
    "altitude",
    "time",
    "speed",
    "course",
    "signal_strength",
    "stale",
    "fix_quality",
    "satellites",
)
"""The values of a GPS device's ``read()`` (``get_value``), in this order."""

GPS_UNITS: Final = ("deg", "deg", "m", "1", "m", "ms", "m/s", "deg", "dB-Hz", "1", "1", "1")


@dataclass(frozen=True, slots=True)
class GPSData:
    """A GPS device's latest fix in HAL4RT's units; None: the receiver has not given it.

    The position, altitude, speed, course and ``time_ms`` are those of the last *valid*
    fix: a receiver reporting no fix does not move them, it sets ``stale``.
    """

    latitude: float | None = None
    """Degrees, north positive (WGS-84)."""
    longitude: float | None = None
    """Degrees, east positive."""
    accuracy: float | None = None
    """Metres: the horizontal position's standard error (see the device for its source)."""
    dop: float | None = None
    """Horizontal dilution of precision (HDOP)."""
    altitude: float | None = None
    """Metres above the WGS-84 ellipsoid."""
    time_ms: float | None = None
    """UTC time of the fix, milliseconds since 1970-01-01T00:00Z."""
    speed: float | None = None
    """m/s over ground."""
    course: float | None = None
    """Degrees true, 0 <= course < 360 (HAL4RT: 000.0-359.9)."""
    signal_strength: float | None = None
    """dB-Hz: mean carrier-to-noise density of the satellites tracked."""
    stale: bool = True
    """True when the receiver currently reports no fix (or has never reported one)."""
    fix_quality: int = 0
    """NMEA GGA fix quality (0 none, 1 GNSS, 2 DGNSS, 4 RTK fixed, 5 RTK float, ...)."""
    satellites: int | None = None
    """Satellites used in the fix."""
    time_ns: int = 0
    """Component clock time (ns) at which the data last changed."""

    @property
    def has_position(self) -> bool:
        return self.latitude is not None and self.longitude is not None

    def values(self) -> tuple[float, ...]:
        """The :data:`GPS_VALUE_NAMES` vector; an unavailable quantity is 0.0 (the value
        vector must be finite), ``stale`` is 1.0 or 0.0."""

        def v(x: float | None) -> float:
            return 0.0 if x is None else float(x)

        return (
            v(self.latitude),
            v(self.longitude),
            v(self.accuracy),
            v(self.dop),
            v(self.altitude),
            v(self.time_ms),
            v(self.speed),
            v(self.course),
            v(self.signal_strength),
            1.0 if self.stale else 0.0,
            float(self.fix_quality),
            v(self.satellites),
        )


def _radians(latitude: float, longitude: float) -> tuple[float, float]:
    return math.radians(latitude), math.radians(longitude)


def bearing_deg(lat1: float, lon1: float, lat2: float, lon2: float) -> float:
    """Initial great-circle bearing from point 1 to point 2, degrees in [0, 360).

    On a sphere: within about 0.2 degrees of the ellipsoidal (geodesic) azimuth.
    """
    p1, l1 = _radians(lat1, lon1)
    p2, l2 = _radians(lat2, lon2)
    dl = l2 - l1
    y = math.sin(dl) * math.cos(p2)
    x = math.cos(p1) * math.sin(p2) - math.sin(p1) * math.cos(p2) * math.cos(dl)
    return math.degrees(math.atan2(y, x)) % 360.0


def distance_m(lat1: float, lon1: float, lat2: float, lon2: float) -> float:
    """Great-circle distance (haversine) on the sphere of :data:`EARTH_MEAN_RADIUS_M`;
    within 0.5 % of the geodesic distance on the WGS-84 ellipsoid."""
    p1, l1 = _radians(lat1, lon1)
    p2, l2 = _radians(lat2, lon2)
    a = math.sin((p2 - p1) / 2) ** 2 + math.cos(p1) * math.cos(p2) * math.sin((l2 - l1) / 2) ** 2
    return 2 * EARTH_MEAN_RADIUS_M * math.asin(min(1.0, math.sqrt(a)))


def _finite(name: str, value: object, allowed: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise BadParameterError(name, value, allowed)
    number = float(value)
    if not math.isfinite(number):
        raise BadParameterError(name, value, allowed)
    return number


def check_latitude(value: object, name: str = "latitude") -> float:
    """A latitude in degrees, -90..90 (BadParameterError naming ``name`` otherwise)."""
    number = _finite(name, value, "degrees in -90..90")
    if not -90.0 <= number <= 90.0:
        raise BadParameterError(name, value, "degrees in -90..90")
    return number


def check_longitude(value: object, name: str = "longitude") -> float:
    """A longitude in degrees, -180..180 (BadParameterError naming ``name`` otherwise)."""
    number = _finite(name, value, "degrees in -180..180")
    if not -180.0 <= number <= 180.0:
        raise BadParameterError(name, value, "degrees in -180..180")
    return number


class GPSDevice(SensorDevice):
    """A GPS receiver: its latest fix as :class:`GPSData`, and a settable output period.

    ``read()`` returns the :data:`GPS_VALUE_NAMES` vector of :meth:`read_gps`.
    """

    units = GPS_UNITS
    period_range_ms: tuple[float, float] = (0.0, math.inf)
    """The output periods (ms) the receiver accepts, inclusive."""
    period_ms: float | None = None
    """The output period in force (ms), None until known."""

    @abstractmethod
    async def read_gps(self) -> GPSData:
        """The latest fix (raise a ``HALError`` when there has been none at all)."""

    @abstractmethod
    async def set_period(self, period_ms: float) -> None:
        """Send the receiver's rate command and return once it took effect (already
        checked: finite, > 0 and within ``period_range_ms``)."""

    async def read(self) -> Reading:
        data = await self.read_gps()
        return Reading(data.values(), data.time_ns)


class GPSSensor(KindSensor):
    """HAL4RT's GPS Sensor over a :class:`GPSDevice` (kind ``DeviceKind.GPS``).

    The getters read the device's latest fix; a quantity the receiver has not given
    raises ``HALError`` naming it. The values are those of the last valid fix:
    :meth:`is_stale` says whether the receiver currently reports no fix.
    """

    KIND = DeviceKind.GPS
    device: GPSDevice
    device_class = GPSDevice

    def __init__(
        self,
        device: GPSDevice,
        *,
        hal_id: HALId | None = None,
        device_name: str | None = None,
        function_list: tuple[str, ...] | None = None,
        clock: Clock | None = None,
        auto_init: bool = True,
        open_timeout: float = 10.0,
    ) -> None:
        super().__init__(
            device,
            hal_id=hal_id,
            device_name=device_name,
            function_list=function_list,
            clock=clock,
            auto_init=auto_init,
            open_timeout=open_timeout,
        )
        self._target: tuple[float, float] | None = None

    # -- the fix -----------------------------------------------------------------------
    async def get_fix(self) -> GPSData:
        """The whole latest fix (every quantity, None where not available)."""
        return await self._fix("get_fix")

    async def _fix(self, operation: str) -> GPSData:
        self._require(operation, _ACTIVE)
        try:
            return await self.device.read_gps()
        except LINK_FAULTS as exc:
            raise self._fault_from(exc) from exc

    async def _quantity(self, name: str, operation: str) -> float:
        data = await self._fix(operation)
        value = getattr(data, name)
        if value is None:
            raise HALError(f"{self.device_name}: {name} not available (not received yet)")
        return float(value)

    async def get_latitude(self) -> float:
        """GetLatitude: degrees, north positive."""
        return await self._quantity("latitude", "get_latitude")

    async def get_longitude(self) -> float:
        """GetLongitude: degrees, east positive."""
        return await self._quantity("longitude", "get_longitude")

    async def get_accuracy(self) -> float:
        """GetAccuracy: the estimated horizontal accuracy, metres."""
        return await self._quantity("accuracy", "get_accuracy")

    async def get_dop(self) -> float:
        """GetDOP: the horizontal dilution of precision (HDOP)."""
        return await self._quantity("dop", "get_dop")

    async def get_altitude(self) -> float:
        """GetAltitude: metres above the WGS-84 ellipsoid."""
        return await self._quantity("altitude", "get_altitude")

    async def get_fix_time(self) -> float:
        """HAL4RT GPS ``GetTime``: UTC time of the fix, ms since 1970-01-01 (renamed: the
        component's own ``get_time`` is OpenEL's GetTime of the component clock)."""
        return await self._quantity("time_ms", "get_fix_time")

    async def get_speed(self) -> float:
        """GetSpeed: m/s over ground."""
        return await self._quantity("speed", "get_speed")

    async def get_course(self) -> float:
        """GetCourse: degrees true, 0 <= course < 360."""
        return await self._quantity("course", "get_course")

    async def get_signal_strength(self) -> float:
        """GetSignalStrength: mean C/N0 of the satellites tracked, dB-Hz."""
        return await self._quantity("signal_strength", "get_signal_strength")

    async def is_stale(self) -> bool:
        """True when the receiver reports no fix now (the values are the last fix's)."""
        return (await self._fix("is_stale")).stale

    # -- angle: heading to a GPS position -------------------------------------------------
    def set_target(self, latitude: float, longitude: float) -> None:
        """The GPS position that :meth:`get_angle` and :meth:`get_distance` refer to
        (Active state only, as every operation)."""
        self._require("set_target", _ACTIVE)
        lat = check_latitude(latitude)
        lon = check_longitude(longitude)
        self._target = (lat, lon)

    @property
    def target(self) -> tuple[float, float] | None:
        return self._target

    async def _to_target(self, operation: str) -> tuple[float, float, float, float]:
        self._require(operation, _ACTIVE)
        target = self._target
        if target is None:
            raise HALError(f"{self.device_name}: no target position: call set_target first")
        data = await self._fix(operation)
        if data.latitude is None or data.longitude is None:
            missing = "latitude" if data.latitude is None else "longitude"
            raise HALError(f"{self.device_name}: {missing} not available (not received yet)")
        return data.latitude, data.longitude, *target

    async def get_angle(self) -> float:
        """GetAngle: the heading to the target (``set_target``), degrees clockwise from
        true north in [0, 360): the initial great-circle bearing from the fix."""
        return bearing_deg(*await self._to_target("get_angle"))

    async def get_distance(self) -> float:
        """Distance from the fix to the target, metres (great circle; an extension)."""
        return distance_m(*await self._to_target("get_distance"))

    # -- period ---------------------------------------------------------------------------
    @property
    def period_ms(self) -> float | None:
        """The receiver's output period in force (ms), None until known."""
        return self.device.period_ms

    async def set_period(self, period_ms: float) -> None:
        """SetPeriod: the receiver's output period in milliseconds.

        ``BadParameterError`` naming ``period_ms`` for a value that is not finite and > 0
        or outside the device's ``period_range_ms``; the period is then unchanged.
        """
        self._require("set_period", _ACTIVE)
        low, high = self.device.period_range_ms
        allowed = f"a finite period in ms, > 0 and within [{low:g}, {high:g}]"
        period = _finite("period_ms", period_ms, allowed)
        if not (period > 0 and low <= period <= high):
            raise BadParameterError("period_ms", period_ms, allowed)
        try:
            await self.device.set_period(period)
        except LINK_FAULTS as exc:
            raise self._fault_from(exc) from exc


register_sensor_class(DeviceKind.GPS, GPSSensor)
