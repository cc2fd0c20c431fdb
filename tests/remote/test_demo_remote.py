"""``openel-async demo --remote``: the two-axis demo with its devices served by a second
process (``openel-async serve``), stopped with the demo, also on Ctrl-C."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys

import anyio
import anyio.abc
import pytest

# -v: the tests follow the server process through its info events (the default shows warnings).
DEMO = [sys.executable, "-m", "openel_async.cli", "-v", "demo", "--remote", "--no-live"]
ENV = {**os.environ, "PYTHONUNBUFFERED": "1"}


def gone(pid: int) -> bool:
    """Whether process ``pid`` has ended (and was reaped by its parent)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    with open(f"/proc/{pid}/stat") as stat:  # a zombie is as good as gone
        return stat.read().split(") ", 1)[1].startswith("Z")


def server_pid(output: str) -> int:
    found = re.search(r"serve_process_started\s+.*?pid=(\d+)", output)
    assert found is not None, output
    return int(found.group(1))


@pytest.mark.timeout(90)
def test_demo_remote_runs_the_two_axis_demo_on_a_served_rig() -> None:
    done = subprocess.run(
        [*DEMO, "--duration", "0.5"], capture_output=True, text=True, timeout=60, env=ENV
    )
    output = done.stdout + done.stderr
    assert done.returncode == 0, output
    assert "summary (simulated devices served by 'openel-async serve' (pid" in output
    # 50 ticks x 2 axes on an idle machine; on a loaded one many ticks find the observer
    # still awaiting the previous tick's four remote calls (the timer discards them)
    sent = re.search(r"setpoints sent\s+(\d+)\b", output)
    assert sent is not None and 10 <= int(sent.group(1)) <= 100, output
    assert re.search(r"errors\s+0\b", output), output
    assert re.search(r"sensor reads\s+[1-9]", output), output
    pid = server_pid(output)
    assert "serve_process_stopped" in output
    assert gone(pid)


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--inject-fault"], "--inject-fault needs --bus sim or can: the remote devices are in"),
        (["--bus", "can"], "--remote serves the sim devices; not with --bus can"),
        (["--virtual"], "--virtual needs --bus sim"),
    ],
)
def test_demo_remote_refuses_what_it_cannot_do(extra: list[str], message: str) -> None:
    done = subprocess.run(
        [*DEMO, "--duration", "0.5", *extra], capture_output=True, text=True, timeout=60, env=ENV
    )
    assert done.returncode == 2, done.stdout + done.stderr
    assert message in done.stderr
    assert "serve_process_started" not in done.stdout + done.stderr  # refused before starting


@pytest.mark.timeout(90)
async def test_ctrl_c_stops_the_demo_and_its_server() -> None:
    process = await anyio.open_process(
        [*DEMO, "--duration", "60"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=ENV
    )
    output = b""
    try:
        assert process.stdout is not None
        with anyio.fail_after(45):  # until the demo's timer runs on the served devices
            while b"timer_started" not in output:
                output += await process.stdout.receive()
        pid = server_pid(output.decode())
        assert not gone(pid)
        process.send_signal(signal.SIGINT)
        with anyio.fail_after(30):
            async for chunk in process.stdout:
                output += chunk
            await process.wait()
    finally:
        if process.returncode is None:
            process.kill()
            with anyio.CancelScope(shield=True):
                await process.wait()
        await process.aclose()
    text = output.decode()
    assert process.returncode == 130, text
    assert "serve_process_stopped" in text
    assert gone(pid)
