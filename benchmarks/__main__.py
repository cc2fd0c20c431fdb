"""Command line: run benchmarks, print their tables, optionally rewrite docs/benchmarks.md."""

from __future__ import annotations

import argparse
import cProfile
import gc
import pstats
import sys
import time
import traceback
from collections.abc import Sequence
from dataclasses import replace

from . import available, load
from .harness import (
    COMMAND,
    DOC_PATH,
    BenchResult,
    format_text,
    machine_info,
    quiet_logging,
    summary_line,
    write_document,
)

PROFILE_TOP = 25


def main(argv: Sequence[str] | None = None) -> int:
    names = available()
    parser = argparse.ArgumentParser(
        prog=COMMAND.removeprefix("uv run "),
        description="Run the openel-async benchmarks (each against a baseline measured "
        "in the same run). Exit status 1 when a benchmark fails with an error, and with "
        "--check also when a row misses its target.",
    )
    parser.add_argument(
        "names", nargs="*", metavar="NAME", help=f"benchmarks to run (default: all of {names})"
    )
    parser.add_argument("--quick", action="store_true", help="shorter runs, for a smoke test")
    parser.add_argument(
        "--write-docs",
        action="store_true",
        help=f"rewrite the sections of the benchmarks run in {DOC_PATH.name}",
    )
    parser.add_argument(
        "--profile",
        action="store_true",
        help="run under cProfile and print the top functions (inflates the figures; "
        "not allowed with --write-docs)",
    )
    parser.add_argument(
        "--check",
        action="store_true",
        help="exit with status 1 when any row misses its target (each row: the median of "
        "at least 5 interleaved rounds), listing the rows missed: for CI and regressions",
    )
    parser.add_argument("--list", action="store_true", help="list the benchmarks and exit")
    args = parser.parse_args(argv)
    if args.list:
        print("\n".join(names))
        return 0
    unknown = [n for n in args.names if n not in names]
    if unknown:
        parser.error(f"unknown benchmark(s) {unknown}; choose from {names}")
    if args.profile and args.write_docs:
        parser.error("--profile inflates the figures: it cannot be combined with --write-docs")
    selected = list(dict.fromkeys(args.names)) or names

    quiet_logging()
    results: list[BenchResult] = []
    for name in selected:
        module = load(name)
        gc.collect()
        machine = machine_info()  # load average as the benchmark starts
        started = time.perf_counter()
        profiler = cProfile.Profile() if args.profile else None
        try:
            if profiler is not None:
                result = profiler.runcall(module.run, args.quick)
            else:
                result = module.run(args.quick)
        except Exception as exc:  # one broken benchmark must not hide the others
            traceback.print_exc()
            result = BenchResult(name=name, title="", rows=(), error=f"{type(exc).__name__}: {exc}")
        result = replace(result, machine=machine, quick=args.quick)
        print(format_text(result), end="", flush=True)
        print(f"   ({time.perf_counter() - started:.1f} s)\n", flush=True)
        results.append(result)
        if profiler is not None:
            stats = pstats.Stats(profiler, stream=sys.stdout)
            stats.sort_stats("tottime").print_stats(PROFILE_TOP)

    print(summary_line(results))
    if args.write_docs:
        written = write_document(results)
        print(f"wrote sections {written} of {DOC_PATH}")
    if any(r.error is not None for r in results):
        return 1
    if not args.check:
        return 0
    missed = [(r.name, row) for r in results if r.skipped is None for row in r.failures]
    for name, row in missed:
        print(f"target missed: {name}: {row.metric}: {row.target}")
    return 1 if missed else 0


if __name__ == "__main__":
    sys.exit(main())
