"""openel-async: run the demos and apps, check RTC Profiles and HAL4RT messages, inspect and
replay recordings.

Options after a command apply to it; the output options (--log-format, --log-level, -v, -q)
work before or after any command. 'openel-async COMMAND --help' explains a command.
"""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
from collections.abc import Sequence
from typing import Any

from ..app import EXIT_SIGINT, install_sigterm_handler, interrupt_code
from .commands import attach, discover_commands
from .logs import configure_logging
from .options import (
    GLOBAL_FLAGS,
    GLOBAL_VALUE_OPTIONS,
    SHORT_GLOBAL_FLAGS,
    HelpFormatter,
    add_global_options,
    log_level,
)
from .record_cmd import add_tap_arguments
from .rig_cmd import add_rig_arguments

PROG = "openel-async"
QUIET_START = frozenset({"devices", "rig", "hal4rt", "completion", "scan", "bus"})
"""Commands that run no application code: structlog is loaded only if something logs."""
SHELLS = ("bash", "zsh", "tcsh")

DEMO_DESCRIPTION = """\
Run a demo app with the demo's options. Without --app: the MuJoCo arm traces a square
(--bus mujoco, the default; the two-axis demo where MuJoCo cannot load), or the two-axis
synchronized demo of spec Figs. 7.5-7.8 (--bus sim, --bus can, --remote).

Every option is checked before anything runs (exit status 2). Ctrl-C (SIGINT) stops the demo
with exit status 130, SIGTERM with 143, after a summary; the PNG files are then complete or
absent.
"""

RUN_DESCRIPTION = """\
Run a registered app (by name: 'openel-async demo --list'), a Python app file (async def
main(argv), or an APP_INFO) or the RT component an RTC Profile describes.

Options after NAME are the app's ('openel-async run NAME --help' lists them), except
--record, --foxglove, --foxglove-host and --foxglove-port, which openel-async takes wherever
they are (an app with an option of the same name is refused: give openel-async's before NAME
and the app's after '--').

All of these EXECUTE Python code: the app, or the module the profile's 'implementation'
parameter names (next to the profile, or installed); run only what you trust. Ctrl-C (SIGINT)
stops the run with exit status 130, SIGTERM with 143, after a summary. The output options
(--log-level, -v, -q, --log-format) go before NAME: after it they are the app's.
"""


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("openel-async")
    except PackageNotFoundError:  # a source tree that is not installed
        return "unknown"


class _VersionAction(argparse.Action):
    """``--version``: the installed version, read from the package's metadata only when
    asked (reading it parses the METADATA file: every other command is spared that)."""

    def __init__(self, option_strings: Sequence[str], dest: str, **kwargs: Any) -> None:
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, **kwargs)

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: object,
        option_string: str | None = None,
    ) -> None:
        print(f"{parser.prog} {_version()}")
        parser.exit()


def _subcommand(
    sub: argparse._SubParsersAction[argparse.ArgumentParser], name: str, **kwargs: object
) -> argparse.ArgumentParser:
    parser: argparse.ArgumentParser = sub.add_parser(
        name,
        formatter_class=HelpFormatter,
        **kwargs,  # type: ignore[arg-type]
    )
    return parser


SCAN_HELP = "find the devices on a bus (CAN, serial) before writing a rig"
SCAN_DESCRIPTION = """\
Find the devices on a bus before writing a rig: each kind of bus is scanned by its driver
('openel-async scan BUS --help'). Prints a table (--json for scripts) and, with --rig-out, a
rig file to edit. Every option is checked before anything is opened (exit status 2); Ctrl-C
stops the scan with exit status 130.
"""
BUS_HELP = "watch a bus: its frames decoded, rates and errors"
BUS_DESCRIPTION = """\
Watch a bus: 'monitor' prints its frames decoded by what the drivers know, with per-id
rates and error counters ('openel-async bus monitor --help'). Contributed by the drivers.
"""


def _parent(
    sub: argparse._SubParsersAction[argparse.ArgumentParser],
    name: str,
    metavar: str,
    help: str,
    description: str,
) -> argparse._SubParsersAction[argparse.ArgumentParser]:
    """A command whose actions the drivers contribute (``scan can``, ``bus monitor``)."""
    parser = _subcommand(sub, name, help=help, description=description, allow_abbrev=False)
    actions = parser.add_subparsers(
        title="actions (from the installed drivers)",
        dest=f"{name}_command",
        required=True,
        metavar=metavar,
    )
    return actions


def _finish(parser: argparse.ArgumentParser, depth: int) -> None:
    """Give every subcommand below ``parser`` the formatter and the global options."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {choice.dest: choice.help for choice in action._choices_actions}
            for name, child in action.choices.items():
                if child.description is None and helps.get(name):  # its one line, as a sentence
                    text = str(helps[name])
                    child.description = text[0].upper() + text[1:] + "."
            for child in dict.fromkeys(action.choices.values()):
                child.formatter_class = HelpFormatter
                if not any(a.dest.startswith("verbose_") for a in child._actions):
                    add_global_options(child, depth=depth + 1)
                _finish(child, depth + 1)


SOLO_COMMANDS = ("demo", "run", "devices", "profile", "record", "replay", "rig", "param", "jog")
"""The framework's commands with no actions contributed by drivers: when the command line
names one, only its parser is built (see :func:`_build_parser`)."""


def named_command(argv: Sequence[str]) -> str | None:
    """The command ``argv`` names, found as argparse finds it: the first word that is not a
    global option (:func:`~.options.add_global_options`) or the value of one. None if
    anything else comes first (``-h``, ``--version``, ``--``, another option) or no word."""
    tokens = iter(argv)
    for token in tokens:
        if not token.startswith("-"):
            return token
        name, equals, _ = token.partition("=")
        if name in GLOBAL_VALUE_OPTIONS:
            if not equals:
                next(tokens, None)  # its value
        elif not (token in GLOBAL_FLAGS or set(token[1:]) <= SHORT_GLOBAL_FLAGS):
            return None
    return None


def _build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The command line's parser: every command's, or with ``only`` (one of
    :data:`SOLO_COMMANDS`) that command's alone. Building the ~45 parsers of every command
    and action (and importing the drivers' contributed commands) is a tenth of an app's
    ``--help``; a command line that names a command parses exactly as with the whole
    parser, since argparse reads only the chosen command's parser."""
    # No abbreviations at the top: it would refuse a command's own option that is the prefix
    # of a global one (bus monitor --log, against --log-format and --log-level).
    parser = argparse.ArgumentParser(
        prog=PROG, description=__doc__, formatter_class=HelpFormatter, allow_abbrev=False
    )
    parser.add_argument(
        "--version", action=_VersionAction,
        help="print the version and exit",
    )  # fmt: skip
    add_global_options(parser, depth=0)
    sub = parser.add_subparsers(title="commands", dest="command", required=True, metavar="COMMAND")
    for name in SOLO_COMMANDS:
        if only is None or name == only:
            _add_command(sub, name)
    if only is None:
        _add_contributed(sub)
    _finish(parser, 0)
    groups = parser._action_groups  # the commands first, then the options
    groups.sort(key=lambda group: group.title != "commands")
    return parser


def _add_contributed(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The commands whose actions the drivers contribute, ``completion``, and the drivers'
    own commands."""
    from .hal4rt_cmd import add_parser as add_hal4rt_parser

    parents = {
        "hal4rt": add_hal4rt_parser(sub),
        "scan": _parent(sub, "scan", "BUS", SCAN_HELP, SCAN_DESCRIPTION),
        "bus": _parent(sub, "bus", "ACTION", BUS_HELP, BUS_DESCRIPTION),
    }
    completion = _subcommand(
        sub,
        "completion",
        help="print a shell completion script (bash, zsh or tcsh)",
        description="Print the completion script of a shell. Load it in the current shell:\n\n"
        '- bash: eval "$(openel-async completion bash)"\n'
        "- zsh: openel-async completion zsh > ~/.zfunc/_openel-async (a folder on $fpath)\n"
        "- tcsh: eval `openel-async completion tcsh`",
    )
    completion.add_argument("shell", choices=SHELLS, help="the shell: bash, zsh or tcsh")
    for command in discover_commands():  # contributed by drivers (openel_zenoh: serve, exec)
        target = sub if command.parent is None else parents.get(command.parent)
        if target is not None:
            attach(command, target)


def _add_demo(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    demo = _subcommand(
        sub,
        "demo",
        help="run a demo: the MuJoCo arm traces a square (default), the 6-DoF arm picks and "
        "places a box (--app arm6), two axes in step (--bus sim or can)",
        description=DEMO_DESCRIPTION,
    )
    demo.add_argument(
        "--app",
        metavar="NAME",
        default=None,
        help="the app to run, by its registered name (--list shows them):\n"
        "arm2: the 2-DoF arm traces a square (the default).\n"
        "arm6: the 6-DoF arm picks and places a box with its suction cup.\n"
        "twoaxis: the two-axis demo (the default of --bus sim, --bus can and --remote).",
    )
    demo.add_argument(
        "--list", action="store_true", help="list the registered apps, one a line, and exit"
    )
    demo.add_argument(
        "--duration",
        type=float,
        metavar="S",
        default=None,
        help="seconds, for each app:\n"
        "arm2: seconds per lap of the square (default 5, at most 600).\n"
        "arm6: seconds of arm motion (default 8, at most 600).\n"
        "twoaxis: seconds of synchronized motion (default 5).",
    )
    demo.add_argument(
        "--period-ms",
        type=float,
        metavar="MS",
        default=None,
        help="the EventTimer's period in milliseconds:\n"
        "arm2, arm6: a whole number from 1 to 100 (default 2).\n"
        "twoaxis: from 0.1 to 1000 (default 10).",
    )
    pacing = demo.add_mutually_exclusive_group()
    pacing.add_argument(
        "--virtual",
        dest="virtual",
        action="store_true",
        default=False,
        help="run as fast as possible: the virtual clock (twoaxis, --bus sim only) or "
        "lockstep MuJoCo pacing (arm2, arm6)",
    )
    pacing.add_argument(
        "--realtime",
        dest="virtual",
        action="store_false",
        default=False,
        help="run in real time on the monotonic clock (the default)",
    )
    demo.add_argument(
        "--inject-fault",
        action="store_true",
        help="trip a drive halfway and recover it (twoaxis on --bus sim or can)",
    )
    demo.add_argument("--no-live", action="store_true", help="no live progress line")
    demo.add_argument(
        "--out",
        metavar="DIR",
        default=None,
        help="arm2, arm6: the folder for the PNG files, created if needed (default "
        "out/<app>/ in the current folder, e.g. out/arm2_square/)",
    )
    demo.add_argument(
        "--bus",
        choices=("mujoco", "sim", "can"),
        default=None,
        help="the device layer:\n"
        "mujoco: the MuJoCo arm (falls back to sim when MuJoCo cannot load).\n"
        "sim: openel_sim motors.\n"
        "can: simulated CAN drives.",
    )
    demo.add_argument(
        "--remote",
        action="store_true",
        help="the two-axis demo with its sim devices served by a second process "
        "('openel-async serve' on a free loopback port) and driven over Zenoh",
    )
    add_tap_arguments(demo)


def _add_run(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    run = _subcommand(
        sub,
        "run",
        help="run an app by name, an app file (apps/NAME.py) or an RTC Profile (.yaml, .xml)",
        description=RUN_DESCRIPTION,
    )
    add_tap_arguments(run)
    add_rig_arguments(run)
    run.add_argument(
        "path", metavar="NAME|PATH", help="a registered app's name, an app file or folder, or "
        "an RTC Profile",
    )  # fmt: skip
    run.add_argument(
        "app_args", nargs=argparse.REMAINDER, metavar="...", help="the app's own options"
    )


def _add_devices(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    devices = _subcommand(
        sub, "devices", help="list the registered drivers and their devices",
        description="List the registered drivers (entry-point group openel_async.drivers) and "
        "the devices each offers, with the class that implements each.",
    )  # fmt: skip
    devices.add_argument(
        "--profile",
        action="store_true",
        help="print every device's characteristics profile (kind, commands with ids, "
        "parameters with units) as JSON",
    )


def _add_command(sub: argparse._SubParsersAction[argparse.ArgumentParser], name: str) -> None:
    """Add the parser of the framework's command ``name`` (one of :data:`SOLO_COMMANDS`)."""
    if name == "demo":
        _add_demo(sub)
    elif name == "run":
        _add_run(sub)
    elif name == "devices":
        _add_devices(sub)
    else:  # the module <name>_cmd adds it
        importlib.import_module(f"{__name__}.{name}_cmd").add_parser(sub)


def main(argv: Sequence[str] | None = None) -> int:
    """Run a command; returns its exit status.

    SIGINT (Ctrl-C) ends any command with status 130 and SIGTERM with 143, without a
    traceback: the long-running commands stop their work, print a summary and leave their
    output files complete or absent (openel_async.app); elsewhere the signal unwinds the
    command like an exception."""
    previous_sigterm = signal.getsignal(signal.SIGTERM)
    install_sigterm_handler()
    try:
        return _main(argv)
    except BaseException as exc:
        if _broken_pipe(exc):
            # The reader of stdout went away (``| head``): stop quietly, as a shell tool
            # does, and point stdout at /dev/null so that the exit's flush raises nothing.
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
            os.close(devnull)
            return EXIT_BROKEN_PIPE
        code = interrupt_code(exc)
        if code is None:
            raise
        name = "SIGINT" if code == EXIT_SIGINT else "SIGTERM"
        print(f"\n{PROG}: interrupted by {name}", file=sys.stderr)
        return code
    finally:
        signal.signal(signal.SIGTERM, previous_sigterm)


EXIT_BROKEN_PIPE = 128 + 13
"""The exit status when stdout's reader left (killed by SIGPIPE, as a shell reports it)."""


def _broken_pipe(exc: BaseException) -> bool:
    """Whether ``exc`` is a BrokenPipeError on stdout, alone or in an exception group."""
    if isinstance(exc, BaseExceptionGroup):
        return all(_broken_pipe(e) for e in exc.exceptions)
    return isinstance(exc, BrokenPipeError)


def _main(argv: Sequence[str] | None) -> int:
    command = named_command(sys.argv[1:] if argv is None else argv)
    parser = _build_parser(command if command in SOLO_COMMANDS else None)
    args = parser.parse_args(argv)
    # Commands that run no application code, and a run that only asks an app for its help,
    # configure structlog when it is first used.
    only_help = args.command == "run" and bool({"-h", "--help"} & set(args.app_args))
    defer = args.command in QUIET_START or only_help
    configure_logging(args.log_format, log_level(args), defer=defer)
    contributed = getattr(args, "contributed", None)
    if contributed is not None:
        code: int = contributed.run(args)
        return code
    if args.command == "completion":
        import shtab

        print(shtab.complete(parser, shell=args.shell), end="")
        return 0
    if args.command == "devices":
        if args.profile:
            from .devices_cmd import print_profiles

            return print_profiles()
        from .devices_cmd import print_devices

        return print_devices()
    if args.command == "demo":
        from .demo_cmd import run as run_demo_cmd

        return run_demo_cmd(args)
    if args.command == "run":
        from .run_cmd import run

        app_args = list(args.app_args)
        raw = list(sys.argv[1:] if argv is None else argv)
        cut = len(raw) - len(app_args) - 1
        if cut >= 0 and raw[cut] == "--" and raw[cut + 1 :] == app_args:
            app_args.insert(0, "--")  # argparse drops a '--' right after the app's name
        return run(args.path, app_args, tap_args=args)
    if args.command == "rig":
        from .rig_cmd import run as run_rig_cmd

        return run_rig_cmd(args)
    if args.command == "param":
        from .param_cmd import run as run_param_cmd

        return run_param_cmd(args)
    if args.command == "jog":
        from .jog_cmd import run as run_jog_cmd

        return run_jog_cmd(args)
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


if __name__ == "__main__":
    sys.exit(main())
