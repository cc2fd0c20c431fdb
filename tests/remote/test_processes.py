"""Real processes on loopback: ``openel-async serve`` with sim devices, a commanding client
and a subscribed client, the server killed mid-motion and restarted. In
``test_clients_in_processes_of_their_own`` all three are OS processes (the clients are
``client_process.py``); ``test_serve_kill_restart_mid_motion`` keeps the clients in the
test process to check their objects directly (motion outcome, last_fault)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import AsyncIterator, Iterator
from contextlib import asynccontextmanager, contextmanager
from pathlib import Path
from typing import Any

import anyio
import anyio.abc
import pytest

from openel_async import (
    Actuator,
    ComponentState,
    ErrorId,
    EventId,
    ObserverQueue,
    Request,
    ReturnCode,
    Sensor,
)
from openel_async.observers import ErrorNotice, EventNotice
from openel_async.surface import ApplicationQueue, EventNotification
from openel_zenoh import RemoteActuator, RemoteSensor, RemoteSurface

from .conftest import client_cfg, free_port, session

RIG = """\
namespace: proc
components:
  - {name: MOTOR_1, driver: sim, device: motor, params: {max_velocity: 1.0, max_acceleration: 10.0}}
  - {name: MOTOR_2, driver: sim, device: motor, params: {max_velocity: 1.0, max_acceleration: 10.0}}
  - {name: ENCODER_1, driver: sim, device: encoder, params: {motor: {ref: MOTOR_1}}}
"""


@contextmanager
def serve(rig: Path, port: int) -> Iterator[subprocess.Popen[str]]:
    """``openel-async serve`` in a process of its own; waits (bounded) for its ready line."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "openel_async.cli", "--log-level", "warning", "serve", str(rig),
         "--listen", f"tcp/127.0.0.1:{port}"],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 30
        assert proc.stdout is not None
        while True:
            line = proc.stdout.readline()
            if line.startswith("serving"):
                break
            if (not line and proc.poll() is not None) or time.monotonic() > deadline:
                pytest.fail(f"serve did not start: {line!r} rc={proc.poll()}")
        yield proc
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(5)
        if proc.stdout is not None:
            proc.stdout.close()


@pytest.mark.timeout(90)
async def test_serve_kill_restart_mid_motion(tmp_path: Path) -> None:
    rig = tmp_path / "rig.yaml"
    rig.write_text(RIG)
    port = free_port()
    with serve(rig, port) as server:
        async with (
            session(client_cfg(port)) as zc,
            session(client_cfg(port)) as zl,
            RemoteSurface(zc, "proc", timeout=1.0) as commander,
            RemoteSurface(zl, "proc", timeout=1.0) as listener_surface,
        ):
            await commander.wait_server(10)
            await listener_surface.wait_server(10)
            listener = ApplicationQueue()
            await listener_surface.subscribe("Motor", "COMPLETED", listener)
            async with (
                Actuator(RemoteActuator(commander, 0)) as axis,
                Sensor(RemoteSensor(commander, 0)) as encoder,
            ):
                notices = ObserverQueue()
                axis.add_observer(notices)
                assert axis.device_name != "" and encoder.units == ("rad",)
                with anyio.fail_after(10):
                    motion = await axis.set_value(0.2)
                    assert not motion.done()
                    assert (await notices.get()).event_id == EventId.COMPLETED  # type: ignore[union-attr]
                    event = await listener.get()
                assert isinstance(event, EventNotification) and event.event_type == "COMPLETED"
                assert (await listener_surface.get_event_detail(event.event_id)).value(
                    "logical_id"
                ) == 0
                assert await axis.get_value(Request.POSITION_ACTUAL) == pytest.approx(0.2)
                assert (await encoder.get_value())[0] == pytest.approx(
                    0.2, abs=1e-2
                )  # encoder counts

                # Mid-motion (a 2 rad move at 1 rad/s takes > 2 s), the server dies.
                long_move = await axis.set_value(2.0)
                server.kill()
                server.wait(10)
                with anyio.fail_after(15):
                    error = await notices.get()
                assert isinstance(error, ErrorNotice) and error.error_id == ErrorId.DISCONNECTED
                assert axis.state is ComponentState.ERROR
                assert (
                    axis.last_fault is not None
                    and axis.last_fault.code is ReturnCode.HAL_NO_CONNECTED
                )
                assert long_move.done() and long_move.outcome.name != "REACHED"
                # re_init while the server is away fails and leaves the axis in Error.
                with pytest.raises(Exception, match="not reachable"):
                    await axis.re_init()
                assert axis.state is ComponentState.ERROR

                # The server comes back (a new process, fresh devices): re_init recovers.
                with serve(rig, port):
                    with anyio.fail_after(20):
                        await commander.wait_server(20)
                        await listener_surface.wait_server(20)
                    await axis.re_init()
                    assert axis.state is ComponentState.ACTIVE
                    with anyio.fail_after(10):
                        motion = await axis.set_value(-0.1)
                        notice = await notices.get()
                        assert (
                            isinstance(notice, EventNotice) and notice.event_id == EventId.COMPLETED
                        )
                        event = await listener.get()  # the listener was subscribed again
                    assert isinstance(event, EventNotification)
                    assert motion.outcome.name == "REACHED"
                    assert await axis.get_value(Request.POSITION_ACTUAL) == pytest.approx(-0.1)


CLIENT = Path(__file__).with_name("client_process.py")


class ClientProcess:
    """A client_process.py in a process of its own: commands in, JSON lines out."""

    def __init__(self, process: anyio.abc.Process) -> None:
        self.process = process
        self.buffer = b""
        self.seen: list[dict[str, Any]] = []

    async def send(self, line: str) -> None:
        assert self.process.stdin is not None
        await self.process.stdin.send(line.encode() + b"\n")

    async def expect(self, key: str, wait_s: float = 20.0) -> dict[str, Any]:
        """The next JSON line that has ``key`` (the lines before it are kept in ``seen``)."""
        assert self.process.stdout is not None
        with anyio.move_on_after(wait_s):
            while True:
                while b"\n" in self.buffer:
                    line, self.buffer = self.buffer.split(b"\n", 1)
                    try:
                        value = json.loads(line)
                    except ValueError:
                        continue  # a log line
                    if isinstance(value, dict):
                        self.seen.append(value)
                        if key in value:
                            return value
                try:
                    self.buffer += await self.process.stdout.receive()
                except anyio.EndOfStream:
                    break
        pytest.fail(f"no {key!r} from the client within {wait_s} s: {self.seen} {self.buffer!r}")


@asynccontextmanager
async def client_process(role: str, port: int, namespace: str) -> AsyncIterator[ClientProcess]:
    process = await anyio.open_process(
        [sys.executable, str(CLIENT), role, str(port), namespace],
        env={**os.environ, "PYTHONUNBUFFERED": "1"}, stderr=subprocess.STDOUT,
    )  # fmt: skip
    try:
        yield ClientProcess(process)
    finally:
        with anyio.move_on_after(10, shield=True):
            if process.stdin is not None:
                await process.stdin.aclose()  # the client ends when its stdin closes
            await process.wait()
        if process.returncode is None:
            process.kill()
            with anyio.move_on_after(5, shield=True):
                await process.wait()
        await process.aclose()


@pytest.mark.timeout(120)
async def test_clients_in_processes_of_their_own(tmp_path: Path) -> None:
    """The server, a commanding client and a subscribed client: three OS processes."""
    rig = tmp_path / "rig.yaml"
    rig.write_text(RIG.replace("namespace: proc", "namespace: procs"))
    port = free_port()
    with serve(rig, port) as server:
        async with (
            client_process("listener", port, "procs") as listener,
            client_process("commander", port, "procs") as commander,
        ):
            await listener.expect("ready")
            ready = await commander.expect("ready")
            assert ready["units"] == ["rad"]
            await commander.send("move 0.2")
            moved = await commander.expect("completed")
            assert moved["completed"] is True
            assert moved["position"] == pytest.approx(0.2)
            assert moved["encoder"] == pytest.approx(0.2, abs=1e-2)
            event = await listener.expect("event")
            assert event == {"event": "COMPLETED", "logical_id": 0, "missed": 0}

            # Mid-motion (2 rad at 1 rad/s), the server dies: a link fault in the commander,
            # and the listener hears the server leave.
            await commander.send("start 2.0")
            assert (await commander.expect("started"))["done"] is False
            server.kill()
            server.wait(10)
            await commander.send("wait_error")
            error = await commander.expect("error_id")
            assert error["error_id"] == ErrorId.DISCONNECTED
            assert error["state"] == str(ComponentState.ERROR)
            assert error["code"] == "HAL_NO_CONNECTED"
            assert error["motion_done"] is True and error["outcome"] != "REACHED"
            assert (await listener.expect("server"))["server"] is False
            await commander.send("reinit")
            refused = await commander.expect("reinit")
            assert "not reachable" in refused["reinit"]
            assert refused["state"] == str(ComponentState.ERROR)

            # A new server process: re_init recovers, the listener was subscribed again.
            with serve(rig, port):
                await commander.send("wait_server")
                await commander.expect("server", 30)
                assert (await listener.expect("server", 30))["server"] is True
                await commander.send("reinit")
                recovered = await commander.expect("reinit")
                assert recovered["reinit"] == "ok" and recovered["encoder_state"] == "Active"
                await commander.send("move -0.1")
                moved = await commander.expect("completed")
                assert moved["completed"] is True
                assert moved["position"] == pytest.approx(-0.1)
                assert moved["encoder"] == pytest.approx(-0.1, abs=1e-2)
                event = await listener.expect("event")
                assert event["event"] == "COMPLETED" and event["missed"] == 0


SAMPLES = Path(__file__).parents[1] / "surface" / "samples"


@pytest.mark.timeout(60)
def test_hal4rt_exec_sends_a_message_to_a_running_server(tmp_path: Path) -> None:
    rig = tmp_path / "rig.yaml"
    rig.write_text(RIG.replace("namespace: proc", "namespace: cli"))
    port = free_port()
    with serve(rig, port):
        common = ["--connect", f"tcp/127.0.0.1:{port}", "--namespace", "cli", "--timeout", "5"]
        done = subprocess.run(
            [sys.executable, "-m", "openel_async.cli", "--log-level", "warning", "hal4rt", "exec",
             str(SAMPLES / "set_position.xml"), *common],
            capture_output=True, text=True, timeout=30,
        )  # fmt: skip
        assert done.returncode == 0, done.stderr
        assert "<return_code>" not in done.stdout  # results are parameters, not elements
        assert "<name>return_code</name><value>0</value>" in done.stdout
        bad = tmp_path / "bad.xml"
        bad.write_text(
            "<Device><device_kind>Motor</device_kind><CommandMessage><function_name>Fly"
            "</function_name><command_id/><arguments><parameters><data_type_id>1</data_type_id>"
            "<name>logical_id</name><value>0</value></parameters></arguments></CommandMessage></Device>"
        )
        done = subprocess.run(
            [sys.executable, "-m", "openel_async.cli", "--log-level", "warning", "hal4rt", "exec", str(bad), *common],
            capture_output=True, text=True, timeout=30,
        )  # fmt: skip
        assert done.returncode == 3
        assert "<value>5</value>" in done.stdout and "no function" in done.stdout


@pytest.mark.timeout(60)
def test_serve_with_stop_on_eof_obeys_signals_while_its_input_stays_open(tmp_path: Path) -> None:
    """Issue 26 defect 2: with --stop-on-eof and the pipe kept open, SIGTERM and SIGINT
    stopped the components and then hung (a thread blocked reading standard input was
    joined at exit) until the parent closed the pipe. Both servers run at once."""
    procs: dict[signal.Signals, subprocess.Popen[str]] = {}
    try:
        for signum in (signal.SIGTERM, signal.SIGINT):
            rig = tmp_path / f"rig-{signum.name}.yaml"
            rig.write_text(RIG.replace("namespace: proc", f"namespace: eof{int(signum)}"))
            procs[signum] = subprocess.Popen(
                [sys.executable, "-m", "openel_async.cli", "--log-level", "info", "serve",
                 str(rig), "--listen", f"tcp/127.0.0.1:{free_port()}", "--stop-on-eof"],
                stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                text=True, env={**os.environ, "PYTHONUNBUFFERED": "1"},
            )  # fmt: skip
        deadline = time.monotonic() + 30
        for proc in procs.values():
            assert proc.stdout is not None
            while not proc.stdout.readline().startswith("serving"):
                assert proc.poll() is None and time.monotonic() < deadline
        for signum, proc in procs.items():
            proc.send_signal(signum)
        for signum, proc in procs.items():
            code = proc.wait(10)  # the pipe is still open
            assert code in (0, 130), (signum, code)
            assert proc.stdout is not None
            output = proc.stdout.read()
            assert "Traceback" not in output and "end of standard input" not in output
    finally:
        for proc in procs.values():
            if proc.poll() is None:
                proc.kill()
                proc.wait(5)
            for stream in (proc.stdin, proc.stdout):
                if stream is not None:
                    stream.close()


@pytest.mark.timeout(60)
def test_serve_stops_at_the_end_of_its_input_with_stop_on_eof(tmp_path: Path) -> None:
    rig = tmp_path / "rig.yaml"
    rig.write_text(RIG.replace("namespace: proc", "namespace: eof"))
    proc = subprocess.Popen(
        [sys.executable, "-m", "openel_async.cli", "--log-level", "info", "serve", str(rig),
         "--listen", f"tcp/127.0.0.1:{free_port()}", "--stop-on-eof"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )  # fmt: skip
    try:
        assert proc.stdout is not None and proc.stdin is not None
        deadline = time.monotonic() + 30
        while not proc.stdout.readline().startswith("serving"):
            assert proc.poll() is None and time.monotonic() < deadline
        proc.stdin.close()
        assert proc.wait(15) == 0  # no signal: the end of its input stops it
        output = proc.stdout.read()
        assert "end of standard input" in output
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(5)
