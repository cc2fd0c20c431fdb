"""Remote devices at scale: 10 client processes x 20 served devices, against raw Zenoh.

A server process serves 20 SimMotors through a ``SurfaceServer`` on a ``GatedEventLoop``
(the stack of ``openel-async serve``; ``python -m benchmarks.bench_remote serve PORT 20
noburst``) and 10 client processes, each with its own Zenoh session and
``RemoteSurface``, run a paced mix every 200 ms: ``get_value`` of all 20 devices through
``Actuator(RemoteActuator(...))``, then ``set_value`` of the 2 devices it owns (each device
is commanded by one client), one awaited call after the other; every call's latency is
recorded. The baseline is the same shape on raw Zenoh (no code of ours on the path): a raw
peer process with 20 queryables (``raw/d/0``..``raw/d/19``, answered on Zenoh's thread) and
10 raw client processes doing blocking ``session.get`` queries, 22 per 200 ms cycle. Both
are offered 1100 calls/s; a cycle that ends late starts the next at once (no catch-up
burst), so "calls answered" below the offered rate means the machine did not keep up
(with a 100 ms cycle, 2200 calls/s, ours answered 836/s on a 2-core VM loaded by other
work, raw all of them: our clients' CPU per call is several times raw's). Everything on
loopback (127.0.0.1).

Our clients and the raw ones alternate in rounds (a warm-up round, then 5 measured rounds;
60 s of load on each server in all, 5 s with ``--quick``), so a load change on the
machine hits both; a latency row is the median over the rounds of that round's percentile
of all 10 clients' calls, its ratio the median of the per-round ratios. The server
processes' CPU time (``/proc/PID/stat``, every thread), and the 10 clients' together, is
summed over their own rounds and divided by the calls answered; their resident set size is read after the warm-up
round, in the middle and at the end: flat means the end within 10 % of the start.
"""

from __future__ import annotations

import json
import os
import statistics
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import anyio

from .bench_remote import NAMESPACE, Popen, free_port, pct, read_line, start, stop_all, wait_ready
from .harness import BenchResult, Row, ratio_of

NAME = "remote_scale"
MODULE = "benchmarks.bench_remote_scale"
CLIENTS = 10
DEVICES = 20
SETS = 2
"""set_value calls per cycle and client (on the devices the client owns)."""
CYCLE = 0.2
"""Seconds between the starts of a client's cycles (DEVICES + SETS calls each)."""
ROUNDS = 5
DURATION = 60.0
QUICK_DURATION = 5.0
WARMUP = 3.0
QUICK_WARMUP = 0.5
CALL_TIMEOUT = 2.0
START_TIMEOUT = 120.0
"""Seconds for all 22 processes to start (20 Python interpreters on a loaded 2-core box)."""
ROUND_SLACK = 30.0
"""Seconds a round's report may come after the round's end."""
TARGET_RSS_GROWTH = 0.10


# -- measuring a process from outside -----------------------------------------------------
def cpu_seconds(pid: int) -> float:
    """User + system CPU time of process ``pid`` (all its threads), from /proc."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def rss_bytes(pid: int) -> int:
    """Resident set size of process ``pid``, from /proc."""
    with open(f"/proc/{pid}/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


# -- the client processes ------------------------------------------------------------------
def _owned(index: int) -> list[int]:
    return [(index * SETS + j) % DEVICES for j in range(SETS)]


def _report(
    gets: list[float], sets: list[float], failed: int, errors: list[str], **extra: Any
) -> None:
    print(
        json.dumps(
            {
                "get": [round(x * 1e6, 1) for x in gets],
                "set": [round(x * 1e6, 1) for x in sets],
                "failed": failed,
                "errors": errors[:5],
                **extra,
            }
        ),
        flush=True,
    )


async def _our_client(port: int, index: int) -> None:
    """``ready``; then for each ``go SECONDS`` line on stdin, cycles for that long and a
    JSON report; ends at EOF."""
    from contextlib import AsyncExitStack

    from openel_async import Actuator, Request
    from openel_async.cli.logs import configure_logging
    from openel_zenoh import RemoteActuator, RemoteSurface, close_session, open_session
    from openel_zenoh.config import client_config, endpoint

    configure_logging("console", "warning")
    session = await open_session(client_config([endpoint(port)]))
    try:
        async with AsyncExitStack() as stack:
            remote = await stack.enter_async_context(
                RemoteSurface(session, NAMESPACE, timeout=CALL_TIMEOUT)
            )
            await remote.wait_server(30)
            axes = [  # each opening is a few remote calls, bounded by CALL_TIMEOUT
                await stack.enter_async_context(Actuator(RemoteActuator(remote, i)))
                for i in range(DEVICES)
            ]
            owned = [axes[i] for i in _owned(index)]
            print("ready", flush=True)
            target = 0.0
            while True:
                line = await anyio.to_thread.run_sync(sys.stdin.readline)
                if not line.startswith("go "):
                    return
                seconds = float(line.split()[1])
                gets: list[float] = []
                sets: list[float] = []
                errors: list[str] = []
                failed = late = 0
                hits, misses = remote.busy_hits, remote.busy_misses
                t_end = time.monotonic() + seconds
                next_cycle = time.monotonic()
                while next_cycle < t_end:
                    for axis in axes:
                        t0 = time.perf_counter()
                        try:
                            await axis.get_value(Request.POSITION_ACTUAL)
                        except Exception as exc:
                            failed += 1
                            errors.append(repr(exc))
                        else:
                            gets.append(time.perf_counter() - t0)
                    target = 0.001 if target == 0.0 else 0.0
                    for axis in owned:
                        t0 = time.perf_counter()
                        try:
                            await axis.set_value(target)
                        except Exception as exc:
                            failed += 1
                            errors.append(repr(exc))
                        else:
                            sets.append(time.perf_counter() - t0)
                    next_cycle += CYCLE
                    now = time.monotonic()
                    if now > next_cycle:
                        late += 1
                        next_cycle = now  # no burst to catch up
                    else:
                        await anyio.sleep(next_cycle - now)
                _report(
                    gets, sets, failed, errors, late=late,
                    busy=[remote.busy_hits - hits, remote.busy_misses - misses],
                )  # fmt: skip
    finally:
        await close_session(session)


def _raw_client(port: int, index: int) -> None:
    """The raw analogue of :func:`_our_client`: blocking queries, the same cycle."""
    import zenoh

    from openel_zenoh.config import client_config, endpoint

    session = zenoh.open(client_config([endpoint(port)]))
    try:
        keys = [f"raw/d/{i}" for i in range(DEVICES)]
        owned = [keys[i] for i in _owned(index)]

        def query(key: str, payload: bytes) -> None:
            replies = list(session.get(key, payload=payload, timeout=CALL_TIMEOUT))
            if not replies or replies[0].ok is None:
                raise RuntimeError(f"no reply from {key}")

        deadline = time.monotonic() + 30  # until the routes to every queryable are known
        for key in keys:
            while True:
                try:
                    query(key, b"g")
                    break
                except RuntimeError:
                    if time.monotonic() > deadline:
                        raise
                    time.sleep(0.05)
        print("ready", flush=True)
        while True:
            line = sys.stdin.readline()
            if not line.startswith("go "):
                return
            seconds = float(line.split()[1])
            gets: list[float] = []
            sets: list[float] = []
            errors: list[str] = []
            failed = late = 0
            t_end = time.monotonic() + seconds
            next_cycle = time.monotonic()
            while next_cycle < t_end:
                for calls, samples, payload in ((keys, gets, b"g"), (owned, sets, b"s" * 9)):
                    for key in calls:
                        t0 = time.perf_counter()
                        try:
                            query(key, payload)
                        except Exception as exc:
                            failed += 1
                            errors.append(repr(exc))
                        else:
                            samples.append(time.perf_counter() - t0)
                next_cycle += CYCLE
                now = time.monotonic()
                if now > next_cycle:
                    late += 1
                    next_cycle = now
                else:
                    time.sleep(next_cycle - now)
            _report(gets, sets, failed, errors, late=late)
    finally:
        session.close()  # type: ignore[no-untyped-call]


# -- the driving process -------------------------------------------------------------------
@dataclass
class Side:
    """One server and its clients (ours or raw), and what their rounds measured."""

    server: Popen
    clients: list[Popen]
    p50: list[float] = field(default_factory=list)
    """Per measured round: the p50 of every client's calls (us); p99 and set_p50 alike."""
    p99: list[float] = field(default_factory=list)
    set_p50: list[float] = field(default_factory=list)
    rss: list[int] = field(default_factory=list)
    """The server's RSS after the warm-up round, in the middle and at the end."""
    errors: list[str] = field(default_factory=list)
    calls: int = 0
    failed: int = 0
    late: int = 0
    seconds: float = 0.0
    """Seconds of measured rounds."""
    cpu: float = 0.0
    """The server's CPU seconds during the measured rounds."""
    client_cpu: float = 0.0
    """The clients' CPU seconds (all 10 processes) during the measured rounds."""
    busy_hits: int = 0
    busy_misses: int = 0


def _round(side: Side, seconds: float, measured: bool) -> None:
    """Run the side's clients for ``seconds`` (all at once) and collect their reports."""
    cpu0 = cpu_seconds(side.server.pid)
    client_cpu0 = sum(cpu_seconds(proc.pid) for proc in side.clients)
    for proc in side.clients:
        assert proc.stdin is not None
        proc.stdin.write(f"go {seconds}\n")
        proc.stdin.flush()
    deadline = time.monotonic() + seconds + ROUND_SLACK
    reports: list[dict[str, Any]] = []
    for proc in side.clients:
        line = read_line(proc, deadline - time.monotonic())
        if not line:
            raise RuntimeError(f"client {proc.pid} sent no report ({line!r})")
        reports.append(json.loads(line))
    cpu = cpu_seconds(side.server.pid) - cpu0
    client_cpu = sum(cpu_seconds(proc.pid) for proc in side.clients) - client_cpu0
    if not measured:
        return
    calls = [x for r in reports for x in (*r["get"], *r["set"])]
    if not calls:
        raise RuntimeError("a round without a single call answered")
    side.p50.append(pct(calls, 0.5))
    side.p99.append(pct(calls, 0.99))
    sets = [x for r in reports for x in r["set"]]
    side.set_p50.append(pct(sets, 0.5) if sets else float("nan"))
    side.calls += len(calls)
    side.failed += sum(r["failed"] for r in reports)
    side.late += sum(r["late"] for r in reports)
    side.errors += [e for r in reports for e in r["errors"]]
    side.seconds += seconds
    side.cpu += cpu
    side.client_cpu += client_cpu
    for r in reports:
        if "busy" in r:
            side.busy_hits += r["busy"][0]
            side.busy_misses += r["busy"][1]


def _start_all(our_port: int, raw_port: int) -> tuple[Side, Side, list[Popen]]:
    procs: list[Popen] = []
    try:
        server = start("serve", our_port, str(DEVICES), "noburst")
        procs.append(server)
        raw_server = start("raw", raw_port, str(DEVICES))
        procs.append(raw_server)
        deadline = time.monotonic() + START_TIMEOUT
        wait_ready(server, "server", deadline - time.monotonic())
        wait_ready(raw_server, "raw peer", deadline - time.monotonic())
        ours = [start("ours", our_port, str(i), module=MODULE) for i in range(CLIENTS)]
        procs += ours
        raw = [start("raw", raw_port, str(i), module=MODULE) for i in range(CLIENTS)]
        procs += raw
        for proc in (*ours, *raw):
            wait_ready(proc, "client", deadline - time.monotonic())
    except BaseException:
        stop_all(procs)
        raise
    return Side(server, ours), Side(raw_server, raw), procs


def _median(values: Sequence[float]) -> float:
    return statistics.median(values) if values else float("nan")


def run(quick: bool) -> BenchResult:
    duration = QUICK_DURATION if quick else DURATION
    warmup = QUICK_WARMUP if quick else WARMUP
    per_round = duration / ROUNDS
    ours, raw, procs = _start_all(free_port(), free_port())
    try:
        for round_ in range(ROUNDS + 1):  # round 0 warms up
            for side in (ours, raw):
                _round(side, per_round if round_ else warmup, measured=round_ > 0)
                if round_ in (0, (ROUNDS + 1) // 2, ROUNDS):
                    side.rss.append(rss_bytes(side.server.pid))
    finally:
        stop_all(procs[2:])  # the clients first: a server gone first is a link fault to them
        stop_all(procs[:2])

    us, mib = 1e6, 1 / 2**20
    p99_ratio = _median([ratio_of(o, r) for o, r in zip(ours.p99, raw.p99, strict=True)])
    growth = ratio_of(ours.rss[-1] - ours.rss[0], ours.rss[0])
    raw_growth = ratio_of(raw.rss[-1] - raw.rss[0], raw.rss[0])
    rows = (
        Row("per-call latency p50", _median(ours.p50), "us", _median(raw.p50), "raw Zenoh query p50",
            _median([ratio_of(o, r) for o, r in zip(ours.p50, raw.p50, strict=True)]), "ours/raw"),
        Row("per-call latency p99", _median(ours.p99), "us", _median(raw.p99), "raw Zenoh query p99",
            p99_ratio, "ours/raw"),
        Row("set_value latency p50", _median(ours.set_p50), "us", _median(raw.set_p50),
            "raw Zenoh query p50", ratio_of(_median(ours.set_p50), _median(raw.set_p50)), "ours/raw"),
        Row("calls answered", ours.calls / ours.seconds, "calls/s", raw.calls / raw.seconds,
            "raw Zenoh queries", ratio_of(ours.calls, raw.calls), "ours/raw", digits=0),
        Row("failed calls", ours.failed, "calls", raw.failed, "raw Zenoh queries", target="0",
            passed=ours.failed == 0, digits=0),
        Row("server CPU per call", ours.cpu / max(1, ours.calls) * us, "us", raw.cpu / max(1, raw.calls) * us,
            "raw Zenoh peer", ratio_of(ours.cpu / max(1, ours.calls), raw.cpu / max(1, raw.calls)), "ours/raw"),
        Row("client CPU per call", ours.client_cpu / max(1, ours.calls) * us, "us",
            raw.client_cpu / max(1, raw.calls) * us, "raw Zenoh clients",
            ratio_of(ours.client_cpu / max(1, ours.calls), raw.client_cpu / max(1, raw.calls)), "ours/raw"),
        Row("server CPU", ours.cpu / ours.seconds * 100, "% of a core",
            raw.cpu / raw.seconds * 100, "raw Zenoh peer"),
        Row("server RSS after warm-up", ours.rss[0] * mib, "MiB", raw.rss[0] * mib, "raw Zenoh peer"),
        Row("server RSS, middle", ours.rss[1] * mib, "MiB", raw.rss[1] * mib, "raw Zenoh peer"),
        Row("server RSS, end", ours.rss[-1] * mib, "MiB", raw.rss[-1] * mib, "raw Zenoh peer"),
        Row("server RSS growth (end vs after warm-up)", growth * 100, "%", raw_growth * 100, "raw Zenoh peer",
            target=f"<= {TARGET_RSS_GROWTH:.0%}", passed=growth <= TARGET_RSS_GROWTH),
    )  # fmt: skip
    notes = [f"client error: `{e}`" for e in dict.fromkeys(ours.errors + raw.errors)][:5]
    return BenchResult(
        name=NAME,
        title=f"Remote devices at scale ({CLIENTS} client processes x {DEVICES} served devices)",
        rows=rows,
        description=(__doc__ or "").split("\n\n", 1)[1].strip(),
        params={
            "clients": str(CLIENTS),
            "devices": str(DEVICES),
            "cycle": f"{DEVICES} get_value + {SETS} set_value every {CYCLE * 1000:.0f} ms",
            "load per side": f"{duration:g} s in {ROUNDS} rounds (+{warmup:g} s warm-up)",
            "late cycles ours/raw": f"{ours.late}/{raw.late}",
            "busy-wait hits/misses": f"{ours.busy_hits}/{ours.busy_misses}",
        },
        notes=tuple(notes),
        quick=quick,
    )


if __name__ == "__main__":
    role, port, index = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
    if role == "ours":
        anyio.run(_our_client, port, index, backend="asyncio")
    elif role == "raw":
        _raw_client(port, index)
    else:
        sys.exit(f"unknown role {role}")
