"""The ``openel-async`` command line."""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence
from typing import TYPE_CHECKING

import anyio

from .logs import LEVELS, configure_logging

if TYPE_CHECKING:
    from .demo_sim import RigFactory


def _build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="openel-async", description=__doc__)
    parser.add_argument("--log-format", choices=("console", "json"), default="console")
    parser.add_argument("--log-level", choices=LEVELS, default="info")
    sub = parser.add_subparsers(dest="command", required=True)

    demo = sub.add_parser("demo", help="run the two-axis synchronized demo (spec Figs. 7.5-7.8)")
    demo.add_argument("--duration", type=float, default=5.0, help="seconds of synchronized motion")
    demo.add_argument("--period-ms", type=float, default=10.0, help="EventTimer period (ms)")
    demo.add_argument("--virtual", action="store_true", help="run on the virtual clock (instant)")
    demo.add_argument(
        "--inject-fault", action="store_true", help="trip a drive halfway and recover"
    )
    demo.add_argument("--no-live", action="store_true", help="no live progress line")

    demo.add_argument("--bus", choices=("sim", "can"), default="sim", help="device layer to use")

    run = sub.add_parser("run", help="run an app (apps/<name>.py) or an RTC Profile (.yaml/.xml)")
    run.add_argument("path", help="application file or directory, or RTC Profile")
    run.add_argument("app_args", nargs=argparse.REMAINDER, help="arguments for the application")

    sub.add_parser("devices", help="list the registered drivers and their devices")
    from .profile_cmd import add_parser as add_profile_parser

    add_profile_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = _build_parser().parse_args(argv)
    configure_logging(args.log_format, args.log_level)
    if args.command == "devices":
        return _devices()
    if args.command == "demo":
        return _demo(args)
    if args.command == "run":
        from .run_cmd import run

        return run(args.path, list(args.app_args))
    if args.command == "profile":
        from .profile_cmd import run as run_profile_cmd

        return run_profile_cmd(args)
    return 2


def _devices() -> int:
    from ..registry import discover_drivers

    for entry in discover_drivers():
        if entry.info is None:
            print(f"{entry.name:10} ({entry.value})  unavailable: {entry.error}")
            continue
        print(f"{entry.name:10} {entry.info.description}")
        for device_name, cls in entry.info.devices.items():
            print(f"  {device_name:14} {cls.__module__}.{cls.__qualname__}")
    return 0


def _demo(args: argparse.Namespace) -> int:
    from .demo_sim import run_demo
    from .progress import LiveLine

    if args.duration <= 0:
        print("--duration must be > 0", file=sys.stderr)
        return 2
    rig = _rig(args.bus)
    if rig is None:
        return 2
    if args.virtual and args.bus != "sim":
        print("--virtual needs --bus sim: a bus runs in real time", file=sys.stderr)
        return 2
    live = None if args.no_live else LiveLine()
    summary = anyio.run(
        lambda: run_demo(
            duration_s=args.duration,
            period_ms=args.period_ms,
            virtual=args.virtual,
            inject_fault=args.inject_fault,
            live=live,
            rig=rig,
        ),
        backend="asyncio",
    )
    print(f"\nsummary ({summary.rig})")
    for line in summary.lines():
        print("  " + line)
    return 0


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
