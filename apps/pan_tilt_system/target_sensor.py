"""TargetSensor: a simulated sensor that sees a target move (pan, tilt angles in rad)
and publishes it on its OutPort "target" (TimedDoubleSeq, 2 values) every cycle."""

from __future__ import annotations

import math

from openel_async import Clock
from openel_async.clock import NS_PER_S
from openel_async.rtc import CallbackResult, RTObject
from openel_async.rtc.configuration import Configuration
from openel_async.rtc.ports import OutPort, TimedDoubleSeq


class TargetSensor(RTObject):
    def __init__(
        self,
        instance_name: str = "",
        *,
        configuration: Configuration | None = None,
        clock: Clock | None = None,
    ) -> None:
        super().__init__(instance_name, configuration=configuration, clock=clock)
        self.out = self.add_port(OutPort("target", TimedDoubleSeq))
        self.samples = 0
        self._t0 = 0

    async def on_activated(self, exec_handle: int) -> CallbackResult:
        self._t0 = self.clock.now_ns()
        return None

    async def on_execute(self, exec_handle: int) -> CallbackResult:
        amplitude = float(self.configuration.get("amplitude"))  # type: ignore[arg-type]
        frequency = float(self.configuration.get("frequency"))  # type: ignore[arg-type]
        phase = 2 * math.pi * frequency * (self.clock.now_ns() - self._t0) / NS_PER_S
        await self.out.write((amplitude * math.sin(phase), 0.5 * amplitude * math.sin(2 * phase)))
        self.samples += 1
        return None

    def report(self) -> dict[str, object]:
        return {"samples": self.samples}
