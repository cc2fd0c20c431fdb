"""Zenoh session configurations with safe defaults.

By default nothing is reachable from the network: peer mode, the server listening on
127.0.0.1 only, clients not listening at all, multicast and gossip scouting off. The link's
lease is LEASE_S (1 s, keep-alives every quarter of it) instead of Zenoh's 10 s, so that a
partition is detected within about a second, and a lost connection is tried again every
0.25 s doubling up to RETRY_MAX_S (1 s; Zenoh: 1 s up to 4 s), so that it is back within
about a second of the heal (docs/remote.md, "Faults"). A LAN
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
LEASE_S = 1.0
"""Seconds of silence after which a Zenoh link is closed (its peer's liveliness tokens go):
the bound on detecting a partition or a dead peer. Zenoh's own default is 10 s."""
RETRY_INIT_S = 0.25
RETRY_MAX_S = 1.0
"""A connect endpoint not connected is tried again after RETRY_INIT_S, doubling up to this."""


def endpoint(port: int, host: str = "127.0.0.1") -> str:
    return f"tcp/{host}:{port}"


def safe_config(
    *, listen: Sequence[str] = (), connect: Sequence[str] = (), lease: float = LEASE_S
) -> zenoh.Config:
    """A peer configuration that listens on ``listen`` only, scouts nothing and closes a
    link silent for ``lease`` seconds."""
    if isinstance(lease, bool) or not isinstance(lease, (int, float)) or not 0.1 <= lease <= 3600:
        raise BadParameterError("lease", lease, "seconds in [0.1, 3600]")
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
    config.insert_json5("transport/link/tx/lease", str(round(lease * 1000)))
    retry = {
        "period_init_ms": round(RETRY_INIT_S * 1000),
        "period_max_ms": round(RETRY_MAX_S * 1000),
        "period_increase_factor": 2,
    }
    config.insert_json5("connect/retry", json.dumps(retry))
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
