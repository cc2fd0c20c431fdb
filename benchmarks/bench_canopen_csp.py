"""Four CiA 402 axes in cyclic synchronous position (CSP) at the fastest cycle the bus allows:
our stack (EventTimer + CanSync + ``Cia402Drive(mode="csp", eds=...)``) vs canopen-py doing
the same cycle with its own PDO and SYNC API in a thread, against the same simulated drives
in a child process.

The cycle is the wire limit at 1 Mbit/s (``openel_can.busload``): four RPDOs (controlword +
target position, 6 bytes), four synchronous TPDO1s (statusword + position + torque, 8 bytes)
and the SYNC, worst-case bit stuffing, rounded up to 0.1 ms.

* **The drives**: four ``SimCia402Drive`` peers in a child process
  (``benchmarks.csp_peers``), reached through an ``AF_UNIX``/``SOCK_SEQPACKET`` socket pair
  carrying one CAN frame per datagram (python-can bus ``benchmarks.can_peers.SocketPairBus``:
  a non-blocking ``send`` per frame, ``recv`` per frame, as ``socketcan`` does). The child
  is pinned to the machine's last CPU and the master to the others (on a real bus the drives
  are other devices; without it the kernel schedules the drives, woken by each frame the
  master sends, on the master's CPU in the middle of its cycle). Their CPU time and their
  GIL are not the master's. The master process runs at real-time priority (``SCHED_FIFO``
  10, its threads too: canopen-py's notifier) when permitted, as a CANopen master on Linux
  runs: on a machine shared with other work its wake-ups would otherwise wait behind that
  work for whole scheduler ticks (4 ms), whichever stack it is.
* **Ours**: four ``Actuator(Cia402Drive(bus, n, mode="csp", eds=SHIPPED_EDS))`` (configured
  from the EDS by SDO, ``default_pdos("csp")``) on a ``CanBus`` reading the socket in the
  event loop (``read_mode="loop"``, what ``socketcan`` gets by default), an ``EventTimer``
  at the cycle, ``CanSync.of(bus).start(timer)`` (SYNC first at each tick, then the socket
  read once: ``CanBus.read_now``), and a timer observer staging a new target for every
  drive each tick (``command_nowait``, what an ``AxisGroup`` does without its planning):
  the four RPDOs go out at the end of that tick (``CanSync``'s last observer, in one burst:
  ``NodePort.send_all_nowait``), the next tick's SYNC latches them.
* **canopen-py**: ``canopen.Network(bus)`` on the same kind of socket pair, four
  ``RemoteNode`` objects from the same EDS, mapped with its ``pdo`` tooling exactly as ours maps
  them, CSP selected and enabled by RPDO; a thread runs the cycle on ``time.perf_counter``
  deadlines (a deadline it missed by a whole period is skipped, as our timer does): each
  axis's ``rpdo["Target position"].raw = x`` and ``rpdo.transmit()``, then
  ``network.sync.transmit()``, and each axis's position read from its TPDO1
  (``tpdo["Position actual value"].raw``, decoded by canopen's notifier thread).

Figures: the SYNC period jitter, |interval - cycle| between consecutive SYNC frames on the
wire -- each SYNC stamped by the kernel when the master's ``send`` queued it on the socket
(``SO_TIMESTAMPNS`` on the drives' end, as a socketcan adapter stamps frames), whatever the
drives' process was doing -- p50 and p99; a missed cycle (a tick skipped because the master
woke a whole period late) is an interval of two periods, a deviation of one period. The host
CPU per cycle: the master process's own CPU time (``time.process_time``: every thread of it,
nothing of the drives) over the measured cycles, divided by them. The cycles missed. Median
of the interleaved rounds (ours, canopen-py, ours, ...).
"""

from __future__ import annotations

import itertools
import math
import statistics
import time
from collections.abc import Iterator, Sequence
from contextlib import AsyncExitStack
from typing import NamedTuple

import anyio
import anyio.from_thread
import can
import canopen

from openel_async import Actuator, EventTimer, Request
from openel_can import CanBus, CanSync, Cia402CyclicDrive, Cia402Drive
from openel_can import cia402 as ds
from openel_can.busload import frame_time
from openel_can.cyclic402 import interpolation_period
from openel_can.od import SHIPPED_EDS

from .csp_peers import CspPeersProcess, realtime_permitted
from .harness import BenchResult, Row, interleaved, ratio_of

NAME = "canopen_csp"
NODES = (1, 2, 3, 4)
BITRATE = 1_000_000
CYCLES = 2_000
QUICK_CYCLES = 300
ROUNDS = 5
QUICK_ROUNDS = 1
WARMUP_CYCLES = 50
TARGET_JITTER = 0.5
"""Ours p99 SYNC jitter at most half of canopen-py's."""
TARGET_CPU = 1.0
CSP = int(ds.ModeOfOperation.CYCLIC_SYNC_POSITION)


class Run(NamedTuple):
    jitter_p50: float
    jitter_p99: float
    cpu: float
    """Host CPU seconds per cycle."""
    missed: int
    cycles: int


def wire_cycle_ms() -> float:
    """The fastest cycle four CSP axes fit at :data:`BITRATE` (0.1 ms steps)."""
    per_axis = frame_time(6, BITRATE) + frame_time(8, BITRATE)
    seconds = len(NODES) * per_axis + frame_time(0, BITRATE)
    return math.ceil(seconds * 1e4 - 1e-9) / 10


def _target(cycle: int) -> float:
    return 0.5 * math.sin(cycle * 0.005)


def jitter(stamps_ns: Sequence[int], period_s: float) -> tuple[float, float]:
    """p50 and p99 of |interval - period| between consecutive SYNC stamps (seconds)."""
    period_ns = period_s * 1e9
    deviations = sorted(abs(b - a - period_ns) / 1e9 for a, b in itertools.pairwise(stamps_ns))
    if not deviations:
        raise AssertionError("no SYNC recorded")
    p99 = deviations[min(len(deviations) - 1, math.ceil(0.99 * len(deviations)) - 1)]
    return statistics.median(deviations), p99


def _measured(stamps_ns: Sequence[int], cycles: int) -> list[int]:
    """The SYNCs of the measured cycles (after the warm-up)."""
    return list(stamps_ns[WARMUP_CYCLES : WARMUP_CYCLES + cycles + 1])


class _Streamer:
    """A timer observer staging a new target for every drive each tick."""

    def __init__(self, drives: Sequence[Cia402CyclicDrive], cycles: int) -> None:
        self.drives = drives
        self.cycles = cycles
        self.tick = 0
        self.done = anyio.Event()

    def notify_timer(self, timer: EventTimer) -> None:
        self.tick += 1
        x = _target(self.tick)
        for drive in self.drives:
            drive.command_nowait(Request.POSITION, x)
        if self.tick >= self.cycles:
            self.done.set()


def ours(cycles: int, period_ms: float) -> Run:
    async def main(peers: CspPeersProcess) -> tuple[float, int]:
        async with (
            CanBus(peers.bus(), name="bench-csp", send_mode="inline", read_mode="loop") as bus,
            AsyncExitStack() as stack,
        ):
            axes = [
                await stack.enter_async_context(
                    Actuator(Cia402Drive(bus, n, mode="csp", eds=SHIPPED_EDS))
                )
                for n in NODES
            ]
            drives = [a.device for a in axes]
            assert all(isinstance(d, Cia402CyclicDrive) for d in drives)
            timer = await stack.enter_async_context(EventTimer(period_ms, name="bench"))
            sync = CanSync.of(bus)
            await sync.start(timer)
            stack.callback(sync.stop)
            streamer = _Streamer(drives, cycles + WARMUP_CYCLES)  # type: ignore[arg-type]
            timer.add_observer(streamer)
            timer.start_timer()
            with anyio.fail_after(60):
                while streamer.tick < WARMUP_CYCLES:  # noqa: ASYNC110
                    await anyio.sleep(0.01)
            cpu0, missed0 = time.process_time(), sync.stats.missed
            with anyio.fail_after(60):
                await streamer.done.wait()
            cpu = time.process_time() - cpu0
            missed = sync.stats.missed - missed0
            timer.stop_timer()
            for axis in axes:
                if axis.state.value != "Active":
                    raise AssertionError(f"ours: {axis.device_name} left Active")
        return cpu, missed

    with CspPeersProcess(NODES) as peers:
        cpu, missed = anyio.run(main, peers, backend="asyncio")
    p50, p99 = jitter(_measured(peers.sync_stamps_ns, cycles), period_ms / 1000)
    return Run(p50, p99, cpu / cycles, missed, cycles)


def _configure(network: canopen.Network, node: canopen.RemoteNode, period_ms: float) -> None:
    """In PRE-OPERATIONAL with canopen's SDO and pdo tooling, as ours maps them."""
    node.nmt.state = "PRE-OPERATIONAL"
    node.tpdo.read()
    node.rpdo.read()
    rpdo, tpdo1, tpdo2 = node.rpdo[1], node.tpdo[1], node.tpdo[2]
    rpdo.clear()
    rpdo.add_variable("Controlword")
    rpdo.add_variable("Target position")
    rpdo.trans_type = 1
    rpdo.enabled = True
    tpdo1.clear()
    for name in ("Statusword", "Position actual value", "Torque actual value"):
        tpdo1.add_variable(name)
    tpdo1.trans_type = 1
    tpdo1.enabled = True
    tpdo2.clear()
    tpdo2.add_variable("Statusword")
    tpdo2.add_variable("Modes of operation display")
    tpdo2.trans_type = 0xFF
    tpdo2.event_timer = 0
    tpdo2.enabled = True
    for n in (2, 3, 4):
        node.rpdo[n].enabled = False
    for n in (3, 4):
        node.tpdo[n].enabled = False
    node.rpdo.save()
    node.tpdo.save()
    value, index = interpolation_period(round(period_ms * 1e6))
    node.sdo["Interpolation time period"]["Interpolation time period value"].raw = value
    node.sdo["Interpolation time period"]["Interpolation time index"].raw = index
    actual = node.sdo["Position actual value"].raw
    node.sdo["Target position"].raw = actual
    node.sdo["Modes of operation"].raw = CSP
    if node.sdo["Modes of operation display"].raw != CSP:
        raise AssertionError("canopen: CSP not selected")


def _enable(node: canopen.RemoteNode) -> None:
    rpdo, tpdo2 = node.rpdo[1], node.tpdo[2]
    for word, mask, value in ((0x06, 0x6F, 0x21), (0x07, 0x6F, 0x23), (0x0F, 0x6F, 0x27)):
        with tpdo2.receive_condition:
            rpdo["Controlword"].raw = word
            rpdo.transmit()
            if not tpdo2.receive_condition.wait_for(
                lambda m=mask, v=value: tpdo2["Statusword"].raw & m == v, 1.0
            ):
                raise AssertionError(f"canopen: no statusword after controlword {word:#x}")


class _Pacer:
    """The peers' cycle: ``time.perf_counter`` deadlines ``period_s`` apart, sleeping to each
    (``spin``: busy-waiting); a deadline missed by a whole period is skipped, as our timer
    does, and the skipped periods after the warm-up counted in :attr:`missed`."""

    def __init__(self, period_s: float, *, spin: bool = False) -> None:
        self.period_s = period_s
        self.spin = spin
        self.missed = 0

    def ticks(self, total: int) -> Iterator[int]:
        """1..``total``, each at its deadline."""
        period = self.period_s
        clock = time.perf_counter
        deadline = clock()
        for tick in range(1, total + 1):
            deadline += period
            now = clock()
            if now - deadline >= period:  # skip the whole periods missed
                skipped = int((now - deadline) // period)
                deadline += skipped * period
                if tick > WARMUP_CYCLES:
                    self.missed += skipped
            if self.spin:
                while clock() < deadline:
                    pass
            else:
                delay = deadline - clock()
                if delay > 0:
                    time.sleep(delay)
            yield tick


def peer(cycles: int, period_ms: float) -> Run:
    with CspPeersProcess(NODES) as peers:
        network = canopen.Network(peers.bus())
        network.connect()
        try:
            nodes = []
            for n in NODES:
                node = canopen.RemoteNode(n, str(SHIPPED_EDS))
                network.add_node(node)
                node.sdo.RESPONSE_TIMEOUT = 1.0
                nodes.append(node)
            for node in nodes:
                _configure(network, node, period_ms)
            for node in nodes:
                node.nmt.state = "OPERATIONAL"
            time.sleep(0.05)
            for node in nodes:
                _enable(node)
            rpdos = [node.rpdo[1] for node in nodes]
            targets = [rpdo["Target position"] for rpdo in rpdos]
            positions = [node.tpdo[1]["Position actual value"] for node in nodes]
            for rpdo in rpdos:
                rpdo["Controlword"].raw = 0x0F
            counts_per_rad = 10_000 / math.tau
            period = period_ms / 1000
            total = cycles + WARMUP_CYCLES
            pacer = _Pacer(period)
            cpu0 = 0.0
            for tick in pacer.ticks(total):
                counts = round(_target(tick) * counts_per_rad)
                for target, rpdo in zip(targets, rpdos, strict=True):
                    target.raw = counts
                    rpdo.transmit()
                network.sync.transmit()
                for position in positions:
                    _ = position.raw
                if tick == WARMUP_CYCLES:
                    cpu0 = time.process_time()
            cpu = time.process_time() - cpu0
            time.sleep(0.05)
        finally:
            network.disconnect()
    p50, p99 = jitter(_measured(peers.sync_stamps_ns, cycles), period_ms / 1000)
    return Run(p50, p99, cpu / cycles, pacer.missed, cycles)


def floor(cycles: int, period_ms: float, *, spin: bool) -> Run:
    """The least a SYNC sender in user space can do on this machine: a bare loop that only
    sends SYNC on ``time.perf_counter`` deadlines (and takes whatever the drives send, so
    nothing backs up), at the same priority and on the same CPU as the masters. ``spin``:
    busy-waits to each deadline instead of sleeping (no wake-up latency; the whole CPU)."""
    with CspPeersProcess(NODES) as peers:
        bus = peers.bus()
        sync = can.Message(arbitration_id=0x080, data=b"", is_extended_id=False)
        period = period_ms / 1000
        total = cycles + WARMUP_CYCLES
        pacer = _Pacer(period, spin=spin)
        cpu0 = 0.0
        for tick in pacer.ticks(total):
            bus.send(sync)
            while bus.recv(0.0) is not None:
                pass
            if tick == WARMUP_CYCLES:
                cpu0 = time.process_time()
        cpu = time.process_time() - cpu0
        bus.shutdown()
    p50, p99 = jitter(_measured(peers.sync_stamps_ns, cycles), period_ms / 1000)
    return Run(p50, p99, cpu / cycles, pacer.missed, cycles)


def run(quick: bool) -> BenchResult:
    cycles = QUICK_CYCLES if quick else CYCLES
    rounds = QUICK_ROUNDS if quick else ROUNDS
    period_ms = wire_cycle_ms()
    measured = interleaved(
        rounds,
        {
            "ours": lambda: ours(cycles, period_ms),
            "peer": lambda: peer(cycles, period_ms),
            "sleep": lambda: floor(cycles, period_ms, spin=False),
            "spin": lambda: floor(cycles, period_ms, spin=True),
        },
    )
    mine, theirs = measured["ours"], measured["peer"]
    bare, busy = measured["sleep"], measured["spin"]

    def median(runs: list[Run], field: str) -> float:
        return float(statistics.median(getattr(r, field) for r in runs))

    def row(metric: str, field: str, target: float | None, scale: float = 1e6) -> Row:
        a, b = median(mine, field), median(theirs, field)
        ratio = ratio_of(a, b)
        return Row(
            metric,
            a * scale,
            "µs",
            baseline=b * scale,
            baseline_label="canopen-py",
            ratio=ratio,
            ratio_label="ours/canopen-py",
            target="" if target is None else f"<= {target:g}x canopen-py",
            passed=None if target is None else ratio <= target,
            digits=0,
        )

    missed = Row(
        "missed cycles (median of the rounds)",
        median(mine, "missed"),
        "cycles",
        baseline=median(theirs, "missed"),
        baseline_label="canopen-py",
        digits=0,
    )

    def floor_row(metric: str, runs: list[Run], field: str) -> Row:
        a, b = median(runs, field), median(theirs, field)
        return Row(
            metric,
            a * 1e6,
            "µs",
            baseline=b * 1e6,
            baseline_label="canopen-py",
            ratio=ratio_of(a, b),
            ratio_label="floor/canopen-py",
            digits=0,
        )

    rows = (
        row("SYNC period jitter p50", "jitter_p50", None),
        row("SYNC period jitter p99", "jitter_p99", TARGET_JITTER),
        row("host CPU per cycle (4 RPDO + SYNC + 4 TPDO)", "cpu", TARGET_CPU),
        missed,
        floor_row("floor: SYNC jitter p99 of a bare sleeping SYNC loop", bare, "jitter_p99"),
        floor_row("floor: SYNC jitter p99 of a busy-waiting SYNC loop", busy, "jitter_p99"),
        floor_row("floor: CPU per cycle of the busy-waiting SYNC loop", busy, "cpu"),
    )

    def each(runs: list[Run]) -> str:
        return "; ".join(
            f"p99 {r.jitter_p99 * 1e6:.0f} µs, CPU {r.cpu * 1e6:.0f} µs, missed {r.missed}"
            for r in runs
        )

    notes = (
        f"Cycle {period_ms:g} ms: the wire limit of four CSP axes at 1 Mbit/s (worst case); "
        f"{rounds} interleaved round(s) of {cycles:,} cycles after {WARMUP_CYCLES} warm-up "
        f"cycles. Ours: {each(mine)}. canopen-py: {each(theirs)}. Bare sleeping SYNC loop: "
        f"{each(bare)}. Busy-waiting SYNC loop: {each(busy)}.",
        "Floors (same rounds, same drives, priority and CPU): a loop that only sends SYNC on "
        "its deadlines, sleeping to each (the least wake-up jitter of a user-space sender on "
        "this machine), and the same loop busy-waiting to each deadline instead (no "
        "wake-up, the whole CPU). A SYNC p99 under the sleeping loop's needs the master to "
        "stay awake before each deadline, at the busy loop's CPU cost.",
        "Host CPU: the master process's CPU time per cycle (ours: the event loop, which also "
        "reads the socket; canopen-py: its cycle thread and its notifier thread). The drives "
        "run in a child process pinned to the last CPU, the master on the other(s)"
        + (
            ", at SCHED_FIFO priority."
            if realtime_permitted()
            else " (real-time priority not permitted here: normal priority)."
        ),
    )
    return BenchResult(
        name=NAME,
        title="Four CiA 402 axes in CSP at the wire limit: openel_can vs canopen-py",
        rows=rows,
        description=__doc__ or "",
        notes=notes,
        params={
            "axes": str(len(NODES)),
            "cycle": f"{period_ms:g} ms",
            "cycles": f"{cycles:,}",
            "interface": "socket pair to a child process (one frame a datagram)",
            "canopen": canopen.__version__,
            "python-can": can.__version__,
        },
    )
