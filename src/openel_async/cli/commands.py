"""Subcommands contributed by driver packages, through the ``openel_async.commands``
entry-point group.

The framework's command line imports no driver. A driver that offers a command (the Zenoh
driver's ``serve``, ``hal4rt exec``) registers a :class:`CliCommand`::

    [project.entry-points."openel_async.commands"]
    serve = "openel_zenoh.commands:SERVE"

``parent`` None adds a top-level subcommand (``openel-async serve``); ``"hal4rt"``, ``"scan"``
or ``"bus"`` adds an action under that command (``openel-async hal4rt exec``, ``openel-async scan
can``, ``openel-async bus monitor``): the framework owns ``scan`` and ``bus``, each driver
contributes the kinds of bus it knows. A contributed command whose package cannot be imported
is left out of the command line, silently (the parser is built before logging is configured;
``openel-async devices`` reports a driver that fails to load): the rest works without it.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, TypeAlias

from ..entrypoints import entry_points
from .options import EXIT_USAGE, log_level, no_such_file

__all__ = [
    "ENTRY_POINT_GROUP",
    "EXIT_USAGE",
    "CliCommand",
    "discover_commands",
    "load_bytes",
    "log_level",
    "no_such_file",
]

ENTRY_POINT_GROUP = "openel_async.commands"

if TYPE_CHECKING:
    SubParsers: TypeAlias = argparse._SubParsersAction[argparse.ArgumentParser]


@dataclass(frozen=True)
class CliCommand:
    """A subcommand: ``add_parser(subparsers)`` returns the parser it added, ``run(args)``
    runs it and returns the exit status."""

    name: str
    add_parser: Callable[[SubParsers], argparse.ArgumentParser]
    run: Callable[[argparse.Namespace], int]
    parent: str | None = None
    """None: ``openel-async NAME``; ``"hal4rt"``, ``"scan"``, ``"bus"``: ``openel-async PARENT
    NAME``."""


def discover_commands() -> list[CliCommand]:
    """Every contributed command that loads, in name order."""
    found: list[CliCommand] = []
    for ep in sorted(entry_points(group=ENTRY_POINT_GROUP), key=lambda e: e.name):
        try:
            command = ep.load()
        except Exception:  # a driver that cannot load contributes nothing
            continue
        if isinstance(command, CliCommand):
            found.append(command)
    return found


def attach(command: CliCommand, sub: SubParsers) -> None:
    """Add ``command`` to ``sub``; the parsed arguments carry it as ``contributed``."""
    parser = command.add_parser(sub)
    parser.set_defaults(contributed=command)


def load_bytes(name: str) -> bytes:
    """The bytes of file ``name`` (``-``: standard input), for a command's file arguments."""
    return sys.stdin.buffer.read() if name == "-" else Path(name).read_bytes()
