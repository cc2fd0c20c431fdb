"""The CAN frames of one ODrive node, shared by the axis and the sensors of
:mod:`openel_can.odrive`: the latest message per CANSimple command (with RTR polling and
bounded waits for a fresh one), what is refused while the axis is e-stopped, unit helpers
and the parameter checks."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from typing import Final, TypeVar

import anyio

from openel_async.clock import Clock
from openel_async.device import DeviceContext
from openel_async.errors import BadParameterError, HALError
from openel_async.logs import get_logger

from . import cansimple as cs
from .bus import CanBus, NodePort
from .errors import DecodeError

__all__ = [
    "KELVIN_OFFSET",
    "ODRIVE_VENDOR_ID",
    "ODriveLink",
    "WatchdogFeeder",
    "check_node",
    "check_seconds",
    "drives_motor",
    "rad_to_turns",
    "turns_to_rad",
]

log = get_logger(__name__)

TAU: Final = math.tau
KELVIN_OFFSET: Final = 273.15
ODRIVE_VENDOR_ID: Final = 0x0D21
M = TypeVar("M", bound=cs.CanSimpleMessage)


def turns_to_rad(turns: float) -> float:
    return turns * TAU


def rad_to_turns(rad: float) -> float:
    return rad / TAU


def check_node(node_id: int) -> None:
    if (
        isinstance(node_id, bool)
        or not isinstance(node_id, int)
        or not 0 <= node_id < cs.MAX_NODE_ID
    ):
        raise BadParameterError("node_id", node_id, f"an ODrive node id in 0..{cs.MAX_NODE_ID - 1}")


def check_seconds(name: str, value: float) -> None:
    if not (math.isfinite(value) and value > 0):
        raise BadParameterError(name, value, "a finite number of seconds > 0")


def drives_motor(msg: cs.CanSimpleMessage) -> bool:
    """A frame that engages the axis or gives it a set-point (refused while e-stopped)."""
    if isinstance(msg, cs.SetAxisState):
        return msg.state is not cs.AxisState.IDLE
    return isinstance(msg, cs.SetInputPos | cs.SetInputVel | cs.SetInputTorque)


class ODriveLink:
    """The frames of one ODrive node: latest message per command, with RTR polling."""

    def __init__(
        self,
        bus: CanBus,
        node_id: int,
        cmds: Iterable[cs.CmdId],
        *,
        request_timeout: float,
    ) -> None:
        self.bus = bus
        self.node_id = node_id
        self.cmds = frozenset(cmds)
        self.request_timeout = request_timeout
        self.latest: dict[cs.CmdId, tuple[int, cs.CanSimpleMessage]] = {}
        self.port: NodePort | None = None
        self.ctx: DeviceContext | None = None
        self.on_message: Callable[[cs.CanSimpleMessage, int], None] | None = None
        self.sent_ns: int | None = None
        """When a frame to this node was last sent (every frame feeds the axis watchdog)."""
        self.estopped = False
        """Set by the axis's e-stop, cleared by its ``re_init``: while set, :meth:`send`
        refuses every frame that would drive the motor (see :func:`drives_motor`)."""
        self._changed = anyio.Event()

    def open(self, ctx: DeviceContext, on_bus_error: Callable[[str], None]) -> None:
        self.ctx = ctx
        ids = [cs.arbitration_id(self.node_id, cmd) for cmd in self.cmds]
        self.port = self.bus.attach(ids, name=ctx.name, on_bus_error=on_bus_error)
        ctx.start_soon(self._run, self.port)

    def close(self) -> None:
        if self.port is not None:
            self.port.close()

    @property
    def malformed(self) -> int:
        return self.port.malformed if self.port is not None else 0

    def now(self) -> int:
        assert self.ctx is not None, "used before open()"
        return self.ctx.clock.now_ns()

    async def _run(self, port: NodePort) -> None:
        decode = cs.decode
        latest = self.latest
        async for batch in port:
            now = self.now()
            for frame in batch:
                if frame.is_remote_frame:
                    continue  # another host polling this node
                try:
                    msg = decode(frame.arbitration_id, frame.data, from_host=False)
                except DecodeError:
                    port.malformed += 1
                    continue
                latest[msg.cmd] = (now, msg)
                if self.on_message is not None:
                    self.on_message(msg, now)
            changed, self._changed = self._changed, anyio.Event()
            changed.set()

    async def send(self, msg: cs.CanSimpleMessage) -> None:
        assert self.port is not None, "used before open()"
        if self.estopped and drives_motor(msg):
            # A command already on its way when the e-stop came: its later steps must not
            # re-engage the axis (only re_init does).
            raise HALError(
                f"ODrive node {self.node_id}: e-stopped: {type(msg).__name__} refused until re_init"
            )
        arb_id, data = cs.encode(msg)
        await self.port.send(arb_id, data, remote=isinstance(msg, cs.Request))
        self.sent_ns = self.now()

    async def request(self, cmd: cs.CmdId, kind: type[M]) -> tuple[int, M]:
        """Poll ``cmd`` with a remote frame; the first reply received after the request."""
        asked = self.now()
        await self.send(cs.Request(self.node_id, cmd))
        return await self.wait_for(cmd, kind, after_ns=asked, timeout=self.request_timeout)

    async def fresh(self, cmd: cs.CmdId, kind: type[M], max_age_ns: int) -> tuple[int, M]:
        """The cached message when younger than ``max_age_ns``, else a polled one."""
        cached = self.latest.get(cmd)
        if cached is not None and self.now() - cached[0] <= max_age_ns:
            stamp, msg = cached
            assert isinstance(msg, kind)
            return stamp, msg
        return await self.request(cmd, kind)

    async def wait_for(
        self,
        cmd: cs.CmdId,
        kind: type[M],
        *,
        after_ns: int,
        timeout: float,  # noqa: ASYNC109 - a bound, by contract
        predicate: Callable[[M], bool] | None = None,
    ) -> tuple[int, M]:
        """Wait (bounded) for a ``cmd`` message received after ``after_ns`` matching ``predicate``."""
        with anyio.move_on_after(timeout):
            while True:
                cached = self.latest.get(cmd)
                if cached is not None and cached[0] >= after_ns:
                    stamp, msg = cached
                    assert isinstance(msg, kind)
                    if predicate is None or predicate(msg):
                        return stamp, msg
                await self._changed.wait()
        raise TimeoutError(
            f"ODrive node {self.node_id}: no {cmd.name} reply within {timeout * 1000:.0f} ms"
        )


class WatchdogFeeder:
    """Feeds the axis watchdogs of every armed ODrive on one bus with one clock and one
    timeout: one task of the bus for all of them (not one per axis), so the axes are checked
    in one wake-up per period.

    Any frame sent to a node feeds its watchdog: at each pass, a node nothing was sent to for
    the last ``period`` (less half a period: fed up to that much early, so the feeder's
    nodes fall in step and share the wake-up) gets a heartbeat poll (remote frame); then
    the task sleeps until the earliest ``last frame + period``. While set-points stream,
    a pass sends nothing. A node is dropped once its ``armed()`` is no longer this feeder's
    timeout (disarmed, or armed with another) or its link is closed; the task ends with
    the last one, and with the bus. A task in the event loop: a stalled loop starves it.
    """

    def __init__(self, bus: CanBus, clock: Clock, timeout: float, fraction: int) -> None:
        self.bus = bus
        self.clock = clock
        self.timeout = timeout
        self.period_ns = max(1, round(timeout * 1e9 / fraction))
        self.polls = 0
        """Heartbeat polls sent (a node nothing else was sent to for a period)."""
        self._links: dict[ODriveLink, Callable[[], float | None]] = {}
        self._running = False

    @classmethod
    def for_bus(cls, bus: CanBus, clock: Clock, timeout: float, fraction: int) -> WatchdogFeeder:
        """The bus's feeder for ``clock`` and ``timeout`` (fed every ``timeout / fraction``)."""
        key = ("odrive-watchdog-feeder", clock, timeout, fraction)
        return bus.shared(key, lambda: cls(bus, clock, timeout, fraction))

    @property
    def running(self) -> bool:
        """Whether the feeding task runs (it ends with the last node fed)."""
        return self._running

    def add(self, link: ODriveLink, armed: Callable[[], float | None]) -> None:
        """Feed ``link``'s node while ``armed()`` equals :attr:`timeout` and the link is open."""
        self._links[link] = armed
        if not self._running:
            self.bus.start_soon(self._run, name=f"odrive-watchdog-{self.bus.name}")
            self._running = True

    async def _run(self) -> None:
        clock = self.clock
        period = self.period_ns
        due_after = period - period // 2
        links = self._links
        try:
            while links:
                now = clock.now_ns()
                next_due: int | None = None
                for link, armed in list(links.items()):
                    port = link.port
                    if armed() != self.timeout or port is None or not port.attached:
                        del links[link]
                        continue
                    sent = link.sent_ns
                    if sent is None or now - sent >= due_after:
                        try:
                            await link.send(cs.Request(link.node_id, cs.CmdId.HEARTBEAT))
                            self.polls += 1
                        except (TimeoutError, HALError) as exc:  # the bus is down, or full
                            log.debug(
                                "odrive_watchdog_feed_failed", node=link.node_id, error=repr(exc)
                            )
                        sent = now
                    due = sent + period
                    if next_due is None or due < next_due:
                        next_due = due
                if next_due is not None:
                    await clock.sleep_until(next_due)
        finally:
            self._running = False
