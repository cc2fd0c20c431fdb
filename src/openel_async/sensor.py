"""Sensor: GetValue and GetTimedValue in SI units."""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence
from typing import NamedTuple

from .clock import Clock
from .component import LINK_FAULTS, ComponentState, HALComponent
from .device import ErrorId, Reading, SensorDevice, has_nowait
from .errors import HALError, StateError, WouldBlockError
from .ids import HALId

S = ComponentState
_ACTIVE = S.ACTIVE  # enum member as a module constant on the per-read path (~80 ns saved)


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

    @property
    def units(self) -> tuple[str, ...]:
        return self.device.units

    async def get_value(self) -> tuple[float, ...]:
        """GetValue: the measurement values in SI units (``len`` is the spec's ``num``)."""
        if self.state is not _ACTIVE:
            raise StateError("get_value", self.state, (_ACTIVE,))
        return self._checked_values((await self._read()).values)

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
        return self._checked_values(self._read_now().values)

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
        time_ns = reading.time_ns
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
