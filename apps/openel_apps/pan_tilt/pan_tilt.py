"""PanTilt: the RT component of apps/pan_tilt/RTC.yaml.

A data flow, multi-mode component driving the two OpenEL Actuators ``pan`` and ``tilt`` of a
rig file (``openel-async rig schema``), by default ``rigs/pantilt-sim.yaml`` (two ``openel_sim`` motors):

- on_initialize opens the rig its configuration names (``rig``, with ``sim``) and takes
  its actuators ``pan`` and ``tilt`` (they live until on_finalize; both run in the
  runner's task, so their task groups nest properly); the rig's limits are checked on
  every command;
- on_finalize closes the rig, which leaves every actuator as its ``safety.on_exit`` says
  (the summary's ``on exit`` line);
- in mode ``scan`` every on_execute streams one position target to each axis, a
  Lissajous figure: pan = amplitude sin(2 pi f t), tilt = amplitude/2 sin(4 pi f t);
- in mode ``hold`` on_mode_changed stops both axes where they are;
- on_state_update reads both actual positions and tracks the largest tracking error;
- with ``mode_period`` > 0 on_execute requests the other mode every mode_period seconds;
  the request is pending until the next cycle, where on_mode_changed runs before
  on_execute.

Configuration parameters ``amplitude``, ``frequency``, ``start_mode`` and ``mode_period`` are
read from the active configuration set every cycle, so a change applies at once; ``rig``
and ``sim`` when the component is initialized.
"""

from __future__ import annotations

import math
from contextlib import AsyncExitStack
from pathlib import Path

from openel_apps.pan_tilt import RIGS, SIM_RIG
from openel_async import Actuator, BadParameterError, Clock, Request, VirtualClock
from openel_async.clock import NS_PER_S
from openel_async.rig import Rig, load_rig, open_rig, resolve_rig
from openel_async.rtc import CallbackResult, MultiModeObject
from openel_async.rtc.configuration import Configuration

AXES = ("pan", "tilt")
"""The names of the head's two actuators in a rig file."""


def rig_path(text: str) -> Path:
    """The rig file the configuration parameter ``rig`` names: a path (a relative one from
    the current directory), else the file name of a rig shipped with the apps
    (``openel_apps/rigs``, e.g. ``pantilt-sim.yaml``). BadParameterError when there is no
    such file."""
    path = Path(text).expanduser()
    if text and path.is_file():
        return path
    if text and path.name == text and (RIGS / text).is_file():
        return RIGS / text
    shipped = ", ".join(sorted(p.name for p in RIGS.glob("*.yaml")))
    raise BadParameterError(
        "rig", text, f"a rig file: a path, or the name of a shipped rig ({shipped})"
    )


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
        self.rig: Rig | None = None
        """The opened rig (None before on_initialize); after on_finalize it says how it left
        the actuators (:attr:`Rig.exit_report`)."""
        self.rig_name = ""
        """The configuration's ``rig`` when the rig was opened."""
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

    def _rig_name(self) -> str:
        """The configuration's ``rig``; the shipped sim rig for a configuration without one
        (a PanTilt built in Python without its profile's configuration)."""
        if "rig" not in self.configuration.parameters:
            return SIM_RIG.name
        value = self.configuration.get("rig")
        if not isinstance(value, str):
            raise TypeError(f"configuration 'rig' is {value!r}, not a string")
        return value

    def _sim(self) -> bool:
        params = self.configuration.parameters
        return "sim" in params and self.configuration.get("sim") is True

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
        name = self._rig_name()
        resolved = resolve_rig(load_rig(rig_path(name)))
        sim = self._sim()
        names = [c.name for c in resolved.spec.components]
        missing = [axis for axis in AXES if axis not in names]
        if missing:  # said before anything is opened
            raise BadParameterError(
                "rig",
                resolved.spec.source,
                f"a rig with actuators named {' and '.join(AXES)} (it has no "
                f"{', '.join(missing)}; its components: {', '.join(names)})",
            )
        if resolved.spec.buses and isinstance(self.clock, VirtualClock):
            raise BadParameterError(
                "rig",
                resolved.spec.source,
                "a rig without buses on the virtual clock (--virtual): buses run in real time",
            )
        stack = AsyncExitStack()
        try:
            rig = await stack.enter_async_context(
                open_rig(resolved, self.clock, sim=sim, handle_sigquit=True)
            )
            self.pan, self.tilt = rig.actuator(AXES[0]), rig.actuator(AXES[1])
        except BaseException:
            await stack.aclose()
            raise
        self.rig, self.rig_name = rig, name
        self._stack = stack
        self.log.info(
            "rig_opened",
            rig=rig.spec.source,
            description=rig.spec.description,
            simulated=rig.simulated,
        )
        return None

    async def on_finalize(self) -> CallbackResult:
        if self._stack is None:
            return None
        try:
            await self._stack.aclose()  # every actuator left as the rig's safety.on_exit says
        finally:
            self._stack = None
            self.pan = self.tilt = None
            if self.rig is not None:
                self.log.info("rig_closed", rig=self.rig.spec.source, on_exit=self._exit_text())
        return None

    def _exit_text(self) -> str:
        """How the rig left the actuators: ``hold: pan done, tilt done``."""
        assert self.rig is not None
        return self.rig.exit_line().removeprefix("on exit").strip()

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
        out: dict[str, object] = {
            "setpoints": self.setpoints,
            "mode changes": self.mode_changes,
            "tracking error": f"max {self.max_tracking_error:.4f} rad",
            "final positions": f"pan {pan:+.4f} rad, tilt {tilt:+.4f} rad",
        }
        if self.rig is not None:
            spec = self.rig.spec
            sim = " (simulated peers)" if self.rig.simulated and spec.buses else ""
            about = f" ({spec.description}{sim})" if spec.description or sim else ""
            out["rig"] = f"{self.rig_name}{about}"
            if self._stack is None:  # closed: it says how it left the actuators
                out["on exit"] = self._exit_text()
        return out
