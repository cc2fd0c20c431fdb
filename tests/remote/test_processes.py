"""Real processes on loopback: ``openel-async serve`` with sim devices, a commanding client
and a subscribed client (two Zenoh sessions of their own), the server killed mid-motion
and restarted."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import anyio
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
