"""Start-up of the command line: ``openel-async --help``, ``devices`` and ``run NAME --help``.

What a user waits for before a command does anything: a new interpreter, its imports and
the command's own start, to its exit, timed from this process (wall time of
``python -m openel_async.cli ARGS``). The peer is the floor every Python command line pays:
the same interpreter started with ``-c pass`` (its ``site`` and the virtual environment's
``.pth`` files, nothing of ours), measured in the same rounds; python-can's own
``python -m can.logger --help`` is shown beside it, as a library command line a user of
this field already runs.

Each round runs every command once, in a rotating order (interleaved, so that the load of the
machine hits all alike); each figure is the median over the rounds. The child processes run
with bytecode caching on (``PYTHONDONTWRITEBYTECODE`` removed from their environment, as a
user's shell has it) after one warm-up run of each, so that the figures are those of every
start but the very first after an install or an edit.

What each loads: ``--help`` builds the parser of every command; a command line that names one
of the framework's own commands (``run``, ``devices``, ...) builds that command's parser alone.
The entry points (the drivers' commands, the apps, the drivers) are read from the installed
distributions' ``entry_points.txt`` without importing ``importlib.metadata``. ``run NAME
--help`` imports the app and the framework modules it uses, but neither asyncio nor ctypes
(the clocks load them at their first wait) nor yaml, msgspec, numpy, MuJoCo or rich
(``tests/cli/test_startup.py`` checks this).

Targets (issue 27): ``--help`` <= 0.25 s, ``devices`` <= 0.5 s, ``run NAME --help`` <= 0.4 s
for every shipped app.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import time

from .harness import BenchResult, Row, ratio_of

APPS = ("twoaxis", "arm2", "so101", "csp4", "pantilt")
TARGETS = {"--help": 0.25, "devices": 0.5, "run": 0.4}


def _commands() -> dict[str, list[str]]:
    cli = [sys.executable, "-m", "openel_async.cli"]
    commands = {
        "python -c pass (the floor)": [sys.executable, "-c", "pass"],
        "python -m can.logger --help": [sys.executable, "-m", "can.logger", "--help"],
        "openel-async --help": [*cli, "--help"],
        "openel-async devices": [*cli, "devices"],
    }
    for app in APPS:
        commands[f"openel-async run {app} --help"] = [*cli, "run", app, "--help"]
    return commands


def _time(argv: list[str], env: dict[str, str]) -> float:
    start = time.perf_counter()
    done = subprocess.run(argv, env=env, capture_output=True, timeout=120, check=False)
    elapsed = time.perf_counter() - start
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(argv)}: exit {done.returncode}: {done.stderr[-500:]!r}")
    return elapsed


def run(quick: bool) -> BenchResult:
    rounds = 5 if quick else 9
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["NO_COLOR"] = "1"
    commands = _commands()
    for argv in commands.values():  # warm-up: bytecode caches written
        _time(argv, env)
    times: dict[str, list[float]] = {name: [] for name in commands}
    names = list(commands)
    for r in range(rounds):
        order = names[r % len(names) :] + names[: r % len(names)]
        for name in order:
            times[name].append(_time(commands[name], env))
    median = {name: statistics.median(t) for name, t in times.items()}
    floor = median["python -c pass (the floor)"]
    rows = []
    for name, value in median.items():
        if name.startswith("python"):
            rows.append(Row(name, value * 1e3, " ms", digits=0))
            continue
        target = TARGETS["run" if " run " in name else name.split()[-1]]
        rows.append(
            Row(
                name,
                value * 1e3,
                " ms",
                floor * 1e3,
                "python -c pass",
                ratio_of(value, floor),
                "ours/floor",
                f"<= {target * 1e3:.0f} ms",
                value <= target,
                digits=0,
            )
        )
    spread = [
        f"{name}: {min(t) * 1e3:.0f}-{max(t) * 1e3:.0f} ms over the rounds"
        for name, t in times.items()
    ]
    return BenchResult(
        name="startup",
        title="command-line start-up: --help, devices, run NAME --help",
        rows=tuple(rows),
        description=(__doc__ or "").split("\n\n", 1)[1].strip(),
        notes=(
            f"Median of {rounds} interleaved round(s) after one warm-up run of each command.",
            "; ".join(spread) + ".",
        ),
        params={"rounds": str(rounds), "apps": ", ".join(APPS)},
        quick=quick,
    )
