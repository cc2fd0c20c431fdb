"""Issue 22, safe stop on every exit path: whether a run ends normally, by Ctrl-C, by SIGTERM or
by an exception, every actuator of the rig is left in the state ``safety.on_exit`` names, on
the simulated drives themselves, and the summary says so. The rig is the two-axis demo's CAN
rig (an ODrive and a CiA 402 drive) with ``--sim``: the simulated peers on a virtual bus;
SIGTERM is tested on a rig of two Dynamixel servos on a simulated port."""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
APP = Path(__file__).with_name("exit_app.py")
CAN_RIG = ROOT / "apps" / "openel_apps" / "rigs" / "twoaxis-can.yaml"

HOLDING = ["peer MOTOR_1 axis_state=CLOSED_LOOP_CONTROL", "peer MOTOR_2 power_state=OPERATION_ENABLED"]  # fmt: skip
TORQUE_OFF = ["peer MOTOR_1 axis_state=IDLE"]


def _rig(tmp_path: Path, on_exit: str) -> Path:
    path = tmp_path / f"rig-{on_exit}.yaml"
    path.write_text(CAN_RIG.read_text().replace("on_exit: hold", f"on_exit: {on_exit}"))
    return path


def _start(rig: Path, then: str) -> subprocess.Popen[str]:
    env = dict(os.environ, NO_COLOR="1")
    return subprocess.Popen(
        [sys.executable, "-m", "openel_async.cli", "run", str(APP), "--rig", str(rig), "--sim",
         "--", "--then", then],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
    )  # fmt: skip


def _wait_for(proc: subprocess.Popen[str], wanted: set[str], timeout: float = 20.0) -> list[str]:
    """Read lines until every one of ``wanted`` was printed (bounded)."""
    assert proc.stdout is not None
    lines: list[str] = []
    missing = set(wanted)
    deadline = time.monotonic() + timeout
    while missing and time.monotonic() < deadline:
        if not select.select([proc.stdout], [], [], deadline - time.monotonic())[0]:
            break
        line = proc.stdout.readline()
        if not line:
            break
        lines.append(line.rstrip("\n"))
        missing.discard(line.strip())
    if missing:
        proc.kill()
        err = proc.stderr.read() if proc.stderr else ""
        raise AssertionError(f"never printed {sorted(missing)}: {lines} {err}")
    return lines


def _wait_ready(proc: subprocess.Popen[str]) -> list[str]:
    return _wait_for(proc, {"ready"})


def _finish(proc: subprocess.Popen[str], timeout: float = 20.0) -> tuple[int, str, str]:
    out, err = proc.communicate(timeout=timeout)
    return proc.returncode, out, err


def test_a_normal_end_holds(tmp_path: Path) -> None:
    proc = _start(_rig(tmp_path, "hold"), "return")
    _wait_ready(proc)
    code, out, err = _finish(proc)
    assert code == 0, err
    assert "on exit            hold: MOTOR_1 done, MOTOR_2 done" in out
    for line in HOLDING:
        assert line in out


def test_ctrl_c_leaves_the_drives_as_on_exit_says(tmp_path: Path) -> None:
    signum, status = signal.SIGINT, 130
    proc = _start(_rig(tmp_path, "hold"), "wait")
    _wait_ready(proc)
    proc.send_signal(signum)
    code, out, err = _finish(proc)
    assert code == status, err
    assert "interrupted" in out
    assert "on exit            hold: MOTOR_1 done, MOTOR_2 done" in out
    for line in HOLDING:
        assert line in out


def test_an_exception_still_leaves_the_drives_safe(tmp_path: Path) -> None:
    proc = _start(_rig(tmp_path, "torque_off"), "raise")
    _wait_ready(proc)
    code, out, err = _finish(proc)
    assert code == 1
    assert "RuntimeError: the app failed" in err
    assert "on exit            torque_off: MOTOR_1 done, MOTOR_2 done" in err
    for line in TORQUE_OFF:
        assert line in out
    assert "peer MOTOR_2 power_state=OPERATION_ENABLED" not in out


def test_sigquit_estops_every_drive_and_the_exit_leaves_them_so(tmp_path: Path) -> None:
    proc = _start(_rig(tmp_path, "hold"), "wait")
    _wait_ready(proc)
    proc.send_signal(signal.SIGQUIT)
    _wait_for(proc, {"error MOTOR_1 8", "error MOTOR_2 8"})  # ErrorId.ESTOP on both
    proc.send_signal(signal.SIGINT)  # the exit must not undo the e-stop
    code, out, err = _finish(proc)
    assert code == 130, err
    assert "on exit            hold: MOTOR_1 e-stopped, MOTOR_2 e-stopped" in out
    assert "peer MOTOR_1 axis_state=IDLE" in out  # ODrive Estop: disarmed
    # CiA 402 quick stop: power stage off (or holding in Quick stop active), never enabled
    motor_2 = next(line for line in out.splitlines() if line.startswith("peer MOTOR_2 "))
    assert motor_2.split("=")[1] in {
        "QUICK_STOP_ACTIVE", "SWITCH_ON_DISABLED", "READY_TO_SWITCH_ON"
    }, motor_2  # fmt: skip


SERVOS = """\
description: two Dynamixel servos
buses:
  arm: {type: serial, protocol: dynamixel, device: /dev/ttyUSB0, baudrate: 1000000}
components:
  - {name: J1, driver: serial, device: dynamixel_xm430_w350, bus: arm, params: {dxl_id: 1}}
  - {name: J2, driver: serial, device: dynamixel_xm430_w350, bus: arm, params: {dxl_id: 2}}
safety: {watchdog_timeout: 0.5, on_exit: ON_EXIT}
"""


def test_sigterm_leaves_dynamixel_servos_as_on_exit_says(tmp_path: Path) -> None:
    """SIGTERM, on the other driver with a safe stop of its own (torque_off: the servos'
    Torque Enable 0; holding, see the CAN tests, keeps it on)."""
    on_exit, torque = "torque_off", "off"
    rig = tmp_path / "servos.yaml"
    rig.write_text(SERVOS.replace("ON_EXIT", on_exit))
    proc = _start(rig, "wait")
    _wait_ready(proc)
    proc.send_signal(signal.SIGTERM)
    code, out, err = _finish(proc)
    assert code == 143, err
    assert f"on exit            {on_exit}: J1 done, J2 done" in out
    assert f"peer J1 torque={torque}" in out and f"peer J2 torque={torque}" in out
