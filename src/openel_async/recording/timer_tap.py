"""The tap's view of one timer (:class:`TimerTap`): its tick statistics records and, on a
clock that is not an InlineScheduler, the pace of the tap's joint-state samples; and
:func:`next_due`, the grid those periods keep.

Used by :mod:`.tap`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..timer import EventTimer
from .records import TICK

if TYPE_CHECKING:
    from .tap import Tap

__all__ = ["TimerTap", "next_due"]


class TimerTap:
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
