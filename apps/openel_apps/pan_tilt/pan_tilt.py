"""PanTilt: the RT component of apps/pan_tilt/RTC.yaml.

A data flow, multi-mode component driving two OpenEL Actuators over simulated motors
(``openel_sim.SimMotor``) through the HAL:

- on_initialize enters the two Actuators (they live until on_finalize; both run in the
  runner's task, so their task groups nest properly);
- in mode ``scan`` every on_execute streams one position target to each axis, a
  Lissajous figure: pan = amplitude sin(2 pi f t), tilt = amplitude/2 sin(4 pi f t);
- in mode ``hold`` on_mode_changed stops both axes where they are;
- on_state_update reads both actual positions and tracks the largest tracking error;
- with ``mode_period`` > 0 on_execute requests the other mode every mode_period seconds;
  the request is pending until the next cycle, where on_mode_changed runs before
  on_execute.

Configuration parameters (``amplitude``, ``frequency``, ``start_mode``, ``mode_period``)
are read from the active configuration set every cycle, so a change applies at once.
"""

from __future__ import annotations

import math
from contextlib import AsyncExitStack

from openel_async import Actuator, Clock, Request
from openel_async.clock import NS_PER_S
from openel_async.rtc import CallbackResult, MultiModeObject
from openel_async.rtc.configuration import Configuration
from openel_sim import SimMotor


class PanTilt(MultiModeObject):
    """Scans with two actuators in mode "scan", holds them in mode "hold"."""

    modes = ("scan", "hold")

    def __init__(
        self,
        instance_name: str = "",
        *,
        configuration: Configuration | None = None,
        clock: Clock | None = None,
    ) -> None:
        super().__init__(instance_name, configuration=configuration, clock=clock)
        self._stack: AsyncExitStack | None = None
        self.pan: Actuator | None = None
        self.tilt: Actuator | None = None
        self._t0 = 0
        self._next_switch: int | None = None
        self.setpoints = 0
        self.mode_changes = 0
        self.max_tracking_error = 0.0
        self.final_positions = (0.0, 0.0)

    # -- configuration -----------------------------------------------------------------
    def _number(self, name: str) -> float:
        value = self.configuration.get(name)
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise TypeError(f"configuration {name!r} is {value!r}, not a number")
        return float(value)

    def _axes(self) -> tuple[Actuator, Actuator]:
        if self.pan is None or self.tilt is None:
            raise RuntimeError("PanTilt is not initialized")
        return self.pan, self.tilt

    async def _hold(self) -> None:
        for axis in self._axes():
            position = await axis.get_value(Request.POSITION_ACTUAL)
            await axis.set_value(position, Request.POSITION)

    # -- lifecycle ---------------------------------------------------------------------
    async def on_initialize(self) -> CallbackResult:
        stack = AsyncExitStack()
        try:
            self.pan = await stack.enter_async_context(_axis("pan", self.clock))
            self.tilt = await stack.enter_async_context(_axis("tilt", self.clock))
        except BaseException:
            await stack.aclose()
            raise
        self._stack = stack
        return None

    async def on_finalize(self) -> CallbackResult:
        if self._stack is not None:
            await self._stack.aclose()
            self._stack = None
        return None

    async def on_activated(self, exec_handle: int) -> CallbackResult:
        now = self.clock.now_ns()
        self._t0 = now
        period = self._number("mode_period")
        self._next_switch = now + round(period * NS_PER_S) if period > 0 else None
        await self.set_mode(str(self.configuration.get("start_mode")))
        return None

    async def on_deactivated(self, exec_handle: int) -> CallbackResult:
        await self._hold()
        pan, tilt = self._axes()
        self.final_positions = (
            await pan.get_value(Request.POSITION_ACTUAL),
            await tilt.get_value(Request.POSITION_ACTUAL),
        )
        return None

    async def on_aborting(self, exec_handle: int) -> CallbackResult:
        await self._hold()
        return None

    # -- modes -------------------------------------------------------------------------
    async def on_mode_changed(self, exec_handle: int) -> CallbackResult:
        self.mode_changes += 1
        if self.mode_of(exec_handle) == "hold":
            await self._hold()
        return None

    # -- data flow ---------------------------------------------------------------------
    async def on_execute(self, exec_handle: int) -> CallbackResult:
        now = self.clock.now_ns()
        if self._next_switch is not None and now >= self._next_switch:
            self._next_switch += round(self._number("mode_period") * NS_PER_S)
            other = "hold" if self.mode_of(exec_handle) == "scan" else "scan"
            await self.set_mode(other)  # taken at the next cycle, before on_execute
        if self.mode_of(exec_handle) != "scan":
            return None
        amplitude = self._number("amplitude")
        phase = 2 * math.pi * self._number("frequency") * (now - self._t0) / NS_PER_S
        pan, tilt = self._axes()
        await pan.set_value(amplitude * math.sin(phase), Request.POSITION)
        await tilt.set_value(0.5 * amplitude * math.sin(2 * phase), Request.POSITION)
        self.setpoints += 2
        return None

    async def on_state_update(self, exec_handle: int) -> CallbackResult:
        for axis in self._axes():
            target = await axis.get_value(Request.POSITION)
            actual = await axis.get_value(Request.POSITION_ACTUAL)
            self.max_tracking_error = max(self.max_tracking_error, abs(target - actual))
        return None

    def report(self) -> dict[str, object]:
        pan, tilt = self.final_positions
        return {
            "setpoints": self.setpoints,
            "mode changes": self.mode_changes,
            "tracking error": f"max {self.max_tracking_error:.4f} rad",
            "final positions": f"pan {pan:+.4f} rad, tilt {tilt:+.4f} rad",
        }


def _axis(name: str, clock: Clock) -> Actuator:
    """One axis of the head, named as the user knows it (logs, recordings, summaries)."""
    motor = SimMotor(max_velocity=4.0, max_acceleration=40.0)
    return Actuator(motor, device_name=name, clock=clock)
