"""``openel-async bus monitor RIG.yaml BUS`` on a serial servo bus of the rig (the command's
parser is the CAN driver's; a rig bus of ``type: serial`` is handed to
:meth:`openel_serial.rigbus.SerialBusKind.monitor`, which calls :func:`run`).

* ``--port DEVICE``: a second adapter listening on the same RS-485/TTL line, only read (a
  serial bus cannot be shared: the app keeps its own adapter), at the rig's baud rate;
* ``--sim``: the rig's simulated servos on a pty behind a :class:`~openel_serial.monitor.TapRelay`,
  and the rig's own driver port (the code an app runs) reading them: a PING of each servo,
  then every 0.1 s a SYNC READ of their present state and a READ of one servo's present
  temperature in turn. It writes nothing: no torque on, nothing moves.

Exit status: 0 done, 1 the port failed, 2 usage error, 130 Ctrl-C.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
from collections.abc import Awaitable, Callable
from typing import Any

import anyio
import msgspec

from openel_async.cli.commands import EXIT_USAGE
from openel_async.errors import HALError

from .monitor import (
    Chunk,
    SerialMonitorStats,
    TapRelay,
    check_capture_path,
    listen_port,
    monitor_stream,
)
from .sniffer import DynamixelSniffer, FeetechSniffer, Frame, Sniffer

__all__ = ["SIM_POLL_PERIOD", "run"]

PROG = "openel-async bus monitor"
EXIT_FAILED = 1
SIM_POLL_PERIOD = 0.1
"""Seconds between the reads of ``--sim``."""
_CAN_ONLY = ("interface", "channel", "bitrate")


def _refuse(message: str) -> int:
    print(f"{PROG}: {message}", file=sys.stderr)
    return EXIT_USAGE


def run(args: argparse.Namespace, name: str, bus: Any) -> int:
    """Monitor the rig's serial bus ``name`` (its resolved entry ``bus``: kind, options,
    devices) as the options say."""
    options = bus.options
    if options.protocol not in ("dynamixel", "feetech"):
        return _refuse(f"{name} carries {options.protocol}: the monitor decodes servo buses")
    given = [f"--{k}" for k in _CAN_ONLY if getattr(args, k, None) is not None]
    given += [f"--{k}" for k in ("odrive", "cia402") if getattr(args, k, "")]
    if given:
        return _refuse(f"{', '.join(given)}: CAN options ({name} is a serial bus)")
    if args.sim == (args.port is not None):
        return _refuse(
            f"{name} is a serial bus, which the app's adapter cannot share: give --port DEVICE "
            "(a second adapter listening on the same line) or --sim"
        )
    if args.log is not None and (why := check_capture_path(args.log)) is not None:
        return _refuse(f"--log {args.log}: {why}")
    try:
        return anyio.run(_monitor, args, name, bus)
    except (OSError, HALError) as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)
        return EXIT_FAILED


def _sniffer(protocol: str) -> Sniffer:
    return DynamixelSniffer() if protocol == "dynamixel" else FeetechSniffer()


async def _monitor(args: argparse.Namespace, name: str, bus: Any) -> int:
    options = bus.options
    sniffer = _sniffer(options.protocol)
    send, receive = anyio.create_memory_object_stream[Chunk](4096)
    first: list[float] = []

    def frame_line(frame: Frame) -> None:
        if args.json:
            print(json.dumps(frame.to_dict()), flush=True)
        else:
            first[:] = first or [frame.timestamp]
            print(frame.line(first[0]), flush=True)

    def summary(stats: SerialMonitorStats) -> None:
        if args.json:
            print(json.dumps({"summary": stats.to_dict()}), flush=True)
        else:
            print(stats.summary(), flush=True)

    async def watch(description: str) -> SerialMonitorStats:
        if not args.json:
            print(f"monitoring {description} for {args.duration:g} s", flush=True)
        return await monitor_stream(
            receive,
            sniffer,
            duration=args.duration,
            on_frame=frame_line,
            on_summary=summary,
            summary_every=args.summary,
            log=args.log,
            description=description,
        )

    if args.sim:
        stats = await _simulated(name, bus, send, watch)
    else:
        description = (
            f"{args.port} at {options.baudrate} baud (listening to {name}: "
            f"{bus.kind.describe(options)})"
        )
        async with anyio.create_task_group() as tg:
            await tg.start(listen_port, args.port, options.baudrate, send)
            stats = await watch(description)
            tg.cancel_scope.cancel()
    summary(stats)
    if args.log is not None and not args.json:
        print(f"wrote {args.log} ({stats.bytes} bytes)", flush=True)
    return 0


async def _simulated(
    name: str,
    bus: Any,
    send: Any,
    watch: Callable[[str], Awaitable[SerialMonitorStats]],
) -> SerialMonitorStats:
    kind, options = bus.kind, bus.options
    ids = sorted(int(d.params["servo_id" if options.protocol == "feetech" else "dxl_id"])
                 for d in bus.devices)  # fmt: skip
    async with kind.simulate(name, options, bus.devices) as sim:
        relay = TapRelay(sim.options.device, send)
        async with relay:
            port_options = msgspec.structs.replace(sim.options, device=relay.path)
            async with kind.open(name, port_options) as port, anyio.create_task_group() as tg:
                tg.start_soon(_read_servos, port, ids, options.protocol)
                stats = await watch(
                    f"{sim.description}, through a tap; the driver's port reads them every "
                    f"{SIM_POLL_PERIOD:g} s (nothing written)"
                )
                tg.cancel_scope.cancel()
    return stats


async def _read_servos(port: Any, ids: list[int], protocol: str) -> None:
    """What ``--sim`` shows: the driver's port reading (never writing) the servos."""
    if protocol == "feetech":
        from .feetech import STS as table

        block = (table.PRESENT_POSITION.address, 8)  # position, speed, load, voltage, temp.
        temperature = table.PRESENT_TEMPERATURE
    else:
        from .dynamixel_table import XSeries as table  # type: ignore[assignment]

        block = (table.PRESENT_CURRENT.address, 10)  # current, velocity, position
        temperature = table.PRESENT_TEMPERATURE
    for servo_id in ids:
        with contextlib.suppress(HALError):  # shown by the monitor: no status
            await port.ping(servo_id)
    turn = 0
    while True:
        with contextlib.suppress(HALError):  # a timeout is seen on the line
            await port.sync_read_statuses(ids, *block)
            servo_id = ids[turn % len(ids)]
            await port.read(servo_id, temperature.address, temperature.size)
        turn += 1
        await anyio.sleep(SIM_POLL_PERIOD)
