"""FeetechServo: one Feetech STS servo (STS3215) on a :class:`FeetechPort`, as an actuator.

The same public shape as :class:`~openel_serial.servo.DynamixelServo` (a rig or an app treats
them alike). Control modes (Operating Mode, 33; a change turns the torque off first, and is
not kept at power-off since Lock stays 1):

* ``POSITION`` -> position mode 0: Acceleration (41), Goal Position (42), Goal Time (44) = 0 and
  Goal Speed (46) in one WRITE (the vendor's WritePosEx); steps, 4096 per turn, step 2048 =
  0 rad. ``speed`` (rad/s) and ``acceleration`` (rad/s^2) are the move's profile (None: the
  servo's fastest, 0 in both registers).
* ``VELOCITY`` -> wheel mode 1: Goal Speed (46), steps/s, sign-magnitude (bit 15), reached at
  ``acceleration``.
* ``NO_EXCITE`` -> Torque Enable (40) = 0; the next command enables it again.

``calibration`` (a :class:`~openel_serial.feetech_calibration.JointCalibration`, the entry
of a calibration file written by ``openel-async calibrate``; a serial bus with
``calibration: FILE`` gives it): at open the servo's Homing Offset (31) and Min/Max Angle Limits
(9, 11) are compared with the entry and, when they differ, written to its EEPROM (behind the
lock) -- only while its torque is off (a servo holding the arm is refused with
:class:`HALError` rather than let go or jump); the entry's range (in radians, intersected with
``position_limits`` when both are given) becomes the component's position limits, and
``drive_mode`` 1 reverses the direction (positions, speeds and load change sign about step
2048). The entry's ``id`` must be the ``servo_id``.

``gripper=True``: POSITION and POSITION_ACTUAL are the opening 0 (closed, the Min Angle Limit
or ``position_limits[0]``) .. 1 (open, the Max Angle Limit or ``position_limits[1]``), linear in
the angle, as the SO-101 model's gripper reads; VELOCITY is in openings per second.

Actual values come from the port's poller (one SYNC READ of 56..70 for every servo per cycle):
POSITION_ACTUAL, VELOCITY_ACTUAL and, with ``stall_torque`` (N m), TORQUE_ACTUAL = Present Load
(0.1 % of the stall torque) x ``stall_torque``; :attr:`FeetechServo.state` has them all (load,
voltage, temperature, current, the alarm bits). Completion as Dynamixel's: only a poll sent after
the goal write counts; position: Moving (66) = 0 and within ``position_tolerance``; velocity:
within ``velocity_tolerance``.

Alarms: a status whose alarm bits include one of the servo's Unloading Condition (19) (the
servo has turned its torque off: overheat, overcurrent, overload by default) faults the component
(``ErrorId.DEVICE_ERROR``); others (the supply voltage out of range) are posted once
(``post_error(DEVICE_ERROR)``). ``re_init`` enables the torque again when the alarm is gone
(raising :class:`~openel_serial.errors.FeetechStatusError` while it is in force).

Safety (:mod:`openel_async.safety`): the STS has no bus watchdog; ``arm_watchdog(timeout_s)``
arms the port's host watchdog (a thread that turns every servo's torque off when the poller has
not run for ``timeout_s``: a stalled event loop; see :mod:`openel_serial.feetech_port` for what
it cannot cover), a trip faults the component with ``ErrorId.WATCHDOG``. ``estop()``: Torque
Enable = 0 at once (``FeetechPort.estop`` does every servo with one broadcast), ``ErrorId.ESTOP``.
``safe_stop``: ``HOLD``/``STOP`` hold the present position with the torque on (``STOP`` in wheel
mode: Goal Speed 0), ``TORQUE_OFF`` turns the torque off; an e-stopped servo keeps it off.
"""

from __future__ import annotations

import math
from typing import ClassVar, Final

from openel_async.device import ActuatorLimits, DeviceInfo, ErrorId
from openel_async.errors import BadParameterError, HALError, NotImplementedHALError
from openel_async.ids import DeviceKind
from openel_async.requests import Request
from openel_async.safety import ExitAction
from openel_serial import feetech as ft
from openel_serial.errors import FeetechStatusError
from openel_serial.feetech_calibration import JointCalibration
from openel_serial.feetech_port import (
    POLL_ADDRESS,
    POLL_LENGTH,
    FeetechPort,
    FeetechPresentState,
)
from openel_serial.halfduplex import positive_or_none
from openel_serial.servobase import (
    LINK_ERRORS,
    BusServo,
    Pending,
    check_position_limits,
    check_servo_id,
)

__all__ = ["FEETECH_VENDOR_ID", "FeetechSTS3215", "FeetechServo"]

S = ft.STS
RAD_PER_TICK: Final = 2 * math.pi / ft.TICKS_PER_REV
FEETECH_VENDOR_ID: Final = 0x4654
"""This project's vendor id for Feetech ("FT"): neither OpenEL nor HAL4RT registers one."""
TABLE_LENGTH: Final = S.LOCK.address + 1  # 0..55 in one READ
STS3215_TOP_SPEED: Final = 3073 * RAD_PER_TICK
"""rad/s of an unloaded STS3215 at 7.4 V (0.222 s / 60 deg)."""


class FeetechServo(BusServo[FeetechPort, FeetechPresentState]):
    """A Feetech STS/SMS servo on a shared :class:`FeetechPort` (see the module docstring).

    ``port`` must be entered before the component is. ``position_limits`` (rad) override the
    Min/Max Angle Limits (9, 11); ``velocity_limit`` (rad/s) the model's top speed.
    """

    info = DeviceInfo(
        kind=DeviceKind.MOTOR,
        vendor_id=FEETECH_VENDOR_ID,
        vendor_name="Feetech",
        product_name="STS",
    )
    log_prefix: ClassVar[str] = "feetech"
    model_number: ClassVar[int] = 0
    """The Model Number (3) the class requires (0: any)."""
    top_speed: ClassVar[float] = STS3215_TOP_SPEED

    def __init__(
        self,
        port: FeetechPort,
        servo_id: int,
        *,
        position_limits: tuple[float, float] | None = None,
        velocity_limit: float | None = None,
        speed: float | None = None,
        acceleration: float | None = None,
        stall_torque: float | None = None,
        gripper: bool = False,
        calibration: JointCalibration | None = None,
        position_tolerance: float = 8 * RAD_PER_TICK,
        velocity_tolerance: float = 0.1,
        torque_off_on_close: bool = False,
    ) -> None:
        if not isinstance(port, FeetechPort):
            raise BadParameterError("port", port, "a FeetechPort")
        check_servo_id("servo_id", servo_id, ft.MAX_ID)
        check_position_limits(position_limits)
        if calibration is not None:
            if not isinstance(calibration, JointCalibration):
                raise BadParameterError(
                    "calibration",
                    calibration,
                    "a JointCalibration (an entry of a calibration file)",
                )
            if calibration.id != servo_id:
                raise BadParameterError(
                    "calibration", calibration, f"the calibration of servo {servo_id}"
                )
        super().__init__(port, servo_id, torque_off_on_close=torque_off_on_close)
        self.calibration = calibration
        self._sign = -1 if calibration is not None and calibration.drive_mode else 1
        self.position_limits = position_limits
        self.velocity_limit = positive_or_none("velocity_limit", velocity_limit)
        self.speed = positive_or_none("speed", speed)
        self.acceleration = positive_or_none("acceleration", acceleration)
        self.stall_torque = positive_or_none("stall_torque", stall_torque)
        self.gripper = bool(gripper)
        self.position_tolerance = float(
            positive_or_none("position_tolerance", position_tolerance) or 0
        )
        self.velocity_tolerance = float(
            positive_or_none("velocity_tolerance", velocity_tolerance) or 0
        )
        self.supported_requests = frozenset({Request.NO_EXCITE, Request.POSITION, Request.VELOCITY})
        self._speed_units = 0 if self.speed is None else max(1, ft.rad_s_to_speed(self.speed))
        acc = self.acceleration
        self._acc_units = (
            0
            if acc is None
            else max(1, min(254, round(acc / RAD_PER_TICK / ft.ACCELERATION_UNIT_STEPS_S2)))
        )
        self._span: tuple[float, float] = (-math.pi, math.pi)
        """The angle range (rad) the gripper's opening 0..1 maps onto."""
        self._unloading = 0
        self._alarm_reported = False
        self._watchdog_timeout: float | None = None
        self.present_model: int | None = None

    @property
    def watchdog_timeout(self) -> float | None:
        return self._watchdog_timeout

    # -- units -----------------------------------------------------------------------
    def _to_ticks(self, value: float) -> int:
        if self.gripper:
            low, high = self._span
            value = low + value * (high - low)
        return ft.rad_to_ticks(self._sign * value)

    def _from_ticks(self, ticks: int) -> float:
        rad = self._sign * ft.ticks_to_rad(ticks)
        if self.gripper:
            low, high = self._span
            return (rad - low) / (high - low)
        return rad

    def _speed_scale(self) -> float:
        """rad/s (or openings/s for a gripper) per step/s."""
        if self.gripper:
            low, high = self._span
            return self._sign * RAD_PER_TICK / (high - low)
        return self._sign * RAD_PER_TICK

    # -- lifecycle -------------------------------------------------------------------
    async def identify(self) -> None:
        info = await self.port.ping(self._servo_id)
        self.present_model = info.model_number
        if self.model_number and info.model_number != self.model_number:
            raise HALError(
                f"servo {self._servo_id} is model {info.model_number}, not the "
                f"{self.info.product_name} (model number {self.model_number})"
            )

    def opened_fields(self) -> dict[str, object]:
        return {"model": self.present_model, "mode": self._mode}

    async def torque_off(self) -> None:
        await self._write(S.TORQUE_ENABLE, 0)

    async def load_table(self) -> None:
        table = await self.port.read(self._servo_id, 0, TABLE_LENGTH)

        def item(it: ft.ControlItem) -> int:
            return it.of(table, 0)

        self._mode = item(S.OPERATING_MODE)
        self._torque = bool(item(S.TORQUE_ENABLE))
        self._ack_writes = item(S.RESPONSE_STATUS_LEVEL) >= 1
        self._unloading = item(S.UNLOADING_CONDITION)
        self.check_return_delay(item(S.RETURN_DELAY) * ft.RETURN_DELAY_UNIT_S)
        low_ticks, high_ticks = item(S.MIN_ANGLE_LIMIT), item(S.MAX_ANGLE_LIMIT)
        cal = self.calibration
        if cal is not None:
            await self._apply_calibration(cal, table)
            span = cal.radians()
            if self.position_limits is not None:
                span = (
                    max(span[0], self.position_limits[0]),
                    min(span[1], self.position_limits[1]),
                )
                if span[0] >= span[1]:
                    raise BadParameterError(
                        "position_limits",
                        self.position_limits,
                        f"limits that overlap the calibrated range {cal.radians()}",
                    )
        elif self.position_limits is not None:
            span = self.position_limits
        elif low_ticks < high_ticks:
            span = (ft.ticks_to_rad(low_ticks), ft.ticks_to_rad(high_ticks))
        else:
            span = (-math.pi, math.pi)
        self._span = (float(span[0]), float(span[1]))
        velocity = self.velocity_limit or self.top_speed
        torque = self.stall_torque or math.inf
        if self.gripper:
            width = self._span[1] - self._span[0]
            self.limits = ActuatorLimits((0.0, 1.0), velocity / width, torque)
        else:
            self.limits = ActuatorLimits(self._span, velocity, torque)

    async def _apply_calibration(self, cal: JointCalibration, table: bytes) -> None:
        """Write the entry's homing offset and angle limits where the servo's differ (torque
        off only)."""
        writes = [
            (it, value)
            for it, value in (
                (S.HOMING_OFFSET, cal.homing_offset),
                (S.MIN_ANGLE_LIMIT, cal.range_min),
                (S.MAX_ANGLE_LIMIT, cal.range_max),
            )
            if it.of(table, 0) != value
        ]
        if not writes:
            return
        differ = ", ".join(f"{it.address}: {it.of(table, 0)} -> {v}" for it, v in writes)
        if self._torque:
            raise HALError(
                f"servo {self._servo_id}: its calibration differs from the file's ({differ}) "
                "and its torque is on: turn it off (power cycle) to have it written, or run "
                "openel-async calibrate"
            )
        await self.port.write_eeprom(self._servo_id, writes)
        self._log.warning("feetech_calibration_written", registers=differ)

    async def refresh_state(self) -> FeetechPresentState:
        data = await self.port.read(self._servo_id, POLL_ADDRESS, POLL_LENGTH)
        state = FeetechPresentState.decode(data, self.port.transactions, self.port.clock.now_ns())
        self._state = state
        return state

    async def make_operational(self) -> None:
        """Hold the present position in position mode with the torque on (refused while an
        unloading alarm is in force)."""
        await self.port.reconnect()
        state = await self.refresh_state()
        alarms = state.status & self._unloading
        if alarms:
            raise FeetechStatusError(
                self._servo_id, alarms, "init", "the alarm is still in force: torque stays off"
            )
        self._pending = None
        await self._apply_position(state.position)
        self._alarm_reported = False
        self.resume_polling()

    # -- commands --------------------------------------------------------------------
    async def _write(self, item: ft.ControlItem, value: int) -> None:
        await self.port.write_item(self._servo_id, item, value, ack=self._ack_writes)

    async def _set_mode(self, mode: int) -> None:
        if self._mode == mode:
            return
        if self._torque:
            await self._write(S.TORQUE_ENABLE, 0)
            self._torque = False
        await self._write(S.OPERATING_MODE, mode)
        self._mode = mode

    async def _torque_on(self) -> None:
        if not self._torque:
            self.check_not_estopped()  # an e-stop that came during this command
            await self._write(S.TORQUE_ENABLE, 1)
            self._torque = True

    async def _apply_position(self, ticks: int) -> None:
        await self._set_mode(ft.OperatingMode.POSITION)
        block = (
            bytes((self._acc_units,))
            + S.GOAL_POSITION.encode(ticks)
            + S.GOAL_TIME.encode(0)
            + S.GOAL_SPEED.encode(self._speed_units)
        )
        await self.port.write(self._servo_id, S.ACCELERATION.address, block, ack=self._ack_writes)
        await self._torque_on()

    async def _apply_speed(self, speed: int) -> None:
        await self._set_mode(ft.OperatingMode.WHEEL)
        block = bytes((self._acc_units,)) + bytes(4) + S.GOAL_SPEED.encode(speed)
        await self.port.write(self._servo_id, S.ACCELERATION.address, block, ack=self._ack_writes)
        await self._torque_on()

    async def command(self, request: Request, value: float) -> None:
        self._pending = None
        try:
            if request is Request.NO_EXCITE:
                await self._write(S.TORQUE_ENABLE, 0)
                self._torque = False
                return
            self.check_not_estopped()
            if request is Request.POSITION:
                raw = self._to_ticks(value)
                if not 0 <= raw < 1 << 15:
                    raise BadParameterError("value", value, "a position the servo can reach")
                await self._apply_position(raw)
            elif request is Request.VELOCITY:
                raw = round(value / self._speed_scale())
                if abs(raw) >= 1 << 15:
                    raise BadParameterError("value", value, "a speed below 32767 steps/s")
                await self._apply_speed(raw)
            else:
                raise NotImplementedHALError(
                    f"servo {self._servo_id} does not support {request.name}"
                )
        except LINK_ERRORS:
            self.stop_polling()
            raise
        self._pending = Pending(request, raw, self.port.transactions)

    async def read(self, request: Request) -> float:
        state = await self.present()
        if request is Request.POSITION_ACTUAL:
            return self._from_ticks(state.position)
        if request is Request.VELOCITY_ACTUAL:
            return state.speed * self._speed_scale()
        if request is Request.TORQUE_ACTUAL:
            if self.stall_torque is None:
                raise NotImplementedHALError(
                    f"servo {self._servo_id}: TORQUE_ACTUAL needs a stall_torque (N m)"
                )
            return self._sign * state.load * ft.LOAD_UNIT * self.stall_torque
        raise BadParameterError(
            "request", request, "POSITION_ACTUAL, VELOCITY_ACTUAL or TORQUE_ACTUAL"
        )

    # -- safety ----------------------------------------------------------------------
    async def arm_watchdog(self, timeout_s: float) -> None:
        """Arm the port's host watchdog (see the module docstring) with ``timeout_s``."""
        if isinstance(timeout_s, bool) or not isinstance(timeout_s, int | float):
            raise BadParameterError("timeout_s", timeout_s, "a number of seconds")
        self.port.arm_host_watchdog(self._servo_id, float(timeout_s))
        self._watchdog_timeout = float(timeout_s)
        self._log.info("feetech_host_watchdog_armed", timeout_s=timeout_s)

    async def disarm_watchdog(self) -> None:
        self._watchdog_timeout = None
        self.port.disarm_host_watchdog(self._servo_id)

    async def safe_stop(self, action: ExitAction) -> None:
        action = ExitAction(action)
        self._pending = None
        if action is ExitAction.TORQUE_OFF:
            await self._write(S.TORQUE_ENABLE, 0)
            self._torque = False
        elif self._estop_active or not self._torque:
            pass  # torque off (e-stop, alarm, NO_EXCITE, host watchdog): keep it off
        elif action is ExitAction.STOP and self._mode == ft.OperatingMode.WHEEL:
            await self._apply_speed(0)
        else:
            state = await self.refresh_state()
            await self._apply_position(state.position)
        self._log.info("feetech_safe_stop", action=str(action), torque=self._torque)

    # -- poller callbacks --------------------------------------------------------------
    def _poll_update(self, state: FeetechPresentState) -> None:
        self._state = state
        alarms = state.error | state.status
        if alarms & self._unloading and self._polled:
            self._torque = False
            self.fault(
                ErrorId.DEVICE_ERROR,
                str(FeetechStatusError(self._servo_id, alarms, "poll", "torque unloaded")),
            )
            return
        if alarms and not self._alarm_reported:
            self._alarm_reported = True
            self._log.warning("feetech_alarm", alarms=ft.StatusError(alarms).describe())
            self.context().post_error(ErrorId.DEVICE_ERROR)
        elif not alarms:
            self._alarm_reported = False
        self.complete_if_reached(state)

    def reached(self, pending: Pending, state: FeetechPresentState) -> bool:
        if pending.request is Request.POSITION:
            return not state.moving and abs(state.position - pending.goal) <= (
                self.position_tolerance / RAD_PER_TICK
            )
        return abs(state.speed - pending.goal) <= self.velocity_tolerance / self._speed_scale()


class FeetechSTS3215(FeetechServo):
    """An STS3215 (model number 777): the SO-100/SO-101 arm's servo; 4096 steps per turn,
    ~1.9 N m stall torque at 7.4 V (2.9 N m for the 12 V version)."""

    info = DeviceInfo(
        kind=DeviceKind.MOTOR,
        vendor_id=FEETECH_VENDOR_ID,
        product_id=ft.STS3215_MODEL,
        vendor_name="Feetech",
        product_name="STS3215",
    )
    model_number = ft.STS3215_MODEL
