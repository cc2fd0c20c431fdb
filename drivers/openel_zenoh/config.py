"""Zenoh session configurations with safe defaults.

By default nothing is reachable from the network: peer mode, the server listening on
127.0.0.1 only, clients not listening at all, multicast and gossip scouting off. A LAN
setup is the user's explicit choice: a JSON5 configuration file (examples ship in
``openel_zenoh/configs``: TLS, access control) replaces these defaults whole.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import zenoh

from openel_async.errors import BadParameterError

DEFAULT_PORT = 7447
DEFAULT_ENDPOINT = f"tcp/127.0.0.1:{DEFAULT_PORT}"
CONFIG_DIR = Path(__file__).with_name("configs")


def endpoint(port: int, host: str = "127.0.0.1") -> str:
    return f"tcp/{host}:{port}"


def safe_config(*, listen: Sequence[str] = (), connect: Sequence[str] = ()) -> zenoh.Config:
    """A peer configuration that listens on ``listen`` only and scouts nothing."""
    for name, endpoints in (("listen", listen), ("connect", connect)):
        if isinstance(endpoints, str) or not all(
            isinstance(e, str) and "/" in e for e in endpoints
        ):
            raise BadParameterError(
                name, endpoints, "a list of Zenoh endpoints like tcp/127.0.0.1:7447"
            )
    config = zenoh.Config()
    config.insert_json5("mode", '"peer"')
    config.insert_json5("listen/endpoints", json.dumps(list(listen)))
    config.insert_json5("connect/endpoints", json.dumps(list(connect)))
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("scouting/gossip/enabled", "false")
    return config


def server_config(listen: Sequence[str] = (DEFAULT_ENDPOINT,)) -> zenoh.Config:
    return safe_config(listen=listen)


def client_config(connect: Sequence[str] = (DEFAULT_ENDPOINT,)) -> zenoh.Config:
    return safe_config(connect=connect)


def file_config(path: str | Path) -> zenoh.Config:
    """A configuration from a JSON5 file (the user's choice, used as written)."""
    path = Path(path)
    if not path.is_file():
        raise BadParameterError("config", str(path), "an existing Zenoh JSON5 configuration file")
    return zenoh.Config.from_file(str(path))
