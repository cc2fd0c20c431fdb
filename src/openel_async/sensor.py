"""Sensor: GetValue and GetTimedValue, with HAL4RT's per-value unit, scale factor and origin.

Values are the device's SI values until the unit, scale factor or origin of some value is
set (HAL4RT §7.4.5.5); then each value i is ``gain_i * raw_i + offset_i``, precomputed
from ``unit_i(scale_i * (raw_i - origin_i))`` when the setting changes (docs/psm.md §8.1).
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import NamedTuple

from .clock import Clock
from .component import LINK_FAULTS, ComponentState, HALComponent
from .device import ErrorId, Reading, SensorDevice, has_nowait
from .errors import BadParameterError, HALError, NotImplementedHALError, StateError, WouldBlockError
from .ids import HALId
from .units import affine

S = ComponentState
_ACTIVE = S.ACTIVE  # enum member as a module constant on the per-read path (~80 ns saved)


class SettingsVersion:
    """Counts changes of any sensor's measurement settings (a SensorBank re-checks its
    members' conversions only when it moved)."""

    __slots__ = ("value",)

    def __init__(self) -> None:
        self.value = 0


MEASUREMENT_SETTINGS_VERSION = SettingsVersion()


@dataclass(frozen=True, slots=True)
class Measurement:
    """The per-value settings of a sensor and the affine map they make.

    ``value_i = gain_i * raw_i + offset_i`` with ``gain_i = a_i * scale_i`` and
    ``offset_i = b_i - gain_i * origin_i``, where ``(a_i, b_i)`` converts the device's SI
    unit into ``units[i]``.
    """

    units: tuple[str, ...]
    scale: tuple[float, ...]
    origin: tuple[float, ...]
    gain: tuple[float, ...]
    offset: tuple[float, ...]
    apply: Callable[[Sequence[float]], tuple[float, ...]]

    @property
    def identity(self) -> bool:
        return all(g == 1.0 for g in self.gain) and all(o == 0.0 for o in self.offset)

    @classmethod
    def build(
        cls,
        si_units: tuple[str, ...],
        units: tuple[str, ...],
        scale: tuple[float, ...],
        origin: tuple[float, ...],
        conversions: tuple[tuple[float, float], ...],
    ) -> Measurement:
        gain = tuple(a * s for (a, _), s in zip(conversions, scale, strict=True))
        offset = tuple(b - g * o for (_, b), g, o in zip(conversions, gain, origin, strict=True))
        return cls(units, scale, origin, gain, offset, _affine_map(gain, offset))


def _affine_map(
    gain: tuple[float, ...], offset: tuple[float, ...]
) -> Callable[[Sequence[float]], tuple[float, ...]]:
    """One closure per value count: unrolled up to 3 values (the common sensors)."""
    if len(gain) == 1:
        (g0,), (o0,) = gain, offset
        return lambda v: (g0 * v[0] + o0,)
    if len(gain) == 2:
        (g0, g1), (o0, o1) = gain, offset
        return lambda v: (g0 * v[0] + o0, g1 * v[1] + o1)
    if len(gain) == 3:
        (g0, g1, g2), (o0, o1, o2) = gain, offset
        return lambda v: (g0 * v[0] + o0, g1 * v[1] + o1, g2 * v[2] + o2)
    pairs = tuple(zip(gain, offset, strict=True))
    return lambda v: tuple([g * x + o for (g, o), x in zip(pairs, v, strict=True)])


def checked_affine_map(
    gain: tuple[float, ...], offset: tuple[float, ...]
) -> Callable[[Sequence[float]], tuple[float, ...]]:
    """The read path's map: the converted values if the raw ones are as many as ``gain``
    and every converted value is a finite ``float``; ``ValueError`` (or ``TypeError``)
    otherwise, and the caller takes the checking path. Length, conversion and check in
    one call (unrolled up to 3 values): the finite test is one sum, a float only if
    every term is one (a NumPy scalar makes it a NumPy scalar), ``t - t`` 0.0 only if
    finite."""
    if len(gain) == 1:
        (g0,), (o0,) = gain, offset

        def one(v: Sequence[float]) -> tuple[float, ...]:
            (x0,) = v
            a = g0 * x0 + o0
            if type(a) is float and a - a == 0.0:
                return (a,)
            raise ValueError(a)

        return one
    if len(gain) == 2:
        (g0, g1), (o0, o1) = gain, offset

        def two(v: Sequence[float]) -> tuple[float, ...]:
            x0, x1 = v
            a, b = g0 * x0 + o0, g1 * x1 + o1
            t = a + b
            if type(t) is float and t - t == 0.0:
                return (a, b)
            raise ValueError(t)

        return two
    if len(gain) == 3:
        (g0, g1, g2), (o0, o1, o2) = gain, offset

        def three(v: Sequence[float]) -> tuple[float, ...]:
            x0, x1, x2 = v
            a, b, c = g0 * x0 + o0, g1 * x1 + o1, g2 * x2 + o2
            t = a + b + c
            if type(t) is float and t - t == 0.0:
                return (a, b, c)
            raise ValueError(t)

        return three
    pairs = tuple(zip(gain, offset, strict=True))

    def many(v: Sequence[float]) -> tuple[float, ...]:
        out = tuple([g * x + o for (g, o), x in zip(pairs, v, strict=True)])
        t = sum(out)
        if type(t) is float and t - t == 0.0:
            return out
        raise ValueError(t)

    return many


def check_reals(
    parameter: str, values: object, count: int, *, nonzero: bool = False
) -> tuple[float, ...]:
    """``count`` finite reals (non-zero if asked) as floats, else BadParameterError."""
    if isinstance(values, str | bytes) or not isinstance(values, Sequence) or len(values) != count:
        raise BadParameterError(
            parameter, values, f"a sequence of {count} values, one per value of the sensor"
        )
    out = []
    for i, value in enumerate(values):
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise BadParameterError(f"{parameter}[{i}]", value, "a finite real number")
        try:
            number = float(value)
        except OverflowError:
            number = math.inf
        if not math.isfinite(number) or (nonzero and number == 0.0):
            allowed = "a finite real number other than 0" if nonzero else "a finite real number"
            raise BadParameterError(f"{parameter}[{i}]", value, allowed)
        out.append(number)
    return tuple(out)


class TimedValue(NamedTuple):
    """GetTimedValue's outputs: the value list (its length is the spec's ``num``) and time."""

    values: tuple[float, ...]
    time_ns: int

    @property
    def num(self) -> int:
        return len(self.values)


class Sensor(HALComponent):
    """An OpenEL Sensor over a :class:`SensorDevice` driver."""

    device: SensorDevice
    device_class = SensorDevice

    def __init__(
        self,
        device: SensorDevice,
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
        self._nowait = has_nowait(device, "read_nowait", "read")
        self._measurement: Measurement | None = None
        # The read path's copy of it: the affine map and the number of values it takes.
        self._convert: Callable[[Sequence[float]], tuple[float, ...]] | None = None
        """The per-value settings; None while they are the identity (SI values as read)."""
        self._settings: Measurement | None = None
        """The settings as set, kept even when they make the identity."""

    @property
    def units(self) -> tuple[str, ...]:
        """The unit of each value ``get_value`` returns (the device's SI units by default)."""
        settings = self._settings
        return self.device.units if settings is None else settings.units

    # -- HAL4RT Sensor operations (§7.4.5.5) --------------------------------------------
    @property
    def sensor_kind(self) -> int:
        """HAL4RT ``sensorKindId``: the device kind id (docs/psm.md §4.3)."""
        return self.hal_id.device_kind_id

    def get_sensor_kind(self) -> int:
        """GetSensorKind."""
        self._require("get_sensor_kind", _ACTIVE)
        return self.hal_id.device_kind_id

    async def get_value_of_measurement(self) -> tuple[float, ...]:
        """GetValueOfMeasurement: :meth:`get_value`."""
        return await self.get_value()

    def get_unit_of_measurement(self) -> tuple[str, ...]:
        """GetUnitOfMeasurement: the unit of each value."""
        self._require("get_unit_of_measurement", _ACTIVE)
        return self.units

    def set_unit_of_measurement(self, units: Sequence[str]) -> None:
        """SetUnitOfMeasurement: one unit per value, each of its SI unit's dimension
        ('deg' for 'rad', 'degC' for 'K', 'g' or 'standard_gravity' for 'm/s^2')."""
        si_units = self._si_units("set_unit_of_measurement")
        count = len(si_units)
        if isinstance(units, str) or not isinstance(units, Sequence) or len(units) != count:
            raise BadParameterError("units", units, f"a sequence of {count} unit names")
        chosen = tuple(units)
        for i, unit in enumerate(chosen):
            affine(si_units[i], unit, f"units[{i}]")  # every unit checked before any is set
        current = self._current(si_units)
        self._apply(si_units, chosen, current.scale, current.origin)

    def get_scale_factor(self) -> tuple[float, ...]:
        """GetScaleFactor: the factor of each value (1.0 by default)."""
        si_units = self._si_units("get_scale_factor")
        return self._current(si_units).scale

    def set_scale_factor(self, values: Sequence[float]) -> None:
        """SetScaleFactor: one finite, non-zero factor per value."""
        si_units = self._si_units("set_scale_factor")
        scale = check_reals("values", values, len(si_units), nonzero=True)
        current = self._current(si_units)
        self._apply(si_units, current.units, scale, current.origin)

    def get_origin(self) -> tuple[float, ...]:
        """The origin of each value, in the device's SI unit (0.0 by default)."""
        si_units = self._si_units("get_origin")
        return self._current(si_units).origin

    def set_origin(self, values: Sequence[float]) -> None:
        """SetOrigin: the raw SI value of each value that reads as 0 (before the unit's
        own offset: an origin of 273.15 K reads 0 K, i.e. -273.15 degC)."""
        si_units = self._si_units("set_origin")
        origin = check_reals("values", values, len(si_units))
        current = self._current(si_units)
        self._apply(si_units, current.units, current.scale, origin)

    def _si_units(self, operation: str) -> tuple[str, ...]:
        self._require(operation, _ACTIVE)
        si_units = tuple(self.device.units)
        if not si_units:
            raise NotImplementedHALError(
                f"{self.device_name}: the device declares no units, so the number of its "
                "values is unknown: the unit, scale factor and origin cannot be set"
            )
        return si_units

    def _current(self, si_units: tuple[str, ...]) -> Measurement:
        settings = self._settings
        if settings is not None:
            return settings
        n = len(si_units)
        return Measurement.build(si_units, si_units, (1.0,) * n, (0.0,) * n, ((1.0, 0.0),) * n)

    def _apply(
        self,
        si_units: tuple[str, ...],
        units: tuple[str, ...],
        scale: tuple[float, ...],
        origin: tuple[float, ...],
    ) -> None:
        conversions = tuple(affine(si, unit) for si, unit in zip(si_units, units, strict=True))
        settings = Measurement.build(si_units, units, scale, origin, conversions)
        self._settings = settings
        self._measurement = None if settings.identity else settings
        self._convert = (
            None if settings.identity else checked_affine_map(settings.gain, settings.offset)
        )
        MEASUREMENT_SETTINGS_VERSION.value += 1

    def _checked_conversion(self, raw: Sequence[float]) -> tuple[float, ...]:
        """The slow path of a converted read: raw values checked (a fault names them),
        their count checked, converted, and the results checked (an overflow is a fault);
        NumPy scalars and integers come out as floats."""
        return self._checked_values(self._converted_values(self._checked_values(raw)))

    def _converted_values(self, values: tuple[float, ...]) -> tuple[float, ...]:
        """Apply the measurement settings (only called when some are set)."""
        measurement = self._measurement
        assert measurement is not None
        if len(values) == len(measurement.gain):
            return measurement.apply(values)
        raise self._fault(
            ErrorId.DEVICE_ERROR,
            f"read() returned {len(values)} values where the device declares "
            f"{len(measurement.gain)} units",
        )

    async def get_value(self) -> tuple[float, ...]:
        """GetValue: the measurement values in SI units (``len`` is the spec's ``num``)."""
        if self.state is not _ACTIVE:
            raise StateError("get_value", self.state, (_ACTIVE,))
        raw = (await self._read()).values
        convert = self._convert
        if convert is None:
            values = self._checked_values(raw)
        else:  # converted and checked in one call; anything unusual the checking way
            try:
                values = convert(raw)
            except (TypeError, ValueError):
                values = self._checked_conversion(raw)
        listener = self._observers.listener
        if listener is not None:
            listener.on_reading(self, None, values)
        return values

    async def get_timed_value(self) -> TimedValue:
        """GetTimedValue: values and their measurement time on the component's clock (ns)."""
        self._require_time("get_timed_value")
        return self._checked(await self._read())

    def get_value_nowait(self) -> tuple[float, ...]:
        """GetValue without suspending, for synchronous code (a plain TimerObserver).

        Only for devices that need no I/O to measure (simulations); others raise
        :class:`WouldBlockError`.
        """
        if self.state is not _ACTIVE:
            raise StateError("get_value_nowait", self.state, (_ACTIVE,))
        raw = self._read_now().values
        convert = self._convert
        if convert is None:
            values = self._checked_values(raw)
        else:  # as in get_value
            try:
                values = convert(raw)
            except (TypeError, ValueError):
                values = self._checked_conversion(raw)
        listener = self._observers.listener
        if listener is not None:
            listener.on_reading(self, None, values)
        return values

    def get_timed_value_nowait(self) -> TimedValue:
        """GetTimedValue without suspending (see :meth:`get_value_nowait`)."""
        self._require_time("get_timed_value_nowait")
        return self._checked(self._read_now())

    def _require_time(self, operation: str) -> None:
        if self.state is not _ACTIVE:
            raise StateError(operation, self.state, (_ACTIVE,))
        if not self.device.has_time:
            raise HALError(f"{self.device_name} has no time attribute")

    async def _read(self) -> Reading:
        try:
            if self._nowait:  # a device that needs no I/O: the same, without suspending
                return self.device.read_nowait()
            return await self.device.read()
        except LINK_FAULTS as exc:
            raise self._fault_from(exc) from exc

    def _read_now(self) -> Reading:
        if not self._nowait:
            raise WouldBlockError(
                f"{self.device_name}: the device has no synchronous read path; "
                "use 'await get_value()'"
            )
        try:
            return self.device.read_nowait()
        except LINK_FAULTS as exc:
            raise self._fault_from(exc) from exc

    def _checked(self, reading: Reading) -> TimedValue:
        values = self._checked_values(reading.values)
        if self._measurement is not None:
            values = self._converted_values(values)
        time_ns = reading.time_ns
        listener = self._observers.listener
        if listener is not None:
            listener.on_reading(self, None, values)
        return TimedValue(values, self.clock.now_ns() if time_ns is None else time_ns)

    def _checked_values(self, raw: Sequence[float]) -> tuple[float, ...]:
        """The values as a tuple of finite floats; anything else is a device fault."""
        if type(raw) is tuple:
            # One sum answers "finite floats?" for the common case: it is a float only if
            # some value is a float (ints alone or NumPy scalars are converted below), and
            # x - x is 0.0 only for finite x.
            try:
                total: object = sum(raw)
            except TypeError:  # not numbers: a device fault, below
                total = math.nan
            if type(total) is float and total - total == 0.0:
                return raw
        return self._converted(raw)

    def _converted(self, raw: object) -> tuple[float, ...]:
        try:
            values = tuple(
                float(v) if isinstance(v, numbers.Real) else math.nan
                for v in raw  # type: ignore[attr-defined]
            )
        except (TypeError, ValueError, OverflowError):
            values = (math.nan,)
        if all(math.isfinite(v) for v in values):
            return values
        raise self._fault(
            ErrorId.DEVICE_ERROR, f"read() returned a non-finite or non-numeric value in {raw!r}"
        )
