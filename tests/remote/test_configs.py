"""Safe defaults, and the shipped LAN examples (TLS with a CA made here, access control)
exercised on loopback."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest
import zenoh

from openel_async import Actuator
from openel_async.surface import Surface
from openel_sim import SimMotor
from openel_zenoh import RemoteSurface, SurfaceServer
from openel_zenoh.config import CONFIG_DIR, client_config, file_config, server_config

from .conftest import free_port, session


def test_defaults_listen_on_loopback_only_and_scout_nothing() -> None:
    server = server_config()
    assert json.loads(server.get_json("listen/endpoints")) == ["tcp/127.0.0.1:7447"]
    assert json.loads(server.get_json("mode")) == "peer"
    for config in (server, client_config()):
        assert json.loads(config.get_json("scouting/multicast/enabled")) is False
        assert json.loads(config.get_json("scouting/gossip/enabled")) is False
    assert json.loads(client_config().get_json("listen/endpoints")) == []


def _set(config: zenoh.Config, key: str, value: object) -> None:
    config.insert_json5(key, json.dumps(value))


def _make_ca(directory: Path) -> None:
    """A test CA, and server and client certificates for 127.0.0.1, made with openssl."""

    def run(*args: str) -> None:
        subprocess.run(
            ["openssl", *args], cwd=directory, check=True, capture_output=True, timeout=30
        )

    ec = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:P-256", "-nodes"]
    run(
        "req",
        "-x509",
        *ec,
        "-keyout",
        "ca-key.pem",
        "-out",
        "ca.pem",
        "-days",
        "2",
        "-subj",
        "/CN=openel test CA",
    )
    for who in ("server", "client"):
        run("req", *ec, "-keyout", f"{who}-key.pem", "-out", f"{who}.csr", "-subj", f"/CN={who}")
        (directory / f"{who}.ext").write_text(
            "subjectAltName=IP:127.0.0.1,DNS:localhost\nextendedKeyUsage=serverAuth,clientAuth\n"
        )
        run("x509", "-req", "-in", f"{who}.csr", "-CA", "ca.pem", "-CAkey", "ca-key.pem", "-CAcreateserial",
            "-out", f"{who}.pem", "-days", "2", "-extfile", f"{who}.ext")  # fmt: skip


def _tls_pair(certs: Path, port: int) -> tuple[zenoh.Config, zenoh.Config]:
    server = file_config(CONFIG_DIR / "lan-tls-server.json5")
    _set(server, "listen/endpoints", [f"tls/127.0.0.1:{port}"])
    client = file_config(CONFIG_DIR / "lan-tls-client.json5")
    _set(client, "connect/endpoints", [f"tls/127.0.0.1:{port}"])
    for config in (server, client):
        _set(config, "transport/link/tls/root_ca_certificate", str(certs / "ca.pem"))
    _set(server, "transport/link/tls/listen_private_key", str(certs / "server-key.pem"))
    _set(server, "transport/link/tls/listen_certificate", str(certs / "server.pem"))
    _set(client, "transport/link/tls/connect_private_key", str(certs / "client-key.pem"))
    _set(client, "transport/link/tls/connect_certificate", str(certs / "client.pem"))
    return server, client


@pytest.mark.skipif(shutil.which("openssl") is None, reason="needs the openssl command")
async def test_tls_example_serves_clients_with_certificates_only(tmp_path: Path) -> None:
    _make_ca(tmp_path)
    port = free_port()
    server_cfg, client_cfg = _tls_pair(tmp_path, port)
    stranger_cfg = zenoh.Config.from_json5(
        json.dumps(
            {
                "mode": "peer",
                "connect": {"endpoints": [f"tls/127.0.0.1:{port}"]},
                "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
                "transport": {"link": {"tls": {"root_ca_certificate": str(tmp_path / "ca.pem")}}},
            }
        )
    )  # trusts the CA but has no client certificate
    async with (
        session(server_cfg) as zs,
        Actuator(SimMotor()) as axis,
        Surface([axis]) as surface,
        SurfaceServer(surface, zs, "lab"),
        session(client_cfg) as zc,
        RemoteSurface(zc, "lab", timeout=3.0) as remote,
        session(stranger_cfg) as zx,
        RemoteSurface(zx, "lab", timeout=0.5) as stranger,
    ):
        await remote.wait_server(5)
        assert [c.device_name for c in await remote.components()] == [axis.device_name]
        with pytest.raises(TimeoutError):
            await stranger.components()


async def test_acl_example_refuses_an_unlisted_key_expression() -> None:
    port = free_port()
    server_cfg = file_config(CONFIG_DIR / "lan-acl-server.json5")
    _set(server_cfg, "listen/endpoints", [f"tcp/127.0.0.1:{port}"])
    async with (
        session(server_cfg) as zs,
        Actuator(SimMotor()) as axis,
        Surface([axis]) as surface,
        SurfaceServer(surface, zs, "lab"),
        SurfaceServer(surface, zs, "other"),  # served, but not listed in the ACL
        session(client_config([f"tcp/127.0.0.1:{port}"])) as zc,
        RemoteSurface(zc, "lab", timeout=3.0) as lab,
        RemoteSurface(zc, "other", timeout=0.5) as other,
    ):
        await lab.wait_server(5)
        assert len(await lab.components()) == 1
        with pytest.raises(TimeoutError):
            await other.components()
        assert not other.server_alive  # its liveliness token is filtered too
