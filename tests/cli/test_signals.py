"""SIGINT and SIGTERM end every long-running command promptly and cleanly: real processes,
signalled once they printed their first progress line."""

from __future__ import annotations

import os
import queue
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAN_TILT = ROOT / "apps" / "pan_tilt" / "RTC.yaml"
STARTUP_S = 60.0
"""Bound on a command's start-up (imports, MuJoCo's model) until its first progress line."""
STOP_S = 15.0
"""Bound on the time from the signal to the end of the process."""


class Command:
    """A CLI process whose output (stdout and stderr merged) is read line by line."""

    def __init__(self, args: list[str], cwd: Path) -> None:
        env = dict(os.environ, PYTHONUNBUFFERED="1", MUJOCO_GL=os.environ.get("MUJOCO_GL", ""))
        self.process = subprocess.Popen(
            [sys.executable, "-m", "openel_async.cli", "--log-format", "json", *args],
            cwd=cwd,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        self.lines: list[str] = []
        self._queue: queue.Queue[str | None] = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            self._queue.put(line)
        self._queue.put(None)

    def wait_for(self, text: str, timeout: float = STARTUP_S) -> None:
        deadline = time.monotonic() + timeout
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                break
            try:
                line = self._queue.get(timeout=remaining)
            except queue.Empty:
                break
            if line is None:
                break
            self.lines.append(line)
            if text in line:
                return
        self.process.kill()
        pytest.fail(f"no line with {text!r} within {timeout} s:\n{self.output()}")

    def stop(self, signum: signal.Signals) -> tuple[int, float]:
        """Send ``signum``; the exit status and the seconds until the process ended."""
        sent = time.monotonic()
        self.process.send_signal(signum)
        try:
            code = self.process.wait(timeout=STOP_S)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
            pytest.fail(f"still running {STOP_S} s after {signum.name}:\n{self.output()}")
        elapsed = time.monotonic() - sent
        while (line := self._queue.get(timeout=STOP_S)) is not None:
            self.lines.append(line)
        return code, elapsed

    def output(self) -> str:
        return "".join(self.lines)


def test_ctrl_c_stops_the_sim_demo_with_a_summary(tmp_path: Path) -> None:
    command = Command(["demo", "--bus", "sim", "--duration", "60"], tmp_path)
    command.wait_for("ticks=")  # the live progress line (plain lines off a terminal)
    code, elapsed = command.stop(signal.SIGINT)
    out = command.output()
    assert code == 130, out
    assert "Traceback" not in out
    assert "summary (simulated devices, openel_sim, interrupted)" in out
    assert "interrupted        by SIGINT after" in out
    assert "openel-async: interrupted by SIGINT (exit status 130)" in out
    assert elapsed < STOP_S


def test_sigterm_stops_the_mujoco_demo_and_leaves_no_partial_file(tmp_path: Path) -> None:
    out_dir = tmp_path / "out"
    command = Command(["demo", "--duration", "30", "--out", str(out_dir)], tmp_path)
    command.wait_for("s sim")  # the square's live progress line
    code, _ = command.stop(signal.SIGTERM)
    out = command.output()
    assert code == 143, out
    assert "Traceback" not in out
    assert "summary (MuJoCo arm2 demo, interrupted)" in out
    assert "interrupted        by SIGTERM after" in out
    # stopped mid-run: the files of the end of the run are absent, and no temporary is left
    files = sorted(p.name for p in out_dir.iterdir()) if out_dir.exists() else []
    assert files == [], files
    assert "files              none written" in out


def test_signals_end_a_profile_run_with_its_summary(tmp_path: Path) -> None:
    command = Command(["-v", "run", str(PAN_TILT)], tmp_path)  # until Ctrl-C; -v: info events
    command.wait_for("profile_running")
    code, elapsed = command.stop(signal.SIGTERM)
    out = command.output()
    assert code == 143, out
    assert "Traceback" not in out
    assert "stopped by         SIGTERM" in out and "cycles" in out
    assert elapsed < STOP_S


def test_ctrl_c_stops_a_python_app(tmp_path: Path) -> None:
    app = tmp_path / "sleeper.py"
    app.write_text(
        "import anyio\n\n"
        "async def main(argv):\n"
        "    print('started', flush=True)\n"
        "    try:\n"
        "        await anyio.sleep(600)\n"
        "    finally:\n"
        "        print('cleaned up', flush=True)\n"
    )
    command = Command(["run", str(app)], tmp_path)
    command.wait_for("started")
    code, _ = command.stop(signal.SIGINT)
    out = command.output()
    assert code == 130, out
    assert "Traceback" not in out
    assert "cleaned up" in out
    assert "interrupted by SIGINT (exit status 130)" in out
