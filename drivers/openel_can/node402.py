"""The CiA 402 node under :class:`~openel_can.drive402.Cia402Drive`: configuration, the power
state machine, feedback, faults and the heartbeat watchdog (:class:`Cia402Node`).

Opening the drive (``open``): NMT Enter pre-operational, then by expedited SDO the
heartbeat producer time (0x1017), the encoder resolution (0x608F, unless given) and the
rated torque (0x6076, unless given), the PDO mapping (disable, clear, map, count,
enable, as CiA 301 prescribes: :meth:`Cia402Node._map_pdo`; or, for a drive given its
``eds``/``dcf``, its DCF's parameter values first and the maps of
:mod:`openel_can.layout402` through :func:`openel_can.pdomap.configure_pdos`) and the profile parameters,
then NMT Start and the first TPDO. The set-point modes (profile position/velocity/torque in
:mod:`openel_can.drive402`, the cyclic synchronous modes in :mod:`openel_can.cyclic402`) are
subclasses.

The power state machine (:class:`~openel_can.node402_power.PowerStateMachine`, a mixin with
the fixed PDO maps and the controlword RPDOs) runs on the controlword: ``init`` goes shutdown -> switch on ->
enable operation (:func:`openel_can.cia402.next_controlword`, each step confirmed by the
statusword); ``reset`` (``re_init``) reconfigures the node if it rebooted, sends the
fault reset edge (bit 7) and enables again; NO_EXCITE disables operation (Switched on);
:meth:`Cia402Node.quick_stop` sends quick stop.

Faults: one report per fault. An EMCY is posted with the next statusword: when that
statusword shows Fault or Fault reaction active, the ``fault(DEVICE_ERROR)`` it causes is
the report (its reason names the EMCY), else ``post_error(DEVICE_ERROR)`` (a warning; code
0x0000, "error reset", is only logged); a statusword in Fault or Fault reaction active, a
heartbeat in another NMT state than Operational, a boot-up message -> ``fault(DEVICE_ERROR)``; no heartbeat for
``heartbeat_timeout`` -> ``fault(DISCONNECTED)``; SDO timeout -> ``TimeoutError`` (a link
fault: Error, ``ErrorId.TIMEOUT``); SDO abort -> :class:`~openel_can.sdo.SdoAbortError`
(the state does not change); bus failure -> ``fault(BUS_ERROR)``.

Heartbeat watchdog (:class:`~openel_async.safety.Watchdog`): :meth:`Cia402Node.arm_watchdog`
makes the bus produce the host's heartbeat (0x700 + ``host_node_id``, every timeout / 4, a
task of the bus in the event loop: :meth:`~openel_can.bus.CanBus.produce_heartbeat`), then
writes by SDO the abort connection option code 0x6007 = 3 (quick stop) and the drive's
heartbeat consumer 0x1016:1 = ``host_node_id << 16 | timeout in ms`` (4..65535 ms). When
the host's heartbeat stops (the loop stalls, the process dies) the drive raises EMCY 0x8130
and quick-stops; the driver reports that episode as ``fault(WATCHDOG)``.
:meth:`Cia402Node.disarm_watchdog` writes 0x1016:1 = 0, then releases the producer.

Units: positions ``rad = counts * 2π / counts_per_rev``, velocities in counts/s the same
way, torques in per mille of the rated torque (Nm at the API).
"""

from __future__ import annotations

import asyncio
import math
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

import anyio
import can

from openel_async.device import (
    ActuatorDevice,
    ActuatorLimits,
    DeviceContext,
    ErrorId,
)
from openel_async.errors import BadParameterError, HALError
from openel_async.logs import get_logger
from openel_async.requests import Request

from . import canopen as co
from . import cia402 as ds
from .bus import CanBus, NodePort
from .errors import DecodeError
from .layout402 import (
    DriveFiles,
    DriveLayout,
    load_drive_files,
    plan_layout,
)
from .node402_pdos import LayoutPdos
from .node402_power import (
    ENABLE_OPERATION,
    RPDO_CODECS,
    RPDO_MAP_ENTRIES,
    RPDO_MAPS,
    RPDO_OF_MODE,
    TARGET_REACHED,
    TPDO1_CODEC,
    TPDO1_MAP,
    TPDO2_CODEC,
    TPDO2_MAP,
    TPDO_MAPS,
    FaultedError,
    emcy_name,
)
from .node402_safety import (
    CONSUMER_HEARTBEAT_TIME_1,
    QUICK_STOP_ON_ABORT,
    WATCHDOG_FEED_FRACTION,
    NodeSafety,
)
from .node_faults import NodeFaults
from .od import write_parameter_values
from .pdomap import configure_pdos
from .sdo import SdoClient

__all__ = [
    "CIA402_VENDOR_ID",
    "CONSUMER_HEARTBEAT_TIME_1",
    "DEFAULT_HOST_NODE_ID",
    "DRIVE_MODES",
    "ENABLE_OPERATION",
    "QUICK_STOP_ON_ABORT",
    "RPDO_CODECS",
    "RPDO_MAPS",
    "RPDO_OF_MODE",
    "TARGET_REACHED",
    "TPDO1_CODEC",
    "TPDO_MAPS",
    "WATCHDOG_FEED_FRACTION",
    "Cia402Node",
    "FaultedError",
    "Setpoint",
    "check_node",
    "check_positive",
]

log = get_logger(__name__)

PS = ds.PowerState
Mode = ds.ModeOfOperation
SB = ds.StatusBit
CB = ds.ControlBit
CIA402_VENDOR_ID: Final = 0x0402

_PROFILE_REQUESTS: Final = {
    Request.POSITION: Mode.PROFILE_POSITION,
    Request.VELOCITY: Mode.PROFILE_VELOCITY,
    Request.TORQUE: Mode.PROFILE_TORQUE,
}
DRIVE_MODES: Final = ("pp", "csp", "csv", "cst")
"""The ``mode`` parameter: ``pp`` the profile modes (position, velocity, torque as commanded),
``csp``/``csv``/``cst`` cyclic synchronous position/velocity/torque on the bus's SYNC."""
DEFAULT_HOST_NODE_ID: Final = 127
"""The host's CANopen node id for its heartbeat (0x77F): give another one when a drive uses 127."""


def check_node(node_id: int) -> None:
    if (
        isinstance(node_id, bool)
        or not isinstance(node_id, int)
        or not 1 <= node_id <= co.MAX_NODE_ID
    ):
        raise BadParameterError("node_id", node_id, f"a CANopen node id in 1..{co.MAX_NODE_ID}")


def check_positive(name: str, value: float | None, *, optional: bool = True) -> None:
    if value is None and optional:
        return
    if value is None or not (math.isfinite(value) and value > 0):
        raise BadParameterError(name, value, "a finite value > 0")


@dataclass
class Setpoint:
    """A command whose completion (statusword bit 10) is reported once."""

    request: Request
    reported: bool = False


class Cia402Node(LayoutPdos, NodeSafety, NodeFaults, ActuatorDevice):
    """The CiA 402 node a set-point mode subclass drives; see the module docstring."""

    node_label = "CiA 402"

    left_safe: bool = False
    """``safe_stop`` left the device in its exit state: ``close`` leaves it so (set until
    the next ``init``)."""

    def __init__(
        self,
        bus: CanBus,
        node_id: int,
        *,
        counts_per_rev: int | None = None,
        rated_torque: float | None = None,
        limits: ActuatorLimits | None = None,
        profile_velocity: float | None = None,
        profile_acceleration: float | None = None,
        heartbeat_ms: int = 1000,
        heartbeat_timeout: float | None = None,
        tpdo_event_ms: int = 10,
        sync: bool = False,
        sdo_timeout: float = 0.1,
        state_timeout: float = 0.5,
        feedback_max_age: float | None = None,
        host_node_id: int = DEFAULT_HOST_NODE_ID,
        mode: str = "pp",
        eds: str | os.PathLike[str] | None = None,
        dcf: str | os.PathLike[str] | None = None,
        pdos: Any = None,
        files_dir: str | os.PathLike[str] | None = None,
    ) -> None:
        if not isinstance(bus, CanBus):
            raise BadParameterError("bus", bus, "an openel_can.CanBus")
        check_node(node_id)
        if mode not in DRIVE_MODES:
            raise BadParameterError("mode", mode, f"one of {', '.join(DRIVE_MODES)}")
        if (
            isinstance(host_node_id, bool)
            or not isinstance(host_node_id, int)
            or not 1 <= host_node_id <= co.MAX_NODE_ID
            or host_node_id == node_id
        ):
            raise BadParameterError(
                "host_node_id",
                host_node_id,
                f"a CANopen node id in 1..{co.MAX_NODE_ID} other than the drive's ({node_id})",
            )
        if counts_per_rev is not None and (
            isinstance(counts_per_rev, bool)
            or not isinstance(counts_per_rev, int)
            or counts_per_rev < 1
        ):
            raise BadParameterError("counts_per_rev", counts_per_rev, "None or an int >= 1")
        for name, value in (
            ("rated_torque", rated_torque),
            ("profile_velocity", profile_velocity),
            ("profile_acceleration", profile_acceleration),
            ("heartbeat_timeout", heartbeat_timeout),
            ("feedback_max_age", feedback_max_age),
        ):
            check_positive(name, value)
        for name, value in (("sdo_timeout", sdo_timeout), ("state_timeout", state_timeout)):
            check_positive(name, value, optional=False)
        for name, ms in (("heartbeat_ms", heartbeat_ms), ("tpdo_event_ms", tpdo_event_ms)):
            if isinstance(ms, bool) or not isinstance(ms, int) or not 1 <= ms <= 0xFFFF:
                raise BadParameterError(name, ms, "milliseconds in 1..65535")
        self.bus = bus
        self.node_id = node_id
        self.mode = mode
        """``pp`` (profile modes, chosen by each command) or a cyclic synchronous mode."""
        self.counts_per_rev = counts_per_rev
        self.rated_torque = rated_torque
        if limits is not None:
            self.limits = limits
        self.profile_velocity = profile_velocity
        self.profile_acceleration = profile_acceleration
        self.heartbeat_ms = heartbeat_ms
        self.heartbeat_timeout = heartbeat_timeout or 3 * heartbeat_ms / 1000
        self.tpdo_event_ms = tpdo_event_ms
        self.sync = sync
        self.sdo_timeout = sdo_timeout
        self.state_timeout = state_timeout
        self.feedback_max_age = feedback_max_age or max(0.05, 3 * tpdo_event_ms / 1000)
        self.host_node_id = host_node_id
        self.watchdog_timeout: float | None = None
        """The armed heartbeat consumer time in seconds (None: not armed by this driver)."""
        self._heartbeat_error = False
        """EMCY 0x8130 (the drive's consumer missed the host's heartbeat) this episode."""
        self.sdo = SdoClient.for_node(bus, node_id, timeout=sdo_timeout)
        self.files: DriveFiles | None = load_drive_files(
            node_id,
            mode,
            eds=eds,
            dcf=dcf,
            pdos=pdos,
            files_dir=None if files_dir is None else Path(files_dir),
            sync=sync,
            tpdo_event_ms=tpdo_event_ms,
        )
        """The drive's EDS/DCF and PDO maps (None: the fixed maps; :mod:`openel_can.layout402`)."""
        self.layout: DriveLayout | None = None
        """The maps the driver runs with when :attr:`files` are given."""
        if self.files is not None:
            self.layout = plan_layout(self.files, node_id, mode)
            self.sdo.od = self.files.od
            if mode == "pp":
                self.supported_requests = frozenset(
                    {Request.NO_EXCITE}
                    | {r for r, m in _PROFILE_REQUESTS.items() if m in self.layout.rpdo_of_mode}
                )
        self.pdo_values: dict[str, int] = {}
        """TPDO objects the driver does not follow itself, by name (with :attr:`layout`)."""
        self._seen_ns: dict[int, int] = {}
        self._tpdo_plans: dict[int, Any] = {}
        """Per TPDO COB-ID, where it carries the followed objects (node402_pdos)."""
        """When each TPDO object (by index) last arrived (with :attr:`layout`)."""
        self._status_pdo_ns: int | None = None
        """When a statusword last arrived by PDO (with :attr:`layout`)."""
        self._ctx: DeviceContext | None = None
        self._port: NodePort | None = None
        self._lock = anyio.Lock(fast_acquire=True)
        self._changed: anyio.Event | None = None
        """Set (and dropped) after each received batch; created only when awaited."""
        self._status_waiters: list[tuple[Callable[[int], bool], asyncio.Future[bool], float]] = []
        """Statusword waits (predicate, future, deadline in loop time): each future is
        resolved by the batch that satisfies its predicate (True), by a fault latch (True:
        the waiter re-checks), or by the node's status timer at its deadline (False)."""
        self._status_timer: asyncio.TimerHandle | None = None
        self._status_timer_loop: asyncio.AbstractEventLoop | None = None
        self._statusword: int | None = None
        self._position = 0
        self._torque = 0
        self._velocity = 0
        self._mode_display: int | None = None
        self._tpdo1_ns: int | None = None
        self._tpdo2_ns: int | None = None
        self._heartbeat_ns: int | None = None
        self.nmt_state: co.NmtState | int | None = None
        self._mode: Mode | None = None
        self._controlword = 0
        self._targets = dict.fromkeys(RPDO_OF_MODE, 0)
        """The target each mode's RPDO carries with the next controlword."""
        self._pending: Setpoint | None = None
        self._enabled_wanted = False
        self._estop_active = False
        """Set by :meth:`estop`, cleared by ``init``/``re_init``: while set no controlword
        that switches the drive on or enables it is sent (:meth:`_send_rpdo`)."""
        self._engaged = False
        self._latched = False
        self._needs_config = True
        self._saved_profile_accel: tuple[int, int] | None = None
        """(0x6083, 0x6084) before the first tm_acc ramp overwrote them."""
        self._ramp_accel_written = False
        self.last_emcy: co.Emergency | None = None
        self.emcy_count = 0
        self._emcy_unreported = False
        """An EMCY came since the last statusword (reported with the next one)."""
        self.log = log.bind(node=node_id)

    # -- units ----------------------------------------------------------------------------
    def _cpr(self) -> float:
        assert self.counts_per_rev is not None, "encoder resolution not known before open()"
        return float(self.counts_per_rev)

    def counts_to_rad(self, counts: float) -> float:
        return counts * math.tau / self._cpr()

    def rad_to_counts(self, rad: float) -> int:
        return round(rad * self._cpr() / math.tau)

    def _torque_nm(self, permille: float) -> float:
        assert self.rated_torque is not None
        return permille / 1000 * self.rated_torque

    def _torque_permille(self, nm: float) -> int:
        assert self.rated_torque is not None
        return round(nm / self.rated_torque * 1000)

    @property
    def statusword(self) -> int | None:
        """The latest statusword received (TPDO1 or SDO)."""
        return self._statusword

    @property
    def power_state(self) -> ds.PowerState | None:
        return ds.state_from_statusword(self._statusword) if self._statusword is not None else None

    @property
    def malformed_frames(self) -> int:
        return (self._port.malformed if self._port is not None else 0) + self.sdo.malformed

    # -- lifecycle ------------------------------------------------------------------------
    async def open(self, ctx: DeviceContext) -> None:
        self._ctx = ctx
        self.log = self.log.bind(component=ctx.name)
        n = self.node_id
        tpdos = (
            tuple(self.layout.tpdos)
            if self.layout is not None
            else (co.TPDO_BASES[0] + n, co.TPDO_BASES[1] + n)
        )
        ids = (co.EMCY_BASE + n, *tpdos, co.HEARTBEAT_BASE + n)
        self._port = self.bus.attach(
            ids, name=ctx.name, on_bus_error=self._on_bus_error, handler=self._on_frames
        )
        ctx.start_soon(self._watchdog)
        await self._configure()

    async def init(self) -> None:
        self.left_safe = False
        self._latched = False
        self._estop_active = False
        self._heartbeat_error = False
        await self._enable()
        self._heartbeat_ns = self._now()
        self._engaged = True

    async def reset(self) -> None:
        # Not engaged while resetting: nothing the drive says now is a new fault.
        self._engaged = False
        self._latched = False
        self._heartbeat_error = False
        self._pending = None
        self._estop_active = False  # re_init is the way back from an e-stop
        await self.bus.wait_up(self.state_timeout)
        # The node answers (an SDO timeout here means it is still gone).
        self._set_statusword(
            await self.sdo.read(ds.STATUSWORD, timeout=self.sdo_timeout), self._now()
        )
        if self._needs_config or self.nmt_state is not co.NmtState.OPERATIONAL:
            await self._configure()
        await self._enable()
        # The node just answered: the heartbeat consumer counts from now.
        self._heartbeat_ns = self._now()
        self._engaged = True

    async def close(self) -> None:
        # After safe_stop the device stays as it left it (a rig's safety.on_exit: hold
        # must outlive the host); otherwise the axis is disabled.
        self._engaged = False
        self._pending = None
        self.bus.release_heartbeat(self)
        try:
            if (
                not self.left_safe
                and self.bus.is_up
                and self._port is not None
                and self._statusword is not None
            ):
                with anyio.move_on_after(self.state_timeout):
                    state = self.power_state
                    if state in (PS.OPERATION_ENABLED, PS.SWITCHED_ON):
                        await self._send_control(int(ds.Command.SHUTDOWN))
        except Exception as exc:  # closing a broken link must not raise
            self.log.debug("cia402_shutdown_not_sent", error=repr(exc))
        finally:
            if self._port is not None:
                self._port.close()

    async def _configure(self) -> None:
        """NMT pre-operational, SDO configuration, PDO mapping, NMT start, first TPDO."""
        n = self.node_id
        sdo = self.sdo
        timeout = self.sdo_timeout
        await self._nmt(co.NmtCommand.ENTER_PRE_OPERATIONAL)
        if self.files is not None and self.files.dcf is not None:
            # The DCF's parameters first: the driver's own objects below have the last word.
            await write_parameter_values(sdo, self.files.dcf, timeout=timeout)
        await sdo.write(
            co.ObjectEntry(co.PRODUCER_HEARTBEAT_TIME, 0, co.DataType.UNSIGNED16),
            self.heartbeat_ms,
            timeout=timeout,
        )
        if self.counts_per_rev is None:
            increments = await sdo.read(ds.POSITION_ENCODER_INCREMENTS, timeout=timeout)
            revolutions = await sdo.read(ds.POSITION_ENCODER_MOTOR_REVOLUTIONS, timeout=timeout)
            if increments < 1 or revolutions < 1:
                raise HALError(
                    f"CiA 402 node {n}: bad encoder resolution {increments}/{revolutions}"
                )
            self.counts_per_rev = round(increments / revolutions)
        if self.rated_torque is None:
            rated_mnm = await sdo.read(ds.MOTOR_RATED_TORQUE, timeout=timeout)
            if rated_mnm < 1:
                raise HALError(f"CiA 402 node {n}: rated torque 0x6076 is {rated_mnm} mNm")
            self.rated_torque = rated_mnm / 1000
        await self._map_pdos()
        cpr = self._cpr()
        if self.profile_velocity is not None:
            await sdo.write(
                ds.PROFILE_VELOCITY, round(self.profile_velocity * cpr / math.tau), timeout=timeout
            )
        if self.profile_acceleration is not None:
            accel = round(self.profile_acceleration * cpr / math.tau)
            await sdo.write(ds.PROFILE_ACCELERATION, accel, timeout=timeout)
            await sdo.write(ds.PROFILE_DECELERATION, accel, timeout=timeout)
        await self._select_initial_mode()
        started = self._now()
        await self._nmt(co.NmtCommand.START)
        self.nmt_state = co.NmtState.OPERATIONAL
        await self._wait_first_feedback(started)
        self._needs_config = False

    async def _map_pdos(self) -> None:
        """The rig's maps (:attr:`layout`: configured and verified), else the fixed ones."""
        if self.layout is not None:
            await configure_pdos(self.sdo, self.layout.pdos, timeout=self.sdo_timeout)
            return
        await self._map_fixed_pdos()

    async def _map_fixed_pdos(self) -> None:
        """The fixed mapping of the module docstring (a subclass maps its own)."""
        n = self.node_id
        for number, entries in enumerate(RPDO_MAP_ENTRIES, start=1):
            await self._map_pdo(
                co.RPDO_COMM_BASE + number - 1,
                co.RPDO_MAPPING_BASE + number - 1,
                co.rpdo_cob_id(number, n),
                entries,
                transmission=0xFF,
            )
        for number, tentries in enumerate((TPDO1_MAP, TPDO2_MAP), start=1):
            comm = co.TPDO_COMM_BASE + number - 1
            await self._map_pdo(
                comm,
                co.TPDO_MAPPING_BASE + number - 1,
                co.tpdo_cob_id(number, n),
                tentries,
                transmission=1 if self.sync else 0xFF,
                event_ms=0 if self.sync else self.tpdo_event_ms,
            )

    async def _select_initial_mode(self) -> None:
        """0x6060 at configuration (pre-operational): profile position."""
        await self.sdo.write(
            ds.MODES_OF_OPERATION, int(Mode.PROFILE_POSITION), timeout=self.sdo_timeout
        )
        self._mode = Mode.PROFILE_POSITION

    async def _wait_first_feedback(self, started: int) -> None:
        """After NMT start: TPDO1 (event-driven: sent at once) or, on SYNC, the next SYNC."""
        if self.layout is not None:
            await self._wait_layout_status(started)
            return
        await self._wait_tpdo(
            started, timeout=max(self.state_timeout, 3 * self.tpdo_event_ms / 1000)
        )

    async def _map_pdo(
        self,
        comm: int,
        mapping: int,
        cob_id: int,
        entries: tuple[co.PdoMapEntry, ...],
        *,
        transmission: int,
        event_ms: int | None = None,
    ) -> None:
        sdo = self.sdo
        timeout = self.sdo_timeout
        u8, u16, u32 = co.DataType.UNSIGNED8, co.DataType.UNSIGNED16, co.DataType.UNSIGNED32
        await sdo.write(
            co.ObjectEntry(comm, 1, u32), cob_id | co.PDO_COB_ID_INVALID, timeout=timeout
        )
        await sdo.write(co.ObjectEntry(mapping, 0, u8), 0, timeout=timeout)
        for sub, entry in enumerate(entries, start=1):
            await sdo.write(co.ObjectEntry(mapping, sub, u32), entry.to_u32(), timeout=timeout)
        await sdo.write(co.ObjectEntry(mapping, 0, u8), len(entries), timeout=timeout)
        await sdo.write(co.ObjectEntry(comm, 2, u8), transmission, timeout=timeout)
        if event_ms is not None:
            await sdo.write(co.ObjectEntry(comm, 5, u16), event_ms, timeout=timeout)
        await sdo.write(co.ObjectEntry(comm, 1, u32), cob_id, timeout=timeout)

    async def _nmt(self, command: co.NmtCommand) -> None:
        assert self._port is not None
        cob_id, data = co.encode(co.NmtControl(command, self.node_id))
        await self._port.send(cob_id, data)

    async def _wait_tpdo(self, after_ns: int, timeout: float) -> None:  # noqa: ASYNC109
        with anyio.move_on_after(timeout):
            while self._tpdo1_ns is None or self._tpdo1_ns < after_ns:
                await self._change_event().wait()
            return
        raise TimeoutError(f"CiA 402 node {self.node_id}: no TPDO1 within {timeout * 1000:.0f} ms")

    async def _report_later(self, setpoint: Setpoint) -> None:
        """Report a target already reached at command time, once the Motion exists."""
        self._report(setpoint)

    def _report(self, setpoint: Setpoint) -> None:
        if (
            setpoint is self._pending
            and not setpoint.reported
            and self._engaged
            and self._ctx is not None
        ):
            setpoint.reported = True
            self._ctx.target_reached()

    # -- receive side -----------------------------------------------------------------------
    def _now(self) -> int:
        assert self._ctx is not None, "used before open()"
        return self._ctx.clock.now_ns()

    def _on_frames(self, batch: list[can.Message]) -> None:
        """Port handler (event loop, as each batch is dispatched): decode, then wake waiters."""
        port = self._port
        assert port is not None
        n = self.node_id
        tpdo1, tpdo2 = co.TPDO_BASES[0] + n, co.TPDO_BASES[1] + n
        emcy, heartbeat = co.EMCY_BASE + n, co.HEARTBEAT_BASE + n
        now = self._now()
        layout = self.layout
        for frame in batch:
            if frame.is_remote_frame:
                continue
            try:
                arb = frame.arbitration_id
                if layout is not None:
                    tpdo = layout.tpdos.get(arb)
                    if tpdo is not None:
                        self._on_layout_tpdo(tpdo, frame, now)
                        continue
                if arb == tpdo1 and layout is None:
                    self._on_tpdo1(frame, now)
                elif arb == tpdo2 and layout is None:
                    self._on_tpdo2(frame, now)
                elif arb == emcy:
                    self._on_emcy(frame)
                elif arb == heartbeat:
                    self._on_heartbeat(frame, now)
            except DecodeError:
                port.malformed += 1
        changed = self._changed
        if changed is not None:
            self._changed = None
            changed.set()
        if self._status_waiters:
            self._wake_status_waiters()

    def _change_event(self) -> anyio.Event:
        """The event set after the next received batch."""
        changed = self._changed
        if changed is None:
            changed = self._changed = anyio.Event()
        return changed

    def _wake_status_waiters(self) -> None:
        """Resolve the statusword waits the latest statusword (or a fault latch) ends."""
        sw, latched = self._statusword, self._latched
        for predicate, waiter, _ in self._status_waiters:
            if not waiter.done() and (latched or (sw is not None and predicate(sw))):
                waiter.set_result(True)

    def _on_tpdo1(self, frame: can.Message, now: int) -> None:
        statusword, position, torque = TPDO1_CODEC.unpack(frame.data)
        # A statusword matching no state is malformed: nothing of this TPDO is kept.
        state = ds.state_from_statusword(statusword)
        self._position, self._torque = position, torque
        self._tpdo1_ns = now
        self._set_statusword(statusword, now, state)

    def _on_tpdo2(self, frame: can.Message, now: int) -> None:
        self._velocity, self._mode_display = TPDO2_CODEC.unpack(frame.data)
        self._tpdo2_ns = now

    def _set_statusword(
        self, statusword: int, now: int, state: ds.PowerState | None = None
    ) -> None:
        if state is None:
            state = ds.state_from_statusword(statusword)
        self._statusword = statusword
        faulted = state in (PS.FAULT, PS.FAULT_REACTION_ACTIVE)
        tripped = (
            self._heartbeat_error
            and state is not PS.OPERATION_ENABLED
            and (self._enabled_wanted or faulted)
        )
        if self._emcy_unreported:
            self._emcy_unreported = False
            # An EMCY with a fault is reported once, by the fault below (or by the fault
            # of this episode already latched); without one it is a warning.
            if not ((faulted or tripped) and self._engaged) and self._ctx is not None:
                self._ctx.post_error(ErrorId.DEVICE_ERROR)
        if not self._engaged or self._latched:
            return
        if tripped:
            self._fault(
                ErrorId.WATCHDOG,
                f"CiA 402 node {self.node_id}: heartbeat consumer timeout (EMCY 0x8130: no host "
                f"heartbeat within {self.watchdog_timeout} s), drive in {state.name}",
            )
            return
        if faulted:
            emcy = self.last_emcy
            detail = f", EMCY {emcy_name(emcy.error_code)}" if emcy and emcy.error_code else ""
            self._fault(
                ErrorId.DEVICE_ERROR, f"CiA 402 node {self.node_id} in {state.name}{detail}"
            )
            return
        if self._enabled_wanted and state is not PS.OPERATION_ENABLED:
            self._fault(
                ErrorId.DEVICE_ERROR,
                f"CiA 402 node {self.node_id} left Operation enabled ({state.name})",
            )
            return
        setpoint = self._pending
        if setpoint is not None and statusword & TARGET_REACHED:
            self._report(setpoint)

    def _on_emcy(self, frame: can.Message) -> None:
        msg = co.decode(frame.arbitration_id, frame.data)
        assert isinstance(msg, co.Emergency)
        self.last_emcy = msg
        if msg.error_code == co.EmcyCode.NO_ERROR:
            self.log.info("cia402_emcy_reset")
            return
        self.emcy_count += 1
        if msg.error_code == co.EmcyCode.LIFE_GUARD_OR_HEARTBEAT:
            self._heartbeat_error = True
        self.log.warning(
            "cia402_emcy", code=emcy_name(msg.error_code), register=f"{msg.error_register:#04x}"
        )
        self._emcy_unreported = True  # with the next statusword: a fault, or a warning

    def _on_heartbeat(self, frame: can.Message, now: int) -> None:
        msg = co.decode(frame.arbitration_id, frame.data)
        assert isinstance(msg, co.Heartbeat)
        if not isinstance(msg.state, co.NmtState):
            # The codec keeps the value; CiA 301 defines no other state: counted as malformed.
            raise co.CanOpenDecodeError(f"unknown NMT state {msg.state:#04x}")
        self._heartbeat_ns = now
        previous, self.nmt_state = self.nmt_state, msg.state
        if msg.state is co.NmtState.BOOT_UP:
            self._needs_config = True
            self._fault(
                ErrorId.DEVICE_ERROR, f"CiA 402 node {self.node_id} rebooted (boot-up message)"
            )
        elif msg.state is not co.NmtState.OPERATIONAL and previous is co.NmtState.OPERATIONAL:
            self._fault(
                ErrorId.DEVICE_ERROR,
                f"CiA 402 node {self.node_id} left NMT Operational ({msg.state.name})",
            )

    # -- faults ---------------------------------------------------------------------------
    def _on_latch(self) -> None:
        self._pending = None
        self._enabled_wanted = False
        # A statusword wait ends now (it raises FaultedError), not at its timeout.
        if self._status_waiters:
            self._wake_status_waiters()
