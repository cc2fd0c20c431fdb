"""Sensor: GetValue and GetTimedValue in SI units."""

from __future__ import annotations

import math
from typing import NamedTuple

from .clock import Clock
from .component import LINK_FAULTS, ComponentState, HALComponent
from .device import SensorDevice
from .errors import HALError
from .ids import HALId

S = ComponentState


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

    @property
    def units(self) -> tuple[str, ...]:
        return self.device.units

    async def get_value(self) -> tuple[float, ...]:
        """GetValue: the measurement values in SI units (``len`` is the spec's ``num``)."""
        return (await self._read("get_value")).values

    async def get_timed_value(self) -> TimedValue:
        """GetTimedValue: values and their measurement time on the component's clock (ns)."""
        if not self.device.has_time and self.state is S.ACTIVE:
            raise HALError(f"{self.device_name} has no time attribute")
        return await self._read("get_timed_value")

    async def _read(self, operation: str) -> TimedValue:
        self._require(operation, S.ACTIVE)
        try:
            reading = await self.device.read()
        except LINK_FAULTS as exc:
            raise self._fault_from(exc) from exc
        raw = reading.values
        values = raw if type(raw) is tuple else tuple(raw)
        # One sum answers "all finite?" for the common case; look closer only if not.
        if not math.isfinite(math.fsum(values)) and not all(math.isfinite(v) for v in values):
            raise HALError(f"{self.device_name}: device returned a non-finite value {values}")
        time_ns = reading.time_ns if reading.time_ns is not None else self.clock.now_ns()
        return TimedValue(values, time_ns)
