"""Helpers of the AxisGroup tests: SimMotors that record what they are commanded, on the
virtual clock, with an EventTimer and an AxisGroup entered for the test."""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from openel_async import Actuator, EventTimer, Request, VirtualClock
from openel_async.motion import AxisGroup, AxisLimits
from openel_sim import SimMotor

PERIOD_MS = 1
DT = PERIOD_MS / 1000
LIMITS = AxisLimits(max_velocity=1.5, max_acceleration=8.0, max_jerk=80.0)


class RecordingMotor(SimMotor):
    """A SimMotor that keeps every POSITION setpoint it receives with its clock time.

    Generous own limits by default, so it tracks setpoints streamed every millisecond.
    """

    def __init__(self, **kwargs: Any) -> None:
        kwargs.setdefault("max_velocity", 20.0)
        kwargs.setdefault("max_acceleration", 1e5)
        super().__init__(**kwargs)
        self.setpoints: list[tuple[int, float]] = []

    async def command(self, request: Request, value: float) -> None:
        if request is Request.POSITION:
            self.setpoints.append((self._now(), value))
        await super().command(request, value)

    def times(self) -> np.ndarray:
        return np.array([t for t, _ in self.setpoints], dtype=np.int64)

    def values(self) -> np.ndarray:
        return np.array([v for _, v in self.setpoints])

    def on_grid(self, period_ns: int, start: float = 0.0) -> np.ndarray:
        """The setpoint in force at every tick from 0 to the last setpoint (held between).

        Row 0 is time 0, when the motor rested at ``start``.
        """
        times = self.times()
        grid = np.arange(0, times[-1] + 1, period_ns)
        assert np.all(times % period_ns == 0), "setpoints off the tick grid"
        values = np.concatenate([[start], self.values()])
        # Index of the setpoint in force at each tick: the latest one sent at or before it.
        which = np.zeros(grid.shape, dtype=np.int64)
        which[times // period_ns] = np.arange(1, times.size + 1)
        out: np.ndarray = values[np.maximum.accumulate(which)]
        return out


@dataclass
class Rig:
    group: AxisGroup
    actuators: list[Actuator]
    motors: list[RecordingMotor]
    timer: EventTimer
    clock: VirtualClock

    async def sleep(self, seconds: float) -> None:
        await self.clock.sleep(seconds)


RigFactory = Callable[..., Awaitable[Rig]]


def differences(values: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Velocity, acceleration and jerk of a uniformly sampled sequence (finite differences)."""
    v = np.diff(values, axis=0) / dt
    a = np.diff(values, n=2, axis=0) / dt**2
    j = np.diff(values, n=3, axis=0) / dt**3
    return v, a, j
