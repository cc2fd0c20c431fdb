"""Velocity ramps streamed by the framework: ``Motor.set_speed(speed, tm_acc)`` on a device
without a ramp generator of its own.

A :class:`Ramp` goes linearly from ``start`` to ``target`` between ``t0`` and ``t1`` on the
component's clock. Every motor ramping on one clock is served by one
:class:`RampStreamer`: one task, waking every :data:`RAMP_PERIOD_NS` on an absolute grid,
sends each ramp's setpoint in turn, so 64 ramping motors cost one wake per period, not 64.
The task runs in the task group of one of the ramping motors (its host); when the host's
``async with`` ends, the task moves to another ramping motor.

A ramp ends when its final setpoint is sent (at ``t1``), or as soon as its Motion is no
longer pending (superseded by the next command, faulted, cancelled by ``re_init`` or
``finalize``): it is then dropped without sending anything.
"""

from __future__ import annotations

import time
import weakref
from collections.abc import Awaitable, Callable, Coroutine
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from openel_async.logs import get_logger

from .clock import Clock
from .completion import Motion, Outcome
from .lazy import first_use

if TYPE_CHECKING:
    import asyncio

log = get_logger(__name__)

RAMP_PERIOD_NS = 1_000_000
"""The streaming period of framework ramps: 1 ms (1 kHz)."""

_PENDING = Outcome.PENDING


_running_loop: Callable[[], asyncio.AbstractEventLoop] = first_use(
    globals(), "_running_loop", "asyncio", "get_running_loop"
)
"""``asyncio.get_running_loop``, bound at the first ramp (asyncio is imported then, not
with the module: an app printing its --help does not load it)."""

StartSoon = Callable[[Callable[[], Coroutine[Any, Any, None]]], object]


@dataclass(eq=False, slots=True)
class Ramp:
    """One motor's ramp; ``send_nowait`` (devices without I/O) or ``send`` delivers a setpoint.

    The send callables handle the device's failures themselves (the motor faults); they
    must not raise.
    """

    motion: Motion
    start: float
    target: float
    t0_ns: int
    t1_ns: int
    send: Callable[[float], Awaitable[None]]
    send_nowait: Callable[[float], None] | None
    start_soon: StartSoon
    """Runs a task in the owning motor's task group (raises once it has ended)."""
    final_sent: bool = False
    setpoints: int = field(default=0)

    def setpoint(self, now_ns: int) -> float:
        """The ramp's velocity at ``now_ns`` (``target`` from ``t1_ns`` on)."""
        if now_ns >= self.t1_ns:
            return self.target
        if now_ns <= self.t0_ns:
            return self.start
        fraction = (now_ns - self.t0_ns) / (self.t1_ns - self.t0_ns)
        return self.start + (self.target - self.start) * fraction

    @property
    def active(self) -> bool:
        """Still streaming: its Motion is pending and its final setpoint not yet sent."""
        return not self.final_sent and self.motion.outcome is _PENDING


class RampStreamer:
    """Streams the ramps of every motor on one clock; see the module docstring."""

    def __init__(self, clock: Clock, period_ns: int = RAMP_PERIOD_NS) -> None:
        self.clock = clock
        self.period_ns = period_ns
        self._ramps: dict[int, Ramp] = {}
        self._running: asyncio.AbstractEventLoop | None = None
        self.ticks = 0
        """Periods in which the streamer sent setpoints."""
        self.busy_ns = 0
        """Wall time spent sending setpoints (``time.perf_counter_ns``), over all ticks."""

    def __len__(self) -> int:
        return len(self._ramps)

    def add(self, owner: object, ramp: Ramp) -> None:
        """Stream ``ramp`` for ``owner`` (replacing the owner's previous ramp)."""
        self._ramps[id(owner)] = ramp
        loop = _running_loop()
        if self._running is not loop:  # not running, or left behind by a closed loop
            self._host(ramp)

    def remove(self, owner: object) -> None:
        self._ramps.pop(id(owner), None)

    def _host(self, ramp: Ramp) -> None:
        ramp.start_soon(self._run)
        self._running = _running_loop()

    async def _run(self) -> None:
        clock = self.clock
        period = self.period_ns
        ramps = self._ramps
        deadline = clock.now_ns()
        try:
            while ramps:
                deadline += period
                now = clock.now_ns()
                if deadline <= now:  # late: the next grid point, no catching up
                    deadline += (now - deadline) // period * period + period
                await clock.sleep_until(deadline)
                started = time.perf_counter_ns()
                now = clock.now_ns()
                for key, ramp in list(ramps.items()):
                    if ramp.motion.outcome is not _PENDING:
                        del ramps[key]
                        continue
                    value = ramp.setpoint(now)
                    if now >= ramp.t1_ns:
                        ramp.final_sent = True
                        del ramps[key]
                    ramp.setpoints += 1
                    try:
                        if ramp.send_nowait is not None:
                            ramp.send_nowait(value)
                        else:
                            await ramp.send(value)
                    except Exception as exc:  # the send handles device failures: a bug
                        log.error("ramp_send_failed", error=repr(exc))
                        ramps.pop(key, None)
                self.ticks += 1
                self.busy_ns += time.perf_counter_ns() - started
        finally:
            self._running = None
            self._rehost()

    def _rehost(self) -> None:
        """The host's task ended (its component exited): continue in another owner's group."""
        for key, ramp in list(self._ramps.items()):
            if not ramp.active:
                del self._ramps[key]
                continue
            try:
                self._host(ramp)
            except Exception:  # that owner's task group has ended too
                continue
            return
        self._ramps.clear()


_streamers: weakref.WeakKeyDictionary[Clock, RampStreamer] = weakref.WeakKeyDictionary()


def streamer_for(clock: Clock) -> RampStreamer:
    """The streamer shared by every motor on ``clock`` (one per clock)."""
    try:
        streamer = _streamers.get(clock)
    except TypeError:  # a clock that cannot be weakly referenced: a streamer of its own
        return RampStreamer(clock)
    if streamer is None:
        streamer = _streamers[clock] = RampStreamer(clock)
    return streamer
