"""A third-party driver: a simulated linear stage with a first-order lag, and its scale.

The stage does not report completion: the framework detects it by tolerance and settle.
"""

from __future__ import annotations

import math

from openel_async import (
    ActuatorDevice,
    ActuatorLimits,
    Clock,
    DeviceContext,
    DeviceInfo,
    DeviceKind,
    DriverInfo,
    NotConnectedError,
    Reading,
    Request,
    SensorDevice,
    default_clock,
)


class LinearStage(ActuatorDevice):
    """Position/velocity-controlled stage in metres; the actual value lags the target."""

    info = DeviceInfo(DeviceKind.MOTOR, 0x5A, 0x1, "Acme", "LinearStage")
    limits = ActuatorLimits(position=(0.0, 0.3), velocity=0.5)
    supported_requests = frozenset({Request.NO_EXCITE, Request.POSITION, Request.VELOCITY})
    # No force sensor: get_value(TORQUE_ACTUAL) is the commanded torque, read() never sees it.
    measured_requests = frozenset({Request.POSITION_ACTUAL, Request.VELOCITY_ACTUAL})
    reports_completion = False

    def __init__(self, time_constant: float = 0.05) -> None:
        self.tau = time_constant
        self.connected = True  # set False to simulate a lost link
        self.clock: Clock = default_clock()  # replaced by the component's clock in open()
        self._t0, self._p0, self._v0 = 0, 0.0, 0.0
        self._mode, self._target = Request.VELOCITY, 0.0  # at rest

    async def open(self, ctx: DeviceContext) -> None:
        self.clock = ctx.clock
        self._t0 = ctx.clock.now_ns()

    async def command(self, request: Request, value: float) -> None:
        self._check()
        now = self.clock.now_ns()
        self._p0, self._v0 = self.state_at(now)
        self._t0 = now
        # NO_EXCITE: power off, the stage coasts to rest (a velocity target of 0).
        self._mode = Request.POSITION if request is Request.POSITION else Request.VELOCITY
        self._target = 0.0 if request is Request.NO_EXCITE else value

    async def read(self, request: Request) -> float:
        self._check()
        position, velocity = self.state_at(self.clock.now_ns())
        return position if request is Request.POSITION_ACTUAL else velocity

    def state_at(self, t_ns: int) -> tuple[float, float]:
        """(position in m, velocity in m/s) at a time of the component's clock, closed-form."""
        dt, p0, v0, x = (t_ns - self._t0) * 1e-9, self._p0, self._v0, self._target
        k = math.exp(-dt / self.tau)
        if self._mode is Request.POSITION:  # x is a position
            return x + (p0 - x) * k, (x - p0) * k / self.tau
        return p0 + x * dt + (v0 - x) * self.tau * (1 - k), x + (v0 - x) * k  # x: velocity

    def _check(self) -> None:
        if not self.connected:
            raise NotConnectedError("stage link lost")  # a link fault: -> Error state


class LinearScale(SensorDevice):
    """An optical scale on the stage: one value, the position in metres."""

    info = DeviceInfo(DeviceKind.DISTANCE, 0x5A, 0x2, "Acme", "LinearScale")
    units = ("m",)

    def __init__(self, stage: LinearStage) -> None:
        self.stage = stage
        self.clock: Clock = default_clock()  # replaced by the component's clock in open()

    async def open(self, ctx: DeviceContext) -> None:
        self.clock = ctx.clock

    async def read(self) -> Reading:
        now = self.clock.now_ns()
        return Reading((self.stage.state_at(now)[0],), now)


DRIVER = DriverInfo(
    name="linear_stage",
    description="Simulated first-order-lag linear stage and its scale",
    devices={"stage": LinearStage, "scale": LinearScale},
)
