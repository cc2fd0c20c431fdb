"""The heartbeat watchdog and the safe stops of a CiA 402 node: :class:`NodeSafety`, a mixin
of :class:`~openel_can.node402.Cia402Node` (see its module docstring)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Final

import anyio

from openel_async.device import DeviceContext, ErrorId
from openel_async.errors import BadParameterError, HALError
from openel_async.safety import ExitAction

from . import canopen as co
from . import cia402 as ds
from .node402_power import PowerStateMachine

if TYPE_CHECKING:
    from .bus import CanBus
    from .sdo import SdoClient

__all__ = [
    "CONSUMER_HEARTBEAT_TIME_1",
    "QUICK_STOP_ON_ABORT",
    "WATCHDOG_FEED_FRACTION",
    "NodeSafety",
]

CB = ds.ControlBit
ENABLE_OPERATION: Final = int(ds.Command.ENABLE_OPERATION)
CONSUMER_HEARTBEAT_TIME_1: Final = co.ObjectEntry(0x1016, 1, co.DataType.UNSIGNED32)
QUICK_STOP_ON_ABORT: Final = 3
"""0x6007 value: quick stop on a lost connection."""
WATCHDOG_FEED_FRACTION: Final = 4
"""The host heartbeat period is ``timeout / WATCHDOG_FEED_FRACTION``."""


class NodeSafety(PowerStateMachine):
    """Mixin: the host heartbeat the drive watches, e-stop and the exit states (on the
    power state machine's controlword path)."""

    bus: CanBus
    node_id: int
    sdo: SdoClient
    sdo_timeout: float
    host_node_id: int
    watchdog_timeout: float | None
    left_safe: bool
    log: Any
    _ctx: DeviceContext | None
    _lock: anyio.Lock
    _enabled_wanted: bool
    _estop_active: bool
    _pending: object | None
    _fault: Callable[..., None]

    # -- heartbeat watchdog ---------------------------------------------------------------
    async def arm_watchdog(self, timeout_s: float) -> None:
        """Host heartbeat every ``timeout_s / 4`` (the bus's producer), 0x6007 = 3 (quick
        stop) and 0x1016:1 = ``host_node_id << 16 | ms`` by SDO.

        ``timeout_s``: a whole number of milliseconds in 4..65535 (the consumer time is an
        UNSIGNED16 in ms; the heartbeat period, a quarter of it, at least 1 ms).
        """
        ok = (
            not isinstance(timeout_s, bool)
            and isinstance(timeout_s, int | float)
            and math.isfinite(timeout_s)
        )
        ms = round(timeout_s * 1000) if ok else 0
        if not (
            ok and WATCHDOG_FEED_FRACTION <= ms <= 0xFFFF and abs(timeout_s * 1000 - ms) < 1e-6
        ):
            raise BadParameterError(
                "timeout_s",
                timeout_s,
                "a whole number of milliseconds in 0.004..65.535 s "
                "(0x1016 heartbeat consumer time, UNSIGNED16 ms)",
            )
        if self._ctx is None:
            raise HALError(f"CiA 402 node {self.node_id}: arm_watchdog before open")
        self.bus.produce_heartbeat(self.host_node_id, timeout_s / WATCHDOG_FEED_FRACTION, self)
        try:
            await self.sdo.write(
                ds.ABORT_CONNECTION_OPTION_CODE, QUICK_STOP_ON_ABORT, timeout=self.sdo_timeout
            )
            await self.sdo.write(
                CONSUMER_HEARTBEAT_TIME_1, self.host_node_id << 16 | ms, timeout=self.sdo_timeout
            )
        except BaseException:
            self.bus.release_heartbeat(self)
            raise
        self.watchdog_timeout = ms / 1000
        self.log.info("cia402_watchdog_armed", timeout_ms=ms, host_node_id=self.host_node_id)

    async def disarm_watchdog(self) -> None:
        """0x1016:1 = 0 (consumer off) by SDO, then stop producing the host heartbeat."""
        if self.watchdog_timeout is None:
            return
        try:
            if self.bus.is_up:
                await self.sdo.write(CONSUMER_HEARTBEAT_TIME_1, 0, timeout=self.sdo_timeout)
        finally:
            self.bus.release_heartbeat(self)
            self.watchdog_timeout = None

    def _on_estop(self) -> None:
        """Called first by :meth:`estop` (a cyclic drive drops its staged set-point)."""

    async def estop(self) -> None:
        """Controlword Quick stop (the drive ramps down with 0x6085, then acts as 0x605A
        says) and ``fault(ESTOP)`` at once; ``re_init`` enables the drive again.

        The quick stop is sent at once, not after a command holding the drive's lock: until
        ``re_init`` no controlword that switches the drive on or enables it is sent, so a
        command on its way (its steps awaited one at a time) fails with ``HALError`` at its
        next step instead of enabling the drive again."""
        self._estop_active = True
        self._enabled_wanted = False
        self._pending = None
        self._on_estop()
        try:
            await self._send_control(int(ds.Command.QUICK_STOP))
        finally:
            self._fault(ErrorId.ESTOP, f"CiA 402 node {self.node_id}: e-stop (quick stop)")

    async def safe_stop(self, action: ExitAction) -> None:
        """HOLD: Operation enabled with Halt (bit 8): ramps down with the profile
        deceleration 0x6084 and holds, loop closed; STOP: Quick stop (0x6085, then as
        0x605A says: 1..4 Switch on disabled, 5..8 stay in Quick stop active holding);
        TORQUE_OFF: Disable voltage (Switch on disabled, power stage off)."""
        action = ExitAction(action)
        self.left_safe = True
        async with self._lock:
            self._enabled_wanted = action is ExitAction.HOLD and self._enabled_wanted
            self._pending = None
            if action is ExitAction.HOLD and self._estop_active:
                # HOLD would enable the drive (Halt): after an e-stop it stays stopped.
                self.log.warning("cia402_hold_after_estop_skipped")
                return
            if action is ExitAction.HOLD:
                await self._send_control(ENABLE_OPERATION | int(CB.HALT))
            elif action is ExitAction.STOP:
                await self._send_control(int(ds.Command.QUICK_STOP))
            else:
                await self._send_control(int(ds.Command.DISABLE_VOLTAGE))

    async def quick_stop(self) -> None:
        """Controlword quick stop: the drive ramps down (next command re-enables it)."""
        async with self._lock:
            self._enabled_wanted = False
            self._pending = None
            await self._send_control(int(ds.Command.QUICK_STOP))
