"""The command line's grammar: the help formatter, the global options every (sub)command
takes, the log level they select, and the file checks shared by the commands."""

from __future__ import annotations

import argparse
import re
import shutil
import sys
import textwrap
from pathlib import Path
from typing import Any

__all__ = [
    "DEFAULT_LEVEL",
    "EXIT_USAGE",
    "GLOBAL_FLAGS",
    "GLOBAL_VALUE_OPTIONS",
    "LEVELS",
    "SHORT_GLOBAL_FLAGS",
    "HelpFormatter",
    "add_global_options",
    "log_level",
    "no_such_file",
    "plain",
]

LEVELS = ("debug", "info", "warning", "error")
DEFAULT_LEVEL = "warning"
"""Shown by default: warnings and errors (a command's own output and summary are not logs)."""
EXIT_USAGE = 2
"""Exit status of a command refused before it ran: a bad option, a missing file."""

_ROLE = re.compile(r":[a-z]+(?::[a-z]+)?:`~?([^`<]*?)(?:\s*<[^>]*>)?`")
_LITERAL = re.compile(r"``([^`]+)``")


def plain(text: str) -> str:
    """``text`` without reStructuredText markup: ````x```` and ``:class:`~a.B``` read x, B."""
    text = _ROLE.sub(
        lambda m: m.group(1).rsplit(".", 1)[-1] if "~" in m.group(0) else m.group(1), text
    )
    return _LITERAL.sub(r"\1", text)


class HelpFormatter(argparse.HelpFormatter):
    """argparse's formatter, for people: no reST markup; an option's help keeps its line
    breaks (one sentence a line), each line wrapped; a description's blank lines separate
    paragraphs and ``- `` starts a list item."""

    def __init__(self, prog: str, **kwargs: Any) -> None:
        width = min(shutil.get_terminal_size((100, 24)).columns, 100) - 2
        kwargs.setdefault("max_help_position", 26)
        kwargs.setdefault("width", width)
        super().__init__(prog, **kwargs)

    def _split_lines(self, text: str, width: int) -> list[str]:
        lines: list[str] = []
        for line in plain(text).splitlines():
            lines += textwrap.wrap(line, width, subsequent_indent="  ") or [""]
        return lines

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        out: list[str] = []
        for paragraph in re.split(r"\n\s*\n", plain(textwrap.dedent(text)).strip()):
            items = re.split(r"\n(?=\s*- )", paragraph)
            for item in items:
                words = " ".join(item.split())
                hanging = "  " if words.startswith("- ") else ""
                out += textwrap.wrap(
                    words, width, initial_indent=indent, subsequent_indent=indent + hanging
                )
            out.append("")
        return "\n".join(out[:-1])


GLOBAL_VALUE_OPTIONS = frozenset({"--log-format", "--log-level"})
"""The options of :func:`add_global_options` that take a value."""
GLOBAL_FLAGS = frozenset({"-v", "--verbose", "-q", "--quiet"})
"""The options of :func:`add_global_options` that take none."""
SHORT_GLOBAL_FLAGS = frozenset("vq")
"""The one-letter flags among them, which combine (``-vv``, ``-vq``)."""


def add_global_options(parser: argparse.ArgumentParser, *, depth: int) -> None:
    """``--log-format``, ``--log-level``, ``-v``, ``-q`` on ``parser``: the top-level parser
    (``depth`` 0) holds the defaults; a subcommand's (depth 1, 2) sets only what is given
    after it, so the options work before or after any subcommand. ``-v`` and ``-q`` count
    wherever they are given."""
    top = depth == 0
    group = parser.add_argument_group("output options")
    group.add_argument(
        "--log-format",
        choices=("console", "json"),
        default="console" if top else argparse.SUPPRESS,
        help="log lines for people (console, the default) or one JSON object a line (json); "
        "logs go to standard error",
    )
    group.add_argument(
        "--log-level",
        choices=LEVELS,
        default=None if top else argparse.SUPPRESS,
        help=f"the least severe log lines shown (default {DEFAULT_LEVEL}: warnings and errors)",
    )
    group.add_argument(
        "-v",
        "--verbose",
        action="count",
        dest=f"verbose_{depth}",
        default=0 if top else argparse.SUPPRESS,
        help="show more log lines: -v info, -vv debug",
    )
    group.add_argument(
        "-q",
        "--quiet",
        action="count",
        dest=f"quiet_{depth}",
        default=0 if top else argparse.SUPPRESS,
        help="show fewer log lines: -q errors only",
    )


def log_level(args: argparse.Namespace) -> str:
    """The level the options select: ``--log-level`` (default warning), moved one step
    more verbose by each ``-v`` and one step quieter by each ``-q``."""
    values = vars(args)
    steps = sum(int(v) for k, v in values.items() if k.startswith("quiet_")) - sum(
        int(v) for k, v in values.items() if k.startswith("verbose_")
    )
    base = LEVELS.index(values.get("log_level") or DEFAULT_LEVEL)
    return LEVELS[min(max(base + steps, 0), len(LEVELS) - 1)]


def no_such_file(prog: str, name: str | Path, *, folder_ok: bool = False) -> bool:
    """True, after printing ``<prog>: <name>: no such file`` (or that it is a folder) on
    standard error, when ``name`` names no file; ``-`` (standard input) is a file."""
    path = Path(name)
    if str(name) == "-" or path.is_file() or (folder_ok and path.is_dir()):
        return False
    problem = "is a folder, not a file" if path.is_dir() else "no such file"
    print(f"{prog}: {name}: {problem}", file=sys.stderr)
    return True
