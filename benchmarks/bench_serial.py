"""Dynamixel SYNC READ of 1, 8 and 32 servos: our driver against dynamixel-sdk's GroupSyncRead.

Both clients talk to the same simulated bus (:class:`openel_serial.peers.SimDynamixelBus`,
Return Delay Time 0) behind a pty, served by a child process
(:mod:`benchmarks.serial_bus`), so the CPU time of the benchmark process is the client's:

* **ours**: ``await DynamixelPort.sync_read(ids, 122, 14)`` (the poller's request:
  Moving .. Present Position) in an anyio event loop, through pyserial-asyncio-fast.
* **peer**: dynamixel-sdk's ``GroupSyncRead(port, PacketHandler(2.0), 122, 14)`` with the
  same ids, ``txRxPacket()`` called in this process's main thread (blocking, as the SDK
  is used), on the SDK's own ``PortHandler`` (pyserial, read timeout 0: it polls).

Rounds of the two alternate on one bus process per N; each transaction is timed alone
(``perf_counter_ns``) and each round's CPU is ``time.process_time_ns`` over its timed
transactions. The figures are the medians over the rounds.
"""

from __future__ import annotations

import asyncio
import cProfile
import gc
import os
import pstats
import statistics
import time
from contextlib import AsyncExitStack
from dataclasses import dataclass

import anyio
import dynamixel_sdk as sdk  # type: ignore[import-untyped]
import serial

from openel_async import Actuator
from openel_serial import DynamixelPort, DynamixelServo
from openel_serial import dynamixel as dx
from openel_serial.port import POLL_ADDRESS, POLL_LENGTH, STATUS_OVERHEAD, wire_time

from .harness import BenchResult, Row, ratio_of
from .serial_bus import BusProcess
from .serial_rounds import Round, make_round, median_of, package_version

NAME = "serial"
SIZES = (1, 8, 32)
BAUD = 1_000_000
CYCLES = {1: 2000, 8: 1500, 32: 600}
QUICK_CYCLES = {1: 400, 8: 300, 32: 150}
WARMUP = 100
ROUNDS = 7
QUICK_ROUNDS = 1
POLLER_SERVOS = 8
POLLER_S = 1.0
QUICK_POLLER_S = 0.3
PROFILE_SERVOS = 8
PROFILE_CYCLES = 500
PROFILE_TOP = 8
TARGET_RATIO = 1.0
TARGET_CPU_US = 60.0
TIMEOUT_MARGIN_S = 0.05
ROUND_TIMEOUT_S = 60.0
"""Bound on a floor client's round (one deadline for the round: none per transaction)."""
READ_SIZE = 4096


def _ids(servos: int) -> tuple[int, ...]:
    return tuple(range(1, servos + 1))


def request_bytes(servos: int) -> int:
    return len(dx.encode(dx.SyncRead(POLL_ADDRESS, POLL_LENGTH, _ids(servos))))


def reply_bytes(servos: int) -> int:
    return servos * (STATUS_OVERHEAD + POLL_LENGTH)


def wire_rate(servos: int, baudrate: int = BAUD) -> float:
    """SYNC READ cycles per second a real bus carries (Return Delay Time 0)."""
    return 1 / wire_time(request_bytes(servos) + reply_bytes(servos), baudrate)


def _round(samples_ns: list[int], cpu_ns: int, failures: int, who: str) -> Round:
    return make_round(samples_ns, cpu_ns, failures, who, "transactions")


# -- the peer: dynamixel-sdk -------------------------------------------------------------


def sdk_round(path: str, servos: int, cycles: int) -> Round:
    """``GroupSyncRead.txRxPacket()`` ``cycles`` times (blocking, this thread)."""
    port = sdk.PortHandler(path)
    if not port.openPort():
        raise RuntimeError(f"dynamixel-sdk cannot open {path}")
    try:
        if not port.setBaudRate(BAUD):
            raise RuntimeError(f"dynamixel-sdk cannot set {BAUD} baud on {path}")
        handler = sdk.PacketHandler(2.0)
        group = sdk.GroupSyncRead(port, handler, POLL_ADDRESS, POLL_LENGTH)
        for dxl_id in _ids(servos):
            if not group.addParam(dxl_id):
                raise RuntimeError(f"GroupSyncRead refused id {dxl_id}")
        success = sdk.COMM_SUCCESS
        for _ in range(WARMUP):
            group.txRxPacket()
        samples: list[int] = []
        failures = 0
        clock, cpu = time.perf_counter_ns, time.process_time_ns
        cpu0 = cpu()
        for _ in range(cycles):
            t0 = clock()
            result = group.txRxPacket()
            samples.append(clock() - t0)
            if result != success:
                failures += 1
        cpu_ns = cpu() - cpu0
    finally:
        port.closePort()
    return _round(samples, cpu_ns, failures, "dynamixel-sdk")


# -- the floors: a bare asyncio client ---------------------------------------------------


def floor_round(path: str, servos: int, cycles: int, *, parse: bool) -> Round:
    """The least an asyncio client pays per transaction on this bus: the same request
    bytes written with ``os.write``, the reply read in ``loop.add_reader``'s callback with
    ``os.read``, one future per transaction completed when the reply's bytes are in;
    nothing checked. ``parse``: the reply, once all in, checked and split by our
    parser's bulk path as our direct path does it
    (:meth:`~openel_serial.dynamixel.PacketParser.feed_bulk`: every fixed byte, id, CRC)
    into ``{id: params}``, the future completed when that holds every servo. No retry, no
    timeout per transaction (one deadline bounds the round). The port is opened and
    configured by pyserial as ours is."""
    tty = serial.serial_for_url(path, baudrate=BAUD)
    try:
        fd = tty.fileno()
        os.set_blocking(fd, False)
        return anyio.run(_floor, fd, servos, cycles, parse, backend="asyncio")
    finally:
        tty.close()


async def _floor(fd: int, servos: int, cycles: int, parse: bool) -> Round:
    request = dx.encode(dx.SyncRead(POLL_ADDRESS, POLL_LENGTH, _ids(servos)))
    expected = reply_bytes(servos)
    loop = asyncio.get_running_loop()
    parser = dx.PacketParser()
    read, write = os.read, os.write
    waiter: asyncio.Future[None] = loop.create_future()
    pending = b""

    def on_readable() -> None:
        nonlocal pending
        data = read(fd, READ_SIZE)
        pending = pending + data if pending else data
        if len(pending) < expected or waiter.done():
            return
        reply, pending = pending, b""
        if parse:
            bulk = parser.feed_bulk(reply, POLL_LENGTH)
            if bulk is None or len(dict(zip(bulk[0], bulk[2], strict=True))) != servos:
                waiter.set_exception(AssertionError(f"floor client: bad reply {reply.hex()}"))
                return
        waiter.set_result(None)

    async def transaction() -> None:
        nonlocal waiter
        waiter = loop.create_future()
        write(fd, request)
        await waiter

    loop.add_reader(fd, on_readable)
    try:
        with anyio.fail_after(ROUND_TIMEOUT_S):
            for _ in range(WARMUP):
                await transaction()
            samples: list[int] = []
            clock, cpu = time.perf_counter_ns, time.process_time_ns
            cpu0 = cpu()
            for _ in range(cycles):
                t0 = clock()
                await transaction()
                samples.append(clock() - t0)
            cpu_ns = cpu() - cpu0
    finally:
        loop.remove_reader(fd)
    if parser.dropped_bytes or parser.crc_errors:
        raise AssertionError(f"floor client: unexpected bytes on the bus: {parser}")
    return _round(samples, cpu_ns, 0, "parse floor" if parse else "bare floor")


# -- ours ----------------------------------------------------------------------------------


async def driver_round(path: str, servos: int, cycles: int) -> Round:
    """``await DynamixelPort.sync_read`` ``cycles`` times."""
    ids = _ids(servos)
    async with DynamixelPort(
        path, baudrate=BAUD, return_delay=0.0, timeout_margin=TIMEOUT_MARGIN_S
    ) as port:
        for _ in range(WARMUP):
            await port.sync_read(ids, POLL_ADDRESS, POLL_LENGTH)
        samples: list[int] = []
        retries = port.stats.retries
        clock, cpu = time.perf_counter_ns, time.process_time_ns
        cpu0 = cpu()
        for _ in range(cycles):
            t0 = clock()
            data = await port.sync_read(ids, POLL_ADDRESS, POLL_LENGTH)
            samples.append(clock() - t0)
            if len(data) != servos:
                raise AssertionError(f"sync read returned {len(data)} of {servos} servos")
        cpu_ns = cpu() - cpu0
        if port.stats.timeouts or port.parser.dropped_bytes:
            raise AssertionError(f"unexpected timeouts/drops: {port.stats}, {port.parser}")
    return _round(samples, cpu_ns, port.stats.retries - retries, "ours")


async def poller_rate(path: str, servos: int, duration_s: float) -> float:
    """Poll cycles per second of the port's poller with ``servos`` servo components."""
    async with (
        DynamixelPort(
            path,
            baudrate=BAUD,
            return_delay=0.0,
            timeout_margin=TIMEOUT_MARGIN_S,
            poll_period=0.0,
        ) as port,
        AsyncExitStack() as stack,
    ):
        for dxl_id in _ids(servos):
            await stack.enter_async_context(Actuator(DynamixelServo(port, dxl_id)))
        await anyio.sleep(0.1)  # warm up
        before, start = port.stats.poll_cycles, time.perf_counter()
        await anyio.sleep(duration_s)
        cycles, elapsed = port.stats.poll_cycles - before, time.perf_counter() - start
        if port.stats.poll_misses:
            raise AssertionError(f"poll misses: {port.stats}")
    return float(cycles / elapsed)


def profile_ours(path: str, servos: int, cycles: int, top: int = PROFILE_TOP) -> list[str]:
    """Our transactions under cProfile (CPU time): the functions with the most own time.

    Each entry: calls and own CPU µs per transaction, as profiled (cProfile's overhead
    inflates every figure, small functions most; compare entries, not with the bench).
    """
    profiler = cProfile.Profile(time.process_time_ns, 1e-9)  # CPU time, not waits
    profiler.enable()
    anyio.run(driver_round, path, servos, cycles, backend="asyncio")
    profiler.disable()
    stats = pstats.Stats(profiler)
    raw = stats.stats  # type: ignore[attr-defined]
    transactions = cycles + WARMUP
    rows = []
    for (filename, line, func), (_cc, calls, tottime, _ct, _callers) in sorted(
        raw.items(), key=lambda kv: kv[1][2], reverse=True
    )[:top]:
        where = filename.rsplit("/site-packages/", 1)[-1].rsplit("/main/", 1)[-1]
        where = where.rsplit("/lib/python3.11/", 1)[-1]
        rows.append(
            f"`{func}` ({where}:{line}) {calls / transactions:.1f} calls, "
            f"{tottime / transactions * 1e6:.1f} µs"
        )
    return rows


# -- the run -------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Size:
    servos: int
    ours: tuple[Round, ...]
    peer: tuple[Round, ...]
    bare: tuple[Round, ...]
    """The bare asyncio client (:func:`floor_round`), in the same rounds."""
    parsed: tuple[Round, ...]
    """The bare asyncio client with our bulk parse."""

    def ours_median(self, field: str) -> float:
        return median_of(self.ours, field)

    def peer_median(self, field: str) -> float:
        return median_of(self.peer, field)


def measure(servos: int, cycles: int, rounds: int) -> Size:
    ours: list[Round] = []
    peer: list[Round] = []
    bare: list[Round] = []
    parsed: list[Round] = []
    with BusProcess(servos) as path:
        for i in range(rounds):  # alternate (and swap who goes first) so load hits all
            order = (
                ("peer", "parsed", "ours", "bare") if i % 2 else ("ours", "bare", "peer", "parsed")
            )
            for who in order:
                gc.collect()
                if who == "ours":
                    ours.append(anyio.run(driver_round, path, servos, cycles, backend="asyncio"))
                elif who == "peer":
                    peer.append(sdk_round(path, servos, cycles))
                else:
                    floor = bare if who == "bare" else parsed
                    floor.append(floor_round(path, servos, cycles, parse=who == "parsed"))
    return Size(servos, tuple(ours), tuple(peer), tuple(bare), tuple(parsed))


def run(quick: bool) -> BenchResult:
    cycles = QUICK_CYCLES if quick else CYCLES
    rounds = QUICK_ROUNDS if quick else ROUNDS
    sizes = [measure(n, cycles[n], rounds) for n in SIZES]
    with BusProcess(POLLER_SERVOS) as path:
        gc.collect()
        poller = anyio.run(
            poller_rate,
            path,
            POLLER_SERVOS,
            QUICK_POLLER_S if quick else POLLER_S,
            backend="asyncio",
        )
        profile = profile_ours(path, PROFILE_SERVOS, PROFILE_CYCLES)

    rows: list[Row] = []
    notes: list[str] = []
    for size in sizes:
        n = size.servos
        median, peer_median = size.ours_median("median_us"), size.peer_median("median_us")
        cpu, peer_cpu = size.ours_median("cpu_us"), size.peer_median("cpu_us")
        # The ratio of each round with the SDK round next to it (same load), then their
        # median: steadier on a shared machine than the ratio of the two medians.
        pairs = [
            ratio_of(o.median_us, p.median_us) for o, p in zip(size.ours, size.peer, strict=True)
        ]
        ratio = statistics.median(pairs)
        cpu_ratio = statistics.median(
            ratio_of(o.cpu_us, p.cpu_us) for o, p in zip(size.ours, size.peer, strict=True)
        )
        rows.append(
            Row(
                f"SYNC READ {n} servo{'s' if n > 1 else ''}, median transaction",
                median,
                "µs",
                baseline=peer_median,
                baseline_label="dynamixel-sdk GroupSyncRead",
                ratio=ratio,
                ratio_label="ours/sdk",
                target=f"<= {TARGET_RATIO:.1f}x sdk",
                passed=ratio <= TARGET_RATIO,
            )
        )
        rows.append(
            Row(
                f"our CPU per transaction, {n} servo{'s' if n > 1 else ''}",
                cpu,
                "µs",
                baseline=peer_cpu,
                baseline_label="dynamixel-sdk, polling read",
                ratio=cpu_ratio,
                ratio_label="ours/sdk",
                target=f"<= {TARGET_CPU_US:.0f} µs",
                passed=cpu <= TARGET_CPU_US,
            )
        )
        rows.append(
            Row(
                f"floor: median transaction of a bare asyncio client, {n} servo"
                + ("s" if n > 1 else ""),
                median_of(size.bare, "median_us"),
                "µs",
                baseline=peer_median,
                baseline_label="dynamixel-sdk GroupSyncRead",
                ratio=statistics.median(
                    ratio_of(b.median_us, p.median_us)
                    for b, p in zip(size.bare, size.peer, strict=True)
                ),
                ratio_label="floor/sdk",
            )
        )
        for label, floor in (
            ("a bare asyncio client", size.bare),
            ("the bare client + our bulk parse", size.parsed),
        ):
            rows.append(
                Row(
                    f"floor: CPU per transaction of {label}, {n} servo{'s' if n > 1 else ''}",
                    median_of(floor, "cpu_us"),
                    "µs",
                    baseline=cpu,
                    baseline_label="ours",
                    ratio=statistics.median(
                        ratio_of(f.cpu_us, o.cpu_us) for f, o in zip(floor, size.ours, strict=True)
                    ),
                    ratio_label="floor/ours",
                )
            )
        per_round = ", ".join(f"{r:.2f}" for r in pairs)
        notes.append(
            f"N = {n}: CPU per round (µs): bare client "
            + ", ".join(f"{r.cpu_us:.0f}" for r in size.bare)
            + "; + our parse "
            + ", ".join(f"{r.cpu_us:.0f}" for r in size.parsed)
            + "; ours over the bare client "
            + ", ".join(
                f"{o.cpu_us - b.cpu_us:+.0f}" for o, b in zip(size.ours, size.bare, strict=True)
            )
            + f"; median transaction of the bare client {median_of(size.bare, 'median_us'):.0f} µs."
        )
        notes.append(
            f"N = {n}: per-round ours/sdk median ratios {per_round}; our CPU per round "
            + ", ".join(f"{r.cpu_us:.0f}" for r in size.ours)
            + " µs; p99 ours "
            f"{size.ours_median('p99_us'):.0f} µs, sdk {size.peer_median('p99_us'):.0f} µs; "
            f"wire limit at 1 Mbaud {wire_rate(n):,.0f} transactions/s "
            f"({1e6 / wire_rate(n):.0f} µs each); failed transactions (peer stalled past "
            f"the timeout: retried by ours, timed out in the SDK): ours "
            f"{sum(r.failures for r in size.ours)}, sdk {sum(r.failures for r in size.peer)}."
        )
    rows.append(
        Row(
            f"poller cycles/s, {POLLER_SERVOS} servo components",
            poller,
            "/s",
            baseline=wire_rate(POLLER_SERVOS),
            baseline_label="wire limit at 1 Mbaud",
            ratio=ratio_of(poller, wire_rate(POLLER_SERVOS)),
            ratio_label="pty/wire",
            target=f">= wire limit {wire_rate(POLLER_SERVOS):,.0f}/s",
            passed=poller >= wire_rate(POLLER_SERVOS),
            digits=0,
        )
    )
    notes.append(
        f"Median of {rounds} alternating round(s) per N after {WARMUP} warm-up transactions; "
        f"cycles per round: " + ", ".join(f"N = {n}: {cycles[n]:,}" for n in SIZES) + "."
    )
    notes.append(
        "CPU: `time.process_time_ns()` of the benchmark process over a round's timed "
        "transactions, divided by their number. The simulated bus runs in a child process, "
        "so its CPU is in neither figure. The SDK reads with pyserial's timeout 0 and "
        "polls until the status arrives: its CPU is about its wall time."
    )
    notes.append(
        f"Where our CPU goes (cProfile with a CPU timer, {PROFILE_CYCLES} transactions of "
        f"{PROFILE_SERVOS} servos; per transaction, as profiled, event loop included): "
        + "; ".join(profile)
        + "."
    )
    return BenchResult(
        name=NAME,
        title="Dynamixel SYNC READ of 1 / 8 / 32 servos vs dynamixel-sdk's GroupSyncRead",
        rows=tuple(rows),
        description=DESCRIPTION,
        notes=tuple(notes),
        params={
            "servos": " / ".join(str(n) for n in SIZES),
            "request": " / ".join(f"{request_bytes(n)} B" for n in SIZES),
            "replies": " / ".join(f"{n} x {STATUS_OVERHEAD + POLL_LENGTH} B" for n in SIZES),
            "baud (SDK setting, our timeouts)": f"{BAUD:,}",
            "rounds": str(rounds),
            "peer": f"dynamixel-sdk {package_version('dynamixel-sdk')}",
        },
    )


DESCRIPTION = f"""\
Dynamixel SYNC READ of Moving .. Present Position (addresses {POLL_ADDRESS}..135, the
poller's request) from N = {" / ".join(str(n) for n in SIZES)} simulated servos, the same
simulated bus for both clients, in the same run:

- **bus**: `openel_serial.peers.SimDynamixelBus` with servos 1..N (Return Delay Time 0)
  behind a pty, served by a child process (`benchmarks/serial_bus.py`), so that its CPU
  time is measured for neither client.
- **ours**: `await DynamixelPort.sync_read(ids, {POLL_ADDRESS}, {POLL_LENGTH})` in an anyio
  (asyncio) event loop, through pyserial-asyncio-fast; every status checked (CRC, id,
  length, error byte), retries and timeouts armed.
- **peer**: dynamixel-sdk's `GroupSyncRead(port, PacketHandler(2.0), {POLL_ADDRESS},
  {POLL_LENGTH})` with `addParam(id)` for the same ids and `txRxPacket()` per transaction,
  blocking, in the benchmark process's main thread, on the SDK's own `PortHandler`.
- **floors** (informational rows, same rounds, same bus): a bare asyncio client, in an
  anyio-run asyncio loop like ours, on the tty opened by pyserial like ours: the same
  request bytes written with `os.write`, the reply read with `os.read` in a
  `loop.add_reader` callback, one future per transaction completed when the reply's
  bytes are in, nothing checked, no retry, no timer (`floor_round`); and the same client
  checking and splitting the reply with our bulk parse (`PacketParser.feed_bulk` into
  `{{id: params}}`, what our direct path does). The bare client is the least any asyncio
  client pays per transaction here: one `write`, one `epoll` wake-up, one `read`, two
  loop passes.

Each transaction is timed alone; rounds of ours and the SDK alternate on the same bus
process (the first of each pair swaps every round). Value and baseline are the medians
over the rounds of each round's median; the ratio is the median over the rounds of
ours/sdk within each pair of adjacent rounds (both under the same machine load).
A pty moves bytes at memory speed: a transaction's time is the two processes' CPU
time plus two wake-ups, not a bus speed.

At N = 1 the transaction is almost all waiting: timestamps in our transport (idle
machine, 2,000 transactions) put 80-95 µs between our write and the reply becoming
readable (the bus process waking, answering, and this process waking from `epoll`) and
8-9 µs from the reply being readable to the next request's write (parse, CRC, the
task's wake-up pass, the benchmark's loop). The SDK never sleeps (it polls the port),
so it saves the last wake-up and pays with its whole wall time in CPU; a client that
sleeps until the reply cannot be more than a few µs faster than that at N = 1.

**The median transaction at N = 1 (issue 27, target <= 1.0x the SDK): met in some full
runs, missed in others, by less than the machine's noise.** Recorded full runs: 0.98x
(12:17 UTC), 1.06x and 1.01x (13:24 and 13:49 UTC, 2026-11-29; per-round ratios
0.96-1.20 and 0.95-1.13), then, with this pass's changes, 1.01x and 1.05x (14:22 and
14:42 UTC; per round 0.85-1.09 and 0.70-1.43). Four more runs of the N = 1 rounds alone (7 rounds of 2,000
each, two of them with this process and the bus process pinned to one core each)
gave medians of 0.96-1.02x, with per-round ratios from 0.77 to 1.51: runs one
minute apart land on either side of 1.0. The limit is shown by the floor row
"median transaction of a bare asyncio client": a client that only writes the request,
sleeps in `epoll`, reads the reply and completes a future, checking nothing, takes
0.83-0.88x of the SDK's time in those four full runs (medians 202, 204, 208 and 198 µs
against 243, 232, 243 and 236 µs). A real client's work sits on the same critical path. Timestamps in our
transport (3,500 transactions of one servo, this pass) put about 14 µs before the
request is written: the bus lock, about 9 µs of it with anyio's cancellation check
(`checkpoint_if_cancelled`, 2.7 µs warm), the packet cache and the exchange's set-up;
`os.write` on the pty alone takes about 20 µs for both clients. After the reply is
readable come 23 µs in the reception callback (of which 13 µs are `feed_bulk`'s
header, id, length and CRC checks, 2.2-3.0 µs when timed warm in a loop) and 12-15 µs
until the task resumes. In the four full runs ours is 27-45 µs over the bare client:
the whole 12-17 % margin that the floor leaves. This pass took the lone status's parse
from 3.0 to 2.2 µs warm (one unpack, no list, zip or `bytes()`) and removed two
coroutines from `sync_read` (the bus lock without `async with`); no change shows
through the round-to-round noise. The decision: keep the event-driven read. The
SDK's latency costs its whole wall time in CPU, 228-237 µs per transaction
against our 87-101 µs, because it polls the port. A spinning client would meet the
target by burning a core, which no poller of a servo bus should do, and a compiled parse
could take off at most the parse's few µs of the 31-45. The row stays at its target and
is reported as it falls; the floor row shows its limit in every run.

**Our CPU per transaction (issue 27, target <= 60 µs at every N): not reachable in
asyncio on this machine: in the same rounds the bare asyncio client alone takes 55-67 µs
at N = 1 (medians of two full runs).** In the full run of this
pass (09:00-09:03 UTC, commit 004d931, load 5.2, 7 rounds; not written to this page)
the bare client alone took 67 / 87 / 123 µs per transaction at N = 1 / 8 / 32 (per
round at N = 1: 52-85 µs, over 60 in 6 of 7 rounds), the bare client with our bulk
parse 98 / 149 / 158 µs, ours 129 / 201 / 253 µs: ours over the bare client (per round,
median) +52 / +113 / +111 µs, ours/floor 2.0 / 2.3 / 1.9. A second full run at load
2.1 (09:20-09:22 UTC, commit 2a34992): bare client 55 / 68 / 80 µs (per round at N = 1:
37-67 µs), with our parse 79 / 91 / 109 µs, ours 112 / 139 / 171 µs (the run recorded
below, before this pass, load 1.5: 93 / 142 / 208 µs), ours over the bare client +54 /
+68 / +87 µs, ours/floor 2.0 / 1.9 / 2.0. With the machine quieter
(load 1.5-2, a script with the same clients, 5 rounds of 1,500) the bare client took
42-69 µs at N = 1 (median 56-59 µs): even then it leaves at most a few µs of the 60 µs
for parsing, checking, the lock, the retry and timeout bookkeeping that the floor does
not do. A client that sleeps until the reply cannot do better than the floor; the
target holds only for one that spins (dynamixel-sdk: 4-10x our CPU).

What this pass changed (the direct path): a SYNC READ whose statuses come in one read,
each from an id asked for, once, with error byte 0 (the usual case), is handed by the
reception to `DynamixelPort.sync_read` as `{{id: params}}` with no object and no Python
loop per status: `PacketParser.feed_bulk` checks every fixed byte of every packet by
extended slices, the ids, and every packet's CRC on its own (one CRC pass over the whole
run, each CRC's two bytes swapped, was 5-6 µs cheaper at 32 statuses, but 4 or more bits
flipped across two packets could cancel out in it: not taken), and unpacks every
params with one `struct` (from 3 statuses on; one or two are unpacked one by one);
`sync_read` calls the exchange directly (two coroutine layers fewer). Anything else (a refusal, an alert, a missing, stray or repeated id, a
reply split across reads) takes the per-status path, retries and error checks as
before. Old (790f49d) and new code in alternating rounds on one bus with the bare client
(6 rounds each, load 3.9-5.6): our CPU 179 -> 164 / 166 -> 163 / 282 -> 222 µs at N = 1
/ 8 / 32 (new/old per round, median: 0.92 / 0.88 / 0.85), ours over the bare client
(median) +86 -> +75 / +101 -> +87 / +169 -> +114 µs. The parse and the per-status
handling alone, timed in a loop on the same bytes (load 3.7): 4.9 -> 5.1 / 14.9 -> 9.9 /
45 -> 11 µs; `feed_bulk` alone 2.5 / 5.1 / 13.9 µs with every CRC checked on its own (load 4). The cost over the floor grows less
with N (N = 8 to 32: +87 -> +114 and +113 -> +111 µs in the two runs, +101 -> +169
before); what remains (+50 to +110 µs at load 5) is mostly the fixed path: the bus
lock, the exchange's bookkeeping (timer, counters, expected ids), the link and transport
layers and the deeper coroutine chain, about 15-25 µs when timed warm in a loop (a fake
link answering in the next loop pass: ours 21-37 µs at N = 1, the bare future 6-12 µs),
multiplied by cold caches after each wake-up on a loaded machine.

A compiled parser would not change the verdict: the whole parse with the `{{id:
params}}` split costs 5 / 10 / 11 µs warm, of which a C or Rust routine might save
4 / 9 / 10 µs; in the run the parse floor sits 30 / 61 / 35 µs over the bare client
(cold caches), the most a compiled parser could take off, while the bare client alone is
at or over 60 µs. The decision: the three rows stay, failing, with the floor rows as
their measured limit; proposed to issue 27 instead: a target relative to the in-run
floor (our CPU per transaction at most 2x the bare asyncio client's in the same rounds:
2.0 / 2.3 / 1.9 and 2.0 / 1.9 / 2.0 in the two runs), which a loaded or quiet machine moves much less than an absolute
one. dynamixel-sdk spends 4-10x our CPU at every N (its polling read)."""
