"""``openel-async demo``: run a registered app with the demo's options.

The app is ``--app NAME`` (any app of the ``openel_async.apps`` entry-point group that takes
the demo's options: its ``AppInfo.demo_args``), else ``twoaxis`` for ``--bus sim|can`` and
``--remote`` (the sim devices served by a second process: ``--bus remote``), and ``arm2``
(the MuJoCo arm's square) otherwise. Where the default app cannot run (it raises
``AppUnavailable``: MuJoCo or its model cannot load), the demo logs ``mujoco_unavailable`` and
runs ``twoaxis`` on ``openel_sim`` motors instead; an app asked for by name does not fall back.
``--list`` prints the registered apps, one line each.
"""

from __future__ import annotations

import argparse
import sys

from openel_async.logs import get_logger

from ..app import AppInfo, AppUnavailable, DemoOptions, discover_apps, find_app, run_app
from .record_cmd import taps_from_args

__all__ = ["BUS_APP", "DEFAULT_APP", "PROG", "list_apps", "run"]

DEFAULT_APP = "arm2"
"""``openel-async demo`` with ``--bus mujoco`` or no ``--bus``: the MuJoCo arm's square."""
BUS_APP = "twoaxis"
"""``openel-async demo --bus sim|can``: the two-axis synchronized demo; also the fallback of
the default demo where MuJoCo cannot load."""
PROG = "openel-async demo"
STOP_LABEL = "openel-async"


def list_apps() -> int:
    """``demo --list``: one line per registered app."""
    entries = discover_apps()
    width = max((len(e.name) for e in entries), default=0) + 2
    for entry in entries:
        if entry.info is None:
            print(f"{entry.name:{width}}({entry.value})  unavailable: {entry.error}")
        else:
            print(f"{entry.name:{width}}{entry.info.description}")
    return 0


def _options(args: argparse.Namespace) -> DemoOptions:
    return DemoOptions(
        bus="remote" if getattr(args, "remote", False) else args.bus,
        duration=args.duration,
        period_ms=args.period_ms,
        virtual=args.virtual,
        inject_fault=args.inject_fault,
        live=not args.no_live,
        out=args.out,
    )


def _demo_argv(info: AppInfo, options: DemoOptions) -> list[str]:
    if info.demo_args is None:
        if options != DemoOptions(bus=options.bus):
            raise ValueError(
                f"app {info.name!r} takes no demo options; run it as 'openel-async run "
                f"{info.name} [its options]'"
            )
        return []
    return info.demo_args(options)


def run(args: argparse.Namespace) -> int:
    if args.list:
        return list_apps()
    if getattr(args, "remote", False) and args.bus not in (None, "sim"):
        print(
            f"{PROG}: --remote serves the sim devices; not with --bus {args.bus}", file=sys.stderr
        )
        return 2
    options = _options(args)
    name = args.app or (BUS_APP if options.bus in ("sim", "can", "remote") else DEFAULT_APP)
    try:
        info = find_app(name)
        argv = _demo_argv(info, options)
    except (LookupError, ValueError) as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)
        return 2
    hooks = taps_from_args(args, PROG)
    if hooks is None:
        return 2
    try:
        return run_app(info, argv, prog=PROG, hooks=hooks, stop_label=STOP_LABEL)
    except AppUnavailable as exc:
        if args.app is not None:  # asked for by name: no fallback
            print(f"{PROG}: {exc.needs} cannot run --app {name}: {exc.reason}", file=sys.stderr)
            return 1
        get_logger(__name__).warning(
            "mujoco_unavailable" if exc.needs == "MuJoCo" else "app_unavailable",
            app=name,
            reason=exc.reason,
            fallback=f"{BUS_APP} on openel_sim motors (--bus sim)",
        )
    fallback = DemoOptions(
        bus="sim",
        duration=options.duration,
        period_ms=options.period_ms,
        virtual=options.virtual,
        live=options.live,
    )
    try:
        info = find_app(BUS_APP)
        argv = _demo_argv(info, fallback)
    except (LookupError, ValueError) as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)
        return 2
    hooks = taps_from_args(args, PROG)  # anew: the first run closed its recording
    if hooks is None:
        return 2
    return run_app(info, argv, prog=PROG, hooks=hooks, stop_label=STOP_LABEL)
