"""``openel-async jog`` (issue 25 point 4): the Textual UI driven headless by its Pilot against
simulated rigs -- key presses reach the simulated devices, jogs stay within the limits, the
e-stop key e-stops the rig -- and the command's usage errors."""

from __future__ import annotations

import math
import subprocess
import sys
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from pathlib import Path

import anyio
import pytest
from textual.pilot import Pilot

from openel_async.cli import main
from openel_async.motor import Motor, MotorControlMode
from openel_async.requests import Request
from openel_async.rig import Rig, load_rig, open_rig
from openel_async.tui.app import JogApp
from openel_async.tui.jogger import Jogger

ROOT = Path(__file__).resolve().parents[2]
TWOAXIS = ROOT / "apps" / "openel_apps" / "rigs" / "twoaxis-sim.yaml"
SIZE = (110, 36)

SMALL_RIG = """\
description: two sim motors, the first with narrow limits, the second in a group
namespace: jogtest
components:
  - {name: NARROW, driver: sim, device: motor, params: {max_velocity: 3.0},
     limits: {position: [-0.3, 0.3]}}
  - {name: GROUPED, driver: sim, device: motor, params: {max_velocity: 3.0}}
  - {name: ENC, driver: sim, device: encoder, params: {motor: {ref: NARROW}}}
timers:
  tick: {period_ms: 20.0}
groups:
  one: {axes: [GROUPED], timer: tick, limits: {max_velocity: 3.0, max_acceleration: 50.0,
        max_jerk: 2000.0}}
safety:
  on_exit: hold
"""


@asynccontextmanager
async def jog_app(
    path: Path, *, step: float = 0.1, velocity: float = 2.0
) -> AsyncIterator[tuple[Rig, Jogger, JogApp, Pilot[None]]]:
    async with (
        open_rig(load_rig(path), sim=True) as rig,
        Jogger(rig, step=step, velocity=velocity) as jogger,
    ):
        app = JogApp(jogger)
        async with app.run_test(size=SIZE) as pilot:
            yield rig, jogger, app, pilot


async def until(pilot: Pilot[None], check: Callable[[], object]) -> None:
    """Let the app run until ``check()`` holds (bounded: 5 s)."""
    with anyio.fail_after(5.0):
        while not check():
            await pilot.pause(0.02)


@pytest.fixture
def small_rig(tmp_path: Path) -> Path:
    path = tmp_path / "small.yaml"
    path.write_text(SMALL_RIG)
    return path


async def test_arrow_keys_jog_the_selected_axis_within_its_limits(small_rig: Path) -> None:
    async with jog_app(small_rig, step=0.25) as (rig, jogger, _app, pilot):
        narrow = rig.actuator("NARROW")
        assert jogger.row.name == "NARROW"  # the first axis is selected
        await pilot.press("right", "right")  # 0.25, then 0.5 clamped to the limit 0.3
        assert jogger.row.target == pytest.approx(0.3)
        await until(pilot, lambda: abs(narrow.get_value_nowait(Request.POSITION) - 0.3) < 1e-9)
        assert narrow.get_value_nowait(Request.POSITION) <= 0.3
        await pilot.press("right")  # already there: refused, said so
        assert any("at its limit" in e.text for e in jogger.log)
        await pilot.press("left_square_bracket", "left")  # step 0.1: back to 0.2
        assert jogger.step == pytest.approx(0.1)
        await until(pilot, lambda: abs(narrow.get_value_nowait(Request.POSITION) - 0.2) < 1e-9)
        await pilot.press("down")  # GROUPED: moved by its group
        assert jogger.row.name == "GROUPED"
        await pilot.press("left")
        grouped = rig.actuator("GROUPED")
        await until(pilot, lambda: abs(grouped.get_value_nowait(Request.POSITION) + 0.1) < 1e-6)
        assert rig.group("one").commanded == pytest.approx((-0.1,))


async def test_the_e_stop_key_e_stops_the_rig_and_r_releases_it() -> None:
    async with jog_app(TWOAXIS) as (rig, jogger, _app, pilot):
        await pilot.press("x")
        await until(pilot, lambda: rig.estopped)
        await until(pilot, lambda: all(str(c.state) == "Error" for c in rig.components.values()))
        await pilot.press("right")  # refused while e-stopped
        assert any("not jogged (e-stopped" in e.text for e in jogger.log)
        await pilot.press("r")
        await until(pilot, lambda: all(str(c.state) == "Active" for c in rig.components.values()))
        assert not rig.estopped
    assert [r.how for r in rig.exit_report] == ["device", "device"] or all(
        r.ok for r in rig.exit_report
    )


async def test_disable_takes_the_torque_off_and_enable_holds() -> None:
    async with jog_app(TWOAXIS) as (rig, jogger, _app, pilot):
        motor = rig.actuator("MOTOR_2")
        assert isinstance(motor, Motor)
        await pilot.press("down", "right")  # MOTOR_2 excited in position mode
        await until(pilot, lambda: motor.get_control_mode() is MotorControlMode.POSITION)
        await pilot.press("d")
        await until(pilot, lambda: motor.get_control_mode() is MotorControlMode.READY_TO_CONTROL)
        await pilot.press("e")
        await until(pilot, lambda: motor.get_control_mode() is MotorControlMode.POSITION)
        assert any("enabled" in e.text for e in jogger.log)


async def test_values_plots_and_a_screenshot() -> None:
    async with jog_app(TWOAXIS) as (_rig, jogger, app, pilot):
        await until(pilot, lambda: all(len(r.history) >= 2 for r in jogger.rows))
        temp = next(r for r in jogger.rows if r.name == "TEMP_2")
        assert temp.units == "K" and 250 < temp.values[0] < 350
        await pilot.press("down", "down", "down", "p")  # TEMP_2 plotted too
        assert temp.plotted
        await pilot.pause(0.15)
        text = app.export_screenshot()
    assert "MOTOR_1" in text and "TEMP_2" in text and "E-STOP" in text


async def test_usage_errors_open_nothing(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["jog", str(TWOAXIS), "--velocity", "nan"]) == 2
    assert main(["jog", str(TWOAXIS)]) == 2  # not a terminal here: refused before opening
    err = capsys.readouterr().err
    assert "--velocity nan" in err and "needs a terminal" in err


def test_command_usage_errors_exit_2() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "openel_async.cli", "jog", "no-such-rig.yaml", "--sim"],
        capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    assert done.returncode == 2
    assert "no-such-rig.yaml: no such file" in done.stderr
    assert "Traceback" not in done.stderr


def test_steps_and_velocities_are_chosen_from_their_lists() -> None:
    jogger = Jogger.__new__(Jogger)
    jogger.step, jogger.velocity = 0.05, 0.5
    assert jogger.change_step(1) == 0.1 and jogger.change_step(-1) == 0.05
    assert jogger.change_velocity(10) == 5.0 and jogger.change_velocity(-100) == 0.01
    assert math.isclose(jogger.change_step(-100), 0.001)
