"""The PDO side of a CiA 402 node configured from its files (:mod:`openel_can.layout402`):
:class:`LayoutPdos`, a mixin of :class:`~openel_can.node402.Cia402Node` -- the RPDO frames
of the configured maps, the TPDOs dispatched by object, the statusword after NMT start,
and when SYNC runs."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import anyio
import can

from openel_async.errors import BadParameterError, HALError

from . import cia402 as ds
from .layout402 import FEEDBACK_OBJECTS, STATUSWORD, TARGET_OF_MODE, DriveLayout, LayoutTpdo

if TYPE_CHECKING:
    from .bus import CanBus
    from .sdo import SdoClient

__all__ = ["LayoutPdos"]

Mode = ds.ModeOfOperation


class _TpdoPlan:
    """Where a TPDO carries the objects the driver follows (positions among its values),
    and the other objects it keeps by name: worked out once per TPDO, not per frame."""

    __slots__ = ("mode_display", "others", "position", "torque", "tpdo", "velocity")

    def __init__(self, tpdo: LayoutTpdo) -> None:
        self.tpdo = tpdo
        at = {index: i for i, index in enumerate(tpdo.slots)}
        self.position = at.get(0x6064)
        self.torque = at.get(0x6077)
        self.velocity = at.get(0x606C)
        self.mode_display = at.get(0x6061)
        self.others = tuple(
            (i, name)
            for i, (index, name) in enumerate(zip(tpdo.slots, tpdo.names, strict=True))
            if index not in FEEDBACK_OBJECTS and index != STATUSWORD
        )


class LayoutPdos:
    """Mixin: what :class:`~openel_can.node402.Cia402Node` does with :attr:`layout`."""

    bus: CanBus
    node_id: int
    sdo: SdoClient
    sdo_timeout: float
    state_timeout: float
    layout: DriveLayout | None
    pdo_values: dict[str, int]
    _targets: dict[Mode, int]
    _seen_ns: dict[int, int]
    _tpdo_plans: dict[int, _TpdoPlan]
    _status_pdo_ns: int | None
    _position: int
    _torque: int
    _velocity: int
    _mode_display: int | None
    _tpdo1_ns: int | None
    _tpdo2_ns: int | None
    _set_statusword: Callable[..., None]
    _now: Callable[[], int]
    _change_event: Callable[[], anyio.Event]

    async def _wait_layout_status(self, started: int) -> None:
        """After NMT start with :attr:`layout`: the event-driven statusword TPDO, else the
        statusword by SDO (a synchronous one waits for SYNC)."""
        layout = self.layout
        assert layout is not None
        if not layout.status_on_event:
            self._set_statusword(
                await self.sdo.read(ds.STATUSWORD, timeout=self.sdo_timeout), self._now()
            )
            return
        with anyio.move_on_after(self.state_timeout):
            while self._status_pdo_ns is None or self._status_pdo_ns < started:
                await self._change_event().wait()
            return
        raise TimeoutError(
            f"CiA 402 node {self.node_id}: no statusword TPDO within "
            f"{self.state_timeout * 1000:.0f} ms"
        )

    def _sync_running(self) -> bool:
        """A SYNC producer runs on the bus (the bus's own, or a timer's CanSync whose
        timer runs: a stopped timer sends no SYNC to apply a synchronous RPDO)."""
        if self.bus.sync_period is not None:
            return True
        from .sync import CanSync  # (it imports nothing of this module)

        return CanSync.of(self.bus).producing

    def _layout_frame(
        self, layout: DriveLayout, mode: Mode, controlword: int, target: int
    ) -> tuple[int, bytes]:
        """(COB-ID, data) of the RPDO of ``layout`` carrying ``mode``'s target."""
        rpdo = layout.rpdo_of_mode.get(mode)
        if rpdo is None:
            raise HALError(
                f"CiA 402 node {self.node_id}: no RPDO of its pdos carries the controlword "
                f"and {TARGET_OF_MODE[mode]:#06x} ({mode.name})"
            )
        own = TARGET_OF_MODE[mode]
        values = []
        for index in rpdo.slots:
            if index == 0x6040:
                values.append(controlword)
            elif index == own:
                values.append(target)
            elif index == 0x6060:
                values.append(int(mode))
            else:  # another mode's target: its latest
                values.append(
                    next(self._targets[m] for m, t in TARGET_OF_MODE.items() if t == index)
                )
        try:
            return rpdo.pdo.cob_id, rpdo.codec.pack(values)
        except ValueError as exc:
            raise BadParameterError("value", target, f"a target that fits {rpdo.pdo.name}") from exc

    def _on_layout_tpdo(self, tpdo: LayoutTpdo, frame: can.Message, now: int) -> None:
        """A TPDO of :attr:`layout`: the objects the driver follows, the others by name."""
        values = tpdo.codec.unpack(frame.data)
        plan = self._tpdo_plans.get(frame.arbitration_id)
        if plan is None or plan.tpdo is not tpdo:
            plan = self._tpdo_plans[frame.arbitration_id] = _TpdoPlan(tpdo)
        statusword: int | None = None
        state: ds.PowerState | None = None
        if tpdo.status_at is not None:
            statusword = values[tpdo.status_at]
            # A statusword matching no state is malformed: nothing of this TPDO is kept.
            state = ds.state_from_statusword(statusword)
        if plan.position is not None:
            self._position = values[plan.position]
        if plan.torque is not None:
            self._torque = values[plan.torque]
        if plan.velocity is not None:
            self._velocity = values[plan.velocity]
        if plan.mode_display is not None:
            self._mode_display = values[plan.mode_display]
        for at, name in plan.others:
            self.pdo_values[name] = values[at]
        seen = self._seen_ns
        for index in tpdo.slots:
            seen[index] = now
        if tpdo.synchronous:
            self._on_sync_tpdo(now)
        if statusword is not None:
            self._status_pdo_ns = now
            self._set_statusword(statusword, now, state)

    def _on_sync_tpdo(self, now: int) -> None:
        """A synchronous TPDO of :attr:`layout` arrived (a cyclic drive notes the cycle)."""

    def feedback_ns(self, index: int) -> int | None:
        """When the TPDO value of object ``index`` (0x6064, 0x606C, 0x6077) last arrived
        (None: never, or no TPDO carries it)."""
        if self.layout is not None:
            return self._seen_ns.get(index)
        if index in (0x6064, 0x6077):
            return self._tpdo1_ns
        return self._tpdo2_ns if index == 0x606C else None
