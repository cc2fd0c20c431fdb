"""The RTC lifecycle and configuration of a served rig (openel_zenoh.lifecycle,
lifecycle_server, lifecycle_commands: activate, deactivate, reset, conf get|set), each
command's async main through a real Zenoh session on loopback against the two-axis rig
served in this process as ``openel-async serve`` serves it; the commands as processes at
the end (one test)."""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path

import anyio
import pytest

from openel_async.component import ComponentState
from openel_async.motor import Motor, MotorControlMode
from openel_async.requests import Request
from openel_async.rig import Rig, load_rig, open_rig
from openel_async.surface import Surface
from openel_zenoh import SurfaceServer
from openel_zenoh import lifecycle_commands as lc
from openel_zenoh import shell_commands as sc
from openel_zenoh.config import endpoint, server_config
from openel_zenoh.estop import RigEstopServer
from openel_zenoh.lifecycle_server import RigLifecycleServer
from openel_zenoh.shell import RigShell

from .conftest import client_cfg, free_port, session

RIG = Path(__file__).resolve().parents[2] / "apps" / "openel_apps" / "rigs" / "twoaxis-sim.yaml"
CLI = [sys.executable, "-m", "openel_async.cli", "--log-level", "warning"]


def parse(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers(dest="command")
    for add in (
        lc.add_activate_parser,
        lc.add_deactivate_parser,
        lc.add_conf_parser,
        sc.add_reset_parser,
        sc.add_ls_parser,
        sc.add_set_parser,
    ):
        add(sub)
    return parser.parse_args(list(argv))


@asynccontextmanager
async def served(port: int, namespace: str = "twoaxis") -> AsyncIterator[Rig]:
    """The two-axis rig served as ``openel-async serve`` serves it."""
    async with (
        session(server_config([endpoint(port)])) as zs,
        open_rig(load_rig(RIG), sim=True) as rig,
        RigEstopServer(rig, zs, namespace),
        Surface(list(rig.components.values())) as surface,
        RigLifecycleServer(surface, zs, namespace) as lifecycle,
        SurfaceServer(surface, zs, namespace, admit=lifecycle.lifecycle.admit),
    ):
        yield rig


@asynccontextmanager
async def shell(port: int) -> AsyncIterator[RigShell]:
    async with RigShell(client_cfg(port), timeout=5.0) as opened:
        yield opened


def motor(rig: Rig, name: str) -> Motor:
    found = rig.actuator(name)
    assert isinstance(found, Motor)
    return found


async def test_deactivate_takes_the_torque_off_and_refuses_commands_until_activate(
    capsys: pytest.CaptureFixture[str],
) -> None:
    port = free_port()
    async with served(port) as rig, shell(port) as rig_shell:
        m1 = motor(rig, "MOTOR_1")
        assert await sc.set_main(rig_shell, _set("MOTOR_1", "0.2")) == 0
        assert m1.get_control_mode() is MotorControlMode.POSITION
        capsys.readouterr()

        assert await lc.lifecycle_main(rig_shell, parse("deactivate", "MOTOR_1")) == 0
        assert capsys.readouterr().out == "MOTOR_1 INACTIVE (HAL Active)\n"
        assert m1.get_control_mode() is MotorControlMode.READY_TO_CONTROL  # no torque
        assert await sc.set_main(rig_shell, _set("MOTOR_1", "0.5")) == sc.EXIT_FAILED
        err = capsys.readouterr().err
        assert "MOTOR_1 is INACTIVE (deactivated, no torque): SetPosition refused" in err
        assert m1.get_control_mode() is MotorControlMode.READY_TO_CONTROL
        assert await sc.set_main(rig_shell, _set("MOTOR_2", "0.1")) == 0  # the others go on
        capsys.readouterr()

        assert await sc.ls_main(rig_shell, parse("ls")) == 0
        lines = capsys.readouterr().out.splitlines()
        assert lines[1].split()[:4] == ["NAME", "ADDRESS", "STATE", "LIFECYCLE"]
        assert lines[2].split()[:4] == ["MOTOR_1", "Motor[0]", "Active", "INACTIVE"]
        assert lines[3].split()[:4] == ["MOTOR_2", "Motor[1]", "Active", "ACTIVE"]

        again = parse("deactivate", "MOTOR_1", "--json")
        assert await lc.lifecycle_main(rig_shell, again) == sc.EXIT_FAILED
        reply = json.loads(capsys.readouterr().out)
        assert "is INACTIVE: deactivate needs ACTIVE" in reply["failures"][0]

        position = await m1.get_value(Request.POSITION_ACTUAL)
        assert await lc.lifecycle_main(rig_shell, parse("activate", "MOTOR_1")) == 0
        assert capsys.readouterr().out == "MOTOR_1 ACTIVE (HAL Active)\n"
        assert m1.get_control_mode() is MotorControlMode.POSITION  # holding where it was
        held = await m1.get_value(Request.POSITION)  # (the rotor may still coast a little)
        assert held == pytest.approx(position, abs=0.02)
        assert await sc.set_main(rig_shell, _set("MOTOR_1", "0.0")) == 0


async def test_a_fault_is_error_and_reset_leaves_it_inactive(
    capsys: pytest.CaptureFixture[str],
) -> None:
    port = free_port()
    async with served(port) as rig, shell(port) as rig_shell:
        m2 = motor(rig, "MOTOR_2")
        await rig.estop()
        reply = await rig_shell.lifecycle("twoaxis", "get", ["MOTOR_2"])
        assert [(c.state, c.hal_state, c.latched) for c in reply.components] == [
            ("ERROR", "Error", True)
        ]
        assert await lc.lifecycle_main(rig_shell, parse("activate", "MOTOR_2")) == sc.EXIT_FAILED
        assert "MOTOR_2 is ERROR: activate needs INACTIVE" in capsys.readouterr().err
        rig.release_estop()
        assert await sc.reset_main(rig_shell, parse("reset", "MOTOR_2")) == 0
        out = capsys.readouterr().out
        assert out.startswith("MOTOR_2 Active INACTIVE (no torque"), out
        assert m2.state is ComponentState.ACTIVE
        assert m2.get_control_mode() is MotorControlMode.READY_TO_CONTROL
        assert await sc.set_main(rig_shell, _set("MOTOR_2", "0.3")) == sc.EXIT_FAILED
        reset = await rig_shell.lifecycle("twoaxis", "reset", ["MOTOR_1"])  # in Error too
        assert reset.return_code == 0 and reset.components[0].state == "INACTIVE"
        assert await lc.lifecycle_main(rig_shell, parse("activate", "MOTOR_1", "MOTOR_2")) == 0
        assert await sc.set_main(rig_shell, _set("MOTOR_2", "0.3")) == 0


async def test_conf_get_lists_the_limits_and_set_refuses_a_value_outside_its_constraint(
    capsys: pytest.CaptureFixture[str],
) -> None:
    port = free_port()
    async with served(port) as rig, shell(port) as rig_shell:
        m1 = motor(rig, "MOTOR_1")
        assert await lc.conf_main(rig_shell, parse("conf", "get", "MOTOR_1")) == 0
        out = capsys.readouterr().out.splitlines()
        assert out[0] == "MOTOR_1 set default (active)"
        names = [line.split()[0] for line in out[1:]]
        assert names[:3] == ["position_min", "position_max", "max_velocity"]
        assert out[2].split() == [
            "position_max", "3.141592653589793", "rad", "(double)",
            "[-3.141592653589793<=x<=3.141592653589793]",
        ]  # fmt: skip

        too_far = parse("conf", "set", "MOTOR_1", "position_max", "9")
        assert await lc.conf_main(rig_shell, too_far) == sc.EXIT_FAILED
        err = capsys.readouterr().err
        assert "violates constraint '-3.141592653589793<=x<=3.141592653589793'" in err
        assert m1.device.limits.position[1] == pytest.approx(3.141592653589793)

        narrow = parse("conf", "set", "MOTOR_1", "position_max", "0.5")
        assert await lc.conf_main(rig_shell, narrow) == 0
        assert capsys.readouterr().out == "MOTOR_1 default position_max 0.5\n"
        assert m1.device.limits.position[1] == 0.5  # live
        assert await sc.set_main(rig_shell, _set("MOTOR_1", "0.7")) == sc.EXIT_FAILED
        assert "expected a position in [" in capsys.readouterr().err

        crossed = parse("conf", "set", "MOTOR_1", "position_min", "0.6", "--json")
        assert await lc.conf_main(rig_shell, crossed) == sc.EXIT_FAILED
        assert json.loads(capsys.readouterr().out)["constraint"] == "position_min < position_max"

        speed = parse("conf", "get", "MOTOR_1", "max_velocity", "--json")
        assert await lc.conf_main(rig_shell, speed) == 0
        record = json.loads(capsys.readouterr().out)
        assert record["parameters"]["max_velocity"]["constraint"].startswith("0<x<=")
        assert record["sets"]["default"]["position_max"] == "0.5"

        assert await lc.conf_main(rig_shell, parse("conf", "get", "TEMP_2")) == 0
        assert capsys.readouterr().out == "TEMP_2: no configuration parameters\n"


def _set(name: str, value: str) -> argparse.Namespace:
    args = parse("set", name, value)
    args.arguments = sc.set_arguments(args)
    return args


@pytest.mark.parametrize(
    ("argv", "complaint"),
    [
        (("activate", "MOTOR_1", "--timeout", "0"), "--timeout=0.0 is not allowed"),
        (("deactivate", "MOTOR_1", "--namespace", "a/b"), "--namespace='a/b' is not allowed"),
        (("conf", "set", "MOTOR_1", "position_max", " "), "VALUE is empty"),
    ],
)
def test_usage_errors_exit_2_before_anything_is_opened(
    argv: tuple[str, ...], complaint: str, capsys: pytest.CaptureFixture[str]
) -> None:
    args = parse(*argv)
    run = {"activate": lc.run_activate, "deactivate": lc.run_deactivate, "conf": lc.run_conf}
    assert run[argv[0]](args) == 2
    assert complaint in capsys.readouterr().err


@pytest.mark.timeout(90)
async def test_lifecycle_commands_as_processes() -> None:
    port = free_port()
    where = ["--connect", endpoint(port), "--timeout", "10"]
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}

    async def run(*argv: str) -> subprocess.CompletedProcess[bytes]:
        with anyio.fail_after(60):
            return await anyio.run_process([*CLI, *argv, *where], check=False, env=env)

    async with served(port) as rig:
        m1 = motor(rig, "MOTOR_1")
        done: dict[str, subprocess.CompletedProcess[bytes]] = {}

        async def one(name: str, *argv: str) -> None:
            done[name] = await run(*argv)

        async with anyio.create_task_group() as tg:
            tg.start_soon(one, "deactivate", "deactivate", "MOTOR_1")
            tg.start_soon(one, "conf_set", "conf", "set", "MOTOR_2", "max_velocity", "99")
            tg.start_soon(one, "conf_get", "conf", "get", "MOTOR_2", "max_velocity", "--json")
            tg.start_soon(one, "activate", "activate", "MOTOR_1", "--namespace", "nope")
        assert m1.get_control_mode() is MotorControlMode.READY_TO_CONTROL
    assert done["deactivate"].returncode == 0, done["deactivate"]
    assert done["deactivate"].stdout == b"MOTOR_1 INACTIVE (HAL Active)\n"
    assert done["conf_set"].returncode == 3 and b"violates constraint '0<x<=" in (
        done["conf_set"].stderr
    )
    assert done["conf_get"].returncode == 0
    assert json.loads(done["conf_get"].stdout)["sets"]["default"]["max_velocity"]
    activate = done["activate"]
    assert activate.returncode == 1 and b"namespace 'nope'; served: twoaxis" in activate.stderr
    for process in done.values():
        assert b"Traceback" not in process.stderr
