"""AxisGroup: time-synchronized, jerk-limited motion of N actuators on an EventTimer.

The group plans each motion with ruckig when it is requested and streams POSITION
setpoints to every axis at every tick of its timer as one validated batch through an
:class:`~openel_async.ActuatorBank` (``get_value`` for the actual positions), so it
drives any actuator: simulated, MuJoCo, CAN or serial. See docs/motion.md.
"""

from __future__ import annotations

import contextlib
import itertools
import time
from collections import deque
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass
from types import TracebackType
from typing import Self

import anyio
import anyio.abc
import anyio.lowlevel

from openel_async.logs import get_logger

from ..actuator import Actuator
from ..banks import ActuatorBank
from ..clock import NS_PER_S, run_in_thread
from ..component import ComponentState
from ..device import has_nowait
from ..errors import BadParameterError, HALError, StateError
from ..requests import Request
from ..stats import LatenessRecorder, LatenessSummary
from ..timer import EventTimer, TimerState
from ..wakeup import Wakeup
from .arguments import check_actuators, positions_arg, waypoints_arg
from .errors import (
    AxisStateError,
    MotionStoppedError,
    PreemptedError,
)
from .handle import GroupMotion, GroupOutcome
from .log import TrajectoryLog
from .outcomes import (
    axis_failure,
    goal_timeout,
    left_active,
    path_violation,
    worst_goal_miss,
)
from .params import (
    AxisLimits,
    Tolerances,
    Waypoint,
    finite_non_negative,
    finite_positive,
    per_axis,
)
from .planner import KinematicState, Plan, Planner

log = get_logger(__name__)

S = ComponentState
POSITION = Request.POSITION
POSITION_ACTUAL = Request.POSITION_ACTUAL
COST_WINDOW = 100_000


@dataclass(frozen=True, slots=True)
class GroupStats:
    ticks: int
    """Ticks processed while a motion ran."""
    skipped_ticks: int
    """Ticks dropped because the group was still busy with an earlier one."""
    tick_cost: LatenessSummary
    """Wall time of the group's work per processed tick in ns (sampling the trajectory,
    reading actual positions if needed, sending every setpoint, logging)."""


class AxisGroup:
    """N actuators moving together under one EventTimer.

    Use it as an async context manager (it owns its streaming task). On entry it
    subscribes to ``timer`` as a TimerObserver and starts the timer if it is stopped
    (and then stops it again on exit); leaving the context holds any running motion.

    ``limits``: one :class:`AxisLimits` for every axis or one per axis.
    ``tolerances``: likewise (default: goal 1e-3, no path check).
    ``goal_time``: seconds allowed, after the last setpoint of a motion was sent, for
    every axis to come within its goal tolerance.
    ``synchronization``: ``"phase"`` (straight lines in joint space when ruckig can)
    or ``"time"``. ``log_capacity`` ticks are kept in :attr:`log` (0: no log);
    ``log_actual`` also reads and logs every axis' POSITION_ACTUAL at every tick.

    Each axis' observers hear COMPLETED once per motion, when a ``move_to`` or ``follow``
    succeeds (every axis within its goal tolerance), not for each streamed setpoint; a
    stopped, held, preempted or aborted motion posts none. ``setpoint_events=True`` asks
    for the per-setpoint events instead: each setpoint an axis reaches before the next
    one posts COMPLETED, as a ``set_value`` would, and the group posts none itself.
    """

    def __init__(
        self,
        actuators: Sequence[Actuator],
        *,
        timer: EventTimer,
        limits: AxisLimits | Sequence[AxisLimits],
        tolerances: Tolerances | Sequence[Tolerances] | None = None,
        goal_time: float = 1.0,
        synchronization: str = "phase",
        name: str = "axis-group",
        log_capacity: int = 10_000,
        log_actual: bool = False,
        setpoint_events: bool = False,
    ) -> None:
        axes = check_actuators(actuators)
        if not isinstance(timer, EventTimer):
            raise BadParameterError("timer", timer, "an EventTimer")
        if not isinstance(setpoint_events, bool):
            raise BadParameterError("setpoint_events", setpoint_events, "True or False")
        n = len(axes)
        self.name = name
        self.axes: tuple[Actuator, ...] = axes
        self.setpoint_events = setpoint_events
        """Whether each streamed setpoint an axis reaches posts COMPLETED (else: one
        COMPLETED per axis when a motion succeeds)."""
        self._bank = ActuatorBank(axes, setpoint_events=setpoint_events)
        # Devices that accept a command without I/O (simulations): the batch is streamed
        # without suspending and builds no Motion per axis (ActuatorBank.set_values_nowait).
        self._nowait = all(has_nowait(a.device, "command_nowait", "command") for a in axes)
        # Devices read without I/O: the actual positions in one bank read per tick (its
        # listeners hear the batch in one call).
        self._read_now = all(has_nowait(a.device, "read_nowait", "read") for a in axes)
        self.timer = timer
        self._limits: tuple[AxisLimits, ...] = per_axis(limits, n, "limits", AxisLimits)
        self._tolerances: tuple[Tolerances, ...] = per_axis(
            Tolerances() if tolerances is None else tolerances, n, "tolerances", Tolerances
        )
        self.goal_time = finite_non_negative("goal_time", goal_time)
        self._planner = Planner(n, [(-1.0, 1.0)] * n, [1.0] * n, synchronization)
        self.log = TrajectoryLog(n, log_capacity, actual=log_actual)
        self._log_actual = bool(log_actual)
        self._active: GroupMotion | None = None
        zeros = [0.0] * n
        self._last_t = 0
        self._last_state: KinematicState | None = KinematicState(
            list(zeros), list(zeros), list(zeros)
        )
        """The commanded state at ``_last_t``; None: ``_last_plan`` sampled at ``_last_t``
        (a tick streams positions only; the full state is computed when needed)."""
        self._last_plan: Plan | None = None
        self._commanded: list[float] = list(zeros)
        self._pending: int | None = None
        """The deadline of the tick waiting for the streaming task (None: none)."""
        self._busy = False
        """The streaming task is inside a tick that awaits (a driver's I/O)."""
        self._crashed: BaseException | None = None
        """An unexpected exception of a tick run inline: raised by the streaming task."""
        self._fast: Callable[[int], None] | None = None
        """The proven streaming tick of ``_fast_motion`` (see :meth:`_proven_tick`)."""
        self._fast_motion: GroupMotion | None = None
        self._fast_step: Callable[[int], Awaitable[None]] | None = None
        """The proven awaited tick of ``_fast_motion`` (see :meth:`_proven_step`)."""
        self._wakeup = Wakeup()
        self._ids = itertools.count(1)
        self._tg: anyio.abc.TaskGroup | None = None
        self._closed = False
        self._started_timer = False
        self._ticks = 0
        self._skipped = 0
        self._cost = LatenessRecorder()
        self._costs: deque[int] = deque(maxlen=COST_WINDOW)
        self._log = log.bind(group=name)

    # -- context -------------------------------------------------------------------------
    async def __aenter__(self) -> Self:
        if self._tg is not None or self._closed:
            raise StateError("__aenter__", "entered", ["an axis group not yet entered"])
        if not self.log.allocated and self.log.capacity:
            # numpy's first import (0.1-1 s) off the loop: the drives' heartbeats and
            # watchdogs keep being served meanwhile
            await run_in_thread(self.log.allocate)
        tg = anyio.create_task_group()
        await tg.__aenter__()
        try:
            tg.start_soon(self._stream)
            self.timer.add_observer(self)
            if self.timer.state is TimerState.STOPPED:
                self.timer.start_timer()
                self._started_timer = True
        except BaseException as exc:
            if self in self.timer.observers:
                self.timer.remove_observer(self)
            tg.cancel_scope.cancel()
            await tg.__aexit__(type(exc), exc, exc.__traceback__)
            raise
        self._tg = tg
        self._log.info("axis_group_entered", axes=len(self.axes), timer=self.timer.name)
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> bool | None:
        assert self._tg is not None
        self._hold("the axis group was closed")
        if self in self.timer.observers:
            self.timer.remove_observer(self)
        if self._started_timer and self.timer.state is TimerState.RUNNING:
            self.timer.stop_timer()
        tg, self._tg = self._tg, None
        self._closed = True
        tg.cancel_scope.cancel()
        self._log.info("axis_group_closed", ticks=self._ticks, skipped=self._skipped)
        # The streaming task only ever ends by this cancellation: an exception of the
        # body is left to propagate as it is instead of wrapped in an ExceptionGroup.
        await tg.__aexit__(None, None, None)
        return None

    # -- properties ------------------------------------------------------------------------
    @property
    def limits(self) -> tuple[AxisLimits, ...]:
        """Default limits of each axis for the next motions (assign one or one per axis)."""
        return self._limits

    @limits.setter
    def limits(self, value: AxisLimits | Sequence[AxisLimits]) -> None:
        self._limits = per_axis(value, len(self.axes), "limits", AxisLimits)

    @property
    def tolerances(self) -> tuple[Tolerances, ...]:
        """Default tolerances of each axis for the next motions (one or one per axis)."""
        return self._tolerances

    @tolerances.setter
    def tolerances(self, value: Tolerances | Sequence[Tolerances]) -> None:
        self._tolerances = per_axis(value, len(self.axes), "tolerances", Tolerances)

    @property
    def axis_names(self) -> tuple[str, ...]:
        return tuple(a.device_name for a in self.axes)

    @property
    def current(self) -> GroupMotion | None:
        """The running motion, if any."""
        return self._active

    @property
    def moving(self) -> bool:
        return self._active is not None

    @property
    def commanded(self) -> tuple[float, ...]:
        """The setpoints the group sent last (its start positions before the first tick)."""
        return tuple(self._commanded)

    @property
    def stats(self) -> GroupStats:
        return GroupStats(self._ticks, self._skipped, self._cost.summary())

    def reset_stats(self) -> None:
        self._ticks = self._skipped = 0
        self._cost.reset()
        self._costs.clear()

    def tick_costs_ns(self) -> list[int]:
        """Wall time of each of the last processed ticks (up to 100,000), oldest first."""
        return list(self._costs)

    # -- motions -----------------------------------------------------------------------------
    async def move_to(
        self,
        targets: Sequence[float],
        limits: AxisLimits | Sequence[AxisLimits] | None = None,
        *,
        duration: float | None = None,
        tolerances: Tolerances | Sequence[Tolerances] | None = None,
        goal_time: float | None = None,
    ) -> GroupMotion:
        """Move every axis to its target, all starting and arriving together.

        Returns the motion's handle at once (await it for the outcome). A running
        motion is preempted from its current commanded state (position, velocity,
        acceleration): no jump. ``duration`` (s): take exactly this long instead of as
        fast as the limits allow. Invalid input raises before anything changes.
        """
        self._require_open("move_to")
        self._refresh_device_limits()
        goal = positions_arg(targets, "targets", self.axes, self._planner.bounds)
        axis_limits = self._limits_arg(limits)
        tol = self._tolerances_arg(tolerances)
        goal_time_ns = self._goal_time_arg(goal_time)
        dur = None if duration is None else finite_positive("duration", duration)
        idle_positions = await self._prepare("move_to")
        root_ns, state = self._root(idle_positions)
        plan = self._planner.move(root_ns, state, goal, axis_limits, dur)
        return self._install("move", plan, state, tol, goal_time_ns)

    async def follow(
        self,
        waypoints: Sequence[Waypoint],
        limits: AxisLimits | Sequence[AxisLimits] | None = None,
        *,
        tolerances: Tolerances | Sequence[Tolerances] | None = None,
        goal_time: float | None = None,
    ) -> GroupMotion:
        """Pass through the waypoints in order and stop on the last one.

        A waypoint's ``time`` is seconds from the start of this motion; untimed ones
        are reached as early as the limits allow. Velocity is continuous through
        intermediate waypoints (see :meth:`Planner.waypoints`); goal tolerances apply
        to the last waypoint, path tolerances all along.
        """
        self._require_open("follow")
        self._refresh_device_limits()
        points = waypoints_arg(waypoints, self.axes, self._planner.bounds)
        axis_limits = self._limits_arg(limits)
        tol = self._tolerances_arg(tolerances)
        goal_time_ns = self._goal_time_arg(goal_time)
        idle_positions = await self._prepare("follow")
        root_ns, state = self._root(idle_positions)
        plan = self._planner.waypoints(root_ns, state, points, axis_limits)
        return self._install("waypoints", plan, state, tol, goal_time_ns)

    async def stop(self) -> None:
        """Brake the running motion to rest, jerk-limited, and return once stopped.

        The running motion ends with :class:`MotionStoppedError`. The braking is a
        motion of its own (kind ``"stop"``, :attr:`current` meanwhile); a new motion
        may preempt it, which ends ``stop()`` early. Raises what aborted the braking
        (an axis fault). Nothing to do when idle.
        """
        self._require_open("stop")
        motion = self._active
        if motion is None:
            await anyio.lowlevel.checkpoint()
            return
        if motion.settling:  # the final setpoints were sent: already braking
            self._hold("stop() during the goal check")
            await anyio.lowlevel.checkpoint()
            return
        if motion.kind == "stop":  # already stopping: wait for that stop
            brake = motion
        else:
            self._refresh_device_limits()
            state = self._commanded_state()
            plan = self._planner.brake(self._last_t, state, self._limits)
            brake = self._install(
                "stop", plan, state, tuple(Tolerances() for _ in self.axes), 0, stopping=True
            )
        # Replaced by a new motion, or held: the stop is over; a fault is raised.
        with contextlib.suppress(PreemptedError, MotionStoppedError):
            await brake

    def hold(self) -> None:
        """Stop streaming now: every axis keeps its last setpoint.

        The running motion ends with :class:`MotionStoppedError`. For a smooth stop
        at speed use :meth:`stop`; ``hold`` leaves the deceleration to each device.
        """
        self._hold("hold() was called")

    # -- the timer's side ----------------------------------------------------------------------
    def notify_timer(self, timer: EventTimer) -> None:
        """TimerObserver: run the tick now if it needs no await (devices with a synchronous
        path, the common case), else hand it to the streaming task (never blocks)."""
        if self._active is None:
            return
        fields = timer.last_tick_fields  # no TimerTick built: the deadline is all we need
        if fields is None:
            return
        deadline = fields[1]
        if self._pending is None and not self._busy and self._ticks_inline():
            started = time.perf_counter_ns()
            try:
                self._tick_now(deadline)
            except Exception as exc:  # a bug, not a device fault: end the group's task
                self._crashed = exc
                self._wakeup.set()
                return
            cost = time.perf_counter_ns() - started
            self._cost.record(cost)
            self._costs.append(cost)
            self._ticks += 1
            return
        if self._pending is not None:
            self._skipped += 1
        self._pending = deadline
        self._wakeup.set()

    def _ticks_inline(self) -> bool:
        """Whether the running motion's tick needs no await: a proven stream, or devices
        that are commanded (and, if the tick reads them, read) without suspending."""
        motion = self._active
        if motion is None:
            return True
        if self._fast is not None and motion is self._fast_motion:
            return True
        return self._nowait and (
            self._read_now or not (motion._settling or motion._checks_path or self._log_actual)
        )

    def _tick_now(self, t: int) -> None:
        """One tick of the running motion, without suspending (see :meth:`_ticks_inline`)."""
        motion = self._active
        if motion is None:
            return
        fast = self._fast
        if fast is not None and motion is self._fast_motion:  # the common tick
            fast(t)
        elif not (motion._settling or motion._checks_path or self._log_actual):
            self._advance_now(motion, t, None)  # sample and stream
        else:
            self._step_now(motion, t)

    async def _stream(self) -> None:
        """The ticks that await (devices without a synchronous path), one at a time."""
        perf = time.perf_counter_ns
        record = self._cost.record
        keep = self._costs.append
        wakeup = self._wakeup
        while True:
            crashed = self._crashed
            if crashed is not None:
                self._crashed = None
                raise crashed
            t = self._pending
            if t is None:
                await wakeup.wait()
                continue
            self._pending = None
            started = perf()
            if self._ticks_inline():
                self._tick_now(t)
            else:
                self._busy = True
                try:
                    await self._step(t)
                finally:
                    self._busy = False
            cost = perf() - started
            record(cost)
            keep(cost)
            self._ticks += 1

    def _step_now(self, motion: GroupMotion, t: int) -> None:
        """:meth:`_step` for devices read and commanded without suspending."""
        actual: list[float] | None = None
        settling = motion._settling
        if settling or motion._checks_path or self._log_actual:
            if self._axis_left_active(motion, t):
                return
            try:
                actual = list(self._bank.get_values_nowait(POSITION_ACTUAL))
            except Exception as exc:
                self._read_failed(motion, exc, t)
                return
            if not settling and motion._checks_path and self._path_violated(motion, actual, t):
                return
        if settling:
            assert actual is not None
            self._settle(motion, actual, t)
            return
        self._advance_now(motion, t, actual)

    async def _step(self, t: int) -> None:
        """One tick of the running motion, over devices that need an await."""
        motion = self._active
        if motion is None:
            return
        fast = self._fast_step
        if fast is not None and motion is self._fast_motion:  # the common awaited tick
            await fast(t)
            return
        settling = motion._settling
        actual: list[float] | None = None
        if settling or motion._checks_path or self._log_actual:
            if self._axis_left_active(motion, t):
                return
            if self._read_now:
                try:
                    actual = list(self._bank.get_values_nowait(POSITION_ACTUAL))
                except Exception as exc:
                    self._read_failed(motion, exc, t)
                    return
            else:
                actual = []
                append = actual.append
                try:
                    for axis in self.axes:
                        append(await axis.get_value(POSITION_ACTUAL))
                except Exception as exc:
                    self._axis_failed(len(actual), exc, t)
                    return
            if self._active is not motion:  # preempted or held during the reads
                return
            if not settling and motion._checks_path and self._path_violated(motion, actual, t):
                return
        if settling:
            assert actual is not None
            self._settle(motion, actual, t)
            return
        if self._nowait:
            self._advance_now(motion, t, actual)
            return
        plan = motion._plan
        position = plan.positions(t)
        self._last_t = t
        self._last_state = None
        self._last_plan = plan
        self.log.append_plan(t, motion.id, plan, actual)
        # One validated batch: every axis Active and every setpoint within its limits
        # before any is sent (else nothing is sent and the motion aborts).
        try:
            # One coroutine for the batch (one awaited device batch when the driver offers
            # one), Motions built only when asked for.
            await self._bank.set_values(position, POSITION)
        except Exception as exc:
            self._stream_failed(motion, position, exc, t)
            return
        self._sent(motion, plan, position, t)

    def _advance_now(self, motion: GroupMotion, t: int, actual: list[float] | None) -> None:
        """The setpoints of tick ``t``, streamed without suspending (devices with a
        synchronous path): the same as the end of :meth:`_step`, with no coroutine."""
        plan = motion._plan
        position = plan.positions(t)
        self._last_t = t
        self._last_state = None
        self._last_plan = plan
        self.log.append_plan(t, motion.id, plan, actual)
        try:
            self._bank.set_values_nowait(position, POSITION)
        except Exception as exc:
            self._stream_failed(motion, position, exc, t)
            return
        self._sent(motion, plan, position, t)

    def _proven_tick(self, motion: GroupMotion, plan: Plan) -> Callable[[int], None] | None:
        """The tick of ``motion`` when its whole path is proven within every device's
        limits (None otherwise: each tick's batch is then checked value by value).

        The proof: ruckig's position extrema of the plan (:meth:`Plan.position_bounds`)
        lie within each device's position limits, and the planner's samples are floats
        (finite, inside those extrema). The bank's sender still checks per batch what can
        change during the motion: every axis Active, and no device's limits set since the
        proof (else it proves the extrema again against the new limits, and while that
        fails checks the batch value by value: a value outside them raises the same
        BadParameterError as on the general path, nothing sent, and the motion aborts)
        (:meth:`ActuatorBank.position_stream`). The tick samples the plan, logs the row
        and sends the batch; the final setpoints (at or after the plan's end) take the
        general path, which also starts the goal check.
        """
        if not self._nowait or motion._checks_path or self._log_actual:
            return None
        send = self._bank.position_stream(*plan.position_bounds())
        if send is None:
            return None
        positions, row, end_ns, failed = self._stream_parts(motion, plan)

        def tick(t: int) -> None:
            if t >= end_ns:
                self._fast = self._fast_motion = None
                self._advance_now(motion, t, None)
                return
            position = positions(t)
            self._last_t = t
            self._last_state = None
            self._last_plan = plan
            row(t)
            try:
                send(position)
            except Exception as exc:
                failed(motion, position, exc, t)
                return
            self._commanded = position

        return tick

    def _proven_step(
        self, motion: GroupMotion, plan: Plan
    ) -> Callable[[int], Awaitable[None]] | None:
        """:meth:`_proven_tick` over devices that need an await (a bus's one write for every
        drive): the tick awaits one device batch proven within every device's limits once
        (:meth:`ActuatorBank.position_stream_awaited`), without the per-value checks of
        :meth:`_step`; every axis is still checked Active before each batch."""
        if self._nowait or motion._checks_path or self._log_actual:
            return None
        send = self._bank.position_stream_awaited(*plan.position_bounds())
        if send is None:
            return None
        positions, row, end_ns, failed = self._stream_parts(motion, plan)

        async def step(t: int) -> None:
            if t >= end_ns:  # the final setpoints take the general path (the goal check)
                self._fast_step = None
                await self._step(t)
                return
            position = positions(t)
            self._last_t = t
            self._last_state = None
            self._last_plan = plan
            row(t)
            try:
                await send(position)
            except Exception as exc:
                failed(motion, position, exc, t)
                return
            self._commanded = position

        return step

    def _stream_parts(
        self, motion: GroupMotion, plan: Plan
    ) -> tuple[
        Callable[[int], list[float]],
        Callable[[int], None],
        int,
        Callable[[GroupMotion, list[float], Exception, int], None],
    ]:
        """What a proven tick of ``motion`` binds once: the plan's sampler, the log's row
        writer, the plan's end and the failure handler."""
        return plan.sampler(), self.log.plan_rows(motion.id, plan), plan.end_ns, self._stream_failed

    def _sent(self, motion: GroupMotion, plan: Plan, position: list[float], t: int) -> None:
        """Every axis took the setpoints of tick ``t``; the motion settles after its last."""
        self._commanded = position
        if t >= plan.end_ns and self._active is motion:
            if motion.kind == "stop":
                self._succeed(motion, t)
            else:
                motion._settling = True
                motion._goal_deadline_ns = plan.end_ns + motion._goal_time_ns

    def _axis_left_active(self, motion: GroupMotion, t: int) -> bool:
        """Abort ``motion`` with AxisFaultError if an axis is no longer Active."""
        error = left_active(self.name, self.axes, t)
        if error is None:
            return False
        self._abort(motion, error, t)
        return True

    def _read_failed(self, motion: GroupMotion, exc: Exception, t: int) -> None:
        """The bank's read of the actual positions raised: abort, naming the axis.

        A device fault (link failure, a non-finite value) has moved that axis to Error and
        is named with its fault; else (an exception of a driver) the first axis whose own
        read raises, read again one by one (axis 0 if none does any more).
        """
        if self._axis_left_active(motion, t):
            return
        index = 0
        for i, axis in enumerate(self.axes):
            try:
                axis.get_value_nowait(POSITION_ACTUAL)
            except Exception:
                index = i
                break
            if self._axis_left_active(motion, t):
                return
        self._axis_failed(index, exc, t)

    def _stream_failed(
        self, motion: GroupMotion, position: list[float], exc: Exception, t: int
    ) -> None:
        """The batch of setpoints raised: abort, naming the axis it failed at.

        An axis that left Active (refused before anything was sent, or faulted by its
        device during the send) is named with its fault; else the first axis whose
        commanded position is not the setpoint of this tick (the batch sends in axis
        order, so that is where it stopped).
        """
        if self._axis_left_active(motion, t):
            return
        index = 0
        if isinstance(exc, BadParameterError) and exc.parameter.startswith("values["):
            index = int(exc.parameter[len("values[") : -1])
        else:
            for i, (axis, value) in enumerate(zip(self.axes, position, strict=True)):
                if axis.get_value_nowait(POSITION) != value:
                    index = i
                    break
        self._axis_failed(index, exc, t)

    # -- tolerances and outcomes --------------------------------------------------------------
    def _path_violated(self, motion: GroupMotion, actual: list[float], t: int) -> bool:
        """Abort ``motion`` with PathToleranceError if an axis is beyond its path tolerance."""
        error = path_violation(self.name, self.axes, motion, actual, self._commanded, t)
        if error is None:
            return False
        self._abort(motion, error, t)
        return True

    def _settle(self, motion: GroupMotion, actual: list[float], t: int) -> None:
        self._last_t = t
        self._last_state = None
        self._last_plan = motion._plan
        self.log.append_plan(t, motion.id, motion._plan, actual)
        worst = worst_goal_miss(motion, actual)
        if worst is None:
            self._succeed(motion, t)
        elif t > motion._goal_deadline_ns:
            self._abort(motion, goal_timeout(self.name, self.axes, motion, worst, t), t)

    def _axis_failed(self, axis_index: int, exc: Exception, t: int) -> None:
        motion = self._active
        if motion is None:
            return
        axis = self.axes[axis_index]
        if not isinstance(exc, HALError):
            self._log.exception("axis_call_failed", axis=axis_index, actuator=axis.device_name)
        self._abort(motion, axis_failure(self.name, self.axes, axis_index, exc, t), t)

    def _succeed(self, motion: GroupMotion, t: int) -> None:
        if self._active is motion:
            self._active = None
            self._fast = self._fast_motion = None
        if motion.kind != "stop" and not motion.done() and not self.setpoint_events:
            for axis in self.axes:  # the group's target is reached: one COMPLETED per axis
                axis._post_completed()
        if motion._finish(GroupOutcome.SUCCEEDED, t):
            self._log.info("motion_succeeded", motion=motion.id, kind=motion.kind)

    def _abort(self, motion: GroupMotion, error: HALError, t: int) -> None:
        """End the motion and stop streaming: the other axes hold their last setpoint."""
        if self._active is motion:
            self._active = None
            self._fast = self._fast_motion = None
        if motion._finish(GroupOutcome.ABORTED, t, error):
            self._log.warning(
                "motion_aborted", motion=motion.id, error=str(error), kind=type(error).__name__
            )

    def _hold(self, reason: str) -> None:
        motion = self._active
        if motion is None:
            return
        self._active = None
        self._fast = self._fast_motion = None
        now = self.timer.clock.now_ns()
        if motion._finish(GroupOutcome.STOPPED, now, MotionStoppedError(f"{self.name}: {reason}")):
            self._log.info("motion_stopped", motion=motion.id, reason=reason)

    # -- installing a motion ---------------------------------------------------------------------
    async def _prepare(self, operation: str) -> list[float] | None:
        """Check the axes and, when idle, read where each one is commanded to be."""
        self._check_axes_active()
        if self.timer.state is not TimerState.RUNNING:
            raise StateError(operation, f"timer {self.timer.state}", ["timer Running"])
        if self._active is not None:
            return None
        positions: list[float] = []
        for axis in self.axes:
            positions.append(await axis.get_value(POSITION))
        self._check_axes_active()  # an axis may have faulted meanwhile
        return positions

    def _commanded_state(self) -> KinematicState:
        """Position, velocity and acceleration commanded at ``_last_t``."""
        state = self._last_state
        if state is None:
            assert self._last_plan is not None
            state = self._last_state = self._last_plan.sample(self._last_t)
        return state

    def _root(self, idle_positions: list[float] | None) -> tuple[int, KinematicState]:
        """Where and when the next trajectory starts. No await from here to _install."""
        motion = self._active
        if motion is not None and not motion._settling:
            return self._last_t, self._commanded_state()
        tick = self.timer.last_tick
        root = tick.deadline_ns if tick is not None else self.timer.clock.now_ns()
        zeros = [0.0] * len(self.axes)
        if motion is not None:  # at rest on its final setpoints, waiting for the goal
            return max(root, self._last_t), KinematicState(list(motion.targets), zeros, list(zeros))
        assert idle_positions is not None
        return root, KinematicState(list(idle_positions), zeros, list(zeros))

    def _install(
        self,
        kind: str,
        plan: Plan,
        state: KinematicState,
        tolerances: tuple[Tolerances, ...],
        goal_time_ns: int,
        *,
        stopping: bool = False,
    ) -> GroupMotion:
        motion = GroupMotion(
            next(self._ids),
            kind,
            plan,
            tuple(t.goal for t in tolerances),
            tuple(t.path for t in tolerances),
            goal_time_ns,
        )
        fast = self._proven_tick(motion, plan)
        fast_step = None if fast is not None else self._proven_step(motion, plan)
        previous = self._active
        self._active = motion
        self._fast_motion = motion
        self._fast = fast
        self._fast_step = fast_step
        self._last_t = plan.start_ns
        self._last_state = state
        if previous is None:
            self._commanded = list(state.position)
        else:
            now = self.timer.clock.now_ns()
            if stopping:
                error: HALError = MotionStoppedError(f"{self.name}: stop() was called")
                outcome = GroupOutcome.STOPPED
            else:
                error = PreemptedError(
                    f"{self.name}: motion #{previous.id} was preempted by motion #{motion.id}",
                    by=motion.id,
                )
                outcome = GroupOutcome.PREEMPTED
            if previous._finish(outcome, now, error):
                self._log.info("motion_replaced", motion=previous.id, by=motion.id)
        self._log.info(
            "motion_started",
            motion=motion.id,
            kind=kind,
            duration_s=round(plan.duration, 6),
            start_ns=plan.start_ns,
        )
        return motion

    # -- validation --------------------------------------------------------------------------------
    def _require_open(self, operation: str) -> None:
        if self._tg is None:
            state = "closed" if self._closed else "not entered"
            raise StateError(operation, state, ["inside 'async with group'"])

    def _check_axes_active(self) -> None:
        for i, axis in enumerate(self.axes):
            if axis.state is not S.ACTIVE:
                raise AxisStateError(
                    f"{self.name}: axis {i} ({axis.device_name}) is {axis.state}, not Active",
                    axis=i,
                    axis_name=axis.device_name,
                    state=axis.state,
                )

    def _refresh_device_limits(self) -> None:
        """Device limits may be set when a device opens: read them for every motion."""
        planner = self._planner
        planner.bounds = tuple(a.device.limits.position for a in self.axes)
        planner.velocity_caps = tuple(a.device.limits.velocity for a in self.axes)

    def _limits_arg(
        self, limits: AxisLimits | Sequence[AxisLimits] | None
    ) -> tuple[AxisLimits, ...]:
        if limits is None:
            return self._limits
        return per_axis(limits, len(self.axes), "limits", AxisLimits)

    def _tolerances_arg(
        self, tolerances: Tolerances | Sequence[Tolerances] | None
    ) -> tuple[Tolerances, ...]:
        if tolerances is None:
            return self._tolerances
        return per_axis(tolerances, len(self.axes), "tolerances", Tolerances)

    def _goal_time_arg(self, goal_time: float | None) -> int:
        seconds = (
            self.goal_time if goal_time is None else finite_non_negative("goal_time", goal_time)
        )
        return round(seconds * NS_PER_S)

    def __repr__(self) -> str:
        state = "closed" if self._closed else ("open" if self._tg is not None else "new")
        return f"AxisGroup({self.name!r}, axes={len(self.axes)}, {state}, current={self._active})"
