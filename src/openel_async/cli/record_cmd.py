"""``openel-async record info|plot FILE.mcap`` and the ``--record``/``--foxglove`` options of
``demo`` and ``run`` (the hooks they attach to the app).

The recording of ``--record`` is complete or absent: its path is checked before anything
runs (exit status 2), and a run that the app refuses before it registers a component (a bad
option, ``--help``, MuJoCo unavailable) leaves no file, nor does a writer that cannot start.
At the end the summary says where the recording went (its path, messages and drops): a
``recording`` line after the app's own summary lines, or, when a signal stopped the run, a
``file written`` line of the interrupted run's summary (the writer process ignores the signal
and closes the file once the run has stopped)."""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ..app import AppContext, AppHook
    from ..component import HALComponent
    from ..recording import Tap

__all__ = [
    "TAP_OPTIONS",
    "add_parser",
    "add_tap_arguments",
    "record_path_problem",
    "run",
    "taps_from_args",
]


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


def record_path_problem(path: Path) -> str | None:
    """Why ``--record`` cannot write ``path`` (None: it can), said before anything runs."""
    parent = path.parent
    if path.is_dir():
        return f"{path}: is a directory"
    if not parent.exists():
        return f"{path}: no such directory: {parent}"
    if not parent.is_dir():
        return f"{path}: {parent} is not a directory"
    if not os.access(parent, os.W_OK | os.X_OK) or (path.exists() and not os.access(path, os.W_OK)):
        return f"{path}: permission denied"
    return None


def taps_from_args(args: argparse.Namespace, prog: str) -> list[AppHook] | None:
    """The hook ``--record``/``--foxglove`` ask for, its writer process started; None (after
    printing why) when it cannot start (an unwritable file, a port in use)."""
    record, foxglove = getattr(args, "record", None), getattr(args, "foxglove", False)
    if record is None and not foxglove:
        return []
    if record is not None:
        problem = record_path_problem(Path(record))
        if problem is not None:
            print(f"{prog}: --record: {problem}", file=sys.stderr)
            return None
    from ..recording.pipeline import SinkStartError

    server = (args.foxglove_host, args.foxglove_port) if foxglove else None
    tap = _command_tap(record, server)
    try:
        tap.start()
    except BaseException as exc:  # no file is left behind (a port in use, a signal...)
        if record is not None:
            with contextlib.suppress(OSError):
                os.unlink(record)
        if not isinstance(exc, SinkStartError):
            raise
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


def _command_tap(record: str | None, server: tuple[str, int] | None) -> Tap:
    """The :class:`~openel_async.recording.Tap` of the command line (see the module
    docstring); a class made here, so that importing this module imports no recorder."""
    import anyio

    from ..app import note_written
    from ..recording import Tap

    path = None if record is None else Path(record).absolute()

    class CommandTap(Tap):
        def __init__(self) -> None:
            super().__init__(record=record, foxglove=server)
            self.registered = False
            """The app registered a component: it ran (else its recording is removed)."""

        def component_added(self, ctx: AppContext, component: HALComponent) -> None:
            self.registered = True
            super().component_added(ctx, component)

        async def __aexit__(
            self,
            exc_type: type[BaseException] | None,
            exc: BaseException | None,
            tb: TracebackType | None,
        ) -> None:
            await super().__aexit__(exc_type, exc, tb)
            if path is None:
                return
            if not self.registered:  # refused before it ran: complete or absent
                with contextlib.suppress(OSError):
                    os.unlink(path)  # a local file: no wait worth a thread
                return
            stats = self.final_stats or self.stats
            error = self.pipeline.error
            detail = f"{stats.written} messages, {stats.dropped} dropped" + (
                "" if error is None else f"; cut short: {error}"
            )
            note_written(path, detail)  # an interrupted run's summary lists it
            if exc_type is None or not issubclass(exc_type, anyio.get_cancelled_exc_class()):
                print(f"  recording          {path} ({detail})", flush=True)

    return CommandTap()


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
    from ..recording.reader import NotMcapError
    from .options import EXIT_USAGE, no_such_file

    path = Path(args.file)
    if no_such_file(f"openel-async record {args.record_action}", args.file):
        return EXIT_USAGE
    try:
        recording = read_recording(path)
    except (NotMcapError, OSError) as exc:
        print(f"openel-async record {args.record_action}: {exc}", file=sys.stderr)
        return 1
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
