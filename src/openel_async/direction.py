"""HAL4RT's Direction Sensor (§7.4.5.14): the World Magnetic Model and a compass heading.

:class:`MagneticModel` evaluates the World Magnetic Model (WMM2025, NOAA NCEI / BGS, valid
2025.0-2030.0) with pygeomag: the field's north, east and vertical (down) components X, Y,
Z, the horizontal and total intensities H and F (nT), the inclination I and the
declination D (degrees, east and down positive) at a geodetic position and a date.

:class:`DirectionSensor` is the component: HAL4RT's SetLatitude/SetLongitude/SetAltitude/
SetDate and GetF ... GetD over the model, and, from its device (a three-axis
magnetometer), the heading: the magnetic heading from the horizontal field in the
sensor's frame, plus the declination D, gives the heading from true north.

Frames: the magnetometer's values 0, 1, 2 are the field along the sensor's axes, in any
one unit: ``frame="FLU"`` (default) x forward, y left, z up (REP-103 body frame; a
MuJoCo site), ``frame="FRD"`` x forward, y right, z down (aerospace; the ``sim`` driver's
``SimMagnetometer``). The sensor is taken as level (no tilt compensation): heading =
atan2(left, forward) + D, degrees clockwise from true north in [0, 360).
"""

from __future__ import annotations

import datetime as dt
import math
from dataclasses import dataclass
from typing import Final, Literal

from pygeomag import GeoMag, decimal_year_from_date  # type: ignore[import-untyped]

from .clock import Clock
from .component import ComponentState
from .device import SensorDevice
from .errors import BadParameterError, HALError
from .gps import check_latitude, check_longitude
from .ids import DeviceKind, HALId
from .sensor_kinds import KindSensor, register_sensor_class

__all__ = [
    "ALTITUDE_RANGE_M",
    "DirectionSensor",
    "MagneticField",
    "MagneticModel",
    "heading_deg",
]

_ACTIVE = ComponentState.ACTIVE

ALTITUDE_RANGE_M: Final = (-1_000.0, 850_000.0)
"""Heights above the WGS-84 ellipsoid where the WMM is valid: 1 km below to 850 km above."""

WMM2025_COEFFICIENTS: Final = "wmm/WMM_2025.COF"
"""pygeomag's copy of NOAA's WMM2025 coefficient file (WMM-2025, released 11/13/2024)."""


@dataclass(frozen=True, slots=True)
class MagneticField:
    """The main geomagnetic field at a place and date (nT; angles in degrees)."""

    x: float
    """North component."""
    y: float
    """East component."""
    z: float
    """Vertical component, down positive."""
    h: float
    """Horizontal intensity."""
    f: float
    """Total intensity."""
    i: float
    """Inclination (dip), down positive."""
    d: float
    """Declination (magnetic variation), east positive."""


class MagneticModel:
    """The World Magnetic Model through pygeomag (WMM2025 unless another file is given)."""

    def __init__(self, coefficients_file: str = WMM2025_COEFFICIENTS) -> None:
        self._geomag = GeoMag(coefficients_file=coefficients_file)
        start, end = self._geomag.life_span
        self.valid_from: float = float(start)
        """First decimal year of the model's validity."""
        self.valid_to: float = float(end)
        """Last decimal year of the model's validity (inclusive)."""
        self.name: str = str(self._geomag.model)

    def decimal_year(self, date: float | dt.date, parameter: str = "date") -> float:
        """``date`` (a decimal year, a ``date`` or a ``datetime``) as a decimal year inside
        the model's validity; ``BadParameterError`` naming ``parameter`` otherwise."""
        allowed = (
            f"a date in {self.valid_from:g}..{self.valid_to:g} ({self.name}): a decimal "
            "year, datetime.date or datetime.datetime"
        )
        if isinstance(date, dt.datetime):
            utc = date.astimezone(dt.UTC) if date.tzinfo is not None else date
            start = dt.datetime(utc.year, 1, 1, tzinfo=utc.tzinfo)
            end = dt.datetime(utc.year + 1, 1, 1, tzinfo=utc.tzinfo)
            year = utc.year + (utc - start) / (end - start)
        elif isinstance(date, dt.date):
            year = float(decimal_year_from_date(date))
        elif isinstance(date, int | float) and not isinstance(date, bool):
            year = float(date)
        else:
            raise BadParameterError(parameter, date, allowed)
        if not (math.isfinite(year) and self.valid_from <= year <= self.valid_to):
            raise BadParameterError(parameter, date, allowed)
        return year

    def field(
        self, latitude: float, longitude: float, altitude: float, date: float | dt.date
    ) -> MagneticField:
        """The field at geodetic ``latitude``/``longitude`` (degrees), ``altitude`` (m above
        the WGS-84 ellipsoid) and ``date``; each argument is checked (BadParameterError)."""
        lat = check_latitude(latitude)
        lon = check_longitude(longitude)
        alt = _check_altitude(altitude)
        year = self.decimal_year(date)
        result = self._geomag.calculate(glat=lat, glon=lon, alt=alt / 1000.0, time=year)
        return MagneticField(
            float(result.x),
            float(result.y),
            float(result.z),
            float(result.h),
            float(result.f),
            float(result.i),
            float(result.d),
        )


def _check_altitude(value: object) -> float:
    low, high = ALTITUDE_RANGE_M
    allowed = f"metres above the WGS-84 ellipsoid in {low:g}..{high:g}"
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise BadParameterError("altitude", value, allowed)
    number = float(value)
    if not (math.isfinite(number) and low <= number <= high):
        raise BadParameterError("altitude", value, allowed)
    return number


def heading_deg(forward: float, left: float, declination: float = 0.0) -> float:
    """Heading from the field along a level sensor's forward and left axes: degrees
    clockwise from north in [0, 360) (magnetic north, or true north with the
    ``declination`` added)."""
    if forward == 0.0 and left == 0.0:
        raise HALError("no horizontal magnetic field: the heading is undefined")
    return (math.degrees(math.atan2(left, forward)) + declination) % 360.0


class DirectionSensor(KindSensor):
    """HAL4RT's Direction Sensor (kind ``DeviceKind.COMPASS``): the WMM at a set place and
    date, and the heading of a magnetometer (its first three values, in ``frame``)."""

    KIND = DeviceKind.COMPASS

    def __init__(
        self,
        device: SensorDevice,
        *,
        frame: Literal["FLU", "FRD"] = "FLU",
        model: MagneticModel | None = None,
        hal_id: HALId | None = None,
        device_name: str | None = None,
        function_list: tuple[str, ...] | None = None,
        clock: Clock | None = None,
        auto_init: bool = True,
        open_timeout: float = 10.0,
    ) -> None:
        units = tuple(device.units) if isinstance(device, SensorDevice) else ()
        if len(units) < 3 or len(set(units[:3])) != 1:
            raise BadParameterError(
                "device", device, "a magnetometer: three values of one unit (x, y, z)"
            )
        if frame not in ("FLU", "FRD"):
            raise BadParameterError("frame", frame, "'FLU' (x forward, y left, z up) or 'FRD'")
        super().__init__(
            device,
            hal_id=hal_id,
            device_name=device_name,
            function_list=function_list,
            clock=clock,
            auto_init=auto_init,
            open_timeout=open_timeout,
        )
        self.frame = frame
        self._left_sign = 1.0 if frame == "FLU" else -1.0
        self.model = model if model is not None else MagneticModel()
        self._latitude = 0.0
        self._longitude = 0.0
        self._altitude = 0.0
        self._date: float | None = None
        self._field: MagneticField | None = None

    # -- place and date --------------------------------------------------------------
    @property
    def latitude(self) -> float:
        return self._latitude

    @property
    def longitude(self) -> float:
        return self._longitude

    @property
    def altitude(self) -> float:
        return self._altitude

    @property
    def date(self) -> float | None:
        """The decimal year set with :meth:`set_date` (None before)."""
        return self._date

    def set_latitude(self, latitude: float) -> None:
        """SetLatitude: geodetic degrees, -90..90."""
        self._require("set_latitude", _ACTIVE)
        self._latitude = check_latitude(latitude)
        self._field = None

    def set_longitude(self, longitude: float) -> None:
        """SetLongitude: degrees, -180..180, east positive."""
        self._require("set_longitude", _ACTIVE)
        self._longitude = check_longitude(longitude)
        self._field = None

    def set_altitude(self, altitude: float) -> None:
        """SetAltitude: metres above the WGS-84 ellipsoid (-1 km .. 850 km)."""
        self._require("set_altitude", _ACTIVE)
        self._altitude = _check_altitude(altitude)
        self._field = None

    def set_date(self, date: float | dt.date) -> None:
        """SetDate: a decimal year (2027.5), a ``date`` or a ``datetime``, inside the model's
        validity (WMM2025: 2025.0..2030.0)."""
        self._require("set_date", _ACTIVE)
        self._date = self.model.decimal_year(date)
        self._field = None

    # -- the model's field -------------------------------------------------------------
    def field(self) -> MagneticField:
        """The WMM's field at the place and date set (computed once per change)."""
        return self._model_field("field")

    def _model_field(self, operation: str) -> MagneticField:
        self._require(operation, _ACTIVE)
        field = self._field
        if field is None:
            if self._date is None:
                raise HALError(f"{self.device_name}: no date: call set_date first")
            field = self._field = self.model.field(
                self._latitude, self._longitude, self._altitude, self._date
            )
        return field

    def get_f(self) -> float:
        """GetF: total intensity, nT."""
        return self._model_field("get_f").f

    def get_h(self) -> float:
        """GetH: horizontal intensity, nT."""
        return self._model_field("get_h").h

    def get_x(self) -> float:
        """GetX: north component, nT."""
        return self._model_field("get_x").x

    def get_y(self) -> float:
        """GetY: east component, nT."""
        return self._model_field("get_y").y

    def get_z(self) -> float:
        """GetZ: vertical component (down positive), nT."""
        return self._model_field("get_z").z

    def get_i(self) -> float:
        """GetI: inclination (dip), degrees, down positive."""
        return self._model_field("get_i").i

    def get_d(self) -> float:
        """GetD: declination (magnetic variation), degrees, east positive."""
        return self._model_field("get_d").d

    # -- heading from the magnetometer ----------------------------------------------------
    async def get_magnetic_heading(self) -> float:
        """Heading from magnetic north (degrees clockwise, [0, 360)) of the level sensor."""
        values = await self.get_value()
        return heading_deg(values[0], self._left_sign * values[1])

    async def get_heading(self) -> float:
        """Heading from true north: the magnetic heading corrected by the declination D."""
        declination = self._model_field("get_heading").d
        values = await self.get_value()
        return heading_deg(values[0], self._left_sign * values[1], declination)


register_sensor_class(DeviceKind.COMPASS, DirectionSensor)
