"""A CiA 402 drive over CANopen: :class:`Cia402Drive` (actuator), :class:`Cia402Temperature`.

The node itself (configuration, power state machine, feedback, faults, watchdog) is
:class:`~openel_can.node402.Cia402Node`; this module adds the profile set-point modes.

Opening the drive (``open``): NMT Enter pre-operational, then by expedited SDO the
heartbeat producer time (0x1017), the encoder resolution (0x608F, unless given) and the
rated torque (0x6076, unless given), the PDO mapping (disable, clear, map, count,
enable, as CiA 301 prescribes) and the profile parameters, then NMT Start and the first
TPDO. The mapping:

=========  ===============================================  ==========================
PDO        objects                                          use
=========  ===============================================  ==========================
RPDO1      controlword 0x6040, target position 0x607A       profile position (pp)
RPDO2      controlword 0x6040, target velocity 0x60FF       profile velocity (pv)
RPDO3      controlword 0x6040, target torque 0x6071         profile torque (tq)
TPDO1      statusword 0x6041, position 0x6064, torque 0x6077
TPDO2      velocity 0x606C, mode display 0x6061
=========  ===============================================  ==========================

TPDOs are event-driven (type 0xFF) with an event timer of ``tpdo_event_ms``, or sent on
every SYNC (type 1) with ``sync=True`` (give the bus a SYNC producer:
``CanBus(..., sync_period=...)``).

The power state machine runs on the controlword: ``init`` goes shutdown -> switch on ->
enable operation (:func:`openel_can.cia402.next_controlword`, each step confirmed by the
statusword); ``reset`` (``re_init``) reconfigures the node if it rebooted, sends the
fault reset edge (bit 7) and enables again; NO_EXCITE disables operation (Switched on);
:meth:`Cia402Drive.quick_stop` sends quick stop.

Set-points: POSITION selects profile position (0x6060 = 1, by SDO when the mode
changes) and runs the new set-point handshake: target with bit 4 (new set-point) and
bit 5 (change set immediately), wait for statusword bit 12 (set-point acknowledge), then
bit 4 low. VELOCITY / TORQUE select profile velocity / torque; the drive acknowledges
nothing there, so the driver reads the statusword by SDO after the RPDO (the drive
processes both in order). Completion (``reports_completion``): statusword bit 10
(target reached) seen after that acknowledgement.

Speed ramps (``Motor.set_speed(speed, tm_acc)``, :meth:`Cia402Drive.command_velocity_ramp`):
profile velocity mode with profile acceleration 0x6083 and deceleration 0x6084 both set by
SDO to |target - start| / tmAcc in increments/s², then the target velocity 0x60FF. The
values in force before the first ramp (read once by SDO) are written back by the next
plain velocity command, so ``tm_acc = 0`` keeps the drive's own acceleration.

Faults (one report per fault: EMCY, statusword, heartbeat, boot-up, SDO, bus) and the
heartbeat watchdog (``arm_watchdog``/``disarm_watchdog``: the drive quick-stops when the
host's heartbeat stops) are the node's: see :mod:`openel_can.node402`.

Units: positions ``rad = counts * 2π / counts_per_rev``, velocities in counts/s the same
way, torques in per mille of the rated torque (Nm at the API).
"""

from __future__ import annotations

import inspect
import math
from typing import Any, Final

from openel_async.device import (
    DeviceContext,
    DeviceInfo,
    ErrorId,
    Reading,
    SensorDevice,
    VelocityRamp,
)
from openel_async.errors import BadParameterError, ReturnCode
from openel_async.ids import DeviceKind
from openel_async.logs import get_logger
from openel_async.requests import Request

from . import canopen as co
from . import cia402 as ds
from .bus import CanBus, NodePort
from .node402 import (
    CIA402_VENDOR_ID,
    CONSUMER_HEARTBEAT_TIME_1,
    DEFAULT_HOST_NODE_ID,
    ENABLE_OPERATION,
    QUICK_STOP_ON_ABORT,
    RPDO_MAPS,
    TARGET_REACHED,
    TPDO_MAPS,
    WATCHDOG_FEED_FRACTION,
    Cia402Node,
    FaultedError,
    Setpoint,
    check_node,
    check_positive,
)
from .sdo import SdoClient

__all__ = [
    "CIA402_VENDOR_ID",
    "CONSUMER_HEARTBEAT_TIME_1",
    "DEFAULT_HOST_NODE_ID",
    "QUICK_STOP_ON_ABORT",
    "RPDO_MAPS",
    "TPDO_MAPS",
    "WATCHDOG_FEED_FRACTION",
    "Cia402Drive",
    "Cia402Temperature",
]

log = get_logger(__name__)

PS = ds.PowerState
Mode = ds.ModeOfOperation
SB = ds.StatusBit
CB = ds.ControlBit
_MODE_OF_REQUEST: Final = {
    Request.POSITION: Mode.PROFILE_POSITION,
    Request.VELOCITY: Mode.PROFILE_VELOCITY,
    Request.TORQUE: Mode.PROFILE_TORQUE,
}
# Plain ints of the bits tested on every set-point (IntFlag arithmetic is Python code).
_ACK: Final = int(SB.SETPOINT_ACKNOWLEDGE)
_NEW_SETPOINT: Final = int(CB.NEW_SETPOINT)
_PP_BASE: Final = ENABLE_OPERATION | int(CB.CHANGE_SET_IMMEDIATELY)


class Cia402Drive(Cia402Node):
    """A CiA 402 servo drive on a CAN bus (CANopen); see the module docstring.

    ``mode="csp" | "csv" | "cst"`` makes a
    :class:`~openel_can.cyclic402.Cia402CyclicDrive` (a subclass) instead."""

    def __new__(cls, *args: Any, **kwargs: Any) -> Cia402Drive:
        if cls is Cia402Drive and kwargs.get("mode", "pp") != "pp":
            from .cyclic402 import Cia402CyclicDrive  # (it imports this module)

            return super().__new__(Cia402CyclicDrive)
        return super().__new__(cls)

    info = DeviceInfo(
        kind=DeviceKind.MOTOR,
        vendor_id=CIA402_VENDOR_ID,
        product_id=0x0192,
        vendor_name="CiA402",
        product_name="CanDrive",
        functions=("quick_stop",),
    )
    reports_completion = True
    velocity_ramp = True
    """``Motor.set_speed(speed, tm_acc)``: profile velocity with 0x6083/0x6084 (see
    :meth:`command_velocity_ramp`)."""

    left_safe: bool = False
    """``safe_stop`` left the device in its exit state: ``close`` leaves it so (set until
    the next ``init``)."""

    # -- commands -------------------------------------------------------------------------
    async def command(self, request: Request, value: float) -> None:
        try:
            await self._command(request, value)
        except FaultedError:
            # The drive faulted meanwhile: the component is in Error already and the
            # Actuator fails the new Motion with that fault.
            self.log.debug("cia402_command_interrupted_by_fault")

    async def command_velocity_ramp(self, ramp: VelocityRamp) -> None:
        """tmAcc with the drive's own profile: profile velocity mode, 0x6083 = 0x6084 =
        |target - start| / tmAcc (increments/s², by SDO), then target velocity 0x60FF by
        RPDO2. Completion: statusword bit 10 (target reached), at the end of the ramp.

        An acceleration that does not fit UNSIGNED32 is refused (BadParameterError naming
        ``tm_acc``) before anything is sent; a zero rate (start = target) writes none.
        """
        accel = round(ramp.rate * self._cpr() / math.tau)
        if accel > 0xFFFF_FFFF:
            raise BadParameterError(
                "tm_acc",
                ramp.duration_s,
                f"a ramp time giving a profile acceleration <= 4294967295 increments/s^2 "
                f"(got {accel})",
            )
        try:
            await self._command(Request.VELOCITY, ramp.target, accel if accel > 0 else None)
        except FaultedError:
            self.log.debug("cia402_command_interrupted_by_fault")

    async def _write_profile_accel(self, accel: int, decel: int) -> None:
        await self.sdo.write(ds.PROFILE_ACCELERATION, accel, timeout=self.sdo_timeout)
        await self.sdo.write(ds.PROFILE_DECELERATION, decel, timeout=self.sdo_timeout)

    async def _command(self, request: Request, value: float, ramp_accel: int | None = None) -> None:
        async with self._lock:
            self._pending = None  # reports of the previous set-point stop here
            if request is Request.NO_EXCITE:
                self._enabled_wanted = False
                if self.power_state is PS.OPERATION_ENABLED:
                    await self._drive_to(PS.SWITCHED_ON)
                return
            if not self._enabled_wanted or self.power_state is not PS.OPERATION_ENABLED:
                await self._enable()
            mode = _MODE_OF_REQUEST[request]
            if mode is not self._mode:
                await self._set_mode(mode)
                self._targets[Mode.PROFILE_VELOCITY] = self._targets[Mode.PROFILE_TORQUE] = 0
                self._targets[Mode.PROFILE_POSITION] = self._position
            if request is Request.POSITION:
                await self._position_setpoint(self.rad_to_counts(value))
            else:
                if ramp_accel is not None:
                    if self._saved_profile_accel is None:
                        timeout = self.sdo_timeout
                        self._saved_profile_accel = (
                            await self.sdo.read(ds.PROFILE_ACCELERATION, timeout=timeout),
                            await self.sdo.read(ds.PROFILE_DECELERATION, timeout=timeout),
                        )
                    await self._write_profile_accel(ramp_accel, ramp_accel)
                    self._ramp_accel_written = True
                elif request is Request.VELOCITY and self._ramp_accel_written:
                    if self._saved_profile_accel is not None:
                        await self._write_profile_accel(*self._saved_profile_accel)
                    self._ramp_accel_written = False
                raw = (
                    self.rad_to_counts(value)
                    if request is Request.VELOCITY
                    else self._torque_permille(value)
                )
                self._targets[mode] = raw
                await self._send_rpdo(mode, ENABLE_OPERATION, raw)
                # No handshake in pv/tq: the SDO answer comes after the RPDO was processed.
                self._set_statusword(
                    await self.sdo.read(ds.STATUSWORD, timeout=self.sdo_timeout), self._now()
                )
            setpoint = Setpoint(request)
            self._pending = setpoint  # armed right before returning (see ODriveAxis.command)
            sw = self._statusword
            if sw is not None and sw & TARGET_REACHED and self._ctx is not None:
                # Already there: report once the Actuator has installed the new Motion.
                self._ctx.start_soon(self._report_later, setpoint)

    async def _position_setpoint(self, counts: int) -> None:
        mode = Mode.PROFILE_POSITION
        base = _PP_BASE
        if self._controlword & _NEW_SETPOINT or (self._statusword or 0) & _ACK:
            await self._send_rpdo(mode, base, self._targets[mode])
            await self._wait_status(lambda sw: not sw & _ACK, "set-point acknowledge low")
        self._targets[mode] = counts
        await self._send_rpdo(mode, base | _NEW_SETPOINT, counts)
        await self._wait_status(lambda sw: bool(sw & _ACK), "set-point acknowledge")
        await self._send_rpdo(mode, base, counts)

    async def read(self, request: Request) -> float:
        now = self._now()
        max_age = round(self.feedback_max_age * 1e9)

        def fresh(index: int) -> bool:
            seen = self.feedback_ns(index)
            return seen is not None and now - seen <= max_age

        if request is Request.POSITION_ACTUAL:
            counts = (
                self._position
                if fresh(0x6064)
                else await self.sdo.read(ds.POSITION_ACTUAL_VALUE, timeout=self.sdo_timeout)
            )
            return self.counts_to_rad(counts)
        if request is Request.VELOCITY_ACTUAL:
            counts = (
                self._velocity
                if fresh(0x606C)
                else await self.sdo.read(ds.VELOCITY_ACTUAL_VALUE, timeout=self.sdo_timeout)
            )
            return self.counts_to_rad(counts)
        if request is Request.TORQUE_ACTUAL:
            permille = (
                self._torque
                if fresh(0x6077)
                else await self.sdo.read(ds.TORQUE_ACTUAL_VALUE, timeout=self.sdo_timeout)
            )
            return self._torque_nm(permille)
        raise BadParameterError(
            "request", request, "POSITION_ACTUAL, VELOCITY_ACTUAL or TORQUE_ACTUAL"
        )


def _signature() -> inspect.Signature:
    """Cia402Drive's arguments are Cia402Node's (``__new__`` takes ``**kwargs`` only to pick
    the cyclic subclass): a rig's unknown params key is refused naming the close ones."""
    signature = inspect.signature(Cia402Node.__init__)
    return signature.replace(parameters=list(signature.parameters.values())[1:])


Cia402Drive.__signature__ = _signature()  # type: ignore[attr-defined]


class Cia402Temperature(SensorDevice):
    """A drive temperature read by SDO (default: manufacturer object 0x2022, 0.1 °C), in K."""

    info = DeviceInfo(DeviceKind.TEMPERATURE, CIA402_VENDOR_ID, 0x0408, "CiA402", "CanTemperature")
    units = ("K",)

    def __init__(
        self,
        bus: CanBus,
        node_id: int,
        *,
        entry: co.ObjectEntry = co.ObjectEntry(0x2022, 0, co.DataType.INTEGER16),  # noqa: B008
        celsius_per_unit: float = 0.1,
        sdo_timeout: float = 0.1,
    ) -> None:
        if not isinstance(bus, CanBus):
            raise BadParameterError("bus", bus, "an openel_can.CanBus")
        check_node(node_id)
        check_positive("celsius_per_unit", celsius_per_unit, optional=False)
        check_positive("sdo_timeout", sdo_timeout, optional=False)
        self.bus = bus
        self.node_id = node_id
        self.entry = entry
        self.celsius_per_unit = celsius_per_unit
        self.sdo_timeout = sdo_timeout
        self.sdo = SdoClient.for_node(bus, node_id, timeout=sdo_timeout)
        self._ctx: DeviceContext | None = None
        self._port: NodePort | None = None
        self._latched = False

    async def open(self, ctx: DeviceContext) -> None:
        self._ctx = ctx
        # A port without ids: only to hear about bus failures.
        self._port = self.bus.attach((), name=ctx.name, on_bus_error=self._on_bus_error)
        await self.read()

    async def init(self) -> None:
        self._latched = False

    async def reset(self) -> None:
        await self.bus.wait_up(1.0)
        await self.read()
        self._latched = False

    async def close(self) -> None:
        if self._port is not None:
            self._port.close()

    def _on_bus_error(self, reason: str) -> None:
        if not self._latched and self._ctx is not None:
            self._latched = True
            self._ctx.fault(
                ErrorId.BUS_ERROR, f"CAN bus error: {reason}", ReturnCode.HAL_NO_CONNECTED
            )

    async def read(self) -> Reading:
        raw = await self.sdo.read(self.entry, timeout=self.sdo_timeout)
        assert self._ctx is not None
        return Reading((raw * self.celsius_per_unit + 273.15,), self._ctx.clock.now_ns())
