"""``openel-async record info|plot FILE.mcap`` and the ``--record``/``--foxglove`` options of
``demo`` and ``run`` (the hooks they attach to the app)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ..app import AppHook

__all__ = ["add_parser", "add_tap_arguments", "run", "taps_from_args"]


def add_tap_arguments(parser: argparse.ArgumentParser) -> None:
    """``--record FILE.mcap``, ``--foxglove``, ``--foxglove-host``, ``--foxglove-port``."""
    parser.add_argument(
        "--record",
        metavar="FILE.mcap",
        default=None,
        help="record every command, reading, event, error, state change and timer tick to "
        "this MCAP file (openel-async record info FILE)",
    )
    parser.add_argument(
        "--foxglove",
        action="store_true",
        help="publish joint states, sensor values, events and logs live to Foxglove "
        "(WebSocket server, ws://127.0.0.1:8765 by default)",
    )
    parser.add_argument("--foxglove-host", default="127.0.0.1", help=argparse.SUPPRESS)
    parser.add_argument("--foxglove-port", type=int, default=8765, help=argparse.SUPPRESS)


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
    info.add_argument("file", metavar="FILE.mcap")
    plot = actions.add_parser("plot", help="the demos' joint plot (PNG) from a recording")
    plot.add_argument("file", metavar="FILE.mcap")
    plot.add_argument(
        "--out", metavar="DIR", default=None, help="output directory (default: next to FILE)"
    )


def run(args: argparse.Namespace) -> int:
    from ..recording import info_lines, read_recording

    path = Path(args.file)
    if not path.is_file():
        print(f"openel-async record: {path}: no such file", file=sys.stderr)
        return 2
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
