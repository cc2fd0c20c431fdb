"""Ctrl-C ends the bring-up tools with status 130 and no traceback, in real processes.

Each command is started as a user starts it, left to reach the part of its work that waits
on the bus (a line it prints says so), then sent SIGINT as a terminal sends it.
"""

from __future__ import annotations

import os
import selectors
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

RIGS = Path(__file__).resolve().parents[2] / "apps" / "openel_apps" / "rigs"
SCAN_SO101 = ["scan", "serial", "--rig", str(RIGS / "so101.yaml"), "--sim"]


def wait_for(process: subprocess.Popen[bytes], marker: bytes, timeout: float) -> bytes:
    """What the process wrote to stdout and stderr until *marker* appeared (bounded)."""
    assert process.stdout is not None and process.stderr is not None
    seen = b""
    deadline = time.monotonic() + timeout
    with selectors.DefaultSelector() as selector:
        selector.register(process.stdout, selectors.EVENT_READ)
        selector.register(process.stderr, selectors.EVENT_READ)
        while marker not in seen:
            left = deadline - time.monotonic()
            assert left > 0, f"no {marker!r} within {timeout} s: {seen!r}"
            for key, _ in selector.select(left):
                chunk = os.read(key.fd, 65536)
                assert chunk or process.poll() is None, f"exited early: {seen!r}"
                seen += chunk
    return seen


@pytest.mark.parametrize(
    ("argv", "marker"),
    [
        pytest.param(
            ["bus", "monitor", str(RIGS / "twoaxis-can.yaml"), "can0", "--sim", "--duration", "60"],
            b"monitoring python-can virtual channel",
            id="bus-monitor",
        ),
        pytest.param(
            [*SCAN_SO101, "--ids", "0-252", "--timeout", "0.5", "-v"],
            b"serial_port_opened",
            id="scan-serial",
        ),
    ],
)
def test_ctrl_c_exits_130_without_a_traceback(argv: list[str], marker: bytes) -> None:
    process = subprocess.Popen(
        [sys.executable, "-m", "openel_async.cli", *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env=dict(os.environ, NO_COLOR="1"),
    )
    try:
        wait_for(process, marker, timeout=30.0)
        process.send_signal(signal.SIGINT)
        out, err = process.communicate(timeout=15.0)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait(5.0)
    assert process.returncode == 130, err
    assert b"interrupted by SIGINT" in err and b"Traceback" not in err + out
