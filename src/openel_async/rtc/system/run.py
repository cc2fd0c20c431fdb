"""Running a system: every component in its own context, ports connected, a live
status line, a summary at the end (``openel-async run SYSTEM.yaml``).

Sequence (docs/rtc.md §14): enter every context and connector; initialize every
component (in file order); add each to its context; start the contexts; activate the
components; run until ``duration_s`` or SIGINT/SIGTERM; then ``exit()`` every component
in reverse order (stop, deactivate, remove, finalize), also after a failure; leave the
connectors and contexts.
"""

from __future__ import annotations

import argparse
import math
import signal
import sys
from collections.abc import Callable, Sequence
from contextlib import AsyncExitStack
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import anyio
import anyio.to_thread

from openel_async.logs import get_logger

from ...clock import NS_PER_S, Clock, MonotonicClock, VirtualClock
from ..context import ExecutionContext, ExecutionKind, LifeCycleState
from ..errors import RTCError
from ..modes import MultiModeObject
from ..ports import ConnectorStats
from ..run_cli import PROG, duration_problem, finish_run, read_problem
from ..runner import make_context
from .build import PreparedSystem, prepare_system
from .loader import load_system
from .model import SystemFileError

__all__ = [
    "ComponentReport",
    "ConnectorReport",
    "SystemSummary",
    "run_system",
    "run_system_cli",
    "run_system_file",
]

log = get_logger(__name__)
MAX_VIRTUAL_CYCLES = 1_000_000


@dataclass(slots=True)
class ComponentReport:
    name: str
    kind: ExecutionKind
    rate_hz: float | None
    cycles: int = 0
    overruns: int = 0
    state: LifeCycleState | None = None
    mode: str | None = None
    report: dict[str, object] = field(default_factory=dict)

    def line(self) -> str:
        rate = f" {self.rate_hz:g} Hz" if self.rate_hz is not None else ""
        kind = "SPORADIC" if self.kind is ExecutionKind.OTHER else str(self.kind)
        mode = f", mode {self.mode}" if self.mode is not None else ""
        extra = "".join(f", {k} {v}" for k, v in self.report.items())
        return (
            f"{self.name:<14} {kind}{rate}: {self.cycles} cycles ({self.overruns} overruns), "
            f"{self.state}{mode}{extra}"
        )


@dataclass(slots=True)
class ConnectorReport:
    name: str
    kind: str
    stats: ConnectorStats

    @property
    def lost(self) -> int:
        s = self.stats
        return s.overwritten + s.refused + s.timeouts + s.skipped

    def line(self) -> str:
        s = self.stats
        return (
            f"{self.name} [{self.kind}]: written {s.written}, received {s.received}, read "
            f"{s.read}, lost {self.lost} (overwritten {s.overwritten}, refused {s.refused}, "
            f"timeouts {s.timeouts}, skipped {s.skipped})"
        )


@dataclass(slots=True)
class SystemSummary:
    system: str
    duration_s: float = 0.0
    components: list[ComponentReport] = field(default_factory=list)
    connectors: list[ConnectorReport] = field(default_factory=list)
    stopped_by: str | None = None

    def lines(self) -> list[str]:
        out = [f"system             {self.system}", f"duration           {self.duration_s:.3f} s"]
        out += ["components"] + ["  " + c.line() for c in self.components]
        if self.connectors:
            out += ["connections"] + ["  " + c.line() for c in self.connectors]
        if self.stopped_by is not None:
            out.append(f"stopped by         {self.stopped_by}")
        return out


def _status(prepared: PreparedSystem, contexts: list[ExecutionContext], t_s: float) -> str:
    parts = [f"t={t_s:8.2f} s"]
    for pc, ec in zip(prepared.components, contexts, strict=True):
        rtc = pc.rtc
        state = ec.get_component_state(rtc) if rtc in ec.participants else "-"
        parts.append(f"{pc.spec.name} {state} {ec.stats.cycles}")
    if prepared.connectors:
        stats = [c.stats for c in prepared.connectors]
        delivered = sum(s.received for s in stats)
        lost = sum(s.overwritten + s.refused + s.timeouts + s.skipped for s in stats)
        parts.append(f"data {delivered} delivered, {lost} lost")
    return " | ".join(parts)


async def run_system(
    prepared: PreparedSystem,
    *,
    clock: Clock,
    duration_s: float | None = None,
    handle_signals: bool = True,
    live_interval_s: float | None = None,
    on_live: Callable[[str], None] | None = None,
) -> SystemSummary:
    """Run a prepared system (see the module docstring); raises RTCError (or an
    ExceptionGroup of them) when a lifecycle step fails, after every component exited."""
    if duration_s is not None and not (math.isfinite(duration_s) and duration_s > 0):
        raise ValueError(f"duration_s={duration_s!r}: expected a finite number of seconds > 0")
    if duration_s is None and not handle_signals:
        raise ValueError("a run without duration_s needs handle_signals to end")
    summary = SystemSummary(prepared.spec.name)
    contexts = [
        make_context(pc.execution, owner=pc.rtc, clock=clock, name=f"{pc.spec.name}.ec0")
        for pc in prepared.components
    ]
    initialized = []
    errors: list[BaseException] = []
    start = clock.now_ns()
    async with AsyncExitStack() as stack:
        for ec in contexts:
            await stack.enter_async_context(ec)
        for connector in prepared.connectors:
            await stack.enter_async_context(connector)
        try:
            for pc in prepared.components:
                await pc.rtc.initialize()
                initialized.append(pc)
            for pc, ec in zip(prepared.components, contexts, strict=True):
                await ec.add_component(pc.rtc)
            for ec in contexts:
                await ec.start()
            for pc, ec in zip(prepared.components, contexts, strict=True):
                await ec.activate_component(pc.rtc)
            log.info("system_running", system=summary.system, components=len(contexts))
            await _wait(
                clock,
                start,
                duration_s,
                handle_signals,
                summary,
                live_interval_s,
                partial(_status, prepared, contexts),
                on_live,
            )
        finally:
            summary.duration_s = (clock.now_ns() - start) / NS_PER_S
            for pc, ec in zip(prepared.components, contexts, strict=True):
                report = ComponentReport(pc.spec.name, pc.execution.kind, pc.execution.rate_hz)
                if pc.rtc in ec.participants:
                    report.state = ec.get_component_state(pc.rtc)
                summary.components.append(report)
            for pc in reversed(initialized):
                try:
                    await pc.rtc.exit()
                except RTCError as exc:
                    log.warning("system_exit_failed", rtc=pc.spec.name, error=str(exc))
                    errors.append(exc)
    for report, pc, ec in zip(summary.components, prepared.components, contexts, strict=True):
        report.cycles, report.overruns = ec.stats.cycles, ec.stats.overruns
        if isinstance(pc.rtc, MultiModeObject):
            report.mode = pc.rtc.get_current_mode()
        report.report = pc.rtc.report()
    for connector in prepared.connectors:
        p = connector.profile
        kind = p.dataflow.value + ("" if p.dataflow.value == "pull" else "/" + p.subscription.value)
        name = f"{connector.info.out_port} -> {connector.info.in_port}"
        summary.connectors.append(ConnectorReport(name, kind, connector.stats))
    if errors:
        raise errors[0]
    log.info("system_finished", system=summary.system, duration_s=summary.duration_s)
    return summary


async def _wait(
    clock: Clock,
    start_ns: int,
    duration_s: float | None,
    handle_signals: bool,
    summary: SystemSummary,
    live_interval_s: float | None,
    status: Callable[[float], str],
    on_live: Callable[[str], None] | None,
) -> None:
    with anyio.CancelScope() as waiting:

        async def until_signal() -> None:
            with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
                async for signum in signals:
                    summary.stopped_by = signal.Signals(signum).name
                    waiting.cancel()
                    return

        async def until_end(end_ns: int) -> None:
            await clock.sleep_until(end_ns)
            waiting.cancel()

        async def live(interval_ns: int) -> None:
            assert on_live is not None
            deadline = start_ns + interval_ns
            while True:
                await clock.sleep_until(deadline)
                on_live(status((clock.now_ns() - start_ns) / NS_PER_S))
                deadline += interval_ns

        async with anyio.create_task_group() as tg:
            if handle_signals:
                tg.start_soon(until_signal)
            if duration_s is not None:
                tg.start_soon(until_end, start_ns + round(duration_s * NS_PER_S))
            if live_interval_s and on_live is not None:
                tg.start_soon(live, max(1, round(live_interval_s * NS_PER_S)))


async def run_system_file(
    path: Path,
    *,
    clock: Clock | None = None,
    duration_s: float | None = None,
    handle_signals: bool = True,
    live_interval_s: float | None = None,
    on_live: Callable[[str], None] | None = None,
) -> SystemSummary:
    """Load, check and run a system file (SystemFileError before anything starts)."""
    clock = clock or MonotonicClock()
    # reading the file (and, for rtsys, the schema on first use) blocks: not in the loop
    spec = await anyio.to_thread.run_sync(load_system, path)
    prepared = prepare_system(spec, clock=clock)
    return await run_system(
        prepared,
        clock=clock,
        duration_s=duration_s,
        handle_signals=handle_signals,
        live_interval_s=live_interval_s,
        on_live=on_live,
    )


def run_system_cli(path: Path, argv: Sequence[str]) -> int:
    """``openel-async run SYSTEM.yaml [--duration S] [--virtual] [--live S]``.

    Exit status: 0 after a clean run, 1 when a lifecycle step failed, 2 for a bad
    system file or command line, 130 / 143 after SIGINT / SIGTERM."""
    prog = PROG
    parser = argparse.ArgumentParser(
        prog=f"{prog} SYSTEM",
        description="Run a system of RT components (a system YAML or an RTSystemEditor rtsys "
        "XML): each component in its context, ports connected, a live status line. This "
        "imports and executes the modules its profiles name: run only files you trust.",
    )
    parser.add_argument("--duration", type=float, help="seconds to run (default: until Ctrl-C)")
    parser.add_argument("--virtual", action="store_true", help="virtual clock (needs --duration)")
    parser.add_argument(
        "--live", type=float, default=1.0, help="seconds between status lines (0: none)"
    )
    try:
        args = parser.parse_args(list(argv))
    except SystemExit as exc:
        return 0 if exc.code in (0, None) else 2
    problem = duration_problem(args.duration, args.virtual)
    if problem is not None:
        print(f"{prog}: {problem}", file=sys.stderr)
        return 2
    if not (math.isfinite(args.live) and args.live >= 0):
        print(f"{prog}: --live must be a number of seconds >= 0", file=sys.stderr)
        return 2
    clock: Clock = VirtualClock() if args.virtual else MonotonicClock()
    try:
        prepared = prepare_system(load_system(path), clock=clock)
    except OSError as exc:
        print(f"{prog}: {path}: {read_problem(exc)}", file=sys.stderr)
        return 2
    except SystemFileError as exc:
        # a located error starts with the file's name (and line and column) already
        print(f"{prog}: {exc if exc.location is not None else f'{path}: {exc}'}", file=sys.stderr)
        return 2
    if args.virtual:
        cycles = sum(
            (pc.execution.rate_hz or 0.0) * args.duration
            for pc in prepared.components
            if pc.execution.kind is ExecutionKind.PERIODIC
        )
        if cycles > MAX_VIRTUAL_CYCLES:
            print(
                f"{prog}: {path}: {cycles:.3g} cycles on the virtual clock; at most "
                f"{MAX_VIRTUAL_CYCLES:,} (a shorter --duration)",
                file=sys.stderr,
            )
            return 2

    def live(line: str) -> None:
        print(line, flush=True)

    async def main() -> SystemSummary:
        run = partial(
            run_system,
            prepared,
            clock=clock,
            duration_s=args.duration,
            live_interval_s=args.live or None,
            on_live=live,
        )
        if isinstance(clock, VirtualClock):
            async with clock.autojump():
                return await run()
        return await run()

    return finish_run(path, main)
