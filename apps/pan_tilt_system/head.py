"""Head: the pan-tilt actuators. A SPORADIC component: the arrival of a command on its
InPort "command" triggers its context (at most executionRate times a second). Each run
sends the newest command to two OpenEL Actuators over simulated motors and publishes
the actual positions on OutPort "measured". Its service port "head" provides
PanTiltHead (home, positions)."""

from __future__ import annotations

from contextlib import AsyncExitStack
from typing import Protocol

from openel_async import Actuator, Clock, Request
from openel_async.rtc import CallbackResult, RTObject, SporadicExecutionContext
from openel_async.rtc.configuration import Configuration
from openel_async.rtc.ports import (
    InPort,
    ListenerType,
    OutPort,
    PortEvent,
    ServicePort,
    TimedDoubleSeq,
)
from openel_sim import SimMotor


class PanTiltHead(Protocol):
    """The head's service interface (type name "PanTiltHead"; each side declares it, as
    each side of an OpenRTM service compiles the same IDL)."""

    async def home(self) -> None: ...

    async def positions(self) -> tuple[float, float]: ...


class HeadService:
    """The PanTiltHead implementation the service port provides."""

    def __init__(self, head: Head) -> None:
        self._head = head

    async def home(self) -> None:
        for axis in self._head.axes():
            await axis.set_value(0.0, Request.POSITION)

    async def positions(self) -> tuple[float, float]:
        pan, tilt = self._head.axes()
        return (
            await pan.get_value(Request.POSITION_ACTUAL),
            await tilt.get_value(Request.POSITION_ACTUAL),
        )


class Head(RTObject):
    def __init__(
        self,
        instance_name: str = "",
        *,
        configuration: Configuration | None = None,
        clock: Clock | None = None,
    ) -> None:
        super().__init__(instance_name, configuration=configuration, clock=clock)
        self.command = self.add_port(InPort("command", TimedDoubleSeq))
        self.measured = self.add_port(OutPort("measured", TimedDoubleSeq))
        self.service = HeadService(self)
        port = self.add_port(ServicePort("head"))
        port.provide("head", "PanTiltHead", self.service, PanTiltHead)
        self.command.add_listener(ListenerType.ON_RECEIVED, self._on_command)
        self._stack: AsyncExitStack | None = None
        self._axes: tuple[Actuator, Actuator] | None = None
        self.runs = 0
        self.setpoints = 0

    def axes(self) -> tuple[Actuator, Actuator]:
        if self._axes is None:
            raise RuntimeError("Head is not initialized")
        return self._axes

    def _on_command(self, event: PortEvent) -> None:
        for ec in self.get_participating_contexts():
            if isinstance(ec, SporadicExecutionContext) and ec.is_running():
                ec.trigger()

    async def on_initialize(self) -> CallbackResult:
        stack = AsyncExitStack()
        try:
            axes = [
                await stack.enter_async_context(
                    Actuator(SimMotor(max_velocity=3.0, max_acceleration=30.0), clock=self.clock)
                )
                for _ in range(2)
            ]
        except BaseException:
            await stack.aclose()
            raise
        self._axes = (axes[0], axes[1])
        self._stack = stack
        return None

    async def on_finalize(self) -> CallbackResult:
        if self._stack is not None:
            await self._stack.aclose()
            self._stack = None
        return None

    async def on_execute(self, exec_handle: int) -> CallbackResult:
        newest = None
        while self.command.is_new():
            newest = await self.command.read()
        self.runs += 1
        if newest is not None:
            for axis, target in zip(self.axes(), newest.data, strict=True):
                await axis.set_value(target, Request.POSITION)
                self.setpoints += 1
        await self.measured.write(await self.service.positions())
        return None

    def report(self) -> dict[str, object]:
        return {"runs": self.runs, "setpoints": self.setpoints}
