"""SimPanTiltHead: a camera on a pan-tilt head, one component that is an actuator and a
sensor (OpenEL §7.4.1.1, "cameras with gimbal mechanisms"; ``SensingMotor``).

The actuator is the pan axis (a 1-DOF SimMotor: OpenEL's Actuator has one degree of
freedom); the tilt axis is a vendor function, ``set_tilt(angle)``, moved by a second
simulated servo. The sensor is the camera: its line of sight (azimuth = pan, elevation =
tilt, rad, from the head's encoders) and where a target appears in the image (the target's
direction minus the line of sight, rad), the error a tracking loop closes.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Coroutine
from typing import Any

from openel_async.clock import Clock
from openel_async.device import DeviceContext, DeviceInfo, Reading
from openel_async.errors import BadParameterError, ReturnCode
from openel_async.ids import DeviceKind, HALId
from openel_async.requests import Request
from openel_async.sensing import SensingActuatorDevice

from .motor import SimMotor


class _TiltContext:
    """The head's context for its tilt servo: the tilt's arrival is not the pan's."""

    def __init__(self, ctx: DeviceContext) -> None:
        self._ctx = ctx

    @property
    def clock(self) -> Clock:
        return self._ctx.clock

    @property
    def name(self) -> str:
        return f"{self._ctx.name}.tilt"

    @property
    def hal_id(self) -> HALId:
        return self._ctx.hal_id

    def start_soon(self, func: Callable[..., Coroutine[Any, Any, Any]], *args: Any) -> None:
        self._ctx.start_soon(func, *args)

    def target_reached(self) -> None:
        pass

    def post_event(self, event_id: int) -> None:
        pass

    def post_error(self, error_id: int) -> None:
        self._ctx.post_error(error_id)

    def fault(self, error_id: int, reason: str, code: ReturnCode = ReturnCode.HAL_ERROR) -> None:
        self._ctx.fault(error_id, f"tilt: {reason}", code)


class SimPanTiltHead(SimMotor, SensingActuatorDevice):
    """Pan axis (the actuator) + tilt servo (``set_tilt``) + camera (the sensor)."""

    info = DeviceInfo(
        kind=DeviceKind.MOTOR,
        vendor_id=0x0E1,
        product_id=0x800,
        vendor_name="OpenEL",
        product_name="SimPanTiltHead",
        functions=("set_tilt", "get_tilt", "set_target"),
    )
    sensor_kind = DeviceKind.ROTARY_ANGLE
    sensor_units = ("rad", "rad", "rad", "rad")
    """Azimuth, elevation of the line of sight; target offset in the image (x, y)."""

    def __init__(
        self,
        *,
        tilt_limits: tuple[float, float] = (-math.pi / 2, math.pi / 2),
        target: tuple[float, float] = (0.0, 0.0),
        **pan: Any,
    ) -> None:
        super().__init__(**pan)
        self.tilt = SimMotor(position_limits=tilt_limits, max_velocity=1.0)
        self.target = target

    async def open(self, ctx: DeviceContext) -> None:
        await super().open(ctx)
        await self.tilt.open(_TiltContext(ctx))

    async def close(self) -> None:
        await self.tilt.close()
        await super().close()

    def set_tilt(self, angle: float) -> None:
        """Move the tilt axis to ``angle`` (rad) within its limits."""
        self.tilt.limits.check(Request.POSITION, angle)
        self.tilt.command_nowait(Request.POSITION, angle)

    def get_tilt(self) -> float:
        return self.tilt.read_nowait(Request.POSITION_ACTUAL)

    def set_target(self, azimuth: float, elevation: float) -> None:
        """The direction of the target the camera sees (rad)."""
        if not (math.isfinite(azimuth) and math.isfinite(elevation)):
            raise BadParameterError("target", (azimuth, elevation), "finite angles (rad)")
        self.target = (azimuth, elevation)

    async def read_sensor(self) -> Reading:
        return self.read_sensor_nowait()

    def read_sensor_nowait(self) -> Reading:
        now = self._now()
        azimuth = self.state_at(now)[0]
        elevation = self.tilt.state_at(now)[0]
        return Reading(
            (azimuth, elevation, self.target[0] - azimuth, self.target[1] - elevation), now
        )
