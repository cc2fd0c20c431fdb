"""Key expressions of the HAL4RT surface over Zenoh (one table, documented in docs/remote.md).

| key expression                          | declared by        | what                                      |
|-----------------------------------------|--------------------|-------------------------------------------|
| ``openel/<ns>/surface/execute``          | server, queryable  | execute(): a Device message in, out       |
| ``openel/<ns>/surface/subscribe``        | server, queryable  | subscribe(device_kind, event_type)        |
| ``openel/<ns>/surface/unsubscribe``      | server, queryable  | unsubscribe(subscribe_id)                 |
| ``openel/<ns>/surface/event_detail``     | server, queryable  | get_event_detail(event_id)                |
| ``openel/<ns>/surface/error_detail``     | server, queryable  | get_error_detail(error_id)                |
| ``openel/<ns>/surface/components``       | server, queryable  | the components: kind, logical id, name    |
| ``openel/<ns>/rig/estop``                | serve, queryable   | e-stop every component of the rig at once |
| ``openel/<ns>/rig/estop/release``        | serve, queryable   | release the rig's e-stop                  |
| ``openel/<ns>/rig/lifecycle``           | serve, queryable   | lifecycle states; activate, deactivate, reset |
| ``openel/<ns>/rig/conf``                | serve, queryable   | configuration sets: get, set (constraints) |
| ``openel/<ns>/client/<client>/notices``  | server, publisher  | completed, notify_event, notify_error of one client, numbered |
| ``openel/<ns>/alive/server``             | server, liveliness | the server is up                          |
| ``openel/<ns>/alive/client/<client>``    | client, liveliness | the client is up (its state is dropped when it goes) |
"""

from __future__ import annotations

import re

from openel_async.errors import BadParameterError

DEFAULT_NAMESPACE = "default"
_CHUNK = re.compile(r"[A-Za-z0-9_.\-]+")


def check_chunk(name: str, value: str) -> str:
    """A key-expression chunk without wildcards or separators."""
    if not isinstance(value, str) or not _CHUNK.fullmatch(value):
        raise BadParameterError(name, value, "letters, digits, '_', '.' or '-' (one key chunk)")
    return value


class Keys:
    """The key expressions of one namespace."""

    def __init__(self, namespace: str = DEFAULT_NAMESPACE) -> None:
        self.namespace = check_chunk("namespace", namespace)
        root = f"openel/{namespace}"
        self.root = root
        self.execute = f"{root}/surface/execute"
        self.subscribe = f"{root}/surface/subscribe"
        self.unsubscribe = f"{root}/surface/unsubscribe"
        self.event_detail = f"{root}/surface/event_detail"
        self.error_detail = f"{root}/surface/error_detail"
        self.components = f"{root}/surface/components"
        self.rig_estop = f"{root}/rig/estop"
        self.rig_estop_release = f"{root}/rig/estop/release"
        self.rig_lifecycle = f"{root}/rig/lifecycle"
        self.rig_conf = f"{root}/rig/conf"
        self.server_alive = f"{root}/alive/server"
        self.clients_alive = f"{root}/alive/client/*"

    def notices(self, client: str) -> str:
        return f"{self.root}/client/{check_chunk('client', client)}/notices"

    def client_alive(self, client: str) -> str:
        return f"{self.root}/alive/client/{check_chunk('client', client)}"

    def client_of_alive_key(self, key: str) -> str:
        return key.rsplit("/", 1)[-1]
