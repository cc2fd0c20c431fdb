"""The serial driver's subcommand of ``openel-async`` (entry-point group
``openel_async.commands``; the framework's command line imports no driver):

``openel-async calibrate RIG.yaml``: calibrate the Feetech STS servos of a rig, as
``lerobot-calibrate`` does (:mod:`openel_serial.feetech_calibration`): every Feetech bus of the
rig is opened (``--bus`` to choose; ``--sim``: simulated servos, moved by a simulated hand),
the torque turned off, the user puts the arm in the middle of its range and presses Enter (the
homing offsets are written so that this pose reads step 2048, 0 rad), then moves each joint
through its full range by hand while the present positions and the minimum and maximum seen
are shown live, and presses Enter (the ranges are written as the angle limits). The
calibration file goes to ``--out``, else to the bus's ``calibration:`` option, else next to the
rig (``RIG.calibration.yaml``); joints of the file that were not calibrated this time are kept.

The command owns the terminal: prompts and the summary on standard output, the live table on
it while the joints are moved (on a terminal: rich's live display, log lines printed above
it; off a terminal: one line a second), logs on standard error. Input: one line (Enter) per
step from standard input; its end before a step is an error (exit status 1).
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, TypeAlias

from openel_async.cli.commands import CliCommand

if TYPE_CHECKING:
    SubParsers: TypeAlias = argparse._SubParsersAction[argparse.ArgumentParser]

__all__ = ["CALIBRATE", "SCAN_SERIAL"]


def add_calibrate_parser(sub: SubParsers) -> argparse.ArgumentParser:
    parser: argparse.ArgumentParser = sub.add_parser(
        "calibrate",
        help="calibrate the Feetech servos of a rig file by hand (homing offsets, ranges)",
        description="Calibrate the Feetech STS servos of a rig (the SO-101's): torque off, "
        "put the arm in the middle of its range (Enter: the homing offsets are written so that "
        "it reads 0 rad), move each joint through its full range by hand while the positions "
        "are shown live (Enter: the ranges are written as the servos' angle limits), then the "
        "calibration file is written. Exit status: 0 done, 1 failed, 2 usage error.",
    )
    parser.add_argument("rig", help="rig file (YAML) with a serial bus of protocol feetech")
    parser.add_argument(
        "--out",
        metavar="FILE",
        help="the calibration file to write (default: the bus's 'calibration:' option, else "
        "RIG.calibration.yaml next to the rig file)",
    )
    parser.add_argument(
        "--bus",
        action="append",
        metavar="NAME",
        help="calibrate only this Feetech bus of the rig (repeatable; default: every one)",
    )
    parser.add_argument(
        "--sim",
        action="store_true",
        help="against simulated servos on a pty: a simulated hand puts the arm off-centre, "
        "then sweeps each joint over its position_limits (Enter still confirms each step)",
    )
    return parser


def run_calibrate(args: argparse.Namespace) -> int:
    """Calibrate (:mod:`openel_serial.calibrate_cmd`, loaded only when the command runs)."""
    from .calibrate_cmd import run

    return run(args)


CALIBRATE = CliCommand("calibrate", add_calibrate_parser, run_calibrate)


SCAN_DESCRIPTION = """\
Find what is on a serial port before writing a rig: Dynamixel Protocol 2.0 or Feetech STS
servos (a PING of every id of --ids at each baud rate of --baud, each bounded by the status
time plus --timeout, through the driver's own port; on a Dynamixel bus one broadcast PING
instead when that is quicker, as for the default 0-252) or an NMEA 0183 receiver (the port
listened to for --listen seconds at each baud rate: whole, checksummed sentences come only at
the receiver's rate).

The port: --port DEVICE --protocol P, or a rig file's serial bus (--rig RIG.yaml [--bus
NAME]; --sim: its simulated servos or receiver on a pty). Default rates: the rig's; without a
rig Dynamixel 57600 and 1000000, Feetech 1000000, NMEA 9600, 4800, 38400 and 115200 (--baud
all: every rate of the protocol). A servo answers only at its own rate.

Prints a table (--json: one JSON document); --rig-out FILE writes a rig file naming what was
found, to edit and check with 'openel-async rig check FILE'. Exit status: 0 something found,
1 nothing found (or the port failed), 2 usage error, 130 Ctrl-C.
"""


def add_scan_serial_parser(sub: SubParsers) -> argparse.ArgumentParser:
    parser: argparse.ArgumentParser = sub.add_parser(
        "serial",
        help="find the Dynamixel or Feetech servos or the NMEA receiver on a serial port",
        description=SCAN_DESCRIPTION,
    )
    port = parser.add_argument_group("the port (a device and a protocol, or a rig file's bus)")
    port.add_argument("--port", metavar="DEVICE", help="/dev/ttyUSB0, /dev/ttyACM0, a URL...")
    port.add_argument(
        "--protocol", choices=("dynamixel", "feetech", "nmea"), help="what it carries"
    )
    port.add_argument("--rig", metavar="RIG.yaml", help="take the port from this rig file")
    port.add_argument("--bus", metavar="NAME", help="the rig's serial bus (default: its only one)")
    port.add_argument(
        "--sim",
        action="store_true",
        help="the rig's bus simulated: a pty with the rig's servos or receiver",
    )
    parser.add_argument(
        "--baud",
        metavar="RATES",
        help="baud rates to try, separated by commas, or 'all' (default: see above)",
    )
    parser.add_argument(
        "--ids", default="0-252", metavar="IDS", help="servo ids to ping: 1-6,10 (default 0-252)"
    )
    parser.add_argument(
        "--timeout",
        type=float,
        default=0.005,
        metavar="S",
        help="seconds added to each PING's status time before the id counts as absent "
        "(default 0.005; more behind a USB adapter with a long latency timer)",
    )
    parser.add_argument(
        "--listen",
        type=float,
        default=1.5,
        metavar="S",
        help="NMEA: seconds to listen at each rate (default 1.5: a 1 Hz receiver is heard)",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON document")
    parser.add_argument("--rig-out", metavar="FILE", help="write a rig file naming what was found")
    return parser


def run_scan_serial(args: argparse.Namespace) -> int:
    """Scan (:mod:`openel_serial.scan_cmd`, loaded only when the command runs)."""
    from .scan_cmd import run

    return run(args)


SCAN_SERIAL = CliCommand("serial", add_scan_serial_parser, run_scan_serial, parent="scan")
"""``openel-async scan serial``."""
