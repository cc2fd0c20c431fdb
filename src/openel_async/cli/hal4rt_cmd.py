"""``openel-async hal4rt``: HAL4RT XML messages (spec §7.5.3).

- ``validate FILE.xml...``: check each file against the schema and the data types;
- ``show FILE.xml``: print the message as a readable tree;
- ``schema``: print the shipped XSD (the spec's, typos fixed);
- ``exec FILE.xml``: send a ``<Device>`` message to a running ``openel-async serve`` and
  print the reply as XML -- contributed by the Zenoh driver (``openel_zenoh.commands``,
  entry-point group ``openel_async.commands``, parent ``hal4rt``).
"""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

from .commands import load_bytes
from .options import EXIT_USAGE, no_such_file

if TYPE_CHECKING:
    from ..surface.messages import Message, Parameter

# The surface layer is imported when an action runs: 'openel-async --help' does not load it.


def add_parser(
    sub: argparse._SubParsersAction[argparse.ArgumentParser],
) -> argparse._SubParsersAction[argparse.ArgumentParser]:
    """Add ``hal4rt``; returns its actions, where drivers add theirs (``exec``)."""
    hal4rt = sub.add_parser("hal4rt", help="validate, show or execute HAL4RT XML messages")
    actions = hal4rt.add_subparsers(dest="hal4rt_command", required=True)
    validate = actions.add_parser(
        "validate", help="validate XML messages against the HAL4RT schema"
    )
    validate.add_argument(
        "files", nargs="+", metavar="FILE.xml", help="the messages ('-' for standard input)"
    )
    show = actions.add_parser("show", help="print a message as a tree")
    show.add_argument("file", metavar="FILE.xml", help="the message ('-' for standard input)")
    actions.add_parser("schema", help="print the shipped XML schema")
    return actions


def run(args: argparse.Namespace) -> int:
    command = args.hal4rt_command
    if command == "validate":
        return _validate(args.files)
    if command == "schema":
        from ..surface import xml_psm

        print(xml_psm.schema_text(), end="")
        return 0
    if command == "show":
        if no_such_file("openel-async hal4rt show", args.file):
            return EXIT_USAGE
        message = _read(args.file)
        if message is None:
            return 1
        print("\n".join(describe(message)))
        return 0
    raise AssertionError(f"unknown hal4rt action {command!r}")  # argparse allows no other


def _read(name: str) -> Message | None:
    from ..errors import BadParameterError
    from ..surface import xml_psm

    try:
        return xml_psm.from_xml(load_bytes(name))
    except (OSError, BadParameterError) as exc:
        print(f"{name}: {exc}", file=sys.stderr)
        return None


def _validate(files: list[str]) -> int:
    """Each file valid or not; 1 when one is invalid, 2 when one does not exist."""
    failed = missing = 0
    for name in files:
        if no_such_file("openel-async hal4rt validate", name):
            missing += 1
            continue
        message = _read(name)
        if message is None:
            failed += 1
        else:
            print(f"{name}: valid {type(message).__name__}")
    return EXIT_USAGE if missing else (1 if failed else 0)


def _parameter(p: Parameter) -> str:
    from ..surface.messages import DataType

    try:
        kind = DataType(p.data_type_id).name
    except ValueError:
        kind = str(p.data_type_id)
    value = f'"{p.value}"' if isinstance(p.value, str) else p.value
    return f"{p.name} ({kind}) = {value}"


def describe(message: Message, indent: str = "") -> list[str]:
    """A readable outline of a message."""
    from ..surface.messages import ArgumentList, CommandMessage, Device, ResultList

    if isinstance(message, Device):
        lines = [f"{indent}Device {message.device_kind}"]
        for command in message.commands:
            lines += describe(command, indent + "  ")
        return lines
    if isinstance(message, CommandMessage):
        lines = [f"{indent}{message.function_name} [{message.command_id or '-'}]"]
        if message.arguments is not None:
            lines += [f"{indent}  in  {_parameter(p)}" for p in message.arguments.parameters]
        if message.results is not None:
            lines += [f"{indent}  out {_parameter(p)}" for p in message.results.parameters]
        return lines
    if isinstance(message, ArgumentList | ResultList):
        return [f"{indent}{type(message).__name__}"] + [
            f"{indent}  {_parameter(p)}" for p in message.parameters
        ]
    return [f"{indent}{_parameter(message)}"]
