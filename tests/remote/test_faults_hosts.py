"""Issue 26: several rigs on several hosts joined by a Zenoh router (docs/remote.md, "Several
hosts"). Two ``openel-async serve`` processes, each in a network namespace of its own (a
host), connect to a router in this namespace with the shipped ``via-router.json5``; a client
here, connected to the router only, finds which rigs exist and drives both. Skips, with the
reason, where the machine allows no network namespaces."""

from __future__ import annotations

import json
from pathlib import Path

import anyio
import pytest
import zenoh

from openel_async import Actuator, Request
from openel_zenoh import RemoteActuator, RemoteSurface
from openel_zenoh.config import CONFIG_DIR, file_config
from openel_zenoh.discovery import served_namespaces

from .conftest import free_port, session
from .netns import netns, require_netns, serve_many

RIG = """\
namespace: {namespace}
components:
  - {{name: MOTOR_1, driver: sim, device: motor, params: {{max_velocity: 4.0, max_acceleration: 40.0}}}}
"""
PLACEHOLDER = "tcp/192.0.2.1:7447"
"""The router's address in the shipped examples."""


def shipped(name: str, router: str, folder: Path) -> Path:
    """A shipped example configuration with the router's address put in."""
    text = (CONFIG_DIR / name).read_text(encoding="utf-8")
    assert PLACEHOLDER in text
    path = folder / name
    path.write_text(text.replace(PLACEHOLDER, router), encoding="utf-8")
    return path


@pytest.mark.timeout(60)
async def test_rigs_on_two_hosts_joined_by_a_router(tmp_path: Path) -> None:
    require_netns()
    port = free_port()
    async with netns() as host_a, netns() as host_b:
        router_config = zenoh.Config.from_file(
            str(shipped("router.json5", f"tcp/0.0.0.0:{port}", tmp_path))
        )
        assert json.loads(router_config.get_json("mode")) == "router"
        rigs = []
        for host, namespace in ((host_a, "cell_a"), (host_b, "cell_b")):
            folder = tmp_path / namespace
            folder.mkdir()
            rig = folder / "rig.yaml"
            rig.write_text(RIG.format(namespace=namespace), encoding="utf-8")
            config = shipped("via-router.json5", f"tcp/{host.host_ip}:{port}", folder)
            rigs.append((host, str(rig), str(config)))
        async with (
            session(router_config),
            serve_many([(host, rig, [], ("--config", config)) for host, rig, config in rigs]),
            session(
                file_config(shipped("via-router.json5", f"tcp/127.0.0.1:{port}", tmp_path))
            ) as client,
        ):
            with anyio.fail_after(15):
                found: list[str] = []
                while found != ["cell_a", "cell_b"]:
                    found = await served_namespaces(client, 2.0)
                    await anyio.sleep(0.05)
            for namespace in found:
                async with RemoteSurface(client, namespace) as remote:
                    await remote.wait_server(10)
                    async with Actuator(RemoteActuator(remote, 0)) as axis:
                        with anyio.fail_after(10):
                            await (await axis.set_value(0.1, Request.POSITION))
                        assert await axis.get_value(Request.POSITION_ACTUAL) == pytest.approx(0.1)
