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
from ..device import ValueSource
from ..errors import HALError, WouldBlockError
from ..ids import DeviceKind, component_name, profile_name
from ..listeners import BatchListener
from ..requests import EventId, Request
from ..timer import EventTimer
from .columns import Columns
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
    POSE_BYTES,
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

log = get_logger(__name__)

_ACTIVE = ComponentState.ACTIVE
_COMPLETED = int(EventId.COMPLETED)
_POSITION = Request.POSITION
_POSITION_ACTUAL = Request.POSITION_ACTUAL
_POSITION_CODE = int(Request.POSITION)
FRESH_PERIODS = 5
"""A joint-state sample of a device that reads only with I/O takes the application's latest
read when it is at most this many joint periods old (a late tick of a busy real-time loop
moves the reads by tens of ms), else the position is unknown."""
_LOG_LEVELS = {"debug": 1, "info": 2, "warning": 3, "warn": 3, "error": 4, "critical": 5}


class _ComponentTap:
    """The listener the tap sets on one component: its records go straight into the
    pipeline (one call from the component; no lookup of the channel).

    Readings go to column buffers (:mod:`.columns`): one per request code, made at the
    first reading of that code (its width: that reading's number of values); the common one
    -- the first code read -- is kept at hand. A reading of another width, and state
    changes, go to the queue as tuples of ints, floats, None and strings (a Request as its
    int: the garbage collector then untracks them at its first passes)."""

    __slots__ = (
        "actuals",
        "capacity",
        "channel",
        "component",
        "muted",
        "now",
        "pipeline",
        "queue",
        "read_code",
        "read_times",
        "read_values",
        "read_width",
        "readings",
        "tap",
    )

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
        self.actuals: list[tuple[Columns, int, int]] = []
        """The column buffers of its POSITION_ACTUAL readings (its own, its banks' reads):
        each with its value's index in a record and the record's width."""
        self.readings: dict[Request | None, Columns | None] = {}
        """Request -> the column buffer of its readings (None: they do not fit one)."""
        self.read_code: Request | bool | None = False  # the request of the buffer at hand
        # (False: none yet; True: none, its reads take the other path, _ActuatorTap._reading)
        self.read_times: list[int] = []
        self.read_values: list[float] = []
        self.read_width = 0

    def on_command(
        self, component: HALComponent, request: Request, value: float, time_ns: int
    ) -> None:
        self.hand_over()
        queue = self.queue
        if len(queue) < self.capacity:
            queue.append((self.channel, time_ns, COMMAND, int(request), value))
        else:
            self.pipeline.dropped += 1

    def hand_over(self) -> None:
        """Queue what this component's column buffers hold: before a record of its channel
        goes to the queue (the writer gets a channel's records in order)."""
        pipeline = self.pipeline
        for columns in self.readings.values():
            if columns is not None and columns.times:
                pipeline.hand_over(columns)

    def on_reading(
        self, component: HALComponent, request: Request | None, values: tuple[float, ...]
    ) -> None:
        if request is self.read_code and len(values) == self.read_width and not self.muted:
            times = self.read_times  # Columns.append, inline (the per-tick path)
            if len(times) < self.capacity:
                times.append(self.now())
                self.read_values.extend(values)
            else:
                self.pipeline.dropped += 1
            return
        if self.muted:  # the tap's own read
            return
        self._reading(request, values)

    def _reading(self, request: Request | None, values: tuple[float, ...]) -> None:
        """A reading off the path at hand: into its request's column buffer, else queued."""
        if request in self.readings:
            columns = self.readings[request]
        else:  # the first reading of this request: its buffer
            code = None if request is None else int(request)
            columns = None
            if values and all(type(v) is float for v in values):  # as readings are
                columns = self.pipeline.add_columns(READING, code, (self.channel,), len(values))
            self.readings[request] = columns
            if columns is not None and request is _POSITION_ACTUAL:
                self.actuals.append((columns, 0, columns.width))  # the sample looks at it
            if columns is not None and self.read_code is False:
                self.read_code = request
                self.read_times, self.read_values = columns.times, columns.values
                self.read_width = columns.width
        if columns is not None and len(values) == columns.width:
            if not columns.append(self.now(), values):
                self.pipeline.dropped += 1
            return
        self.hand_over()
        code = None if request is None else int(request)
        self.pipeline.put((self.channel, self.now(), READING, code, values))

    def on_state(self, component: HALComponent, old: ComponentState, new: ComponentState) -> None:
        self.hand_over()
        self.pipeline.put((self.channel, self.now(), STATE, str(old), str(new)))
        if new is _ACTIVE:
            self.tap.observe_events(component)


class _ActuatorTap(_ComponentTap):
    """An actuator's listener: its position commands go to a column buffer; it also keeps
    what the joint-state sample needs without reading through the framework: the commanded
    position (the last POSITION command it heard, or the latest of its banks' batches
    (:class:`_BankTap`) when one came after it: each bank's batch count is noted at each
    of its own commands; read once through the framework after each activation, which
    resets it) and the device's own actual-position read (``None``: the framework answers
    the commanded value for it, or the device has no synchronous read).

    Its POSITION commands go to a column buffer while it is in no bank; a bank member's
    own commands (rare: the bank streams) go to the queue after the bank's earlier
    batches, so that the file keeps their order."""

    __slots__ = (
        "actuator",
        "banks",
        "command_times",
        "command_values",
        "commanded",
        "commands",
        "marks",
        "name",
        "read",
    )

    def __init__(self, tap: Tap, component: Actuator, channel: int) -> None:
        super().__init__(tap, component, channel)
        self.actuator = component
        self.name = component.device_name
        self.commanded: float | None = None
        """The last POSITION command heard since the last state change (None: unknown)."""
        self.banks: list[tuple[_BankTap, int]] = []
        """The batch listeners of the banks it is in, and its index in each."""
        self.marks: list[int] = []
        """Each bank's batch count at its last own command or state change (a bank
        joined since: 0), in the order of :attr:`banks`."""
        self.commands: Columns | None = None  # its POSITION commands (made at the first)
        self.command_times: list[int] = []
        self.command_values: list[float] = []
        measured = component.value_source(_POSITION_ACTUAL) is not ValueSource.COMMANDED
        self.read: Callable[[Request], float] | None = (
            component.device.read_nowait if measured else None
        )

    def on_command(
        self, component: HALComponent, request: Request, value: float, time_ns: int
    ) -> None:
        if request is _POSITION:
            self.commanded = value
            if self.banks:
                self.mark()
        if request is _POSITION and not self.banks:
            times = self.command_times  # Columns.append, inline
            if len(times) < self.capacity:
                if self.commands is None:
                    self._command_columns()
                    times = self.command_times
                times.append(time_ns)
                self.command_values.append(value)
            else:
                self.pipeline.dropped += 1
            return
        self.hand_over()
        queue = self.queue
        if len(queue) < self.capacity:
            queue.append((self.channel, time_ns, COMMAND, int(request), value))
        else:
            self.pipeline.dropped += 1

    def hand_over(self) -> None:
        super().hand_over()
        pipeline = self.pipeline
        commands = self.commands
        if commands is not None and commands.times:
            pipeline.hand_over(commands)
        for bank, _ in self.banks:
            bank.hand_over()

    def _reading(self, request: Request | None, values: tuple[float, ...]) -> None:
        """Its own read of a code that one of its banks reads too: the banks' reads held
        first, and its later own reads of it stay off the path at hand (and the bank's too,
        :meth:`_BankTap._read`): the two sources of one channel keep their order."""
        shared = False
        for bank, _ in self.banks:
            if request in bank.reads:
                shared = True
                bank.hand_over()
                if bank.read_code is request:
                    bank.read_code = None
        super()._reading(request, values)
        if shared and self.read_code is request:
            self.read_code = True

    def _command_columns(self) -> None:
        columns = self.pipeline.add_columns(COMMAND, _POSITION_CODE, (self.channel,), 1)
        self.commands = columns
        self.command_times, self.command_values = columns.times, columns.values

    def on_state(self, component: HALComponent, old: ComponentState, new: ComponentState) -> None:
        self.commanded = None  # an activation sets it to the actual position
        self.mark()  # and the banks' earlier batches are older
        super().on_state(component, old, new)

    def batch_listener(self, components: Sequence[HALComponent]) -> BatchListener | None:
        """The batch listener of a bank of ``components`` (every one observed by this tap):
        its :meth:`_BankTap.on_batch` (a bound method: the cheapest call, not an instance's
        ``__call__``), else None (each member's listener hears its command)."""
        bank = self.tap.bank_tap(components)
        return None if bank is None else bank.on_batch

    def latest_commanded(self) -> float | None:
        """The commanded position: the last POSITION command heard, its own or in a bank's
        batch, whichever came last (read through the framework after an activation)."""
        commanded = self.commanded
        banks = self.banks
        if len(banks) == 1 and not banks[0][0].drops:  # the usual case: one bank, no drop
            bank, index = banks[0]
            columns = bank.columns
            times = columns.times
            n = len(times)
            if columns.taken + n > self.marks[0]:  # a batch since its own command
                if n:
                    return columns.values[(n - 1) * columns.width + index]
                if columns.last_values is not None:
                    return columns.last_values[index]
        elif banks:  # _BankTap.batches and latest, inline (every sample)
            at = -1
            for (bank, index), mark in zip(banks, self.marks, strict=True):
                columns = bank.columns
                times = columns.times
                n = len(times)
                count = columns.taken + n + bank.drops
                if count <= mark:  # none since its own command
                    continue
                if bank.lost_at == count and bank.lost is not None:  # the latest was dropped
                    t, value = bank.lost[0], bank.lost[1][index]
                elif n:
                    t, value = times[n - 1], columns.values[(n - 1) * columns.width + index]
                elif columns.last_values is not None:
                    t, value = columns.last_time, columns.last_values[index]
                else:
                    continue
                if t > at:  # the newest bank's
                    at, commanded = t, value
        if commanded is None:
            commanded = self.read_commanded()
        return commanded

    def mark(self) -> None:
        """Note each bank's batch count (its own command or a state change came now)."""
        self.marks = [bank.batches() for bank, _ in self.banks]

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
        return self.commanded


class _BankTap:
    """The batch listener of a bank (:func:`openel_async.listeners.batch_listener`): a
    POSITION batch is a record of a column buffer (:mod:`.columns`; the writer process makes
    a COMMAND message of each value on its component's channel), another command's a BATCH
    record in the queue; the latest POSITION batch is what the joint-state sample takes
    (:meth:`_ActuatorTap.latest_commanded`). A read of the members (an actual-value code) is
    a record of that code's column buffer (a READING message of each value on its
    component's channel); the first code read is kept at hand."""

    __slots__ = (
        "capacity",
        "channels",
        "columns",
        "count",
        "drops",
        "lost",
        "lost_at",
        "members",
        "pipeline",
        "queue",
        "read_code",
        "read_times",
        "read_values",
        "reads",
        "size",
        "times",
        "values",
    )

    def __init__(self, tap: Tap, members: Sequence[_ComponentTap]) -> None:
        self.members = tuple(members)
        self.channels = tuple(m.channel for m in members)
        self.size = len(members)
        self.pipeline = tap.pipeline
        self.queue = tap.pipeline.queue
        self.capacity = tap.pipeline.capacity
        self.columns = tap.pipeline.add_columns(COMMAND, _POSITION_CODE, self.channels, self.size)
        self.times = self.columns.times
        self.values = self.columns.values
        self.count = 0
        """BATCH records queued (the pipeline counts ``size`` messages for each)."""
        self.lost: tuple[int, tuple[float, ...]] | None = None
        """The latest POSITION batch that was dropped (its time and values)."""
        self.drops = 0
        """POSITION batches dropped so far."""
        self.lost_at = 0
        """:meth:`batches` when :attr:`lost` was dropped."""
        self.reads: dict[Request, Columns | None] = {}
        """Actual-value code -> the column buffer of the reads (None: they do not fit one)."""
        self.read_code: Request | None = None  # the code of the buffer at hand
        self.read_times: list[int] = []
        self.read_values: list[float] = []

    def on_batch(self, request: Request, values: Sequence[float], time_ns: int) -> None:
        """The :data:`~openel_async.listeners.BatchListener`."""
        if request is _POSITION:  # Columns.append, inline (the per-tick path)
            times = self.times
            if len(times) < self.capacity:
                times.append(time_ns)
                self.values.extend(values)
            else:
                self.pipeline.dropped += self.size
                self.lost = (time_ns, tuple(values))  # not recorded, but the latest command
                self.drops += 1
                self.lost_at = self.batches()
            return
        if request is self.read_code:  # the members' actual positions read (per tick)
            times = self.read_times
            if len(times) < self.capacity:
                times.append(time_ns)
                self.read_values.extend(values)
            else:
                self.pipeline.dropped += self.size
            return
        if not request.is_command:
            self._read(request, values, time_ns)
            return
        for member in self.members:  # their channels' earlier records first
            member.hand_over()
        self.hand_over()
        queue = self.queue
        if len(queue) < self.capacity:
            queue.append((BATCH, time_ns, COMMAND, int(request), self.channels, tuple(values)))
            self.count += 1
        else:
            self.pipeline.dropped += self.size

    def _read(self, request: Request, values: Sequence[float], time_ns: int) -> None:
        """A read off the path at hand: into its code's column buffer (made at its first
        read), else each value to its member's listener."""
        if request in self.reads:
            columns = self.reads[request]
        else:
            columns = None
            if all(type(v) is float for v in values):  # as the actual values are
                code = int(request)
                columns = self.pipeline.add_columns(READING, code, self.channels, self.size)
                if request is _POSITION_ACTUAL:  # the joint-state sample looks at it
                    for index, member in enumerate(self.members):
                        member.actuals.append((columns, index, self.size))
            self.reads[request] = columns
            own = [m for m in self.members if request in m.readings]
            for member in own:  # its own reads of it leave the path at hand (see _reading)
                if member.read_code is request:
                    member.read_code = True
            if columns is not None and self.read_code is None and not own:
                self.read_code = request
                self.read_times, self.read_values = columns.times, columns.values
        if columns is not None and all(type(v) is float for v in values):
            for member in self.members:  # a member's own reads held: they came first
                if request in member.readings:
                    member.hand_over()
            if not columns.append(time_ns, values):
                self.pipeline.dropped += self.size
            return
        for member, value in zip(self.members, values, strict=True):
            member.on_reading(member.component, request, (value,))

    def hand_over(self) -> None:
        """Queue what its column buffers hold (before another record of its members)."""
        pipeline = self.pipeline
        if self.times:
            pipeline.hand_over(self.columns)
        for columns in self.reads.values():
            if columns is not None and columns.times:
                pipeline.hand_over(columns)

    def batches(self) -> int:
        """POSITION batches heard so far (held, handed over or dropped)."""
        columns = self.columns
        return columns.taken + len(self.times) + self.drops


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
        fields = timer.last_tick_fields
        self.last_index = 0 if fields is None else fields[0]
        self.delivered = timer.ticks_delivered  # at the last statistics record

    def notify_timer(self, timer: EventTimer) -> None:
        self.ticks += 1
        if self.ticks >= self.due:
            self.check(timer)

    def check(self, timer: EventTimer) -> None:
        tap = self.tap
        now = self.now()
        self.stats_due(now)
        slack = self.timer_period_ns >> 1  # a tick's jitter: the look is on time
        if now + slack >= tap.next_joint_ns:
            tap.next_joint_ns = next_due(tap.next_joint_ns, tap.joint_period_ns, now, slack)
            tap.sample(now)
        self.ticks = 0
        self.due = self.step
        tap.flush_due()  # a batch of records encoded here, written by the pipeline's thread

    def stats_due(self, now: int) -> None:
        """The statistics record if its period has passed at ``now``."""
        slack = self.timer_period_ns >> 1
        if now + slack >= self.next_ns:
            self.next_ns = next_due(self.next_ns, self.period_ns, now, slack)
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
        fields = timer.last_tick_fields  # no TimerTick built
        if fields is None or not ticks:
            return
        index, deadline_ns, time_ns, _ = fields
        missed = index - self.last_index - ticks
        self.last_index = index
        self.delivered = delivered
        self.tap.pipeline.put((self.channel, time_ns, TICK, index, deadline_ns, missed, ticks))


def next_due(due: int, period: int, now: int, slack: int) -> int:
    """The deadline after ``due`` (reached at ``now``): one ``period`` later, on the same
    grid, so that looks every few ticks keep the period on average; after a pause (that
    one already passed) one period from now. ``slack``: how early a look may come."""
    following = due + period
    return following if following + slack > now else now + period


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
        self._listeners: dict[int, _ComponentTap] = {}  # id(component) -> its listener
        self._timer_taps: dict[int, _TimerTap] = {}  # id(timer) -> its observer
        self._components: list[HALComponent] = []
        self._observing: set[int] = set()
        self._timers: list[EventTimer] = []
        self._actuators: list[_ActuatorTap] = []  # their listeners
        self._scenes: list[tuple[SceneSource, Any, Any]] = []
        """(source, its frames or None, its pose_bytes or None)."""
        self.next_joint_ns = 0
        """When the next joint-state sample is due (clock ns)."""
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
        if isinstance(listener, _ActuatorTap) and joint:  # a suction cup is no joint
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
        observer = self._timer_taps[id(timer)] = _TimerTap(self, timer, channel)
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
