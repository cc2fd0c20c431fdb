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

__all__ = ["CALIBRATE"]


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
