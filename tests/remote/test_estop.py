"""The e-stop of a served rig: ``openel-async estop`` (and ``--release``) against
``openel-async serve`` in a process of its own, SIGQUIT to the server, and the Python API
(``estop_rig``, ``RemoteSurface.estop_rig``) against a rig served in this process."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import anyio
import pytest

from openel_async import Actuator, ErrorId, HALError, ObserverQueue
from openel_async.component import ComponentState
from openel_async.observers import ErrorNotice
from openel_async.rig import open_rig, parse_rig
from openel_async.surface import ApplicationQueue, CommandMessage, ErrorNotification, Surface
from openel_zenoh import RemoteActuator, RemoteSurface, SurfaceServer
from openel_zenoh.config import endpoint, server_config
from openel_zenoh.device import results_of
from openel_zenoh.estop import RigEstopServer, describe, estop_rig
from openel_zenoh.spawn import served

from .conftest import client_cfg, free_port, session

RIG = """\
namespace: estop
components:
  - {name: MOTOR_1, driver: sim, device: motor, params: {max_velocity: 0.25, max_acceleration: 10.0}}
  - {name: MOTOR_2, driver: sim, device: motor, params: {max_velocity: 1.0, max_acceleration: 10.0}}
  - {name: ENCODER_1, driver: sim, device: encoder, params: {motor: {ref: MOTOR_1}}}
"""
NAMES = ["MOTOR_1", "MOTOR_2", "ENCODER_1"]
CLI = [sys.executable, "-m", "openel_async.cli", "--log-level", "warning", "estop"]
ENV = {**os.environ, "PYTHONUNBUFFERED": "1"}


async def estop_command(*args: str) -> subprocess.CompletedProcess[bytes]:
    with anyio.fail_after(15):
        return await anyio.run_process([*CLI, *args], check=False, env=ENV)


def lines(done: subprocess.CompletedProcess[bytes]) -> list[str]:
    return done.stdout.decode().splitlines()


async def re_init(remote: RemoteSurface, device_kind: str, logical_id: int) -> None:
    """ReInit of a served component (the surface's Reset), its failure raised."""
    command = CommandMessage.call("Reset", "", logical_id=logical_id)
    results_of(await remote.execute_command(device_kind, command))


@pytest.mark.timeout(60)
async def test_estop_command_latches_every_component_until_released() -> None:
    async with served(RIG, "estop", timeout=5.0) as rig:
        remote = rig.remote
        where = ["--connect", endpoint(rig.port), "--namespace", "estop"]
        async with Actuator(RemoteActuator(remote, 0)) as axis:
            notices = ObserverQueue()
            axis.add_observer(notices)
            # moving when the e-stop comes: 2 rad at 0.25 rad/s take 8 s (the estop command's
            # process may take seconds to start on a loaded machine)
            motion = await axis.set_value(2.0)

            done = await estop_command(*where)
            assert done.returncode == 0, done
            assert lines(done) == [f"{name} Error (e-stop, error 8)" for name in NAMES]
            with anyio.fail_after(5):
                notice = await notices.get()
            assert isinstance(notice, ErrorNotice) and notice.error_id == ErrorId.ESTOP
            assert axis.state is ComponentState.ERROR
            assert motion.done() and motion.outcome.name != "REACHED"
            assert [c.state for c in await remote.components()] == ["Error"] * 3

            # Latched: re_init is refused on the server.
            for kind, logical_id in (("Motor", 0), ("Motor", 1), ("Encoder", 0)):
                with pytest.raises(HALError, match="e-stop is not released"):
                    await re_init(remote, kind, logical_id)
            assert [c.state for c in await remote.components()] == ["Error"] * 3

            done = await estop_command("--release", *where)
            assert done.returncode == 0, done
            assert lines(done) == [f"{name} Error (released, error 8)" for name in NAMES]
            for kind, logical_id in (("Motor", 0), ("Motor", 1), ("Encoder", 0)):
                await re_init(remote, kind, logical_id)
            assert [c.state for c in await remote.components()] == ["Active"] * 3


async def test_estop_command_without_a_server_exits_1_at_once() -> None:
    started = time.monotonic()
    done = await estop_command("--connect", endpoint(free_port()), "--timeout", "0.5")
    assert done.returncode == 1, done
    assert done.stdout == b""
    assert b"no rig served at tcp/127.0.0.1:" in done.stderr
    assert time.monotonic() - started < 10


async def test_estop_command_usage_errors_exit_2() -> None:
    codes: dict[str, int] = {}

    async def run(*args: str) -> None:
        codes[" ".join(args)] = (await estop_command(*args)).returncode

    async with anyio.create_task_group() as tg:
        for args in (["--timeout", "0"], ["--namespace", "a/b"], ["--bogus"]):
            tg.start_soon(run, *args)
    assert codes == {"--timeout 0": 2, "--namespace a/b": 2, "--bogus": 2}


@pytest.mark.timeout(60)
async def test_sigquit_to_serve_estops_every_component() -> None:
    async with served(RIG, "quit", timeout=5.0) as rig:
        remote = rig.remote
        errors = ApplicationQueue()
        remote.attach(errors)
        async with Actuator(RemoteActuator(remote, 1)) as axis:  # MOTOR_2
            os.kill(rig.pid, signal.SIGQUIT)
            faulted: dict[str, int] = {}
            with anyio.fail_after(10):
                while len(faulted) < len(NAMES):
                    notice = await errors.get()
                    assert isinstance(notice, ErrorNotification)
                    detail = remote.cached_error_detail(notice.error_id)
                    assert detail is not None
                    faulted[str(detail.value("device_name"))] = int(detail.value("error_code"))
            assert faulted == dict.fromkeys(NAMES, int(ErrorId.ESTOP))
            assert axis.state is ComponentState.ERROR
            with pytest.raises(HALError, match="e-stop is not released"):
                await re_init(remote, "Motor", 1)

            reply = await remote.estop_rig(release=True)
            assert reply.return_code == 0 and reply.release
            assert [(c.name, c.state, c.error_id, c.latched) for c in reply.components] == [
                (name, "Error", 8, False) for name in NAMES
            ]
            await re_init(remote, "Motor", 1)
            assert [c.state for c in await remote.components()] == ["Error", "Active", "Error"]


async def test_estop_rig_in_process() -> None:
    """The Python API against a rig served here: estop_rig in a session of its own, and
    RemoteSurface.estop_rig; a component not operating is reported as it is."""
    spec = parse_rig(
        {
            "namespace": "inproc",
            "safety": {"watchdog_timeout": None},
            "components": [
                {"name": "MOTOR_1", "driver": "sim", "device": "motor"},
                {"name": "MOTOR_2", "driver": "sim", "device": "motor"},
            ],
        }
    )
    port = free_port()
    async with (
        session(server_config([endpoint(port)])) as zs,
        open_rig(spec) as rig,
        RigEstopServer(rig, zs, "inproc") as server,
        Surface(list(rig.components.values())) as surface,
        SurfaceServer(surface, zs, "inproc"),
        session(client_cfg(port)) as zc,
    ):
        await rig.component("MOTOR_2").finalize()
        reply = await estop_rig(zc, "inproc", timeout=5.0)
        assert reply.return_code == 0 and not reply.release
        assert [describe(c) for c in reply.components] == [
            "MOTOR_1 Error (e-stop, error 8)",
            "MOTOR_2 Finalized",  # nothing to e-stop
        ]
        assert rig.estopped and server.estops == 1
        async with RemoteSurface(zc, "inproc", timeout=5.0) as remote:
            await remote.wait_server(5)
            reply = await remote.estop_rig(release=True)
        assert [describe(c, release=True) for c in reply.components] == [
            "MOTOR_1 Error (released, error 8)",
            "MOTOR_2 Finalized",
        ]
        assert not rig.estopped and server.releases == 1
        await rig.component("MOTOR_1").re_init()

        with pytest.raises(TimeoutError, match="no server"):
            await estop_rig(zc, "elsewhere", timeout=0.3)


async def test_remote_actuator_re_init_after_a_released_estop() -> None:
    spec = parse_rig(
        {
            "namespace": "axis",
            "safety": {"watchdog_timeout": None},
            "components": [{"name": "MOTOR_1", "driver": "sim", "device": "motor"}],
        }
    )
    port = free_port()
    async with (
        session(server_config([endpoint(port)])) as zs,
        open_rig(spec) as rig,
        RigEstopServer(rig, zs, "axis"),
        Surface(list(rig.components.values())) as surface,
        SurfaceServer(surface, zs, "axis"),
        session(client_cfg(port)) as zc,
        RemoteSurface(zc, "axis", timeout=5.0) as remote,
    ):
        await remote.wait_server(5)
        async with Actuator(RemoteActuator(remote, 0)) as axis:
            notices = ObserverQueue()
            axis.add_observer(notices)
            await remote.estop_rig()
            with anyio.fail_after(5):
                notice = await notices.get()
            assert isinstance(notice, ErrorNotice) and notice.error_id == ErrorId.ESTOP
            with pytest.raises(HALError, match="e-stop is not released"):
                await axis.re_init()
            await remote.estop_rig(release=True)
            await axis.re_init()
            assert axis.state is ComponentState.ACTIVE
