"""``openel-async jog --remote NAMESPACE`` (openel_zenoh.jog): the Textual UI driven headless
by its Pilot over a rig served in this process on loopback -- key presses move the served
simulated device within the limits the server reports, d/e deactivate and activate it, x
e-stops the served rig -- and the command's usage errors."""

from __future__ import annotations

import argparse
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager

import anyio
import pytest
from textual.pilot import Pilot

from openel_async.cli import main
from openel_async.motor import MotorControlMode
from openel_async.requests import Request
from openel_async.rig import Rig
from openel_async.tui.app import JogApp
from openel_zenoh.config import endpoint
from openel_zenoh.jog import REMOTE_JOG, RemoteJogger

from .conftest import free_port
from .test_lifecycle import motor, served

SIZE = (110, 36)


@asynccontextmanager
async def remote_jog(
    step: float = 0.25,
) -> AsyncIterator[tuple[Rig, RemoteJogger, JogApp, Pilot[None]]]:
    port = free_port()
    args = argparse.Namespace(
        remote="twoaxis", connect=[endpoint(port)], config=None, timeout=5.0,
        step=step, velocity=5.0,
    )  # fmt: skip
    assert REMOTE_JOG.check(args) is None
    async with served(port) as rig, REMOTE_JOG.session(args) as jogger:
        assert isinstance(jogger, RemoteJogger)
        app = JogApp(jogger)
        async with app.run_test(size=SIZE) as pilot:
            yield rig, jogger, app, pilot


async def until(pilot: Pilot[None], check: Callable[[], object]) -> None:
    with anyio.fail_after(5.0):
        while not check():
            await pilot.pause(0.02)


async def test_keys_jog_the_served_axis_within_the_served_limits() -> None:
    async with remote_jog() as (rig, jogger, app, pilot):
        m1 = motor(rig, "MOTOR_1")
        m1.device.limits = type(m1.device.limits)((-0.6, 0.6), 2.0, m1.device.limits.torque)
        assert jogger.row.name == "MOTOR_1"
        await until(pilot, lambda: jogger.row.values and jogger.row.limits == (-0.6, 0.6))
        await pilot.press("right", "right", "right")  # 0.25, 0.5, then 0.6: the limit
        await until(pilot, lambda: abs(m1.get_value_nowait(Request.POSITION) - 0.6) < 1e-9)
        await pilot.press("right")
        assert any("at its limit 0.6" in e.text for e in jogger.log)
        assert "served rig 'twoaxis'" in app.sub_title
        text = app.export_screenshot()
    assert "MOTOR_1" in text and "[-0.6,&#160;0.6]" in text


async def test_d_deactivates_e_activates_and_x_e_stops_the_served_rig() -> None:
    async with remote_jog() as (rig, jogger, _app, pilot):
        m1 = motor(rig, "MOTOR_1")
        await until(pilot, lambda: jogger.row.values)
        await pilot.press("right")
        await until(pilot, lambda: m1.get_control_mode() is MotorControlMode.POSITION)
        await pilot.press("d")
        await until(pilot, lambda: m1.get_control_mode() is MotorControlMode.READY_TO_CONTROL)
        await until(pilot, lambda: jogger.row.state == "Inactive")
        await pilot.press("right")  # refused: not jogged
        assert any("is Inactive: not jogged" in e.text for e in jogger.log)
        await pilot.press("e")
        await until(pilot, lambda: m1.get_control_mode() is MotorControlMode.POSITION)
        await pilot.press("x")
        await until(pilot, lambda: rig.estopped)
        await until(pilot, lambda: jogger.row.state == "Error")
        await pilot.press("r")
        await until(pilot, lambda: not rig.estopped and jogger.row.state == "Inactive")
        assert str(m1.state) == "Active"


def test_usage_errors_exit_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["jog", "--remote", "a/b"]) == 2
    assert main(["jog", "rig.yaml", "--remote", "lab"]) == 2
    assert main(["jog", "--remote", "lab", "--timeout", "0"]) == 2
    assert main(["jog", "--remote", "lab"]) == 2  # not a terminal here: refused before opening
    err = capsys.readouterr().err
    assert "--remote='a/b' is not allowed" in err
    assert "no RIG.yaml" in err and "--timeout=0.0 is not allowed" in err
    assert "needs a terminal" in err
