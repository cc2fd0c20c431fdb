"""Cyclic synchronous modes of a CiA 402 drive: :class:`Cia402CyclicDrive` (CSP 8, CSV 9, CST 10).

Made by ``Cia402Drive(bus, node_id, mode="csp" | "csv" | "cst")`` (in a rig: ``params:
{node_id: 1, mode: csp}``). The drive runs one mode for its whole life and takes one request:
POSITION (csp), VELOCITY (csv) or TORQUE (cst). Every cycle of the bus's
:class:`~openel_can.sync.CanSync` (an EventTimer's tick) the latest set-point goes out as the
mode's RPDO, then SYNC latches it; the drive follows it over the interpolation time period
0x60C2 and answers with TPDO1. In the loop the driver sends no SDO: a command is packed and
staged without I/O (``command_nowait``: an :class:`~openel_async.motion.AxisGroup` streams
through it without suspending), actual values come from TPDO1.

PDO mapping without ``eds``/``dcf`` (with them: ``default_pdos(mode)`` or the rig's
``pdos``, :mod:`openel_can.layout402`; the set-point RPDO is then the one carrying the
controlword and the mode's target, the cycle's feedback any synchronous TPDO):

=========  ===============================================  ==============================
PDO        objects                                          transmission
=========  ===============================================  ==============================
RPDO1      controlword 0x6040, target position 0x607A       CSP (0xFF: taken on receipt,
RPDO2      controlword 0x6040, target velocity 0x60FF       CSV  latched by the drive at
RPDO3      controlword 0x6040, target torque 0x6071         CST  the next SYNC)
TPDO1      statusword 0x6041, position 0x6064, torque 0x6077  type 1: every SYNC
TPDO2      statusword 0x6041, mode display 0x6061           0xFF, on change (no timer)
=========  ===============================================  ==============================

TPDO2 carries each statusword change at once, so the power state machine runs whether SYNC
runs or not (the drive is enabled at ``init``, before any timer); TPDO1 is the cycle's
feedback (:attr:`Cia402CyclicDrive.feedback_cycle` = the SYNC it answered).

Entering (configuration and every ``init``/``re_init``): the actual position 0x6064 is read
by SDO and written as the target (0x607A; 0x60FF and 0x6071 = 0) before the mode 0x6060 is
selected and before enabling, and the enabling RPDOs carry that target, so the drive does not
jump; then statusword bit 12 ("drive follows the command value") is awaited. The
interpolation time period 0x60C2 (sub1 value, sub2 power of ten, e.g. 2 and -3 for 2 ms) is
written from the timer's period when the bus's CanSync starts, and at every configuration
while it runs. Leaving (:meth:`Cia402CyclicDrive.leave_cyclic`, also at ``close`` unless a
safe stop left the drive as it is): Halt (bit 8: the drive stops with 0x6084), then profile
position with target = actual, still enabled.

An EMCY (other than 0x0000, error reset) faults the component at once, with the code's
class in words (:func:`openel_can.emcy.describe_emcy`): the staged set-point is dropped and
a quick stop sent. ("At once": when the EMCY is read. On a bus :class:`~openel_can.CanSync`
reads once per tick, that is the next tick, before its SYNC: the set-point staged for that
SYNC never leaves.)
"""

from __future__ import annotations

from typing import Any, Final

import anyio
import can

from openel_async.device import ErrorId, VelocityRamp
from openel_async.errors import BadParameterError, HALError, StateError
from openel_async.logs import get_logger
from openel_async.requests import Request

from . import canopen as co
from . import cia402 as ds
from .drive402 import Cia402Drive
from .emcy import describe_emcy
from .layout402 import TARGET_OF_MODE
from .node402 import (
    ENABLE_OPERATION,
    RPDO_CODECS,
    RPDO_MAPS,
    RPDO_OF_MODE,
    TARGET_REACHED,
    TPDO_MAPS,
)
from .sdo import SdoAbortError
from .sync import CanSync

__all__ = ["CYCLIC_MODES", "STATUS_TPDO_MAP", "Cia402CyclicDrive", "interpolation_period"]

log = get_logger(__name__)

PS = ds.PowerState
Mode = ds.ModeOfOperation
CYCLIC_MODES: Final = {
    "csp": Mode.CYCLIC_SYNC_POSITION,
    "csv": Mode.CYCLIC_SYNC_VELOCITY,
    "cst": Mode.CYCLIC_SYNC_TORQUE,
}
_REQUEST_OF_MODE: Final = {
    Mode.CYCLIC_SYNC_POSITION: Request.POSITION,
    Mode.CYCLIC_SYNC_VELOCITY: Request.VELOCITY,
    Mode.CYCLIC_SYNC_TORQUE: Request.TORQUE,
}
STATUS_TPDO_MAP: Final = (ds.STATUSWORD, ds.MODES_OF_OPERATION_DISPLAY)
"""TPDO2 in the cyclic modes: every statusword change at once."""
_STATUS_CODEC: Final = co.PdoCodec(tuple(e.map_entry() for e in STATUS_TPDO_MAP))
_FOLLOWS: Final = int(ds.StatusBit.SETPOINT_ACKNOWLEDGE)
"""Statusword bit 12 in the cyclic modes: the drive follows the command value."""
_HALT: Final = int(ds.ControlBit.HALT)
INTERPOLATION_PERIOD_VALUE: Final = co.ObjectEntry(0x60C2, 1, co.DataType.UNSIGNED8)
INTERPOLATION_PERIOD_INDEX: Final = co.ObjectEntry(0x60C2, 2, co.DataType.INTEGER8)
SYNC_COUNTER_OVERFLOW: Final = co.ObjectEntry(0x1019, 0, co.DataType.UNSIGNED8)


def interpolation_period(period_ns: int) -> tuple[int, int]:
    """0x60C2 (value 1..255, index -9..0: ``value x 10^index`` s) for ``period_ns``: exact
    when it can be, else the closest with the most digits."""
    if period_ns <= 0:
        raise BadParameterError("period_ns", period_ns, "a period > 0")
    for index in range(0, -10, -1):
        unit = 10 ** (9 + index)  # ns per step at this index
        if period_ns % unit == 0 and period_ns // unit <= 255:
            return period_ns // unit, index
    for index in range(0, -10, -1):
        value = round(period_ns / 10 ** (9 + index))
        if value >= 26:
            return min(255, value), index
    return 255, -9  # (never: 1 ns is exact at -9)


class Cia402CyclicDrive(Cia402Drive):
    """A CiA 402 drive in a cyclic synchronous mode on the bus's SYNC (module docstring)."""

    reports_completion = False
    """Streamed set-points: completion is the framework's (tolerance), not bit 10."""
    velocity_ramp = False

    def __init__(self, bus: Any, node_id: int, *, mode: str = "csp", **kwargs: Any) -> None:
        if mode not in CYCLIC_MODES:
            raise BadParameterError("mode", mode, f"a cyclic mode ({', '.join(CYCLIC_MODES)})")
        super().__init__(bus, node_id, mode=mode, **kwargs)
        self.cyclic_mode: Mode = CYCLIC_MODES[mode]
        self.request: Request = _REQUEST_OF_MODE[self.cyclic_mode]
        """The one request the drive takes."""
        self.supported_requests = frozenset({self.request})
        self._rpdo = RPDO_OF_MODE[self.cyclic_mode]
        self._stage_plan: tuple[co.PdoCodec, list[int], int] | None = None
        self.rpdo_cob_id = (
            co.RPDO_BASES[self._rpdo] + node_id
            if self.layout is None
            else self.layout.rpdo_of_mode[self.cyclic_mode].pdo.cob_id
        )
        """The COB-ID of the set-point RPDO staged every cycle."""
        self.sync_source = CanSync.of(bus)
        self.feedback_cycle = 0
        """The SYNC (:attr:`CanSync.cycle`) the last TPDO1 answered."""
        self.interpolation: tuple[int, int] | None = None
        """0x60C2 as last written (value, index)."""
        self.sync_counter = 0
        """0x1019 (SYNC counter overflow) as last written (0: not written, or no counter)."""

    # -- configuration ----------------------------------------------------------------------
    async def _map_fixed_pdos(self) -> None:
        n = self.node_id
        for number, entries in enumerate(RPDO_MAPS, start=1):
            await self._map_pdo(
                co.RPDO_COMM_BASE + number - 1,
                co.RPDO_MAPPING_BASE + number - 1,
                co.rpdo_cob_id(number, n),
                tuple(e.map_entry() for e in entries),
                transmission=0xFF,
            )
        for number, tentries, transmission in ((1, TPDO_MAPS[0], 1), (2, STATUS_TPDO_MAP, 0xFF)):
            await self._map_pdo(
                co.TPDO_COMM_BASE + number - 1,
                co.TPDO_MAPPING_BASE + number - 1,
                co.tpdo_cob_id(number, n),
                tuple(e.map_entry() for e in tentries),
                transmission=transmission,
                event_ms=0,
            )

    async def _select_initial_mode(self) -> None:
        period = self.sync_source.period_ns
        if period is not None:
            await self.set_cycle(period, self.sync_source.counter_overflow)
        await self._select_cyclic(await self._read_actual())

    async def _wait_first_feedback(self, started: int) -> None:
        """TPDO2 (event-driven: sent at once on NMT start); with a layout, its statusword."""
        if self.layout is not None:
            await super()._wait_first_feedback(started)
            return
        with anyio.move_on_after(self.state_timeout):
            while self._tpdo2_ns is None or self._tpdo2_ns < started:
                await self._change_event().wait()
            return
        raise TimeoutError(
            f"CiA 402 node {self.node_id}: no TPDO2 within {self.state_timeout * 1000:.0f} ms"
        )

    async def set_cycle(self, period_ns: int, counter_overflow: int = 0) -> None:
        """0x60C2 = the cycle and 0x1019 = the SYNC counter overflow (by SDO;
        :meth:`CanSync.start` calls it before the first SYNC). 0x1019 is written when the
        SYNC counts (``counter_overflow`` 2..240) or the drive's counter is set; a drive
        without 0x1019 (an SDO abort) only gets a warning: the counter is then informative."""
        value, index = interpolation_period(period_ns)
        await self.sdo.write(INTERPOLATION_PERIOD_VALUE, value, timeout=self.sdo_timeout)
        await self.sdo.write(INTERPOLATION_PERIOD_INDEX, index, timeout=self.sdo_timeout)
        self.interpolation = (value, index)
        if counter_overflow or self.sync_counter:
            try:
                await self.sdo.write(
                    SYNC_COUNTER_OVERFLOW, counter_overflow, timeout=self.sdo_timeout
                )
                self.sync_counter = counter_overflow
            except SdoAbortError as exc:
                self.log.warning("cia402_sync_counter_not_written", error=str(exc))
        self.log.info(
            "cia402_interpolation_period", value=value, index=index, counter=counter_overflow
        )

    async def _read_actual(self) -> int:
        actual: int = await self.sdo.read(ds.POSITION_ACTUAL_VALUE, timeout=self.sdo_timeout)
        self._position = actual
        return actual

    async def _select_cyclic(self, actual: int) -> None:
        """Target = ``actual`` (and zero velocity/torque), then 0x6060 = the cyclic mode."""
        timeout = self.sdo_timeout
        await self.sdo.write(ds.TARGET_POSITION, actual, timeout=timeout)
        if self.cyclic_mode is not Mode.CYCLIC_SYNC_POSITION:
            await self.sdo.write(ds.TARGET_VELOCITY, 0, timeout=timeout)
            await self.sdo.write(ds.TARGET_TORQUE, 0, timeout=timeout)
        self._targets[Mode.CYCLIC_SYNC_POSITION] = actual
        self._targets[Mode.CYCLIC_SYNC_VELOCITY] = self._targets[Mode.CYCLIC_SYNC_TORQUE] = 0
        await self._set_mode(self.cyclic_mode)

    # -- lifecycle --------------------------------------------------------------------------
    async def open(self, ctx: Any) -> None:
        self.sync_source.add_consumer(self)
        await super().open(ctx)

    async def _enable(self) -> None:
        """Target = actual (read now), the cyclic mode, enable, then bit 12 (follows)."""
        self._enabled_wanted = False
        self.sync_source.unstage(self.rpdo_cob_id)  # nothing stale goes out after enabling
        self._stage_plan = None
        actual = await self._read_actual()
        if self._mode is not self.cyclic_mode:
            await self._select_cyclic(actual)
        else:
            position = self.cyclic_mode is Mode.CYCLIC_SYNC_POSITION
            self._targets[self.cyclic_mode] = actual if position else 0
        await self._drive_to(PS.OPERATION_ENABLED)
        await self._wait_status(lambda sw: bool(sw & _FOLLOWS), "drive follows (bit 12)")
        self._enabled_wanted = True

    async def close(self) -> None:
        self.sync_source.remove_consumer(self)
        self.sync_source.unstage(self.rpdo_cob_id)
        if (
            not self.left_safe
            and self.bus.is_up
            and self._port is not None
            and self.power_state is PS.OPERATION_ENABLED
            and self._mode is self.cyclic_mode
        ):
            try:
                with anyio.move_on_after(2 * self.state_timeout):
                    await self.leave_cyclic()
            except Exception as exc:  # closing a broken link must not raise
                self.log.debug("cia402_leave_cyclic_failed", error=repr(exc))
        await super().close()

    async def leave_cyclic(self) -> None:
        """Halt (the drive stops with 0x6084), then profile position with target = actual;
        the drive stays enabled. Commands are refused until :meth:`enter_cyclic`."""
        async with self._lock:
            self.sync_source.unstage(self.rpdo_cob_id)
            self._pending = None
            await self._send_control(ENABLE_OPERATION | _HALT)
            try:
                await self._wait_status(lambda sw: bool(sw & TARGET_REACHED), "halted")
            except TimeoutError:
                self.log.warning("cia402_halt_not_confirmed")
            actual = await self._read_actual()
            await self.sdo.write(ds.TARGET_POSITION, actual, timeout=self.sdo_timeout)
            await self._set_mode(Mode.PROFILE_POSITION)
            self._targets[Mode.PROFILE_POSITION] = actual
            await self._send_control(ENABLE_OPERATION)  # halt off; no new set-point: no motion
            self.log.info("cia402_left_cyclic", mode=self.mode, position=actual)

    async def enter_cyclic(self) -> None:
        """Back into the cyclic mode (target = actual first), enabled."""
        async with self._lock:
            await self._enable()

    # -- commands ---------------------------------------------------------------------------
    def command_nowait(self, request: Request, value: float) -> None:
        """Stage the set-point for the next SYNC (no I/O; :meth:`CanSync.stage`)."""
        if request is not self.request:
            raise BadParameterError("request", request, f"{self.request.name} (mode {self.mode})")
        if self._estop_active:
            raise HALError(f"CiA 402 node {self.node_id}: e-stopped: no set-point until re_init")
        if self._mode is not self.cyclic_mode or not self._enabled_wanted:
            raise StateError(
                "command", f"node {self.node_id} not enabled in {self.mode}", ["enter_cyclic()"]
            )
        if request is Request.TORQUE:
            raw = self._torque_permille(value)
        else:
            raw = self.rad_to_counts(value)
        if self.layout is None:
            try:
                data = RPDO_CODECS[self._rpdo].pack((ENABLE_OPERATION, raw))
            except ValueError as exc:
                raise BadParameterError(
                    "value", value, f"a target that fits {RPDO_MAPS[self._rpdo][1].data_type.name}"
                ) from exc
        else:
            plan = self._stage_plan
            if plan is None:
                plan = self._stage_plan = self._plan_stage()
            codec, values, at = plan
            values[at] = raw
            try:
                data = codec.pack(values)
            except ValueError as exc:
                raise BadParameterError("value", value, "a target that fits the RPDO") from exc
        self._targets[self.cyclic_mode] = raw
        self._controlword = ENABLE_OPERATION
        self.sync_source.stage(self.rpdo_cob_id, data)

    async def command(self, request: Request, value: float) -> None:
        self.command_nowait(request, value)

    def _plan_stage(self) -> tuple[co.PdoCodec, list[int], int]:
        """The cyclic mode's RPDO of :attr:`layout` as (codec, values, position of the
        target): the controlword Enable operation and the other slots' values are filled in
        once (:meth:`_enable` drops the plan), each set-point writes only its target."""
        layout = self.layout
        assert layout is not None
        mode = self.cyclic_mode
        rpdo = layout.rpdo_of_mode[mode]  # checked when the drive was made
        values = list(rpdo.codec.unpack(self.rpdo_frame(mode, ENABLE_OPERATION, 0)[1]))
        return rpdo.codec, values, rpdo.slots.index(TARGET_OF_MODE[mode])

    async def command_velocity_ramp(self, ramp: VelocityRamp) -> None:
        raise HALError(f"CiA 402 node {self.node_id}: no velocity ramp in {self.mode}")

    async def read(self, request: Request) -> float:
        if request is Request.VELOCITY_ACTUAL and (
            self.layout is None or not self.layout.carries(0x606C)
        ):  # not in a PDO: by SDO
            counts = await self.sdo.read(ds.VELOCITY_ACTUAL_VALUE, timeout=self.sdo_timeout)
            return self.counts_to_rad(counts)
        return await super().read(request)

    # -- receive side -----------------------------------------------------------------------
    def _on_tpdo1(self, frame: can.Message, now: int) -> None:
        super()._on_tpdo1(frame, now)
        self.feedback_cycle = self.sync_source.cycle

    def _on_emcy(self, frame: can.Message) -> None:
        """An EMCY (other than error reset) faults the component at once, in the cyclic
        modes: a drive streaming set-points must not wait for the next statusword. The
        staged set-point is dropped and a quick stop sent (a drive in Fault ignores it)."""
        super()._on_emcy(frame)
        emcy = self.last_emcy
        if emcy is None or emcy.error_code == co.EmcyCode.NO_ERROR:
            return
        if not self._engaged or self._latched:
            return
        self._emcy_unreported = False  # reported here, once
        self.sync_source.unstage(self.rpdo_cob_id)
        heartbeat = emcy.error_code == co.EmcyCode.LIFE_GUARD_OR_HEARTBEAT
        self._fault(
            ErrorId.WATCHDOG if heartbeat else ErrorId.DEVICE_ERROR,
            f"CiA 402 node {self.node_id} in {self.mode}: EMCY {describe_emcy(emcy.error_code)}, "
            f"error register {emcy.error_register:#04x}",
        )
        if self._ctx is not None:
            self._ctx.start_soon(self._stop_after_emcy)

    async def _stop_after_emcy(self) -> None:
        """Quick stop after an EMCY fault (bounded; a broken link is only logged)."""
        try:
            with anyio.move_on_after(self.state_timeout):
                await self.quick_stop()
        except Exception as exc:
            self.log.warning("cia402_quick_stop_after_emcy_failed", error=repr(exc))

    def _on_estop(self) -> None:
        self.sync_source.unstage(self.rpdo_cob_id)  # a staged Enable operation stays here

    def _on_sync_tpdo(self, now: int) -> None:
        self.feedback_cycle = self.sync_source.cycle

    def _on_tpdo2(self, frame: can.Message, now: int) -> None:
        statusword, self._mode_display = _STATUS_CODEC.unpack(frame.data)
        self._tpdo2_ns = now
        self._set_statusword(statusword, now)
