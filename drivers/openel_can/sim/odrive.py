"""A simulated ODrive axis speaking CANSimple (firmware 0.6.x) on a python-can bus.

The peer is an anyio task (:meth:`SimODrive.serve` on its own python-can bus, or
:meth:`SimODrive.run` on a given :class:`~openel_can.bus.CanBus`). It answers remote
frames (Get_* and Heartbeat polls), executes host commands in the order received, and
transmits its cyclic messages at the ODrive defaults: Heartbeat every 100 ms and
Get_Encoder_Estimates every 10 ms (both configurable).

Dynamics in turns (closed form, :mod:`openel_sim.profile`): TRAP_TRAJ position moves
are trapezoids under the trajectory velocity/acceleration limits with the
trajectory-done flag cleared while moving; VEL_RAMP ramps at ``vel_ramp_rate``;
TORQUE accelerates the rotor inertia up to the velocity limit; IDLE coasts to rest.
Entering closed loop holds the current position (as ``input_pos = pos_estimate``).
Temperatures follow a first-order thermal model of the I²R losses.

Fault injection: :meth:`inject_error` (an axis error that disarms, or not),
:meth:`set_silent` (the node stops transmitting and listening: heartbeat loss), and
Estop from the host (ESTOP_REQUESTED). ``axis_state`` may be set to any int (newer
firmware reports states this codec does not name, e.g. 15 and 16 in 0.6.11).

Firmware: the node's endpoint ids are those of ``endpoints`` (an
:class:`~openel_can.odrive_firmware.EndpointTable`; default: the built-in table), and it
answers Get_Version (a remote frame) with ``firmware`` (default: the table's own version --
:data:`~openel_can.odrive_firmware.SIMULATED_FIRMWARE` for the built-in table, a loaded
``flat_endpoints.json``'s ``fw_version``/``hw_version`` otherwise). Give another ``firmware``
to simulate an axis running firmware other than the host's table.

Endpoint access (RxSdo/TxSdo): the endpoint ``vel_ramp_rate_endpoint`` (default: the
table's ``axis0.controller.config.vel_ramp_rate``, a float32 in turns/s²) is read and
written; a read is answered with TxSdo, a write is not answered. The other endpoints of the
table (what ``openel-async param`` reads) are answered too: a written value is read back as
written, one never written reads as the simulation's own value where it has one (bus
voltage, limits, node id, state, temperatures...) or 0. Endpoint ids outside that table are
recorded and otherwise ignored (no reply), as is a non-finite or negative rate.

Axis watchdog (``axis0.config.enable_watchdog`` / ``watchdog_timeout``, endpoints
``enable_watchdog_endpoint`` / ``watchdog_timeout_endpoint``, defaults: the table's):
written by RxSdo, or set directly with :meth:`SimODrive.set_watchdog`. As in the firmware's
CANSimple ``do_command``, every frame addressed to this node (data or remote) feeds it.
While enabled with a timeout > 0 and the axis is in closed loop, a feed older than the
timeout (on the peer's own clock) raises WATCHDOG_TIMER_EXPIRED and drops the axis to IDLE.
``watchdog_trips`` counts the trips.

Set_Limits overwrites both limits with the values received, as the firmware does
(``vel_limit`` turn/s, ``current_limit`` A); an infinite velocity limit is stored but the
motion model keeps the last finite one. ``commands`` keeps the newest
``history`` host commands (a :class:`~openel_can.sim.history.History`: ``discarded``
counts the older ones); a command with an enum value the codec does not know is
recorded and otherwise ignored.
"""

from __future__ import annotations

import math
import struct
from typing import Final

import anyio
import anyio.abc
import can

from openel_async.clock import Clock, default_clock
from openel_async.logs import get_logger
from openel_sim import profile as prof

from .. import cansimple as cs
from ..bus import CanBus, NodePort
from ..errors import DecodeError
from ..odrive import ODriveError
from ..odrive_firmware import BUILTIN_TABLE, SIMULATED_FIRMWARE, EndpointTable, FirmwareVersion
from .history import DEFAULT_HISTORY, History

__all__ = ["SimODrive"]

log = get_logger(__name__)

NS: Final = 1e-9
_HOST_CMDS: Final = (
    cs.CmdId.ESTOP,
    cs.CmdId.RX_SDO,
    cs.CmdId.SET_AXIS_STATE,
    cs.CmdId.SET_CONTROLLER_MODE,
    cs.CmdId.SET_INPUT_POS,
    cs.CmdId.SET_INPUT_VEL,
    cs.CmdId.SET_INPUT_TORQUE,
    cs.CmdId.SET_LIMITS,
    cs.CmdId.SET_TRAJ_VEL_LIMIT,
    cs.CmdId.SET_TRAJ_ACCEL_LIMITS,
    cs.CmdId.SET_TRAJ_INERTIA,
    cs.CmdId.REBOOT,
    cs.CmdId.CLEAR_ERRORS,
    cs.CmdId.SET_ABSOLUTE_POSITION,
    cs.CmdId.SET_POS_GAIN,
    cs.CmdId.SET_VEL_GAINS,
)
_POLLED: Final = (
    cs.CmdId.GET_VERSION,
    cs.CmdId.HEARTBEAT,
    cs.CmdId.GET_ERROR,
    cs.CmdId.GET_ENCODER_ESTIMATES,
    cs.CmdId.GET_IQ,
    cs.CmdId.GET_TEMPERATURE,
    cs.CmdId.GET_BUS_VOLTAGE_CURRENT,
    cs.CmdId.GET_TORQUES,
    cs.CmdId.GET_POWERS,
)
TORQUE_RISE_S: Final = 0.002
AMBIENT_C: Final = 25.0


class SimODrive:
    """One simulated ODrive axis; all internal quantities in turns, turns/s, Nm, A, °C."""

    def __init__(
        self,
        node_id: int = 0,
        *,
        heartbeat_period: float = 0.1,
        encoder_period: float = 0.01,
        vel_limit: float = 2.0,
        current_limit: float = 10.0,
        traj_vel_limit: float = 1.0,
        traj_accel_limit: float = 8.0,
        vel_ramp_rate: float = 8.0,
        inertia: float = 0.001,
        torque_constant: float = 0.0827,
        phase_resistance: float = 0.05,
        thermal_time_constant: float = 30.0,
        thermal_resistance: float = 4.0,
        bus_voltage: float = 24.0,
        initial_position: float = 0.0,
        history: int = DEFAULT_HISTORY,
        clock: Clock | None = None,
        endpoints: EndpointTable = BUILTIN_TABLE,
        firmware: FirmwareVersion | None = None,
        vel_ramp_rate_endpoint: int | None = None,
        watchdog_timeout_endpoint: int | None = None,
        enable_watchdog_endpoint: int | None = None,
        serial_number: int | None = None,
    ) -> None:
        if not 0 <= node_id < cs.MAX_NODE_ID:
            raise ValueError(f"node_id {node_id} outside 0..{cs.MAX_NODE_ID - 1}")
        self.node_id = node_id
        self.endpoints = endpoints
        self.firmware = firmware or _firmware_of(endpoints)
        """What Get_Version reports (may be changed at any time: a reflashed axis)."""
        self._endpoint_names = {e.id: e.name for e in endpoints.endpoints}

        def endpoint_id(given: int | None, name: str) -> int:
            if given is not None:
                return given
            endpoint = endpoints.get(name)
            return -1 if endpoint is None else endpoint.id  # -1: never addressed

        vel_ramp_rate_endpoint = endpoint_id(
            vel_ramp_rate_endpoint, "axis0.controller.config.vel_ramp_rate"
        )
        watchdog_timeout_endpoint = endpoint_id(
            watchdog_timeout_endpoint, "axis0.config.watchdog_timeout"
        )
        enable_watchdog_endpoint = endpoint_id(
            enable_watchdog_endpoint, "axis0.config.enable_watchdog"
        )
        self.serial_number = 0x3A5F_2000_0000 + node_id if serial_number is None else serial_number
        """48 bits, sent in the Address reply (firmware 0.6.9+) to a broadcast request."""
        self.heartbeat_period = heartbeat_period
        self.encoder_period = encoder_period
        self.vel_limit = vel_limit
        self.current_limit = current_limit
        """A: as last set by Set_Limits (not modelled beyond being stored)."""
        self.traj_vel_limit = traj_vel_limit
        self.traj_accel_limit = traj_accel_limit
        self.vel_ramp_rate = vel_ramp_rate
        """turns/s²: VEL_RAMP's rate (written by RxSdo to ``vel_ramp_rate_endpoint``)."""
        self.vel_ramp_rate_endpoint = vel_ramp_rate_endpoint
        self.inertia = inertia  # kg m^2
        self.torque_constant = torque_constant  # Nm/A
        self.phase_resistance = phase_resistance
        self.thermal_time_constant = thermal_time_constant
        self.thermal_resistance = thermal_resistance  # K/W
        self.nominal_bus_voltage = bus_voltage
        self.clock: Clock = clock or default_clock()
        now = self.clock.now_ns()
        self.axis_state: cs.AxisState | int = cs.AxisState.IDLE
        self.fault_requested: str | None = None
        """A fault asked for by :meth:`inject_fault`, not yet applied."""
        self.control_mode = cs.ControlMode.POSITION
        self.input_mode = cs.InputMode.PASSTHROUGH
        self.active_errors = 0
        self.disarm_reason = 0
        self.procedure_result = cs.ProcedureResult.SUCCESS
        self.silent = False
        self.segments = prof.hold(now, initial_position)
        self.traj_end_ns: int | None = None
        self.torque_setpoint = 0.0
        self.torque_since_ns = now
        self.motor_temp = AMBIENT_C
        self.fet_temp = AMBIENT_C
        self._thermal_ns = now
        self.commands: History[cs.CanSimpleMessage] = History(history)
        """The newest host commands received, in order (``commands.discarded``: older ones)."""
        self.malformed = 0
        self._port: NodePort | None = None
        self.watchdog_timeout_endpoint = watchdog_timeout_endpoint
        self.enable_watchdog_endpoint = enable_watchdog_endpoint
        self.endpoint_values: dict[int, bytes] = {}
        """The other endpoints of the table written by RxSdo (read back as written; never
        written: zero, or the simulation's own value)."""
        self.enable_watchdog = False
        """``axis0.config.enable_watchdog``."""
        self.watchdog_timeout = 0.0
        """``axis0.config.watchdog_timeout`` in seconds (0: no watchdog)."""
        self.watchdog_fed_ns = now
        self.watchdog_trips = 0
        self.log = log.bind(sim_odrive=node_id)

    # -- running ----------------------------------------------------------------------------
    async def serve(
        self,
        channel: str,
        *,
        interface: str = "virtual",
        task_status: anyio.abc.TaskStatus[None] = anyio.TASK_STATUS_IGNORED,
    ) -> None:
        """Open an own python-can bus on ``channel`` and run until cancelled."""
        async with CanBus(
            interface=interface,
            channel=channel,
            name=f"sim-odrive-{self.node_id}",
            poll_interval=0.02,
        ) as bus:
            await self.run(bus, task_status=task_status)

    async def run(
        self, bus: CanBus, *, task_status: anyio.abc.TaskStatus[None] = anyio.TASK_STATUS_IGNORED
    ) -> None:
        ids = [cs.arbitration_id(self.node_id, cmd) for cmd in (*_HOST_CMDS, *_POLLED)]
        ids.append(cs.arbitration_id(cs.BROADCAST_NODE_ID, cs.CmdId.ADDRESS))  # discovery
        port = self._port = bus.attach(ids, name=f"sim-odrive-{self.node_id}")
        try:
            async with anyio.create_task_group() as tg:
                tg.start_soon(self._receive, port)
                tg.start_soon(self._cyclic)
                tg.start_soon(self._watchdog)
                task_status.started()
        finally:
            port.close()
            self.log.info(
                "sim_stopped",
                commands=self.commands.total,
                commands_discarded=self.commands.discarded,
                malformed=self.malformed,
            )

    # -- fault injection ------------------------------------------------------------------
    def inject_error(self, error: int = ODriveError.DRV_FAULT, *, disarm: bool = True) -> None:
        """Raise an axis error; a disarming one drops the axis to IDLE (it coasts)."""
        self.active_errors |= int(error)
        if disarm:
            self.disarm_reason |= int(error)
            self._set_state(cs.AxisState.IDLE)

    def inject_fault(self, reason: str) -> None:
        """Trip on motor over-temperature (``openel_async.rig.FaultInjection``), from any
        thread: the request is applied by the peer's own loop within an encoder period."""
        self.fault_requested = reason

    def set_silent(self, silent: bool = True) -> None:
        """Stop (or resume) transmitting and listening: a node cut off the bus."""
        self.silent = silent

    def set_watchdog(self, timeout: float, *, enable: bool = True) -> None:
        """Configure the axis watchdog as ``odrivetool`` would (and feed it)."""
        self.watchdog_timeout = timeout
        self.enable_watchdog = enable
        self.watchdog_feed()

    def watchdog_feed(self) -> None:
        self.watchdog_fed_ns = self.now()

    def watchdog_expired(self, now: int) -> bool:
        """The firmware's watchdog check (run while the axis is in closed loop)."""
        if not self.enable_watchdog or self.watchdog_timeout <= 0.0:
            return False
        return now - self.watchdog_fed_ns > round(self.watchdog_timeout * 1e9)

    async def _watchdog(self) -> None:
        clock = self.clock
        while True:
            now = clock.now_ns()
            if self.axis_state is cs.AxisState.CLOSED_LOOP_CONTROL and self.watchdog_expired(now):
                self.watchdog_trips += 1
                self.log.info("sim_watchdog_expired", timeout=self.watchdog_timeout)
                self.inject_error(ODriveError.WATCHDOG_TIMER_EXPIRED)
            # The firmware checks every control cycle; here at the deadline (>= 1 ms ahead)
            # or every 10 ms while the configuration may change.
            wake = now + 10_000_000
            if self.enable_watchdog and self.watchdog_timeout > 0.0:
                deadline = self.watchdog_fed_ns + round(self.watchdog_timeout * 1e9) + 1
                wake = max(now + 1_000_000, min(wake, deadline))
            await clock.sleep_until(wake)

    # -- state ------------------------------------------------------------------------------
    def now(self) -> int:
        return self.clock.now_ns()

    def state_at(self, t_ns: int) -> tuple[float, float, float]:
        """(position turns, velocity turns/s, acceleration turns/s^2)."""
        return prof.evaluate(self.segments, t_ns)

    @property
    def position(self) -> float:
        return self.state_at(self.now())[0]

    def torque_at(self, t_ns: int) -> float:
        _, v, a = self.state_at(t_ns)
        if self.axis_state is not cs.AxisState.CLOSED_LOOP_CONTROL:
            return 0.0
        if self.control_mode is cs.ControlMode.TORQUE:
            if abs(v) >= self.vel_limit - 1e-9 and a == 0:
                return 0.0  # held at the velocity limit
            rise = min(1.0, (t_ns - self.torque_since_ns) * NS / TORQUE_RISE_S)
            return self.torque_setpoint * rise
        return self.inertia * a * math.tau

    def trajectory_done(self, t_ns: int) -> bool:
        return self.traj_end_ns is None or t_ns >= self.traj_end_ns

    def _set_state(self, state: cs.AxisState) -> None:
        now = self.now()
        p, v, _ = self.state_at(now)
        self.axis_state = state
        self.traj_end_ns = None
        self.torque_setpoint = 0.0
        if state is cs.AxisState.CLOSED_LOOP_CONTROL:
            # input_pos = pos_estimate: stop where we are.
            self.segments = prof.ramp(now, p, v, 0.0, self.traj_accel_limit * 4)
        else:
            self.segments = prof.ramp(now, p, v, 0.0, 2.0)  # coast down under friction

    def _plan(self, msg: cs.CanSimpleMessage) -> None:
        now = self.now()
        p, v, _ = self.state_at(now)
        if self.axis_state is not cs.AxisState.CLOSED_LOOP_CONTROL:
            return  # inputs are latched by a real ODrive but do nothing while IDLE
        mode = self.control_mode
        if isinstance(msg, cs.SetInputPos) and mode is cs.ControlMode.POSITION:
            if self.input_mode is cs.InputMode.TRAP_TRAJ:
                self.segments = prof.trapezoid(
                    now, p, v, msg.pos, self.traj_vel_limit, self.traj_accel_limit
                )
                end = prof.end_time(self.segments)
                self.traj_end_ns = end if end > now else None
            else:  # the position loop tracks a step: a stiff trapezoid
                self.segments = prof.trapezoid(now, p, v, msg.pos, self.vel_limit, 50.0)
        elif isinstance(msg, cs.SetInputVel) and mode is cs.ControlMode.VELOCITY:
            target = max(-self.vel_limit, min(self.vel_limit, msg.vel))
            rate = self.vel_ramp_rate if self.input_mode is cs.InputMode.VEL_RAMP else 50.0
            self.segments = prof.ramp(now, p, v, target, rate)
        elif isinstance(msg, cs.SetInputTorque) and mode is cs.ControlMode.TORQUE:
            self.torque_setpoint = msg.torque
            self.torque_since_ns = now
            accel = msg.torque / (self.inertia * math.tau)
            self.segments = prof.accelerate(now, p, v, accel, self.vel_limit)

    def _update_thermal(self, now: int) -> None:
        dt = (now - self._thermal_ns) * NS
        if dt <= 0:
            return
        self._thermal_ns = now
        current = self.torque_at(now) / self.torque_constant
        power = 1.5 * current * current * self.phase_resistance
        decay = math.exp(-dt / self.thermal_time_constant)
        for name, gain in (("motor_temp", 1.0), ("fet_temp", 0.5)):
            steady = AMBIENT_C + gain * power * self.thermal_resistance
            value = getattr(self, name)
            setattr(self, name, steady + (value - steady) * decay)

    # -- messages ---------------------------------------------------------------------------
    def reply(self, cmd: cs.CmdId) -> cs.CanSimpleMessage | None:
        """The message this node sends for ``cmd`` now."""
        now = self.now()
        node = self.node_id
        p, v, _ = self.state_at(now)
        if cmd is cs.CmdId.HEARTBEAT:
            return cs.Heartbeat(
                node,
                self.active_errors | self.disarm_reason,
                self.axis_state,
                int(self.procedure_result),
                self.trajectory_done(now),
            )
        if cmd is cs.CmdId.GET_ENCODER_ESTIMATES:
            return cs.EncoderEstimates(node, p, v)
        if cmd is cs.CmdId.GET_ERROR:
            return cs.ErrorStatus(node, self.active_errors, self.disarm_reason)
        torque = self.torque_at(now)
        current = torque / self.torque_constant
        if cmd is cs.CmdId.GET_TORQUES:
            target = self.torque_setpoint if self.control_mode is cs.ControlMode.TORQUE else torque
            return cs.Torques(node, target, torque)
        if cmd is cs.CmdId.GET_IQ:
            return cs.Iq(node, current, current)
        if cmd is cs.CmdId.GET_TEMPERATURE:
            self._update_thermal(now)
            return cs.Temperature(node, self.fet_temp, self.motor_temp)
        mechanical = torque * v * math.tau
        electrical = mechanical + 1.5 * current * current * self.phase_resistance + 0.5
        bus_current = electrical / self.nominal_bus_voltage
        if cmd is cs.CmdId.GET_BUS_VOLTAGE_CURRENT:
            return cs.BusVoltageCurrent(
                node, self.nominal_bus_voltage - 0.05 * bus_current, bus_current
            )
        if cmd is cs.CmdId.GET_POWERS:
            return cs.Powers(node, electrical, mechanical)
        if cmd is cs.CmdId.GET_VERSION:
            return self.firmware.message(node)
        if cmd is cs.CmdId.ADDRESS:  # to a broadcast request: who is on the bus
            return cs.Address(node, node, self.serial_number)
        return None

    def _sdo_read(self, endpoint: int) -> cs.TxSdo | None:
        """The TxSdo answering a read of ``endpoint`` (None: an endpoint not simulated)."""
        if endpoint == self.vel_ramp_rate_endpoint:
            value = struct.pack("<f", self.vel_ramp_rate)
        elif endpoint == self.watchdog_timeout_endpoint:
            value = struct.pack("<f", self.watchdog_timeout)
        elif endpoint == self.enable_watchdog_endpoint:
            value = bytes((int(self.enable_watchdog), 0, 0, 0))
        elif endpoint in self._endpoint_names:
            value = self.endpoint_values.get(endpoint) or self._endpoint_value(endpoint)
        else:
            return None
        return cs.TxSdo(self.node_id, endpoint, value)

    def _endpoint_value(self, endpoint: int) -> bytes:
        """An endpoint never written: the simulation's own value where it has one, else 0."""
        name = self._endpoint_names[endpoint]
        floats = {
            "vbus_voltage": self.nominal_bus_voltage,
            "axis0.controller.config.vel_limit": self.vel_limit,
            "axis0.trap_traj.config.vel_limit": self.traj_vel_limit,
            "axis0.trap_traj.config.accel_limit": self.traj_accel_limit,
            "axis0.trap_traj.config.decel_limit": self.traj_accel_limit,
            "axis0.config.motor.torque_constant": self.torque_constant,
            "axis0.config.motor.phase_resistance": self.phase_resistance,
            "axis0.motor.motor_thermistor.temperature": self.motor_temp,
            "axis0.motor.fet_thermistor.temperature": self.fet_temp,
        }
        if name in floats:
            return struct.pack("<f", floats[name])
        ints = {
            "fw_version_major": self.firmware.fw[0],
            "fw_version_minor": self.firmware.fw[1],
            "fw_version_revision": self.firmware.fw[2],
            "fw_version_unreleased": self.firmware.unreleased,
            "hw_version_major": self.firmware.hw[0],
            "hw_version_minor": self.firmware.hw[1],
            "hw_version_variant": self.firmware.hw[2],
            "axis0.config.can.node_id": self.node_id,
            "axis0.config.can.heartbeat_msg_rate_ms": round(self.heartbeat_period * 1000),
            "axis0.config.can.encoder_msg_rate_ms": round(self.encoder_period * 1000),
            "axis0.current_state": int(self.axis_state),
            "axis0.controller.config.control_mode": int(self.control_mode),
            "axis0.controller.config.input_mode": int(self.input_mode),
            "axis0.active_errors": self.active_errors,
            "axis0.disarm_reason": self.disarm_reason,
        }
        return struct.pack("<I", ints.get(name, 0) & 0xFFFF_FFFF)

    async def _send(self, msg: cs.CanSimpleMessage | None) -> None:
        if msg is None or self.silent or self._port is None:
            return
        arb_id, data = cs.encode(msg)
        try:
            await self._port.send(arb_id, data)
        except Exception as exc:  # the peer's own bus failing is not the host's problem
            self.log.debug("sim_send_failed", error=repr(exc))

    def _apply(self, msg: cs.CanSimpleMessage) -> None:
        self.commands.append(msg)
        if isinstance(msg, cs.SetAxisState):
            if msg.state is cs.AxisState.CLOSED_LOOP_CONTROL and self.disarm_reason:
                self.procedure_result = cs.ProcedureResult.DISARMED
                return  # refused: errors must be cleared first
            if msg.state is cs.AxisState.CLOSED_LOOP_CONTROL or msg.state is cs.AxisState.IDLE:
                self.procedure_result = cs.ProcedureResult.SUCCESS
                self._set_state(msg.state)
        elif isinstance(msg, cs.SetControllerMode):
            control, inputs = msg.control_mode, msg.input_mode
            if not (isinstance(control, cs.ControlMode) and isinstance(inputs, cs.InputMode)):
                return  # a mode this simulation does not know: ignored
            self.control_mode, self.input_mode = control, inputs
            if self.axis_state is cs.AxisState.CLOSED_LOOP_CONTROL:
                self._set_state(cs.AxisState.CLOSED_LOOP_CONTROL)  # new mode: hold here
        elif isinstance(msg, cs.SetInputPos | cs.SetInputVel | cs.SetInputTorque):
            self._plan(msg)
        elif isinstance(msg, cs.RxSdo):
            if msg.opcode is not cs.SdoOpcode.WRITE:
                return
            if msg.endpoint_id == self.vel_ramp_rate_endpoint:
                (rate,) = struct.unpack("<f", msg.value)
                if math.isfinite(rate) and rate >= 0.0:
                    self.vel_ramp_rate = rate
            elif msg.endpoint_id == self.watchdog_timeout_endpoint:
                (timeout,) = struct.unpack("<f", msg.value)
                if math.isfinite(timeout) and timeout >= 0.0:
                    self.watchdog_timeout = timeout
            elif msg.endpoint_id == self.enable_watchdog_endpoint:
                self.enable_watchdog = msg.value[0] != 0  # a bool endpoint: the first byte
            elif msg.endpoint_id in self._endpoint_names:
                self.endpoint_values[msg.endpoint_id] = bytes(msg.value)
        elif isinstance(msg, cs.Estop):
            self.inject_error(ODriveError.ESTOP_REQUESTED)
        elif isinstance(msg, cs.ClearErrors):
            self.active_errors = self.disarm_reason = 0
            self.procedure_result = cs.ProcedureResult.SUCCESS
        elif isinstance(msg, cs.SetLimits):
            # The firmware overwrites both limits with whatever it receives.
            self.current_limit = msg.current_limit
            self.vel_limit = (
                msg.velocity_limit if math.isfinite(msg.velocity_limit) else self.vel_limit
            )
        elif isinstance(msg, cs.SetTrajVelLimit):
            self.traj_vel_limit = msg.vel_limit
        elif isinstance(msg, cs.SetTrajAccelLimits):
            self.traj_accel_limit = msg.accel_limit
        elif isinstance(msg, cs.SetAbsolutePosition):
            now = self.now()
            self.segments = prof.hold(now, msg.position)
        elif isinstance(msg, cs.Reboot):
            self.active_errors = self.disarm_reason = 0
            self._set_state(cs.AxisState.IDLE)

    async def _receive(self, port: NodePort) -> None:
        async for batch in port:
            if self.silent:
                continue
            for frame in batch:
                self.watchdog_feed()  # do_command feeds on every frame for this node
                try:
                    msg = cs.decode(
                        frame.arbitration_id,
                        frame.data,
                        from_host=True,
                        remote=frame.is_remote_frame,
                    )
                except DecodeError:
                    self.malformed += 1
                    continue
                if isinstance(msg, cs.Request):
                    await self._send(self.reply(msg.cmd_id))
                elif isinstance(msg, cs.RxSdo) and msg.opcode is cs.SdoOpcode.READ:
                    self.commands.append(msg)
                    await self._send(self._sdo_read(msg.endpoint_id))
                else:
                    self._apply(msg)

    async def _cyclic(self) -> None:
        clock = self.clock
        next_hb = next_enc = clock.now_ns()
        hb_ns = round(self.heartbeat_period * 1e9)
        enc_ns = round(self.encoder_period * 1e9)
        while True:
            now = clock.now_ns()
            if self.fault_requested is not None:
                self.log.warning("sim_fault_injected", reason=self.fault_requested)
                self.fault_requested = None
                self.inject_error(ODriveError.MOTOR_OVER_TEMP)
            if now >= next_hb:
                next_hb = max(next_hb + hb_ns, now)
                await self._send(self.reply(cs.CmdId.HEARTBEAT))
            if now >= next_enc:
                next_enc = max(next_enc + enc_ns, now)
                await self._send(self.reply(cs.CmdId.GET_ENCODER_ESTIMATES))
                self._update_thermal(now)
            await clock.sleep_until(min(next_hb, next_enc))


def _firmware_of(table: EndpointTable) -> FirmwareVersion:
    """The version an axis whose ids are ``table``'s reports: the file's ``fw_version`` and
    ``hw_version``; the simulation's own for the built-in table."""
    if table.fw_version is None or table.hw_version is None:
        return SIMULATED_FIRMWARE
    fw = tuple(int(n) for n in table.fw_version.partition("-")[0].split("."))
    hw = tuple(int(n) for n in table.hw_version.partition("-")[0].split("."))
    return FirmwareVersion((fw[0], fw[1], fw[2]), (hw[0], hw[1], hw[2]))


def frame_of(msg: cs.CanSimpleMessage) -> can.Message:
    """A python-can frame carrying ``msg`` (remote for a Request)."""
    arb_id, data = cs.encode(msg)
    return can.Message(
        arbitration_id=arb_id,
        data=data,
        is_extended_id=False,
        is_remote_frame=isinstance(msg, cs.Request),
    )
