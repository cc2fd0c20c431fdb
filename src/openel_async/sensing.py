"""A component with both Actuator and Sensor characteristics (OpenEL §7.4.1.1: "such as
cameras with gimbal mechanisms").

:class:`SensingMotor` is one component (one HALId, one state machine, one observer list)
that is a :class:`Motor` (a 1-DOF actuator: set_value/get_value, the HAL4RT Motor names)
and also offers the Sensor operations over the values its device measures besides the
actuator's own position, speed and torque (a camera head's line of sight, a gripper's
finger forces...). The Sensor names that would clash with the actuator's are renamed:
OpenEL's Sensor ``GetValue`` is :meth:`~SensingMotor.get_value_of_measurement` (HAL4RT's
name), HAL4RT's Sensor ``SetScaleFactor``/``SetOrigin`` are
``set_measurement_scale_factor``/``set_measurement_origin`` (the Motor has its own scale
factor and origin).
"""

from __future__ import annotations

import math
import numbers
from abc import abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass

from .actuator import CompletionPolicy
from .clock import Clock
from .component import LINK_FAULTS, ComponentState
from .device import ActuatorDevice, ErrorId, Reading
from .errors import BadParameterError, HALError, NotImplementedHALError, WouldBlockError
from .ids import HALId
from .motor import Motor
from .sensor import Measurement, TimedValue, check_reals
from .units import affine

_ACTIVE = ComponentState.ACTIVE


class SensingActuatorDevice(ActuatorDevice):
    """An actuator device that also measures: the driver of a :class:`SensingMotor`."""

    sensor_kind: int = 0
    """The device kind id of the measurement (``DeviceKind.ROTARY_ANGLE``...)."""
    sensor_units: tuple[str, ...] = ()
    """The SI unit of each measured value (fixes their number)."""

    @abstractmethod
    async def read_sensor(self) -> Reading:
        """One measurement, in SI units (as ``SensorDevice.read``)."""

    def read_sensor_nowait(self) -> Reading:
        """``read_sensor`` without suspending; only for devices that need no I/O."""
        raise WouldBlockError(f"{type(self).__name__} has no synchronous sensor path")


@dataclass(slots=True)
class SensingState:
    """The Sensor side's settings (one slot: the Actuator's attribute budget)."""

    settings: Measurement | None = None


class SensingMotor(Motor):
    """A Motor that is also a Sensor; see the module docstring."""

    __slots__ = ("_sensing",)
    device: SensingActuatorDevice
    device_class = SensingActuatorDevice

    def __init__(
        self,
        device: SensingActuatorDevice,
        *,
        scale_factor: float | None = None,
        hal_id: HALId | None = None,
        device_name: str | None = None,
        function_list: tuple[str, ...] | None = None,
        clock: Clock | None = None,
        auto_init: bool = True,
        open_timeout: float = 10.0,
        completion: CompletionPolicy | None = None,
    ) -> None:
        super().__init__(
            device,
            scale_factor=scale_factor,
            hal_id=hal_id,
            device_name=device_name,
            function_list=function_list,
            clock=clock,
            auto_init=auto_init,
            open_timeout=open_timeout,
            completion=completion,
        )
        self._sensing = SensingState()

    # -- Sensor characteristics ---------------------------------------------------------
    @property
    def sensor_kind(self) -> int:
        return int(self.device.sensor_kind)

    def get_sensor_kind(self) -> int:
        """GetSensorKind: the kind of the measurement (the component's own kind is
        ``profile_id``, a motor)."""
        self._require("get_sensor_kind", _ACTIVE)
        return int(self.device.sensor_kind)

    @property
    def sensor_units(self) -> tuple[str, ...]:
        settings = self._sensing.settings
        return tuple(self.device.sensor_units) if settings is None else settings.units

    async def get_value_of_measurement(self) -> tuple[float, ...]:
        """OpenEL Sensor GetValue / HAL4RT GetValueOfMeasurement."""
        self._require("get_value_of_measurement", _ACTIVE)
        try:
            reading = await self.device.read_sensor()
        except LINK_FAULTS as exc:
            raise self._fault_from(exc) from exc
        return self._measured(reading.values)

    def get_value_of_measurement_nowait(self) -> tuple[float, ...]:
        """:meth:`get_value_of_measurement` without suspending (devices without I/O)."""
        self._require("get_value_of_measurement_nowait", _ACTIVE)
        try:
            reading = self.device.read_sensor_nowait()
        except LINK_FAULTS as exc:
            raise self._fault_from(exc) from exc
        return self._measured(reading.values)

    async def get_timed_value(self) -> TimedValue:
        """OpenEL Sensor GetTimedValue: the measurement and its time on the clock (ns)."""
        self._require("get_timed_value", _ACTIVE)
        if not self.device.has_time:
            raise HALError(f"{self.device_name} has no time attribute")
        try:
            reading = await self.device.read_sensor()
        except LINK_FAULTS as exc:
            raise self._fault_from(exc) from exc
        values = self._measured(reading.values)
        time_ns = reading.time_ns
        return TimedValue(values, self.clock.now_ns() if time_ns is None else time_ns)

    def get_timed_value_nowait(self) -> TimedValue:
        """:meth:`get_timed_value` without suspending (devices without I/O)."""
        self._require("get_timed_value_nowait", _ACTIVE)
        if not self.device.has_time:
            raise HALError(f"{self.device_name} has no time attribute")
        try:
            reading = self.device.read_sensor_nowait()
        except LINK_FAULTS as exc:
            raise self._fault_from(exc) from exc
        values = self._measured(reading.values)
        time_ns = reading.time_ns
        return TimedValue(values, self.clock.now_ns() if time_ns is None else time_ns)

    def get_unit_of_measurement(self) -> tuple[str, ...]:
        self._require("get_unit_of_measurement", _ACTIVE)
        return self.sensor_units

    def set_unit_of_measurement(self, units: Sequence[str]) -> None:
        """As ``Sensor.set_unit_of_measurement`` (docs/psm.md §8.1)."""
        si_units = self._si_units("set_unit_of_measurement")
        if isinstance(units, str) or not isinstance(units, Sequence) or len(units) != len(si_units):
            raise BadParameterError("units", units, f"a sequence of {len(si_units)} unit names")
        chosen = tuple(units)
        for i, unit in enumerate(chosen):
            affine(si_units[i], unit, f"units[{i}]")
        current = self._current(si_units)
        self._apply(si_units, chosen, current.scale, current.origin)

    def get_measurement_scale_factor(self) -> tuple[float, ...]:
        """HAL4RT Sensor GetScaleFactor (the Motor's own is ``get_scale_factor``)."""
        return self._current(self._si_units("get_measurement_scale_factor")).scale

    def set_measurement_scale_factor(self, values: Sequence[float]) -> None:
        """HAL4RT Sensor SetScaleFactor (the Motor's own is ``set_scale_factor``)."""
        si_units = self._si_units("set_measurement_scale_factor")
        scale = check_reals("values", values, len(si_units), nonzero=True)
        current = self._current(si_units)
        self._apply(si_units, current.units, scale, current.origin)

    def get_measurement_origin(self) -> tuple[float, ...]:
        return self._current(self._si_units("get_measurement_origin")).origin

    def set_measurement_origin(self, values: Sequence[float]) -> None:
        """HAL4RT Sensor SetOrigin (the Motor's own is ``set_origin``)."""
        si_units = self._si_units("set_measurement_origin")
        origin = check_reals("values", values, len(si_units))
        current = self._current(si_units)
        self._apply(si_units, current.units, current.scale, origin)

    # -- internals ------------------------------------------------------------------------
    def _si_units(self, operation: str) -> tuple[str, ...]:
        self._require(operation, _ACTIVE)
        si_units = tuple(self.device.sensor_units)
        if not si_units:
            raise NotImplementedHALError(f"{self.device_name}: the device declares no sensor units")
        return si_units

    def _current(self, si_units: tuple[str, ...]) -> Measurement:
        settings = self._sensing.settings
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
        self._sensing.settings = Measurement.build(si_units, units, scale, origin, conversions)

    def _measured(self, raw: Sequence[float]) -> tuple[float, ...]:
        """Finite floats, converted by the settings; anything else is a device fault."""
        values: list[float] = []
        for value in raw:
            number = float(value) if isinstance(value, numbers.Real) else math.nan
            if not math.isfinite(number):
                raise self._fault(
                    ErrorId.DEVICE_ERROR,
                    f"read_sensor() returned a non-finite or non-numeric value in {raw!r}",
                )
            values.append(number)
        settings = self._sensing.settings
        if settings is None:
            result = tuple(values)
        elif len(values) == len(settings.gain):
            result = settings.apply(tuple(values))
        else:
            raise self._fault(
                ErrorId.DEVICE_ERROR,
                f"read_sensor() returned {len(values)} values for {len(settings.gain)} units",
            )
        listener = self._observers.listener
        if listener is not None:  # a recorder hears the sensor side as a Sensor's reading
            listener.on_reading(self, None, result)
        return result
