"""SimMotor: a simulated servo motor with trapezoidal position moves and limits.

Position control follows a time-optimal trapezoid under the velocity and acceleration
limits; velocity control ramps at the acceleration limit; torque control accelerates
the rotor inertia until the velocity limit. Position limits are hard stops that post
event 2 (LIMIT_REACHED). The motor reports COMPLETED itself, at the exact arrival time
on the component's clock. Faults can be injected: disconnect, an error id, stuck.
"""

from __future__ import annotations

import math
import random
from collections.abc import Sequence

import anyio

from openel_async.clock import Clock
from openel_async.device import (
    ActuatorDevice,
    ActuatorLimits,
    BatchCommander,
    DeviceContext,
    DeviceInfo,
    ErrorId,
    VelocityRamp,
)
from openel_async.errors import BadParameterError, NotConnectedError, ReturnCode
from openel_async.ids import DeviceKind
from openel_async.logs import get_logger
from openel_async.requests import EventId, Request

from . import profile as prof
from .profile import evaluate, evaluate_plan, plan_trapezoid

log = get_logger(__name__)

_POSITION = Request.POSITION
_VELOCITY = Request.VELOCITY
_TORQUE = Request.TORQUE

INSIDE_MARGIN = 1e-6
"""Relative margin by which a position profile's extremes must lie inside the limits for
the exact crossing search to be skipped (the profile's rounding is ~1e-12 relative)."""

TORQUE_RISE_NS = 2_000_000
"""Current-loop response: the commanded torque is reached this long after the command."""


class SimMotor(ActuatorDevice):
    """A simulated one-axis servo; all quantities SI (rad, rad/s, rad/s^2, Nm, kg m^2)."""

    info = DeviceInfo(
        kind=DeviceKind.MOTOR,
        vendor_id=0x0E1,
        product_id=0x100,
        vendor_name="OpenEL",
        product_name="SimMotor",
        functions=("inject_fault", "disconnect", "reconnect", "set_stuck"),
    )
    reports_completion = True
    velocity_ramp = True
    """Its own velocity ramp (``Motor.set_speed`` with a tmAcc): see command_velocity_ramp."""

    def __init__(
        self,
        *,
        position_limits: tuple[float, float] = (-math.pi, math.pi),
        max_velocity: float = 2.0,
        max_acceleration: float = 10.0,
        max_torque: float = 2.0,
        inertia: float = 0.01,
        initial_position: float = 0.0,
        position_noise: float = 0.0,
        seed: int = 0,
        native_ramp: bool = True,
    ) -> None:
        for name, value in (
            ("max_velocity", max_velocity),
            ("max_acceleration", max_acceleration),
            ("max_torque", max_torque),
            ("inertia", inertia),
        ):
            if not (math.isfinite(value) and value > 0):
                raise BadParameterError(name, value, "a finite value > 0")
        low, high = position_limits
        if not low <= initial_position <= high:
            raise BadParameterError(
                "initial_position", initial_position, f"a position in [{low}, {high}]"
            )
        self.limits = ActuatorLimits(position_limits, max_velocity, max_torque)
        self.velocity_ramp = native_ramp  # False: Motor.set_speed streams the ramp itself
        self.max_acceleration = max_acceleration
        self.inertia = inertia
        self.position_noise = position_noise
        self._rng = random.Random(seed)
        self._initial_position = initial_position
        self._segments = prof.hold(0, initial_position)
        """The motion profile, unless ``_plan`` holds it."""
        self._plan: prof.Plan | None = None
        """The motion profile when it is a position move within the limits (the per-command
        path: one flat tuple, no segment objects); None when ``_segments`` holds it."""
        self._request = Request.NO_EXCITE
        self._torque_cmd = 0.0
        self._torque_since = 0
        self._arrival_ns: int | None = None
        self._limit_ns: int | None = None
        self._ctx: DeviceContext | None = None
        self._clock: Clock | None = None
        """The component's clock (read once at open: the per-command path)."""
        self._sleep_scope: anyio.CancelScope | None = None
        """The watcher's wait for its deadline (``_sleep_until``), while it waits for one."""
        self._sleep_until = 0
        self._idle: anyio.Event | None = None
        """Set by the next profile with something due, while the watcher has nothing due."""
        self.connected = True
        self.stuck = False
        self.commands = 0

    # -- lifecycle -------------------------------------------------------------------
    async def open(self, ctx: DeviceContext) -> None:
        self._ctx = ctx
        self._clock = ctx.clock
        now = ctx.clock.now_ns()
        self._segments = prof.hold(now, self._initial_position)
        self._plan = None
        ctx.start_soon(self._watch)

    async def init(self) -> None:
        self._check_connected()

    async def reset(self) -> None:
        self._check_connected()
        now = self._now()
        p, _, _ = self.state_at(now)
        self._set_profile(prof.hold(now, p), Request.NO_EXCITE, arrival=False)

    async def close(self) -> None:
        if self._ctx is not None and self.connected:
            now = self._now()
            p, _, _ = self.state_at(now)
            self._segments = prof.hold(now, p)
            self._plan = None
        self._arrival_ns = self._limit_ns = None

    # -- commands and readings -------------------------------------------------------
    async def command(self, request: Request, value: float) -> None:
        self.command_nowait(request, value)

    def command_nowait(self, request: Request, value: float) -> None:
        if not self.connected:
            raise NotConnectedError("simulated motor is disconnected")
        self.commands += 1
        clock = self._clock
        now = clock.now_ns() if clock is not None else 0
        plan = self._plan
        p, v, _ = evaluate(self._segments, now) if plan is None else evaluate_plan(plan, now)
        limits = self.limits
        vmax, amax = limits.velocity, self.max_acceleration
        if self.stuck:
            segments = prof.hold(now, p)
        elif request is _POSITION:
            plan = plan_trapezoid(now, p, v, value, vmax, amax)
            # A trapezoid's farthest points are its start, its target and where braking
            # now would stop (the turn of an overshoot or of a start heading away); when
            # they lie inside the limits by a margin far above the profile's rounding,
            # the limit check is done (else clip_to_limits looks for the crossing).
            low, high = limits.position
            stop = p + v * (v if v >= 0.0 else -v) / (2 * amax)
            lo = p if p < stop else stop
            hi = p if p > stop else stop
            if value < lo:
                lo = value
            elif value > hi:
                hi = value
            # (min and max of the three, and a margin relative to their magnitude)
            margin = INSIDE_MARGIN * (1.0 + (hi if hi >= 0.0 else -hi) + (lo if lo >= 0.0 else -lo))
            if low + margin < lo and hi < high - margin:
                # _set_inside(segments, POSITION, arrival), inline: the per-command path
                arrival_ns = plan[12]
                self._plan = plan
                self._request = _POSITION
                self._limit_ns = None
                self._arrival_ns = arrival_ns
                scope = self._sleep_scope
                if scope is not None:
                    if arrival_ns < self._sleep_until:
                        scope.cancel()  # the watcher has something due earlier
                else:
                    idle = self._idle
                    if idle is not None:  # the watcher has had nothing due
                        self._idle = None
                        idle.set()
                return
            segments = prof.plan_segments(plan)
        elif request is Request.VELOCITY:
            segments = prof.ramp(now, p, v, value, amax)
        elif request is Request.TORQUE:
            segments = prof.accelerate(now, p, v, value / self.inertia, vmax)
            self._torque_cmd, self._torque_since = value, now
        else:  # NO_EXCITE: the rotor coasts to rest under friction
            segments = prof.ramp(now, p, v, 0.0, amax / 4)
        self._set_profile(segments, request, arrival=not self.stuck)

    @classmethod
    def batch_commander(cls, devices: Sequence[ActuatorDevice]) -> BatchCommander | None:
        """Every motor of a bank commanded in one call (an ``ActuatorBank`` streaming
        setpoints): all or nothing, so a disconnected motor declines the whole batch and
        the bank's per-device path reports it on its own component."""
        motors = tuple(d for d in devices if isinstance(d, SimMotor))
        if len(motors) != len(devices) or cls.command_nowait is not SimMotor.command_nowait:
            return None  # a subclass with its own command path is commanded one by one

        def command_all(request: Request, values: Sequence[float], /) -> bool:
            for motor in motors:
                if not motor.connected:
                    return False
            for motor, value in zip(motors, values, strict=True):
                motor.command_nowait(request, value)
            return True

        return command_all

    async def command_velocity_ramp(self, ramp: VelocityRamp) -> None:
        """The drive's own ramp: from its velocity to ``ramp.target`` at the constant
        acceleration that takes ``ramp.duration_s`` (at most ``max_acceleration``: a ramp
        asked to be steeper takes longer). COMPLETED when the target velocity is reached."""
        self._check_connected()
        self.commands += 1
        now = self._now()
        p, v, _ = self.state_at(now)
        rate = min(abs(ramp.target - v) / ramp.duration_s, self.max_acceleration)
        if self.stuck:
            segments = prof.hold(now, p)
        else:
            segments = prof.ramp(now, p, v, ramp.target, rate or self.max_acceleration)
        self._set_profile(segments, Request.VELOCITY, arrival=not self.stuck)

    async def read(self, request: Request) -> float:
        return self.read_nowait(request)

    def read_nowait(self, request: Request) -> float:
        self._check_connected()
        now = self._now()
        p, v, _ = self.state_at(now)
        if request is Request.POSITION_ACTUAL:
            return p + (self._rng.gauss(0.0, self.position_noise) if self.position_noise else 0.0)
        if request is Request.VELOCITY_ACTUAL:
            return v
        if request is Request.TORQUE_ACTUAL:
            return self.torque_at(now)
        raise BadParameterError(
            "request", request, "POSITION_ACTUAL, VELOCITY_ACTUAL or TORQUE_ACTUAL"
        )

    def torque_at(self, t_ns: int) -> float:
        _, _, a = self.state_at(t_ns)
        if self._request is Request.TORQUE:
            rise = min(1.0, (t_ns - self._torque_since) / TORQUE_RISE_NS)
            return self._torque_cmd * rise if a else 0.0
        return self.inertia * a

    @property
    def segments(self) -> list[prof.Segment]:
        """The current motion profile, as segments (a copy)."""
        plan = self._plan
        return list(self._segments) if plan is None else prof.plan_segments(plan)

    def state_at(self, t_ns: int) -> tuple[float, float, float]:
        """(position, velocity, acceleration) at a clock time; for sensors attached to it."""
        plan = self._plan
        return evaluate(self._segments, t_ns) if plan is None else evaluate_plan(plan, t_ns)

    # -- fault injection -------------------------------------------------------------
    def inject_fault(
        self, error_id: int = ErrorId.DEVICE_ERROR, reason: str = "injected fault"
    ) -> None:
        """The drive trips: it holds position and the component goes to Error."""
        now = self._now()
        p, _, _ = self.state_at(now)
        self._set_profile(prof.hold(now, p), Request.NO_EXCITE, arrival=False)
        assert self._ctx is not None
        self._ctx.fault(error_id, reason)

    def disconnect(self) -> None:
        """The link drops: every call raises NotConnectedError until reconnect()."""
        self.connected = False
        if self._ctx is not None:
            self._ctx.fault(
                ErrorId.DISCONNECTED, "device disconnected", ReturnCode.HAL_NO_CONNECTED
            )

    def reconnect(self) -> None:
        self.connected = True

    def set_stuck(self, stuck: bool = True) -> None:
        """A jammed rotor: it stops where it is and never reaches a target."""
        self.stuck = stuck
        if stuck:
            now = self._now()
            p, _, _ = self.state_at(now)
            self._set_profile(prof.hold(now, p), self._request, arrival=False)

    # -- internals -------------------------------------------------------------------
    def _now(self) -> int:
        return self._clock.now_ns() if self._clock is not None else 0

    def _check_connected(self) -> None:
        if not self.connected:
            raise NotConnectedError("simulated motor is disconnected")

    def _set_profile(
        self, segments: list[prof.Segment], request: Request, *, arrival: bool
    ) -> None:
        low, high = self.limits.position
        arrival_ns: int | None = None
        if arrival:
            if request is _POSITION or request is _VELOCITY:
                arrival_ns = prof.end_time(segments)
            elif request is _TORQUE:
                arrival_ns = self._now() + TORQUE_RISE_NS
        segments, limit_ns = prof.clip_to_limits(segments, low, high)
        if limit_ns is not None and arrival_ns is not None and limit_ns < arrival_ns:
            arrival_ns = None  # stopped by a limit first: the target is never reached
        self._set_inside(segments, request, arrival_ns, limit_ns)

    def _set_inside(
        self,
        segments: list[prof.Segment],
        request: Request,
        arrival_ns: int | None,
        limit_ns: int | None = None,
    ) -> None:
        """:meth:`_set_profile` once the profile is within the limits (``limit_ns``: when
        it stops on one)."""
        self._segments = segments
        self._plan = None
        self._request = request
        self._limit_ns = limit_ns
        self._arrival_ns = arrival_ns
        # Wake the watcher only if it now has something due earlier than its deadline (or
        # had nothing due); a later due time is picked up when it wakes.
        if limit_ns is None:
            due = arrival_ns
        elif arrival_ns is None or limit_ns < arrival_ns:
            due = limit_ns
        else:
            due = arrival_ns
        if due is None:
            return
        scope = self._sleep_scope
        if scope is not None:
            if due < self._sleep_until:
                scope.cancel()
        else:
            idle = self._idle
            if idle is not None:
                self._idle = None
                idle.set()

    async def _watch(self) -> None:
        """Post COMPLETED at the arrival time and LIMIT_REACHED at a limit stop.

        With nothing due it waits for an Event the next profile sets (a set -> COMPLETED ->
        set chain wakes it once per command, without a cancellation); with something due it
        sleeps on the clock in a cancel scope, cancelled only by a profile due earlier."""
        assert self._ctx is not None
        ctx = self._ctx
        clock = ctx.clock
        while True:
            arrival, limit = self._arrival_ns, self._limit_ns
            if limit is None:
                if arrival is None:
                    idle = self._idle = anyio.Event()
                    await idle.wait()
                    continue
                due = arrival
            elif arrival is None or limit < arrival:
                due = limit
            else:
                due = arrival
            with anyio.CancelScope() as scope:
                self._sleep_scope = scope  # a profile due earlier cancels the wait
                self._sleep_until = due
                await clock.sleep_until(due)
            self._sleep_scope = None
            if scope.cancel_called:
                continue
            now = clock.now_ns()
            if self._limit_ns is not None and self._limit_ns <= now:
                self._limit_ns = None
                ctx.post_event(EventId.LIMIT_REACHED)
            if self._arrival_ns is not None and self._arrival_ns <= now:
                self._arrival_ns = None
                ctx.target_reached()
