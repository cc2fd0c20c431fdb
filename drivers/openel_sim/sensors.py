"""Simulated sensors: encoder (rad), IMU (m/s^2, rad/s), gyro (rad/s), accelerometer
(m/s^2), torque (N*m), force (N), temperature (K), humidity (percent) and magnetometer (T),
with noise and timestamps; docs/testing.md lists every constructor with its units.

Noise (``noise``: a standard deviation in the value's unit) comes from a generator seeded
with ``seed`` so a run is reproducible; readings carry the clock time at which they were
taken. A sensor given a ``motor`` reads that SimMotor's state at that time.
"""

from __future__ import annotations

import math
import random
from abc import abstractmethod

from openel_async.device import DeviceContext, DeviceInfo, Reading, SensorDevice
from openel_async.errors import BadParameterError, NotConnectedError
from openel_async.ids import DeviceKind

from .motor import SimMotor

STANDARD_GRAVITY = 9.80665
THERMAL_STEP_NS = 10_000_000
MAX_THERMAL_STEPS = 10_000


def _motion(motor: SimMotor | None, t_ns: int) -> tuple[float, float, float]:
    """(position, velocity, acceleration) of ``motor`` at a clock time; zeros without one."""
    return motor.state_at(t_ns) if motor is not None else (0.0, 0.0, 0.0)


def _torque(motor: SimMotor | None, t_ns: int) -> float:
    """``motor``'s torque at a clock time; zero without one."""
    return motor.torque_at(t_ns) if motor is not None else 0.0


def _link_acceleration(omega: float, alpha: float, radius: float) -> tuple[float, float, float]:
    """Acceleration (m/s^2, gravity included) of a point at ``radius`` on a link rotating
    about z at ``omega`` (rad/s) and ``alpha`` (rad/s^2): centripetal and tangential terms."""
    return (-omega * omega * radius, alpha * radius, STANDARD_GRAVITY)


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

    def read_nowait(self) -> Reading:
        self._check()
        now = self._now()
        return Reading(self._sample(now), now)

    @abstractmethod
    def _sample(self, now: int) -> tuple[float, ...]:
        """The values at clock time ``now`` (noise included); the sensor is connected."""

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

    def _sample(self, now: int) -> tuple[float, ...]:
        position, _, _ = self.motor.state_at(now)
        step = 2 * math.pi / self.counts_per_rev
        return (round(self._noisy(position) / step) * step,)


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

    def _sample(self, now: int) -> tuple[float, ...]:
        _, omega, alpha = _motion(self.motor, now)
        values = (*_link_acceleration(omega, alpha, self.radius), 0.0, 0.0, omega + self.gyro_bias)
        return tuple(self._noisy(v) for v in values)


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

    def _sample(self, now: int) -> tuple[float, ...]:
        t = self._last_ns if self._last_ns is not None else now
        # Exact first-order steps over sub-intervals short against the thermal time
        # constant, each heated by the torque at its start.
        step = max(THERMAL_STEP_NS, (now - t) // MAX_THERMAL_STEPS)
        while t < now:
            dt = min(step, now - t)
            torque = _torque(self.motor, t)
            steady = self.ambient + self.heating * torque * torque
            decay = math.exp(-dt * 1e-9 / self.time_constant)
            self._temperature = steady + (self._temperature - steady) * decay
            t += dt
        self._last_ns = now
        return (self._noisy(self._temperature),)


class SimGyro(_SimSensor):
    """A 3-axis gyro (rad/s) at rest or on a SimMotor's shaft (rotation about z)."""

    info = DeviceInfo(DeviceKind.GYRO, 0x0E1, 0x310, "OpenEL", "SimGyro")
    units = ("rad/s", "rad/s", "rad/s")

    def __init__(
        self, motor: SimMotor | None = None, *, bias: float = 0.0, noise: float = 0.0, seed: int = 0
    ) -> None:
        super().__init__(noise=noise, seed=seed)
        self.motor = motor
        self.bias = bias

    def _sample(self, now: int) -> tuple[float, ...]:
        omega = _motion(self.motor, now)[1]
        return (self._noisy(0.0), self._noisy(0.0), self._noisy(omega + self.bias))


class SimAccelerometer(_SimSensor):
    """A 3-axis accelerometer (m/s^2, gravity included) at ``radius`` on a SimMotor's link."""

    info = DeviceInfo(DeviceKind.ACCEL, 0x0E1, 0x320, "OpenEL", "SimAccelerometer")
    units = ("m/s^2", "m/s^2", "m/s^2")

    def __init__(
        self,
        motor: SimMotor | None = None,
        *,
        radius: float = 0.0,
        noise: float = 0.0,
        seed: int = 0,
    ) -> None:
        super().__init__(noise=noise, seed=seed)
        self.motor = motor
        self.radius = radius

    def _sample(self, now: int) -> tuple[float, ...]:
        _, omega, alpha = _motion(self.motor, now)
        return tuple(self._noisy(v) for v in _link_acceleration(omega, alpha, self.radius))


class SimTorqueSensor(_SimSensor):
    """An in-line torque sensor on a SimMotor's shaft (N*m): the motor's torque."""

    info = DeviceInfo(DeviceKind.TORQUE, 0x0E1, 0x600, "OpenEL", "SimTorqueSensor")
    units = ("N*m",)

    def __init__(self, motor: SimMotor, *, noise: float = 0.0, seed: int = 0) -> None:
        super().__init__(noise=noise, seed=seed)
        self.motor = motor

    def _sample(self, now: int) -> tuple[float, ...]:
        return (self._noisy(self.motor.torque_at(now)),)


class SimForceSensor(_SimSensor):
    """A force sensor at the tip of a SimMotor's lever arm (N): the tangential force
    torque / ``lever_arm``, plus a constant ``load`` (N)."""

    info = DeviceInfo(DeviceKind.FORCE, 0x0E1, 0x500, "OpenEL", "SimForceSensor")
    units = ("N",)

    def __init__(
        self,
        motor: SimMotor | None = None,
        *,
        lever_arm: float = 0.1,
        load: float = 0.0,
        noise: float = 0.0,
        seed: int = 0,
    ) -> None:
        super().__init__(noise=noise, seed=seed)
        if not (math.isfinite(lever_arm) and lever_arm > 0):
            raise BadParameterError("lever_arm", lever_arm, "a finite length > 0 (m)")
        self.motor = motor
        self.lever_arm = lever_arm
        self.load = load

    def _sample(self, now: int) -> tuple[float, ...]:
        return (self._noisy(_torque(self.motor, now) / self.lever_arm + self.load),)


class SimHumidity(_SimSensor):
    """A relative-humidity sensor (percent): the air's water content fixed by
    ``humidity`` at ``ambient`` K; next to a SimTemperature it follows that temperature
    (Magnus formula: warmer air, lower relative humidity), clipped to 0-100 %."""

    info = DeviceInfo(DeviceKind.HUMIDITY, 0x0E1, 0x900, "OpenEL", "SimHumidity")
    units = ("percent",)

    def __init__(
        self,
        thermometer: SimTemperature | None = None,
        *,
        humidity: float = 45.0,
        ambient: float = 298.15,
        noise: float = 0.0,
        seed: int = 0,
    ) -> None:
        super().__init__(noise=noise, seed=seed)
        if not (math.isfinite(humidity) and 0.0 <= humidity <= 100.0):
            raise BadParameterError("humidity", humidity, "a relative humidity in 0..100 %")
        self.thermometer = thermometer
        self.humidity = humidity
        self.ambient = ambient

    @staticmethod
    def _saturation(kelvin: float) -> float:
        celsius = kelvin - 273.15
        return 6.112 * math.exp(17.62 * celsius / (243.12 + celsius))  # hPa (Magnus)

    def _sample(self, now: int) -> tuple[float, ...]:
        rh = self.humidity
        if self.thermometer is not None:
            temperature = self.thermometer.read_nowait().values[0]
            rh *= self._saturation(self.ambient) / self._saturation(temperature)
        return (min(100.0, max(0.0, self._noisy(rh))),)


DEFAULT_FIELD_NED_NT = (30_500.0, -3_900.0, 35_600.0)
"""Earth's field (north X, east Y, down Z, nT) used by default: WMM2025 near Tokyo, 2025.0
(a declination of about -7.3 degrees, an inclination of about 49 degrees)."""


class SimMagnetometer(_SimSensor):
    """A 3-axis magnetometer (T): Earth's field seen in the sensor frame.

    The sensor frame is x forward, y right, z down; it yaws with a SimMotor's shaft
    (``motor`` position + ``mount_yaw``, rad, clockwise seen from above, 0 = x north).
    With the field (X north, Y east, Z down) and yaw psi, the reading is
    ``(X cos psi + Y sin psi, -X sin psi + Y cos psi, Z)`` plus a hard-iron ``offset``
    (T), so ``atan2(-y, x)`` is the magnetic heading psi - D (D = atan2(Y, X), the
    declination), and the true heading is that plus D.
    """

    info = DeviceInfo(DeviceKind.COMPASS, 0x0E1, 0x700, "OpenEL", "SimMagnetometer")
    units = ("T", "T", "T")

    def __init__(
        self,
        motor: SimMotor | None = None,
        *,
        field_ned_nt: tuple[float, float, float] = DEFAULT_FIELD_NED_NT,
        mount_yaw: float = 0.0,
        offset: tuple[float, float, float] = (0.0, 0.0, 0.0),
        noise: float = 0.0,
        seed: int = 0,
    ) -> None:
        super().__init__(noise=noise, seed=seed)
        if len(field_ned_nt) != 3 or not all(math.isfinite(v) for v in field_ned_nt):
            raise BadParameterError("field_ned_nt", field_ned_nt, "3 finite values (nT)")
        if len(offset) != 3 or not all(math.isfinite(v) for v in offset):
            raise BadParameterError("offset", offset, "3 finite values (T)")
        self.motor = motor
        self.field_ned_nt = tuple(field_ned_nt)
        self.mount_yaw = mount_yaw
        self.offset = tuple(offset)

    def yaw_at(self, t_ns: int) -> float:
        """The sensor's yaw (rad) at a clock time."""
        return _motion(self.motor, t_ns)[0] + self.mount_yaw

    def _sample(self, now: int) -> tuple[float, ...]:
        psi = self.yaw_at(now)
        north, east, down = (v * 1e-9 for v in self.field_ned_nt)
        c, s = math.cos(psi), math.sin(psi)
        field = (north * c + east * s, -north * s + east * c, down)
        return tuple(self._noisy(f + o) for f, o in zip(field, self.offset, strict=True))
