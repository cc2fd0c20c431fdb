"""What ``openel-async scan can`` prints and writes: the table of a :class:`~openel_can.scan.CanScan`
and a rig file naming what it found."""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

from rich.console import Console
from rich.table import Table

from .scan import CIA402_PROFILE, CanScan

if TYPE_CHECKING:
    from .commands import BusSource

__all__ = ["print_table", "rig_text", "wide_console", "writable"]


def _hex(value: int | None, digits: int = 8) -> str:
    return "-" if value is None else f"0x{value:0{digits}X}"


def wide_console() -> Console:
    """A console for tables: the terminal's width, or 120 columns into a pipe or a file."""
    console = Console(highlight=False, soft_wrap=True)
    if not console.is_terminal:
        console = Console(highlight=False, soft_wrap=True, width=120)
    return console


def print_table(result: CanScan, description: str, console: Console | None = None) -> None:
    """The nodes found, one row each, and a summary line."""
    console = console or wide_console()
    console.print(f"{description}: {result.frames} frames in {result.seconds:.2f} s")
    if result.odrives:
        table = Table(title="ODrive axes (CANSimple)", title_justify="left")
        for column in ("node", "state", "error", "firmware", "hardware", "serial"):
            table.add_column(column)
        for o in result.odrives:
            table.add_row(
                str(o.node_id),
                o.axis_state or "-",
                "-" if o.axis_error is None else f"0x{o.axis_error:X}",
                o.firmware or "-",
                o.hardware or "-",
                "-" if o.serial_number is None else f"{o.serial_number:X}",
            )
        console.print(table)
    if result.canopen:
        table = Table(title="CANopen nodes", title_justify="left")
        for column in ("node", "state", "device type", "profile", "vendor", "product",
                       "revision", "serial"):  # fmt: skip
            table.add_column(column)
        for n in result.canopen:
            table.add_row(
                str(n.node_id),
                n.state or "-",
                _hex(n.device_type),
                "-" if n.profile is None else f"CiA {n.profile}",
                _hex(n.vendor_id),
                _hex(n.product_code),
                _hex(n.revision),
                _hex(n.serial_number),
            )
        console.print(table)
    if not (result.odrives or result.canopen):
        console.print("nothing found")
    if result.skipped:
        console.print(
            f"not swept with SDO (their requests are an ODrive's commands): node ids "
            f"{result.skipped[0]}..{result.skipped[-1]}"
        )


def writable(result: CanScan) -> bool:
    """Whether a rig file can name something found (an ODrive or a CiA 402 drive)."""
    return bool(result.odrives) or any(n.profile == CIA402_PROFILE for n in result.canopen)


def rig_text(result: CanScan, source: BusSource) -> str:
    """A rig file with the bus and a component per ODrive axis and CiA 402 drive found
    (other CANopen nodes as comments), for the user to edit."""
    options = source.options
    bus = source.name
    lines = [
        "# Written by 'openel-async scan can'. Edit the names, add limits (docs/hardware.md),",
        "# then check it: openel-async rig check FILE",
        f"description: {json.dumps(f'scanned: {len(result.odrives)} ODrive, {len(result.canopen)} CANopen')}",
        "namespace: scanned",
        "buses:",
        f"  {bus}:",
        "    type: can",
        f"    interface: {json.dumps(options.interface)}",
    ]
    if options.channel is not None:
        lines.append(f"    channel: {json.dumps(options.channel)}")
    if options.bitrate is not None:
        lines.append(f"    bitrate: {options.bitrate}")
    lines.append("components:")
    for o in result.odrives:
        about = ", ".join(
            x
            for x in (
                f"firmware {o.firmware}" if o.firmware else "",
                f"serial {o.serial_number:X}" if o.serial_number is not None else "",
            )
            if x
        )
        lines += [
            f"  - name: ODRIVE_{o.node_id}" + (f"   # {about}" if about else ""),
            "    driver: can",
            "    device: odrive_axis",
            f"    bus: {bus}",
            f"    params: {{node_id: {o.node_id}}}",
        ]
    for n in result.canopen:
        identity = (
            f"vendor {_hex(n.vendor_id)}, product {_hex(n.product_code)}, "
            f"serial {_hex(n.serial_number)}"
        )
        if n.profile != CIA402_PROFILE:
            lines.append(
                f"  # CANopen node {n.node_id}: device type {_hex(n.device_type)}, {identity}"
                " -- not a CiA 402 drive, no component"
            )
            continue
        lines += [
            f"  - name: DRIVE_{n.node_id}   # CiA 402, {identity}",
            "    driver: can",
            "    device: cia402_drive",
            f"    bus: {bus}",
            f"    params: {{node_id: {n.node_id}}}",
        ]
    return "\n".join(lines) + "\n"
