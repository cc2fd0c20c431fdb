"""The tap: what the recorder and the live view attach to an application's components and
timers. It turns every command, reading, event, completion, error, state change and timer
tick into a record for a :class:`~.pipeline.Pipeline` (a tuple appended to its queue by a
listener object per component and an observer per timer: the only work done in the control
loop); the writer process makes them the messages of
:mod:`.schemas`. Nothing here blocks or raises into the control loop.

A :class:`Tap` is an :class:`~openel_async.app.AppHook` (``--record``/``--foxglove``
attach it to any app) and can be used directly::

    async with Recorder("run.mcap") as rec:
        rec.observe(actuator)          # before or after entering it
        rec.observe_timer(timer)

The listeners it sets on components and banks are in :mod:`.component_taps`, its observer of
each timer in :mod:`.timer_tap`.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import os
import time
from collections.abc import Callable, Sequence
from types import TracebackType
from typing import Any, cast

import anyio
import structlog

from openel_async.logs import ensure_configured, get_logger

from ..actuator import Actuator
from ..app import AppContext, AppHook
from ..clock import Clock, InlineScheduler, ScheduledCall, run_in_thread
from ..component import ComponentState, HALComponent
from ..errors import HALError, WouldBlockError
from ..ids import DeviceKind, component_name, profile_name
from ..requests import EventId, Request
from ..timer import EventTimer
from .component_taps import ActuatorTap, BankTap, ComponentTap
from .pipeline import Pipeline, PipelineStats
from .records import (
    COMPLETION,
    ERROR,
    EVENT,
    JOINTS,
    LOG_LINE,
    MESSAGE,
    POSE_BYTES,
    POSES,
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
from .timer_tap import TimerTap, next_due

__all__ = ["Tap"]

log = get_logger(__name__)

_ACTIVE = ComponentState.ACTIVE
_COMPLETED = int(EventId.COMPLETED)
_POSITION_ACTUAL = Request.POSITION_ACTUAL
FRESH_PERIODS = 5
"""A joint-state sample of a device that reads only with I/O takes the application's latest
read when it is at most this many joint periods old (a late tick of a busy real-time loop
moves the reads by tens of ms), else the position is unknown."""
_LOG_LEVELS = {"debug": 1, "info": 2, "warning": 3, "warn": 3, "error": 4, "critical": 5}


def is_joint(component: HALComponent) -> bool:
    """``component`` is a joint of ``/joint_states``: an Actuator of the HAL Motor kind (a
    rotary or linear motor), not an extension device such as a suction cup."""
    return isinstance(component, Actuator) and component.hal_id.device_kind_id == DeviceKind.MOTOR


def user_name(component: HALComponent) -> str:
    """The name to show for ``component``: its component name, unless that is the one
    HAL4RT derives from its device's class (``HalMotorMuJoCoShoulder``) and the device has a
    name of its own (the model's joint, ``shoulder``)."""
    name = component.device_name
    own = getattr(component.device, "name", None)
    if not isinstance(own, str) or not own:
        return name
    info = component.device.info
    try:
        derived = component_name(
            profile_name(component.hal_id.device_kind_id), info.vendor_name, info.product_name
        )
    except HALError:
        return name
    return own if name == derived else name


def _unreadable(request: Request) -> float:
    """The read of a device without a synchronous read path: nothing (NaN: None)."""
    return math.nan


def _never() -> int:
    """The clock's time before the tap knows a clock."""
    return 0


class Tap(AppHook):
    """Observe components and timers into an MCAP file (``record``) and/or a Foxglove server
    (``foxglove``: (host, port); port 0: any free port).

    ``joint_period_ms``: the period of ``/joint_states`` (and ``/tf``) samples, taken at the
    observed timers' ticks, on the app's clock (default 20 ms: 50 Hz, the default
    ``publish_frequency`` of ROS 1's robot_state_publisher); ``timer_stats_ms``: the period of each timer's statistics messages
    (``/timer/<name>``). ``capacity``: records the queue holds before
    it drops (counted in :attr:`stats`). ``logs``: forward log lines (info and above) to
    ``/log``. ``chunk_size``: bytes per MCAP chunk (a killed run loses at most one)."""

    def __init__(
        self,
        *,
        record: str | os.PathLike[str] | None = None,
        foxglove: tuple[str, int] | None = None,
        joint_period_ms: float = 20.0,
        timer_stats_ms: float = 100.0,
        capacity: int = 100_000,
        logs: bool = True,
        chunk_size: int = 64 * 1024,
    ) -> None:
        if not joint_period_ms > 0:
            raise ValueError(f"joint_period_ms must be > 0, got {joint_period_ms}")
        if not timer_stats_ms > 0:
            raise ValueError(f"timer_stats_ms must be > 0, got {timer_stats_ms}")
        self.pipeline = Pipeline(
            mcap=record, foxglove=foxglove, capacity=capacity, chunk_size=chunk_size
        )
        self._put = self.pipeline.put
        self.joint_period_ns = round(joint_period_ms * 1e6)
        self.timer_stats_period_ns = round(timer_stats_ms * 1e6)
        self._pace_period = min(self.joint_period_ns, self.timer_stats_period_ns)
        self._logs = logs
        self._offset: int | None = None
        self._clock: Clock | None = None
        self._channels: dict[int, int] = {}  # id(component or timer) -> channel
        self._listeners: dict[int, ComponentTap] = {}  # id(component) -> its listener
        self._timer_taps: dict[int, TimerTap] = {}  # id(timer) -> its observer
        self._components: list[HALComponent] = []
        self._observing: set[int] = set()
        self._timers: list[EventTimer] = []
        self._actuators: list[ActuatorTap] = []  # their listeners
        self._scenes: list[tuple[SceneSource, Any, Any]] = []
        """(source, its frames or None, its pose_bytes or None)."""
        self.next_joint_ns = 0
        """When the next joint-state sample is due (clock ns)."""
        self.now: Callable[[], int] = _never
        """The app's clock's ``now_ns`` (once known)."""
        self.flush_due = self.pipeline.flush_due
        self._paced: list[TimerTap] = []  # the timers on an InlineScheduler clock
        self._pace_call: ScheduledCall | None = None  # the tap's callback on that clock
        self._bank_taps: dict[tuple[int, ...], BankTap] = {}  # ids of the members -> it
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
        try:
            loop = asyncio.get_running_loop()
        except RuntimeError:  # not on asyncio: the pipeline's thread writes
            pass
        else:
            self.pipeline.drive_from(loop)  # the loop writes: no thread wakes up meanwhile
        offset, self.pipeline.offset_ns = self.pipeline.offset_ns, 0
        self._log_channel = self.pipeline.add_channel(LOG_TOPIC, LOG)  # times: log times
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
        self.pipeline.release_loop()  # detached: the thread takes what is left at stop
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
        label = user_name(component)
        if label != component.device_name:
            metadata["label"] = label
        joint = is_joint(component)
        if isinstance(component, Actuator):
            metadata["unit"] = "m" if getattr(device, "linear", False) else "rad"
            metadata["joint"] = "true" if joint else "false"
        if limits is not None:
            low, high = limits.position
            metadata.update(
                position_min=repr(low), position_max=repr(high), velocity_max=repr(limits.velocity)
            )
        channel = len(self.pipeline.channels)  # the id add_channel gives it
        listener = (
            ActuatorTap(self, component, channel)
            if isinstance(component, Actuator)
            else ComponentTap(self, component, channel)
        )
        component.set_listener(listener)  # refused (nothing registered) if it has another
        self._channels[id(component)] = self.pipeline.add_channel(
            hal_topic(component.device_name), HAL_RECORD, metadata
        )
        self._listeners[id(component)] = listener
        self._components.append(component)
        if isinstance(listener, ActuatorTap) and joint:  # a suction cup is no joint
            self._actuators.append(listener)
            if self._joint_channel < 0:
                self._joint_channel = self.pipeline.add_channel(JOINT_STATES_TOPIC, JOINT_STATES)
        if component.state is _ACTIVE:
            self.observe_events(component)

    def bank_tap(self, components: Sequence[HALComponent]) -> BankTap | None:
        """The batch listener for a bank of ``components`` when this tap listens to each of
        them, else None (made once per set of members)."""
        key = tuple(map(id, components))
        members = [self._listeners.get(k) for k in key]
        if not members or any(m is None or m.component.listener is not m for m in members):
            return None
        found = self._bank_taps.get(key)
        if found is None:
            found = self._bank_taps[key] = BankTap(self, cast(list[ComponentTap], members))
            self.pipeline.batches.append(found)
            for index, member in enumerate(members):
                if isinstance(member, ActuatorTap):
                    member.banks.append((found, index))
                    member.marks.append(0)
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
        observer = self._timer_taps[id(timer)] = TimerTap(self, timer, channel)
        self._timers.append(timer)
        clock = timer.clock
        if isinstance(clock, InlineScheduler) and clock is self._clock:
            self._paced.append(observer)
            if self._pace_call is None:
                self._pace_call = clock.call_at(clock.now_ns() + self._pace_period, self.pace)
        else:
            timer.add_observer(observer)

    def pace(self) -> int:
        """The tap's callback on an InlineScheduler clock, every ``min(joint_period_ms,
        timer_stats_ms)``: the timers' statistics and the joint-state sample when due, and
        a batch of records encoded for the writer; returns its next deadline."""
        now = self.now()
        for timer_tap in self._paced:
            if now + (timer_tap.timer_period_ns >> 1) >= timer_tap.next_ns:  # stats_due's test
                timer_tap.stats_due(now)
        if now >= self.next_joint_ns:  # on the timer's deadlines: exact
            self.next_joint_ns = next_due(self.next_joint_ns, self.joint_period_ns, now, 0)
            self.sample(now)
        self.flush_due()
        due = now + self._pace_period
        timer = self._paced[0].timer
        fields = timer.last_tick_fields
        if fields is not None:  # on one of the timer's deadlines: no extra break of the steps
            due += (fields[1] - due) % timer.period_ns
        return due

    def add_scene(self, source: SceneSource) -> None:
        """Publish ``source``'s geometry on ``/scene`` now and its body poses on ``/tf`` at
        every joint-state sample (as plain numbers, :class:`~.scene.PoseSource`, when the
        source offers them; the messages are built in the writer process)."""
        if self._tf_channel < 0:
            self._tf_channel = self.pipeline.add_channel(TF_TOPIC, FRAME_TRANSFORMS)
            self._scene_channel = self.pipeline.add_channel(SCENE_TOPIC, SCENE_UPDATE)
        frames = getattr(source, "frames", None)
        entry = (
            source,
            None if frames is None else tuple(map(tuple, frames())),
            getattr(source, "pose_bytes", None) if frames is not None else None,
        )
        self._scenes.append(entry)
        now = self._clock.now_ns() if self._clock is not None else 0
        log_time = now + (self._offset or 0)
        scene = scene_message(source.primitives(), log_time)
        self._put((self._scene_channel, now, MESSAGE, scene))
        self._put_poses(entry, now, log_time)

    def _put_poses(self, entry: tuple[SceneSource, Any, Any], now: int, log_time: int) -> None:
        source, frames, pose_bytes = entry
        if pose_bytes is not None:  # the cheapest: two byte strings
            positions, orientations = pose_bytes()
            self._put(
                (self._tf_channel, now, POSE_BYTES, log_time, frames, positions, orientations)
            )
            return
        if frames is None:
            frames, poses = flat_poses(source.transforms())
        else:
            poses = source.poses()  # type: ignore[attr-defined]
        self._put((self._tf_channel, now, POSES, log_time, frames, poses))

    # -- observers ---------------------------------------------------------------------
    def notify_event(self, source: HALComponent, event_id: int) -> None:
        self._listeners[id(source)].hand_over()
        kind = COMPLETION if event_id == _COMPLETED else EVENT
        self._put((self._channels[id(source)], source.clock.now_ns(), kind, event_id))

    def notify_error(self, source: HALComponent, error_id: int) -> None:
        self._listeners[id(source)].hand_over()
        self._put((self._channels[id(source)], source.clock.now_ns(), ERROR, error_id))

    def sample(self, now: int) -> None:
        """``/joint_states`` (and ``/tf``) at ``now``: each Active joint's commanded
        position (the last one its listener heard) and actual position (the application's
        own ``POSITION_ACTUAL`` read at this very clock time, when it made one; else its
        device's synchronous read, as ``get_value_nowait`` reads it but without its side
        effects: a non-finite value is recorded as None, not made a fault of the actuator;
        for a device that reads only with I/O -- a bus drive, which the application reads
        with an awaited ``get_value`` that ends after the sample's instant -- the
        application's latest read within the last :data:`FRESH_PERIODS` joint periods; else
        None), with no read through the framework."""
        log_time = now + (self._offset or 0)
        if self._actuators:
            joints = []
            fresh = FRESH_PERIODS * self.joint_period_ns
            for tap in self._actuators:
                if tap.actuator.state is not _ACTIVE:
                    continue
                commanded = tap.latest_commanded()
                read = tap.read
                if read is None:  # the framework answers the commanded value for it
                    joints.append((tap.name, commanded, commanded))
                    continue
                app_read = None
                at = -1
                for readings, index, width in tap.actuals:  # the app's latest read
                    times = readings.times
                    n = len(times)
                    if n:
                        if times[n - 1] > at:
                            at = times[n - 1]
                            app_read = readings.values[(n - 1) * width + index]
                    elif readings.last_values is not None and readings.last_time > at:
                        at = readings.last_time
                        app_read = readings.last_values[index]
                if app_read is not None and at == now:  # read at this very time
                    joints.append((tap.name, commanded, app_read))
                    continue
                actual: float | None = None
                if read is not _unreadable:
                    try:
                        actual = read(_POSITION_ACTUAL)
                    except WouldBlockError:  # a bus device: no synchronous read, now or later
                        tap.read = read = _unreadable
                    except Exception:  # a fault: the component reports it on its own path
                        actual = None
                    if type(actual) is not float or actual - actual != 0.0:
                        actual = None  # recorded as unknown, not made a fault of the actuator
                if read is _unreadable and app_read is not None and now - at <= fresh:
                    actual = app_read  # what the drive last reported to the application
                joints.append((tap.name, commanded, actual))
            self._put((self._joint_channel, now, JOINTS, log_time, joints))
        for entry in self._scenes:
            self._put_poses(entry, now, log_time)

    # -- log lines -------------------------------------------------------------------
    def _install_log_forwarder(self) -> None:
        ensure_configured()  # an application's configuration first, then the forwarder in it
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
            # On the app's clock shifted to the wall clock, as every other channel (the
            # /log channel's offset is 0: its records carry their log time); before a clock
            # is known, the wall clock (the shift is taken from it then).
            offset = self._offset
            wall = time.time_ns() if offset is None else self.now() + offset
            fields = " ".join(
                f"{k}={v}"
                for k, v in event_dict.items()
                if k not in ("event", "timestamp", "level")
            )
            name = str(event_dict.get("logger", event_dict.get("component", "")))
            message = f"{event_dict.get('event', '')} {fields}".strip()
            self._put((self._log_channel, wall, LOG_LINE, wall, level, message, name))
        return event_dict
