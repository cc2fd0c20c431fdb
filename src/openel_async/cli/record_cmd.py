"""``openel-async record info|plot FILE.mcap`` and the ``--record``/``--foxglove`` options of
``demo`` and ``run`` (the hooks they attach to the app)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ..app import AppHook

__all__ = ["TAP_OPTIONS", "add_parser", "add_tap_arguments", "run", "taps_from_args"]


TAP_OPTIONS = ("--record", "--foxglove", "--foxglove-host", "--foxglove-port")
"""The options of :func:`add_tap_arguments`: ``run`` takes them after the app's name too."""


def add_tap_arguments(parser: argparse.ArgumentParser) -> None:
    """``--record FILE.mcap``, ``--foxglove``, ``--foxglove-host``, ``--foxglove-port``."""
    group = parser.add_argument_group("recording and live view (docs/recording.md)")
    group.add_argument(
        "--record",
        metavar="FILE.mcap",
        default=None,
        help="record every command, reading, event, error, state change and timer tick to "
        "this MCAP file (openel-async record info FILE.mcap summarizes it)",
    )
    group.add_argument(
        "--foxglove",
        action="store_true",
        help="publish joint states, sensor values, events and logs live to Foxglove "
        "(a WebSocket server at --foxglove-host and --foxglove-port)",
    )
    group.add_argument(
        "--foxglove-host",
        metavar="HOST",
        default="127.0.0.1",
        help="the address the Foxglove server listens on (default 127.0.0.1: this machine "
        "only; 0.0.0.0: every network)",
    )
    group.add_argument(
        "--foxglove-port",
        metavar="PORT",
        type=int,
        default=8765,
        help="the Foxglove server's TCP port (default 8765; 0: any free port)",
    )


def taps_from_args(args: argparse.Namespace, prog: str) -> list[AppHook] | None:
    """The hook ``--record``/``--foxglove`` ask for, its writer process started; None (after
    printing why) when it cannot start (an unwritable file, a port in use)."""
    record, foxglove = getattr(args, "record", None), getattr(args, "foxglove", False)
    if record is None and not foxglove:
        return []
    from ..recording import Tap
    from ..recording.pipeline import SinkStartError

    server = (args.foxglove_host, args.foxglove_port) if foxglove else None
    tap = Tap(record=record, foxglove=server)
    try:
        tap.start()
    except SinkStartError as exc:
        what = (
            "--record/--foxglove"
            if record is not None and foxglove
            else ("--record" if record is not None else "--foxglove")
        )
        print(f"{prog}: {what}: cannot start: {exc}", file=sys.stderr)
        return None
    if foxglove:
        print(f"{prog}: Foxglove live view on ws://{args.foxglove_host}:{tap.pipeline.port}")
    return [tap]


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    record = sub.add_parser(
        "record", help="inspect a recording: info (channels, counts, duration) or plot (PNG)"
    )
    actions = record.add_subparsers(dest="record_action", required=True)
    info = actions.add_parser("info", help="summarize a recording: channels, counts, duration")
    info.add_argument("file", metavar="FILE.mcap", help="the recording")
    plot = actions.add_parser("plot", help="the demos' joint plot (PNG) from a recording")
    plot.add_argument("file", metavar="FILE.mcap", help="the recording")
    plot.add_argument(
        "--out", metavar="DIR", default=None, help="output directory (default: next to FILE)"
    )


def run(args: argparse.Namespace) -> int:
    from ..recording import info_lines, read_recording
    from .options import EXIT_USAGE, no_such_file

    path = Path(args.file)
    if no_such_file(f"openel-async record {args.record_action}", args.file):
        return EXIT_USAGE
    recording = read_recording(path)
    if args.record_action == "info":
        print("\n".join(info_lines(recording)))
        return 0
    from ..recording.plot import plot_recording

    try:
        written = plot_recording(recording, args.out or path.parent)
    except ValueError as exc:
        print(f"openel-async record plot: {exc}", file=sys.stderr)
        return 1
    for out in written:
        print(f"plot  {out}")
    return 0
