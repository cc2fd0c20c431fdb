"""Issue 22, real adapter code paths: the two-axis demo's ODrive and CiA 402 drives through
python-can's own ``slcan`` interface against the simulated slcan adapter on a pty, from a rig
file alone; and ``kill -9`` of the app: every drive stops within its watchdog timeout."""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

from openel_can.sim.slcan import SlcanAdapterProcess

ROOT = Path(__file__).resolve().parents[2]
CAN_RIG = ROOT / "apps" / "openel_apps" / "rigs" / "twoaxis-can.yaml"
APP = Path(__file__).with_name("exit_app.py")
TIMEOUT_S = 0.3
CIA402_STOPPED = frozenset(
    {"cia402 2 QUICK_STOP_ACTIVE", "cia402 2 SWITCH_ON_DISABLED", "cia402 2 READY_TO_SWITCH_ON"}
)
"""A quick stop as its option code 0x605A says: holding in Quick stop active, or on through it
to a disabled power stage."""


def _slcan_rig(tmp_path: Path, port: str, watchdog_s: float = 0.5) -> Path:
    text = CAN_RIG.read_text()
    text = text.replace(
        "    interface: socketcan\n    channel: can0\n",
        f"    interface: slcan\n    channel: {port}\n    sleep_after_open: 0\n",
    )
    text = text.replace("watchdog_timeout: 0.5", f"watchdog_timeout: {watchdog_s}")
    assert f"channel: {port}" in text and f"watchdog_timeout: {watchdog_s}" in text
    path = tmp_path / "slcan-rig.yaml"
    path.write_text(text)
    return path


def test_the_two_axis_demo_runs_through_slcan_from_a_rig_file(tmp_path: Path) -> None:
    with SlcanAdapterProcess("--odrive", "1", "--cia402", "2") as adapter:
        rig = _slcan_rig(tmp_path, adapter.port)
        result = subprocess.run(
            [sys.executable, "-m", "openel_async.cli", "run", "twoaxis", "--rig", str(rig),
             "--duration", "1", "--no-live"],
            capture_output=True, text=True, timeout=60, env=dict(os.environ, NO_COLOR="1"),
        )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "summary (CAN: ODrive node 1 (CANSimple) + CiA 402 node 2 (CANopen))" in result.stdout
    assert "errors             0" in result.stdout
    assert "final positions    MOTOR_1 +0.0000 rad, MOTOR_2 +0.0000 rad" in result.stdout
    assert "on exit            hold: MOTOR_1 done, MOTOR_2 done" in result.stdout


class Lines:
    """Lines of a pipe read with ``os.read`` (a buffered reader's ``readline`` may hold lines
    that ``select`` no longer sees)."""

    def __init__(self, stream: object) -> None:
        self.fd = stream.fileno()  # type: ignore[attr-defined]
        self.buffer = b""
        self.seen: list[str] = []

    def until(self, wanted: set[str | frozenset[str]], timeout: float) -> float:
        """Read until every one of ``wanted`` (a line, or a set of lines any of which will
        do) was seen; the time the last one was."""
        missing = {w if isinstance(w, frozenset) else frozenset({w}) for w in wanted}
        deadline = time.monotonic() + timeout
        while missing:
            while b"\n" in self.buffer and missing:
                raw, self.buffer = self.buffer.split(b"\n", 1)
                line = raw.decode().strip()
                self.seen.append(line)
                missing = {group for group in missing if line not in group}
            if not missing:
                break
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([self.fd], [], [], left)[0]:
                raise AssertionError(f"never saw {sorted(missing)} (saw {self.seen})")
            chunk = os.read(self.fd, 4096)
            if not chunk:
                raise AssertionError(f"end of output before {sorted(missing)} (saw {self.seen})")
            self.buffer += chunk
        return time.monotonic()


def test_kill_9_of_the_app_lets_every_drive_stop_within_its_watchdog(tmp_path: Path) -> None:
    with SlcanAdapterProcess("--odrive", "1", "--cia402", "2", "--report") as adapter:
        assert adapter.process is not None and adapter.process.stdout is not None
        states = Lines(adapter.process.stdout)
        rig = _slcan_rig(tmp_path, adapter.port, TIMEOUT_S)
        app = subprocess.Popen(
            [sys.executable, "-m", "openel_async.cli", "run", str(APP), "--rig", str(rig), "--",
             "--then", "wait"],
            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
        )  # fmt: skip
        try:
            assert app.stdout is not None
            Lines(app.stdout).until({"ready"}, 30)
            states.until({"odrive 1 CLOSED_LOOP_CONTROL", "cia402 2 OPERATION_ENABLED"}, 5)
            killed = time.monotonic()
            os.kill(app.pid, signal.SIGKILL)
            # ODrive: the axis watchdog disarms it to IDLE; CiA 402: the heartbeat consumer
            # (abort connection option 3) quick-stops it.
            stopped = states.until({"odrive 1 IDLE", CIA402_STOPPED}, 5)
        finally:
            app.kill()
            app.wait(10)
        # within the timeout, plus the peers' own polling and the report's 10 ms
        assert stopped - killed < TIMEOUT_S + 0.25
