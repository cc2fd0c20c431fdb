"""``openel-async scan serial`` at work (its parser: :mod:`openel_serial.commands`): the port
named by the options or a rig's serial bus (``--sim``: its simulated servos or receiver on a
pty), scanned (:mod:`openel_serial.scan`), printed as a table or JSON, and with ``--rig-out``
written as a rig file to edit."""

from __future__ import annotations

import argparse
import json
import logging
import sys
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import anyio

from openel_async.cli.commands import EXIT_USAGE, log_level, no_such_file
from openel_async.errors import BadParameterError, HALError

from . import dynamixel as dx
from . import feetech as ft
from .rigbus import (
    DYNAMIXEL_BAUDRATES,
    FEETECH_BAUDRATES,
    NMEA_BAUDRATES,
    SerialBusKind,
    SerialBusOptions,
)
from .scan import DEFAULT_BAUDRATES, Protocol, SerialScan, parse_ids, scan

__all__ = ["PROG", "rig_text", "run"]

PROG = "openel-async scan serial"
EXIT_NOTHING_FOUND = 1
EXIT_FAILED = 1
RATES = {"dynamixel": DYNAMIXEL_BAUDRATES, "feetech": FEETECH_BAUDRATES, "nmea": NMEA_BAUDRATES}
MAX_IDS = {"dynamixel": dx.MAX_ID, "feetech": ft.MAX_ID}


@dataclass(frozen=True)
class Plan:
    """What to scan, checked; nothing opened yet."""

    name: str
    """The bus's name in the rig (``serial0`` without a rig)."""
    protocol: Protocol
    device: str
    baudrates: tuple[int, ...]
    ids: tuple[int, ...]
    rig_options: SerialBusOptions | None = None
    """The rig's bus (``--rig``)."""
    devices: tuple[Any, ...] = ()
    sim: bool = False


def _refuse(message: str) -> None:
    print(f"{PROG}: {message}", file=sys.stderr)


def _plan(args: argparse.Namespace) -> Plan | None:
    """The scan the options describe, or None after saying why not (exit status 2)."""
    if not 0.001 <= args.timeout <= 1.0:
        _refuse(f"--timeout {args.timeout:g}: a number of seconds in 0.001..1")
        return None
    if not 0.1 <= args.listen <= 60.0:
        _refuse(f"--listen {args.listen:g}: a number of seconds in 0.1..60")
        return None
    if args.rig_out is not None and not Path(args.rig_out).resolve().parent.is_dir():
        _refuse(f"--rig-out {args.rig_out}: no such folder")
        return None
    name, devices, options = "serial0", (), None
    if args.rig is None:
        if args.port is None or args.protocol is None:
            _refuse("give --port DEVICE and --protocol (dynamixel, feetech, nmea), or --rig")
            return None
        if args.sim or args.bus is not None:
            _refuse("--sim and --bus go with --rig")
            return None
        protocol, device = args.protocol, args.port
    else:
        if args.port is not None or args.protocol is not None:
            _refuse(
                "--rig takes the port and the protocol from the rig file: no --port, --protocol"
            )
            return None
        if no_such_file(PROG, args.rig):
            return None
        found = _rig_bus(args)
        if found is None:
            return None
        name, options, devices = found
        protocol, device = options.protocol, options.device
    rates = RATES[protocol]
    if args.baud is None:
        baudrates = DEFAULT_BAUDRATES[protocol] if options is None else (options.baudrate,)
    elif args.baud == "all":
        baudrates = tuple(rates)
    else:
        try:
            baudrates = tuple(int(b) for b in args.baud.split(","))
        except ValueError:
            _refuse(f"--baud {args.baud}: baud rates separated by commas, or 'all'")
            return None
        wrong = [b for b in baudrates if b not in rates]
        if wrong:
            _refuse(
                f"--baud {wrong[0]}: not a {protocol} rate; one of {', '.join(map(str, rates))}"
            )
            return None
    ids: tuple[int, ...] = ()
    if protocol != "nmea":
        try:
            ids = parse_ids(args.ids, MAX_IDS[protocol])
        except ValueError as exc:
            _refuse(f"--ids {args.ids}: {exc}")
            return None
    elif args.ids != DEFAULT_IDS:
        _refuse("--ids: an NMEA port has no ids")
        return None
    return Plan(name, protocol, device, baudrates, ids, options, devices, args.sim)


DEFAULT_IDS = "0-252"


def _rig_bus(args: argparse.Namespace) -> tuple[str, SerialBusOptions, tuple[Any, ...]] | None:
    from openel_async.rig import load_rig, resolve_rig

    try:
        resolved = resolve_rig(load_rig(args.rig))
    except BadParameterError as exc:
        _refuse(str(exc))
        return None
    buses = {n: b for n, b in resolved.buses.items() if isinstance(b.options, SerialBusOptions)}
    if args.bus is None:
        if len(buses) != 1:
            _refuse(
                f"{args.rig} has {len(buses)} serial buses ({', '.join(buses) or 'none'}): "
                "say which with --bus"
            )
            return None
        args.bus = next(iter(buses))
    bus = buses.get(args.bus)
    if bus is None:
        _refuse(
            f"--bus {args.bus}: {args.rig} has no serial bus of that name (its serial buses: "
            f"{', '.join(buses) or 'none'})"
        )
        return None
    assert isinstance(bus.options, SerialBusOptions)
    return args.bus, bus.options, tuple(bus.devices)


@asynccontextmanager
async def _port(plan: Plan) -> AsyncIterator[tuple[str, str]]:
    """The port's path (a pty with ``--sim``) and what it is, in words."""
    if not plan.sim or plan.rig_options is None:
        yield plan.device, f"{plan.device} ({plan.protocol})"
        return
    # The simulated devices hear only at the rig's rate: at another one they answer nothing,
    # as real ones do.
    async with SerialBusKind().simulate(plan.name, plan.rig_options, plan.devices) as simulated:
        options = simulated.options
        assert isinstance(options, SerialBusOptions)
        yield options.device, simulated.description


async def _scan(plan: Plan, args: argparse.Namespace) -> tuple[SerialScan, str]:
    async with _port(plan) as (path, description):
        result = await scan(
            path,
            plan.protocol,
            plan.baudrates,
            plan.ids,
            timeout_margin=args.timeout,
            listen=args.listen,
        )
    return result, description


def run(args: argparse.Namespace) -> int:
    plan = _plan(args)
    if plan is None:
        return EXIT_USAGE
    # An id that does not answer is what a scan expects, not a warning of the port's (shown
    # with -v, at the info level).
    ports = logging.getLogger("openel_serial")
    level = ports.level
    if log_level(args) not in ("debug", "info"):
        ports.setLevel(logging.ERROR)
    try:
        result, description = anyio.run(_scan, plan, args)
    except HALError as exc:  # the port cannot be opened, or went away
        print(f"{PROG}: {exc}", file=sys.stderr)
        return EXIT_FAILED
    finally:
        ports.setLevel(level)
    if args.json:
        print(json.dumps({"bus": description, **result.to_dict()}, indent=2))
    else:
        print_table(result, description)
    if args.rig_out is not None:
        if not result.found:
            print(f"nothing found: {args.rig_out} not written", file=sys.stderr)
        else:
            Path(args.rig_out).write_text(rig_text(result, plan), encoding="utf-8")
            if not args.json:
                print(
                    f"wrote {args.rig_out}: check it with 'openel-async rig check {args.rig_out}'"
                )
    return 0 if result.found else EXIT_NOTHING_FOUND


def print_table(result: SerialScan, description: str) -> None:
    from rich.console import Console
    from rich.table import Table

    console = Console(highlight=False, soft_wrap=True)
    if not console.is_terminal:
        console = Console(highlight=False, soft_wrap=True, width=120)
    rates = ", ".join(map(str, result.baudrates))
    console.print(f"{description}: {result.protocol} at {rates} baud in {result.seconds:.2f} s")
    if result.servos:
        table = Table(title=f"{result.protocol.capitalize()} servos", title_justify="left")
        for column in ("id", "baud", "model", "device", "firmware", "error"):
            table.add_column(column)
        for s in result.servos:
            table.add_row(
                str(s.servo_id),
                str(s.baudrate),
                f"{s.model or '?'} ({s.model_number})",
                s.device or "-",
                "-" if s.firmware is None else str(s.firmware),
                f"0x{s.error:02X}",
            )
        console.print(table)
    if result.receivers:
        table = Table(title="NMEA receivers", title_justify="left")
        for column in ("baud", "sentences", "kinds", "checksum errors"):
            table.add_column(column)
        for r in result.receivers:
            table.add_row(
                str(r.baudrate), str(r.sentences), " ".join(r.kinds), str(r.checksum_errors)
            )
        console.print(table)
    if not result.found:
        console.print("nothing found")


def rig_text(result: SerialScan, plan: Plan) -> str:
    """A rig file with one serial bus per baud rate where something answered and a component
    per servo (or the receiver), for the user to edit."""
    lines = [
        "# Written by 'openel-async scan serial'. Edit the names, add position_limits",
        "# (docs/hardware.md), then check it: openel-async rig check FILE",
        f"description: {json.dumps(f'scanned: {plan.device} ({result.protocol})')}",
        "namespace: scanned",
        "buses:",
    ]
    rates = sorted({s.baudrate for s in result.servos} | {r.baudrate for r in result.receivers})
    names = {b: plan.name if len(rates) == 1 else f"{plan.name}_{b}" for b in rates}
    for baudrate in rates:
        lines += [
            f"  {names[baudrate]}:",
            "    type: serial",
            f"    protocol: {result.protocol}",
            f"    device: {json.dumps(plan.device)}",
            f"    baudrate: {baudrate}",
        ]
    lines.append("components:")
    key = "dxl_id" if result.protocol == "dynamixel" else "servo_id"
    for s in result.servos:
        model = f"{s.model or 'model'} {s.model_number}"
        if s.device is None:
            lines.append(f"  # id {s.servo_id}: {model} -- no device class of the driver fits")
            continue
        lines += [
            f"  - name: SERVO_{s.servo_id}   # {model}",
            "    driver: serial",
            f"    device: {s.device}",
            f"    bus: {names[s.baudrate]}",
            f"    params: {{{key}: {s.servo_id}}}",
        ]
    for r in result.receivers[:1]:  # one receiver on a port
        lines += [
            f"  - name: GPS   # {' '.join(r.kinds)}",
            "    driver: serial",
            "    device: nmea_gps",
            f"    bus: {names[r.baudrate]}",
        ]
    return "\n".join(lines) + "\n"
