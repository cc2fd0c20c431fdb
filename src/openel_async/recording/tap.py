"""The tap: what the recorder and the live view attach to an application's components and
timers. It turns every command, reading, event, completion, error, state change and timer
tick into a record for a :class:`~.pipeline.Pipeline` (a tuple appended to its queue by a
listener object per component and an observer per timer: the only work done in the control
loop); the writer process makes them the messages of
:mod:`.schemas`. Nothing here blocks or raises into the control loop.

A :class:`Tap` is an :class:`~openel_async.cli.app.AppHook` (``--record``/``--foxglove``
attach it to any app) and can be used directly::

    async with Recorder("run.mcap") as rec:
        rec.observe(actuator)          # before or after entering it
        rec.observe_timer(timer)
"""

from __future__ import annotations

import contextlib
import math
import os
import time
from collections.abc import Callable, Sequence
from types import TracebackType
from typing import Any, cast

import anyio
import structlog

from ..actuator import Actuator
from ..cli.app import AppContext, AppHook
from ..clock import Clock, InlineScheduler, ScheduledCall, run_in_thread
from ..component import ComponentState, HALComponent
from ..device import ValueSource
from ..errors import HALError, WouldBlockError
from ..requests import EventId, Request
from ..timer import EventTimer
from .pipeline import Pipeline, PipelineStats
from .records import (
    BATCH,
    COMMAND,
    COMPLETION,
    ERROR,
    EVENT,
    JOINTS,
    LOG_LINE,
    MESSAGE,
    POSES,
    READING,
    STATE,
    TICK,
)
from .scene import SceneSource, flat_poses, scene_message
from .schemas import (
    FRAME_TRANSFORMS,
    HAL_RECORD,
    JOINT_STATES,
    JOINT_STATES_TOPIC,
    LOG,
    LOG_TOPIC,
    SCENE_TOPIC,
    SCENE_UPDATE,
    TF_TOPIC,
    TIMER_TICK,
    hal_topic,
    timer_topic,
)

__all__ = ["Tap"]

log = structlog.get_logger(__name__)

_ACTIVE = ComponentState.ACTIVE
_COMPLETED = int(EventId.COMPLETED)
_POSITION = Request.POSITION
_POSITION_ACTUAL = Request.POSITION_ACTUAL
_POSITION_CODE = int(Request.POSITION)
_LOG_LEVELS = {"debug": 1, "info": 2, "warning": 3, "warn": 3, "error": 4, "critical": 5}


class _ComponentTap:
    """The listener the tap sets on one component: its records go straight into the
    pipeline's queue (one call from the component; no lookup of the channel).

    A record holds only ints, floats, None and strings (a Request as its int): the garbage
    collector then untracks it at its first passes, so thousands of queued records do not
    make every full collection longer (a Request member would keep it tracked)."""

    __slots__ = ("capacity", "channel", "component", "muted", "now", "pipeline", "queue", "tap")

    def __init__(self, tap: Tap, component: HALComponent, channel: int) -> None:
        self.tap = tap
        self.component = component
        self.channel = channel
        self.now = component.clock.now_ns
        self.pipeline = tap.pipeline
        self.queue = tap.pipeline.queue
        self.capacity = tap.pipeline.capacity
        self.muted = False
        """True while the tap reads the component itself (that read is not recorded)."""

    def on_command(
        self, component: HALComponent, request: Request, value: float, time_ns: int
    ) -> None:
        queue = self.queue
        if len(queue) < self.capacity:
            queue.append((self.channel, time_ns, COMMAND, int(request), value))
        else:
            self.pipeline.dropped += 1

    def on_reading(
        self, component: HALComponent, request: Request | None, values: tuple[float, ...]
    ) -> None:
        if self.muted:  # the tap's own read
            return
        queue = self.queue
        if len(queue) < self.capacity:
            code = None if request is None else int(request)
            queue.append((self.channel, self.now(), READING, code, values))
        else:
            self.pipeline.dropped += 1

    def on_state(self, component: HALComponent, old: ComponentState, new: ComponentState) -> None:
        self.pipeline.put((self.channel, self.now(), STATE, str(old), str(new)))
        if new is _ACTIVE:
            self.tap.observe_events(component)


class _ActuatorTap(_ComponentTap):
    """An actuator's listener; it also keeps what the joint-state sample needs without
    reading through the framework: the commanded position (the last POSITION command it
    heard, read once through the framework after each activation, which resets it; or the
    latest of its banks' batches, :class:`_BankTap`, when one came after) and the
    device's own actual-position read (``None``: the framework answers the commanded value
    for it, or the device has no synchronous read)."""

    __slots__ = ("actuator", "banks", "commanded", "name", "read", "seq")

    def __init__(self, tap: Tap, component: Actuator, channel: int) -> None:
        super().__init__(tap, component, channel)
        self.actuator = component
        self.name = component.device_name
        self.commanded: float | None = None
        """The last POSITION command heard since the last state change (None: unknown)."""
        self.seq = 0
        """``tap.seq`` when :attr:`commanded` was set: a bank's batch with a higher one is
        newer."""
        self.banks: list[tuple[_BankTap, int]] = []
        """The batch listeners of the banks it is in, and its index in each."""
        measured = component.value_source(_POSITION_ACTUAL) is not ValueSource.COMMANDED
        self.read: Callable[[Request], float] | None = (
            component.device.read_nowait if measured else None
        )

    def on_command(
        self, component: HALComponent, request: Request, value: float, time_ns: int
    ) -> None:
        if request is _POSITION:  # the usual one: its code without an int() call
            self.commanded = value
            self.seq = self.tap.seq
            code = _POSITION_CODE
        else:
            code = int(request)
        queue = self.queue
        if len(queue) < self.capacity:
            queue.append((self.channel, time_ns, COMMAND, code, value))
        else:
            self.pipeline.dropped += 1

    def on_state(self, component: HALComponent, old: ComponentState, new: ComponentState) -> None:
        self.commanded = None  # an activation sets it to the actual position
        self.seq = self.tap.seq  # and the banks' earlier batches are older
        super().on_state(component, old, new)

    def batch_listener(self, components: Sequence[HALComponent]) -> _BankTap | None:
        """The batch listener of a bank of ``components`` (every one observed by this tap),
        else None (each member's listener hears its command)."""
        return self.tap.bank_tap(components)

    def latest_commanded(self) -> float | None:
        """The commanded position: the last POSITION command heard, its own or in a bank's
        batch, whichever came last (read through the framework after an activation)."""
        commanded, seq = self.commanded, self.seq
        for bank, index in self.banks:
            if bank.seq > seq and bank.values is not None:
                commanded, seq = bank.values[index], bank.seq
        if commanded is None:
            commanded = self.read_commanded()
        return commanded

    def read_commanded(self) -> float | None:
        """The commanded position read through the framework (after an activation; that
        read is not recorded)."""
        self.muted = True
        try:
            self.commanded = self.actuator.get_value_nowait(_POSITION)
        except HALError:
            return None
        finally:
            self.muted = False
        self.seq = self.tap.seq
        return self.commanded


class _BankTap:
    """The batch listener of a bank (:func:`openel_async.listeners.batch_listener`): one
    BATCH record per batch, split into a COMMAND message per component (on each one's
    channel) by the writer process; it keeps the latest POSITION batch for the joint-state
    sample (:meth:`_ActuatorTap.latest_commanded`)."""

    __slots__ = (
        "capacity",
        "channels",
        "count",
        "pipeline",
        "queue",
        "seq",
        "size",
        "tap",
        "values",
    )

    def __init__(self, tap: Tap, members: Sequence[_ComponentTap]) -> None:
        self.tap = tap
        self.channels = tuple(m.channel for m in members)
        self.size = len(members)
        self.pipeline = tap.pipeline
        self.queue = tap.pipeline.queue
        self.capacity = tap.pipeline.capacity
        self.count = 0
        """BATCH records queued (the pipeline counts ``size`` messages for each)."""
        self.seq = 0
        """``tap.seq`` of the latest POSITION batch."""
        self.values: tuple[float, ...] | None = None
        """The latest POSITION batch (None: none yet)."""

    def __call__(self, request: Request, values: Sequence[float], time_ns: int) -> None:
        queue = self.queue
        if len(queue) < self.capacity:
            if request is _POSITION:
                self.values = values = tuple(values)
                tap = self.tap
                self.seq = tap.seq = tap.seq + 1
                queue.append((BATCH, time_ns, COMMAND, _POSITION_CODE, self.channels, values))
            else:
                queue.append((BATCH, time_ns, COMMAND, int(request), self.channels, tuple(values)))
            self.count += 1
        else:
            self.pipeline.dropped += self.size
            if request is _POSITION:  # not recorded, but the joints' latest command
                self.values = tuple(values)
                tap = self.tap
                self.seq = tap.seq = tap.seq + 1


def _unreadable(request: Request) -> float:
    """The read of a device without a synchronous read path: nothing (NaN: None)."""
    return math.nan


class _TimerTap:
    """The tap's view of one timer: its tick statistics (one record per statistics period:
    the ticks delivered since the previous one, read from the timer, and the periods
    skipped; not a record per tick) and, on a clock that is not an
    :class:`~openel_async.clock.InlineScheduler`, the pace of the joint-state samples.

    On such a clock it observes the timer and per tick only counts (no :class:`~openel_async.observers.TimerTick`
    built: the timer keeps its cheap path); every few ticks (the shorter of the two
    periods, in ticks) it looks at the clock. On an InlineScheduler (a lockstep
    simulation) it does not observe the timer at all: the tap's own callback on the clock
    (:meth:`Tap.pace`) does that work at the period."""

    __slots__ = (
        "channel",
        "delivered",
        "due",
        "last_index",
        "next_ns",
        "now",
        "period_ns",
        "step",
        "tap",
        "ticks",
        "timer",
        "timer_period_ns",
    )

    def __init__(self, tap: Tap, timer: EventTimer, channel: int) -> None:
        self.tap = tap
        self.timer = timer
        self.channel = channel
        self.now = timer.clock.now_ns
        self.period_ns = tap.timer_stats_period_ns
        self.next_ns = 0
        self.ticks = 0  # ticks heard since the last look at the clock (observing only)
        self.due = 0  # self.ticks at which to look at the clock again
        self.step = 1
        self.timer_period_ns = 0
        self.update_step(timer)
        tick = timer.last_tick
        self.last_index = 0 if tick is None else tick.index
        self.delivered = timer.ticks_delivered  # at the last statistics record

    def notify_timer(self, timer: EventTimer) -> None:
        self.ticks += 1
        if self.ticks >= self.due:
            self.check(timer)

    def check(self, timer: EventTimer) -> None:
        tap = self.tap
        now = self.now()
        self.stats_due(now)
        if now >= tap.next_joint_ns:
            tap.next_joint_ns = now + tap.joint_period_ns
            tap.sample(now)
        self.ticks = 0
        self.due = self.step
        tap.flush_due()  # a batch of records encoded here, written by the pipeline's thread

    def stats_due(self, now: int) -> None:
        """The statistics record if its period has passed at ``now``."""
        if now >= self.next_ns:
            self.next_ns = now + self.period_ns
            self.flush()
            self.update_step(self.timer)

    def update_step(self, timer: EventTimer) -> None:
        """Ticks between two looks at the clock (the shorter period, in the timer's ticks;
        the timer's period re-read at every statistics record, should it change)."""
        period = timer.period_ns
        if period != self.timer_period_ns:
            self.timer_period_ns = period
            self.step = max(1, min(self.period_ns, self.tap.joint_period_ns) // period)

    def flush(self) -> None:
        """The statistics record of the ticks delivered since the previous one."""
        timer = self.timer
        delivered = timer.ticks_delivered
        ticks = delivered - self.delivered
        tick = timer.last_tick
        if tick is None or not ticks:
            return
        missed = tick.index - self.last_index - ticks
        self.last_index = tick.index
        self.delivered = delivered
        self.tap.pipeline.put(
            (self.channel, tick.time_ns, TICK, tick.index, tick.deadline_ns, missed, ticks)
        )


def _never() -> int:
    """The clock's time before the tap knows a clock."""
    return 0


class Tap(AppHook):
    """Observe components and timers into an MCAP file (``record``) and/or a Foxglove server
    (``foxglove``: (host, port); port 0: any free port).

    ``joint_period_ms``: the period of ``/joint_states`` (and ``/tf``) samples, taken at the
    observed timers' ticks, on the app's clock; ``timer_stats_ms``: the period of each
    timer's statistics messages (``/timer/<name>``; default: ``joint_period_ms``). ``capacity``: records the queue holds before
    it drops (counted in :attr:`stats`). ``logs``: forward log lines (info and above) to
    ``/log``. ``chunk_size``: bytes per MCAP chunk (a killed run loses at most one)."""

    def __init__(
        self,
        *,
        record: str | os.PathLike[str] | None = None,
        foxglove: tuple[str, int] | None = None,
        joint_period_ms: float = 10.0,
        timer_stats_ms: float | None = None,
        capacity: int = 100_000,
        logs: bool = True,
        chunk_size: int = 64 * 1024,
    ) -> None:
        if not joint_period_ms > 0:
            raise ValueError(f"joint_period_ms must be > 0, got {joint_period_ms}")
        if timer_stats_ms is None:
            timer_stats_ms = joint_period_ms
        if not timer_stats_ms > 0:
            raise ValueError(f"timer_stats_ms must be > 0, got {timer_stats_ms}")
        self.pipeline = Pipeline(
            mcap=record, foxglove=foxglove, capacity=capacity, chunk_size=chunk_size
        )
        self._put = self.pipeline.put
        self.joint_period_ns = round(joint_period_ms * 1e6)
        self.timer_stats_period_ns = round(timer_stats_ms * 1e6)
        self._logs = logs
        self._offset: int | None = None
        self._clock: Clock | None = None
        self._channels: dict[int, int] = {}  # id(component or timer) -> channel
        self._listeners: dict[int, _ComponentTap] = {}  # id(component) -> its listener
        self._timer_taps: dict[int, _TimerTap] = {}  # id(timer) -> its observer
        self._components: list[HALComponent] = []
        self._observing: set[int] = set()
        self._timers: list[EventTimer] = []
        self._actuators: list[_ActuatorTap] = []  # their listeners
        self._scenes: list[tuple[SceneSource, Any]] = []  # (source, its frames or None)
        self.next_joint_ns = 0
        """When the next joint-state sample is due (clock ns)."""
        self.seq = 0
        """Counts the banks' POSITION batches: orders them against single commands."""
        self.now: Callable[[], int] = _never
        """The app's clock's ``now_ns`` (once known)."""
        self.flush_due = self.pipeline.flush_due
        self._paced: list[_TimerTap] = []  # the timers on an InlineScheduler clock
        self._pace_call: ScheduledCall | None = None  # the tap's callback on that clock
        self._bank_taps: dict[tuple[int, ...], _BankTap] = {}  # ids of the members -> it
        self._joint_channel = -1
        self._log_channel = -1
        self._tf_channel = -1
        self._scene_channel = -1
        self._processors: list[Any] | None = None
        self._entered = False
        self._started = False
        self.final_stats: PipelineStats | None = None

    # -- lifetime --------------------------------------------------------------------
    def start(self) -> None:
        """Start the writer process now (blocking; ``async with`` does it otherwise): raises
        :class:`~.pipeline.SinkStartError` when the file or the server cannot open."""
        if not self._started:
            self.pipeline.start()
            self._started = True

    async def __aenter__(self) -> Tap:
        if self._entered:
            raise RuntimeError("a Tap is entered once")
        self._entered = True
        if not self._started:
            await run_in_thread(self.start)  # under external_work: no simulated time passes
        offset, self.pipeline.offset_ns = self.pipeline.offset_ns, 0
        self._log_channel = self.pipeline.add_channel(LOG_TOPIC, LOG)  # wall-clock times
        self.pipeline.offset_ns = offset
        if self._logs:
            self._install_log_forwarder()
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self._remove_log_forwarder()
        for component in self._components:
            if component.listener is self._listeners[id(component)]:
                component.set_listener(None)
        if self._pace_call is not None:
            self._pace_call.cancel()
            self._pace_call = None
        for timer in self._timers:
            timer_tap = self._timer_taps[id(timer)]
            timer_tap.flush()  # the ticks since its last statistics record
            if timer_tap not in self._paced:
                with contextlib.suppress(Exception):  # already gone
                    timer.remove_observer(timer_tap)
        with anyio.CancelScope(shield=True):
            stats = await run_in_thread(self.pipeline.stop)
        self.final_stats = stats
        if stats.dropped:
            log.warning("recording_dropped", dropped=stats.dropped, capacity=stats.capacity)

    @property
    def stats(self) -> PipelineStats:
        """Records queued, written and dropped so far."""
        return self.pipeline.stats

    # -- time ------------------------------------------------------------------------
    def _use_clock(self, clock: Clock) -> None:
        if self._offset is None:
            self._clock = clock
            self.now = clock.now_ns
            self._offset = time.time_ns() - clock.now_ns()
            self.pipeline.offset_ns = self._offset

    # -- AppHook ---------------------------------------------------------------------
    def clock_set(self, ctx: AppContext, clock: Clock) -> None:
        self._use_clock(clock)

    def component_added(self, ctx: AppContext, component: HALComponent) -> None:
        self.observe(component)

    def timer_added(self, ctx: AppContext, timer: EventTimer) -> None:
        self.observe_timer(timer)

    def scene_added(self, ctx: AppContext, source: object) -> None:
        self.add_scene(cast(SceneSource, source))

    # -- what to observe -------------------------------------------------------------
    def observe(self, component: HALComponent) -> None:
        """Record ``component``: its channel ``/hal/<name>``; its commands, readings and
        state changes from now on, its events and errors once it is Active."""
        if id(component) in self._channels:
            return
        self._use_clock(component.clock)
        device = component.device
        limits = getattr(device, "limits", None)
        metadata = {
            "component": component.device_name,
            "kind": "actuator" if isinstance(component, Actuator) else "sensor",
            "device": str(getattr(device, "name", "") or type(device).__name__),
            "device_class": f"{type(device).__module__}.{type(device).__qualname__}",
        }
        if limits is not None:
            low, high = limits.position
            metadata.update(
                position_min=repr(low), position_max=repr(high), velocity_max=repr(limits.velocity)
            )
        channel = len(self.pipeline.channels)  # the id add_channel gives it
        listener = (
            _ActuatorTap(self, component, channel)
            if isinstance(component, Actuator)
            else _ComponentTap(self, component, channel)
        )
        component.set_listener(listener)  # refused (nothing registered) if it has another
        self._channels[id(component)] = self.pipeline.add_channel(
            hal_topic(component.device_name), HAL_RECORD, metadata
        )
        self._listeners[id(component)] = listener
        self._components.append(component)
        if isinstance(listener, _ActuatorTap):
            self._actuators.append(listener)
            if self._joint_channel < 0:
                self._joint_channel = self.pipeline.add_channel(JOINT_STATES_TOPIC, JOINT_STATES)
        if component.state is _ACTIVE:
            self.observe_events(component)

    def bank_tap(self, components: Sequence[HALComponent]) -> _BankTap | None:
        """The batch listener for a bank of ``components`` when this tap listens to each of
        them, else None (made once per set of members)."""
        key = tuple(map(id, components))
        members = [self._listeners.get(k) for k in key]
        if not members or any(m is None or m.component.listener is not m for m in members):
            return None
        found = self._bank_taps.get(key)
        if found is None:
            found = self._bank_taps[key] = _BankTap(self, cast(list[_ComponentTap], members))
            self.pipeline.batches.append(found)
            for index, member in enumerate(members):
                if isinstance(member, _ActuatorTap):
                    member.banks.append((found, index))
        return found

    def observe_events(self, component: HALComponent) -> None:
        """Record ``component``'s events and errors (from when it is Active)."""
        if id(component) not in self._observing:
            self._observing.add(id(component))
            component.add_observer(self)

    def observe_timer(self, timer: EventTimer) -> None:
        """Record ``timer``'s tick statistics (``/timer/<name>``); its ticks also pace the
        joint states and transforms. On a clock that calls back between simulation steps
        (an :class:`~openel_async.clock.InlineScheduler`: a lockstep simulation) the tap
        does not observe the timer: its own callback on that clock takes the statistics
        and the samples at their periods."""
        if id(timer) in self._channels:
            return
        self._use_clock(timer.clock)
        channel = self.pipeline.add_channel(
            timer_topic(timer.name), TIMER_TICK, {"period_ms": repr(timer.period_ms)}
        )
        self._channels[id(timer)] = channel
        observer = self._timer_taps[id(timer)] = _TimerTap(self, timer, channel)
        self._timers.append(timer)
        clock = timer.clock
        if isinstance(clock, InlineScheduler) and clock is self._clock:
            self._paced.append(observer)
            if self._pace_call is None:
                self._pace_call = clock.call_at(clock.now_ns() + self._pace_ns(), self.pace)
        else:
            timer.add_observer(observer)

    def _pace_ns(self) -> int:
        return min(self.joint_period_ns, self.timer_stats_period_ns)

    def pace(self) -> int:
        """The tap's callback on an InlineScheduler clock, every ``min(joint_period_ms,
        timer_stats_ms)``: the timers' statistics and the joint-state sample when due, and
        a batch of records encoded for the writer; returns its next deadline."""
        now = self.now()
        for timer_tap in self._paced:
            timer_tap.stats_due(now)
        if now >= self.next_joint_ns:
            self.next_joint_ns = now + self.joint_period_ns
            self.sample(now)
        self.flush_due()
        due = now + self._pace_ns()
        tick = self._paced[0].timer.last_tick
        if tick is not None:  # on one of the timer's deadlines: no extra break of the steps
            period = tick.timer.period_ns
            due += (tick.deadline_ns - due) % period
        return due

    def add_scene(self, source: SceneSource) -> None:
        """Publish ``source``'s geometry on ``/scene`` now and its body poses on ``/tf`` at
        every joint-state sample (as plain numbers, :class:`~.scene.PoseSource`, when the
        source offers them; the messages are built in the writer process)."""
        if self._tf_channel < 0:
            self._tf_channel = self.pipeline.add_channel(TF_TOPIC, FRAME_TRANSFORMS)
            self._scene_channel = self.pipeline.add_channel(SCENE_TOPIC, SCENE_UPDATE)
        frames = getattr(source, "frames", None)
        entry = (source, None if frames is None else tuple(map(tuple, frames())))
        self._scenes.append(entry)
        now = self._clock.now_ns() if self._clock is not None else 0
        log_time = now + (self._offset or 0)
        scene = scene_message(source.primitives(), log_time)
        self._put((self._scene_channel, now, MESSAGE, scene))
        self._put_poses(entry, now, log_time)

    def _put_poses(self, entry: tuple[SceneSource, Any], now: int, log_time: int) -> None:
        source, frames = entry
        if frames is None:
            frames, poses = flat_poses(source.transforms())
        else:
            poses = source.poses()  # type: ignore[attr-defined]
        self._put((self._tf_channel, now, POSES, log_time, frames, poses))

    # -- observers ---------------------------------------------------------------------
    def notify_event(self, source: HALComponent, event_id: int) -> None:
        kind = COMPLETION if event_id == _COMPLETED else EVENT
        self._put((self._channels[id(source)], source.clock.now_ns(), kind, event_id))

    def notify_error(self, source: HALComponent, error_id: int) -> None:
        self._put((self._channels[id(source)], source.clock.now_ns(), ERROR, error_id))

    def sample(self, now: int) -> None:
        """``/joint_states`` (and ``/tf``) at ``now``: each Active actuator's commanded
        position (the last one its listener heard) and actual position (its device's
        synchronous read, as ``get_value_nowait`` reads it but without its side effects: a
        non-finite value is recorded as None, not made a fault of the actuator; None when
        the device cannot read now), with no read through the framework."""
        log_time = now + (self._offset or 0)
        if self._actuators:
            joints = []
            for tap in self._actuators:
                if tap.actuator.state is not _ACTIVE:
                    continue
                commanded = tap.latest_commanded()
                read = tap.read
                if read is None:  # the framework answers the commanded value for it
                    joints.append((tap.name, commanded, commanded))
                    continue
                try:
                    actual: float | None = read(_POSITION_ACTUAL)
                except WouldBlockError:  # a bus device: no synchronous read, now or later
                    tap.read = _unreadable
                    actual = None
                except Exception:  # a fault: the component reports it on its own path
                    actual = None
                if type(actual) is not float or actual - actual != 0.0:
                    actual = None  # recorded as unknown, not made a fault of the actuator
                joints.append((tap.name, commanded, actual))
            self._put((self._joint_channel, now, JOINTS, log_time, joints))
        for entry in self._scenes:
            self._put_poses(entry, now, log_time)

    # -- log lines -------------------------------------------------------------------
    def _install_log_forwarder(self) -> None:
        config = structlog.get_config()
        processors = list(config.get("processors", ()))
        self._processors = processors
        position = max(len(processors) - 1, 0)  # before the renderer
        structlog.configure(
            processors=[*processors[:position], self._forward, *processors[position:]]
        )

    def _remove_log_forwarder(self) -> None:
        if self._processors is not None:
            structlog.configure(processors=self._processors)
            self._processors = None

    def _forward(self, logger: Any, method_name: str, event_dict: Any) -> Any:
        level = _LOG_LEVELS.get(method_name, 2)
        if level >= 2:
            wall = time.time_ns()  # the /log channel's offset is 0: wall-clock times
            fields = " ".join(
                f"{k}={v}"
                for k, v in event_dict.items()
                if k not in ("event", "timestamp", "level")
            )
            name = str(event_dict.get("logger", event_dict.get("component", "")))
            message = f"{event_dict.get('event', '')} {fields}".strip()
            self._put((self._log_channel, wall, LOG_LINE, wall, level, message, name))
        return event_dict
