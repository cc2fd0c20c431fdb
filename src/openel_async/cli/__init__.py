"""The ``openel-async`` command line."""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence
from typing import TYPE_CHECKING

import anyio
import structlog

from .logs import LEVELS, configure_logging

if TYPE_CHECKING:
    from .demo_sim import RigFactory

MUJOCO_APPS = {"arm2": "arm2_square", "arm6": "arm6_pick_place"}
"""``demo --app``: the arm apps of ``--bus mujoco`` (modules of this package)."""
DEMO_DURATION_S = 5.0
"""Default ``demo --duration``: of the two-axis demo, and of a lap of the square."""


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
        "default 5; arm6: seconds of arm motion, default 8)",
    )
    demo.add_argument(
        "--period-ms",
        type=float,
        default=None,
        help="EventTimer period, ms (default: 10; mujoco: 2)",
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
        "--out", metavar="DIR", default=None, help="mujoco: directory for the PNG files "
        "(default: out/<app>/ under the current directory, e.g. out/arm2_square/)",
    )  # fmt: skip

    demo.add_argument(
        "--bus",
        choices=("mujoco", "sim", "can"),
        default="mujoco",
        help="device layer: mujoco (the MuJoCo arm; falls back to sim when MuJoCo cannot "
        "load), sim (openel_sim motors) or can (simulated CAN drives)",
    )

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
        width = max((len(name) for name in entry.info.devices), default=0) + 2
        for device_name, cls in entry.info.devices.items():
            print(f"  {device_name:{width}}{cls.__module__}.{cls.__qualname__}")
    return 0


def _demo(args: argparse.Namespace) -> int:
    from .demo_sim import run_demo
    from .progress import LiveLine

    if args.duration is not None and not args.duration > 0:
        print("--duration must be > 0", file=sys.stderr)
        return 2
    if args.app is not None and args.bus != "mujoco":
        print("--app needs --bus mujoco (the arm apps run on MuJoCo)", file=sys.stderr)
        return 2
    if args.period_ms is not None and args.period_ms <= 0:
        print("--period-ms must be > 0", file=sys.stderr)
        return 2
    if args.bus == "mujoco":
        if args.inject_fault:
            print("--inject-fault needs --bus sim or --bus can", file=sys.stderr)
            return 2
        code = anyio.run(_demo_mujoco, args, backend="asyncio")
        if code is not None:
            return code
        args.bus = "sim"  # MuJoCo could not load: the two-axis demo on simulated motors
    rig = _rig(args.bus)
    if rig is None:
        return 2
    if args.virtual and args.bus != "sim":
        print("--virtual needs --bus sim or mujoco: a bus runs in real time", file=sys.stderr)
        return 2
    live = None if args.no_live else LiveLine()
    summary = anyio.run(
        lambda: run_demo(
            duration_s=DEMO_DURATION_S if args.duration is None else args.duration,
            period_ms=10.0 if args.period_ms is None else args.period_ms,
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
