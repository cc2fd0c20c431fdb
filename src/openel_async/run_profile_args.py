"""The command line of ``openel-async run PROFILE`` (and of a profile app such as ``run
pantilt``): its parser and the bounds its help states, outside the ``rtc`` package, so that
``--help`` and a mistaken option are answered without loading the RTC machinery (the
profile loaders, yaml, msgspec): the runner parses with the same parser."""

from __future__ import annotations

import argparse
from collections.abc import Sequence

__all__ = [
    "CLI_MAX_VIRTUAL_CYCLES",
    "MAX_RATE_HZ",
    "MIN_RATE_HZ",
    "parse_profile_run_args",
    "profile_run_parser",
]

MAX_RATE_HZ = 10_000.0
"""The fastest periodic context: a 100 us period.  A cycle costs the context some
microseconds of bookkeeping plus the participants' callbacks, so faster rates could
only overrun on a real clock, and on a virtual clock they turn seconds of simulated
time into minutes of CPU."""
MIN_RATE_HZ = 1e-6
"""The slowest periodic context (a period of about 11.6 days)."""
CLI_MAX_VIRTUAL_CYCLES = 1_000_000
"""``openel-async run --virtual``: most cycles (rate x duration), about a minute of CPU."""


def profile_run_parser() -> argparse.ArgumentParser:
    """The parser of ``openel-async run PROFILE [options]``."""
    parser = argparse.ArgumentParser(
        prog="openel-async run PROFILE",
        description="Run the RT component an RTC Profile (.yaml/.yml/.xml) describes. This "
        "imports and executes the Python module the profile names (its 'implementation' "
        "parameter: a module next to the profile or an installed one): run only profiles "
        "you trust. Ctrl-C (SIGINT) ends the run with exit status 130, SIGTERM with 143, "
        "after the summary. A component whose execution type is ExtTrigExecutionContext "
        "runs one cycle per tick: --ticks/--tick-rate, else one per line of standard input "
        "(Enter: one tick, a number N: N ticks, end of input (Ctrl-D): the end of the run).",
    )
    parser.add_argument("--duration", type=float, help="seconds to run (default: until Ctrl-C)")
    clock = parser.add_mutually_exclusive_group()
    clock.add_argument(
        "--virtual",
        action="store_true",
        help="run on the virtual clock (simulated time, as fast as possible; needs --duration, "
        "or --ticks for an ExtTrigExecutionContext)",
    )
    clock.add_argument(
        "--realtime",
        action="store_true",
        help="run on the real monotonic clock (the default), as every app does",
    )
    parser.add_argument(
        "--rate",
        type=float,
        help=f"rate in Hz of a periodic context ({MIN_RATE_HZ:g} to {MAX_RATE_HZ:g}; with "
        f"--virtual, rate x duration at most {CLI_MAX_VIRTUAL_CYCLES:,} cycles)",
    )
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="configuration value (repeatable); checked against the parameter's constraint",
    )
    parser.add_argument("--name", help="instance name (default: basicInfo.name)")
    parser.add_argument(
        "--ticks",
        type=int,
        metavar="N",
        help="ExtTrigExecutionContext: tick N times (each after the previous cycle), then end "
        f"the run (at most {CLI_MAX_VIRTUAL_CYCLES:,})",
    )
    parser.add_argument(
        "--tick-rate",
        type=float,
        metavar="HZ",
        help="ExtTrigExecutionContext: tick HZ times a second (with --ticks N: N times; "
        "else until --duration or Ctrl-C) instead of back to back",
    )
    return parser


def parse_profile_run_args(argv: Sequence[str]) -> argparse.Namespace:
    """``argv`` parsed (argparse's SystemExit for ``--help`` or a mistake)."""
    return profile_run_parser().parse_args(list(argv))
