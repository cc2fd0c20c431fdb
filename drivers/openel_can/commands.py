"""The CAN driver's subcommands of ``openel-async`` (entry-point group
``openel_async.commands``; the framework's command line imports no driver):

- ``openel-async scan can``: find the CANopen nodes and ODrive axes on a bus
  (:mod:`openel_can.scan`), print a table (``--json``: one JSON document) and, with
  ``--rig-out``, write a rig file naming them;
- ``openel-async bus monitor``: print the frames of a bus decoded (:mod:`openel_can.monitor`).
  A rig bus of another kind whose ``BusKind`` has a ``monitor(args, name, bus) -> int``
  method (the serial driver's: Dynamixel and Feetech packets) is handed to it, with the
  parsed options (``--port`` is for those).

Both open a bus from python-can options (``--interface``, ``--channel``, ``--bitrate``) or
from a rig file's bus (``--rig RIG.yaml --bus NAME``; ``--sim``: the rig's simulated bus with
its simulated peers). Every option is checked before anything is opened (exit status 2).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeAlias

from openel_async.cli.commands import EXIT_USAGE, CliCommand, no_such_file
from openel_async.errors import BadParameterError

if TYPE_CHECKING:
    from .bus import CanBus
    from .monitor import Decoder
    from .scan import CanScan

    SubParsers: TypeAlias = argparse._SubParsersAction[argparse.ArgumentParser]

EXIT_NOTHING_FOUND = 1
"""``scan``: the scan ran and found nothing."""


# -- the bus to open ----------------------------------------------------------------------------


def add_bus_arguments(parser: argparse.ArgumentParser) -> None:
    """``--interface/--channel/--bitrate`` or ``--rig/--bus`` (``--sim``)."""
    group = parser.add_argument_group("the bus (python-can options, or a rig file's bus)")
    group.add_argument(
        "--interface",
        metavar="NAME",
        help="a python-can interface: socketcan, slcan, gs_usb, pcan, kvaser, virtual...",
    )
    group.add_argument(
        "--channel", metavar="CHANNEL", help="its channel: can0, /dev/ttyACM0, PCAN_USBBUS1..."
    )
    group.add_argument("--bitrate", type=int, metavar="BPS", help="bits per second (e.g. 1000000)")
    group.add_argument("--rig", metavar="RIG.yaml", help="take the bus from this rig file")
    group.add_argument("--bus", metavar="NAME", help="the rig's CAN bus (default: its only one)")
    group.add_argument(
        "--sim",
        action="store_true",
        help="the rig's bus simulated: a python-can virtual channel with the rig's nodes as "
        "simulated peers",
    )


@dataclass(frozen=True)
class BusSource:
    """Where the bus comes from, checked (:func:`bus_source`), nothing opened yet."""

    name: str
    kind: Any
    """The rig's ``can`` BusKind."""
    options: Any
    """Its CanBusOptions."""
    devices: tuple[Any, ...] = ()
    sim: bool = False


def bus_source(prog: str, args: argparse.Namespace) -> BusSource | None:
    """The bus the options name, or None after printing why not (exit status 2)."""
    from openel_async.rig import load_rig, resolve_rig

    from .rigbus import CanBusKind, CanBusOptions

    def refuse(message: str) -> None:
        print(f"{prog}: {message}", file=sys.stderr)

    if args.rig is None:
        if args.interface is None:
            refuse("give --interface (and --channel, --bitrate) or --rig RIG.yaml")
            return None
        if args.sim or args.bus is not None:
            refuse("--sim and --bus go with --rig")
            return None
        if args.bitrate is not None and args.bitrate <= 0:
            refuse(f"--bitrate {args.bitrate}: a number of bits per second > 0")
            return None
        options = CanBusOptions(
            interface=args.interface, channel=args.channel, bitrate=args.bitrate
        )
        return BusSource("can0", CanBusKind(), options)
    if args.interface is not None or args.channel is not None or args.bitrate is not None:
        refuse("--rig takes the bus from the rig file: no --interface, --channel or --bitrate")
        return None
    if no_such_file(prog, args.rig):
        return None
    try:
        resolved = resolve_rig(load_rig(args.rig))
    except BadParameterError as exc:
        refuse(str(exc))
        return None
    can_buses = {
        name: bus for name, bus in resolved.buses.items() if isinstance(bus.kind, CanBusKind)
    }
    if args.bus is None:
        if len(can_buses) != 1:
            refuse(
                f"{args.rig} has {len(can_buses)} CAN buses ({', '.join(can_buses) or 'none'}): "
                "say which with --bus"
            )
            return None
        args.bus = next(iter(can_buses))
    bus = can_buses.get(args.bus)
    if bus is None:
        refuse(
            f"--bus {args.bus}: {args.rig} has no CAN bus of that name (its CAN buses: "
            f"{', '.join(can_buses) or 'none'})"
        )
        return None
    return BusSource(args.bus, bus.kind, bus.options, bus.devices, args.sim)


@asynccontextmanager
async def open_bus(source: BusSource) -> AsyncIterator[tuple[CanBus, str]]:
    """The bus open (its simulated peers running with ``--sim``), and what it is in words."""
    options = source.options
    from .bus import CanBus

    description = source.kind.describe(options)
    async with _simulated(source) as simulated:
        if simulated is not None:
            options, description = simulated
        async with source.kind.open(source.name, options) as bus:
            assert isinstance(bus, CanBus)
            yield bus, description


@asynccontextmanager
async def _simulated(source: BusSource) -> AsyncIterator[tuple[Any, str] | None]:
    if not source.sim:
        yield None
        return
    async with source.kind.simulate(source.name, source.options, source.devices) as sim:
        yield sim.options, sim.description


def check_seconds(prog: str, name: str, value: float, low: float, high: float) -> bool:
    """True when ``low <= value <= high``; else False after saying so."""
    if low <= value <= high:
        return True
    print(f"{prog}: {name} {value:g}: a number of seconds in {low:g}..{high:g}", file=sys.stderr)
    return False


# -- scan can -----------------------------------------------------------------------------------

SCAN_DESCRIPTION = """\
Find what is on a CAN bus before writing a rig: CANopen nodes (their heartbeats and boot-ups,
then an SDO read of 0x1000 device type and 0x1018 identity -- vendor, product, revision,
serial -- of node ids 1..127, a few at a time, each bounded by --timeout) and ODrive axes
(their heartbeats and the answers to an Address request, then Get_Version).

Prints a table (--json: one JSON document); --rig-out FILE writes a rig file naming what was
found, to edit (limits, names) and check with 'openel-async rig check FILE'. Exit status: 0
something found, 1 nothing found, 2 usage error, 130 Ctrl-C.

The SDO requests to nodes 1..127 use ids 0x601..0x67F, which are commands of ODrive nodes
48..51: when such an ODrive is heard, the node ids it would take as commands are not swept
(--no-sdo skips the sweep altogether).
"""


def add_scan_can_parser(sub: SubParsers) -> argparse.ArgumentParser:
    parser: argparse.ArgumentParser = sub.add_parser(
        "can",
        help="find the CANopen nodes and ODrive axes on a CAN bus",
        description=SCAN_DESCRIPTION,
    )
    add_bus_arguments(parser)
    parser.add_argument(
        "--listen",
        type=float,
        default=1.1,
        metavar="S",
        help="seconds to listen for heartbeats first (default 1.1: a 1 s heartbeat is heard)",
    )
    parser.add_argument(
        "--timeout",
        type=float,
        default=0.05,
        metavar="S",
        help="seconds to wait for each node's answer (default 0.05)",
    )
    parser.add_argument(
        "--concurrency",
        type=int,
        default=16,
        metavar="N",
        help="SDO requests in flight at once, 1..127 (default 16)",
    )
    parser.add_argument(
        "--no-sdo", action="store_true", help="no SDO sweep: only the nodes that are heard"
    )
    parser.add_argument("--json", action="store_true", help="print one JSON document")
    parser.add_argument("--rig-out", metavar="FILE", help="write a rig file naming what was found")
    return parser


def run_scan_can(args: argparse.Namespace) -> int:
    import anyio

    prog = "openel-async scan can"
    if not (
        check_seconds(prog, "--listen", args.listen, 0.0, 60.0)
        and check_seconds(prog, "--timeout", args.timeout, 0.001, 5.0)
    ):
        return EXIT_USAGE
    if not 1 <= args.concurrency <= 127:
        print(f"{prog}: --concurrency {args.concurrency}: an int in 1..127", file=sys.stderr)
        return EXIT_USAGE
    if args.rig_out is not None and not Path(args.rig_out).resolve().parent.is_dir():
        print(f"{prog}: --rig-out {args.rig_out}: no such folder", file=sys.stderr)
        return EXIT_USAGE
    source = bus_source(prog, args)
    if source is None:
        return EXIT_USAGE
    result, description = anyio.run(_scan, source, args)
    return report_scan(result, description, source, args)


async def _scan(source: BusSource, args: argparse.Namespace) -> tuple[CanScan, str]:
    from .scan import scan_can

    async with open_bus(source) as (bus, description):
        result = await scan_can(
            bus,
            listen=args.listen,
            node_timeout=args.timeout,
            concurrency=args.concurrency,
            sdo=not args.no_sdo,
        )
    return result, description


def report_scan(
    result: CanScan, description: str, source: BusSource, args: argparse.Namespace
) -> int:
    """Print the scan (a table or JSON) and write the rig file; the exit status."""
    from .scanreport import print_table, rig_text, writable

    found = bool(result.canopen or result.odrives)
    if args.json:
        print(json.dumps({"bus": description, **result.to_dict()}, indent=2))
    else:
        print_table(result, description)
    if args.rig_out is not None:
        if not writable(result):
            print(f"no ODrive or CiA 402 drive found: {args.rig_out} not written", file=sys.stderr)
        else:
            Path(args.rig_out).write_text(rig_text(result, source), encoding="utf-8")
            if not args.json:
                print(
                    f"wrote {args.rig_out}: check it with 'openel-async rig check {args.rig_out}'"
                )
    return 0 if found else EXIT_NOTHING_FOUND


SCAN_CAN = CliCommand("can", add_scan_can_parser, run_scan_can, parent="scan")
"""``openel-async scan can``."""


# -- bus monitor --------------------------------------------------------------------------------

MONITOR_DESCRIPTION = """\
Watch a CAN bus or a serial servo bus of a rig: every frame on one line, decoded by what the rig knows -- ODrive messages
(CANSimple) of its ODrive nodes, CANopen (NMT, SYNC, heartbeats, EMCY with its class, SDO
transfers with the object by name and its value, the PDOs of its CiA 402 drives field by
field by the maps the driver writes to them, other PDOs raw) -- with a summary of per-id
rates and error counters every --summary seconds and at the end. --json: one JSON object a
line.

The monitor is passive: it sends nothing. With --sim the rig's simulated peers run and send
what they send unprompted (heartbeats, an ODrive's encoder estimates); run an app on the real
bus in another terminal to see its commands. --log FILE also writes every frame in a format
python-can reads back (can.player, can.logger, can.LogReader), chosen by the extension:
.asc, .blf, .trc, .log or .csv.

A serial bus of a rig (Dynamixel 2.0, Feetech STS): its packets in both directions, by
instruction and control-table item, with rates and error counters; --port DEVICE is a second
adapter listening on the same line (only read), --sim the rig's simulated servos read by its
driver through a tap (nothing written); --log FILE writes timestamped hex lines.

Exit status: 0 done (after --duration seconds), 1 a serial port failed, 2 usage error, 130
Ctrl-C.
"""


def add_monitor_parser(sub: SubParsers) -> argparse.ArgumentParser:
    parser: argparse.ArgumentParser = sub.add_parser(
        "monitor",
        help="print the frames of a CAN bus decoded, with rates and error counters",
        description=MONITOR_DESCRIPTION,
        allow_abbrev=False,
    )
    parser.add_argument("rig_file", nargs="?", metavar="RIG.yaml", help="a rig file")
    parser.add_argument("bus_name", nargs="?", metavar="BUS", help="its CAN bus")
    add_bus_arguments(parser)
    parser.add_argument(
        "--odrive",
        metavar="NODES",
        default="",
        help="ODrive node ids to decode as CANSimple, e.g. 1,2 (a rig says its own)",
    )
    parser.add_argument(
        "--cia402",
        metavar="NODES",
        default="",
        help="CiA 402 node ids whose PDOs to decode by the driver's maps of a drive with no "
        "files, each with its mode: 2,3:csp (modes pp, csp, csv, cst; default pp; a rig "
        "says its own drives' maps)",
    )
    serial = parser.add_argument_group("a serial servo bus of the rig (Dynamixel, Feetech)")
    serial.add_argument(
        "--port",
        metavar="DEVICE",
        help="a second adapter on the same line, only read (the app keeps its own); "
        "or --sim: the rig's simulated servos read by its driver, through a tap",
    )
    parser.add_argument(
        "--duration", type=float, default=10.0, metavar="S", help="seconds to watch (default 10)"
    )
    parser.add_argument(
        "--summary",
        type=float,
        default=1.0,
        metavar="S",
        help="seconds between summaries (default 1)",
    )
    parser.add_argument("--json", action="store_true", help="one JSON object a line")
    parser.add_argument(
        "--log",
        metavar="FILE",
        help="also write the frames to FILE (CAN: .asc, .blf, .trc, .log, .csv; serial: "
        "timestamped hex lines)",
    )
    return parser


def _node_list(text: str) -> frozenset[int] | None:
    try:
        nodes = frozenset(int(part, 0) for part in text.split(",") if part.strip())
    except ValueError:
        return None
    return nodes if all(0 <= n < 0x3F for n in nodes) else None


def _other_kind(prog: str, args: argparse.Namespace) -> int | None:
    """The exit status of the monitor of a rig bus that is not CAN (its kind's ``monitor``),
    or None: a CAN bus (or a rig that does not load: :func:`bus_source` says why)."""
    if args.rig is None or args.bus is None or not Path(args.rig).is_file():
        return None
    from openel_async.rig import load_rig, resolve_rig

    from .rigbus import CanBusKind

    try:
        bus = resolve_rig(load_rig(args.rig)).buses.get(args.bus)
    except BadParameterError:
        return None
    if bus is None or isinstance(bus.kind, CanBusKind):
        return None
    monitor = getattr(bus.kind, "monitor", None)
    if monitor is None:
        print(
            f"{prog}: {args.bus}: the installed drivers monitor no bus of its kind", file=sys.stderr
        )
        return EXIT_USAGE
    status: int = monitor(args, args.bus, bus)
    return status


def _cia402_list(text: str) -> dict[int, str] | None:
    """``2,3:csp`` -> {2: "pp", 3: "csp"}; None when malformed."""
    from .monitor_canopen import CIA402_MODES

    out: dict[int, str] = {}
    for part in (p.strip() for p in text.split(",")):
        if not part:
            continue
        node_text, _, mode = part.partition(":")
        try:
            node = int(node_text, 0)
        except ValueError:
            return None
        if not 1 <= node <= 127 or (mode or "pp") not in CIA402_MODES:
            return None
        out[node] = mode or "pp"
    return out


def run_monitor(args: argparse.Namespace) -> int:
    import anyio

    from .monitor import check_log_path

    prog = "openel-async bus monitor"

    def refuse(message: str) -> int:
        print(f"{prog}: {message}", file=sys.stderr)
        return EXIT_USAGE

    if args.rig_file is not None:
        if args.rig is not None or args.bus is not None:
            return refuse("give the rig and its bus as RIG.yaml BUS or --rig/--bus, not both")
        args.rig, args.bus = args.rig_file, args.bus_name
    if not (
        check_seconds(prog, "--duration", args.duration, 0.001, 86400.0)
        and check_seconds(prog, "--summary", args.summary, 0.1, 3600.0)
    ):
        return EXIT_USAGE
    handed = _other_kind(prog, args)
    if handed is not None:
        return handed
    if args.port is not None:
        return refuse("--port goes with a serial bus of a rig (RIG.yaml BUS)")
    odrives = _node_list(args.odrive)
    if odrives is None:
        return refuse(f"--odrive {args.odrive}: node ids 0..62, separated by commas")
    cia402 = _cia402_list(args.cia402)
    if cia402 is None:
        return refuse(
            f"--cia402 {args.cia402}: node ids 1..127 separated by commas, each with an "
            "optional mode :pp, :csp, :csv or :cst"
        )
    if args.log is not None and (why := check_log_path(args.log)) is not None:
        return refuse(f"--log {args.log}: {why}")
    source = bus_source(prog, args)
    if source is None:
        return EXIT_USAGE
    from .monitor import Decoder
    from .monitor_canopen import rig_knowledge
    from .rigbus import ODRIVE_DEVICES

    odrives |= {d.params["node_id"] for d in source.devices if d.device in ODRIVE_DEVICES}
    try:
        known = rig_knowledge(source.devices)
    except BadParameterError as exc:
        return refuse(f"{args.rig}: {exc}")
    for node, mode in cia402.items():
        if not any(layout.node_id == node for layout in known.pdos.values()):
            known.add_fixed(node, mode)
    anyio.run(_monitor, source, Decoder(odrives, known=known), args)
    return 0


async def _monitor(source: BusSource, decoder: Decoder, args: argparse.Namespace) -> None:
    from .monitor import Decoded, MonitorStats, monitor

    first: list[float] = []

    def frame_line(decoded: Decoded) -> None:
        if args.json:
            print(json.dumps(decoded.to_dict()), flush=True)
        else:
            first[:] = first or [decoded.timestamp]
            print(decoded.line(first[0]), flush=True)

    def summary(stats: MonitorStats) -> None:
        if args.json:
            print(json.dumps({"summary": stats.to_dict()}), flush=True)
        else:
            print(stats.summary(), flush=True)

    async with open_bus(source) as (bus, description):
        if not args.json:
            print(f"monitoring {description} for {args.duration:g} s", flush=True)
        stats = await monitor(
            bus,
            decoder,
            duration=args.duration,
            on_frame=frame_line,
            on_summary=summary,
            summary_every=args.summary,
            log=args.log,
        )
    summary(stats)
    if args.log is not None and not args.json:
        print(f"wrote {args.log} ({stats.frames} frames)", flush=True)


BUS_MONITOR = CliCommand("monitor", add_monitor_parser, run_monitor, parent="bus")
"""``openel-async bus monitor``."""
