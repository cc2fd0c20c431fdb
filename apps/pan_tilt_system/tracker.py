"""Tracker: the controller. Each cycle it reads the newest target (InPort "target"),
pulls the head's measured positions (InPort "measured", a pull connector), and writes
a position command (OutPort "command") that moves each axis towards the target by at
most ``max_step`` rad. On activation it homes the head through its required service
interface "head" (PanTiltHead)."""

from __future__ import annotations

from typing import Protocol

from openel_async import Clock
from openel_async.rtc import CallbackResult, RTObject
from openel_async.rtc.configuration import Configuration
from openel_async.rtc.ports import InPort, OutPort, ServicePort, TimedDoubleSeq


class PanTiltHead(Protocol):
    """The head's service interface (type name "PanTiltHead"; each side declares it, as
    each side of an OpenRTM service compiles the same IDL)."""

    async def home(self) -> None: ...

    async def positions(self) -> tuple[float, float]: ...


class Tracker(RTObject):
    def __init__(
        self,
        instance_name: str = "",
        *,
        configuration: Configuration | None = None,
        clock: Clock | None = None,
    ) -> None:
        super().__init__(instance_name, configuration=configuration, clock=clock)
        self.target = self.add_port(InPort("target", TimedDoubleSeq))
        self.measured = self.add_port(InPort("measured", TimedDoubleSeq))
        self.command = self.add_port(OutPort("command", TimedDoubleSeq))
        self.head = self.add_port(ServicePort("head")).require("head", "PanTiltHead", PanTiltHead)
        self.commands = 0
        self.max_error = 0.0
        self.last_error = 0.0

    async def on_activated(self, exec_handle: int) -> CallbackResult:
        await self.head.ref.home()
        return None

    async def on_execute(self, exec_handle: int) -> CallbackResult:
        target = await self.target.read()  # readback: the last target when none is new
        measured = await self.measured.read()
        if target is None:
            return None
        position = measured.data if measured is not None else await self.head.ref.positions()
        gain = float(self.configuration.get("gain"))  # type: ignore[arg-type]
        step = float(self.configuration.get("max_step"))  # type: ignore[arg-type]
        command = []
        errors = []
        for want, have in zip(target.data, position, strict=True):
            error = want - have
            errors.append(abs(error))
            command.append(have + max(-step, min(step, gain * error)))
        self.last_error = max(errors)
        if self.commands > 100:  # after the head has caught up
            self.max_error = max(self.max_error, self.last_error)
        await self.command.write(command)
        self.commands += 1
        return None

    def report(self) -> dict[str, object]:
        return {
            "commands": self.commands,
            "tracking error": f"max {self.max_error:.3f} rad, last {self.last_error:.3f} rad",
        }
