"""Issue 27 point 2: each command loads what it uses. ``openel-async --help`` lists every
command (the drivers' too) without importing the heavy libraries behind them."""

from __future__ import annotations

import re
import subprocess
import sys

HEAVY = ("structlog", "mujoco", "matplotlib", "zenoh", "foxglove", "can", "serial", "textual")


def test_help_imports_none_of_the_heavy_libraries() -> None:
    done = subprocess.run(
        [sys.executable, "-X", "importtime", "-m", "openel_async.cli", "--help"],
        capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "serve" in done.stdout and "rig" in done.stdout  # a driver's command, the framework's
    imported = set(re.findall(r"^import time:\s+\d+ \|\s+\d+ \| +(\S+)$", done.stderr, re.M))
    assert "openel_async.cli" in imported  # (the output is what this test reads)
    top = {name.split(".")[0] for name in imported}
    assert not top.intersection(HEAVY), sorted(top.intersection(HEAVY))
