"""A served rig from the shell: the Zenoh driver's ``openel-async ls``, ``get``, ``set``,
``watch`` and ``reset`` (entry-point group ``openel_async.commands``; docs/tools.md).

Every command talks to the rigs that ``openel-async serve`` serves, through the surface
layer (no XML to write): the namespaces are discovered from the servers' liveliness
tokens (``--namespace`` picks one; a wrong one is answered with those served), a
component is named by its rig name (``MOTOR_1``) or its address (``Motor[0]``), with
``NAMESPACE/`` before it when several rigs are served. Replies print as text, or as JSON
with ``--json``.

Every option is checked before anything is opened (exit status 2). Exit status: 0 done,
1 no rig served, no such component or no reply within ``--timeout``, 2 usage error, 3
the component refused or failed the command; Ctrl-C ends any of them with 130 (the
framework's command line). This module imports no zenoh: ``openel_zenoh.shell`` is
imported when a command runs.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import re
import sys
import time
from collections.abc import Awaitable, Callable, Mapping
from typing import TYPE_CHECKING, Any, TypeAlias

from openel_async.cli.commands import EXIT_USAGE, CliCommand, no_such_file
from openel_async.errors import BadParameterError, HALError, NotConnectedError, ReturnCode

from .keys import check_chunk

if TYPE_CHECKING:
    import zenoh

    from openel_async.surface.messages import ResultList

    from .shell import RigShell, Target

    SubParsers: TypeAlias = argparse._SubParsersAction[argparse.ArgumentParser]

EXIT_NOT_FOUND = 1
"""No rig served, no such component, or no reply within the timeout: nothing was done."""
EXIT_FAILED = 3
"""The component refused or failed the command."""

MOTOR_GETS = {
    "position": "GetPosition",
    "speed": "GetSpeed",
    "torque": "GetTorque",
    "mode": "GetControlMode",
    "values": "GetValueOfMeasurement",
    "units": "GetUnitOfMeasurement",
}
SENSOR_GETS = {
    "values": "GetValueOfMeasurement",
    "units": "GetUnitOfMeasurement",
    "scale": "GetScaleFactor",
    "kind": "GetSensorKind",
}
COMMON_GETS = {"state": "GetState", "profile": "GetProfile", "time": "GetTime"}
READ_NAMES = sorted({*MOTOR_GETS, *SENSOR_GETS, *COMMON_GETS})
_FUNCTION = re.compile(r"(Get|Is|HalGet|SensorGet)[A-Z][A-Za-z0-9]*")

SETS = {
    "position": ("SetPosition", "position"),
    "speed": ("SetSpeed", "speed"),
    "torque": ("SetTorque", "torque"),
    "mode": ("SetControlMode", "mode"),
}
MODES = {"READY_TO_CONTROL": 0, "POSITION": 1, "SPEED": 2, "TORQUE": 3}


# -- options ----------------------------------------------------------------------------


def add_connection(parser: argparse.ArgumentParser, *, json_help: str | None = None) -> None:
    """The options every command of the shell takes."""
    group = parser.add_argument_group("connection")
    group.add_argument(
        "--connect",
        action="append",
        metavar="ENDPOINT",
        help="a server's endpoint (default tcp/127.0.0.1:7447, serve's; repeatable)",
    )
    group.add_argument(
        "--config", metavar="FILE", help="Zenoh JSON5 configuration (replaces the safe defaults)"
    )
    group.add_argument(
        "--namespace",
        metavar="NS",
        help="the rig's namespace (default: every one served; a NAME may also say NS/NAME)",
    )
    group.add_argument(
        "--timeout",
        type=float,
        default=2.0,
        metavar="S",
        help="seconds to wait for the servers, then for each reply (default 2)",
    )
    if json_help is not None:
        parser.add_argument("--json", action="store_true", help=json_help)


def check_connection(prog: str, args: argparse.Namespace) -> bool:
    """True when the connection options are usable (else a line on standard error)."""
    try:
        if args.namespace is not None:
            check_chunk("--namespace", args.namespace)
        if not (args.timeout > 0 and math.isfinite(args.timeout)):
            raise BadParameterError("--timeout", args.timeout, "a number of seconds > 0")
        for endpoint in args.connect or ():
            if "/" not in endpoint:
                raise BadParameterError(
                    "--connect", endpoint, "a Zenoh endpoint like tcp/127.0.0.1:7447"
                )
    except BadParameterError as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return False
    return not (args.config and no_such_file(prog, args.config))


def where(args: argparse.Namespace) -> str:
    from .config import DEFAULT_ENDPOINT

    return str(args.config or ", ".join(args.connect or [DEFAULT_ENDPOINT]))


def session_config(args: argparse.Namespace) -> zenoh.Config:
    from .config import DEFAULT_ENDPOINT, client_config, file_config

    return (
        file_config(args.config)
        if args.config
        else client_config(args.connect or [DEFAULT_ENDPOINT])
    )


def run_shell(
    prog: str,
    args: argparse.Namespace,
    main: Callable[[RigShell, argparse.Namespace], Awaitable[int]],
) -> int:
    """Open a :class:`RigShell` for ``args``, run ``main`` in it, map the failures to exit
    statuses (the options were checked already)."""
    import anyio
    import zenoh

    from .shell import NoRigError, RigShell

    try:
        config = session_config(args)
    except (BadParameterError, zenoh.ZError) as exc:
        print(f"{prog}: {args.config}: {exc}", file=sys.stderr)
        return EXIT_USAGE

    async def body() -> int:
        async with RigShell(
            config, namespace=args.namespace, timeout=args.timeout, where=where(args)
        ) as shell:
            return await main(shell, args)

    try:
        return anyio.run(body, backend="asyncio")
    except zenoh.ZError as exc:
        print(f"{prog}: no Zenoh session for {where(args)}: {exc}", file=sys.stderr)
    except NoRigError as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
    except BadParameterError as exc:  # a NAME that no served rig has
        print(f"{prog}: {exc}", file=sys.stderr)
    except (TimeoutError, NotConnectedError) as exc:
        print(f"{prog}: no reply from {where(args)}: {exc}", file=sys.stderr)
    except HALError as exc:
        print(f"{prog}: {describe_error(exc)}", file=sys.stderr)
        return EXIT_FAILED
    return EXIT_NOT_FOUND


def describe_error(exc: HALError) -> str:
    return f"{exc.code.name}: {exc}"


def emit_json(value: object) -> None:
    print(json.dumps(value), flush=True)


def plain_value(value: object) -> object:
    """A result's value for JSON (bytes as hex)."""
    if isinstance(value, tuple):
        return [plain_value(v) for v in value]
    return value.hex() if isinstance(value, bytes) else value


def text_value(value: object) -> str:
    if isinstance(value, list | tuple):
        return " ".join(text_value(v) for v in value)
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, bytes):
        return value.hex()
    return str(value)


def results_dict(results: ResultList) -> dict[str, object]:
    """Every result but ``return_code``, by name."""
    return {p.name: plain_value(p.value) for p in results.parameters if p.name != "return_code"}


# -- ls ---------------------------------------------------------------------------------------


def add_ls_parser(sub: SubParsers) -> argparse.ArgumentParser:
    parser: argparse.ArgumentParser = sub.add_parser(
        "ls",
        help="list the live components of every served rig: state, kind, HALId",
        description="List the components of every rig served by 'openel-async serve' (the "
        "namespaces are discovered; --namespace picks one): name, surface address "
        "(Kind[logical id]), state and HALId (device kind, vendor, product, instance). "
        "Exit status: 0 listed, 1 no rig served, 2 usage error.",
    )
    add_connection(parser, json_help="one JSON document: namespace -> its components")
    return parser


def run_ls(args: argparse.Namespace) -> int:
    prog = "openel-async ls"
    if not check_connection(prog, args):
        return EXIT_USAGE
    return run_shell(prog, args, ls_main)


async def ls_main(shell: RigShell, args: argparse.Namespace) -> int:
    import anyio

    from .shell import Target

    listing = await shell.listing()
    targets = [Target(space, info) for space, infos in listing.items() for info in infos]
    profiles: dict[int, dict[str, object]] = {}

    async def profile(index: int, target: Target) -> None:
        try:
            profiles[index] = results_dict(await shell.call(target, "GetProfile"))
        except HALError:  # listed without its HALId
            profiles[index] = {}

    lifecycles: dict[tuple[str, str], str] = {}

    async def lifecycle(space: str) -> None:
        try:
            reply = await shell.lifecycle(space, "get")
        except (HALError, TimeoutError):  # a server without a lifecycle: listed without
            return
        for state in reply.components:
            lifecycles[space, state.name] = state.state

    async with anyio.create_task_group() as tg:
        for index, target in enumerate(targets):
            tg.start_soon(profile, index, target)
        for space in listing:
            tg.start_soon(lifecycle, space)
    rows = [(t, profiles[i]) for i, t in enumerate(targets)]
    if args.json:
        emit_json(
            {
                space: [
                    {
                        "name": t.name,
                        "kind": t.kind,
                        "logical_id": t.logical_id,
                        "state": t.info.state,
                        "lifecycle": lifecycles.get((space, t.name)),
                        "hal_id": hal_id_dict(p),
                    }
                    for t, p in rows
                    if t.namespace == space
                ]
                for space in listing
            }
        )
        return 0
    for space, infos in listing.items():
        print(f"{space}: {len(infos)} component{'s' if len(infos) != 1 else ''}", flush=False)
        table = [("NAME", "ADDRESS", "STATE", "LIFECYCLE", "HALID (kind:vendor:product:instance)")]
        table += [
            (
                t.name,
                t.address,
                t.info.state,
                lifecycles.get((space, t.name), "-"),
                hal_id_text(p),
            )
            for t, p in rows
            if t.namespace == space
        ]
        widths = [max(len(row[i]) for row in table) for i in range(4)]
        for row in table:
            print(
                "  "
                + "  ".join(c.ljust(w) for c, w in zip(row[:4], widths, strict=True))
                + "  "
                + row[4]
            )
    sys.stdout.flush()
    return 0


_HAL_ID = ("device_kind_id", "vendor_id", "product_id", "instance_id")


def hal_id_dict(profile: Mapping[str, object]) -> dict[str, object] | None:
    if not all(key in profile for key in _HAL_ID):
        return None
    return {key: profile[key] for key in _HAL_ID}


def hal_id_text(profile: Mapping[str, object]) -> str:
    ids = hal_id_dict(profile)
    if ids is None:
        return "-"
    kind, vendor, product, instance = (int(cast_int(ids[key])) for key in _HAL_ID)
    return f"0x{kind:X}:0x{vendor:X}:0x{product:X}:{instance}"


def cast_int(value: object) -> int:
    return value if isinstance(value, int) else 0


# -- get --------------------------------------------------------------------------------------


def add_get_parser(sub: SubParsers) -> argparse.ArgumentParser:
    parser: argparse.ArgumentParser = sub.add_parser(
        "get",
        help="read a served component: position, values, state, profile...",
        description="Read a component of a served rig (one command message through the "
        "surface layer) and print its results, one 'NAME result value' line each. REQUEST: "
        f"{', '.join(READ_NAMES)} (default: position for a Motor, values for a sensor), or a "
        "function name of the surface layer (GetLatitude, IsStale...). Exit status: 0 read, 1 "
        "no such rig or component (or no reply), 2 usage error, 3 the component refused.",
    )
    parser.add_argument("name", metavar="NAME", help="the component: MOTOR_1, Motor[0], NS/MOTOR_1")
    parser.add_argument("request", metavar="REQUEST", nargs="?", help="what to read")
    add_connection(parser, json_help="print one JSON object: name, function and results")
    return parser


def check_read(prog: str, request: str | None) -> bool:
    if request is None or request in READ_NAMES or _FUNCTION.fullmatch(request):
        return True
    print(
        f"{prog}: REQUEST={request!r} is not allowed: expected one of {', '.join(READ_NAMES)} "
        "or a Get* function name",
        file=sys.stderr,
    )
    return False


def read_function(target: Target, request: str | None) -> str:
    """The function that reads ``request`` of ``target``; BadParameterError when its kind
    has no such short name."""
    table = {**(MOTOR_GETS if target.is_motor else SENSOR_GETS), **COMMON_GETS}
    if request is None:
        return "GetPosition" if target.is_motor else "GetValueOfMeasurement"
    if _FUNCTION.fullmatch(request):
        return request
    found = table.get(request)
    if found is None:
        raise BadParameterError(
            "REQUEST", request, f"for a {target.kind}: {', '.join(sorted(table))}"
        )
    return found


def run_get(args: argparse.Namespace) -> int:
    prog = "openel-async get"
    if not check_connection(prog, args) or not check_read(prog, args.request):
        return EXIT_USAGE
    return run_shell(prog, args, get_main)


async def get_main(shell: RigShell, args: argparse.Namespace) -> int:
    target = await shell.target(args.name)
    function = read_function(target, args.request)
    results = results_dict(await shell.call(target, function))
    if args.json:
        emit_json({**identity(target), "function": function, "results": results})
    else:
        for key, value in results.items():
            print(f"{target.name} {key} {text_value(value)}")
    return 0


def identity(target: Target) -> dict[str, object]:
    return {
        "namespace": target.namespace,
        "name": target.name,
        "kind": target.kind,
        "logical_id": target.logical_id,
    }


# -- set --------------------------------------------------------------------------------------


def add_set_parser(sub: SubParsers) -> argparse.ArgumentParser:
    parser: argparse.ArgumentParser = sub.add_parser(
        "set",
        help="command a served actuator: position, speed, torque or control mode",
        description="Command an actuator of a served rig (SetPosition, SetSpeed, SetTorque or "
        "SetControlMode through the surface layer). Prints ACCEPTED once the component took "
        "the command, or, with --wait, COMPLETED when it ended well (else the status it ended "
        "with). Exit status: 0 accepted (completed), 1 no such rig or component (or no reply), "
        "2 usage error, 3 refused, or ended with an error or not within --wait-timeout.",
    )
    parser.add_argument("name", metavar="NAME", help="the actuator: MOTOR_1, Motor[0], NS/MOTOR_1")
    parser.add_argument(
        "value",
        metavar="VALUE",
        help="the target (the Motor's units: rad, rad/s, N m by default); for --request mode "
        "0-3 or READY_TO_CONTROL, POSITION, SPEED, TORQUE",
    )
    parser.add_argument(
        "--request",
        choices=sorted(SETS),
        default="position",
        help="what VALUE sets (default position)",
    )
    parser.add_argument(
        "--tm-acc",
        type=float,
        metavar="S",
        help="--request speed: seconds to reach the speed (a Motor's tmAcc)",
    )
    parser.add_argument("--wait", action="store_true", help="wait for the command to complete")
    parser.add_argument(
        "--wait-timeout",
        type=float,
        default=30.0,
        metavar="S",
        help="with --wait: the longest wait for completion (default 30)",
    )
    add_connection(parser, json_help="print one JSON object: the command and its status")
    return parser


def set_arguments(args: argparse.Namespace) -> dict[str, object]:
    """The command's arguments from VALUE and the options; BadParameterError if unusable."""
    function, name = SETS[args.request]
    text = args.value.strip()
    value: object
    if args.request == "mode":
        if text.upper() in MODES:
            value = MODES[text.upper()]
        else:
            try:
                value = int(text, 0)
            except ValueError:
                value = None
            if value not in MODES.values():
                raise BadParameterError(
                    "VALUE", args.value, f"a control mode: 0-3 or {', '.join(MODES)}"
                )
    else:
        try:
            value = float(text)
        except ValueError:
            raise BadParameterError("VALUE", args.value, f"a number ({name})") from None
        if not math.isfinite(value):
            raise BadParameterError("VALUE", args.value, "a finite number")
    arguments: dict[str, object] = {name: value}
    if args.tm_acc is not None:
        if args.request != "speed":
            raise BadParameterError("--tm-acc", args.tm_acc, "only with --request speed")
        if not (math.isfinite(args.tm_acc) and args.tm_acc >= 0):
            raise BadParameterError("--tm-acc", args.tm_acc, "seconds >= 0")
        arguments["tmAcc"] = float(args.tm_acc)
    if not (args.wait_timeout > 0 and math.isfinite(args.wait_timeout)):
        raise BadParameterError("--wait-timeout", args.wait_timeout, "a number of seconds > 0")
    del function
    return arguments


def run_set(args: argparse.Namespace) -> int:
    prog = "openel-async set"
    if not check_connection(prog, args):
        return EXIT_USAGE
    try:
        args.arguments = set_arguments(args)
    except BadParameterError as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return EXIT_USAGE
    return run_shell(prog, args, set_main)


async def set_main(shell: RigShell, args: argparse.Namespace) -> int:
    target = await shell.target(args.name)
    function = SETS[args.request][0]
    return await send_set(shell, target, function, args.arguments, args)


async def send_set(
    shell: RigShell,
    target: Target,
    function: str,
    arguments: Mapping[str, object],
    args: argparse.Namespace,
) -> int:
    """Send one Set* command, print its outcome; the exit status."""
    from .shell import NotCompletedError

    record: dict[str, Any] = {
        **identity(target),
        "function": function,
        "arguments": dict(arguments),
    }
    try:
        command_id, status = await shell.command(
            target, function, arguments, wait=args.wait_timeout if args.wait else None
        )
    except NotCompletedError as exc:
        return outcome(args, record, "TIMEOUT", str(exc), EXIT_FAILED)
    except HALError as exc:
        return outcome(args, record, exc.code.name, str(exc), EXIT_FAILED)
    record["command_id"] = command_id
    if status < 0:
        return outcome(args, record, "ACCEPTED", "", 0)
    if status == 0:
        return outcome(args, record, "COMPLETED", "", 0)
    name = ReturnCode(status).name if status in ReturnCode._value2member_map_ else str(status)
    return outcome(args, record, name, f"ended with {name}", EXIT_FAILED)


def outcome(
    args: argparse.Namespace, record: dict[str, Any], status: str, message: str, code: int
) -> int:
    if args.json:
        emit_json({**record, "status": status, "message": message})
    elif code == 0:
        print(status, flush=True)
    else:
        print(
            f"openel-async {args.command}: {record['name']}: {status}: {message}", file=sys.stderr
        )
    return code


# -- reset ------------------------------------------------------------------------------------


def add_reset_parser(sub: SubParsers) -> argparse.ArgumentParser:
    parser: argparse.ArgumentParser = sub.add_parser(
        "reset",
        help="recover a served component from Error (ReInit), print its state",
        description="ReInit a component of a served rig (the surface layer's Reset; the RTC "
        "lifecycle's reset): from Error back to Active, INACTIVE (no torque until 'openel-async "
        "activate') where the server serves the lifecycle; refused while the rig's e-stop is latched ('openel-async estop "
        "--release' first). A component that is not in Error is left as it is. Prints "
        "'NAME STATE'. Exit status: 0 Active, 1 no such rig or component (or no reply), 2 "
        "usage error, 3 refused or failed.",
    )
    parser.add_argument("name", metavar="NAME", help="the component: MOTOR_1, Motor[0], NS/MOTOR_1")
    add_connection(parser, json_help="print one JSON object: name, state, error_id, message")
    return parser


def run_reset(args: argparse.Namespace) -> int:
    prog = "openel-async reset"
    if not check_connection(prog, args):
        return EXIT_USAGE
    return run_shell(prog, args, reset_main)


async def reset_main(shell: RigShell, args: argparse.Namespace) -> int:
    target = await shell.target(args.name)
    before = results_dict(await shell.call(target, "GetState"))
    failure = ""
    if before.get("state") == "Error":
        try:
            await shell.call(target, "Reset")
        except HALError as exc:
            failure = describe_error(exc)
    after = results_dict(await shell.call(target, "GetState"))
    lifecycle = await lifecycle_state(shell, target)
    if args.json:
        emit_json(
            {
                **identity(target),
                **after,
                "lifecycle": lifecycle,
                "reset": before.get("state") == "Error",
                "failure": failure,
            }
        )
    else:
        note = "" if before.get("state") == "Error" else " (not in Error: nothing to reset)"
        if lifecycle == "INACTIVE" and not note:
            note = " INACTIVE (no torque: 'openel-async activate' to command it)"
        elif lifecycle is not None and not note:
            note = f" {lifecycle}"
        print(f"{target.name} {after.get('state')}{note}", flush=True)
        if failure:
            print(f"openel-async reset: {target.name}: {failure}", file=sys.stderr)
    return EXIT_FAILED if failure or after.get("state") != "Active" else 0


async def lifecycle_state(shell: RigShell, target: Target) -> str | None:
    """The RTC lifecycle state of ``target`` (None: its server has no lifecycle)."""
    try:
        reply = await shell.lifecycle(target.namespace, "get", [target.name])
    except (HALError, TimeoutError):
        return None
    return next((s.state for s in reply.components if s.name == target.name), None)


# -- watch ------------------------------------------------------------------------------------


def add_watch_parser(sub: SubParsers) -> argparse.ArgumentParser:
    parser: argparse.ArgumentParser = sub.add_parser(
        "watch",
        help="print a served component's values, events and errors as they come",
        description="Watch components of a served rig: their values read --rate times a "
        "second (position for a Motor, values for a sensor, or --request), their events "
        "(COMPLETED, LIMIT_REACHED...) and errors as the server sends them. One line each: "
        "seconds since the start, name, type (value, event, error), what and value. Runs "
        "until Ctrl-C (exit status 130) or --duration.",
    )
    parser.add_argument("names", metavar="NAME", nargs="+", help="components: MOTOR_1, Motor[0]")
    parser.add_argument(
        "--request", metavar="REQUEST", help=f"what to read: {', '.join(READ_NAMES)} or Get*"
    )
    parser.add_argument(
        "--rate",
        type=float,
        default=10.0,
        metavar="HZ",
        help="reads a second (default 10; 0: none)",
    )
    parser.add_argument(
        "--duration", type=float, metavar="S", help="stop after this many seconds (default: Ctrl-C)"
    )
    formats = parser.add_mutually_exclusive_group()
    formats.add_argument("--csv", action="store_true", help="CSV with a header line, for scripts")
    formats.add_argument("--json", action="store_true", help="one JSON object a line, for scripts")
    add_connection(parser)
    return parser


def run_watch(args: argparse.Namespace) -> int:
    prog = "openel-async watch"
    if not check_connection(prog, args) or not check_read(prog, args.request):
        return EXIT_USAGE
    problem = None
    if not (0 <= args.rate <= 1000 and math.isfinite(args.rate)):
        problem = f"--rate={args.rate!r} is not allowed: expected 0 to 1000 reads a second"
    elif args.duration is not None and not (args.duration > 0 and math.isfinite(args.duration)):
        problem = f"--duration={args.duration!r} is not allowed: expected seconds > 0"
    if problem:
        print(f"{prog}: {problem}", file=sys.stderr)
        return EXIT_USAGE
    return run_shell(prog, args, watch_main)


class WatchOutput:
    """The lines of ``watch``: text, CSV or JSON."""

    FIELDS = ("t", "namespace", "name", "type", "what", "value")

    def __init__(self, mode: str) -> None:
        self.mode = mode
        self.start = time.monotonic()
        self.rows = 0
        self._csv = csv.writer(sys.stdout, lineterminator="\n") if mode == "csv" else None
        if self._csv is not None:
            self._csv.writerow(self.FIELDS)
            sys.stdout.flush()

    def emit(self, target: Target, kind: str, what: str, value: object) -> None:
        t = round(time.monotonic() - self.start, 4)
        self.rows += 1
        if self._csv is not None:
            text = value if isinstance(value, str) else json.dumps(value)
            self._csv.writerow((f"{t:.4f}", target.namespace, target.name, kind, what, text))
        elif self.mode == "json":
            print(
                json.dumps(
                    {
                        "t": t,
                        "namespace": target.namespace,
                        "name": target.name,
                        "type": kind,
                        "what": what,
                        "value": value,
                    }
                ),
                end="\n",
            )
        else:
            print(f"{t:9.3f}  {target.name:<12} {kind:<5}  {what:<10} {text_value(value)}")
        sys.stdout.flush()


async def watch_main(shell: RigShell, args: argparse.Namespace) -> int:
    import anyio

    from openel_async.surface import ApplicationQueue, ErrorNotification, EventNotification

    targets = await shell.targets(args.names)
    out = WatchOutput("csv" if args.csv else "json" if args.json else "text")
    functions = [read_function(t, args.request) for t in targets]
    by_name = {(t.namespace, t.name): t for t in targets}
    spaces = sorted({t.namespace for t in targets})

    async def notices(space: str) -> None:
        remote = await shell.remote(space)
        app = ApplicationQueue(4096, name=f"watch-{space}")
        remote.attach(app)
        for kind in sorted({t.kind for t in targets if t.namespace == space}):
            await remote.subscribe(kind, "*", app)
        while True:
            notice = await app.get()
            if isinstance(notice, EventNotification):
                detail = remote.cached_event_detail(notice.event_id)
                kind, what, extra = "event", notice.event_type, ""
            elif isinstance(notice, ErrorNotification):
                detail = remote.cached_error_detail(notice.error_id)
                kind, what = "error", notice.error_type
                message = detail.get("message") if detail is not None else None
                extra = str(message.value) if message is not None else ""
            else:
                continue
            name = detail.get("device_name") if detail is not None else None
            target = by_name.get((space, str(name.value))) if name is not None else None
            if target is not None:
                out.emit(target, kind, what, extra)

    async def read(target: Target, function: str, last: dict[str, str]) -> None:
        try:
            results = results_dict(await shell.call(target, function))
        except (HALError, TimeoutError) as exc:
            text = describe_error(exc) if isinstance(exc, HALError) else str(exc)
            if last.get(target.name) != text:  # a failing read is told once, until it changes
                last[target.name] = text
                out.emit(target, "error", "read", text)
            return
        last.pop(target.name, None)
        for key, value in results.items():
            if key != "time_ns":
                out.emit(target, "value", key, value)

    async def poll() -> None:
        period = 1.0 / args.rate
        failing: dict[str, str] = {}
        deadline = anyio.current_time()
        while True:
            async with anyio.create_task_group() as tg:
                for target, function in zip(targets, functions, strict=True):
                    tg.start_soon(read, target, function, failing)
            deadline = max(deadline + period, anyio.current_time())
            await anyio.sleep_until(deadline)

    with anyio.move_on_after(args.duration if args.duration is not None else math.inf):
        async with anyio.create_task_group() as tg:
            for space in spaces:
                tg.start_soon(notices, space)
            if args.rate > 0:
                tg.start_soon(poll)
    return 0


LS = CliCommand("ls", add_ls_parser, run_ls)
"""``openel-async ls``."""
GET = CliCommand("get", add_get_parser, run_get)
"""``openel-async get``."""
SET = CliCommand("set", add_set_parser, run_set)
"""``openel-async set``."""
RESET = CliCommand("reset", add_reset_parser, run_reset)
"""``openel-async reset``."""
WATCH = CliCommand("watch", add_watch_parser, run_watch)
"""``openel-async watch``."""
