"""The lifecycle and configuration of a served rig's components from the shell: the Zenoh
driver's ``openel-async activate``, ``deactivate`` and ``conf get|set`` (rtshell's rtact,
rtdeact and rtconf; docs/tools.md), over ``openel/<ns>/rig/lifecycle`` and ``.../conf``
(openel_zenoh.lifecycle_server).

Connection options, names, output and exit statuses are the shell's
(openel_zenoh.shell_commands): 0 done, 1 no rig served, no such component or no reply
within ``--timeout``, 2 usage error (found before anything is opened), 3 refused (the
component's state, a value outside its constraint) or failed; Ctrl-C 130. This module
imports no zenoh.
"""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING, TypeAlias

from openel_async.cli.commands import EXIT_USAGE, CliCommand

from .shell_commands import (
    EXIT_FAILED,
    EXIT_NOT_FOUND,
    add_connection,
    check_connection,
    emit_json,
    identity,
    run_shell,
)

if TYPE_CHECKING:
    from . import wire
    from .shell import RigShell, Target

    SubParsers: TypeAlias = argparse._SubParsersAction[argparse.ArgumentParser]

RTSHELL = {"activate": "rtact", "deactivate": "rtdeact"}
NAME_HELP = "the component: MOTOR_1, Motor[0], NS/MOTOR_1"


# -- activate / deactivate ----------------------------------------------------------------------


def _add_lifecycle_parser(sub: SubParsers, action: str) -> argparse.ArgumentParser:
    does = {
        "activate": "INACTIVE -> ACTIVE: an actuator holds where it is and takes commands again",
        "deactivate": "ACTIVE -> INACTIVE: an actuator's excitation off (NO_EXCITE, no torque); "
        "its commands are refused until 'activate'",
    }[action]
    parser: argparse.ArgumentParser = sub.add_parser(
        action,
        help=f"{action} served components (RTC lifecycle): {does.split(': ', 1)[1]}",
        description=f"{action.capitalize()} components of a served rig, as rtshell's "
        f"{RTSHELL[action]} does an RTC's: {does}. Refused "
        "in any other state (an ERROR component: 'openel-async reset' first). Prints 'NAME "
        "STATE' for each. Exit status: 0 done, 1 no such rig or component (or no reply), 2 "
        "usage error, 3 refused or failed.",
    )
    parser.add_argument("names", metavar="NAME", nargs="+", help=NAME_HELP)
    add_connection(parser, json_help="print one JSON object: the components and their states")
    return parser


def add_activate_parser(sub: SubParsers) -> argparse.ArgumentParser:
    return _add_lifecycle_parser(sub, "activate")


def add_deactivate_parser(sub: SubParsers) -> argparse.ArgumentParser:
    return _add_lifecycle_parser(sub, "deactivate")


def run_activate(args: argparse.Namespace) -> int:
    if not check_connection("openel-async activate", args):
        return EXIT_USAGE
    return run_shell("openel-async activate", args, lifecycle_main)


def run_deactivate(args: argparse.Namespace) -> int:
    if not check_connection("openel-async deactivate", args):
        return EXIT_USAGE
    return run_shell("openel-async deactivate", args, lifecycle_main)


def state_text(state: wire.LifecycleComponent) -> str:
    latched = ", e-stop latched" if state.latched else ""
    return f"{state.name} {state.state} (HAL {state.hal_state}{latched})"


async def lifecycle_main(shell: RigShell, args: argparse.Namespace) -> int:
    """activate or deactivate (``args.command``) every component named, one query per
    namespace; print the states after it."""
    targets = await shell.targets(args.names)
    failures: list[str] = []
    records: list[dict[str, object]] = []
    for space in dict.fromkeys(t.namespace for t in targets):
        names = [t.name for t in targets if t.namespace == space]
        reply = await shell.lifecycle(space, args.command, names)
        if reply.return_code != 0:
            failures.append(reply.message)
        by_name = {s.name: s for s in reply.components}
        for target in (t for t in targets if t.namespace == space):
            state = by_name.get(target.name)
            if state is None:
                continue
            records.append({**identity(target), "state": state.state, "hal_state": state.hal_state})
            if not args.json:
                print(state_text(state), flush=True)
    if args.json:
        emit_json({"action": args.command, "components": records, "failures": failures})
    else:
        for failure in failures:
            print(f"openel-async {args.command}: {failure}", file=sys.stderr)
    return EXIT_FAILED if failures else 0


# -- conf ---------------------------------------------------------------------------------------


def add_conf_parser(sub: SubParsers) -> argparse.ArgumentParser:
    parser: argparse.ArgumentParser = sub.add_parser(
        "conf",
        help="a served component's configuration sets (its live limits, with constraints)",
        description="Read or set the configuration of a component of a served rig, as "
        "rtshell's rtconf does an RTC's: the set 'default' (active) holds an actuator's live "
        "limits (position_min, position_max, max_velocity, max_torque, max_acceleration), each "
        "with an RTC constraint (the range it had when the server started: a limit can be "
        "narrowed, never widened). A value outside its constraint is refused, the constraint "
        "named, and nothing changes. Exit status: 0 done, 1 no such rig or component (or no "
        "reply), 2 usage error, 3 refused.",
    )
    actions = parser.add_subparsers(dest="conf_action", metavar="ACTION", required=True)
    get = actions.add_parser(
        "get",
        help="list the sets, parameters, values and constraints",
        description="Print the component's configuration: every set's values (or PARAM's), "
        "each parameter's type, unit and constraint.",
    )
    get.add_argument("name", metavar="NAME", help=NAME_HELP)
    get.add_argument("parameter", metavar="PARAM", nargs="?", help="one parameter only")
    get.add_argument("--set", dest="set_name", metavar="SET", help="one set only")
    add_connection(get, json_help="print one JSON object: parameters, active set, sets")
    put = actions.add_parser(
        "set",
        help="set one parameter (applied to the device at once in the active set)",
        description="Set PARAM of the set (default: 'default', the active one) to VALUE; in "
        "the active set it applies to the device at once. Refused, with the constraint named, "
        "when VALUE is outside it.",
    )
    put.add_argument("name", metavar="NAME", help=NAME_HELP)
    put.add_argument("parameter", metavar="PARAM", help="the parameter (position_max...)")
    put.add_argument("value", metavar="VALUE", help="its new value, as text (0.5)")
    put.add_argument(
        "--set", dest="set_name", default="default", metavar="SET", help="the set (default)"
    )
    add_connection(put, json_help="print one JSON object: the set's values after it")
    return parser


def run_conf(args: argparse.Namespace) -> int:
    prog = f"openel-async conf {args.conf_action}"
    if not check_connection(prog, args):
        return EXIT_USAGE
    if args.conf_action == "set" and not args.value.strip():
        print(f"{prog}: VALUE is empty", file=sys.stderr)
        return EXIT_USAGE
    return run_shell(prog, args, conf_main)


def conf_record(target: Target, reply: wire.ConfReply) -> dict[str, object]:
    return {
        **identity(target),
        "active_set": reply.active_set,
        "parameters": {
            p.name: {"type": p.type, "constraint": p.constraint, "unit": p.unit}
            for p in reply.parameters
        },
        "sets": {s.name: s.values for s in reply.sets},
    }


async def conf_main(shell: RigShell, args: argparse.Namespace) -> int:
    from . import wire

    prog = f"openel-async conf {args.conf_action}"
    target = await shell.target(args.name)
    if args.conf_action == "set":
        request = wire.ConfRequest(target.name, args.set_name, args.parameter, args.value.strip())
    else:
        request = wire.ConfRequest(target.name, args.set_name or "", args.parameter or "")
    reply = await shell.conf(target.namespace, request)
    if reply.return_code != 0:
        if args.json:
            emit_json(
                {**identity(target), "message": reply.message, "constraint": reply.constraint}
            )
        else:
            print(f"{prog}: {reply.message}", file=sys.stderr)
        return EXIT_FAILED
    sets = [s for s in reply.sets if not args.set_name or s.name == args.set_name]
    if not sets:
        names = ", ".join(s.name for s in reply.sets)
        print(
            f"{prog}: {target.name}: no configuration set {args.set_name!r}: {names}",
            file=sys.stderr,
        )
        return EXIT_NOT_FOUND
    if args.json:
        emit_json(conf_record(target, reply))
        return 0
    if args.conf_action == "set":
        value = next(s.values for s in sets).get(args.parameter, "")
        print(f"{target.name} {sets[0].name} {args.parameter} {value}", flush=True)
        return 0
    params = [p for p in reply.parameters if not args.parameter or p.name == args.parameter]
    if not reply.parameters:
        print(f"{target.name}: no configuration parameters", flush=True)
        return 0
    for one in sets:
        active = " (active)" if one.name == reply.active_set else ""
        print(f"{target.name} set {one.name}{active}")
        width = max(len(p.name) for p in params)
        for p in params:
            value = one.values.get(p.name, "")
            unit = f" {p.unit}" if p.unit else ""
            constraint = f"  [{p.constraint}]" if p.constraint else ""
            print(f"  {p.name.ljust(width)}  {value}{unit}  ({p.type}){constraint}")
    sys.stdout.flush()
    return 0


ACTIVATE = CliCommand("activate", add_activate_parser, run_activate)
"""``openel-async activate``."""
DEACTIVATE = CliCommand("deactivate", add_deactivate_parser, run_deactivate)
"""``openel-async deactivate``."""
CONF = CliCommand("conf", add_conf_parser, run_conf)
"""``openel-async conf get|set``."""
