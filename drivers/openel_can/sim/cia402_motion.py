"""The CiA 402 behaviour of the simulated drive (:class:`Cia402Motion`, a base class of
:class:`~openel_can.sim.cia402.SimCia402Drive`): what a write of the controlword, the mode
of operation or a target does (the power state machine of
:func:`openel_can.cia402.apply_controlword`, halt, quick stop and fault reaction ramps), and
the motion profiles of the modes of operation: profile position (new set-point handshake,
set-point buffer), profile velocity, profile torque, and the cyclic synchronous modes CSP,
CSV and CST followed over the interpolation period at each SYNC. See the module docstring
of :mod:`openel_can.sim.cia402` for the behaviour.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Final

from openel_async.clock import Clock
from openel_sim import profile as prof

from .. import canopen as co
from .. import cia402 as ds
from .history import History

__all__ = ["CYCLIC_MODES", "NS", "SUPPORTED_MODES", "TORQUE_MODES", "Cia402Motion"]

NS: Final = 1e-9
"""Seconds per nanosecond."""
PS = ds.PowerState
Mode = ds.ModeOfOperation
CYCLIC_MODES: Final = frozenset(
    {Mode.CYCLIC_SYNC_POSITION, Mode.CYCLIC_SYNC_VELOCITY, Mode.CYCLIC_SYNC_TORQUE}
)
"""The cyclic synchronous modes (CSP, CSV, CST): a target latched at each SYNC."""
TORQUE_MODES: Final = frozenset({Mode.PROFILE_TORQUE, Mode.CYCLIC_SYNC_TORQUE})
"""The modes in which the drive follows a torque target (0x6071)."""
SUPPORTED_MODES: Final = {
    Mode.PROFILE_POSITION,
    Mode.PROFILE_VELOCITY,
    Mode.PROFILE_TORQUE,
    *CYCLIC_MODES,
}
"""The modes of operation the simulated drive supports (0x6502, and 0x6060 writes)."""


class Cia402Motion:
    """The CiA 402 state machine and motion of :class:`~openel_can.sim.cia402.SimCia402Drive`
    (its attributes and object access below are the drive's)."""

    clock: Clock
    rated_torque: float
    inertia: float
    power_state: ds.PowerState
    segments: list[prof.Segment]
    pp_target: int
    pp_buffered: int | None
    setpoint_ack: bool
    setpoint_ack_delay: float
    setpoint_due_ns: int | None
    setpoint_immediate: bool
    halted: bool
    arrival_ns: int | None
    stop_until_ns: int | None
    target_reached: bool
    torque_target: float
    torque_from: float
    torque_since_ns: int
    cyclic_target: int
    received_controlwords: History[int]
    prev_controlword: int
    next_heartbeat_ns: int
    consumer_heard_ns: int | None

    if TYPE_CHECKING:

        @property
        def mode(self) -> int: ...

        def _get(self, index: int, sub: int = 0) -> int: ...

        def _set(self, index: int, sub: int, value: int) -> None: ...

        def state_at(self, now: int) -> tuple[float, float, float]: ...

        def _counts_per_rad(self) -> float: ...

        def _torque_ramp(self, now: int) -> float: ...

        def _refresh_actuals(self, now: int) -> None: ...

        def _emcy(self, code: int, register: int | None = None) -> None: ...

    def _after_write(self, written: set[int], now: int) -> None:
        if 0x6060 in written:
            self._change_mode(now, self._get(0x6060))
        if 0x6040 in written:
            self._controlword(now, self._get(0x6040))
        elif self.power_state is PS.OPERATION_ENABLED:
            if 0x60FF in written and self.mode == Mode.PROFILE_VELOCITY:
                self._plan_velocity(now)
            if 0x6071 in written and self.mode == Mode.PROFILE_TORQUE:
                self._plan_torque(now)
        if 0x1017 in written:
            self.next_heartbeat_ns = now
        if 0x1016 in written:
            self.consumer_heard_ns = None  # monitoring starts with the next heartbeat
        self._refresh_actuals(now)

    def _change_mode(self, now: int, mode: int) -> None:
        self._set(0x6061, 0, mode)
        self.setpoint_ack = False
        self.pp_buffered = None
        self.arrival_ns = None
        if self.power_state is PS.OPERATION_ENABLED:
            self._stop(now, self._get(0x6084))
        p, _, _ = self.state_at(now)
        self.pp_target = round(p)

    def _controlword(self, now: int, cw: int) -> None:
        self.received_controlwords.append(cw)
        prev = self.prev_controlword
        self.prev_controlword = cw
        before = self.power_state
        after = ds.apply_controlword(before, cw, previous_controlword=prev)
        if after is not before:
            self.power_state = after
            if after is PS.OPERATION_ENABLED:
                self._hold(now)
            elif after is PS.QUICK_STOP_ACTIVE:
                self._stop(now, self._get(0x6085))
            elif before is PS.OPERATION_ENABLED:
                self._stop(now, self._get(0x6084))
            elif before is PS.FAULT:
                self._set(0x603F, 0, 0)
                self._set(0x1001, 0, 0)
                self._emcy(co.EmcyCode.NO_ERROR, 0)
        if self.power_state is not PS.OPERATION_ENABLED:
            self.setpoint_ack = False
            return
        mode = self.mode
        halt = bool(cw & ds.ControlBit.HALT)
        if halt and not self.halted:
            self.halted = True
            self._stop(now, self._get(0x6084))
            return
        self.halted = halt
        if mode == Mode.PROFILE_POSITION:
            rising = cw & ds.ControlBit.NEW_SETPOINT and not prev & ds.ControlBit.NEW_SETPOINT
            if rising and not self.setpoint_ack and self.setpoint_due_ns is None:
                immediate = bool(cw & ds.ControlBit.CHANGE_SET_IMMEDIATELY)
                self.setpoint_due_ns = now + round(self.setpoint_ack_delay * 1e9)
                self.setpoint_immediate = immediate
                if self.setpoint_due_ns <= now:
                    self._accept_setpoint(now)
            elif not cw & ds.ControlBit.NEW_SETPOINT:
                self.setpoint_ack = False
        elif mode == Mode.PROFILE_VELOCITY:
            self._plan_velocity(now)
        elif mode == Mode.PROFILE_TORQUE:
            self._plan_torque(now)

    def _accept_setpoint(self, now: int) -> None:
        """Latch 0x607A (the drive's next cycle after the new set-point edge)."""
        self.setpoint_due_ns = None
        if self.power_state is not PS.OPERATION_ENABLED or self.mode != Mode.PROFILE_POSITION:
            return
        target = self._get(0x607A)
        self.setpoint_ack = True
        moving = self.arrival_ns is not None
        if self.setpoint_immediate or not moving:
            self.pp_buffered = None
            self._plan_position(now, target)
        else:
            self.pp_buffered = target

    def _hold(self, now: int) -> None:
        p, _, _ = self.state_at(now)
        self.segments = prof.hold(now, p)
        self.pp_target = round(p)
        self.pp_buffered = None
        self.arrival_ns = None
        self.target_reached = True
        self.setpoint_ack = False
        self.torque_target = self.torque_from = 0.0
        if self.mode == Mode.PROFILE_VELOCITY:
            self._set(0x60FF, 0, 0)
        if self.mode == Mode.PROFILE_TORQUE:
            self._set(0x6071, 0, 0)

    def _stop(self, now: int, decel: int) -> None:
        p, v, _ = self.state_at(now)
        self.segments = prof.ramp(now, p, v, 0.0, max(1, decel))
        self.stop_until_ns = prof.end_time(self.segments)
        self.arrival_ns = None
        self.pp_buffered = None
        self.target_reached = self.stop_until_ns <= now
        self.torque_target = self.torque_from = 0.0

    def _limits(self) -> tuple[float, float]:
        return float(self._get(0x607D, 1)), float(self._get(0x607D, 2))

    def _plan_position(self, now: int, target: int) -> None:
        low, high = self._limits()
        target = round(max(low, min(high, target)))
        p, v, _ = self.state_at(now)
        vmax = max(1, min(self._get(0x6081), self._get(0x6080)))
        amax = max(1, self._get(0x6083))
        self.pp_target = target
        self.segments = prof.trapezoid(now, p, v, float(target), vmax, amax)
        end = prof.end_time(self.segments)
        self.arrival_ns = end if end > now else None
        self.target_reached = self.arrival_ns is None

    def _plan_velocity(self, now: int) -> None:
        if self.halted:
            return
        vmax = self._get(0x6080)
        target = max(-vmax, min(vmax, self._get(0x60FF)))
        p, v, _ = self.state_at(now)
        accel = self._get(0x6083) if abs(target) >= abs(v) else self._get(0x6084)
        self.segments = prof.ramp(now, p, v, float(target), max(1, accel))
        end = prof.end_time(self.segments)
        self.arrival_ns = end if end > now else None
        self.target_reached = self.arrival_ns is None

    def _plan_torque(self, now: int) -> None:
        if self.halted:
            return
        self.torque_from = self._torque_ramp(now) if self.mode in TORQUE_MODES else 0.0
        self.torque_since_ns = now
        max_torque = self._get(0x6072)
        self.torque_target = float(max(-max_torque, min(max_torque, self._get(0x6071))))
        self.target_reached = self.torque_from == self.torque_target
        p, v, _ = self.state_at(now)
        torque_nm = self.torque_target / 1000 * self.rated_torque
        accel = torque_nm / self.inertia * self._counts_per_rad()
        self.segments = prof.accelerate(now, p, v, accel, float(self._get(0x6080)))
        self.arrival_ns = None

    # -- cyclic synchronous modes (CSP 8, CSV 9, CST 10) -----------------------------------
    def interpolation_period_ns(self) -> int:
        """0x60C2: sub1 x 10^sub2 seconds, in ns (0: a set-point applies at once)."""
        value, index = self._get(0x60C2, 1), self._get(0x60C2, 2)
        return max(0, round(value * 10.0**index * 1e9))

    def _cyclic_sync(self, now: int) -> None:
        """SYNC in a cyclic mode: latch the target received before it and follow it over
        one interpolation period (CSP: linear position; CSV: linear velocity; CST: the
        torque at once). Without SYNC the drive keeps the last latched target."""
        mode = self.mode
        if mode not in CYCLIC_MODES or self.power_state is not PS.OPERATION_ENABLED or self.halted:
            return
        period = self.interpolation_period_ns()
        p, v, _ = self.state_at(now)
        if mode == Mode.CYCLIC_SYNC_POSITION:
            low, high = self._limits()
            target = max(low, min(high, float(self._get(0x607A))))
            self.cyclic_target = round(target)
            if period:
                rate = (target - p) / (period * NS)
                self.segments = [
                    prof.Segment(now, p, rate, 0.0, now + period),
                    prof.Segment(now + period, target, 0.0, 0.0, None),
                ]
            else:
                self.segments = prof.hold(now, target)
            end = now + period
        elif mode == Mode.CYCLIC_SYNC_VELOCITY:
            vmax = self._get(0x6080)
            target = float(max(-vmax, min(vmax, self._get(0x60FF))))
            self.cyclic_target = round(target)
            accel = abs(target - v) / (period * NS) if period else 1e12  # 0: a step
            self.segments = prof.ramp(now, p, v, target, max(1.0, accel))
            end = prof.end_time(self.segments)
        else:
            max_torque = self._get(0x6072)
            self.torque_target = float(max(-max_torque, min(max_torque, self._get(0x6071))))
            self.cyclic_target = round(self.torque_target)
            self.torque_from, self.torque_since_ns = self.torque_target, now
            torque_nm = self.torque_target / 1000 * self.rated_torque
            accel = torque_nm / self.inertia * self._counts_per_rad()
            self.segments = prof.accelerate(now, p, v, accel, float(self._get(0x6080)))
            end = now
        self.arrival_ns = end if end > now else None
        self.target_reached = self.arrival_ns is None
