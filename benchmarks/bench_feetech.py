"""Feetech STS: one control cycle of an SO-101 -- SYNC READ of 6 servos + SYNC WRITE of 6 goals
-- our FeetechPort against scservo_sdk's GroupSyncRead/GroupSyncWrite.

Both clients talk to the same simulated bus (:class:`openel_serial.feetech_peers.SimFeetechBus`,
six STS3215s, Return Delay 0) behind a pty at 1 Mbaud, served by a child process
(:mod:`benchmarks.feetech_bus`), so the CPU time of the benchmark process is the client's:

* **ours**: ``await FeetechPort.sync_read(ids, 56, 15)`` (the poller's request: Present Position
  .. Present Current) then ``await FeetechPort.sync_write_item(GOAL_POSITION, goals)`` in an
  anyio event loop, through pyserial-asyncio-fast.
* **sdk, in a thread**: what an asyncio application does with the vendor's blocking SDK: each
  cycle ``await anyio.to_thread.run_sync(cycle)``, ``cycle`` being ``GroupSyncRead(port,
  PacketHandler(0), 56, 15).txRxPacket()`` then ``GroupSyncWrite(port, ph, 42, 2)``
  ``clearParam`` / ``addParam`` x 6 / ``txPacket()``, on the SDK's ``PortHandler``.
* **sdk, blocking** (informational): the same ``cycle`` called in the main thread, no event
  loop (a synchronous script).

Rounds of the three alternate (the order rotates every round); each cycle is timed alone
(``perf_counter_ns``) and each round's CPU is ``time.process_time_ns`` over its timed cycles.
"""

from __future__ import annotations

import gc
import statistics
import time
from collections.abc import Callable

import anyio
import anyio.to_thread
import scservo_sdk as sdk  # type: ignore[import-untyped]

from openel_serial import FeetechPort
from openel_serial import feetech as ft
from openel_serial.feetech_port import POLL_ADDRESS, POLL_LENGTH, SYNC_READ_OVERHEAD
from openel_serial.halfduplex import wire_time

from .feetech_bus import FeetechBusProcess
from .harness import BenchResult, Row, ratio_of
from .serial_rounds import Round, make_round, median_of, package_version

NAME = "feetech"
SERVOS = 6
IDS = tuple(range(1, SERVOS + 1))
BAUD = 1_000_000
CYCLES = 1500
QUICK_CYCLES = 300
WARMUP = 100
ROUNDS = 7
QUICK_ROUNDS = 1
TARGET_RATIO = 1.0
TARGET_CPU_RATIO = 0.5
TIMEOUT_MARGIN_S = 0.05
S = ft.STS
GOALS = (ft.CENTER_TICK - 100, ft.CENTER_TICK + 100)
"""Each cycle's goal positions alternate between these (the servos keep moving)."""


def request_bytes() -> int:
    sync_read = SYNC_READ_OVERHEAD + SERVOS
    sync_write = len(
        ft.encode(
            ft.SyncWrite(
                S.GOAL_POSITION.address,
                2,
                tuple(ft.SyncWriteItem(i, b"\x00\x08") for i in IDS),
            )
        )
    )
    return sync_read + sync_write


def reply_bytes() -> int:
    return SERVOS * (ft.STATUS_OVERHEAD + POLL_LENGTH)


def wire_cycle_us() -> float:
    """A cycle's bytes on a real bus at 1 Mbaud (Return Delay 0), µs."""
    return wire_time(request_bytes() + reply_bytes(), BAUD) * 1e6


def _round(samples_ns: list[int], cpu_ns: int, failures: int, who: str) -> Round:
    return make_round(samples_ns, cpu_ns, failures, who, "cycles")


# -- the SDK ---------------------------------------------------------------------------------


class SdkCycle:
    """The vendor SDK's cycle on its own PortHandler: ``__call__`` runs one (blocking) and
    returns whether the SYNC READ got every status."""

    def __init__(self, path: str) -> None:
        self.port = sdk.PortHandler(path)
        if not self.port.openPort():
            raise RuntimeError(f"scservo_sdk cannot open {path}")
        if not self.port.setBaudRate(BAUD):
            raise RuntimeError(f"scservo_sdk cannot set {BAUD} baud on {path}")
        handler = sdk.PacketHandler(0)  # STS/SMS: little-endian
        self.reader = sdk.GroupSyncRead(self.port, handler, POLL_ADDRESS, POLL_LENGTH)
        for servo_id in IDS:
            if not self.reader.addParam(servo_id):
                raise RuntimeError(f"GroupSyncRead refused id {servo_id}")
        self.writer = sdk.GroupSyncWrite(self.port, handler, S.GOAL_POSITION.address, 2)
        self.count = 0
        self.success = sdk.COMM_SUCCESS

    def __call__(self) -> bool:
        ok: bool = self.reader.txRxPacket() == self.success
        goal = GOALS[self.count % 2]
        self.count += 1
        data = [goal & 0xFF, goal >> 8]
        self.writer.clearParam()
        for servo_id in IDS:
            self.writer.addParam(servo_id, data)
        self.writer.txPacket()
        return ok

    def close(self) -> None:
        self.port.closePort()


def sdk_blocking_round(path: str, cycles: int) -> Round:
    cycle = SdkCycle(path)
    try:
        for _ in range(WARMUP):
            cycle()
        samples: list[int] = []
        failures = 0
        clock, cpu = time.perf_counter_ns, time.process_time_ns
        cpu0 = cpu()
        for _ in range(cycles):
            t0 = clock()
            ok = cycle()
            samples.append(clock() - t0)
            failures += not ok
        cpu_ns = cpu() - cpu0
    finally:
        cycle.close()
    return _round(samples, cpu_ns, failures, "scservo_sdk (blocking)")


async def sdk_thread_round(path: str, cycles: int) -> Round:
    cycle = await anyio.to_thread.run_sync(SdkCycle, path)
    run = anyio.to_thread.run_sync
    try:
        for _ in range(WARMUP):
            await run(cycle)
        samples: list[int] = []
        failures = 0
        clock, cpu = time.perf_counter_ns, time.process_time_ns
        cpu0 = cpu()
        for _ in range(cycles):
            t0 = clock()
            ok = await run(cycle)
            samples.append(clock() - t0)
            failures += not ok
        cpu_ns = cpu() - cpu0
    finally:
        await run(cycle.close)
    return _round(samples, cpu_ns, failures, "scservo_sdk (thread)")


# -- ours ----------------------------------------------------------------------------------


async def driver_round(path: str, cycles: int) -> Round:
    async with FeetechPort(
        path, baudrate=BAUD, return_delay=0.0, timeout_margin=TIMEOUT_MARGIN_S
    ) as port:
        goals = [dict.fromkeys(IDS, g) for g in GOALS]
        item = S.GOAL_POSITION

        async def cycle(n: int) -> None:
            data = await port.sync_read(IDS, POLL_ADDRESS, POLL_LENGTH)
            if len(data) != SERVOS:
                raise AssertionError(f"sync read returned {len(data)} of {SERVOS} servos")
            await port.sync_write_item(item, goals[n % 2])

        for n in range(WARMUP):
            await cycle(n)
        samples: list[int] = []
        retries = port.stats.retries
        clock, cpu = time.perf_counter_ns, time.process_time_ns
        cpu0 = cpu()
        for n in range(cycles):
            t0 = clock()
            await cycle(n)
            samples.append(clock() - t0)
        cpu_ns = cpu() - cpu0
        if port.stats.timeouts:
            raise AssertionError(f"unexpected timeouts: {port.stats}")
    return _round(samples, cpu_ns, port.stats.retries - retries, "ours")


# -- the run -------------------------------------------------------------------------------


def run(quick: bool) -> BenchResult:
    cycles = QUICK_CYCLES if quick else CYCLES
    rounds = QUICK_ROUNDS if quick else ROUNDS
    cases: dict[str, Callable[[str], Round]] = {
        "ours": lambda p: anyio.run(driver_round, p, cycles, backend="asyncio"),
        "thread": lambda p: anyio.run(sdk_thread_round, p, cycles, backend="asyncio"),
        "blocking": lambda p: sdk_blocking_round(p, cycles),
    }
    results: dict[str, list[Round]] = {name: [] for name in cases}
    with FeetechBusProcess(SERVOS) as path:
        order = list(cases)
        for i in range(rounds):  # interleaved, the order rotating so load hits each alike
            for name in order[i % 3 :] + order[: i % 3]:
                gc.collect()
                results[name].append(cases[name](path))
    ours, thread, blocking = results["ours"], results["thread"], results["blocking"]
    ratios = [ratio_of(o.median_us, t.median_us) for o, t in zip(ours, thread, strict=True)]
    cpu_ratios = [ratio_of(o.cpu_us, t.cpu_us) for o, t in zip(ours, thread, strict=True)]
    ratio, cpu_ratio = statistics.median(ratios), statistics.median(cpu_ratios)
    rows = [
        Row(
            f"cycle (SYNC READ {SERVOS} + SYNC WRITE {SERVOS}), median wall time",
            median_of(ours, "median_us"),
            "µs",
            baseline=median_of(thread, "median_us"),
            baseline_label="scservo_sdk in a thread",
            ratio=ratio,
            ratio_label="ours/sdk",
            target=f"<= {TARGET_RATIO:.1f}x sdk",
            passed=ratio <= TARGET_RATIO,
        ),
        Row(
            "our CPU per cycle",
            median_of(ours, "cpu_us"),
            "µs",
            baseline=median_of(thread, "cpu_us"),
            baseline_label="scservo_sdk in a thread",
            ratio=cpu_ratio,
            ratio_label="ours/sdk",
            target=f"<= {TARGET_CPU_RATIO:.1f}x sdk",
            passed=cpu_ratio <= TARGET_CPU_RATIO,
        ),
        Row(
            "scservo_sdk blocking in the main thread, median wall time",
            median_of(blocking, "median_us"),
            "µs",
            baseline=median_of(ours, "median_us"),
            baseline_label="ours",
            ratio=ratio_of(median_of(blocking, "median_us"), median_of(ours, "median_us")),
            ratio_label="sdk/ours",
        ),
        Row(
            "scservo_sdk blocking, CPU per cycle",
            median_of(blocking, "cpu_us"),
            "µs",
            baseline=median_of(ours, "cpu_us"),
            baseline_label="ours",
            ratio=ratio_of(median_of(blocking, "cpu_us"), median_of(ours, "cpu_us")),
            ratio_label="sdk/ours",
        ),
    ]
    notes = [
        "Per-round ours/sdk (thread) wall ratios "
        + ", ".join(f"{r:.2f}" for r in ratios)
        + "; CPU ratios "
        + ", ".join(f"{r:.2f}" for r in cpu_ratios)
        + ".",
        f"p99 per cycle: ours {median_of(ours, 'p99_us'):.0f} µs, sdk in a thread "
        f"{median_of(thread, 'p99_us'):.0f} µs, sdk blocking {median_of(blocking, 'p99_us'):.0f} µs; "
        f"failed cycles (a SYNC READ missing a status: retried by ours, COMM_RX_TIMEOUT in the "
        f"SDK): ours {sum(r.failures for r in ours)}, sdk "
        f"{sum(r.failures for r in thread) + sum(r.failures for r in blocking)}.",
        f"On a real bus at 1 Mbaud a cycle's {request_bytes() + reply_bytes()} bytes take "
        f"{wire_cycle_us():.0f} µs on the wire (Return Delay 0), plus the USB adapter's "
        "latency (an FTDI adapter's latency timer: 16 ms by default, set it to 1 ms): the pty measures the "
        "clients, not a bus.",
        f"Median of {rounds} interleaved round(s) of {cycles:,} cycles after {WARMUP} "
        "warm-up cycles; CPU: `time.process_time_ns()` of the benchmark process over a "
        "round's timed cycles (every thread of it), divided by their number; the simulated "
        "bus runs in a child process and is in neither figure.",
    ]
    return BenchResult(
        name=NAME,
        title="Feetech STS: SYNC READ of 6 + SYNC WRITE of 6 per cycle vs scservo_sdk",
        rows=tuple(rows),
        description=DESCRIPTION,
        notes=tuple(notes),
        params={
            "servos": str(SERVOS),
            "requests": f"{request_bytes()} B (SYNC READ + SYNC WRITE)",
            "replies": f"{SERVOS} x {ft.STATUS_OVERHEAD + POLL_LENGTH} B",
            "baud": f"{BAUD:,}",
            "rounds": str(rounds),
            "peer": f"scservo_sdk (feetech-servo-sdk {package_version('feetech-servo-sdk')})",
        },
    )


DESCRIPTION = f"""\
One control cycle of an SO-101 arm: SYNC READ of Present Position .. Present Current
(addresses {POLL_ADDRESS}..70, the poller's request) from the {SERVOS} servos, then SYNC WRITE
of their {SERVOS} Goal Positions (42), against the same simulated bus, in the same run:

- **bus**: `openel_serial.feetech_peers.SimFeetechBus` with STS3215s 1..{SERVOS} (Return Delay
  0) behind a pty, served by a child process (`benchmarks/feetech_bus.py`), so that its CPU
  time is measured for neither client.
- **ours**: `await FeetechPort.sync_read(ids, {POLL_ADDRESS}, {POLL_LENGTH})` then
  `await FeetechPort.sync_write_item(STS.GOAL_POSITION, goals)` in an anyio (asyncio) event
  loop, through pyserial-asyncio-fast; every status checked (checksum, id, length), retries
  and timeouts armed.
- **sdk, in a thread** (the baseline): the vendor's `scservo_sdk` as an asyncio application
  uses a blocking library -- each cycle `await anyio.to_thread.run_sync(cycle)`, where
  `cycle` is `GroupSyncRead(port, PacketHandler(0), {POLL_ADDRESS}, {POLL_LENGTH}).txRxPacket()`
  then `GroupSyncWrite(port, ph, 42, 2)` `clearParam()`, `addParam(id, goal)` x {SERVOS},
  `txPacket()`, on the SDK's own `PortHandler`.
- **sdk, blocking** (informational): the same `cycle` called in the main thread, no event
  loop, as a synchronous script does.

Each cycle is timed alone; rounds of the three alternate (their order rotating every round).
Values and baselines are the medians over the rounds of each round's median; the ratios are
the medians over the rounds of ours/sdk within the same round (same machine load).

**The wall-time row (target <= 1.0x the SDK in a thread): met by less than the machine's
noise.** In the four full runs of 2026-11-29 (13:24 to 14:42 UTC) it was 0.93x, 0.95x,
0.98x and 1.01x, with per-round ratios from 0.65 to 1.36 within a run; earlier full runs
0.80-0.99x. A cycle on the pty is two wake-ups of each process and little work: the SDK's
thread polls the port (its CPU per cycle, 883-1 054 µs, is its wall time), ours sleeps in
`epoll` and spends 0.19-0.22x of the SDK's CPU, and the SDK called without a thread is
0.97-1.03x our wall time. The decision: keep the event-driven read and report the row as
it falls; a client that met the target in every run by spinning would take a core from the
control loop the bus serves, and the CPU row (<= 0.5x the SDK) has held in every run."""
