"""DynamixelServo: one Dynamixel X-series servo on a :class:`DynamixelPort`, as an actuator.

Control modes (Operating Mode, address 11, written with the torque disabled as the
servo requires):

* ``POSITION`` -> position mode 3 (or ``position_mode``: extended 4, current-based 5);
  Goal Position (116) in ticks, 4096 per turn, tick 2048 = 0 rad.
* ``VELOCITY`` -> velocity mode 1; Goal Velocity (104), 0.229 rpm per unit.
* ``TORQUE`` -> current mode 0; Goal Current (102) = torque / ``torque_constant``,
  2.69 mA per unit (XM430). Only with a ``torque_constant`` (Nm/A): otherwise TORQUE is
  not in ``supported_requests`` and ``set_value`` raises NOT_IMPLEMENTED.
* ``NO_EXCITE`` -> Torque Enable (64) = 0 (HAL4RT's READY_TO_CONTROL); the next command
  enables it again.

A mode change resets the servo's Profile Velocity (112) and Profile Acceleration (108) to
0 (e-manual, Operating Mode (11)): the driver writes its profile again after each one.

``Motor.set_speed(speed, tm_acc)`` uses the servo's own ramp (``velocity_ramp``): velocity
mode, Profile Acceleration = |target - start| / tm_acc (214.577 rev/min^2 per unit), then
Goal Velocity; the next other command restores the configured Profile Acceleration.

Every value crossing the API is SI (rad, rad/s, Nm). Limits come from the control
table (Min/Max Position Limit, Velocity Limit, Current Limit) unless given.

Completion (``reports_completion = True``): the port's poller hands the servo its
present values every cycle. A target counts as reached only on a poll sent *after*
the goal write was acknowledged (its transaction number is larger), so the stale
"not moving" a servo reports right after a write never completes a new move:

* position: Moving (122) = 0 and |present - goal| <= ``position_tolerance``;
* velocity: |present velocity - goal| <= ``velocity_tolerance``;
* torque: |present current - goal| <= ``torque_tolerance``.

A new command drops the pending completion of the previous one before it is sent.
Actual values (``read``) are served from the latest poll.

Safety (:mod:`openel_async.safety`; a servo is a ``Watchdog`` and an ``EmergencyStop``):

* ``arm_watchdog(timeout_s)`` writes Bus Watchdog (98) = timeout / 20 ms (a multiple of
  20 ms in 0.02..2.54 s, firmware >= 38; the port's ``poll_period`` must be below half the
  timeout). The port's poller, a task of the event loop, feeds it: when the loop stalls
  for longer than the timeout the servo stops by itself (Goal values ignored, torque kept,
  98 reads -1). The trip is found when the loop resumes (the late poll is followed by a
  read of 98, or a goal write is refused with Data Range Error) and the component goes to
  Error with ``ErrorId.WATCHDOG``; ``re_init`` writes 0 (clears it), holds the present
  position and arms it again. Init clears a Bus Watchdog Error left by an earlier run.
* ``estop()``: Torque Enable (64) = 0 at once (a SYNC WRITE ahead of queued transactions;
  :meth:`DynamixelPort.estop` does every servo of a port in one packet), the component goes
  to Error with ``ErrorId.ESTOP``; ``re_init`` enables the torque again, holding the
  present position.
* ``safe_stop(action)``: ``HOLD`` and ``STOP`` hold the present position with the torque on
  (Goal Position = present position, in position mode -- switched to it, with the torque
  briefly off as the servo requires, from velocity or current mode); the servo has no
  separate braking command: a position goal at the present position while moving makes
  its profile brake at Profile Acceleration and settle on that point. ``STOP`` in
  velocity mode writes Goal Velocity 0 instead (braking at Profile Acceleration).
  ``TORQUE_OFF`` writes Torque Enable 0. An e-stopped servo keeps its torque off; a servo
  stopped by its Bus Watchdog is left as it is (its goals are read-only) unless the action
  is ``TORQUE_OFF``.
"""

from __future__ import annotations

import math
from typing import ClassVar, Final

import anyio

from openel_async.device import ActuatorLimits, DeviceInfo, ErrorId, VelocityRamp
from openel_async.errors import (
    BadParameterError,
    HALError,
    NotImplementedHALError,
)
from openel_async.ids import DeviceKind
from openel_async.requests import Request
from openel_async.safety import ExitAction
from openel_serial import dynamixel as dx
from openel_serial.errors import (
    DynamixelHardwareAlert,
    DynamixelStatusError,
    DynamixelTimeoutError,
)
from openel_serial.halfduplex import positive, positive_or_none
from openel_serial.port import POLL_ADDRESS, POLL_LENGTH, DynamixelPort, PresentState
from openel_serial.servobase import (
    LINK_ERRORS,
    BusServo,
    Pending,
    check_position_limits,
    check_servo_id,
)

__all__ = [
    "MAX_PROFILE_ACCELERATION",
    "ROBOTIS_VENDOR_ID",
    "DynamixelServo",
    "DynamixelXL430W250",
    "DynamixelXM430W350",
    "profile_acceleration_for",
]

X = dx.XSeries
RAD_PER_TICK: Final = 2 * math.pi / dx.TICKS_PER_REV
TABLE_LENGTH: Final = X.HARDWARE_ERROR_STATUS.address + 1  # addresses 0..70 in one READ
EXTENDED_RANGE_REV: Final = 256
ROBOTIS_VENDOR_ID: Final = 0x524F
"""This project's vendor id for ROBOTIS ("RO"): neither OpenEL nor HAL4RT registers one."""
MAX_PROFILE_ACCELERATION: Final = 32767
"""Largest Profile Acceleration (108) of a velocity-based profile (e-manual)."""
TIME_BASED_PROFILE: Final = 0x04
"""Drive Mode (10) bit 2: Profile Velocity/Acceleration are times, not rates."""
_POSITION_MODES: Final = (
    dx.OperatingMode.POSITION,
    dx.OperatingMode.EXTENDED_POSITION,
    dx.OperatingMode.CURRENT_BASED_POSITION,
)


def profile_acceleration_for(ramp: VelocityRamp) -> int:
    """Profile Acceleration (108) for ``ramp``: ``ramp.rate`` in 214.577 rev/min^2 units.

    At least 1 (0 would be "unlimited"); a rate above 32767 units (~12,270 rad/s^2) gives
    0, the servo's fastest change, which is over in less than |target - start| / 12,270 s.
    """
    units = ramp.rate / dx.acceleration_to_rad_s2(1)
    if units > MAX_PROFILE_ACCELERATION:
        return 0
    return max(1, round(units))


class DynamixelServo(BusServo[DynamixelPort, PresentState]):
    """A Dynamixel Protocol 2.0 X-series servo (XM430, XL430, ...) on a shared port.

    ``port`` must be entered (``async with port``) before the component is. Options
    are SI: ``position_limits`` (rad), ``velocity_limit`` (rad/s), ``torque_constant``
    (Nm/A), ``profile_velocity`` (rad/s) and ``profile_acceleration`` (rad/s^2) written
    to the RAM profile items at init (None keeps the servo's values), tolerances for
    completion. ``reboot_on_alert``: init/re_init reboot a servo reporting a hardware
    error (the only way to clear it) instead of failing.
    """

    info = DeviceInfo(
        kind=DeviceKind.MOTOR,
        vendor_id=ROBOTIS_VENDOR_ID,
        vendor_name="Robotis",
        product_name="Dynamixel",
        functions=("reboot",),
    )
    """Product id 0: any X-series model (the model number is known after PING). The
    model classes (:class:`DynamixelXM430W350`...) carry the model number as product id
    and are the ones in the Device Kind ID registry."""
    log_prefix: ClassVar[str] = "dynamixel"
    watchdog_keeps_torque: ClassVar[bool] = True
    velocity_ramp = True
    """Profile Acceleration in velocity mode; False on an instance whose servo uses a
    time-based profile (Drive Mode bit 2): the framework streams the ramp then."""
    has_current: ClassVar[bool] = True
    """Whether the model has current control (Goal/Present Current); XL430: no."""

    def __init__(
        self,
        port: DynamixelPort,
        dxl_id: int,
        *,
        position_limits: tuple[float, float] | None = None,
        velocity_limit: float | None = None,
        torque_constant: float | None = None,
        current_unit: float = dx.CURRENT_UNIT_A,
        profile_velocity: float | None = None,
        profile_acceleration: float | None = None,
        position_tolerance: float = 4 * RAD_PER_TICK,
        velocity_tolerance: float = 0.05,
        torque_tolerance: float = 0.05,
        position_mode: dx.OperatingMode = dx.OperatingMode.POSITION,
        reboot_on_alert: bool = True,
        reboot_timeout: float = 2.0,
        torque_off_on_close: bool = False,
    ) -> None:
        if not isinstance(port, DynamixelPort):
            raise BadParameterError("port", port, "a DynamixelPort")
        check_servo_id("dxl_id", dxl_id, dx.MAX_ID)
        if position_mode not in _POSITION_MODES:
            raise BadParameterError(
                "position_mode",
                position_mode,
                "POSITION, EXTENDED_POSITION or CURRENT_BASED_POSITION",
            )
        check_position_limits(position_limits)
        if torque_constant is not None and not self.has_current:
            raise BadParameterError(
                "torque_constant",
                torque_constant,
                f"None: the {self.info.product_name} has no current control mode",
            )
        super().__init__(port, dxl_id, torque_off_on_close=torque_off_on_close)
        self.position_limits = position_limits
        self.velocity_limit = positive_or_none("velocity_limit", velocity_limit)
        self.torque_constant = positive_or_none("torque_constant", torque_constant)
        self.current_unit = positive("current_unit", current_unit)
        self.profile_velocity = positive_or_none("profile_velocity", profile_velocity)
        self.profile_acceleration = positive_or_none("profile_acceleration", profile_acceleration)
        self.position_tolerance = positive("position_tolerance", position_tolerance)
        self.velocity_tolerance = positive("velocity_tolerance", velocity_tolerance)
        self.torque_tolerance = positive("torque_tolerance", torque_tolerance)
        self.position_mode = dx.OperatingMode(position_mode)
        self.reboot_on_alert = reboot_on_alert
        self.reboot_timeout = positive("reboot_timeout", reboot_timeout)
        requests = {Request.NO_EXCITE, Request.POSITION, Request.VELOCITY}
        if self.torque_constant is not None:
            requests.add(Request.TORQUE)
        self.supported_requests = frozenset(requests)
        # Raw tolerances (control-table units).
        self._tol_ticks = self.position_tolerance / RAD_PER_TICK
        self._tol_velocity = self.velocity_tolerance / dx.velocity_to_rad_s(1)
        kt = self.torque_constant
        self._tol_current = self.torque_tolerance / (kt * self.current_unit) if kt else math.inf
        # Device state.
        self._drive_mode = 0
        self._profile_acc: int | None = None
        """Profile Acceleration on the servo as last written (None: unknown)."""
        self._profile_vel: int | None = None
        self._base_acc: int | None = None
        """The configured Profile Acceleration (``profile_acceleration``, or the servo's at
        the first init): restored after a mode change and after a ramp."""
        self._base_vel: int | None = None
        self._alert = False
        self._status_error_reported = False
        self.model_number: int | None = None
        self.firmware_version: int | None = None
        self._watchdog_units: int | None = None
        """Bus Watchdog (98) setting while armed (None: not armed by us)."""

    # -- identity --------------------------------------------------------------------
    @property
    def dxl_id(self) -> int:
        return self._servo_id

    # -- lifecycle -------------------------------------------------------------------
    async def identify(self) -> None:
        info = await self.port.ping(self._servo_id)
        self.model_number, self.firmware_version = info.model_number, info.firmware_version
        expected = self.info.product_id
        if expected and info.model_number != expected:
            raise HALError(
                f"servo {self._servo_id} is model {info.model_number}, not the "
                f"{self.info.product_name} (model number {expected})"
            )

    def opened_fields(self) -> dict[str, object]:
        return {
            "model": self.model_number,
            "firmware": self.firmware_version,
            "mode": self._mode,
            "torque": self._torque,
            "alert": self._alert,
        }

    async def torque_off(self) -> None:
        await self._write(X.TORQUE_ENABLE, 0)

    async def reboot(self) -> None:
        """REBOOT the servo (clears a hardware error) and wait until it answers PING.

        The servo restarts with its RAM at the defaults: torque off, profile and goals
        reset. Polling resumes if it was on; ``re_init`` (or init) enables the torque
        again. Raises ``TimeoutError`` if the servo is not back within ``reboot_timeout``.
        """
        polled, self._polled = self._polled, False
        self._pending = None
        await self.port.reboot(self._servo_id)
        with anyio.fail_after(self.reboot_timeout):
            while True:
                try:
                    await self.port.ping(self._servo_id)
                    break
                except DynamixelTimeoutError:
                    continue  # still booting (each PING waited its timeout)
        await self.load_table()
        await self.refresh_state()
        if self._watchdog_units is not None:  # RAM reset: arm it again
            await self._write(X.BUS_WATCHDOG, self._watchdog_units)
        if polled and not self._alert:
            self._polled = True
            self.port.wake_poller()

    # -- commands --------------------------------------------------------------------
    async def command(self, request: Request, value: float) -> None:
        previous, self._pending = self._pending, None  # the old target's arrival no longer counts
        mode_before, torque_before = self._mode, self._torque
        try:
            if request is Request.NO_EXCITE:
                await self._write(X.TORQUE_ENABLE, 0)
                self._torque = False
                return
            item, raw, mode = self._goal(request, value)
            await self._apply(mode, item, raw)
        except DynamixelHardwareAlert as exc:
            self._fault_alert(exc)
            raise
        except DynamixelStatusError as exc:
            if await self._refused_by_watchdog(exc):
                raise
            if (self._mode, self._torque) == (mode_before, torque_before):
                self._pending = previous  # nothing changed on the servo
            self._log.warning("dynamixel_command_refused", error=str(exc))
            self.context().post_error(ErrorId.PROTOCOL_ERROR)
            raise
        except LINK_ERRORS:
            self.stop_polling()  # the component faults; stop polling until reset
            raise
        self._pending = Pending(request, raw, self.port.transactions)

    async def command_velocity_ramp(self, ramp: VelocityRamp) -> None:
        """The servo's own ramp: velocity mode, Profile Acceleration from ``ramp.rate``
        (:func:`profile_acceleration_for`), then Goal Velocity; the servo ramps from its
        present velocity. Completion: the present velocity within tolerance of the goal."""
        if not self.velocity_ramp:
            raise NotImplementedHALError(
                f"servo {self._servo_id} uses a time-based profile: no velocity ramp of its own"
            )
        item, raw, mode = self._goal(Request.VELOCITY, ramp.target)
        acceleration = profile_acceleration_for(ramp)
        self._pending = None
        try:
            await self._apply(mode, item, raw, acceleration)
        except DynamixelHardwareAlert as exc:
            self._fault_alert(exc)
            raise
        except DynamixelStatusError as exc:
            if await self._refused_by_watchdog(exc):
                raise
            self._log.warning("dynamixel_command_refused", error=str(exc))
            self.context().post_error(ErrorId.PROTOCOL_ERROR)
            raise
        except LINK_ERRORS:
            self.stop_polling()
            raise
        self._pending = Pending(Request.VELOCITY, raw, self.port.transactions)

    async def read(self, request: Request) -> float:
        self.port.check_connected()
        if request is Request.TORQUE_ACTUAL and self.torque_constant is None:
            raise NotImplementedHALError(
                f"servo {self._servo_id}: TORQUE_ACTUAL needs a torque_constant (Nm/A)"
            )
        state = await self.present()
        if request is Request.POSITION_ACTUAL:
            return dx.ticks_to_rad(state.position)
        if request is Request.VELOCITY_ACTUAL:
            return dx.velocity_to_rad_s(state.velocity)
        if request is Request.TORQUE_ACTUAL:
            assert self.torque_constant is not None
            return state.current * self.current_unit * self.torque_constant
        raise BadParameterError(
            "request", request, "POSITION_ACTUAL, VELOCITY_ACTUAL or TORQUE_ACTUAL"
        )

    # -- safety (openel_async.safety.Watchdog, EmergencyStop) ----------------------------
    @property
    def watchdog_timeout(self) -> float | None:
        """The armed Bus Watchdog timeout (s), or None."""
        units = self._watchdog_units
        return None if units is None else units * dx.BUS_WATCHDOG_UNIT_S

    async def arm_watchdog(self, timeout_s: float) -> None:
        """Bus Watchdog (98) = ``timeout_s`` / 20 ms, fed by the port's poller.

        Refused with :class:`BadParameterError` naming ``timeout_s`` unless it is a
        multiple of 20 ms in 0.02..2.54 s and more than twice the port's ``poll_period``;
        :class:`NotImplementedHALError` for a firmware older than v38 (no Bus Watchdog).
        """
        try:
            units = dx.bus_watchdog_units(timeout_s)
        except ValueError:
            raise BadParameterError(
                "timeout_s",
                timeout_s,
                f"a multiple of {dx.BUS_WATCHDOG_UNIT_S} s in {dx.BUS_WATCHDOG_UNIT_S}.."
                f"{dx.BUS_WATCHDOG_MAX * dx.BUS_WATCHDOG_UNIT_S:g} s (Bus Watchdog (98): "
                f"1..{dx.BUS_WATCHDOG_MAX} units of 20 ms)",
            ) from None
        firmware = self.firmware_version
        if firmware is not None and firmware < dx.BUS_WATCHDOG_FIRMWARE:
            raise NotImplementedHALError(
                f"servo {self._servo_id}: firmware v{firmware} has no Bus Watchdog "
                f"(v{dx.BUS_WATCHDOG_FIRMWARE} and later)"
            )
        self.port.arm_bus_watchdog(self._servo_id, units * dx.BUS_WATCHDOG_UNIT_S)
        try:
            await self._write(X.BUS_WATCHDOG, units)
        except BaseException:
            self.port.disarm_bus_watchdog(self._servo_id)
            raise
        self._watchdog_units = units
        self._log.info("dynamixel_bus_watchdog_armed", timeout_s=units * dx.BUS_WATCHDOG_UNIT_S)

    async def disarm_watchdog(self) -> None:
        """Bus Watchdog (98) = 0 (off; also clears a Bus Watchdog Error)."""
        self._watchdog_units = None
        self.port.disarm_bus_watchdog(self._servo_id)
        if self.port.connected:
            await self._write(X.BUS_WATCHDOG, 0)

    async def safe_stop(self, action: ExitAction) -> None:
        """Leave the servo in ``action``'s state (see the module docstring)."""
        action = ExitAction(action)
        self._pending = None
        if action is ExitAction.TORQUE_OFF:
            await self._write(X.TORQUE_ENABLE, 0)
            self._torque = False
        elif self._estop_active or self._alert or not self._torque:
            pass  # torque off (e-stop, hardware error, NO_EXCITE): keep it off
        elif await self._read_watchdog() == dx.BUS_WATCHDOG_ERROR:
            pass  # stopped and holding by itself; goals are read-only
        elif action is ExitAction.STOP and self._mode == dx.OperatingMode.VELOCITY:
            await self._write(X.GOAL_VELOCITY, 0)
        else:
            state = await self.refresh_state()
            await self._apply(self.position_mode, X.GOAL_POSITION, state.position)
        self._log.info("dynamixel_safe_stop", action=str(action), torque=self._torque)

    async def _read_watchdog(self) -> int:
        return await self.port.read_item(self._servo_id, X.BUS_WATCHDOG, check_alert=False)

    async def _refused_by_watchdog(self, exc: DynamixelStatusError) -> bool:
        """Whether a refused goal write was refused because the Bus Watchdog expired
        (then the component faults with ``ErrorId.WATCHDOG``)."""
        if exc.error_number != dx.ErrorNumber.DATA_RANGE_ERROR or self._watchdog_units is None:
            return False
        try:
            tripped = await self._read_watchdog() == dx.BUS_WATCHDOG_ERROR
        except (HALError, *LINK_ERRORS):
            return False
        if tripped:
            self._watchdog_tripped(
                f"servo {self._servo_id}: Bus Watchdog expired (goal refused: {exc}): "
                "the servo stopped by itself"
            )
        return tripped

    # -- poller callbacks (called by the port) ------------------------------------------
    def _poll_update(self, state: PresentState) -> None:
        self._state = state
        self._status_error_reported = False
        self.complete_if_reached(state)

    def reached(self, pending: Pending, state: PresentState) -> bool:
        if pending.request is Request.POSITION:
            return not state.moving and abs(state.position - pending.goal) <= self._tol_ticks
        if pending.request is Request.VELOCITY:
            return abs(state.velocity - pending.goal) <= self._tol_velocity
        return abs(state.current - pending.goal) <= self._tol_current

    def _poll_status_error(self, error: DynamixelStatusError) -> None:
        if not self._status_error_reported:  # once per run of refused polls
            self._status_error_reported = True
            self._log.warning("dynamixel_poll_refused", error=str(error))
            self.context().post_error(ErrorId.PROTOCOL_ERROR)

    def _hardware_alert(self, error: DynamixelHardwareAlert) -> None:
        if self._polled:
            self._fault_alert(error)

    def _fault_alert(self, error: DynamixelHardwareAlert) -> None:
        self._alert = True
        self._polled = False
        self._pending = None
        self._torque = False  # the servo shut its torque down
        self.context().fault(ErrorId.DEVICE_ERROR, str(error))

    async def _write(self, item: dx.ControlItem, value: int) -> None:
        await self.port.write_item(self._servo_id, item, value, ack=self._ack_writes)

    async def load_table(self) -> None:
        """Read addresses 0..70 (EEPROM, torque, status return level, hardware error)."""
        try:
            table = await self.port.read(self._servo_id, 0, TABLE_LENGTH, check_alert=False)
        except DynamixelTimeoutError as exc:
            raise DynamixelTimeoutError(
                exc.port,
                exc.ids,
                exc.request + " (Status Return Level 0?)",
                exc.timeout,
                exc.attempts,
            ) from exc

        def item(it: dx.ControlItem) -> int:
            return it.decode(table[it.address : it.address + it.size])

        self._mode = item(X.OPERATING_MODE)
        self._drive_mode = item(X.DRIVE_MODE)
        self.velocity_ramp = not self._drive_mode & TIME_BASED_PROFILE
        self._profile_acc = self._profile_vel = None  # RAM: read or written at init
        self._torque = bool(item(X.TORQUE_ENABLE))
        self._ack_writes = item(X.STATUS_RETURN_LEVEL) >= 2
        self._alert = item(X.HARDWARE_ERROR_STATUS) != 0
        self.check_return_delay(item(X.RETURN_DELAY_TIME) * dx.RETURN_DELAY_UNIT_S)
        if self.position_limits is not None:
            position = self.position_limits
        elif self.position_mode is dx.OperatingMode.EXTENDED_POSITION:
            span = EXTENDED_RANGE_REV * 2 * math.pi
            position = (-span, span)
        else:
            position = (
                dx.ticks_to_rad(item(X.MIN_POSITION_LIMIT)),
                dx.ticks_to_rad(item(X.MAX_POSITION_LIMIT)),
            )
        velocity_units = item(X.VELOCITY_LIMIT)
        velocity = self.velocity_limit or (
            dx.velocity_to_rad_s(velocity_units) if velocity_units else math.inf
        )
        torque = math.inf
        if self.torque_constant is not None:
            torque = item(X.CURRENT_LIMIT) * self.current_unit * self.torque_constant or math.inf
        self.limits = ActuatorLimits(position, velocity, torque)

    async def refresh_state(self) -> PresentState:
        data = await self.port.read(self._servo_id, POLL_ADDRESS, POLL_LENGTH, check_alert=False)
        state = PresentState.decode(data, self.port.transactions, self.port.clock.now_ns())
        self._state = state
        return state

    async def make_operational(self) -> None:
        """Clear a hardware error and a Bus Watchdog Error, write the profile, hold the
        present position, torque on, arm the Bus Watchdog again if it was armed."""
        await self.port.reconnect()
        if self._alert:
            if not self.reboot_on_alert:
                hardware = await self.port.read_item(
                    self._servo_id, X.HARDWARE_ERROR_STATUS, check_alert=False
                )
                raise DynamixelHardwareAlert(self._servo_id, dx.ALERT_BIT, "init", hardware)
            self._log.warning("dynamixel_rebooting_after_alert")
            await self.reboot()
            if self._alert:
                raise DynamixelHardwareAlert(self._servo_id, dx.ALERT_BIT, "reboot", None)
        firmware = self.firmware_version
        has_watchdog = firmware is None or firmware >= dx.BUS_WATCHDOG_FIRMWARE
        watchdog = await self._read_watchdog() if has_watchdog else 0
        if watchdog == dx.BUS_WATCHDOG_ERROR or (watchdog and self._watchdog_units is None):
            # Expired (goals are read-only until 0 is written), or armed by an earlier run.
            self._log.warning("dynamixel_bus_watchdog_cleared", value=watchdog)
            await self._write(X.BUS_WATCHDOG, 0)
            watchdog = 0
        if self._base_acc is None or self._base_vel is None:
            data = await self.port.read(self._servo_id, X.PROFILE_ACCELERATION.address, 8)
            self._profile_acc = X.PROFILE_ACCELERATION.decode(data[:4])
            self._profile_vel = X.PROFILE_VELOCITY.decode(data[4:])
            self._base_acc, self._base_vel = self._profile_acc, self._profile_vel
        if self.profile_velocity is not None:
            self._base_vel = dx.rad_s_to_velocity(self.profile_velocity)
        if self.profile_acceleration is not None:
            self._base_acc = dx.rad_s2_to_acceleration(self.profile_acceleration)
        state = await self.refresh_state()
        self._pending = None
        # Writes the profile too (and again after a mode change, which resets it).
        await self._apply(self.position_mode, X.GOAL_POSITION, state.position)
        self._estop_active = False
        if self._watchdog_units is not None and watchdog != self._watchdog_units:
            await self._write(X.BUS_WATCHDOG, self._watchdog_units)
        self.resume_polling()

    def _goal(self, request: Request, value: float) -> tuple[dx.ControlItem, int, int]:
        if request is Request.POSITION:
            item, raw, mode = X.GOAL_POSITION, dx.rad_to_ticks(value), int(self.position_mode)
        elif request is Request.VELOCITY:
            item, raw, mode = (
                X.GOAL_VELOCITY,
                dx.rad_s_to_velocity(value),
                int(dx.OperatingMode.VELOCITY),
            )
        elif request is Request.TORQUE and self.torque_constant is not None:
            raw = round(value / self.torque_constant / self.current_unit)
            item, mode = X.GOAL_CURRENT, int(dx.OperatingMode.CURRENT)
        else:
            raise NotImplementedHALError(f"servo {self._servo_id} does not support {request.name}")
        try:
            item.encode(raw)
        except ValueError:
            raise BadParameterError("value", value, f"a target within the {item} range") from None
        return item, raw, mode

    async def _write_profile(self, acceleration: int | None, velocity: int | None) -> None:
        """Write Profile Acceleration/Velocity where they differ from the servo's."""
        if acceleration is not None and acceleration != self._profile_acc:
            self._profile_acc = None  # unknown until acknowledged
            await self._write(X.PROFILE_ACCELERATION, acceleration)
            self._profile_acc = acceleration
        if velocity is not None and velocity != self._profile_vel:
            self._profile_vel = None
            await self._write(X.PROFILE_VELOCITY, velocity)
            self._profile_vel = velocity

    async def _apply(
        self, mode: int, item: dx.ControlItem, raw: int, acceleration: int | None = None
    ) -> None:
        """Switch the operating mode if needed (torque off first), write the profile
        (``acceleration``, else the configured one), the goal, torque on -- refused while
        e-stopped, also when the e-stop comes between two of these writes."""
        self.check_not_estopped()
        if self._mode != mode:
            if self._torque:
                await self._write(X.TORQUE_ENABLE, 0)
                self._torque = False
            await self._write(X.OPERATING_MODE, mode)
            self._mode = mode
            self._profile_acc = self._profile_vel = 0  # the servo reset them (e-manual)
        position = mode in _POSITION_MODES
        await self._write_profile(
            self._base_acc if acceleration is None else acceleration,
            self._base_vel if position else None,
        )
        await self._write(item, raw)
        if not self._torque:
            self.check_not_estopped()
            await self._write(X.TORQUE_ENABLE, 1)
            self._torque = True


class DynamixelXM430W350(DynamixelServo):
    """An XM430-W350 (model number 1020): current control; TORQUE with a ``torque_constant``.

    The e-manual's stall figures give about 1.78 Nm/A (4.1 Nm at 2.3 A, 12 V) as a guide;
    measure it for torque control that matters.
    """

    info = DeviceInfo(
        kind=DeviceKind.MOTOR,
        vendor_id=ROBOTIS_VENDOR_ID,
        product_id=1020,
        vendor_name="Robotis",
        product_name="XM430W350",
        functions=("reboot",),
    )


class DynamixelXL430W250(DynamixelServo):
    """An XL430-W250 (model number 1060): no current control mode, so no TORQUE
    (a ``torque_constant`` is refused) and no TORQUE_ACTUAL."""

    info = DeviceInfo(
        kind=DeviceKind.MOTOR,
        vendor_id=ROBOTIS_VENDOR_ID,
        product_id=1060,
        vendor_name="Robotis",
        product_name="XL430W250",
        functions=("reboot",),
    )
    has_current = False
