"""What the serial benchmarks (:mod:`benchmarks.bench_serial`, :mod:`benchmarks.bench_feetech`)
share: a round of timed operations (a transaction or a control cycle) against a vendor SDK,
its statistics, the median over rounds, and the SDK's version for the report."""

from __future__ import annotations

import statistics
from collections.abc import Iterable
from dataclasses import dataclass

__all__ = ["MAX_FAILURE_SHARE", "Round", "make_round", "median_of", "package_version"]

MAX_FAILURE_SHARE = 0.01
"""More failed operations than this share of a round end the benchmark."""


@dataclass(frozen=True, slots=True)
class Round:
    median_us: float
    p99_us: float
    cpu_us: float
    """Process CPU time per operation (this process only: the bus runs in another)."""
    failures: int
    """Operations that timed out (the SDK's) or were retried (ours): a stalled peer."""


def make_round(samples_ns: list[int], cpu_ns: int, failures: int, who: str, what: str) -> Round:
    """The round's statistics (``samples_ns`` sorted in place); AssertionError naming ``who``
    when more than :data:`MAX_FAILURE_SHARE` of its ``what`` (operations) failed."""
    if failures > MAX_FAILURE_SHARE * len(samples_ns):
        raise AssertionError(f"{who}: {failures} of {len(samples_ns)} {what} failed")
    samples_ns.sort()
    p99 = samples_ns[min(len(samples_ns) - 1, round(0.99 * (len(samples_ns) - 1)))]
    return Round(
        statistics.median(samples_ns) / 1e3, p99 / 1e3, cpu_ns / len(samples_ns) / 1e3, failures
    )


def median_of(rounds: Iterable[Round], field: str) -> float:
    """The median over ``rounds`` of one of their fields."""
    return float(statistics.median(float(getattr(r, field)) for r in rounds))


def package_version(distribution: str) -> str:
    from importlib import metadata

    try:
        return metadata.version(distribution)
    except metadata.PackageNotFoundError:
        return "(version unknown)"
