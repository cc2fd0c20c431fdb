"""Dynamixel SYNC READ of 8 servos over a pty: the driver against raw bytes and the wire limit.

* **ours**: ``await DynamixelPort.sync_read(ids, 122, 14)`` (the poller's request: Moving
  through Present Position of 8 servos), through pyserial-asyncio-fast, a pty and the
  simulated bus (:class:`openel_serial.peers.SimDynamixelBus`, Return Delay Time 0).
* **raw** (baseline, same pty, same peer, same run): the pre-encoded instruction packet
  written with ``os.write`` on the slave fd, then ``os.read`` until the 8 x 25 reply
  bytes arrived (``anyio.wait_readable`` between reads): no framing, CRC, matching,
  timeout or lock.
* **wire limit**: what a real bus at 1 Mbaud allows: (22 + 8 x 25) bytes x 10 bits =
  2.22 ms per cycle plus the return delays (0 here), i.e. 450 cycles/s.
* **poller**: 8 ``Actuator(DynamixelServo)`` components on one port with
  ``poll_period=0``: SYNC READ cycles per second including the dispatch to the servos.

A pty has no baud rate: its figures measure CPU time of the driver *and* of the peer
(both run in this process, on one event loop), so "pty / wire" says how much headroom
the driver leaves on a real 1 Mbaud bus, not a bus speed.
"""

from __future__ import annotations

import gc
import os
import statistics
import time
from contextlib import AsyncExitStack
from dataclasses import dataclass

import anyio
import anyio.lowlevel

from openel_async import Actuator
from openel_serial import DynamixelPort, DynamixelServo
from openel_serial import dynamixel as dx
from openel_serial.peers import SimDynamixelBus, SimServo
from openel_serial.port import POLL_ADDRESS, POLL_LENGTH, STATUS_OVERHEAD, wire_time

from .harness import BenchResult, Row, ratio_of

NAME = "serial"
SERVOS = 8
BAUD = 1_000_000
CYCLES = 1500
QUICK_CYCLES = 600
WARMUP = 100
ROUNDS = 5
QUICK_ROUNDS = 1
POLLER_S = 1.0
QUICK_POLLER_S = 0.3
IDS = tuple(range(1, SERVOS + 1))
REQUEST = dx.encode(dx.SyncRead(POLL_ADDRESS, POLL_LENGTH, IDS))
REPLY_BYTES = SERVOS * (STATUS_OVERHEAD + POLL_LENGTH)
FACTORY_RETURN_DELAY_S = 500e-6


def wire_cycle_s(baudrate: int, return_delay_s: float) -> float:
    return wire_time(len(REQUEST) + REPLY_BYTES, baudrate) + SERVOS * return_delay_s


@dataclass(frozen=True, slots=True)
class Round:
    rate: float
    """Cycles per second over the timed cycles."""
    median_us: float
    p99_us: float


def _round(samples_ns: list[int], total_ns: int) -> Round:
    samples_ns.sort()
    p99 = samples_ns[min(len(samples_ns) - 1, round(0.99 * (len(samples_ns) - 1)))]
    return Round(len(samples_ns) * 1e9 / total_ns, statistics.median(samples_ns) / 1e3, p99 / 1e3)


def _bus() -> SimDynamixelBus:
    bus = SimDynamixelBus([SimServo(i, return_delay_time=0) for i in IDS])
    bus.keep_log = False
    return bus


async def driver_round(cycles: int) -> Round:
    async with (
        _bus() as bus,
        DynamixelPort(bus.path, baudrate=BAUD, return_delay=0.0, timeout_margin=0.05) as port,
    ):
        for _ in range(WARMUP):
            await port.sync_read(IDS, POLL_ADDRESS, POLL_LENGTH)
        samples: list[int] = []
        start = time.perf_counter_ns()
        for _ in range(cycles):
            t0 = time.perf_counter_ns()
            data = await port.sync_read(IDS, POLL_ADDRESS, POLL_LENGTH)
            samples.append(time.perf_counter_ns() - t0)
            if len(data) != SERVOS:
                raise AssertionError(f"sync read returned {len(data)} servos")
        total = time.perf_counter_ns() - start
        if port.stats.retries or port.stats.timeouts:
            raise AssertionError(f"unexpected retries/timeouts: {port.stats}")
    return _round(samples, total)


async def _raw_cycle(fd: int) -> None:
    os.write(fd, REQUEST)
    got = 0
    while got < REPLY_BYTES:
        try:
            got += len(os.read(fd, 4096))
        except BlockingIOError:
            await anyio.wait_readable(fd)


async def raw_round(cycles: int) -> Round:
    async with _bus() as bus:
        fd = os.open(bus.path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        try:
            for _ in range(WARMUP):
                await _raw_cycle(fd)
            samples: list[int] = []
            start = time.perf_counter_ns()
            for _ in range(cycles):
                t0 = time.perf_counter_ns()
                await _raw_cycle(fd)
                samples.append(time.perf_counter_ns() - t0)
            total = time.perf_counter_ns() - start
        finally:
            anyio.notify_closing(fd)
            os.close(fd)
    return _round(samples, total)


async def poller_rate(duration_s: float) -> float:
    """Poll cycles per second of the port's poller with 8 servo components attached."""
    async with (
        _bus() as bus,
        DynamixelPort(
            bus.path, baudrate=BAUD, return_delay=0.0, timeout_margin=0.05, poll_period=0.0
        ) as port,
        AsyncExitStack() as stack,
    ):
        for dxl_id in IDS:
            await stack.enter_async_context(Actuator(DynamixelServo(port, dxl_id)))
        await anyio.sleep(0.1)  # warm up
        before, start = port.stats.poll_cycles, time.perf_counter()
        await anyio.sleep(duration_s)
        cycles, elapsed = port.stats.poll_cycles - before, time.perf_counter() - start
        if port.stats.poll_misses:
            raise AssertionError(f"poll misses: {port.stats}")
    return cycles / elapsed


def run(quick: bool) -> BenchResult:
    cycles = QUICK_CYCLES if quick else CYCLES
    rounds = QUICK_ROUNDS if quick else ROUNDS
    ours: list[Round] = []
    raw: list[Round] = []
    for _ in range(rounds):  # alternate, so load changes hit both alike
        gc.collect()
        ours.append(anyio.run(driver_round, cycles, backend="asyncio"))
        gc.collect()
        raw.append(anyio.run(raw_round, cycles, backend="asyncio"))
    gc.collect()
    poller = anyio.run(poller_rate, QUICK_POLLER_S if quick else POLLER_S, backend="asyncio")

    rate = statistics.median(r.rate for r in ours)
    raw_rate = statistics.median(r.rate for r in raw)
    median = statistics.median(r.median_us for r in ours)
    raw_median = statistics.median(r.median_us for r in raw)
    p99 = statistics.median(r.p99_us for r in ours)
    raw_p99 = statistics.median(r.p99_us for r in raw)
    wire = 1 / wire_cycle_s(BAUD, 0.0)
    wire_default_delay = 1 / wire_cycle_s(BAUD, FACTORY_RETURN_DELAY_S)
    wire_57k = 1 / wire_cycle_s(57_600, FACTORY_RETURN_DELAY_S)
    rows = (
        Row(
            "SYNC READ cycles/s, 8 servos (pty)",
            rate,
            "/s",
            baseline=raw_rate,
            baseline_label="raw bytes, same pty",
            ratio=ratio_of(rate, raw_rate),
            ratio_label="ours/raw",
            target=f">= wire limit {wire:,.0f}/s",
            passed=rate >= wire,
            digits=0,
        ),
        Row(
            "same, against the 1 Mbaud wire limit",
            rate,
            "/s",
            baseline=wire,
            baseline_label="wire limit, 222 B at 1 Mbaud",
            ratio=ratio_of(rate, wire),
            ratio_label="pty/wire",
            digits=0,
        ),
        Row(
            "median cycle",
            median,
            "µs",
            baseline=raw_median,
            baseline_label="raw bytes",
            ratio=ratio_of(median, raw_median),
            ratio_label="ours/raw",
        ),
        Row(
            "p99 cycle",
            p99,
            "µs",
            baseline=raw_p99,
            baseline_label="raw bytes",
            ratio=ratio_of(p99, raw_p99),
            ratio_label="ours/raw",
        ),
        Row(
            "poller cycles/s, 8 servo components",
            poller,
            "/s",
            baseline=wire,
            baseline_label="wire limit",
            ratio=ratio_of(poller, wire),
            ratio_label="pty/wire",
            target=f">= wire limit {wire:,.0f}/s",
            passed=poller >= wire,
            digits=0,
        ),
    )
    spread = ", ".join(f"{r.rate:,.0f}" for r in ours)
    raw_spread = ", ".join(f"{r.rate:,.0f}" for r in raw)
    notes = (
        f"Median of {rounds} alternating round(s) of {cycles:,} cycles after {WARMUP} "
        f"warm-up cycles; per-round rates: ours {spread}; raw {raw_spread}.",
        f"Driver cost per cycle at the median: {median - raw_median:.0f} µs over raw "
        "(framing and CRC of 8 status packets, matching, timeout scope, lock).",
        f"Wire limits for comparison: {wire:,.0f}/s at 1 Mbaud with Return Delay Time 0; "
        f"{wire_default_delay:,.0f}/s with the factory 500 µs return delay; "
        f"{wire_57k:,.1f}/s at the factory 57,600 baud.",
        "A pty moves bytes at memory speed: the pty figures are CPU-bound (driver and "
        "simulated peer share this process and event loop); they are not a bus speed.",
    )
    return BenchResult(
        name=NAME,
        title="Dynamixel SYNC READ of 8 servos over a pty vs raw bytes and the 1 Mbaud wire",
        rows=rows,
        description=DESCRIPTION,
        notes=notes,
        params={
            "servos": str(SERVOS),
            "request": f"{len(REQUEST)} B",
            "replies": f"{SERVOS} x {STATUS_OVERHEAD + POLL_LENGTH} B",
            "baud (for limits and timeouts)": f"{BAUD:,}",
            "cycles": f"{cycles:,}",
            "rounds": str(rounds),
        },
    )


DESCRIPTION = f"""\
Dynamixel SYNC READ of Moving .. Present Position (addresses {POLL_ADDRESS}..135, the
poller's request) from {SERVOS} simulated servos over a pty, in the same run:

- **ours**: `await DynamixelPort.sync_read(ids, {POLL_ADDRESS}, {POLL_LENGTH})` through
  pyserial-asyncio-fast, the pty and `openel_serial.peers.SimDynamixelBus` (Return Delay
  Time 0); each cycle timed alone.
- **raw** (baseline): the same pre-encoded {len(REQUEST)}-byte instruction written with
  `os.write` on the slave fd of the same kind of pty and peer, then `os.read` until the
  {REPLY_BYTES} reply bytes arrived (`anyio.wait_readable` between reads): no framing,
  CRC, matching, timeout or lock.
- **wire limit**: a real bus at 1 Mbaud carries ({len(REQUEST)} + {SERVOS} x
  {STATUS_OVERHEAD + POLL_LENGTH}) bytes x 10 bits = {wire_cycle_s(BAUD, 0.0) * 1e3:.2f} ms
  per cycle plus the servos' return delays (0 here).
- **poller**: {SERVOS} `Actuator(DynamixelServo)` components on one port with
  `poll_period=0`: cycles per second of the port's poller, dispatch to the servos included.

A pty has no baud rate: bytes move at memory speed, so the pty figures measure the CPU
time of the driver *and* of the simulated peer (both in this process, on one event
loop). "pty/wire" is therefore the headroom the driver leaves on a real 1 Mbaud bus,
not a bus speed. Rounds of ours and raw alternate; the median round is reported."""
