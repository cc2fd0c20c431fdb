"""The ``openel-async`` command line."""

from __future__ import annotations

import argparse
import importlib
import signal
import sys
from collections.abc import Sequence

from ..app import EXIT_SIGINT, install_sigterm_handler, interrupt_code
from .commands import attach, discover_commands
from .logs import LEVELS, configure_logging
from .record_cmd import add_parser as add_record_parser
from .record_cmd import add_tap_arguments
from .replay_cmd import add_parser as add_replay_parser


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
        metavar="NAME",
        default=None,
        help="the app to run, by its registered name (--list shows them): arm2 (the 2-DoF arm "
        "traces a square; default), arm6 (the 6-DoF arm picks and places a box with its suction "
        "cup), twoaxis (the two-axis demo; the default of --bus sim or can)",
    )
    demo.add_argument(
        "--list", action="store_true", help="list the registered apps, one line each, and exit"
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
        default=None,
        help="device layer: mujoco (the MuJoCo arm; falls back to sim when MuJoCo cannot "
        "load), sim (openel_sim motors) or can (simulated CAN drives)",
    )
    demo.add_argument(
        "--remote",
        action="store_true",
        help="two-axis demo with its sim devices served by a second process "
        "('openel-async serve' on a free loopback port) and driven over Zenoh",
    )
    add_tap_arguments(demo)

    run = sub.add_parser(
        "run",
        help="run an app by its registered name (openel-async demo --list), an app file "
        "(apps/<name>.py) or an RTC Profile (.yaml/.xml); this executes the app's Python code, "
        "or the module the profile's 'implementation' names",
        description="Run a registered app (by name), a Python app file (async def main(argv), "
        "or an APP_INFO) or the RT component an RTC Profile describes. All EXECUTE Python "
        "code: the app, or the module the profile's 'implementation' parameter names (next to "
        "the profile, or installed); run only what you trust. Ctrl-C (SIGINT) stops the run "
        "with exit status 130, SIGTERM with 143, after a summary. 'openel-async run NAME "
        "--help' lists an app's options, 'openel-async run PROFILE --help' a profile's.",
    )
    add_tap_arguments(run)
    run.add_argument(
        "path", help="registered app name, application file or directory, or RTC Profile"
    )
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
    add_record_parser(sub)
    add_replay_parser(sub)
    from .hal4rt_cmd import add_parser as add_hal4rt_parser

    parents = {"hal4rt": add_hal4rt_parser(sub)}
    for command in discover_commands():  # contributed by drivers (openel_zenoh: serve, exec)
        target = sub if command.parent is None else parents.get(command.parent)
        if target is not None:
            attach(command, target)
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
    contributed = getattr(args, "contributed", None)
    if contributed is not None:
        code: int = contributed.run(args)
        return code
    if args.command == "devices":
        if args.profile:
            from .devices_cmd import print_profiles

            return print_profiles()
        return _devices()
    if args.command == "demo":
        from .demo_cmd import run as run_demo_cmd

        return run_demo_cmd(args)
    if args.command == "run":
        from .run_cmd import run

        return run(args.path, list(args.app_args), tap_args=args)
    if args.command == "record":
        from .record_cmd import run as run_record_cmd

        return run_record_cmd(args)
    if args.command == "replay":
        from .replay_cmd import run as run_replay_cmd

        return run_replay_cmd(args)
    if args.command == "profile":
        from .profile_cmd import run as run_profile_cmd

        return run_profile_cmd(args)
    if args.command == "hal4rt":
        module = importlib.import_module(f"{__name__}.hal4rt_cmd")
        status: int = module.run(args)
        return status
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


if __name__ == "__main__":
    sys.exit(main())
