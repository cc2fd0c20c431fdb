"""Fault latch and heartbeat watchdog shared by the CAN axis drivers.

A node reports one fault per episode: once latched, the heartbeat loss that follows a
bus-off (or the next error frame) is not reported again until ``re_init`` re-engages
the node and clears the latch.
"""

from __future__ import annotations

from typing import ClassVar

from openel_async.device import DeviceContext, ErrorId
from openel_async.errors import ReturnCode


class NodeFaults:
    """Mixin for an ActuatorDevice on a CAN node that produces heartbeats."""

    node_label: ClassVar[str]
    node_id: int
    heartbeat_timeout: float
    _ctx: DeviceContext | None
    _engaged: bool
    _latched: bool
    _heartbeat_ns: int | None

    def _on_latch(self) -> None:
        """Drop the driver state a fault invalidates (e.g. the pending set-point)."""

    def _fault(
        self, error_id: ErrorId, reason: str, code: ReturnCode = ReturnCode.HAL_ERROR
    ) -> None:
        if self._latched or not self._engaged or self._ctx is None:
            return
        self._latched = True
        self._on_latch()
        self._ctx.fault(error_id, reason, code)

    def _on_bus_error(self, reason: str) -> None:
        self._fault(ErrorId.BUS_ERROR, f"CAN bus error: {reason}", ReturnCode.HAL_NO_CONNECTED)

    async def _watchdog(self) -> None:
        """Heartbeat loss: no heartbeat for ``heartbeat_timeout`` while engaged -> DISCONNECTED."""
        assert self._ctx is not None
        clock = self._ctx.clock
        timeout_ns = round(self.heartbeat_timeout * 1e9)
        while True:
            last = self._heartbeat_ns
            now = clock.now_ns()
            if self._engaged and last is not None and now - last >= timeout_ns:
                self._fault(
                    ErrorId.DISCONNECTED,
                    f"{self.node_label} node {self.node_id}: no heartbeat for "
                    f"{(now - last) / 1e6:.0f} ms",
                    ReturnCode.HAL_NO_CONNECTED,
                )
                last = now
            deadline = (last if last is not None else now) + timeout_ns
            await clock.sleep_until(max(deadline, now + timeout_ns // 4))
