"""SYNC from an EventTimer: :class:`CanSync`, the CANopen SYNC producer of one bus.

The framework's :class:`~openel_async.EventTimer` drives the axes (an
:class:`~openel_async.motion.AxisGroup` streams its setpoints on it); :class:`CanSync`
observes the same timer. The set-points and the SYNC go out this way:

1. a cyclic drive stages the RPDO of its latest set-point (:meth:`stage`, called by
   :class:`~openel_can.cyclic402.Cia402CyclicDrive` from its synchronous command path; a
   newer set-point of the same drive replaces the older). What a plain timer observer
   registered after the producer stages in the tick (an AxisGroup computing the
   set-points) is sent at the end of that tick, after the timer's last observer (the
   producer keeps a second observer of its own last: no extra pass of the event loop);
   what is staged anywhere else is sent as soon as the code staging it yields to the event
   loop (one ``call_soon`` per burst);
2. at every tick, in the tick itself (a plain ``notify_timer``, no task hop), the SYNC
   goes out first (COB-ID 0x080; with ``counter_overflow`` (CiA 301 0x1019, 2..240) one
   data byte counting the SYNCs sent 1..overflow, 1 again after overflow, else none),
   after any RPDO still staged, and latches them. Nothing else runs between the timer's
   wake-up and the SYNC, so the SYNC's period jitter is the wake-up's;
3. then, on a bus read in the event loop through its descriptor (``socketcan``), what
   arrived since the last tick is read (:meth:`CanBus.read_now`: the TPDOs answering the
   previous SYNC, EMCY, SDO answers ...), and the bus is left unread until the next tick:
   one event-loop wake-up a cycle instead of one per frame or batch (``read_on_tick``; a
   stopped or stalled timer leaves the bus read as before within two periods). A frame
   other than a TPDO (an EMCY, an SDO answer) is then handled at the tick after it
   arrived, at most one period later.

Every RPDO of a cycle therefore goes out before the SYNC that latches it (a CiA 402 drive
takes an RPDO on receipt and applies its target at the next SYNC; RPDOs are taken in the
order they arrive, so a quick stop sent after an RPDO overrides its controlword). The
synchronous TPDOs the drives send in answer to SYNC number ``k`` (:attr:`CanSync.cycle` =
``k`` while they arrive, or when they are read at the next tick) are taken by each drive
as cycle ``k``'s actual values (``Cia402CyclicDrive.feedback_cycle``). An AxisGroup
computes the setpoints of tick ``k`` after the tick was delivered, so they leave with SYNC
``k + 1``: one period of transport delay, and a SYNC whose timing does not depend on how
long the computation took.

Missed cycles are counted, never burst: a tick the timer skipped (it woke a whole period
late: ``TimerTick.missed_ticks``) sends nothing for the cycles it skipped, and a SYNC the bus
could not take (down, transmit queue full) counts as missed too (the counter does not advance
for it: the next SYNC sent carries the next value); both are in :attr:`stats`
and logged (at most once a second). One SYNC producer per bus: a ``CanBus(sync_period=...)``
with its own is refused.
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass
from typing import Final, Protocol

from openel_async.errors import BadParameterError, NotConnectedError, StateError
from openel_async.logs import get_logger
from openel_async.timer import EventTimer, TimerState

from . import canopen as co
from .bus import CanBus, NodePort, TxMessage

__all__ = ["CanSync", "SyncConsumer", "SyncStats"]

log = get_logger(__name__)

_NS_PER_S: Final = 1_000_000_000
_PLACE_EVERY: Final = 64


class SyncConsumer(Protocol):
    """A drive that answers every SYNC with a TPDO (checked by :class:`CanSync`)."""

    @property
    def feedback_cycle(self) -> int:
        """The SYNC (:attr:`CanSync.cycle`) of the last synchronous TPDO received."""
        ...

    async def set_cycle(self, period_ns: int, counter_overflow: int = 0) -> None:
        """The cycle is ``period_ns`` from now on (a drive writes its 0x60C2), its SYNC
        counting 1..``counter_overflow`` (0: no counter; a drive writes its 0x1019)."""
        ...


@dataclass(frozen=True, slots=True)
class SyncStats:
    cycles: int
    """SYNC messages sent."""
    missed: int
    """Cycles without a SYNC: ticks the timer skipped, SYNCs the bus could not take."""
    rpdos: int
    """RPDOs sent before a SYNC."""
    dropped_rpdos: int
    """Staged RPDOs the bus could not take (down, transmit queue full)."""
    late_feedback: int
    """Cycles in which a consumer's TPDO answering the previous SYNC had not arrived when
    the next tick came."""


class CanSync:
    """The SYNC producer of one :class:`CanBus` on an :class:`EventTimer` (module docstring).

    ``CanSync.of(bus)`` is the bus's one instance (shared by the drives on it);
    :meth:`start` ties it to a timer, :meth:`stop` unties it.
    """

    def __init__(self, bus: CanBus) -> None:
        if not isinstance(bus, CanBus):
            raise BadParameterError("bus", bus, "an openel_can.CanBus")
        self.bus = bus
        self.timer: EventTimer | None = None
        self.counter_overflow = 0
        self.cycle = 0
        """SYNC messages sent so far (the number of the latest)."""
        self._counter = 0
        self._sync_frames: list[TxMessage] = []
        self._sync_count = 1
        self._staged: dict[int, bytes] = {}
        self._consumers: list[SyncConsumer] = []
        self._port: NodePort | None = None
        self._missed = 0
        self._rpdos = 0
        self._dropped = 0
        self._late = 0
        self._last_warning_ns: int | None = None
        self.read_on_tick = True
        """Read the bus at each tick (module docstring, step 3): set by :meth:`start`."""
        self._hold_s = 0.0
        self._loop: asyncio.AbstractEventLoop | None = None
        self._flush_pending = False
        self._tail: _TickEnd | None = None
        self._in_tick = False
        """Between this producer's SYNC and its tail observer in a tick: what is staged
        then goes out at the tail (module docstring, step 1)."""
        self._stray = False
        """Something was staged outside a tick: look at the tail's place at the next tick."""
        self._next_place = 0
        """The first cycle at which a stray stage has the tail's place looked at again
        (a task staging every cycle: the observers looked at once per
        :data:`_PLACE_EVERY` cycles, not at each)."""
        self.log = log.bind(bus=bus.name)

    @classmethod
    def of(cls, bus: CanBus) -> CanSync:
        """The bus's SYNC producer (one per bus, made on first use)."""
        return bus.shared(CanSync, lambda: cls(bus))

    # -- configuration ----------------------------------------------------------------------
    @property
    def running(self) -> bool:
        """Tied to a timer (:meth:`start`)."""
        return self.timer is not None

    @property
    def producing(self) -> bool:
        """SYNC goes out: tied to a timer that is running."""
        timer = self.timer
        return timer is not None and timer.state is TimerState.RUNNING

    @property
    def period_ns(self) -> int | None:
        """The cycle: the timer's period (None before :meth:`start`)."""
        return None if self.timer is None else self.timer.period_ns

    def add_consumer(self, consumer: SyncConsumer) -> None:
        """A drive answering every SYNC (its feedback is checked at each tick)."""
        if consumer not in self._consumers:
            self._consumers.append(consumer)

    def remove_consumer(self, consumer: SyncConsumer) -> None:
        if consumer in self._consumers:
            self._consumers.remove(consumer)

    async def start(
        self, timer: EventTimer, *, counter_overflow: int = 0, read_on_tick: bool = True
    ) -> None:
        """Produce SYNC on every tick of ``timer`` (it may be running; before or after the
        timer's other observers: the RPDOs staged by the tick are sent first either way).
        Each consumer is told the cycle and the counter first (``set_cycle``: a drive
        writes its 0x60C2 and 0x1019 by SDO), before the first SYNC.

        ``counter_overflow``: 0 (no counter, an empty SYNC) or 2..240 (CiA 301 0x1019: the
        counter runs 1..overflow; give the drives the same 0x1019). ``read_on_tick``: read
        the bus once per tick where it can be (module docstring, step 3); False leaves
        it read as each frame arrives."""
        if not isinstance(timer, EventTimer):
            raise BadParameterError("timer", timer, "an EventTimer")
        if (
            isinstance(counter_overflow, bool)
            or not isinstance(counter_overflow, int)
            or not (counter_overflow == 0 or 2 <= counter_overflow <= 240)
        ):
            raise BadParameterError(
                "counter_overflow", counter_overflow, "0 (no counter) or 2..240 (0x1019)"
            )
        if self.bus.sync_period is not None:
            raise BadParameterError(
                "bus",
                self.bus.name,
                f"a bus without its own SYNC producer (sync_period={self.bus.sync_period})",
            )
        if self.timer is not None:
            raise StateError("start", f"driven by timer {self.timer.name!r}", ["stopped"])
        for consumer in list(self._consumers):
            await consumer.set_cycle(timer.period_ns, counter_overflow)
        if self.timer is not None:
            raise StateError("start", f"driven by timer {self.timer.name!r}", ["stopped"])
        self._loop = asyncio.get_running_loop()
        self._port = self.bus.attach((), name="sync")
        self.read_on_tick = bool(read_on_tick)
        self._hold_s = max(2 * timer.period_ns / _NS_PER_S, 0.002)
        self.counter_overflow = counter_overflow
        self._counter = 0
        self._next_place = 0
        self._build_sync_frames(counter_overflow)
        self.timer = timer
        timer.add_observer(self)
        tail = self._tail = _TickEnd(self)
        timer.add_observer(tail)
        self.log.info(
            "can_sync_started",
            timer=timer.name,
            period_ms=timer.period_ms,
            counter_overflow=counter_overflow,
        )

    def stop(self) -> None:
        """No more SYNC (staged RPDOs are dropped): the drives hold their last target."""
        timer, self.timer = self.timer, None
        tail, self._tail = self._tail, None
        self._in_tick = self._stray = False
        if timer is not None:
            observers = timer.observers
            for observer in (self, tail):
                if observer is not None and observer in observers:
                    timer.remove_observer(observer)
        if self._port is not None:
            self._port.close()
            self._port = None
            if self.read_on_tick:  # the bus read as each frame arrives again, at once
                self.bus.read_now(0.0)
        self._staged.clear()
        if timer is not None:
            self.log.info("can_sync_stopped", **self._stats_dict())

    # -- the cycle --------------------------------------------------------------------------
    def stage(self, cob_id: int, data: bytes) -> None:
        """The RPDO to send before the next SYNC (replaces the one staged for ``cob_id``):
        staged in a tick after this producer's SYNC (by a plain timer observer registered
        after it), sent at the end of that tick; else when the caller yields to the event
        loop, or by the next tick before its SYNC, whichever comes first."""
        if self.timer is None:
            raise StateError("stage", "no SYNC producer", ["CanSync.of(bus).start(timer) first"])
        self._staged[cob_id] = data
        if self._in_tick:
            return  # the tail observer sends it at the end of this tick
        self._stray = True
        if not self._flush_pending and self._loop is not None:
            self._flush_pending = True
            self._loop.call_soon(self._flush)

    def _place_tail(self, timer: EventTimer) -> None:
        """The tail observer last of ``timer``'s (an observer added after :meth:`start`
        stages after it otherwise; one removed by someone else is added again): from the
        next tick on."""
        tail = self._tail
        if tail is None:
            return
        observers = timer.observers
        if observers[-1] is not tail:
            if tail in observers:
                timer.remove_observer(tail)
            timer.add_observer(tail)

    def unstage(self, cob_id: int) -> None:
        """Drop the RPDO staged for ``cob_id`` (its drive left the cyclic mode)."""
        self._staged.pop(cob_id, None)

    def _flush(self) -> None:
        """Send what is staged (in call order, one RPDO per COB-ID)."""
        self._flush_pending = False
        port = self._port
        if not self._staged or port is None:
            return
        staged, self._staged = self._staged, {}
        try:
            sent = port.send_all_nowait(staged.items())
        except NotConnectedError:
            sent = 0
        self._rpdos += sent
        self._dropped += len(staged) - sent

    def notify_timer(self, timer: EventTimer) -> None:
        """TimerObserver: SYNC (after any RPDO still staged), then the bus read (module
        docstring)."""
        port = self._port
        if port is None or timer is not self.timer:
            return
        if self._staged:
            self._flush()
        # no tail in the last tick, or staged outside a tick (looked at now and then)
        misplaced = self._in_tick or (self._stray and self.cycle >= self._next_place)
        self._in_tick = True
        try:
            sent = port.send_frame_nowait(self._sync_frames[self._counter % self._sync_count])
        except NotConnectedError:
            sent = False
        if self.read_on_tick:  # the TPDOs answering the previous SYNC, as its cycle's
            self.bus.read_now(self._hold_s)
            if self._port is None or timer is not self.timer:
                return  # what it read stopped us (a drive faulted)
        if misplaced:
            self._stray = False
            self._next_place = self.cycle + _PLACE_EVERY
            self._place_tail(timer)
        fields = timer.last_tick_fields
        if fields is not None and fields[3]:
            self._count_missed(fields[3], fields[2], "timer skipped ticks")
        if self.cycle:
            for consumer in self._consumers:
                if consumer.feedback_cycle < self.cycle:
                    self._late += 1
        if sent:
            self.cycle += 1
            if self.counter_overflow:  # the counter counts the SYNCs sent (CiA 301)
                self._counter = self._counter % self.counter_overflow + 1
        else:
            self._count_missed(1, timer.clock.now_ns(), "bus did not take the SYNC")

    def _build_sync_frames(self, counter_overflow: int) -> None:
        """The SYNC frames, built once: empty, or one per counter value 1..overflow (the
        next SYNC carries value ``counter % overflow + 1``)."""
        if counter_overflow:
            data = [bytes((value,)) for value in range(1, counter_overflow + 1)]
        else:
            data = [b""]
        self._sync_frames = [TxMessage.frame(co.SYNC_COB_ID, d, False, False) for d in data]
        self._sync_count = len(self._sync_frames)

    def _count_missed(self, cycles: int, now_ns: int, why: str) -> None:
        self._missed += cycles
        last = self._last_warning_ns
        if last is None or now_ns - last >= _NS_PER_S:
            self._last_warning_ns = now_ns
            self.log.warning("can_sync_missed_cycles", cycles=cycles, why=why, total=self._missed)

    # -- statistics -------------------------------------------------------------------------
    @property
    def stats(self) -> SyncStats:
        return SyncStats(self.cycle, self._missed, self._rpdos, self._dropped, self._late)

    def _stats_dict(self) -> dict[str, int]:
        stats = self.stats
        return {
            "cycles": stats.cycles,
            "missed": stats.missed,
            "rpdos": stats.rpdos,
            "dropped_rpdos": stats.dropped_rpdos,
            "late_feedback": stats.late_feedback,
        }

    def __repr__(self) -> str:
        timer = self.timer.name if self.timer is not None else None
        return f"CanSync({self.bus.name!r}, timer={timer!r}, cycle={self.cycle})"


class _TickEnd:
    """The producer's last timer observer: sends what was staged in the tick (module
    docstring, step 1)."""

    __slots__ = ("sync",)

    def __init__(self, sync: CanSync) -> None:
        self.sync = sync

    def notify_timer(self, timer: EventTimer) -> None:
        sync = self.sync
        sync._in_tick = False
        if sync._staged and timer is sync.timer:
            sync._flush()

    def __repr__(self) -> str:
        return f"{self.sync!r}.tick_end"
