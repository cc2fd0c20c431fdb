"""Motor: HAL4RT's Motor (§7.4.5.3-7.4.5.4) over the same Actuator, seen through its names.

``Motor`` *is* an :class:`Actuator`: ``set_position(p)`` is ``set_value`` of a position in
the motor's scale and origin, returns the same :class:`Motion` at once, and completion is
the same event 1. ``set_value``/``get_value``/banks stay in the device's SI frame; only the
HAL4RT names apply the scale factor and the origin.

Control modes (Fig. 7.10, inside Active): Wait (``READY_TO_CONTROL``, not excited),
Position, Speed, Torque. ``set_position``/``set_speed``/``set_torque`` (and ``set_value``)
switch the mode; ``NO_EXCITE`` goes to Wait; the mode is Wait before the first command
and after each transition to Active (``init``, ``re_init``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

from .actuator import Actuator, CompletionPolicy
from .clock import Clock
from .completion import Motion
from .component import LINK_FAULTS, ComponentState
from .device import ActuatorDevice, ErrorId, VelocityRamp
from .errors import BadParameterError, StateError
from .ids import HALId
from .ramp import Ramp, streamer_for
from .requests import Request

_ACTIVE = ComponentState.ACTIVE
TWO_PI = 2.0 * math.pi


class MotorControlMode(IntEnum):
    """HAL4RT ``MotorControlMode``; the values are the OpenEL request codes of the modes."""

    READY_TO_CONTROL = 0
    """HALMOTOR_READY_TO_CONTROL: not excited (the Wait state)."""
    POSITION = 1
    """HALMOTOR_CTL_POSITION."""
    SPEED = 2
    """HALMOTOR_CTL_SPEED."""
    TORQUE = 3
    """HALMOTOR_CTL_TORQUE."""

    @property
    def request(self) -> Request:
        """The ``set_value`` request code that enters this mode."""
        return _REQUEST_OF[self]


_REQUEST_OF = {
    MotorControlMode.READY_TO_CONTROL: Request.NO_EXCITE,
    MotorControlMode.POSITION: Request.POSITION,
    MotorControlMode.SPEED: Request.VELOCITY,
    MotorControlMode.TORQUE: Request.TORQUE,
}
MODE_OF_REQUEST = {request: mode for mode, request in _REQUEST_OF.items()}
_MODES_BY_VALUE = {int(m): m for m in MotorControlMode}


def _real(parameter: str, value: object) -> float:
    """A finite real number as a float, else BadParameterError naming ``parameter``."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise BadParameterError(parameter, value, "a finite real number")
    try:
        result = float(value)
    except OverflowError:
        result = math.inf
    if not math.isfinite(result):
        raise BadParameterError(parameter, value, "a finite real number (not NaN or infinity)")
    return result


def check_scale_factor(value: object, parameter: str = "scale_factor") -> float:
    """A scale factor: finite and not 0 (negative reverses the direction)."""
    result = _real(parameter, value)
    if result == 0.0:
        raise BadParameterError(parameter, value, "a finite real number other than 0")
    return result


@dataclass(slots=True)
class MotorSettings:
    """The Motor's own state, in one slot (an Actuator keeps <= 29 instance attributes)."""

    scale_factor: float
    per_si: float
    """Scale units per rad (scale_factor / 2 pi) or per metre (scale_factor)."""
    origin_offset: float = 0.0
    """Device position (rad or m) at which the Motor's position reads 0."""
    active_since: int = 0
    """The actuator's command sequence number at the last transition to Active."""
    ramp: Ramp | None = None
    """The framework ramp of the latest set_speed, while streaming."""


class Motor(Actuator):
    """HAL4RT Motor: an :class:`Actuator` with the Motor operations, scale factor and origin.

    ``scale_factor`` defaults to 2 pi per revolution (rotary device) or 1.0 per metre
    (``device.linear``): with 360, positions are in degrees and speeds in degrees/s.
    """

    __slots__ = ("_hal4rt",)

    def __init__(
        self,
        device: ActuatorDevice,
        *,
        scale_factor: float | None = None,
        hal_id: HALId | None = None,
        device_name: str | None = None,
        function_list: tuple[str, ...] | None = None,
        clock: Clock | None = None,
        auto_init: bool = True,
        open_timeout: float = 10.0,
        completion: CompletionPolicy | None = None,
    ) -> None:
        super().__init__(
            device,
            hal_id=hal_id,
            device_name=device_name,
            function_list=function_list,
            clock=clock,
            auto_init=auto_init,
            open_timeout=open_timeout,
            completion=completion,
        )
        default = 1.0 if device.linear else TWO_PI
        scale = default if scale_factor is None else check_scale_factor(scale_factor)
        self._hal4rt = MotorSettings(scale, self._per_si(scale))

    def _per_si(self, scale: float) -> float:
        return scale if self.device.linear else scale / TWO_PI

    # -- attributes ------------------------------------------------------------------
    @property
    def scale_factor(self) -> float:
        """Position units per revolution (rotary) or per metre (linear)."""
        return self._hal4rt.scale_factor

    def set_scale_factor(self, scale_factor: float) -> None:
        """Change the scale factor (any state); later set/get positions and speeds use it."""
        scale = check_scale_factor(scale_factor)
        settings = self._hal4rt
        settings.scale_factor, settings.per_si = scale, self._per_si(scale)

    def get_scale_factor(self) -> float:
        return self._hal4rt.scale_factor

    @property
    def origin(self) -> float:
        """The device position (rad or m, SI) at which :meth:`get_position` reads 0."""
        return self._hal4rt.origin_offset

    # -- control mode ----------------------------------------------------------------
    def get_control_mode(self) -> MotorControlMode:
        """GetControlMode: the mode of the latest command since the last transition to
        Active; READY_TO_CONTROL (Wait) before any."""
        self._require("get_control_mode", _ACTIVE)
        motion = self.motion
        if motion is None or motion.sequence <= self._hal4rt.active_since:
            return MotorControlMode.READY_TO_CONTROL
        return MODE_OF_REQUEST[motion.request]

    async def set_control_mode(self, mode: MotorControlMode | int) -> Motion:
        """SetControlMode: enter ``mode`` without a jump.

        READY_TO_CONTROL de-energizes (``NO_EXCITE``); POSITION holds the actual position,
        SPEED keeps the actual speed, TORQUE keeps the actual torque (each clipped to the
        device's limits). Setting the mode in force changes nothing and returns the
        latest Motion.
        """
        if type(mode) is not MotorControlMode:
            found = _MODES_BY_VALUE.get(mode) if type(mode) is int else None
            if found is None:
                raise BadParameterError(
                    "mode",
                    mode,
                    "a MotorControlMode: READY_TO_CONTROL=0, POSITION=1, SPEED=2, TORQUE=3",
                )
            mode = found
        self._require("set_control_mode", _ACTIVE)
        current = self.get_control_mode()
        motion = self.motion
        if mode is current and motion is not None:
            return motion
        request = mode.request
        if request is Request.NO_EXCITE:
            return await self.set_value(0.0, Request.NO_EXCITE)
        self._check_supported(request)
        actual = await self._read_actual(request.actual)
        if self.state is not _ACTIVE:
            raise StateError("set_control_mode", self.state, (_ACTIVE,))
        return await self.set_value(_clip(self.device, request, actual), request)

    def _check_supported(self, request: Request) -> None:
        if request not in self.device.supported_requests:
            self._check_target(request, 0.0)  # raises NotImplementedHALError

    # -- commands --------------------------------------------------------------------
    async def set_position(self, position: float) -> Motion:
        """SetPosition: move to ``position`` (scale units, from the origin); switches to
        POSITION. Returns the Motion at once; reaching it posts event 1."""
        settings = self._hal4rt
        value = _real("position", position)
        target = value / settings.per_si + settings.origin_offset
        try:
            return await self.set_value(target, Request.POSITION)
        except BadParameterError as exc:
            raise self._renamed(exc, "position", position) from None

    async def set_torque(self, torque: float) -> Motion:
        """SetTorque: output ``torque`` (Nm or N, not scaled); switches to TORQUE."""
        value = _real("torque", torque)
        try:
            return await self.set_value(value, Request.TORQUE)
        except BadParameterError as exc:
            raise self._renamed(exc, "torque", torque) from None

    async def set_speed(self, speed: float, tm_acc: float = 0.0) -> Motion:
        """SetSpeed: reach ``speed`` (scale units/s) linearly in ``tm_acc`` seconds;
        switches to SPEED.

        ``tm_acc`` 0 sends the speed at once (the device ramps at its own limit). Otherwise
        a device with its own ramp (``device.velocity_ramp``) gets a
        :class:`VelocityRamp`; else the framework streams the ramp every millisecond on
        the component's clock. The Motion completes (event 1) once the final speed is
        reached, never during the ramp; the next command ends the ramp.
        """
        self._require("set_speed", _ACTIVE)
        value = _real("speed", speed)
        duration = _real("tm_acc", tm_acc)
        if duration < 0.0:
            raise BadParameterError("tm_acc", tm_acc, "a finite number of seconds >= 0")
        target = value / self._hal4rt.per_si
        try:
            self._check_target(Request.VELOCITY, target)
        except BadParameterError as exc:
            raise self._renamed(exc, "speed", speed) from None
        previous = self._hal4rt.ramp
        if duration == 0.0:  # a pending ramp is superseded by this command
            return await self.set_value(target, Request.VELOCITY)
        if previous is not None and previous.active:
            start = previous.setpoint(self.clock.now_ns())
        else:
            start = await self._read_actual(Request.VELOCITY_ACTUAL)
        if self.state is not _ACTIVE:
            raise StateError("set_speed", self.state, (_ACTIVE,))
        if self.device.velocity_ramp:
            return await self._send_native_ramp(VelocityRamp(start, target, duration))
        return await self._start_ramp(start, target, duration)

    async def _send_native_ramp(self, ramp: VelocityRamp) -> Motion:
        sequence = self._next_sequence()  # (leaves a bank's batch stream first)
        try:
            await self.device.command_velocity_ramp(ramp)
        except LINK_FAULTS as exc:
            raise self._fault_from(exc) from exc
        return self._accept(Request.VELOCITY, ramp.target, sequence)

    async def _start_ramp(self, start: float, target: float, duration: float) -> Motion:
        """The framework ramp: command ``start`` now (velocity mode), then stream."""
        sequence = self._next_sequence()  # (leaves a bank's batch stream first)
        device = self.device
        try:
            if self._command_nowait:
                self._sync_send = sequence  # a report of "reached" from inside: not final
                try:
                    device.command_nowait(Request.VELOCITY, start)
                finally:
                    self._sync_send = 0
            else:
                await device.command(Request.VELOCITY, start)
        except LINK_FAULTS as exc:
            raise self._fault_from(exc) from exc
        now = self.clock.now_ns()
        ramp = Ramp(
            motion=Motion(Request.VELOCITY, target, sequence, now),  # replaced below
            start=start,
            target=target,
            t0_ns=now,
            t1_ns=now + max(1, round(duration * 1e9)),
            send=self._ramp_send,
            send_nowait=self._ramp_send_nowait if self._command_nowait else None,
            start_soon=self._task_group().start_soon,
        )
        self._hal4rt.ramp = ramp  # before _accept: completion is held back from now on
        motion = ramp.motion = self._accept(Request.VELOCITY, target, sequence)
        self._reached_in_send = 0
        if motion.done():  # faulted or cancelled while the command was sent
            self._hal4rt.ramp = None
            return motion
        streamer_for(self.clock).add(self, ramp)
        return motion

    def _ramp_send_nowait(self, value: float) -> None:
        try:
            self.device.command_nowait(Request.VELOCITY, value)
        except LINK_FAULTS as exc:
            self._fault_from(exc)
        except Exception as exc:  # a driver bug must not stop the other motors' ramps
            self._fault(ErrorId.DEVICE_ERROR, f"a ramp setpoint failed: {exc!r}")

    async def _ramp_send(self, value: float) -> None:
        try:
            await self.device.command(Request.VELOCITY, value)
        except LINK_FAULTS as exc:
            self._fault_from(exc)
        except Exception as exc:
            self._fault(ErrorId.DEVICE_ERROR, f"a ramp setpoint failed: {exc!r}")

    def _cancel_ramp(self) -> None:
        """A new command ends the framework ramp (its Motion is superseded by it)."""
        settings = self._hal4rt
        if settings.ramp is not None:
            settings.ramp = None
            streamer_for(self.clock).remove(self)

    @property
    def ramping(self) -> bool:
        """Whether a framework ramp of ``set_speed`` is streaming."""
        ramp = self._hal4rt.ramp
        return ramp is not None and ramp.active

    # -- readings --------------------------------------------------------------------
    async def get_position(self) -> float:
        """GetPosition: the actual position in scale units from the origin."""
        settings = self._hal4rt
        raw = await self.get_value(Request.POSITION_ACTUAL)
        return (raw - settings.origin_offset) * settings.per_si

    async def get_speed(self) -> float:
        """GetSpeed: the actual speed in scale units per second."""
        return await self.get_value(Request.VELOCITY_ACTUAL) * self._hal4rt.per_si

    async def get_torque(self) -> float:
        """GetTorque: the actual torque (Nm or N)."""
        return await self.get_value(Request.TORQUE_ACTUAL)

    async def set_origin(self, position: float = 0.0) -> None:
        """SetOrigin: the current actual position becomes ``position`` (rad or m, as HAL4RT
        says; :meth:`get_position` then reads ``position`` in scale units).

        Kept across ``re_init`` (a reset does not move the device's position frame); a
        finalized component is never used again, so nothing survives ``finalize``.
        """
        value = _real("position", position)
        self._require("set_origin", _ACTIVE)
        raw = await self.get_value(Request.POSITION_ACTUAL)
        self._hal4rt.origin_offset = raw - value

    # -- hooks -----------------------------------------------------------------------
    def _complete(self, motion: Motion) -> None:
        ramp = self._hal4rt.ramp
        if ramp is not None and ramp.motion is motion and not ramp.final_sent:
            return  # intermediate setpoints reached: not the final speed
        super()._complete(motion)

    async def _on_active(self) -> None:
        await super()._on_active()
        self._cancel_ramp()
        self._hal4rt.active_since = self._sequence

    def _renamed(self, exc: BadParameterError, parameter: str, value: object) -> BadParameterError:
        """A limit refusal of the SI target, told in the Motor's units."""
        if exc.parameter != "value":
            return exc
        settings = self._hal4rt
        limits = self.device.limits
        if parameter == "position":
            ends = sorted((x - settings.origin_offset) * settings.per_si for x in limits.position)
            return BadParameterError(parameter, value, f"a position in [{ends[0]}, {ends[1]}]")
        if parameter == "speed":
            bound = limits.velocity * abs(settings.per_si)
            return BadParameterError(parameter, value, f"a speed in [-{bound}, {bound}]")
        return BadParameterError(parameter, value, exc.allowed)


def _clip(device: ActuatorDevice, request: Request, value: float) -> float:
    limits = device.limits
    if request is Request.POSITION:
        low, high = limits.position
        return min(max(value, low), high)
    bound = limits.velocity if request is Request.VELOCITY else limits.torque
    return min(max(value, -bound), bound)
