"""``openel-async hal4rt``: HAL4RT XML messages (spec §7.5.3).

- ``validate FILE.xml...``: check each file against the schema and the data types;
- ``show FILE.xml``: print the message as a readable tree;
- ``schema``: print the shipped XSD (the spec's, typos fixed);
- ``exec FILE.xml``: send a ``<Device>`` message to a running ``openel-async serve`` and
  print the reply as XML.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import anyio

from ..errors import BadParameterError, HALError
from ..surface import xml_psm
from ..surface.messages import (
    ArgumentList,
    CommandMessage,
    DataType,
    Device,
    Message,
    Parameter,
    ResultList,
)


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    hal4rt = sub.add_parser("hal4rt", help="validate, show or execute HAL4RT XML messages")
    actions = hal4rt.add_subparsers(dest="hal4rt_command", required=True)
    validate = actions.add_parser(
        "validate", help="validate XML messages against the HAL4RT schema"
    )
    validate.add_argument("files", nargs="+", metavar="FILE.xml")
    show = actions.add_parser("show", help="print a message as a tree")
    show.add_argument("file", metavar="FILE.xml")
    actions.add_parser("schema", help="print the shipped XML schema")
    execute = actions.add_parser(
        "exec", help="send a <Device> message to a server and print the reply"
    )
    execute.add_argument("file", metavar="FILE.xml", help="the message ('-' for standard input)")
    execute.add_argument(
        "--connect",
        action="append",
        metavar="ENDPOINT",
        help="server endpoint (default tcp/127.0.0.1:7447)",
    )
    execute.add_argument(
        "--config", metavar="FILE", help="Zenoh JSON5 configuration (replaces the safe defaults)"
    )
    execute.add_argument("--namespace", default="default")
    execute.add_argument("--timeout", type=float, default=2.0, help="seconds to wait for the reply")


def run(args: argparse.Namespace) -> int:
    command = args.hal4rt_command
    if command == "validate":
        return _validate(args.files)
    if command == "schema":
        print(xml_psm.schema_text(), end="")
        return 0
    if command == "show":
        message = _read(args.file)
        if message is None:
            return 1
        print("\n".join(describe(message)))
        return 0
    return _exec(args)


def _load_bytes(name: str) -> bytes:
    return sys.stdin.buffer.read() if name == "-" else Path(name).read_bytes()


def _read(name: str) -> Message | None:
    try:
        return xml_psm.from_xml(_load_bytes(name))
    except (OSError, BadParameterError) as exc:
        print(f"{name}: {exc}", file=sys.stderr)
        return None


def _validate(files: list[str]) -> int:
    failed = 0
    for name in files:
        message = _read(name)
        if message is None:
            failed += 1
        else:
            print(f"{name}: valid {type(message).__name__}")
    return 1 if failed else 0


def _parameter(p: Parameter) -> str:
    try:
        kind = DataType(p.data_type_id).name
    except ValueError:
        kind = str(p.data_type_id)
    return f"{p.name} ({kind}) = {p.value!r}"


def describe(message: Message, indent: str = "") -> list[str]:
    """A readable outline of a message."""
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


def _exec(args: argparse.Namespace) -> int:
    try:
        device = xml_psm.device_from_xml(_load_bytes(args.file))
    except (OSError, BadParameterError) as exc:
        print(f"{args.file}: {exc}", file=sys.stderr)
        return 1
    try:
        reply = anyio.run(_send, device, args, backend="asyncio")
    except (HALError, TimeoutError) as exc:
        print(f"openel-async hal4rt exec: {exc}", file=sys.stderr)
        return 1
    sys.stdout.write(xml_psm.to_xml(reply).decode("utf-8") + "\n")
    codes = [
        c.results.value("return_code")
        for c in reply.commands
        if c.results and c.results.get("return_code")
    ]
    return 0 if all(code == 0 for code in codes) else 3


async def _send(device: Device, args: argparse.Namespace) -> Device:
    from openel_zenoh import RemoteSurface, close_session, open_session
    from openel_zenoh.config import DEFAULT_ENDPOINT, client_config, file_config

    config = (
        file_config(args.config)
        if args.config
        else client_config(args.connect or [DEFAULT_ENDPOINT])
    )
    session = await open_session(config)
    try:
        async with RemoteSurface(
            session, args.namespace, timeout=args.timeout, encoding="xml"
        ) as remote:
            return await remote.execute(device)
    finally:
        await close_session(session)
