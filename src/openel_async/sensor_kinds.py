"""HAL4RT's sensor kinds (§7.4.5.6-7.4.5.14): one Sensor class per kind, with its kind id.

HAL4RT's example kind table (1 Motor, 2 Encoder, 3 GyroSensor, 4 TorqueSensor) clashes with
the OpenEL registry that :class:`DeviceKind` follows; the OpenEL ids are kept, Encoder is a
``ROTARY_ANGLE`` sensor, Direction a ``COMPASS`` sensor, and GPS takes an id from the
extension range (docs/psm.md §4.3). The classes add no operation (the spec's kinds add none,
except GPS and Direction, which live in their own modules): they fix the kind and check that
the device is of it.
"""

from __future__ import annotations

from typing import ClassVar

from .clock import Clock
from .device import SensorDevice
from .errors import BadParameterError
from .ids import DeviceKind, HALId
from .sensor import Sensor

HAL4RT_KIND_NAMES: dict[int, str] = {
    DeviceKind.MOTOR: "Motor",
    DeviceKind.ROTARY_ANGLE: "Encoder",
    DeviceKind.GYRO: "GyroSensor",
    DeviceKind.ACCEL: "AccelerationSensor",
    DeviceKind.FORCE: "ForceSensor",
    DeviceKind.TORQUE: "TorqueSensor",
    DeviceKind.TEMPERATURE: "TemperatureSensor",
    DeviceKind.HUMIDITY: "HumiditySensor",
    DeviceKind.GPS: "GPSSensor",
    DeviceKind.COMPASS: "DirectionSensor",
}
"""HAL4RT's class name of each device kind id that HAL4RT defines (§7.4.5.4-7.4.5.14)."""


class KindSensor(Sensor):
    """A Sensor of one HAL4RT kind: the device's kind (or the given ``hal_id``'s) must be
    :attr:`KIND`."""

    KIND: ClassVar[DeviceKind]

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
        kind = hal_id.device_kind_id if isinstance(hal_id, HALId) else _kind_of(device)
        if kind != self.KIND:
            raise BadParameterError(
                "device",
                device,
                f"a device of kind {self.KIND.name} (0x{int(self.KIND):X}) for a "
                f"{type(self).__name__}",
            )
        super().__init__(
            device,
            hal_id=hal_id,
            device_name=device_name,
            function_list=function_list,
            clock=clock,
            auto_init=auto_init,
            open_timeout=open_timeout,
        )


def _kind_of(device: object) -> int | None:
    info = getattr(device, "info", None)
    kind = getattr(info, "kind", None)
    return int(kind) if isinstance(kind, int) else None


class Encoder(KindSensor):
    """§7.4.5.6: position / angle (rad or m)."""

    KIND = DeviceKind.ROTARY_ANGLE


class GyroSensor(KindSensor):
    """§7.4.5.7: angular velocity (rad/s)."""

    KIND = DeviceKind.GYRO


class AccelerationSensor(KindSensor):
    """§7.4.5.8: acceleration (m/s^2)."""

    KIND = DeviceKind.ACCEL


class ForceSensor(KindSensor):
    """§7.4.5.9: force (N)."""

    KIND = DeviceKind.FORCE


class TorqueSensor(KindSensor):
    """§7.4.5.10: torque (N m)."""

    KIND = DeviceKind.TORQUE


class TemperatureSensor(KindSensor):
    """§7.4.5.11: temperature (K)."""

    KIND = DeviceKind.TEMPERATURE


class HumiditySensor(KindSensor):
    """§7.4.5.12: relative humidity (percent)."""

    KIND = DeviceKind.HUMIDITY


SENSOR_CLASSES: dict[int, type[Sensor]] = {
    cls.KIND: cls
    for cls in (
        Encoder,
        GyroSensor,
        AccelerationSensor,
        ForceSensor,
        TorqueSensor,
        TemperatureSensor,
        HumiditySensor,
    )
}
"""The Sensor class of each kind id; GPS and Direction register theirs with
:func:`register_sensor_class`."""


def register_sensor_class(kind: int, cls: type[Sensor]) -> None:
    """Make ``cls`` the Sensor class of device kind ``kind`` (for :func:`sensor_class`)."""
    if not (isinstance(cls, type) and issubclass(cls, Sensor)):
        raise BadParameterError("cls", cls, "a Sensor subclass")
    SENSOR_CLASSES[int(kind)] = cls


def sensor_class(kind: int) -> type[Sensor]:
    """The Sensor class of a kind id: its HAL4RT class, else the plain :class:`Sensor`."""
    return SENSOR_CLASSES.get(int(kind), Sensor)
