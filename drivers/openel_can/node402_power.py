"""The power state machine of a CiA 402 node: :class:`PowerStateMachine`, a mixin of
:class:`~openel_can.node402.Cia402Node` (see its module docstring) -- the controlword
sequences to a power state, each step confirmed by the statusword (a future resolved by the
node's port handler, bounded by a loop timer; by SDO polling when no TPDO sends the
statusword on event), the RPDOs that carry the controlword with a mode's target, and the mode
of operation by SDO. Also the fixed PDO maps of a node without its files, and the e-stop gate:
while :attr:`Cia402Node._estop_active` no controlword that switches the drive on or enables it
leaves (:data:`SWITCHES_ON`)."""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Final

import anyio

from openel_async.errors import BadParameterError, HALError

from . import canopen as co
from . import cia402 as ds

if TYPE_CHECKING:
    from .bus import NodePort
    from .layout402 import DriveLayout
    from .sdo import SdoClient

__all__ = [
    "ENABLE_OPERATION",
    "RPDO_CODECS",
    "RPDO_MAPS",
    "RPDO_MAP_ENTRIES",
    "RPDO_OF_MODE",
    "SWITCHES_ON",
    "TARGET_REACHED",
    "TPDO1_CODEC",
    "TPDO1_MAP",
    "TPDO2_CODEC",
    "TPDO2_MAP",
    "TPDO_MAPS",
    "FaultedError",
    "PowerStateMachine",
    "emcy_name",
]

PS = ds.PowerState
Mode = ds.ModeOfOperation
SB = ds.StatusBit

RPDO_MAPS: Final = (
    (ds.CONTROLWORD, ds.TARGET_POSITION),
    (ds.CONTROLWORD, ds.TARGET_VELOCITY),
    (ds.CONTROLWORD, ds.TARGET_TORQUE),
)
TPDO_MAPS: Final = (
    (ds.STATUSWORD, ds.POSITION_ACTUAL_VALUE, ds.TORQUE_ACTUAL_VALUE),
    (ds.VELOCITY_ACTUAL_VALUE, ds.MODES_OF_OPERATION_DISPLAY),
)
RPDO_OF_MODE: Final = {
    Mode.PROFILE_POSITION: 0,
    Mode.PROFILE_VELOCITY: 1,
    Mode.PROFILE_TORQUE: 2,
    # The cyclic synchronous modes use the same RPDOs (controlword + the mode's target).
    Mode.CYCLIC_SYNC_POSITION: 0,
    Mode.CYCLIC_SYNC_VELOCITY: 1,
    Mode.CYCLIC_SYNC_TORQUE: 2,
}
"""The RPDO (0-based: RPDO1..3) carrying the target of each mode."""
TPDO1_MAP: Final = tuple(entry.map_entry() for entry in TPDO_MAPS[0])
TPDO2_MAP: Final = tuple(entry.map_entry() for entry in TPDO_MAPS[1])
RPDO_MAP_ENTRIES: Final = tuple(tuple(e.map_entry() for e in mapping) for mapping in RPDO_MAPS)
RPDO_CODECS: Final = tuple(co.PdoCodec(entries) for entries in RPDO_MAP_ENTRIES)
"""The codec of RPDO1..3 (controlword, target)."""
TPDO1_CODEC: Final = co.PdoCodec(TPDO1_MAP)
TPDO2_CODEC: Final = co.PdoCodec(TPDO2_MAP)
ENABLE_OPERATION: Final = int(ds.Command.ENABLE_OPERATION)
"""The controlword Enable operation as a plain int (IntFlag arithmetic is Python code)."""
TARGET_REACHED: Final = int(SB.TARGET_REACHED)
"""Statusword bit 10 as a plain int."""
SWITCHES_ON: Final = 0x07
"""Controlword bits 0..2 (switch on, enable voltage, quick stop high): Switch on and Enable
operation have all three; Quick stop, Disable voltage, Shutdown and Fault reset do not."""


def emcy_name(code: int) -> str:
    try:
        return co.EmcyCode(code).name
    except ValueError:
        return f"{code:#06x}"


class FaultedError(Exception):
    """The component faulted while a command waited for the drive (internal)."""


class PowerStateMachine:
    """Mixin: the power state machine, the controlword RPDOs and the mode of operation."""

    node_id: int
    sdo: SdoClient
    sdo_timeout: float
    state_timeout: float
    layout: DriveLayout | None
    log: Any
    last_emcy: co.Emergency | None
    _port: NodePort | None
    _statusword: int | None
    _controlword: int
    _mode: Mode | None
    _mode_display: int | None
    _targets: dict[Mode, int]
    _position: int
    _enabled_wanted: bool
    _estop_active: bool
    _latched: bool
    _status_waiters: list[tuple[Callable[[int], bool], asyncio.Future[bool], float]]
    _status_timer: asyncio.TimerHandle | None
    _status_timer_loop: asyncio.AbstractEventLoop | None
    _set_statusword: Callable[..., None]
    _now: Callable[[], int]
    _sync_running: Callable[[], bool]
    _layout_frame: Callable[[DriveLayout, Mode, int, int], tuple[int, bytes]]

    def _power_state_now(self) -> ds.PowerState | None:
        sw = self._statusword
        return ds.state_from_statusword(sw) if sw is not None else None

    async def _current_state(self) -> ds.PowerState:
        if self._statusword is None:
            self._set_statusword(
                await self.sdo.read(ds.STATUSWORD, timeout=self.sdo_timeout), self._now()
            )
        state = self._power_state_now()
        assert state is not None
        return state

    async def _drive_to(self, target: ds.PowerState) -> None:
        """Walk the power state machine to ``target``, one confirmed transition at a time."""
        for _ in range(12):
            state = await self._current_state()
            if state is target:
                return
            if state is PS.FAULT:
                self.log.warning(
                    "cia402_fault_reset",
                    emcy=emcy_name(self.last_emcy.error_code) if self.last_emcy else None,
                )
            word = ds.next_controlword(state, target, previous_controlword=self._controlword)

            def left(sw: int, state: ds.PowerState = state) -> bool:
                return ds.state_from_statusword(sw) is not state

            if word is None:  # the drive is changing state by itself
                await self._wait_status(left, "leave " + state.name)
                continue
            expected = ds.apply_controlword(state, word, previous_controlword=self._controlword)
            await self._send_control(word)
            if expected is not state:
                await self._wait_status(left, f"{state.name} -> {expected.name}")
        raise HALError(
            f"CiA 402 node {self.node_id}: could not reach {target.name} (in {self._power_state_now()})"
        )

    async def _enable(self) -> None:
        self._enabled_wanted = False
        self._targets[Mode.PROFILE_POSITION] = self._position
        self._targets[Mode.PROFILE_VELOCITY] = 0
        self._targets[Mode.PROFILE_TORQUE] = 0
        await self._drive_to(PS.OPERATION_ENABLED)
        self._enabled_wanted = True

    async def _send_control(self, controlword: int) -> None:
        """The controlword in the RPDO of the current mode, with that mode's target."""
        mode = self._mode or Mode.PROFILE_POSITION
        await self._send_rpdo(mode, controlword, self._targets[mode])

    def rpdo_frame(self, mode: Mode, controlword: int, target: int) -> tuple[int, bytes]:
        """(COB-ID, data) of the RPDO of ``mode`` (:attr:`layout`'s or the fixed one)
        carrying ``controlword`` and ``target``; ``BadParameterError`` for a target that
        does not fit, ``HALError`` when no RPDO carries the mode's target."""
        layout = self.layout
        if layout is None:
            number = RPDO_OF_MODE[mode]
            try:
                data = RPDO_CODECS[number].pack((controlword, target))
            except ValueError as exc:
                raise BadParameterError(
                    "value", target, f"a target that fits {RPDO_MAPS[number][1].data_type.name}"
                ) from exc
            return co.RPDO_BASES[number] + self.node_id, data
        return self._layout_frame(layout, mode, controlword, target)

    async def _send_rpdo(self, mode: Mode, controlword: int, target: int) -> None:
        assert self._port is not None
        if self._estop_active and controlword & SWITCHES_ON == SWITCHES_ON:
            # A command already on its way when the e-stop came (its steps are awaited one
            # at a time): its later controlwords must not enable the drive again.
            raise HALError(
                f"CiA 402 node {self.node_id}: e-stopped: controlword {controlword:#06x} "
                "refused until re_init"
            )
        layout = self.layout
        if layout is not None:
            rpdo = layout.rpdo_of_mode.get(mode)
            if rpdo is None or (rpdo.synchronous and not self._sync_running()):
                # No RPDO of this mode (a state transition), or a synchronous one waiting
                # for a SYNC none sends: the controlword by SDO.
                self._controlword = controlword
                await self.sdo.write(ds.CONTROLWORD, controlword, timeout=self.sdo_timeout)
                return
            cob_id, data = self.rpdo_frame(mode, controlword, target)
            self._controlword = controlword
            await self._port.send(cob_id, data)
            return
        number = RPDO_OF_MODE[mode]
        try:
            data = RPDO_CODECS[number].pack((controlword, target))
        except ValueError as exc:
            raise BadParameterError(
                "value", target, f"a target that fits {RPDO_MAPS[number][1].data_type.name}"
            ) from exc
        self._controlword = controlword
        await self._port.send(co.RPDO_BASES[number] + self.node_id, data)

    async def _wait_status(self, predicate: Callable[[int], bool], what: str) -> int:
        if self._latched:
            raise FaultedError(what)
        sw = self._statusword
        if sw is not None and predicate(sw):  # already there: no timer needed
            return sw
        if self.layout is not None and not self.layout.status_on_event:
            return await self._poll_status(predicate, what)
        # A future resolved by the batch that satisfies the predicate (see _on_frames) and
        # the node's status timer bounding the wait (see _arm_status_timer): no cancel
        # scope, no wake-up per unrelated frame. Cancellation from outside cancels the
        # future; the finally clause cleans up.
        loop = asyncio.get_running_loop()
        deadline = loop.time() + self.state_timeout
        waiters = self._status_waiters
        while True:
            waiter: asyncio.Future[bool] = loop.create_future()
            entry = (predicate, waiter, deadline)
            waiters.append(entry)
            self._arm_status_timer(loop, deadline)
            try:
                satisfied = await waiter
            finally:
                waiters.remove(entry)
            if self._latched:
                raise FaultedError(what)
            sw = self._statusword
            if sw is not None and predicate(sw):
                return sw
            if not satisfied:
                break
        raise TimeoutError(
            f"CiA 402 node {self.node_id}: no statusword for {what} within {self.state_timeout * 1000:.0f} ms"
            + (f" (statusword {self._statusword:#06x})" if self._statusword is not None else "")
        )

    def _arm_status_timer(self, loop: asyncio.AbstractEventLoop, deadline: float) -> None:
        """Make the status timer fire by ``deadline`` (loop time).

        One timer serves every statusword wait of the node: it is replaced only when it
        would fire after ``deadline`` (or belongs to another loop); when it fires it ends
        the waits whose deadline passed and is set again for the soonest other one. A
        set-point's two waits cost no timer handle each (pushed on and popped off the
        loop's heap, whose order is Python comparisons).
        """
        timer = self._status_timer
        if timer is not None:
            if (
                timer.when() <= deadline
                and self._status_timer_loop is loop
                and not timer.cancelled()
            ):
                return
            timer.cancel()
        self._status_timer = loop.call_at(deadline, self._status_timer_fired, loop)
        self._status_timer_loop = loop

    def _status_timer_fired(self, loop: asyncio.AbstractEventLoop) -> None:
        self._status_timer = None
        now = loop.time()
        soonest = math.inf
        for _, waiter, deadline in self._status_waiters:
            if waiter.done():
                continue
            if deadline <= now:
                waiter.set_result(False)  # timed out: the wait ends unsatisfied
            elif deadline < soonest:
                soonest = deadline
        if soonest < math.inf:
            self._status_timer = loop.call_at(soonest, self._status_timer_fired, loop)

    async def _poll_status(self, predicate: Callable[[int], bool], what: str) -> int:
        """:meth:`_wait_status` when no TPDO sends the statusword on event: read by SDO."""
        with anyio.move_on_after(self.state_timeout):
            while True:
                sw = await self.sdo.read(ds.STATUSWORD, timeout=self.sdo_timeout)
                self._set_statusword(sw, self._now())
                if self._latched:
                    raise FaultedError(what)
                if predicate(sw):
                    return sw
                await anyio.sleep(0.002)
        raise TimeoutError(
            f"CiA 402 node {self.node_id}: no statusword for {what} within "
            f"{self.state_timeout * 1000:.0f} ms (statusword {self._statusword or 0:#06x}, by SDO)"
        )

    async def _set_mode(self, mode: Mode) -> None:
        if mode is self._mode:
            return
        self._mode = None
        await self.sdo.write(ds.MODES_OF_OPERATION, int(mode), timeout=self.sdo_timeout)
        display = await self.sdo.read(ds.MODES_OF_OPERATION_DISPLAY, timeout=self.sdo_timeout)
        if display != mode:
            raise HALError(
                f"CiA 402 node {self.node_id}: mode display {display} after selecting {mode.name}"
            )
        self._mode = mode
        self._mode_display = display
