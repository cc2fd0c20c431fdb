"""The sensors of an ODrive node: encoder estimates, temperatures and the DC bus, each
polled with its CANSimple Get_* command when the cyclic message is older than ``max_age``."""

from __future__ import annotations

from openel_async.device import DeviceContext, DeviceInfo, ErrorId, Reading, SensorDevice
from openel_async.errors import BadParameterError, ReturnCode
from openel_async.ids import DeviceKind

from . import cansimple as cs
from .bus import CanBus
from .odrive_link import (
    KELVIN_OFFSET,
    ODRIVE_VENDOR_ID,
    ODriveLink,
    check_node,
    check_seconds,
    turns_to_rad,
)

__all__ = ["ODriveBusMonitor", "ODriveEncoder", "ODriveSensor", "ODriveTemperature"]


class ODriveSensor(SensorDevice):
    """What the ODrive sensors share: one node's link polled for one command."""

    _CMD: cs.CmdId

    def __init__(
        self,
        bus: CanBus,
        node_id: int,
        *,
        max_age: float = 0.05,
        request_timeout: float = 0.05,
    ) -> None:
        if not isinstance(bus, CanBus):
            raise BadParameterError("bus", bus, "an openel_can.CanBus")
        check_node(node_id)
        check_seconds("max_age", max_age)
        check_seconds("request_timeout", request_timeout)
        self.bus = bus
        self.node_id = node_id
        self.max_age = max_age
        self._link = ODriveLink(bus, node_id, (self._CMD,), request_timeout=request_timeout)
        self._ctx: DeviceContext | None = None
        self._latched = False

    @property
    def malformed_frames(self) -> int:
        return self._link.malformed

    async def open(self, ctx: DeviceContext) -> None:
        self._ctx = ctx
        self._link.open(ctx, self._on_bus_error)
        await self._link.request(self._CMD, cs.CanSimpleMessage)  # the node answers

    async def init(self) -> None:
        self._latched = False

    async def reset(self) -> None:
        await self.bus.wait_up(1.0)
        await self._link.request(self._CMD, cs.CanSimpleMessage)
        self._latched = False

    async def close(self) -> None:
        self._link.close()

    def _on_bus_error(self, reason: str) -> None:
        if not self._latched and self._ctx is not None:
            self._latched = True
            self._ctx.fault(
                ErrorId.BUS_ERROR, f"CAN bus error: {reason}", ReturnCode.HAL_NO_CONNECTED
            )

    async def _latest(self) -> tuple[int, cs.CanSimpleMessage]:
        return await self._link.fresh(self._CMD, cs.CanSimpleMessage, round(self.max_age * 1e9))


class ODriveEncoder(ODriveSensor):
    """Encoder estimates of an ODrive axis: (position rad, velocity rad/s).

    Uses the cyclic Get_Encoder_Estimates (polled when older than ``max_age``); the
    reading's time is when the frame was received.
    """

    info = DeviceInfo(DeviceKind.ROTARY_ANGLE, ODRIVE_VENDOR_ID, 0x0106, "ODrive", "CanEncoder")
    units = ("rad", "rad/s")
    _CMD = cs.CmdId.GET_ENCODER_ESTIMATES

    def __init__(
        self, bus: CanBus, node_id: int, *, max_age: float = 0.03, request_timeout: float = 0.05
    ) -> None:
        super().__init__(bus, node_id, max_age=max_age, request_timeout=request_timeout)

    async def read(self) -> Reading:
        stamp, msg = await self._latest()
        assert isinstance(msg, cs.EncoderEstimates)
        return Reading((turns_to_rad(msg.pos), turns_to_rad(msg.vel)), stamp)


class ODriveTemperature(ODriveSensor):
    """FET and motor temperatures of an ODrive axis (K), polled with Get_Temperature."""

    info = DeviceInfo(DeviceKind.TEMPERATURE, ODRIVE_VENDOR_ID, 0x0406, "ODrive", "CanTemperature")
    units = ("K", "K")
    _CMD = cs.CmdId.GET_TEMPERATURE

    async def read(self) -> Reading:
        stamp, msg = await self._latest()
        assert isinstance(msg, cs.Temperature)
        return Reading((msg.fet + KELVIN_OFFSET, msg.motor + KELVIN_OFFSET), stamp)


class ODriveBusMonitor(ODriveSensor):
    """DC bus voltage (V) and current (A) of an ODrive, polled with Get_Bus_Voltage_Current."""

    info = DeviceInfo(DeviceKind.CURRENT, ODRIVE_VENDOR_ID, 0x0D06, "ODrive", "CanBusMonitor")
    units = ("V", "A")
    _CMD = cs.CmdId.GET_BUS_VOLTAGE_CURRENT

    async def read(self) -> Reading:
        stamp, msg = await self._latest()
        assert isinstance(msg, cs.BusVoltageCurrent)
        return Reading((msg.voltage, msg.current), stamp)
