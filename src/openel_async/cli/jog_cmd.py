"""``openel-async jog RIG.yaml [--sim]`` (or ``--remote NAMESPACE``, a served rig): the terminal UI (``openel_async.tui``) over an
opened rig: every component with its state and live values, plots, keyboard jogging of the
selected axis within its limits, enable/disable, e-stop, the event and error log.

Every option and the rig file are checked before anything is opened (exit status 2). ``q``
quits (0), Ctrl-C quits with 130, as does a SIGINT from elsewhere (SIGTERM: 143); whatever
ends it, the rig leaves every actuator in its ``safety.on_exit`` state and the line saying so
is printed after the UI is gone."""

from __future__ import annotations

import argparse
import math
import sys
from functools import partial
from typing import Any

from .options import EXIT_USAGE, no_such_file

__all__ = ["add_parser", "run"]

PROG = "openel-async jog"
DEFAULT_STEP = 0.05
DEFAULT_VELOCITY = 0.5

JOG_HELP = "a terminal UI over a rig: live values and plots, jog an axis, enable, e-stop"
JOG_DESCRIPTION = """\
A terminal UI over a rig: every component with its state and live values, plots of the
selected ones, keyboard jogging of the selected axis within its position limits at a chosen
step and velocity, enable/disable, the rig's e-stop on one key, and the event and error log.

Keys: up/down select; left/right (h/l) jog by one step; [ ] change the step, - + the
velocity; space stops; e enables (re-initializes a faulted component, or holds the axis
where it is); d disables (torque off); x e-stops the whole rig, r releases and
re-initializes; p plots the selected component or not; q quits.

Every option is checked before anything is opened (exit status 2). Ctrl-C quits with exit
status 130; whatever ends it, each actuator is left in the rig's safety.on_exit state.
"""


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    jog = sub.add_parser("jog", help=JOG_HELP, description=JOG_DESCRIPTION)
    jog.add_argument(
        "rig", metavar="RIG.yaml", nargs="?", help="the rig file to open (not with --remote)"
    )
    jog.add_argument(
        "--remote",
        metavar="NAMESPACE",
        help="jog the rig 'openel-async serve' serves under NAMESPACE instead of opening one "
        "(through the installed remote driver: Zenoh)",
    )
    jog.add_argument(
        "--connect",
        action="append",
        metavar="ENDPOINT",
        help="--remote: the server's endpoint (default tcp/127.0.0.1:7447, serve's; repeatable)",
    )
    jog.add_argument(
        "--config", metavar="FILE", help="--remote: a Zenoh JSON5 configuration of your own"
    )
    jog.add_argument(
        "--timeout",
        type=float,
        default=2.0,
        metavar="S",
        help="--remote: seconds to wait for the server, then for each reply (default 2)",
    )
    jog.add_argument(
        "--sim",
        action="store_true",
        help="open the rig against simulated peers (every bus simulated, the devices at the "
        "same addresses)",
    )
    jog.add_argument(
        "--step",
        type=float,
        metavar="S",
        default=DEFAULT_STEP,
        help=f"the jog step at start, rad or m (default {DEFAULT_STEP:g}; [ and ] change it)",
    )
    jog.add_argument(
        "--velocity",
        type=float,
        metavar="V",
        default=DEFAULT_VELOCITY,
        help=f"the jog velocity at start, rad/s or m/s (default {DEFAULT_VELOCITY:g}; - and + "
        "change it)",
    )


def _positive(name: str, value: float, high: float) -> bool:
    if math.isfinite(value) and 0.0 < value <= high:
        return True
    print(f"{PROG}: {name} {value:g}: a number > 0 and <= {high:g}", file=sys.stderr)
    return False


def run(args: argparse.Namespace) -> int:
    if not (_positive("--step", args.step, 10.0) and _positive("--velocity", args.velocity, 100.0)):
        return EXIT_USAGE
    if args.remote is not None:
        return run_remote(args)
    if args.rig is None:
        print(f"{PROG}: give a rig file, or --remote NAMESPACE", file=sys.stderr)
        return EXIT_USAGE
    if args.connect or args.config:
        print(f"{PROG}: --connect and --config go with --remote", file=sys.stderr)
        return EXIT_USAGE
    if no_such_file(PROG, args.rig):
        return EXIT_USAGE
    if not (sys.stdin.isatty() and sys.stdout.isatty()):
        print(f"{PROG}: needs a terminal (standard input and output)", file=sys.stderr)
        return EXIT_USAGE
    from ..errors import BadParameterError
    from ..rig import load_rig, resolve_rig

    try:
        resolved = resolve_rig(load_rig(args.rig))
    except BadParameterError as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)
        return EXIT_USAGE

    import anyio

    from ..app import Interrupted, run_interruptible

    lines: list[str] = []
    result = anyio.run(run_interruptible, partial(session, resolved, args, lines))
    for line in lines:
        print(line)
    if isinstance(result, Interrupted):
        for line in result.lines():
            print(line)
        print(f"{PROG}: interrupted by {result.signum.name}", file=sys.stderr)
        return result.exit_code
    return result


async def session(resolved: Any, args: argparse.Namespace, lines: list[str]) -> int:
    """Open the rig, run the UI until it quits; ``lines``: what to print once the UI is gone
    (how each actuator was left), filled even when a signal cancels the session."""
    from ..errors import HALError
    from ..rig import open_rig
    from ..tui.app import JogApp
    from ..tui.jogger import Jogger

    rig = None
    try:
        async with (
            open_rig(resolved, sim=args.sim, handle_sigquit=True) as rig,
            Jogger(rig, step=args.step, velocity=args.velocity) as jogger,
        ):
            app = JogApp(jogger)
            await app.run_async()
        code = app.return_code
    except (HALError, OSError) as exc:  # the UI is gone (or never came)
        print(f"{PROG}: {exc}", file=sys.stderr)
        code = 1
    finally:
        if rig is not None:
            lines.append(rig.exit_line())
    return 1 if code is None else code


def run_remote(args: argparse.Namespace) -> int:
    """``jog --remote NAMESPACE``: a driver's session over a served rig (entry points
    ``openel_async.remote_jog``)."""
    if args.rig is not None or args.sim:
        print(f"{PROG}: --remote jogs a served rig: no RIG.yaml, no --sim", file=sys.stderr)
        return EXIT_USAGE
    from ..tui.session import remote_providers

    providers = remote_providers()
    if not providers:
        print(f"{PROG}: --remote: no remote driver installed (openel_zenoh)", file=sys.stderr)
        return EXIT_USAGE
    provider = providers[0]
    problem = provider.check(args)
    if problem is not None:
        print(f"{PROG}: {problem}", file=sys.stderr)
        return EXIT_USAGE
    if not (sys.stdin.isatty() and sys.stdout.isatty()):
        print(f"{PROG}: needs a terminal (standard input and output)", file=sys.stderr)
        return EXIT_USAGE

    import anyio

    from ..app import Interrupted, run_interruptible

    result = anyio.run(run_interruptible, partial(remote_session, provider, args))
    if isinstance(result, Interrupted):
        print(f"{PROG}: interrupted by {result.signum.name}", file=sys.stderr)
        return result.exit_code
    return result


async def remote_session(provider: Any, args: argparse.Namespace) -> int:
    """Run the UI over ``provider``'s session until it quits (the served rig stays as the
    jogs left it: a jog's setpoints stop at the last one sent)."""
    from ..errors import HALError
    from ..tui.app import JogApp

    try:
        async with provider.session(args) as jogger:
            app = JogApp(jogger)
            await app.run_async()
        code = app.return_code
    except (HALError, OSError) as exc:  # the UI is gone (or never came)
        print(f"{PROG}: {exc}", file=sys.stderr)
        code = 1
    return 1 if code is None else code
