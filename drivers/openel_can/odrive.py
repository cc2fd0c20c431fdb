"""ODrive axes over CANSimple (firmware 0.6.x): an actuator and three sensors (the sensors
live in :mod:`openel_can.odrive_sensors`, the node's frames in :mod:`openel_can.odrive_link`;
both are re-exported here).

Units: ODrive speaks turns, turns/s and Nm; the API speaks SI. Positions and
velocities are converted with exactly ``rad = turns * 2π`` (``math.tau``) both ways;
torques are Nm on both sides; temperatures are converted from °C to K.

:class:`ODriveAxis` (an :class:`~openel_async.device.ActuatorDevice`):

* ``init``: waits for a heartbeat without axis error, requests CLOSED_LOOP_CONTROL
  (Set_Axis_State) and waits until the heartbeat shows it, then selects POSITION
  control. ``close``: IDLE. ``reset`` (``re_init``): Clear_Errors, then as ``init``.
* ``command``: Set_Controller_Mode when the control or input mode changes, then
  Set_Input_Pos / Set_Input_Vel / Set_Input_Torque; NO_EXCITE requests IDLE (the next
  motion command re-engages closed loop first).
* completion (``reports_completion``): POSITION in TRAP_TRAJ mode completes on the
  heartbeat's trajectory-done flag, but a done flag is ignored until the ODrive has
  acknowledged the new setpoint: the flag went false since the command, or this is
  the second heartbeat after it (the first may have left the ODrive before it read the
  command). Other modes complete when the feedback (encoder estimates, torque
  estimate) stays within tolerance for ``settle_samples`` consecutive samples.
* feedback: the cyclic Get_Encoder_Estimates (default every 10 ms) is cached with its
  receive time; a value older than 3 periods is polled with a remote frame instead.
  Torque: Get_Torques, or Get_Iq × ``torque_constant`` when one is given.
* faults: a heartbeat with an axis error that disarmed the axis (or Get_Error with a
  disarm reason) faults the component (``ErrorId.DEVICE_ERROR``); an error that leaves
  the axis in closed loop is posted with ``post_error``. No heartbeat for
  ``heartbeat_timeout`` (default 3 × 100 ms) faults ``ErrorId.DISCONNECTED``; a bus
  failure faults ``ErrorId.BUS_ERROR``. One fault is reported per episode (latched
  until ``reset``). :meth:`ODriveAxis.estop` sends Estop (reported as ``ErrorId.ESTOP``).
* endpoint writes (RxSdo: the watchdog below, ``vel_ramp_rate`` for ``tm_acc`` ramps) use the
  ids of an endpoint table (``endpoints``: the ``flat_endpoints.json`` of the firmware the
  axis runs, a path relative to the rig file; default: the built-in 0.6.x table, which matches
  no firmware version, :mod:`openel_can.odrive_firmware`). Before the first write (again
  after ``reset``) the axis's version is read with Get_Version (remote frame, bounded wait);
  a firmware (or board) other than the table's refuses the write with HALError naming both
  versions -- nothing is written.
* axis watchdog (:class:`~openel_async.safety.Watchdog`): :meth:`ODriveAxis.arm_watchdog`
  writes ``axis0.config.watchdog_timeout`` and ``axis0.config.enable_watchdog`` by RxSdo
  (endpoint access, firmware 0.6.x; 0.5.x CANSimple has no endpoint write: configure the
  watchdog with odrivetool there) and feeds it from the event loop. When the table does not
  match the axis's firmware, arming fails (the rig's ``init`` fails): the axis is put in IDLE
  and the component faulted (``ErrorId.DEVICE_ERROR``; ``re_init`` asks the version again),
  so it is never left enabled with its watchdog silently missing (a rig without watchdogs
  says so: ``safety.watchdog_timeout: null``). The firmware feeds the
  watchdog on every CANSimple frame addressed to the axis, so streamed set-points feed it;
  when nothing was sent for a quarter of the timeout, a heartbeat poll (remote frame) does,
  from one task of the bus for every armed axis of the bus with the same timeout
  (:class:`~openel_can.odrive_link.WatchdogFeeder`: one wake-up per period for all).
  On expiry the ODrive drops to IDLE with WATCHDOG_TIMER_EXPIRED; the next heartbeat faults
  the component with ``ErrorId.WATCHDOG``.
"""

from __future__ import annotations

import math
import os
import struct
from dataclasses import dataclass
from enum import IntFlag
from typing import Final

import anyio

from openel_async.device import (
    ActuatorDevice,
    ActuatorLimits,
    DeviceContext,
    DeviceInfo,
    ErrorId,
    VelocityRamp,
)
from openel_async.errors import BadParameterError, HALError, NotConnectedError
from openel_async.ids import DeviceKind
from openel_async.logs import get_logger
from openel_async.requests import Request
from openel_async.safety import ExitAction

from . import cansimple as cs
from .bus import CanBus
from .node_faults import NodeFaults
from .odrive_firmware import EndpointTable, FirmwareVersion, driver_endpoint_ids, endpoint_table
from .odrive_link import (
    ODRIVE_VENDOR_ID,
    ODriveLink,
    WatchdogFeeder,
    check_node,
    check_seconds,
    rad_to_turns,
    turns_to_rad,
)
from .odrive_sensors import ODriveBusMonitor, ODriveEncoder, ODriveTemperature

__all__ = [
    "ODriveAxis",
    "ODriveBusMonitor",
    "ODriveEncoder",
    "ODriveError",
    "ODriveTemperature",
    "rad_to_turns",
    "turns_to_rad",
]

log = get_logger(__name__)

VEL_RAMP_RATE_ENDPOINT: Final = 390
"""Endpoint id of ``axis0.controller.config.vel_ramp_rate`` (float, turns/s²) in the built-in
table (:mod:`openel_can.odrive_endpoints`: 0.6.x, exact revision unknown, so never written to
a real ODrive by this id; the driver takes the id from the ``endpoints`` table it is given).
Endpoint ids change between firmware builds."""
WATCHDOG_TIMEOUT_ENDPOINT: Final = 200
"""Endpoint id of ``axis0.config.watchdog_timeout`` (float, s) in the built-in table (same
caveat as :data:`VEL_RAMP_RATE_ENDPOINT`)."""
ENABLE_WATCHDOG_ENDPOINT: Final = 201
"""Endpoint id of ``axis0.config.enable_watchdog`` (bool) in the built-in table."""
VERSION_TIMEOUT: Final = 0.5
"""Seconds the Get_Version reply may take before an endpoint write is refused."""
WATCHDOG_FEED_FRACTION: Final = 4
"""The axis is fed at least every ``timeout / WATCHDOG_FEED_FRACTION``."""
_FLOAT32_MAX: Final = 3.4028234663852886e38


class ODriveError(IntFlag):
    """ODrive 0.6 ``ODriveError`` bits (heartbeat Axis_Error, Get_Error fields)."""

    INITIALIZING = 0x1
    SYSTEM_LEVEL = 0x2
    TIMING_ERROR = 0x4
    MISSING_ESTIMATE = 0x8
    BAD_CONFIG = 0x10
    DRV_FAULT = 0x20
    MISSING_INPUT = 0x40
    DC_BUS_OVER_VOLTAGE = 0x100
    DC_BUS_UNDER_VOLTAGE = 0x200
    DC_BUS_OVER_CURRENT = 0x400
    DC_BUS_OVER_REGEN_CURRENT = 0x800
    CURRENT_LIMIT_VIOLATION = 0x1000
    MOTOR_OVER_TEMP = 0x2000
    INVERTER_OVER_TEMP = 0x4000
    VELOCITY_LIMIT_VIOLATION = 0x8000
    POSITION_LIMIT_VIOLATION = 0x10000
    WATCHDOG_TIMER_EXPIRED = 0x1000000
    ESTOP_REQUESTED = 0x2000000
    SPINOUT_DETECTED = 0x4000000
    BRAKE_RESISTOR_DISARMED = 0x8000000
    THERMISTOR_DISCONNECTED = 0x10000000
    CALIBRATION_ERROR = 0x40000000


def error_names(bits: int) -> str:
    """``'ESTOP_REQUESTED|...'`` for known bits, hex for the rest."""
    names = [flag.name for flag in ODriveError if bits & flag and flag.name]
    unknown = bits & ~sum(ODriveError)
    if unknown:
        names.append(f"{unknown:#x}")
    return "|".join(names) or "none"


def _error_id(bits: int) -> ErrorId:
    """The ErrorId a disarming axis error is reported with."""
    if bits & ODriveError.ESTOP_REQUESTED:
        return ErrorId.ESTOP
    if bits & ODriveError.WATCHDOG_TIMER_EXPIRED:
        return ErrorId.WATCHDOG
    return ErrorId.DEVICE_ERROR


@dataclass
class _Setpoint:
    request: Request
    target: float
    heartbeat_mark: int
    trap: bool
    acked: bool = False
    within: int = 0
    reported: bool = False


_TO_HOST: Final = (
    cs.CmdId.GET_VERSION,
    cs.CmdId.HEARTBEAT,
    cs.CmdId.GET_ERROR,
    cs.CmdId.GET_ENCODER_ESTIMATES,
    cs.CmdId.GET_IQ,
    cs.CmdId.GET_TEMPERATURE,
    cs.CmdId.GET_BUS_VOLTAGE_CURRENT,
    cs.CmdId.GET_TORQUES,
    cs.CmdId.TX_SDO,
)


class ODriveAxis(NodeFaults, ActuatorDevice):
    """One ODrive axis on a CAN bus (CANSimple); see the module docstring."""

    node_label = "ODrive"

    info = DeviceInfo(
        kind=DeviceKind.MOTOR,
        vendor_id=ODRIVE_VENDOR_ID,
        product_id=0x0006,
        vendor_name="ODrive",
        product_name="CanAxis",
        functions=("estop", "clear_errors"),
    )
    reports_completion = True
    velocity_ramp = True
    """``Motor.set_speed(speed, tm_acc)``: input mode VEL_RAMP with ``vel_ramp_rate`` written
    by RxSdo (see :meth:`command_velocity_ramp`)."""

    left_safe: bool = False
    """``safe_stop`` left the device in its exit state: ``close`` leaves it so (set until
    the next ``init``)."""

    def __init__(
        self,
        bus: CanBus,
        node_id: int,
        *,
        limits: ActuatorLimits | None = None,
        position_input_mode: cs.InputMode = cs.InputMode.TRAP_TRAJ,
        velocity_input_mode: cs.InputMode = cs.InputMode.VEL_RAMP,
        torque_input_mode: cs.InputMode = cs.InputMode.PASSTHROUGH,
        heartbeat_period: float = 0.1,
        heartbeat_timeout: float | None = None,
        encoder_period: float = 0.01,
        torque_constant: float | None = None,
        request_timeout: float = 0.05,
        engage_timeout: float = 1.0,
        velocity_limit: float | None = None,
        current_limit: float | None = None,
        traj_velocity: float | None = None,
        traj_acceleration: float | None = None,
        position_tolerance: float = 2e-3,
        velocity_tolerance: float = 0.05,
        torque_tolerance: float = 0.01,
        settle_samples: int = 2,
        endpoints: str | os.PathLike[str] | EndpointTable | None = None,
        files_dir: str | os.PathLike[str] | None = None,
        vel_ramp_rate_endpoint: int | None = None,
        watchdog_timeout_endpoint: int | None = None,
        enable_watchdog_endpoint: int | None = None,
    ) -> None:
        if not isinstance(bus, CanBus):
            raise BadParameterError("bus", bus, "an openel_can.CanBus")
        check_node(node_id)
        table = endpoint_table(endpoints, files_dir)
        ids = driver_endpoint_ids(
            table,
            {
                "vel_ramp_rate_endpoint": vel_ramp_rate_endpoint,
                "watchdog_timeout_endpoint": watchdog_timeout_endpoint,
                "enable_watchdog_endpoint": enable_watchdog_endpoint,
            },
        )
        for name, endpoint in ids.items():
            if (
                isinstance(endpoint, bool)
                or not isinstance(endpoint, int)
                or not 0 < endpoint <= 0xFFFF
            ):
                raise BadParameterError(
                    name,
                    endpoint,
                    "an endpoint id in 1..65535 (flat_endpoints.json of the firmware)",
                )
        for name, seconds in (
            ("heartbeat_period", heartbeat_period),
            ("encoder_period", encoder_period),
            ("request_timeout", request_timeout),
            ("engage_timeout", engage_timeout),
        ):
            check_seconds(name, seconds)
        if heartbeat_timeout is not None:
            check_seconds("heartbeat_timeout", heartbeat_timeout)
        for name, optional in (
            ("torque_constant", torque_constant),
            ("velocity_limit", velocity_limit),
            ("current_limit", current_limit),
            ("traj_velocity", traj_velocity),
            ("traj_acceleration", traj_acceleration),
        ):
            if optional is not None and not (math.isfinite(optional) and optional > 0):
                raise BadParameterError(name, optional, "None or a finite value > 0")
        if (velocity_limit is None) != (current_limit is None):
            # Set_Limits carries both; CANSimple 0.6.x cannot read either back (no
            # Get_Limits), so sending one alone would overwrite the other blindly.
            given, missing = (
                ("velocity_limit", "current_limit")
                if current_limit is None
                else ("current_limit", "velocity_limit")
            )
            raise BadParameterError(
                missing,
                None,
                f"a value since {given} is given: Set_Limits writes both limits and the "
                "ODrive's configured one cannot be read back over CANSimple",
            )
        for name, tol in (
            ("position_tolerance", position_tolerance),
            ("velocity_tolerance", velocity_tolerance),
            ("torque_tolerance", torque_tolerance),
        ):
            if not (math.isfinite(tol) and tol > 0):
                raise BadParameterError(name, tol, "a finite value > 0")
        if (
            isinstance(settle_samples, bool)
            or not isinstance(settle_samples, int)
            or settle_samples < 1
        ):
            raise BadParameterError("settle_samples", settle_samples, "an int >= 1")
        self.bus = bus
        self.node_id = node_id
        if limits is not None:
            self.limits = limits
        self.input_modes = {
            Request.POSITION: cs.InputMode(position_input_mode),
            Request.VELOCITY: cs.InputMode(velocity_input_mode),
            Request.TORQUE: cs.InputMode(torque_input_mode),
        }
        self.heartbeat_period = heartbeat_period
        self.heartbeat_timeout = heartbeat_timeout or 3 * heartbeat_period
        self.encoder_period = encoder_period
        self.torque_constant = torque_constant
        self.engage_timeout = engage_timeout
        self.velocity_limit = velocity_limit
        self.current_limit = current_limit
        self.traj_velocity = traj_velocity
        self.traj_acceleration = traj_acceleration
        self.tolerance = {
            Request.POSITION: position_tolerance,
            Request.VELOCITY: velocity_tolerance,
            Request.TORQUE: torque_tolerance,
        }
        self.settle_samples = settle_samples
        self.endpoints = table
        """The endpoint table whose ids the driver writes (checked against the axis's
        firmware before the first write)."""
        self.vel_ramp_rate_endpoint = ids["vel_ramp_rate_endpoint"]
        self.watchdog_timeout_endpoint = ids["watchdog_timeout_endpoint"]
        self.enable_watchdog_endpoint = ids["enable_watchdog_endpoint"]
        self.firmware_version: FirmwareVersion | None = None
        """What the axis reported with Get_Version (None: not asked since open/reset)."""
        self.watchdog_timeout: float | None = None
        """The armed watchdog timeout in seconds (None: not armed by this driver)."""
        self._saved_ramp_rate: bytes | None = None
        """The ODrive's own vel_ramp_rate (raw float32), read before the first tm_acc ramp
        overwrote it; written back by the next plain velocity command."""
        self._ramp_rate_written = False
        self._link = ODriveLink(bus, node_id, _TO_HOST, request_timeout=request_timeout)
        self._link.on_message = self._on_message
        self._ctx: DeviceContext | None = None
        self._lock = anyio.Lock()
        self._heartbeats = 0
        self._heartbeat_ns: int | None = None
        self._controller_mode: tuple[cs.ControlMode, cs.InputMode] | None = None
        self._closed_loop_wanted = False
        self._engaged = False
        self._latched = False
        self._pending: _Setpoint | None = None
        self._posted_error = 0
        self._querying_error = False
        self.velocity_feedforward = 0.0
        """rad/s sent with every Set_Input_Pos (see :meth:`set_feedforward`)."""
        self.torque_feedforward = 0.0
        """Nm sent with every Set_Input_Pos and Set_Input_Vel."""
        self.last_heartbeat: cs.Heartbeat | None = None
        self.last_error_status: cs.ErrorStatus | None = None
        self.log = log.bind(node=node_id)

    @property
    def malformed_frames(self) -> int:
        """Frames of this node that could not be decoded (counted and dropped)."""
        return self._link.malformed

    # -- lifecycle ------------------------------------------------------------------------
    async def open(self, ctx: DeviceContext) -> None:
        self._ctx = ctx
        self.log = self.log.bind(component=ctx.name)
        self._link.open(ctx, self._on_bus_error)
        ctx.start_soon(self._watchdog)
        # A node is there when it sends heartbeats (poll one in case its rate is slow).
        await self._fresh_heartbeat(timeout=max(self.engage_timeout, self.heartbeat_timeout))

    async def init(self) -> None:
        self.left_safe = False
        self._link.estopped = False
        heartbeat = await self._fresh_heartbeat(timeout=self.heartbeat_timeout)
        if heartbeat.axis_error:
            raise HALError(
                f"ODrive node {self.node_id} reports axis error {heartbeat.axis_error:#x} "
                f"({error_names(heartbeat.axis_error)}); clear it before init"
            )
        await self._configure()
        await self._engage()
        self._latched = False
        self._engaged = True

    async def reset(self) -> None:
        # Not engaged while resetting: nothing the ODrive says now is a new fault.
        self._engaged = False
        self._latched = False
        self._pending = None
        self._link.estopped = False  # re_init is the way back from an e-stop
        self.firmware_version = None  # reflashed meanwhile? asked again before a write
        await self.bus.wait_up(self.engage_timeout)
        asked = self._link.now()
        await self._link.send(cs.ClearErrors(self.node_id))
        await self._link.send(cs.Request(self.node_id, cs.CmdId.HEARTBEAT))
        try:
            await self._link.wait_for(
                cs.CmdId.HEARTBEAT,
                cs.Heartbeat,
                after_ns=asked,
                timeout=self.engage_timeout,
                predicate=lambda hb: hb.axis_error == 0,
            )
        except TimeoutError:
            latest = self._link.latest.get(cs.CmdId.HEARTBEAT)
            if latest is None or latest[0] < asked:
                raise NotConnectedError(
                    f"ODrive node {self.node_id}: no heartbeat within {self.engage_timeout} s"
                ) from None
            hb = latest[1]
            assert isinstance(hb, cs.Heartbeat)
            raise HALError(
                f"ODrive node {self.node_id}: Clear_Errors did not clear axis error "
                f"{hb.axis_error:#x} ({error_names(hb.axis_error)})"
            ) from None
        self._closed_loop_wanted = False
        self._posted_error = 0
        self._controller_mode = None
        await self._configure()
        await self._engage()
        self._latched = False
        self._engaged = True

    async def close(self) -> None:
        # After safe_stop the device stays as it left it (a rig's safety.on_exit: hold
        # must outlive the host); otherwise the axis is disabled.
        self._engaged = False
        self._pending = None
        try:
            if not self.left_safe and self.bus.is_up and self._link.port is not None:
                with anyio.move_on_after(self.engage_timeout):
                    await self._link.send(cs.SetAxisState(self.node_id, cs.AxisState.IDLE))
        except Exception as exc:  # closing a broken link must not raise
            self.log.debug("odrive_idle_not_sent", error=repr(exc))
        finally:
            self._link.close()

    async def _configure(self) -> None:
        node = self.node_id
        if self.velocity_limit is not None and self.current_limit is not None:
            vel = rad_to_turns(self.velocity_limit)
            await self._link.send(cs.SetLimits(node, vel, self.current_limit))
        if self.traj_velocity is not None:
            await self._link.send(cs.SetTrajVelLimit(node, rad_to_turns(self.traj_velocity)))
        if self.traj_acceleration is not None:
            accel = rad_to_turns(self.traj_acceleration)
            await self._link.send(cs.SetTrajAccelLimits(node, accel, accel))

    async def _engage(self) -> None:
        """Closed loop, confirmed by a heartbeat (polled every 20 ms), then POSITION mode.

        ``_closed_loop_wanted`` is set only once confirmed: heartbeats still showing IDLE
        while the ODrive switches must not look like a drop out of closed loop.
        """
        link = self._link
        await link.send(cs.SetAxisState(self.node_id, cs.AxisState.CLOSED_LOOP_CONTROL))

        def settled(hb: cs.Heartbeat) -> bool:
            return hb.axis_state is cs.AxisState.CLOSED_LOOP_CONTROL or hb.axis_error != 0

        hb: cs.Heartbeat | None = None
        with anyio.move_on_after(self.engage_timeout):
            while hb is None:
                polled = link.now()
                await link.send(cs.Request(self.node_id, cs.CmdId.HEARTBEAT))
                try:
                    _, hb = await link.wait_for(
                        cs.CmdId.HEARTBEAT,
                        cs.Heartbeat,
                        after_ns=polled,
                        timeout=0.02,
                        predicate=settled,
                    )
                except TimeoutError:
                    continue
        if hb is None:
            last = self.last_heartbeat
            state = cs.value_name(last.axis_state) if last else "no heartbeat"
            raise TimeoutError(
                f"ODrive node {self.node_id} not in CLOSED_LOOP_CONTROL after "
                f"{self.engage_timeout} s ({state})"
            )
        if hb.axis_state is not cs.AxisState.CLOSED_LOOP_CONTROL:
            raise HALError(
                f"ODrive node {self.node_id} refused closed loop: axis error "
                f"{hb.axis_error:#x} ({error_names(hb.axis_error)})"
            )
        self._closed_loop_wanted = True
        if self._controller_mode is None:
            await self._set_mode(Request.POSITION)

    async def _set_mode(self, request: Request) -> None:
        control = {
            Request.POSITION: cs.ControlMode.POSITION,
            Request.VELOCITY: cs.ControlMode.VELOCITY,
            Request.TORQUE: cs.ControlMode.TORQUE,
        }[request]
        await self._set_controller_mode(control, self.input_modes[request])

    async def _set_controller_mode(self, control: cs.ControlMode, inputs: cs.InputMode) -> None:
        wanted = (control, inputs)
        if wanted != self._controller_mode:
            self._controller_mode = None
            await self._link.send(cs.SetControllerMode(self.node_id, *wanted))
            self._controller_mode = wanted

    async def _fresh_heartbeat(self, timeout: float) -> cs.Heartbeat:  # noqa: ASYNC109
        asked = self._link.now()
        await self._link.send(cs.Request(self.node_id, cs.CmdId.HEARTBEAT))
        try:
            _, hb = await self._link.wait_for(
                cs.CmdId.HEARTBEAT, cs.Heartbeat, after_ns=asked, timeout=timeout
            )
        except TimeoutError:
            raise NotConnectedError(
                f"ODrive node {self.node_id}: no heartbeat within {timeout * 1000:.0f} ms"
            ) from None
        return hb

    # -- commands -------------------------------------------------------------------------
    async def command(self, request: Request, value: float) -> None:
        async with self._lock:
            node = self.node_id
            if request is Request.NO_EXCITE:
                self._pending = None
                self._closed_loop_wanted = False
                await self._link.send(cs.SetAxisState(node, cs.AxisState.IDLE))
                return
            if not self._closed_loop_wanted:
                await self._engage()
            await self._set_mode(request)
            if request is Request.POSITION:
                await self._link.send(
                    cs.SetInputPos(
                        node,
                        rad_to_turns(value),
                        rad_to_turns(self.velocity_feedforward),
                        self.torque_feedforward,
                    )
                )
            elif request is Request.VELOCITY:
                if self._ramp_rate_written:
                    await self._restore_ramp_rate()
                await self._link.send(
                    cs.SetInputVel(node, rad_to_turns(value), self.torque_feedforward)
                )
            else:
                await self._link.send(cs.SetInputTorque(node, value))
            trap = (
                request is Request.POSITION and self.input_modes[request] is cs.InputMode.TRAP_TRAJ
            )
            # Armed synchronously right before returning: the Actuator installs the new
            # Motion before the receive task can run, so a report is never misattributed.
            setpoint = _Setpoint(request, value, self._heartbeats, trap)
            self._pending = setpoint
        if request is Request.TORQUE and self._ctx is not None:
            self._ctx.start_soon(self._poll_torque, setpoint)

    async def read(self, request: Request) -> float:
        link = self._link
        if request in (Request.POSITION_ACTUAL, Request.VELOCITY_ACTUAL):
            max_age = round(3 * self.encoder_period * 1e9)
            _, est = await link.fresh(cs.CmdId.GET_ENCODER_ESTIMATES, cs.EncoderEstimates, max_age)
            return turns_to_rad(est.pos if request is Request.POSITION_ACTUAL else est.vel)
        if request is Request.TORQUE_ACTUAL:
            return await self._torque(round(self.encoder_period * 1e9))
        raise BadParameterError(
            "request", request, "POSITION_ACTUAL, VELOCITY_ACTUAL or TORQUE_ACTUAL"
        )

    async def command_velocity_ramp(self, ramp: VelocityRamp) -> None:
        """tmAcc with the ODrive's own ramp: ``vel_ramp_rate`` = |target - start| / tmAcc
        (turns/s², written by RxSdo to :attr:`vel_ramp_rate_endpoint`), Set_Controller_Mode
        VELOCITY / VEL_RAMP, then Set_Input_Vel of the target. Completion as for a velocity
        command: the encoder velocity within tolerance of the target (the end of the ramp).

        The ODrive's own ``vel_ramp_rate`` is read once (RxSdo read, TxSdo reply) before the
        first ramp overwrites it, and written back by the next plain velocity command. A
        rate that does not fit the float32 endpoint is refused (BadParameterError naming
        ``tm_acc``) before anything is sent; a zero rate (start = target) writes no rate. So
        is a ramp when the endpoint table is not the axis's firmware's (HALError).
        """
        rate = rad_to_turns(ramp.rate)
        if not (math.isfinite(rate) and rate <= _FLOAT32_MAX):
            raise BadParameterError(
                "tm_acc",
                ramp.duration_s,
                f"a ramp time giving a vel_ramp_rate that fits a float32 (got {rate} turn/s^2)",
            )
        target = rad_to_turns(ramp.target)
        async with self._lock:
            node = self.node_id
            if rate > 0.0:  # refused before anything is sent when the ids are not the firmware's
                refusal = await self.endpoint_write_refusal("axis0.controller.config.vel_ramp_rate")
                if refusal is not None:
                    raise HALError(refusal)
            if not self._closed_loop_wanted:
                await self._engage()
            if rate > 0.0 and self._saved_ramp_rate is None:
                try:
                    self._saved_ramp_rate = await self.read_endpoint(self.vel_ramp_rate_endpoint)
                except TimeoutError:
                    raise HALError(
                        f"ODrive node {node}: no TxSdo reply for endpoint "
                        f"{self.vel_ramp_rate_endpoint}; is vel_ramp_rate_endpoint the id of "
                        "axis0.controller.config.vel_ramp_rate in this firmware's "
                        "flat_endpoints.json?"
                    ) from None
            await self._set_controller_mode(cs.ControlMode.VELOCITY, cs.InputMode.VEL_RAMP)
            if rate > 0.0:
                await self._write_endpoint(self.vel_ramp_rate_endpoint, struct.pack("<f", rate))
                self._ramp_rate_written = True
            await self._link.send(cs.SetInputVel(node, target, self.torque_feedforward))
            setpoint = _Setpoint(Request.VELOCITY, ramp.target, self._heartbeats, False)
            self._pending = setpoint

    async def _restore_ramp_rate(self) -> None:
        saved = self._saved_ramp_rate
        if saved is not None:
            await self._write_endpoint(self.vel_ramp_rate_endpoint, saved)
        self._ramp_rate_written = False

    async def _write_endpoint(self, endpoint: int, value: bytes) -> None:
        refusal = await self.endpoint_write_refusal(f"endpoint {endpoint}")
        if refusal is not None:
            raise HALError(refusal)
        await self._link.send(cs.RxSdo(self.node_id, cs.SdoOpcode.WRITE, endpoint, value))

    async def read_firmware_version(self) -> FirmwareVersion | None:
        """The axis's Get_Version (remote frame; at most :data:`VERSION_TIMEOUT` s), kept
        until ``reset``; None when it does not answer (asked again next time)."""
        if self.firmware_version is None:
            link = self._link
            asked = link.now()
            await link.send(cs.Request(self.node_id, cs.CmdId.GET_VERSION))
            try:
                _, msg = await link.wait_for(
                    cs.CmdId.GET_VERSION,
                    cs.Version,
                    after_ns=asked,
                    timeout=max(VERSION_TIMEOUT, link.request_timeout),
                )
            except TimeoutError:
                self.log.warning("odrive_no_version_reply", timeout_s=VERSION_TIMEOUT)
                return None
            self.firmware_version = FirmwareVersion.of(msg)
            self.log.info("odrive_firmware", firmware=str(self.firmware_version))
        return self.firmware_version

    async def endpoint_write_refusal(self, what: str) -> str | None:
        """Why writing ``what`` by the endpoint table's ids is refused: the axis's firmware
        is not the table's (or does not say); None: the ids are the firmware's."""
        version = await self.read_firmware_version()
        refusal = self.endpoints.refusal(self.node_id, version, what)
        if refusal is not None:
            self.log.error("odrive_endpoint_write_refused", reason=refusal)
        return refusal

    async def read_endpoint(self, endpoint: int) -> bytes:
        """The raw 4-byte value of an endpoint (RxSdo read, bounded wait for its TxSdo)."""
        link = self._link
        asked = link.now()
        await link.send(cs.RxSdo(self.node_id, cs.SdoOpcode.READ, endpoint))
        _, reply = await link.wait_for(
            cs.CmdId.TX_SDO,
            cs.TxSdo,
            after_ns=asked,
            timeout=link.request_timeout,
            predicate=lambda msg: msg.endpoint_id == endpoint,
        )
        return reply.value

    async def _torque(self, max_age_ns: int) -> float:
        if self.torque_constant is not None:
            _, iq = await self._link.fresh(cs.CmdId.GET_IQ, cs.Iq, max_age_ns)
            return iq.measured * self.torque_constant
        _, torques = await self._link.fresh(cs.CmdId.GET_TORQUES, cs.Torques, max_age_ns)
        return torques.estimate

    def set_feedforward(self, velocity: float = 0.0, torque: float = 0.0) -> None:
        """Feed-forward terms of the following setpoints (rad/s, Nm).

        Set_Input_Pos carries them quantised to 0.001 turn/s and 0.001 Nm in int16
        (|velocity| < 32.767 turn/s, |torque| < 32.767 Nm); Set_Input_Vel carries the
        torque as f32. Streaming a trajectory, pass its velocity here before each position.
        """
        for name, value, bound in (
            ("velocity", velocity, math.tau * 32.767),
            ("torque", torque, 32.767),
        ):
            if not (math.isfinite(value) and abs(value) <= bound):
                raise BadParameterError(
                    name, value, f"a feed-forward in [-{bound:.3f}, {bound:.3f}]"
                )
        self.velocity_feedforward = float(velocity)
        self.torque_feedforward = float(torque)

    async def estop(self) -> None:
        """Send Estop: the ODrive disarms with ESTOP_REQUESTED (IDLE: the motor coasts); its
        next heartbeat faults the component with ``ErrorId.ESTOP`` (``re_init`` sends
        Clear_Errors and re-engages). From now on until ``re_init`` no frame that would
        engage the axis or give it a set-point is sent (a command on its way fails with
        ``HALError``), and the command lock is not waited for: the e-stop goes out at once."""
        self._link.estopped = True
        self._pending = None
        self._closed_loop_wanted = False
        await self._link.send(cs.Estop(self.node_id))
        self._query_error()  # Get_Error now: the report need not wait for the heartbeat

    async def safe_stop(self, action: ExitAction) -> None:
        """HOLD: position control (passthrough) at the current position estimate; STOP:
        velocity control with VEL_RAMP to 0 (the ODrive's ``vel_ramp_rate``), then it holds
        zero velocity; TORQUE_OFF: IDLE."""
        action = ExitAction(action)
        self.left_safe = True
        node = self.node_id
        async with self._lock:
            self._pending = None
            if self._link.estopped and action is not ExitAction.TORQUE_OFF:
                # After an e-stop the axis stays IDLE: no HOLD or STOP re-engages it.
                self.log.warning("odrive_safe_stop_after_estop", action=action.value, sent="IDLE")
                action = ExitAction.TORQUE_OFF
            if action is ExitAction.TORQUE_OFF:
                self._closed_loop_wanted = False
                await self._link.send(cs.SetAxisState(node, cs.AxisState.IDLE))
            elif action is ExitAction.STOP:
                await self._set_controller_mode(cs.ControlMode.VELOCITY, cs.InputMode.VEL_RAMP)
                await self._link.send(cs.SetInputVel(node, 0.0, 0.0))
            else:
                _, est = await self._link.fresh(
                    cs.CmdId.GET_ENCODER_ESTIMATES,
                    cs.EncoderEstimates,
                    round(self.encoder_period * 1e9),
                )
                await self._set_controller_mode(cs.ControlMode.POSITION, cs.InputMode.PASSTHROUGH)
                await self._link.send(cs.SetInputPos(node, est.pos, 0.0, 0.0))

    # -- axis watchdog --------------------------------------------------------------------
    async def arm_watchdog(self, timeout_s: float) -> None:
        """Write ``watchdog_timeout`` = ``timeout_s`` and ``enable_watchdog`` = True (RxSdo),
        confirm the enable by reading it back, and feed from the event loop from now on.

        ``timeout_s``: a float32 number of seconds > 0 (0 disables the ODrive's watchdog and
        is refused here: use :meth:`disarm_watchdog`).
        """
        if (
            isinstance(timeout_s, bool)
            or not isinstance(timeout_s, int | float)
            or not (math.isfinite(timeout_s) and 0.0 < timeout_s <= _FLOAT32_MAX)
            or struct.unpack("<f", struct.pack("<f", timeout_s))[0] <= 0.0
        ):
            raise BadParameterError(
                "timeout_s",
                timeout_s,
                "a finite number of seconds > 0 that fits axis.config.watchdog_timeout (float32)",
            )
        if self._ctx is None:
            raise HALError(f"ODrive node {self.node_id}: arm_watchdog before open")
        async with self._lock:
            refusal = await self.endpoint_write_refusal("the axis watchdog's endpoints")
            if refusal is not None:
                # Never left enabled with its watchdog silently missing: IDLE, and the
                # component faulted (no command re-engages it; re_init checks again).
                self._closed_loop_wanted = False
                self._pending = None
                await self._link.send(cs.SetAxisState(self.node_id, cs.AxisState.IDLE))
                message = (
                    f"{refusal}, or run without the axis watchdog: safety.watchdog_timeout: "
                    "null (the axis was put in IDLE)"
                )
                self._fault(ErrorId.DEVICE_ERROR, message)
                raise HALError(message)
            self.watchdog_timeout = float(timeout_s)
            feeder = WatchdogFeeder.for_bus(
                self.bus, self._ctx.clock, self.watchdog_timeout, WATCHDOG_FEED_FRACTION
            )
            feeder.add(self._link, self._armed_timeout)
            await self._write_endpoint(
                self.watchdog_timeout_endpoint, struct.pack("<f", float(timeout_s))
            )
            await self._write_endpoint(self.enable_watchdog_endpoint, bytes((1, 0, 0, 0)))
            try:
                enabled = await self.read_endpoint(self.enable_watchdog_endpoint)
            except TimeoutError:
                raise HALError(
                    f"ODrive node {self.node_id}: no TxSdo reply for endpoint "
                    f"{self.enable_watchdog_endpoint}; is enable_watchdog_endpoint the id of "
                    "axis0.config.enable_watchdog in this firmware's flat_endpoints.json?"
                ) from None
            if not enabled[0]:
                raise HALError(
                    f"ODrive node {self.node_id}: axis0.config.enable_watchdog reads back False"
                )
        self.log.info("odrive_watchdog_armed", timeout_s=timeout_s)

    async def disarm_watchdog(self) -> None:
        """Write ``enable_watchdog`` = False (RxSdo), then stop feeding."""
        if self.watchdog_timeout is None:
            return
        async with self._lock:
            if self.bus.is_up and self._link.port is not None:
                await self._write_endpoint(self.enable_watchdog_endpoint, bytes(4))
            self.watchdog_timeout = None

    def _armed_timeout(self) -> float | None:
        """For the bus's :class:`~openel_can.odrive_link.WatchdogFeeder`."""
        return self.watchdog_timeout

    async def clear_errors(self) -> None:
        """Send Clear_Errors (``re_init`` does this and re-engages closed loop)."""
        await self._link.send(cs.ClearErrors(self.node_id))

    # -- receive side -----------------------------------------------------------------------
    def _on_message(self, msg: cs.CanSimpleMessage, now: int) -> None:
        if isinstance(msg, cs.Heartbeat):
            self._on_heartbeat(msg, now)
        elif isinstance(msg, cs.EncoderEstimates):
            setpoint = self._pending
            if setpoint is not None and not setpoint.reported and not setpoint.trap:
                if setpoint.request is Request.POSITION:
                    self._settle(setpoint, turns_to_rad(msg.pos))
                elif setpoint.request is Request.VELOCITY:
                    self._settle(setpoint, turns_to_rad(msg.vel))
        elif isinstance(msg, cs.ErrorStatus):
            self._on_error_status(msg)
        elif isinstance(msg, cs.Torques | cs.Iq):
            setpoint = self._pending
            if (
                setpoint is not None
                and setpoint.request is Request.TORQUE
                and not setpoint.reported
            ):
                if isinstance(msg, cs.Torques) and self.torque_constant is None:
                    self._settle(setpoint, msg.estimate)
                elif isinstance(msg, cs.Iq) and self.torque_constant is not None:
                    self._settle(setpoint, msg.measured * self.torque_constant)

    def _on_heartbeat(self, hb: cs.Heartbeat, now: int) -> None:
        self._heartbeats += 1
        self._heartbeat_ns = now
        self.last_heartbeat = hb
        if not self._engaged or self._latched:
            return
        if hb.axis_error:
            self._query_error()
            if self._closed_loop_wanted and hb.axis_state is not cs.AxisState.CLOSED_LOOP_CONTROL:
                self._fault(
                    _error_id(hb.axis_error),
                    f"ODrive node {self.node_id} disarmed: axis error {hb.axis_error:#x} "
                    f"({error_names(hb.axis_error)}), state {cs.value_name(hb.axis_state)}",
                )
                return
            if hb.axis_error != self._posted_error:
                self._posted_error = hb.axis_error
                self.log.warning("odrive_axis_error", error=error_names(hb.axis_error))
                assert self._ctx is not None
                self._ctx.post_error(ErrorId.DEVICE_ERROR)
        elif self._closed_loop_wanted and hb.axis_state is not cs.AxisState.CLOSED_LOOP_CONTROL:
            self._fault(
                ErrorId.DEVICE_ERROR,
                f"ODrive node {self.node_id} left closed loop "
                f"(state {cs.value_name(hb.axis_state)})",
            )
            return
        setpoint = self._pending
        if setpoint is not None and setpoint.trap and not setpoint.reported:
            if not hb.trajectory_done:
                setpoint.acked = True
            elif setpoint.acked or self._heartbeats - setpoint.heartbeat_mark >= 2:
                self._report(setpoint)

    def _on_error_status(self, status: cs.ErrorStatus) -> None:
        self.last_error_status = status
        if not self._engaged or self._latched:
            return
        if status.disarm_reason:
            self._fault(
                _error_id(status.disarm_reason),
                f"ODrive node {self.node_id} disarmed: {error_names(status.disarm_reason)} "
                f"(active {error_names(status.active_errors)})",
            )
        elif status.active_errors and status.active_errors != self._posted_error:
            self._posted_error = status.active_errors
            assert self._ctx is not None
            self._ctx.post_error(ErrorId.DEVICE_ERROR)

    def _query_error(self) -> None:
        if not self._querying_error and self._ctx is not None:
            self._querying_error = True
            self._ctx.start_soon(self._request_error_status)

    async def _request_error_status(self) -> None:
        try:
            await self._link.request(cs.CmdId.GET_ERROR, cs.ErrorStatus)
        except (TimeoutError, NotConnectedError) as exc:
            self.log.debug("odrive_get_error_failed", error=repr(exc))
        finally:
            self._querying_error = False

    def _settle(self, setpoint: _Setpoint, actual: float) -> None:
        if abs(actual - setpoint.target) <= self.tolerance[setpoint.request]:
            setpoint.within += 1
            if setpoint.within >= self.settle_samples:
                self._report(setpoint)
        else:
            setpoint.within = 0

    def _report(self, setpoint: _Setpoint) -> None:
        if setpoint is self._pending and not setpoint.reported and self._ctx is not None:
            setpoint.reported = True
            self._ctx.target_reached()

    async def _poll_torque(self, setpoint: _Setpoint) -> None:
        """Torque has no cyclic feedback: poll it until the setpoint completes or is replaced."""
        assert self._ctx is not None
        clock = self._ctx.clock
        period_ns = round(self.encoder_period * 1e9)
        cmd = cs.CmdId.GET_IQ if self.torque_constant is not None else cs.CmdId.GET_TORQUES
        next_poll = clock.now_ns()
        while setpoint is self._pending and not setpoint.reported and self._engaged:
            try:
                await self._link.send(cs.Request(self.node_id, cmd))
            except (TimeoutError, NotConnectedError):
                return
            next_poll += period_ns
            await clock.sleep_until(next_poll)

    # -- faults ---------------------------------------------------------------------------
    def _on_latch(self) -> None:
        self._pending = None
