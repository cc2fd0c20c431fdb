"""The benchmark harness: typed results, text and Markdown tables, machine info, doc sections.

A benchmark is a module ``benchmarks/bench_<name>.py`` with a ``run(quick: bool) ->
BenchResult`` function. Every benchmark measures its own baseline in the same process
and the same run, so the ratios stay meaningful on a noisy machine even when the
absolute figures move.

``docs/benchmarks.md`` is made of sections delimited by HTML comments::

    <!-- bench:timer -->
    ...
    <!-- /bench:timer -->

Writing the doc replaces only the sections of the benchmarks that ran (new ones are
appended) and keeps every other byte of the file, so benchmarks owned by other
modules (MuJoCo, CAN, serial, RTC) keep their figures until they are run again.
"""

from __future__ import annotations

import datetime as dt
import gc
import os
import platform
import re
import subprocess
import sys
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path
from typing import TypeVar

T = TypeVar("T")

REPO_ROOT = Path(__file__).resolve().parent.parent
DOC_PATH = REPO_ROOT / "docs" / "benchmarks.md"
COMMAND = "uv run python -m benchmarks"


# -- measuring -------------------------------------------------------------------------


def interleaved(rounds: int, cases: Mapping[str, Callable[[], T]]) -> dict[str, list[T]]:
    """Each case's results over ``rounds`` rounds; every round runs the cases in order,
    each after a ``gc.collect()``, so load changes on the machine hit every case alike."""
    out: dict[str, list[T]] = {name: [] for name in cases}
    for _ in range(rounds):
        for name, case in cases.items():
            gc.collect()
            out[name].append(case())
    return out


MIN_ROUNDS = 5
"""Rounds every row's figure is the median of (issue 27): a target counts as met when the
median of at least this many interleaved rounds meets it, in each of two separate runs."""


def median(values: Sequence[float]) -> float:
    """The median of per-round figures (the mean of the middle two for an even count)."""
    if not values:
        raise ValueError("median of no rounds")
    ordered = sorted(values)
    mid = len(ordered) // 2
    if len(ordered) % 2:
        return float(ordered[mid])
    return (ordered[mid - 1] + ordered[mid]) / 2


# -- results ---------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Row:
    """One measured figure, its baseline (if any), their ratio and the target."""

    metric: str
    value: float
    unit: str = ""
    baseline: float | None = None
    baseline_label: str = ""
    """Which baseline ``baseline`` comes from, e.g. ``"naive sleep loop"``."""
    ratio: float | None = None
    ratio_label: str = ""
    """How ``ratio`` is formed, e.g. ``"naive/ours"`` (> 1: ours is better)."""
    target: str = ""
    passed: bool | None = None
    """None: informational figure without a target."""
    digits: int = 1


def ratio_of(numerator: float, denominator: float) -> float:
    """numerator / denominator, infinite when only the denominator is zero."""
    if denominator == 0:
        return float("inf") if numerator else 1.0
    return numerator / denominator


@dataclass(frozen=True, slots=True)
class MachineInfo:
    cpu_model: str
    cores: int
    usable_cores: int
    python: str
    platform: str
    anyio: str
    date: str
    commit: str
    load_average: tuple[float, float, float] | None

    def markdown_lines(self) -> list[str]:
        load = (
            " / ".join(f"{x:.2f}" for x in self.load_average)
            if self.load_average is not None
            else "n/a"
        )
        return [
            f"- CPU: {self.cpu_model}, {self.cores} cores ({self.usable_cores} usable)",
            f"- Python {self.python}, anyio {self.anyio}, {self.platform}",
            f"- Date: {self.date}; commit {self.commit}",
            f"- Load average when the benchmark started (1/5/15 min): {load}",
        ]


@dataclass(frozen=True, slots=True)
class BenchResult:
    name: str
    title: str
    rows: tuple[Row, ...]
    description: str = ""
    """Markdown: what is measured, against which baseline, and how."""
    notes: tuple[str, ...] = ()
    """Observations of this run (Markdown, one bullet each)."""
    params: Mapping[str, str] = field(default_factory=dict)
    quick: bool = False
    skipped: str | None = None
    """Why the benchmark could not run here (no hardware, missing package)."""
    error: str | None = None
    """The exception that ended the run (a failed check such as a lost notification)."""
    machine: MachineInfo | None = None

    @property
    def passed(self) -> bool:
        return (
            self.skipped is None
            and self.error is None
            and all(r.passed is not False for r in self.rows)
        )

    @property
    def failures(self) -> tuple[Row, ...]:
        return tuple(r for r in self.rows if r.passed is False)


# -- machine info ----------------------------------------------------------------------


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


def _commit() -> str:
    try:
        head = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            cwd=REPO_ROOT,
            capture_output=True,
            text=True,
            check=True,
            timeout=5,
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=REPO_ROOT,
            capture_output=True,
            text=True,
            check=True,
            timeout=5,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return f"{head} (with uncommitted changes)" if dirty else head


def machine_info() -> MachineInfo:
    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:
        usable = os.cpu_count() or 1
    try:
        load: tuple[float, float, float] | None = os.getloadavg()
    except OSError:
        load = None
    return MachineInfo(
        cpu_model=_cpu_model(),
        cores=os.cpu_count() or 1,
        usable_cores=usable,
        python=f"{platform.python_implementation()} {platform.python_version()}",
        platform=f"{platform.system()} {platform.release()} {platform.machine()}",
        anyio=metadata.version("anyio"),
        date=dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        commit=_commit(),
        load_average=load,
    )


# -- formatting ------------------------------------------------------------------------


def _num(value: float, digits: int) -> str:
    if value != value:  # NaN
        return "nan"
    if value in (float("inf"), float("-inf")):
        return "inf" if value > 0 else "-inf"
    if digits == 0 or abs(value) >= 10_000:
        return f"{value:,.0f}"
    return f"{value:.{digits}f}"


def _cells(row: Row) -> list[str]:
    unit = f" {row.unit}" if row.unit else ""
    value = f"{_num(row.value, row.digits)}{unit}"
    if row.baseline is None:
        baseline = "-"
    else:
        label = f" ({row.baseline_label})" if row.baseline_label else ""
        baseline = f"{_num(row.baseline, row.digits)}{unit}{label}"
    if row.ratio is None:
        ratio = "-"
    else:
        label = f" {row.ratio_label}" if row.ratio_label else ""
        digits = 2 if abs(row.ratio) < 10 else 1 if abs(row.ratio) < 100 else 0
        ratio = f"{_num(row.ratio, digits)}x{label}"
    verdict = "-" if row.passed is None else ("PASS" if row.passed else "FAIL")
    return [row.metric, value, baseline, ratio, row.target or "-", verdict]


HEADERS = ["metric", "value", "baseline", "ratio", "target", "result"]


def format_text(result: BenchResult) -> str:
    """The plain-text table printed on the terminal."""
    title = f"== {result.name}: {result.title}" + (" [quick]" if result.quick else "")
    if result.skipped is not None:
        return f"{title}\n   SKIPPED: {result.skipped}\n"
    if result.error is not None:
        return f"{title}\n   ERROR: {result.error}\n   => FAIL\n"
    table = [HEADERS, *(_cells(r) for r in result.rows)]
    widths = [max(len(line[i]) for line in table) for i in range(len(HEADERS))]
    lines = [title]
    if result.params:
        lines.append("   " + ", ".join(f"{k}={v}" for k, v in result.params.items()))
    for i, line in enumerate(table):
        lines.append("   " + "  ".join(cell.ljust(w) for cell, w in zip(line, widths, strict=True)))
        if i == 0:
            lines.append("   " + "  ".join("-" * w for w in widths))
    lines.extend(f"   * {_plain(note)}" for note in result.notes)
    verdict = "PASS" if result.passed else "FAIL"
    lines.append(f"   => {verdict}")
    return "\n".join(lines) + "\n"


def _plain(markdown: str) -> str:
    return markdown.replace("`", "").replace("**", "")


def _md_cell(text: str) -> str:
    return text.replace("|", "\\|")


def command_for(name: str, quick: bool) -> str:
    return f"{COMMAND} {name}" + (" --quick" if quick else "")


def format_markdown(result: BenchResult) -> str:
    """The body of the benchmark's section in docs/benchmarks.md (without the markers)."""
    out = [f"## {result.name}: {result.title}", ""]
    if result.description:
        out += [result.description.strip(), ""]
    out += [f"Reproduce: `{command_for(result.name, result.quick)}`", ""]
    if result.quick:
        out += ["*Quick run (shorter durations): figures are indicative only.*", ""]
    if result.params:
        out += ["Parameters: " + ", ".join(f"{k} = {v}" for k, v in result.params.items()), ""]
    if result.skipped is not None:
        out += [f"**Skipped:** {result.skipped}", ""]
    else:
        out.append("| " + " | ".join(HEADERS) + " |")
        out.append("|" + "|".join("---" for _ in HEADERS) + "|")
        for row in result.rows:
            cells = _cells(row)
            if row.passed is not None:
                cells[-1] = f"**{cells[-1]}**"
            out.append("| " + " | ".join(_md_cell(c) for c in cells) + " |")
        out.append("")
        verdict = "all targets met" if result.passed else "**target missed**"
        out += [f"Result: {verdict}.", ""]
    if result.notes:
        out += [f"- {note}" for note in result.notes]
        out.append("")
    if result.machine is not None:
        out += ["Measured on:", "", *result.machine.markdown_lines(), ""]
    return "\n".join(out)


# -- the document ----------------------------------------------------------------------

_SECTION = re.compile(
    r"<!-- bench:(?P<name>[\w.-]+) -->\n.*?<!-- /bench:(?P=name) -->\n?",
    re.DOTALL,
)

PREAMBLE = f"""# Benchmarks

Generated by `{COMMAND} --write-docs` (all benchmarks) or
`{COMMAND} NAME... --write-docs` (only those; the other sections are kept as they are).
`{COMMAND} --list` lists the benchmarks; `--quick` shortens every run;
`--check` exits with status 1 when any row misses its target (or a benchmark fails), so
that a regression shows in CI. A row with a target is the median of at least
{MIN_ROUNDS} interleaved rounds of ours and its peer; a target is met when that median
meets it in each of two separate runs: each section written by the harness
ends with the run it replaced ("The previous run"), its verdicts and the targets met in both.

Every benchmark measures its baseline in the same process and run as the framework
figure and reports their ratio: absolute numbers move with the machine and its load
(see "Measured on" under each section), the ratios much less so. Each section is
delimited by `<!-- bench:NAME -->` ... `<!-- /bench:NAME -->` comments and owned by
the module `benchmarks/bench_NAME.py`; do not edit inside the markers by hand.

"""


def section(name: str, body: str) -> str:
    return f"<!-- bench:{name} -->\n{body.rstrip()}\n<!-- /bench:{name} -->\n"


def section_names(text: str) -> list[str]:
    return [m.group("name") for m in _SECTION.finditer(text)]


def update_document(text: str | None, sections: Mapping[str, str]) -> str:
    """Replace the named sections of ``text`` in place; append those not yet present.

    ``sections`` maps a benchmark name to its Markdown body. Everything outside the
    replaced sections is kept byte for byte; a missing document starts with PREAMBLE.
    """
    doc = PREAMBLE if text is None else text
    pending = dict(sections)

    def replace(match: re.Match[str]) -> str:
        name = match.group("name")
        if name in pending:
            return section(name, pending.pop(name))
        return match.group(0)

    doc = _SECTION.sub(replace, doc)
    for name, body in pending.items():
        if not doc.endswith("\n\n"):
            doc = doc.rstrip("\n") + "\n\n"
        doc += section(name, body)
    return doc


PREVIOUS_RUN = "**The previous run** of this benchmark"


def _table_rows(body: str) -> list[list[str]]:
    """The cells of the first table of a section body (this run's, not the previous one's)."""
    body = body.split(PREVIOUS_RUN, 1)[0]
    rows: list[list[str]] = []
    for line in body.splitlines():
        if line.startswith("| ") and not line.startswith("| metric |"):
            cells = re.split(r"(?<!\\)\|", line.strip().strip("|"))
            rows.append([c.strip().replace("\\|", "|") for c in cells])
        elif rows:
            break
    return rows


def previous_run(old_body: str, new_result: BenchResult) -> list[str]:
    """Markdown lines recording the run a new one replaces: its verdicts, date, commit and
    load, and which rows met their target in both runs (the rule of the preamble).

    Nothing when the old run was a quick one, skipped, or this one is quick."""
    if new_result.quick or "*Quick run" in old_body or "**Skipped:**" in old_body:
        return []
    before = old_body.split(PREVIOUS_RUN, 1)[0]
    judged = [r for r in _table_rows(before) if len(r) == 6 and r[5].strip("*") in ("PASS", "FAIL")]
    if not judged:
        return []
    when = re.search(r"^- Date: (.*)$", before, re.MULTILINE)
    load = re.search(
        r"^- Load average when the benchmark started \(1/5/15 min\): (.*)$", before, re.MULTILINE
    )
    stamp = when.group(1) if when else "date unknown"
    stamp += f"; load average {load.group(1)}" if load else ""
    out = [
        f"{PREVIOUS_RUN} ({stamp}):",
        "",
        "| metric | value | ratio | result |",
        "|---|---|---|---|",
    ]
    out += ["| " + " | ".join(_md_cell(r[i]) for i in (0, 1, 3, 5)) + " |" for r in judged]
    old = {r[0]: r[5].strip("*") == "PASS" for r in judged}
    both = [row.metric for row in new_result.rows if row.passed and old.get(row.metric)]
    either = [
        row.metric
        for row in new_result.rows
        if row.passed is not None and row.metric in old and not (row.passed and old[row.metric])
    ]
    out += ["", f"Targets met in both runs: {len(both)} of {len(both) + len(either)}."]
    if either:
        out[-1] += " Missed in one run or both: " + "; ".join(either) + "."
    return [*out, ""]


def write_document(results: Iterable[BenchResult], path: Path = DOC_PATH) -> list[str]:
    """Write the sections of ``results`` that ran to the end (skipped or failed with an
    error: the section keeps its previous figures). Each new section records the run it
    replaces (``previous_run``), so that two runs in a row leave both in the document."""
    done = [r for r in results if r.skipped is None and r.error is None]
    if not done:
        return []
    text = path.read_text(encoding="utf-8") if path.exists() else None
    old = {m.group("name"): m.group(0) for m in _SECTION.finditer(text or "")}
    sections = {}
    for r in done:
        body = format_markdown(r)
        carried = previous_run(old.get(r.name, ""), r)
        sections[r.name] = body.rstrip() + ("\n\n" + "\n".join(carried) if carried else "")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(update_document(text, sections), encoding="utf-8")
    return list(sections)


def summary_line(results: Sequence[BenchResult]) -> str:
    parts = []
    for r in results:
        if r.skipped is not None:
            verdict = "SKIP"
        elif r.error is not None:
            verdict = "ERROR"
        else:
            verdict = "PASS" if r.passed else "FAIL"
        parts.append(f"{r.name}: {verdict}")
    return "summary: " + ", ".join(parts)


def quiet_logging() -> None:
    """Route framework logs (structlog) to stderr and drop those below WARNING.

    The framework logs nothing per tick or per call on the paths measured here, so this
    only keeps the tables readable; warnings (missed ticks, queue overflow) still show.
    """
    import logging

    import structlog

    structlog.configure(
        wrapper_class=structlog.make_filtering_bound_logger(logging.WARNING),
        logger_factory=structlog.PrintLoggerFactory(sys.stderr),
    )
