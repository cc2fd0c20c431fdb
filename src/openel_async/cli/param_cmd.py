"""``openel-async param get|set|dump|list RIG.yaml NAME [PARAM] [VALUE]``: read and write one
device's own parameters (a CANopen drive's objects, an ODrive's endpoints, a servo's
control table) by name or address, with their types, access, units and storage
(:mod:`openel_async.params`; each driver's bus kind offers them).

Only the named device's bus is opened (``--sim``: against a simulated peer of that device);
no component is built, so nothing is initialized, enabled, moved or stopped: the device is
left as it was found. Every option and the rig file are checked before anything is opened
(exit status 2); an unknown parameter is refused (2) with the close names; a write to
EEPROM asks on a terminal (``--yes`` for scripts; neither: refused, 2); a write that needs
the torque off first (a Dynamixel's EEPROM) asks for that too (``--torque-off``). Each
exchange is bounded by ``--timeout``; no answer: exit status 1. Ctrl-C: 130."""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from collections.abc import Sequence
from functools import partial
from typing import TYPE_CHECKING, Any

from .options import EXIT_USAGE, no_such_file

if TYPE_CHECKING:
    from ..params import ParameterAccess, ParameterInfo, ParamValue
    from ..rig.single import OpenedDevice

__all__ = ["add_parser", "run", "value_json"]

PROG = "openel-async param"
EXIT_DEVICE = 1
DEFAULT_TIMEOUT = 1.0
PROMPT_TIMEOUT = 120.0
DUMP_GIVE_UP = 3
"""``dump`` stops after this many reads in a row got no answer (the device is gone)."""

PARAM_HELP = (
    "read and write a device's parameters (CANopen objects, ODrive endpoints, servo tables)"
)
PARAM_DESCRIPTION = """\
Read and write one device's own parameters by name or address: a CiA 402 drive's objects
(from its EDS, by name or index: 'Profile velocity', 6081, 0x6081:00), an ODrive axis's
endpoints (axis0.controller.config.vel_limit), a Dynamixel's or Feetech servo's
control-table items (Profile Velocity, Torque_Limit). Values are the device's own numbers,
shown with their unit.

Only that device's bus is opened (--sim: against a simulated peer of it); nothing is
initialized, enabled or moved, and the device is left as it was found. Writes to EEPROM
ask on a terminal (--yes for scripts); a write that needs the torque off first (a
Dynamixel's EEPROM) asks for that too (--torque-off); the torque is then left off.

Every option is checked before anything is opened (exit status 2); an unknown parameter is
refused with the closest names (2); no answer within --timeout: 1; Ctrl-C: 130.
"""


def _common(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("rig", metavar="RIG.yaml", help="the rig file naming the device")
    parser.add_argument("name", metavar="NAME", help="the component (device) of the rig")


def _options(parser: argparse.ArgumentParser, *, write: bool = False) -> None:
    parser.add_argument(
        "--sim",
        action="store_true",
        help="open the device's bus against a simulated peer of the device (same address)",
    )
    parser.add_argument("--json", action="store_true", help="one JSON document, for scripts")
    parser.add_argument(
        "--timeout",
        type=float,
        metavar="S",
        default=DEFAULT_TIMEOUT,
        help=f"seconds each exchange with the device may take (default {DEFAULT_TIMEOUT:g})",
    )
    if write:
        parser.add_argument(
            "--yes",
            action="store_true",
            help="confirm a write to EEPROM without asking (scripts)",
        )
        parser.add_argument(
            "--torque-off",
            action="store_true",
            help="turn the torque off first when the write needs it (a Dynamixel's EEPROM); "
            "the axis goes limp and is left so",
        )


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> argparse.ArgumentParser:
    param = sub.add_parser("param", help=PARAM_HELP, description=PARAM_DESCRIPTION)
    actions = param.add_subparsers(
        title="actions", dest="param_action", required=True, metavar="ACTION"
    )
    get = actions.add_parser("get", help="read one parameter")
    _common(get)
    get.add_argument("parameter", metavar="PARAM", help="its name or address")
    _options(get)
    put = actions.add_parser("set", help="write one parameter (then read it back)")
    _common(put)
    put.add_argument("parameter", metavar="PARAM", help="its name or address")
    put.add_argument(
        "value",
        metavar="VALUE",
        help="the device's own number (0x.. hex), true/false, or text",
    )
    _options(put, write=True)
    dump = actions.add_parser("dump", help="read every readable parameter")
    _common(dump)
    _options(dump)
    table = actions.add_parser(
        "list", help="the parameter table (name, address, type, access, unit), nothing read"
    )
    _common(table)
    _options(table)
    return param


def _error(message: str) -> None:
    print(f"{PROG}: {message}", file=sys.stderr)


def run(args: argparse.Namespace) -> int:
    if not (math.isfinite(args.timeout) and 0 < args.timeout <= 60):
        _error(f"--timeout {args.timeout:g}: seconds > 0 and <= 60")
        return EXIT_USAGE
    if no_such_file(PROG, args.rig):
        return EXIT_USAGE
    from ..errors import BadParameterError
    from ..rig import load_rig, resolve_rig
    from ..rig.single import device_of

    try:
        resolved = resolve_rig(load_rig(args.rig))
        device_of(resolved, args.name)
    except BadParameterError as exc:
        _error(str(exc))
        return EXIT_USAGE

    import anyio

    from ..app import Interrupted, run_interruptible

    out: list[str] = []
    result = anyio.run(run_interruptible, partial(_session, resolved, args, out))
    for line in out:
        print(line)
    if isinstance(result, Interrupted):
        _error(f"interrupted by {result.signum.name}")
        return result.exit_code
    return result


async def _session(resolved: Any, args: argparse.Namespace, out: list[str]) -> int:
    from ..errors import BadParameterError, HALError
    from ..rig.single import open_parameters

    try:
        async with open_parameters(resolved, args.name, sim=args.sim) as opened:
            action = args.param_action
            if action == "list":
                return _list(opened, args, out)
            if action == "dump":
                return await _dump(opened, args, out)
            info = opened.access.parameter(args.parameter)
            if action == "get":
                return await _get(opened, info, args, out)
            return await _set(opened, info, args, out)
    except BadParameterError as exc:
        _error(str(exc))
        return EXIT_USAGE
    except TimeoutError as exc:
        _error(f"{args.name}: no answer within {args.timeout:g} s ({exc or 'timeout'})")
        return EXIT_DEVICE
    except (HALError, OSError) as exc:
        _error(f"{args.name}: {exc}")
        return EXIT_DEVICE


# -- the actions --------------------------------------------------------------------------------


def _info_json(info: ParameterInfo) -> dict[str, Any]:
    return {
        "name": info.name,
        "address": info.address,
        "type": info.type,
        "access": info.access,
        "unit": info.unit,
        "scale": info.scale,
        "storage": info.storage,
        "description": info.description,
    }


def value_json(value: ParamValue) -> Any:
    """A JSON value: bytes as hex, a float NaN or infinity as the string "nan", "inf" or
    "-inf" (JSON has no such numbers; ``json.dumps`` would write invalid JSON)."""
    if isinstance(value, bytes):
        return value.hex()
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    return value


def _header(opened: OpenedDevice) -> str:
    return f"{opened.name}: {opened.access.source} ({opened.description})"


def _list(opened: OpenedDevice, args: argparse.Namespace, out: list[str]) -> int:
    params = opened.access.parameters()
    if args.json:
        document = {
            "component": opened.name,
            "source": opened.access.source,
            "parameters": [_info_json(p) for p in params],
        }
        out.append(json.dumps(document, indent=2, allow_nan=False))
        return 0
    out.append(_header(opened))
    rows = [
        (p.address, p.name, p.type, p.access, p.storage, p.unit if p.unit else "") for p in params
    ]
    out.extend(_table(("ADDRESS", "NAME", "TYPE", "ACCESS", "STORAGE", "UNIT"), rows))
    return 0


async def _read(access: ParameterAccess, info: ParameterInfo, timeout: float) -> ParamValue:  # noqa: ASYNC109
    import anyio

    with anyio.fail_after(timeout):
        return await access.read(info)


async def _get(
    opened: OpenedDevice, info: ParameterInfo, args: argparse.Namespace, out: list[str]
) -> int:
    from ..params import format_value

    if not info.readable:
        _error(f"{info.name} ({info.address}) is write-only: nothing to read")
        return EXIT_USAGE
    value = await _read(opened.access, info, args.timeout)
    if args.json:
        document = {
            "component": opened.name,
            "parameter": _info_json(info),
            "value": value_json(value),
            "shown": format_value(info, value),
        }
        out.append(json.dumps(document, indent=2, allow_nan=False))
        return 0
    out.append(f"{opened.name} {info.name} = {format_value(info, value)}")
    out.append(f"  {_facts(info)}")
    return 0


def _facts(info: ParameterInfo) -> str:
    facts = f"{info.address}, {info.type}, {info.access}, {info.storage}"
    return facts + (f": {info.description}" if info.description else "")


async def _dump(opened: OpenedDevice, args: argparse.Namespace, out: list[str]) -> int:
    from ..errors import HALError
    from ..params import format_value

    records: list[dict[str, Any]] = []
    rows: list[tuple[str, ...]] = []
    silent = 0
    for info in opened.access.parameters():
        if not info.readable:
            continue
        try:
            value = await _read(opened.access, info, args.timeout)
        except TimeoutError:
            silent += 1
            records.append({**_info_json(info), "error": "no answer"})
            rows.append((info.address, info.name, info.type, info.access, "(no answer)"))
            if silent >= DUMP_GIVE_UP:
                _error(f"{opened.name}: {silent} reads in a row got no answer: stopped")
                _emit_dump(opened, args, out, records, rows)
                return EXIT_DEVICE
            continue
        except HALError as exc:  # an SDO abort, a status error: that parameter only
            silent = 0
            records.append({**_info_json(info), "error": str(exc)})
            rows.append((info.address, info.name, info.type, info.access, f"({exc})"))
            continue
        silent = 0
        records.append({**_info_json(info), "value": value_json(value)})
        rows.append((info.address, info.name, info.type, info.access, format_value(info, value)))
    _emit_dump(opened, args, out, records, rows)
    return 0


def _emit_dump(
    opened: OpenedDevice,
    args: argparse.Namespace,
    out: list[str],
    records: list[dict[str, Any]],
    rows: list[tuple[str, ...]],
) -> None:
    if args.json:
        document = {"component": opened.name, "source": opened.access.source, "parameters": records}
        out.append(json.dumps(document, indent=2, allow_nan=False))
        return
    out.append(_header(opened))
    out.extend(_table(("ADDRESS", "NAME", "TYPE", "ACCESS", "VALUE"), rows))


async def _set(
    opened: OpenedDevice, info: ParameterInfo, args: argparse.Namespace, out: list[str]
) -> int:
    import anyio

    from ..params import format_value, parse_value

    if not info.writable:
        _error(f"{info.name} ({info.address}) is {info.access}: it cannot be written")
        return EXIT_USAGE
    if info.command:
        _error(
            f"{info.name} ({info.address}) is a command (it would enable, move or stop the "
            "device): param only reads it; the HAL commands it (openel-async jog, an app)"
        )
        return EXIT_USAGE
    value = parse_value(info, args.value)
    if info.storage == "eeprom" and not args.yes:
        question = (
            f"write {info.name} = {format_value(info, value)} to the EEPROM of {opened.name} "
            "(kept at power-off)?"
        )
        if not await _confirm(question, "--yes"):
            return EXIT_USAGE
    with anyio.fail_after(args.timeout):
        blocker = await opened.access.write_blocker(info)
    if (
        blocker is not None
        and not args.torque_off
        and not await _confirm(
            f"{blocker}: turn it off first (the axis goes limp)?", "--torque-off"
        )
    ):
        return EXIT_USAGE
    before = await _read(opened.access, info, args.timeout) if info.readable else None
    with anyio.fail_after(args.timeout):
        await opened.access.write(info, value, unblock=blocker is not None)
    after = await _read(opened.access, info, args.timeout) if info.readable else None
    if args.json:
        document = {
            "component": opened.name,
            "parameter": _info_json(info),
            "before": None if before is None else value_json(before),
            "written": value_json(value),
            "after": None if after is None else value_json(after),
            "torque_turned_off": blocker is not None,
        }
        out.append(json.dumps(document, indent=2, allow_nan=False))
    else:
        was = "" if before is None else f"{format_value(info, before)} -> "
        now = format_value(info, value if after is None else after)
        out.append(f"{opened.name} {info.name}: {was}{now}")
        out.append(f"  {_facts(info)}")
        if blocker is not None:
            out.append(f"  the torque was turned off first and is left off ({blocker})")
    if after is not None and after != value and not _close(after, value):
        _error(f"{info.name} reads {format_value(info, after)} after writing {args.value}")
        return EXIT_DEVICE
    return 0


def _close(a: ParamValue, b: ParamValue) -> bool:
    """Equal as the device stores it (a float32 endpoint keeps 7 digits)."""
    if isinstance(a, float | int) and isinstance(b, float | int):
        return math.isclose(float(a), float(b), rel_tol=1e-6, abs_tol=1e-9)
    return False


async def _confirm(question: str, flag: str) -> bool:
    """Ask on the terminal (bounded); refuse without one, saying which flag answers."""
    import anyio

    if not (sys.stdin.isatty() and sys.stderr.isatty()):
        _error(f"refused: {question.rstrip('?')} needs a yes: give {flag} (no terminal to ask on)")
        return False
    print(f"{question} [y/N] ", end="", file=sys.stderr, flush=True)
    answer = b""
    with anyio.move_on_after(PROMPT_TIMEOUT):
        fd = sys.stdin.fileno()
        while not answer.endswith(b"\n"):
            await anyio.wait_readable(fd)
            chunk = os.read(fd, 256)
            if not chunk:
                break
            answer += chunk
    if answer.strip().lower() in (b"y", b"yes"):
        return True
    _error(f"not written (answer 'y' to write, or give {flag})")
    return False


def _table(header: tuple[str, ...], rows: Sequence[tuple[str, ...]]) -> list[str]:
    widths = [
        max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in enumerate(header)
    ]
    widths[-1] = 0  # the last column is not padded
    lines = ["  ".join(h.ljust(w) for h, w in zip(header, widths, strict=True)).rstrip()]
    lines += ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in rows]
    return lines
