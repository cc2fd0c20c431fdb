"""The ``openel-async`` command line."""

from __future__ import annotations

import argparse
import importlib
import math
import signal
import sys
from collections.abc import Sequence
from functools import partial
from typing import TYPE_CHECKING

import anyio
import structlog

from .interrupt import EXIT_SIGINT, install_sigterm_handler, interrupt_code
from .logs import LEVELS, configure_logging

if TYPE_CHECKING:
    from .demo_sim import RigFactory
    from .interrupt import Interrupted

MUJOCO_APPS = {"arm2": "arm2_square", "arm6": "arm6_pick_place"}
"""``demo --app``: the arm apps of ``--bus mujoco`` (modules of this package)."""
DEMO_DURATION_S = 5.0
"""Default ``demo --duration``: of the two-axis demo, and of a lap of the square."""
DEMO_PERIOD_MS = 10.0
"""Default ``demo --period-ms`` of the two-axis demo (``--bus sim`` or ``can``)."""
DEMO_MIN_PERIOD_MS = 0.1
DEMO_MAX_PERIOD_MS = 1000.0
"""``--period-ms`` range of the two-axis demo: its EventTimer ticks at most at 10 kHz."""
DEMO_MAX_VIRTUAL_TICKS = 1_000_000
"""Most timer ticks of a two-axis demo on the virtual clock (``--duration`` x 1000 /
``--period-ms``): about a minute of CPU."""


def _build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="openel-async", description=__doc__)
    parser.add_argument("--log-format", choices=("console", "json"), default="console")
    parser.add_argument("--log-level", choices=LEVELS, default="info")
    sub = parser.add_subparsers(dest="command", required=True)

    demo = sub.add_parser(
        "demo",
        help="run the demo: the MuJoCo arm traces a square (default), the 6-DoF arm picks and "
        "places a box (--app arm6), or the two-axis synchronized demo of spec Figs. 7.5-7.8 "
        "(--bus sim or can)",
        description="Every option is checked before anything runs (exit status 2). Ctrl-C "
        "(SIGINT) stops the demo with exit status 130, SIGTERM with 143, after a summary; "
        "the PNG files are then complete or absent.",
    )
    demo.add_argument(
        "--app",
        choices=tuple(MUJOCO_APPS),
        default=None,
        help="mujoco: the arm app, arm2 (the 2-DoF arm traces a square; default) or arm6 (the "
        "6-DoF arm picks and places a box with its suction cup)",
    )
    demo.add_argument(
        "--duration",
        type=float,
        default=None,
        help="seconds of synchronized motion (default 5; mujoco: seconds per lap of the square, "
        "default 5; arm6: seconds of arm motion, default 8; mujoco: at most 600)",
    )
    demo.add_argument(
        "--period-ms",
        type=float,
        default=None,
        help="EventTimer period, ms (default: 10, from 0.1 to 1000; mujoco: 2, a whole "
        "number of ms from 1 to 100)",
    )
    demo.add_argument(
        "--virtual",
        action="store_true",
        help="run on the virtual clock (instant); mujoco: lockstep pacing",
    )
    demo.add_argument(
        "--inject-fault", action="store_true", help="trip a drive halfway and recover (sim, can)"
    )
    demo.add_argument("--no-live", action="store_true", help="no live progress line")
    demo.add_argument(
        "--out", metavar="DIR", default=None, help="mujoco: directory for the PNG files, "
        "created if needed (default: out/<app>/ under the current directory, e.g. "
        "out/arm2_square/)",
    )  # fmt: skip

    demo.add_argument(
        "--bus",
        choices=("mujoco", "sim", "can"),
        default="mujoco",
        help="device layer: mujoco (the MuJoCo arm; falls back to sim when MuJoCo cannot "
        "load), sim (openel_sim motors) or can (simulated CAN drives)",
    )

    run = sub.add_parser(
        "run",
        help="run an app (apps/<name>.py) or an RTC Profile (.yaml/.xml); this executes the "
        "app's Python code, or the module the profile's 'implementation' names",
        description="Run a Python app (async def main(argv)) or the RT component an RTC "
        "Profile describes. Both EXECUTE Python code: the app file, or the module the "
        "profile's 'implementation' parameter names (next to the profile, or installed); run "
        "only what you trust. Ctrl-C (SIGINT) stops the run with exit status 130, SIGTERM "
        "with 143, after a summary. 'openel-async run PROFILE --help' lists a profile's "
        "options.",
    )
    run.add_argument("path", help="application file or directory, or RTC Profile")
    run.add_argument("app_args", nargs=argparse.REMAINDER, help="arguments for the application")

    devices = sub.add_parser("devices", help="list the registered drivers and their devices")
    devices.add_argument(
        "--profile",
        action="store_true",
        help="print every device's characteristics profile (kind, commands with ids, "
        "parameters with units) as JSON",
    )
    from .profile_cmd import add_parser as add_profile_parser

    add_profile_parser(sub)
    from .hal4rt_cmd import add_parser as add_hal4rt_parser
    from .serve_cmd import add_parser as add_serve_parser

    add_serve_parser(sub)
    add_hal4rt_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run a command; returns its exit status.

    SIGINT (Ctrl-C) ends any command with status 130 and SIGTERM with 143, without a
    traceback: the long-running commands stop their work, print a summary and leave their
    output files complete or absent (:mod:`.interrupt`); elsewhere the signal unwinds the
    command like an exception."""
    previous_sigterm = signal.getsignal(signal.SIGTERM)
    install_sigterm_handler()
    try:
        return _main(argv)
    except BaseException as exc:
        code = interrupt_code(exc)
        if code is None:
            raise
        name = "SIGINT" if code == EXIT_SIGINT else "SIGTERM"
        print(f"\nopenel-async: interrupted by {name}", file=sys.stderr)
        return code
    finally:
        signal.signal(signal.SIGTERM, previous_sigterm)


def _main(argv: Sequence[str] | None) -> int:
    args = _build_parser().parse_args(argv)
    configure_logging(args.log_format, args.log_level)
    if args.command == "devices":
        if args.profile:
            from .devices_cmd import print_profiles

            return print_profiles()
        return _devices()
    if args.command == "demo":
        return _demo(args)
    if args.command == "run":
        from .run_cmd import run

        return run(args.path, list(args.app_args))
    if args.command == "profile":
        from .profile_cmd import run as run_profile_cmd

        return run_profile_cmd(args)
    if args.command in ("serve", "hal4rt"):
        module = importlib.import_module(f"{__name__}.{args.command}_cmd")
        code: int = module.run(args)
        return code
    return 2


def _devices() -> int:
    from ..registry import discover_drivers

    for entry in discover_drivers():
        if entry.info is None:
            print(f"{entry.name:10} ({entry.value})  unavailable: {entry.error}")
            continue
        print(f"{entry.name:10} {entry.info.description}")
        width = max((len(name) for name in entry.info.devices), default=0) + 2
        for device_name, cls in entry.info.devices.items():
            print(f"  {device_name:{width}}{cls.__module__}.{cls.__qualname__}")
    return 0


def _check_demo(args: argparse.Namespace) -> str | None:
    """Every ``demo`` option, before anything runs: the problem, or None."""
    from .arm_demo import check_duration, check_out_dir, check_period_ms, output_dir

    if args.app is not None and args.bus != "mujoco":
        return "--app needs --bus mujoco (the arm apps run on MuJoCo)"
    if args.bus == "mujoco":
        if args.inject_fault:
            return "--inject-fault needs --bus sim or --bus can"
        try:
            if args.duration is not None:
                check_duration(args.duration)
            if args.period_ms is not None:
                check_period_ms(args.period_ms)
            check_out_dir(output_dir(MUJOCO_APPS[args.app or "arm2"], args.out))
        except ValueError as exc:
            return str(exc)
        return None
    if args.out is not None:
        return "--out needs --bus mujoco (the sim and can demos write no files)"
    if args.virtual and args.bus != "sim":
        return "--virtual needs --bus sim or mujoco: a bus runs in real time"
    duration = DEMO_DURATION_S if args.duration is None else args.duration
    period = DEMO_PERIOD_MS if args.period_ms is None else args.period_ms
    if not (math.isfinite(duration) and duration > 0):
        return f"--duration must be a finite number of seconds > 0, not {duration}"
    if not (math.isfinite(period) and DEMO_MIN_PERIOD_MS <= period <= DEMO_MAX_PERIOD_MS):
        return (
            f"--period-ms must be from {DEMO_MIN_PERIOD_MS:g} to {DEMO_MAX_PERIOD_MS:g} ms, "
            f"not {period}"
        )
    ticks = duration * 1000.0 / period
    if args.virtual and ticks > DEMO_MAX_VIRTUAL_TICKS:
        return (
            f"--duration {duration:g} s at --period-ms {period:g} is {ticks:.3g} timer ticks "
            f"on the virtual clock; at most {DEMO_MAX_VIRTUAL_TICKS:,} (a longer period or a "
            "shorter duration)"
        )
    return None


def _demo(args: argparse.Namespace) -> int:
    from .demo_sim import DemoSummary, run_demo
    from .interrupt import Interrupted, run_interruptible
    from .progress import LiveLine

    problem = _check_demo(args)
    if problem is not None:
        print(f"openel-async demo: {problem}", file=sys.stderr)
        return 2
    if args.bus == "mujoco":
        outcome = anyio.run(run_interruptible, partial(_demo_mujoco, args), backend="asyncio")
        if isinstance(outcome, Interrupted):
            _print_interrupted(f"MuJoCo {args.app or 'arm2'} demo", outcome)
            return outcome.exit_code
        if outcome is not None:
            return outcome
        args.bus = "sim"  # MuJoCo could not load: the two-axis demo on simulated motors
    rig = _rig(args.bus)
    if rig is None:
        return 2
    live = None if args.no_live else LiveLine()
    summary = DemoSummary(duration_s=DEMO_DURATION_S if args.duration is None else args.duration)
    result = anyio.run(
        run_interruptible,
        partial(
            run_demo,
            duration_s=summary.duration_s,
            period_ms=DEMO_PERIOD_MS if args.period_ms is None else args.period_ms,
            virtual=args.virtual,
            inject_fault=args.inject_fault,
            live=live,
            rig=rig,
            summary=summary,
        ),
        backend="asyncio",
    )
    if isinstance(result, Interrupted):
        _print_interrupted(summary.rig or "openel-async demo", result, summary.partial_lines())
        return result.exit_code
    print(f"\nsummary ({summary.rig})")
    for line in summary.lines():
        print("  " + line)
    return 0


def _print_interrupted(title: str, interrupted: Interrupted, lines: Sequence[str] = ()) -> None:
    """The summary of a command stopped by a signal (stdout), and one line on stderr."""
    print(f"\nsummary ({title}, interrupted)")
    for line in (*interrupted.lines(), *lines):
        print("  " + line)
    sys.stdout.flush()
    print(
        f"openel-async: interrupted by {interrupted.signum.name} "
        f"(exit status {interrupted.exit_code})",
        file=sys.stderr,
    )


async def _demo_mujoco(args: argparse.Namespace) -> int | None:
    """A MuJoCo arm app (``--app``, default the arm2 square); None when MuJoCo or the model
    cannot load for the default app (logged: the caller falls back to the sim demo)."""
    from .arm_demo import ArmOptions, output_dir

    app = args.app or "arm2"
    module = importlib.import_module(f"{__name__}.{MUJOCO_APPS[app]}")
    try:
        sim = module.open_sim(realtime=not args.virtual)
    except Exception as exc:  # ImportError, ModelLoadError, MuJoCo's own load errors
        reason = f"{type(exc).__name__}: {exc}"
        if args.app is not None:  # asked for by name: no fallback
            print(f"openel-async demo: MuJoCo cannot run --app {app}: {reason}", file=sys.stderr)
            return 1
        structlog.get_logger(__name__).warning(
            "mujoco_unavailable",
            reason=reason,
            fallback="the two-axis demo on openel_sim motors (--bus sim)",
        )
        return None
    options = ArmOptions(
        duration=(
            (DEMO_DURATION_S if app == "arm2" else module.DEFAULT_DURATION_S)
            if args.duration is None
            else args.duration
        ),
        realtime=not args.virtual,
        out_dir=output_dir(module.APP, args.out),
        live=not args.no_live,
        period_ms=module.DEFAULT_PERIOD_MS if args.period_ms is None else args.period_ms,
    )
    code: int = await module.run_app(sim, options, prog="openel-async demo")
    return code


def _rig(bus: str) -> RigFactory | None:
    from .demo_sim import sim_rig

    if bus == "sim":
        return sim_rig
    try:
        module = importlib.import_module("openel_can.demo")
    except ImportError as exc:
        print(f"the CAN demo rig is not available: {exc}", file=sys.stderr)
        return None
    can_rig: RigFactory = module.can_rig
    return can_rig


if __name__ == "__main__":
    sys.exit(main())
