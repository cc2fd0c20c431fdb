"""Simulated sensors: encoder, IMU and temperature, with noise and timestamps.

Noise comes from a seeded generator so a run is reproducible; readings carry the
clock time at which they were taken.
"""

from __future__ import annotations

import math
import random

from openel_async.device import DeviceContext, DeviceInfo, Reading, SensorDevice
from openel_async.errors import BadParameterError, NotConnectedError
from openel_async.ids import DeviceKind

from .motor import SimMotor

STANDARD_GRAVITY = 9.80665
THERMAL_STEP_NS = 10_000_000
MAX_THERMAL_STEPS = 10_000


class _SimSensor(SensorDevice):
    def __init__(self, *, noise: float = 0.0, seed: int = 0) -> None:
        if not (math.isfinite(noise) and noise >= 0):
            raise BadParameterError("noise", noise, "a finite standard deviation >= 0")
        self.noise = noise
        self._rng = random.Random(seed)
        self._ctx: DeviceContext | None = None
        self.connected = True

    async def open(self, ctx: DeviceContext) -> None:
        self._ctx = ctx

    async def reset(self) -> None:
        self._check()

    def _now(self) -> int:
        assert self._ctx is not None, "sensor used before open()"
        return self._ctx.clock.now_ns()

    def _noisy(self, value: float) -> float:
        return value + self._rng.gauss(0.0, self.noise) if self.noise else value

    async def read(self) -> Reading:
        return self.read_nowait()

    def _check(self) -> None:
        if not self.connected:
            raise NotConnectedError("simulated sensor is disconnected")

    def disconnect(self) -> None:
        self.connected = False

    def reconnect(self) -> None:
        self.connected = True


class SimEncoder(_SimSensor):
    """A rotary encoder on a SimMotor's shaft: the angle quantized to counts (rad)."""

    info = DeviceInfo(DeviceKind.ROTARY_ANGLE, 0x0E1, 0x200, "OpenEL", "SimEncoder")
    units = ("rad",)

    def __init__(
        self, motor: SimMotor, *, counts_per_rev: int = 4096, noise: float = 0.0, seed: int = 0
    ):
        super().__init__(noise=noise, seed=seed)
        if counts_per_rev < 1:
            raise BadParameterError("counts_per_rev", counts_per_rev, "an int >= 1")
        self.motor = motor
        self.counts_per_rev = counts_per_rev

    def read_nowait(self) -> Reading:
        self._check()
        now = self._now()
        position, _, _ = self.motor.state_at(now)
        step = 2 * math.pi / self.counts_per_rev
        return Reading((round(self._noisy(position) / step) * step,), now)


class SimIMU(_SimSensor):
    """A 6-axis IMU at rest or on a SimMotor's shaft (rotation about z).

    Values: acceleration x, y, z (m/s^2, gravity included) then angular rate x, y, z
    (rad/s), each with Gaussian noise and a constant bias.
    """

    info = DeviceInfo(DeviceKind.ACCEL, 0x0E1, 0x300, "OpenEL", "SimIMU")
    units = ("m/s^2", "m/s^2", "m/s^2", "rad/s", "rad/s", "rad/s")

    def __init__(
        self,
        motor: SimMotor | None = None,
        *,
        radius: float = 0.0,
        noise: float = 0.0,
        gyro_bias: float = 0.0,
        seed: int = 0,
    ) -> None:
        super().__init__(noise=noise, seed=seed)
        self.motor = motor
        self.radius = radius
        self.gyro_bias = gyro_bias

    def read_nowait(self) -> Reading:
        self._check()
        now = self._now()
        omega = alpha = 0.0
        if self.motor is not None:
            _, omega, alpha = self.motor.state_at(now)
        # A point at ``radius`` on the rotating link: centripetal and tangential terms.
        ax = -omega * omega * self.radius
        ay = alpha * self.radius
        az = STANDARD_GRAVITY
        values = (ax, ay, az, 0.0, 0.0, omega + self.gyro_bias)
        return Reading(tuple(self._noisy(v) for v in values), now)


class SimTemperature(_SimSensor):
    """A motor-winding thermometer (K): first-order heating by torque^2, cooling to ambient."""

    info = DeviceInfo(DeviceKind.TEMPERATURE, 0x0E1, 0x400, "OpenEL", "SimTemperature")
    units = ("K",)

    def __init__(
        self,
        motor: SimMotor | None = None,
        *,
        ambient: float = 298.15,
        heating: float = 5.0,
        time_constant: float = 30.0,
        noise: float = 0.0,
        seed: int = 0,
    ) -> None:
        super().__init__(noise=noise, seed=seed)
        if not time_constant > 0:
            raise BadParameterError("time_constant", time_constant, "a value > 0 (seconds)")
        self.motor = motor
        self.ambient = ambient
        self.heating = heating
        self.time_constant = time_constant
        self._temperature = ambient
        self._last_ns: int | None = None

    def read_nowait(self) -> Reading:
        self._check()
        now = self._now()
        t = self._last_ns if self._last_ns is not None else now
        # Exact first-order steps over sub-intervals short against the thermal time
        # constant, each heated by the torque at its start.
        step = max(THERMAL_STEP_NS, (now - t) // MAX_THERMAL_STEPS)
        while t < now:
            dt = min(step, now - t)
            torque = self.motor.torque_at(t) if self.motor is not None else 0.0
            steady = self.ambient + self.heating * torque * torque
            decay = math.exp(-dt * 1e-9 / self.time_constant)
            self._temperature = steady + (self._temperature - steady) * decay
            t += dt
        self._last_ns = now
        return Reading((self._noisy(self._temperature),), now)
