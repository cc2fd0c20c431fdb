"""A pseudo-terminal for the CLI tests, and a small screen emulator: what a person sees."""

from __future__ import annotations

import fcntl
import os
import pty
import re
import select
import struct
import subprocess
import sys
import termios
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
COLUMNS = 120
_CSI = re.compile(r"\x1b\[([?0-9;]*)([A-Za-z])")
_OSC = re.compile(r"\x1b\][^\x07\x1b]*(?:\x07|\x1b\\)")


def set_size(fd: int, rows: int = 40, columns: int = COLUMNS) -> None:
    fcntl.ioctl(fd, termios.TIOCSWINSZ, struct.pack("HHHH", rows, columns, 0, 0))


def read_all(master: int, timeout: float = 60.0) -> bytes:
    """Everything written to the terminal until every writer closed it."""
    out = b""
    while select.select([master], [], [], timeout)[0]:
        try:
            chunk = os.read(master, 65536)
        except OSError:  # EIO: the other side is closed
            break
        if not chunk:
            break
        out += chunk
    return out


def run_cli_in_pty(*args: str, timeout: float = 90.0) -> tuple[int, str]:
    """``python -m openel_async.cli ARGS`` with stdin, stdout and stderr on one terminal;
    returns its exit status and everything it wrote."""
    master, slave = pty.openpty()
    set_size(slave)
    env = {**os.environ, "TERM": "xterm-256color", "COLUMNS": str(COLUMNS)}
    env.pop("NO_COLOR", None)
    proc = subprocess.Popen(
        [sys.executable, "-m", "openel_async.cli", *args],
        stdin=slave, stdout=slave, stderr=slave, env=env, cwd=ROOT, close_fds=True,
    )  # fmt: skip
    os.close(slave)
    try:
        output = read_all(master, timeout)
        code = proc.wait(timeout)
    finally:
        os.close(master)
        if proc.poll() is None:
            proc.kill()
    return code, output.decode("utf-8", "replace")


def screen(output: str, columns: int = COLUMNS) -> list[str]:
    """The lines a terminal of ``columns`` shows after ``output`` (cursor moves, carriage
    returns, line erasures and wrapping applied; colours dropped)."""
    lines: list[list[str]] = [[]]
    row = col = 0

    def at(r: int) -> list[str]:
        while len(lines) <= r:
            lines.append([])
        return lines[r]

    i = 0
    while i < len(output):
        m = _CSI.match(output, i) or _OSC.match(output, i)
        if m is not None:
            if m.re is _CSI:
                params, command = m.group(1), m.group(2)
                n = int(params) if params.isdigit() else 0
                if command == "A":
                    row = max(0, row - (n or 1))
                elif command == "B":
                    row += n or 1
                elif command == "G":
                    col = max(0, (n or 1) - 1)
                elif command == "K":
                    line = at(row)
                    if n == 2:
                        line.clear()
                    elif n == 0:
                        del line[col:]
                    else:
                        line[:col] = [" "] * min(col, len(line))
            i = m.end()
            continue
        c = output[i]
        i += 1
        if c == "\r":
            col = 0
        elif c == "\n":
            row += 1
        elif c == "\b":
            col = max(0, col - 1)
        elif c == "\x1b" or c < " ":
            continue
        else:
            if col >= columns:
                row, col = row + 1, 0
            line = at(row)
            while len(line) < col:
                line.append(" ")
            if col < len(line):
                line[col] = c
            else:
                line.append(c)
            col += 1
    return ["".join(line).rstrip() for line in lines]
