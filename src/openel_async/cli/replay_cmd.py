"""``openel-async replay FILE.mcap``: a recording's commands fed, at their recorded times, to
a rig (``--rig sim``: the sim driver's motors on a virtual clock; ``--rig MODULE:FACTORY``:
a driver's rig, e.g. ``openel_mujoco.foxglove_scene:replay_rig`` with ``--rig-arg arm2``)."""

from __future__ import annotations

import argparse
import importlib
import sys
from pathlib import Path
from typing import Any

__all__ = ["add_parser", "run"]


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    replay = sub.add_parser(
        "replay",
        help="feed a recording's commands, at their recorded times, to a rig and compare the "
        "final positions",
    )
    replay.add_argument("file", metavar="FILE.mcap", help="the recording to replay")
    replay.add_argument(
        "--rig",
        default="sim",
        help="sim (default: openel_sim motors, one per recorded actuator) or MODULE:FACTORY, "
        "a driver's rig factory (e.g. openel_mujoco.foxglove_scene:replay_rig)",
    )
    replay.add_argument(
        "--rig-arg", default=None, help="argument of a MODULE:FACTORY rig (e.g. arm2)"
    )
    replay.add_argument(
        "--option",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="sim rig: a motor option (e.g. max_velocity=3.0); repeatable",
    )
    replay.add_argument(
        "--realtime", action="store_true", help="sim rig: the real clock (default: virtual)"
    )


def _rig(args: argparse.Namespace) -> Any:
    """The rig factory, its options checked (ValueError: ``(option, message)``)."""
    from ..recording.replay import parse_options, sim_motor_class, sim_rig

    if args.rig == "sim":
        if args.rig_arg is not None:
            raise _OptionError("--rig-arg", "only a MODULE:FACTORY rig takes an argument")
        try:
            options = parse_options(args.option, sim_motor_class())
        except ValueError as exc:
            raise _OptionError("--option", str(exc)) from exc
        return sim_rig(virtual=not args.realtime, **options)
    if args.option:
        raise _OptionError("--option", "only the sim rig takes motor options")
    module_name, sep, factory_name = args.rig.partition(":")
    if not sep:
        raise _OptionError("--rig", f"sim or MODULE:FACTORY, not {args.rig!r}")
    try:
        factory = getattr(importlib.import_module(module_name), factory_name)
        return factory(args.rig_arg) if args.rig_arg is not None else factory()
    except (ValueError, LookupError, ImportError, AttributeError, TypeError) as exc:
        raise _OptionError("--rig", f"{args.rig}: {exc}") from exc


class _OptionError(Exception):
    def __init__(self, option: str, message: str) -> None:
        super().__init__(f"{option}: {message}")


def run(args: argparse.Namespace) -> int:
    import anyio

    from ..recording import read_recording
    from ..recording.reader import NotMcapError
    from ..recording.replay import replay
    from .options import EXIT_USAGE, no_such_file

    path = Path(args.file)
    if no_such_file("openel-async replay", args.file):
        return EXIT_USAGE
    try:  # every option before anything runs
        rig = _rig(args)
    except (_OptionError, LookupError) as exc:
        print(f"openel-async replay: {exc}", file=sys.stderr)
        return 2
    try:
        recording = read_recording(path)
    except (NotMcapError, OSError) as exc:
        print(f"openel-async replay: {exc}", file=sys.stderr)
        return 1
    try:
        result = anyio.run(replay, recording, rig, backend="asyncio")
    except (ValueError, LookupError) as exc:
        print(f"openel-async replay: {exc}", file=sys.stderr)
        return 1
    print(f"replay of {path} ({len(recording.messages)} messages)")
    for line in result.lines():
        print("  " + line)
    return 0
