"""A simulated CiA 402 servo drive on CANopen (CiA 301), on a python-can bus.

The peer (:meth:`SimCia402Drive.serve` on its own python-can bus, or :meth:`run` on a
given :class:`~openel_can.bus.CanBus`) implements:

* **NMT**: boot-up message, then Pre-operational; start/stop/pre-operational, reset
  node (every object back to its default) and reset communication (0x1000-0x1FFF).
  Heartbeat producer every 0x1017 ms (default 1000 ms; 0 disables it).
* **Object dictionary** from an EDS file (``eds=``, default the shipped
  :data:`~openel_can.od.SHIPPED_EDS`): data types, access rights, PDO mappability and
  defaults are the file's (:mod:`openel_can.sim.objects`, which also names the model
  parameters that override a few defaults); ``object_dictionary`` is the parsed file.
* **SDO server** over that dictionary, with CiA 301 abort codes:
  object/sub-index does not exist, read-only, write-only, length mismatch, value
  range, PDO mapping rules (mapping and COB-ID may change only while the PDO is
  invalid, bit 31; only objects the file marks PDO-mappable, writable ones in RPDOs
  and readable ones in TPDOs as its access type says; at most 64 bits). Objects
  that are not integers (strings, domains) are served as their bytes. Expedited transfers (a
  download without size indication writes the object's own size) and segmented upload
  and download (one transfer at a time; toggle bit and length checked; a new initiate or
  a client abort ends the transfer in progress). Block transfers, unknown command
  specifiers and segments outside a transfer are aborted with 0x05040001.
  :data:`OPERATING_TIME` and :data:`ENERGY_LIMIT` are 64-bit objects (segmented).
* **PDOs**: RPDO1-4 and TPDO1-4 with configurable COB-ID, mapping and transmission
  type. RPDOs act on reception (a too-short RPDO raises EMCY 0x8210). TPDO types
  0xFE/0xFF are event-driven: sent when a discrete mapped object changes (statusword,
  mode display, error code) and every event timer (0x18xx:5) period, never closer than
  the inhibit time (0x18xx:3, 100 µs units); types 1..240 are sent on every n-th SYNC,
  type 0 on SYNC after a change.
* **CiA 402**: the power state machine (:func:`openel_can.cia402.apply_controlword`
  plus the automatic transitions: Not ready -> Switch on disabled at boot, quick stop
  and fault reaction ramps), modes 0x6060 profile position (new set-point bit 4 /
  set-point acknowledge bit 12, change set immediately bit 5 or a one-slot buffer,
  halt bit 8), profile velocity and profile torque (torque slope 0x6087), and
  statusword bit 10 (target reached); the cyclic synchronous modes CSP (8), CSV (9) and
  CST (10): at each SYNC the drive latches the target received before it (0x607A, 0x60FF,
  0x6071) and follows it over the interpolation time period 0x60C2 (sub1 x 10^sub2 s):
  CSP linearly in position, CSV linearly in velocity, CST the torque at once; without
  SYNC it keeps the last target. Statusword bit 12 in those modes: the drive follows the
  command value (Operation enabled, no halt).
* **EMCY** on faults (error code 0x603F, error register 0x1001) and 0x0000 on fault
  reset; :meth:`warn` sends an EMCY without faulting.
* **Heartbeat consumer** (CiA 301 0x1016, one entry: sub 1 = producer node id << 16 |
  time in ms, 0 disables): monitoring starts with the first heartbeat of that node after the
  entry is written; when none comes within the time (on the peer's own clock) the drive
  sends EMCY 0x8130 (heartbeat error, error register bit communication) and, in Operation
  enabled, applies the **abort connection option code** 0x6007 (CiA 402): 0 no action,
  1 fault signal (Fault reaction active, then Fault), 2 disable voltage (Switch on disabled,
  the shaft coasts), 3 quick stop (Quick stop active, then as 0x605A says). Monitoring then
  waits for the next heartbeat. 0x1029 (error behaviour) is not simulated: the NMT state
  does not change on a heartbeat error. ``heartbeat_errors`` counts the events.

Units: positions in increments (0x608F: ``counts_per_rev`` increments per motor
revolution), velocities in increments/s, accelerations in increments/s², torques in
per mille of the rated torque 0x6076 (mNm); the drive temperature is the
manufacturer-specific object 0x2022 in 0.1 °C.

Fault injection: :meth:`trip` (fault with an EMCY code), :meth:`warn`,
:meth:`set_silent` (no transmit/receive: heartbeat loss), ``sdo_silent`` (SDO
requests unanswered: SDO timeouts), :meth:`reboot` (reset node), and
``setpoint_ack_delay`` (set-points latched and acknowledged that much later, like a
drive with a slow cycle). ``received_controlwords`` and ``emcy_sent`` keep the newest
``history`` items (:class:`~openel_can.sim.history.History`, ``discarded`` counts the
rest; logged when the peer stops).

The SDO server is :class:`~openel_can.sim.sdo_server.SdoServer`, the CiA 402 state machine
and motion :class:`~openel_can.sim.cia402_motion.Cia402Motion`: base classes of
:class:`SimCia402Drive`.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Final

import anyio
import anyio.abc
import can

from openel_async.clock import Clock, default_clock
from openel_async.logs import get_logger
from openel_sim import profile as prof

from .. import canopen as co
from .. import cia402 as ds
from ..bus import CanBus, NodePort
from ..errors import DecodeError
from .cia402_motion import CYCLIC_MODES, NS, SUPPORTED_MODES, TORQUE_MODES, Cia402Motion
from .history import DEFAULT_HISTORY, History
from .objects import SimObject, build_dictionary, load_sim_od
from .sdo_server import SdoServer, Transfer

__all__ = ["DRIVE_TEMPERATURE", "ENERGY_LIMIT", "OPERATING_TIME", "SimCia402Drive"]

log = get_logger(__name__)

DT = co.DataType
PS = ds.PowerState
Mode = ds.ModeOfOperation
DRIVE_TEMPERATURE: Final = co.ObjectEntry(0x2022, 0, DT.INTEGER16)
"""Manufacturer-specific: drive (power stage) temperature in 0.1 °C."""
TORQUE_SLOPE: Final = co.ObjectEntry(0x6087, 0, DT.UNSIGNED32)
OPERATING_TIME: Final = co.ObjectEntry(0x2030, 0, DT.UNSIGNED64)
"""Manufacturer-specific, read-only 64-bit: microseconds since the last reset node
(read by segmented SDO upload)."""
ENERGY_LIMIT: Final = co.ObjectEntry(0x2031, 0, DT.INTEGER64)
"""Manufacturer-specific, read-write 64-bit parameter in mJ (written by segmented SDO
download; only stored)."""
_DISCRETE: Final = frozenset({0x6041, 0x6061, 0x603F, 0x1001})
_AMBIENT_C: Final = 25.0


@dataclass
class _TpdoState:
    last_sent_ns: int | None = None
    last_key: tuple[int, ...] | None = None
    sync_count: int = 0
    sync_due: bool = False


class SimCia402Drive(Cia402Motion, SdoServer):
    """One simulated CiA 402 drive; see the module docstring."""

    def __init__(
        self,
        node_id: int = 1,
        *,
        counts_per_rev: int = 10_000,
        rated_torque: float = 1.0,
        inertia: float = 0.0005,
        heartbeat_ms: int = 1000,
        fault_reaction_s: float = 0.005,
        setpoint_ack_delay: float = 0.0,
        history: int = DEFAULT_HISTORY,
        clock: Clock | None = None,
        eds: str | os.PathLike[str] | None = None,
    ) -> None:
        if not 1 <= node_id <= co.MAX_NODE_ID:
            raise ValueError(f"node_id {node_id} outside 1..{co.MAX_NODE_ID}")
        self.node_id = node_id
        self.object_dictionary = load_sim_od(eds, node_id)
        """The EDS the objects come from (default :data:`~openel_can.od.SHIPPED_EDS`)."""
        self.counts_per_rev = counts_per_rev
        self.rated_torque = rated_torque  # Nm
        self.inertia = inertia  # kg m^2
        self.default_heartbeat_ms = heartbeat_ms
        self.fault_reaction_s = fault_reaction_s
        self.setpoint_ack_delay = setpoint_ack_delay
        """Seconds from a new set-point edge to its acknowledge (a drive's cycle time)."""
        self.setpoint_due_ns: int | None = None
        self.setpoint_immediate = False
        self.clock: Clock = clock or default_clock()
        self.silent = False
        self.sdo_silent = False
        self.malformed = 0
        self.received_controlwords: History[int] = History(history)
        """The newest controlwords written, in order (``.discarded``: older ones)."""
        self.emcy_sent: History[co.Emergency] = History(history)
        self._port: NodePort | None = None
        self._scope: anyio.CancelScope | None = None
        self.fault_requested: str | None = None
        """A fault asked for by :meth:`inject_fault`, not yet applied."""
        self._kicked = False
        self.od: dict[tuple[int, int], SimObject] = {}
        self._mappings: dict[int, tuple[co.PdoMapEntry, ...]] = {}
        self._transfer: Transfer | None = None
        self.segments = prof.hold(self.clock.now_ns(), 0.0)
        self.consumer_heard_ns: int | None = None
        """When the consumed heartbeat (0x1016:1) was last received (None: not monitoring)."""
        self.heartbeat_errors = 0
        self.syncs = 0
        self.sync_counters: History[int | None] = History(history)
        """The counter of each SYNC received in Operational (None: a SYNC without one)."""
        """SYNC messages received in Operational."""
        self._boot()
        self.log = log.bind(sim_cia402=node_id)

    # -- boot and state ---------------------------------------------------------------------
    def _boot(self, *, communication_only: bool = False) -> None:
        self._mappings.clear()
        fresh = self._fresh_objects()
        if communication_only:
            for key, obj in fresh.items():
                if 0x1000 <= key[0] <= 0x1FFF and key[0] not in (0x1001,):
                    self.od[key] = obj
        else:
            self.od = fresh
            now = self.clock.now_ns()
            self.power_state = PS.NOT_READY_TO_SWITCH_ON
            self.segments = prof.hold(now, self._p(now))  # the shaft stays where it is
            self.pp_target = 0
            self.pp_buffered: int | None = None
            self.setpoint_ack = False
            self.setpoint_due_ns = None
            self.halted = False
            self.arrival_ns: int | None = None
            self.stop_until_ns: int | None = None
            self.target_reached = True
            self.torque_target = 0.0  # per mille
            self.cyclic_target = 0
            """The target latched at the last SYNC in a cyclic mode (increments, increments/s
            or per mille)."""
            self.torque_from = 0.0
            self.torque_since_ns = now
            self.fault_reaction_end_ns: int | None = None
            self.temperature = _AMBIENT_C
            self._thermal_ns = now
            self._booted_ns = now
        self.nmt_state = co.NmtState.BOOT_UP
        self.prev_controlword = 0
        self.tpdo_state = [_TpdoState() for _ in range(4)]
        self._transfer = None
        self.next_heartbeat_ns = self.clock.now_ns()
        self.pending: list[co.CanOpenMessage] = [co.Heartbeat(self.node_id, co.NmtState.BOOT_UP)]
        self.consumer_heard_ns = None

    def _fresh_objects(self) -> dict[tuple[int, int], SimObject]:
        """Every object at its default, from the EDS (see :mod:`openel_can.sim.objects`)."""
        return build_dictionary(
            self.object_dictionary,
            node_id=self.node_id,
            counts_per_rev=self.counts_per_rev,
            rated_torque_mnm=round(self.rated_torque * 1000),
            heartbeat_ms=self.default_heartbeat_ms,
            supported_modes=SUPPORTED_MODES,
        )

    def _get(self, index: int, sub: int = 0) -> int:
        return self.od[(index, sub)].value

    def _set(self, index: int, sub: int, value: int) -> None:
        self.od[(index, sub)].value = value

    @property
    def mode(self) -> int:
        return self._get(0x6061)

    def _p(self, now: int) -> float:
        return prof.evaluate(self.segments, now)[0]

    def state_at(self, now: int) -> tuple[float, float, float]:
        """(position increments, velocity increments/s, acceleration increments/s²)."""
        return prof.evaluate(self.segments, now)

    @property
    def position(self) -> float:
        """Actual position in increments."""
        return self._p(self.clock.now_ns())

    def statusword(self) -> int:
        state = self.power_state
        enabled = state in (
            PS.READY_TO_SWITCH_ON,
            PS.SWITCHED_ON,
            PS.OPERATION_ENABLED,
            PS.QUICK_STOP_ACTIVE,
        )
        word = ds.Statusword.build(
            state,
            voltage_enabled=enabled or state is PS.FAULT_REACTION_ACTIVE,
            target_reached=self.target_reached,
            setpoint_acknowledge=(
                self.setpoint_ack
                if self.mode == Mode.PROFILE_POSITION
                # cyclic modes: bit 12 "drive follows the command value"
                else self.mode in CYCLIC_MODES and state is PS.OPERATION_ENABLED and not self.halted
            ),
        ).raw
        if state is PS.QUICK_STOP_ACTIVE:
            return word  # bit 5 (quick stop) low
        if state in (PS.READY_TO_SWITCH_ON, PS.SWITCHED_ON, PS.OPERATION_ENABLED):
            word |= ds.StatusBit.QUICK_STOP
        return word

    def _counts_per_rad(self) -> float:
        return self.counts_per_rev / math.tau

    def torque_permille(self, now: int) -> float:
        if self.power_state is not PS.OPERATION_ENABLED and self.power_state not in (
            PS.QUICK_STOP_ACTIVE,
            PS.FAULT_REACTION_ACTIVE,
        ):
            return 0.0
        _, v, a = self.state_at(now)
        if self.mode in TORQUE_MODES and self.power_state is PS.OPERATION_ENABLED:
            if abs(v) >= self._get(0x6080) - 1e-6 and a == 0:
                return 0.0
            return self._torque_ramp(now)
        torque_nm = self.inertia * a / self._counts_per_rad()
        return torque_nm / self.rated_torque * 1000

    def _torque_ramp(self, now: int) -> float:
        slope = max(1, self._get(0x6087))  # per mille per second
        elapsed = (now - self.torque_since_ns) * NS
        span = self.torque_target - self.torque_from
        if abs(span) <= slope * elapsed:
            return self.torque_target
        return self.torque_from + math.copysign(slope * elapsed, span)

    def _refresh_actuals(self, now: int) -> None:
        p, v, _ = self.state_at(now)
        self._set(0x6064, 0, max(-(2**31), min(2**31 - 1, round(p))))
        self._set(0x606C, 0, max(-(2**31), min(2**31 - 1, round(v))))
        self._set(0x6077, 0, max(-32768, min(32767, round(self.torque_permille(now)))))
        self._update_thermal(now)
        self._set(0x6041, 0, self.statusword())
        self._set(0x2030, 0, max(0, now - self._booted_ns) // 1000)

    def _update_thermal(self, now: int) -> None:
        dt = (now - self._thermal_ns) * NS
        if dt <= 0:
            return
        self._thermal_ns = now
        load = self.torque_permille(now) / 1000
        steady = _AMBIENT_C + 30.0 * load * load
        self.temperature = steady + (self.temperature - steady) * math.exp(-dt / 20.0)
        self._set(0x2022, 0, round(self.temperature * 10))

    # -- fault injection --------------------------------------------------------------------
    def trip(
        self,
        code: int = co.EmcyCode.CONTINUOUS_OVER_CURRENT,
        register: int = co.ErrorRegister.GENERIC | co.ErrorRegister.CURRENT,
    ) -> None:
        """The drive faults: Fault reaction active (quick-stop ramp), EMCY, then Fault."""
        now = self.clock.now_ns()
        if self.power_state in (PS.FAULT, PS.FAULT_REACTION_ACTIVE):
            return
        self.power_state = PS.FAULT_REACTION_ACTIVE
        self._set(0x603F, 0, code)
        self._set(0x1001, 0, self._get(0x1001) | register | co.ErrorRegister.GENERIC)
        self._stop(now, self._get(0x6085))
        self.fault_reaction_end_ns = now + round(self.fault_reaction_s * 1e9)
        self._emcy(code)
        self._kick()

    def warn(
        self,
        code: int = co.EmcyCode.DEVICE_OVER_TEMPERATURE,
        register: int = co.ErrorRegister.TEMPERATURE,
    ) -> None:
        """An EMCY without a fault (e.g. a temperature warning)."""
        self._emcy(code, register)
        self._kick()

    def inject_fault(self, reason: str) -> None:
        """Trip on over-temperature (EMCY 0x4210, then Fault; ``openel_async.rig.
        FaultInjection``), from any thread: the request is applied by the peer's own loop."""
        self.fault_requested = reason
        if self._scope is not None:  # wake the loop (a cancel is a flag: safe off-thread)
            self._scope.cancel()

    def set_silent(self, silent: bool = True) -> None:
        """Stop (or resume) transmitting and receiving: a node cut off the bus."""
        self.silent = silent
        self._kick()

    def reboot(self) -> None:
        """Reset node: every object back to its default, boot-up, Pre-operational."""
        self._boot()
        self._kick()

    def _emcy(self, code: int, register: int | None = None) -> None:
        reg = self._get(0x1001) if register is None else register
        self.pending.append(co.Emergency(self.node_id, code, reg))

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
            name=f"sim-cia402-{self.node_id}",
            poll_interval=0.02,
        ) as bus:
            await self.run(bus, task_status=task_status)

    async def run(
        self, bus: CanBus, *, task_status: anyio.abc.TaskStatus[None] = anyio.TASK_STATUS_IGNORED
    ) -> None:
        n = self.node_id
        ids = [
            co.NMT_COB_ID,
            co.SYNC_COB_ID,
            co.SDO_RX_BASE + n,
            *(base + n for base in co.RPDO_BASES),
            *(co.HEARTBEAT_BASE + node for node in range(1, co.MAX_NODE_ID + 1) if node != n),
        ]
        port = self._port = bus.attach(ids, name=f"sim-cia402-{n}", queue_size=256)
        try:
            async with anyio.create_task_group() as tg:
                tg.start_soon(self._receive, port)
                tg.start_soon(self._loop)
                task_status.started()
        finally:
            port.close()
            self.log.info(
                "sim_stopped",
                controlwords=self.received_controlwords.total,
                controlwords_discarded=self.received_controlwords.discarded,
                emcy=self.emcy_sent.total,
                emcy_discarded=self.emcy_sent.discarded,
                malformed=self.malformed,
            )

    def _kick(self) -> None:
        self._kicked = True
        if self._scope is not None:
            self._scope.cancel()

    async def _send(self, msg: co.CanOpenMessage) -> None:
        if self.silent or self._port is None:
            return
        cob_id, data = co.encode(msg)
        try:
            await self._port.send(cob_id, data)
        except Exception as exc:
            self.log.debug("sim_send_failed", error=repr(exc))

    async def _loop(self) -> None:
        clock = self.clock
        while True:
            now = clock.now_ns()
            self._kicked = False
            if self.fault_requested is not None:
                self.log.warning("sim_fault_injected", reason=self.fault_requested)
                self.fault_requested = None
                self.trip(co.EmcyCode.DEVICE_OVER_TEMPERATURE, co.ErrorRegister.TEMPERATURE)
            self._advance(now)
            pending, self.pending = self.pending, []
            for msg in pending:
                if isinstance(msg, co.Emergency):
                    self.emcy_sent.append(msg)
                await self._send(msg)
            if self.nmt_state is co.NmtState.BOOT_UP:
                self.nmt_state = co.NmtState.PRE_OPERATIONAL
                self.next_heartbeat_ns = now
                if self.power_state is PS.NOT_READY_TO_SWITCH_ON:
                    self.power_state = PS.SWITCH_ON_DISABLED
                continue
            due = await self._transmit(now)
            if self._kicked:
                continue
            with anyio.CancelScope() as scope:
                self._scope = scope
                await clock.sleep_until(due)
            self._scope = None

    def _consumer_deadline(self) -> int | None:
        entry = self._get(0x1016, 1)
        time_ms = entry & 0xFFFF
        if not time_ms or self.consumer_heard_ns is None:
            return None
        return self.consumer_heard_ns + time_ms * 1_000_000

    def _heartbeat_error(self, now: int) -> None:
        """The consumer timed out: EMCY 0x8130, then the abort connection option 0x6007."""
        self.consumer_heard_ns = None  # monitoring resumes with the next heartbeat
        self.heartbeat_errors += 1
        self.log.info("sim_heartbeat_consumer_timeout", option=self._get(0x6007))
        option = self._get(0x6007)
        if self.power_state is PS.OPERATION_ENABLED and option == 1:
            self.trip(co.EmcyCode.LIFE_GUARD_OR_HEARTBEAT, co.ErrorRegister.COMMUNICATION)
            return
        self._set(0x1001, 0, self._get(0x1001) | co.ErrorRegister.COMMUNICATION)
        self._emcy(co.EmcyCode.LIFE_GUARD_OR_HEARTBEAT)
        if self.power_state is not PS.OPERATION_ENABLED:
            return
        if option == 2:
            self.power_state = PS.SWITCH_ON_DISABLED
            p, v, _ = self.state_at(now)
            self.segments = prof.ramp(now, p, v, 0.0, 2.0 * self.counts_per_rev)  # coasting
            self.arrival_ns = self.setpoint_due_ns = None
            self.setpoint_ack = False
        elif option == 3:
            self.power_state = PS.QUICK_STOP_ACTIVE
            self.setpoint_ack = False
            self._stop(now, self._get(0x6085))

    def _advance(self, now: int) -> None:
        """Automatic transitions and events that are due."""
        consumer_due = self._consumer_deadline()
        if consumer_due is not None and now > consumer_due:
            self._heartbeat_error(now)
        if self.setpoint_due_ns is not None and now >= self.setpoint_due_ns:
            self._accept_setpoint(now)
        if self.fault_reaction_end_ns is not None and now >= self.fault_reaction_end_ns:
            self.fault_reaction_end_ns = None
            self.power_state = PS.FAULT
            self.setpoint_ack = False
        if self.stop_until_ns is not None and now >= self.stop_until_ns:
            self.stop_until_ns = None
            if self.power_state is PS.QUICK_STOP_ACTIVE and self._get(0x605A) in (1, 2, 3, 4):
                self.power_state = PS.SWITCH_ON_DISABLED
            self.target_reached = True
        if self.arrival_ns is not None and now >= self.arrival_ns:
            self.arrival_ns = None
            if self.pp_buffered is not None and self.mode == Mode.PROFILE_POSITION:
                target, self.pp_buffered = self.pp_buffered, None
                self._plan_position(now, target)
            else:
                self.target_reached = True
        self._refresh_actuals(now)

    async def _transmit(self, now: int) -> int:
        """Send what is due (heartbeat, TPDOs); return the next due time."""
        due = now + 1_000_000_000
        heartbeat_ms = self._get(0x1017)
        if heartbeat_ms:
            if now >= self.next_heartbeat_ns:
                self.next_heartbeat_ns = max(self.next_heartbeat_ns + heartbeat_ms * 1_000_000, now)
                await self._send(co.Heartbeat(self.node_id, self.nmt_state))
            due = min(due, self.next_heartbeat_ns)
        for event in (
            self.arrival_ns,
            self.stop_until_ns,
            self.fault_reaction_end_ns,
            self.setpoint_due_ns,
            None if (c := self._consumer_deadline()) is None else c + 1,
        ):
            if event is not None:
                due = min(due, event)
        if self.power_state is PS.OPERATION_ENABLED and self.mode == Mode.PROFILE_TORQUE:
            if self._torque_ramp(now) != self.torque_target:
                due = min(due, now + 1_000_000)  # torque slope in progress: 1 ms steps
            elif not self.target_reached:
                self.target_reached = True
                self._set(0x6041, 0, self.statusword())
        if self.nmt_state is not co.NmtState.OPERATIONAL:
            return due
        for n in range(4):
            cob = self._get(0x1800 + n, 1)
            if cob & co.PDO_COB_ID_INVALID:
                continue
            state = self.tpdo_state[n]
            ttype = self._get(0x1800 + n, 2)
            inhibit_ns = self._get(0x1800 + n, 3) * 100_000
            timer_ns = self._get(0x1800 + n, 5) * 1_000_000
            mapping = self._mapping(0x1A00 + n)
            key = tuple(self._get(e.index, e.subindex) for e in mapping if e.index in _DISCRETE)
            send = False
            if ttype in (0xFE, 0xFF):
                send = (
                    key != state.last_key
                    or state.last_sent_ns is None
                    or bool(timer_ns and now - state.last_sent_ns >= timer_ns)
                )
            elif state.sync_due:
                send = ttype != 0 or key != state.last_key
                state.sync_due = False
            if send and inhibit_ns and state.last_sent_ns is not None:
                allowed = state.last_sent_ns + inhibit_ns
                if now < allowed:
                    due = min(due, allowed)
                    send = False
            if send:
                state.last_sent_ns = now
                state.last_key = key
                values = [self._get(e.index, e.subindex) for e in mapping]
                await self._send(co.Pdo(self.node_id, n + 1, True, co.pack_pdo(mapping, values)))
            if ttype in (0xFE, 0xFF) and timer_ns and state.last_sent_ns is not None:
                due = min(due, state.last_sent_ns + timer_ns)
        return due

    def _mapping(self, index: int) -> tuple[co.PdoMapEntry, ...]:
        """The parsed mapping of a PDO (cached; writes to 0x1600-0x1BFF clear the cache)."""
        cached = self._mappings.get(index)
        if cached is None:
            entries = []
            for sub in range(1, self._get(index, 0) + 1):
                raw = self._get(index, sub)
                target = self.od[(raw >> 16, (raw >> 8) & 0xFF)]
                signed = target.data_type is not None and target.data_type.signed
                entries.append(co.PdoMapEntry.from_u32(raw, signed=signed))
            cached = self._mappings[index] = tuple(entries)
        return cached

    # -- receive ----------------------------------------------------------------------------
    async def _receive(self, port: NodePort) -> None:
        async for batch in port:
            if self.silent:
                continue
            for frame in batch:
                try:
                    msg = co.decode(frame.arbitration_id, frame.data)
                except DecodeError:
                    self.malformed += 1
                    continue
                if frame.is_remote_frame:
                    continue
                await self._handle(msg)
            self._kick()

    async def _handle(self, msg: co.CanOpenMessage) -> None:
        now = self.clock.now_ns()
        if isinstance(msg, co.Heartbeat):
            entry = self._get(0x1016, 1)
            if entry & 0xFFFF and msg.node_id == (entry >> 16) & 0x7F:
                self.consumer_heard_ns = now
        elif isinstance(msg, co.NmtControl):
            if msg.node_id in (0, self.node_id):
                self._nmt(msg.command)
        elif isinstance(msg, co.Sync):
            if self.nmt_state is co.NmtState.OPERATIONAL:
                self.syncs += 1
                self.sync_counters.append(msg.counter)
                self._cyclic_sync(now)
                for n, state in enumerate(self.tpdo_state):
                    ttype = self._get(0x1800 + n, 2)
                    if ttype <= 240:
                        state.sync_count += 1
                        if ttype == 0 or state.sync_count % ttype == 0:
                            state.sync_due = True
        elif isinstance(msg, co.SDO_CLIENT_MESSAGES):
            if self.sdo_silent or self.nmt_state is co.NmtState.STOPPED:
                return
            reply = self._sdo_server(msg, now)
            if reply is not None:
                await self._send(reply)
        elif (
            isinstance(msg, co.Pdo)
            and not msg.transmit
            and self.nmt_state is co.NmtState.OPERATIONAL
        ):
            self._rpdo(msg, now)

    def _nmt(self, command: co.NmtCommand | int) -> None:
        if command is co.NmtCommand.START:
            self.nmt_state = co.NmtState.OPERATIONAL
            self.tpdo_state = [_TpdoState() for _ in range(4)]
        elif command is co.NmtCommand.STOP:
            self.nmt_state = co.NmtState.STOPPED
        elif command is co.NmtCommand.ENTER_PRE_OPERATIONAL:
            self.nmt_state = co.NmtState.PRE_OPERATIONAL
        elif command is co.NmtCommand.RESET_NODE:
            self._boot()
        elif command is co.NmtCommand.RESET_COMMUNICATION:
            self._boot(communication_only=True)

    def _rpdo(self, msg: co.Pdo, now: int) -> None:
        n = msg.number - 1
        if n >= len(co.RPDO_BASES) or self._get(0x1400 + n, 1) & co.PDO_COB_ID_INVALID:
            return
        mapping = self._mapping(0x1600 + n)
        try:
            values = co.unpack_pdo(mapping, msg.data)
        except DecodeError:
            self._emcy(
                co.EmcyCode.PDO_LENGTH_ERROR, self._get(0x1001) | co.ErrorRegister.COMMUNICATION
            )
            return
        written = set()
        for entry, value in zip(mapping, values, strict=True):
            self._set(entry.index, entry.subindex, value)
            written.add(entry.index)
        self._after_write(written, now)


def frame_of(msg: co.CanOpenMessage) -> can.Message:
    """A python-can frame carrying ``msg``."""
    cob_id, data = co.encode(msg)
    return can.Message(arbitration_id=cob_id, data=data, is_extended_id=False)
