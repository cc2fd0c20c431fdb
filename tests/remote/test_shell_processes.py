"""The shell commands as processes (openel-async set --wait, watch until Ctrl-C) against the
two-axis rig served in this process: the entry points wired, the exit statuses, Ctrl-C. One
test, its processes at once; the behaviour is tested in-process (test_shell.py)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys

import anyio
import pytest

from openel_zenoh.config import endpoint

from .conftest import free_port
from .test_shell import served

CLI = [sys.executable, "-m", "openel_async.cli", "--log-level", "warning"]
ENV = {**os.environ, "PYTHONUNBUFFERED": "1"}


@pytest.mark.timeout(90)
async def test_shell_commands_as_processes() -> None:
    port = free_port()
    where = ["--connect", endpoint(port), "--timeout", "10"]
    done: dict[str, subprocess.CompletedProcess[bytes]] = {}

    async def run(name: str, *argv: str) -> None:
        with anyio.fail_after(60):
            done[name] = await anyio.run_process([*CLI, *argv, *where], check=False, env=ENV)

    async def watch_until_ctrl_c() -> None:
        async with await anyio.open_process(
            [*CLI, "watch", "MOTOR_2", "--rate", "5", *where],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=ENV,
        ) as process:  # fmt: skip
            assert process.stdout is not None and process.stderr is not None
            with anyio.fail_after(60):
                first = (await process.stdout.receive()).decode()
                process.send_signal(signal.SIGINT)
                code = await process.wait()
                errors = b"".join([chunk async for chunk in process.stderr]).decode()
            assert "MOTOR_2      value  position" in first
            assert code == 130, errors
            assert "Traceback" not in errors and "interrupted by SIGINT" in errors

    async with served(port) as rigs:
        async with anyio.create_task_group() as tg:
            tg.start_soon(run, "set", "set", "MOTOR_1", "0.1", "--wait")
            tg.start_soon(watch_until_ctrl_c)
        assert await rigs[0].component("MOTOR_1").get_value() == pytest.approx(0.1, abs=1e-6)
    assert done["set"].returncode == 0 and done["set"].stdout == b"COMPLETED\n", done["set"]
