"""Which rigs are served on a Zenoh network: the namespaces whose server is up.

Every ``SurfaceServer`` (``openel-async serve``) declares the liveliness token
``openel/<ns>/alive/server``; one liveliness query of ``openel/*/alive/server`` lists them,
wherever they are: on this host, on a peer, or behind a router joining several hosts
(docs/remote.md, "Several hosts").
"""

from __future__ import annotations

import zenoh

from openel_async.clock import run_in_thread
from openel_async.errors import BadParameterError

SERVERS = "openel/*/alive/server"
"""The liveliness tokens of every served rig."""


def _namespaces(session: zenoh.Session, timeout: float) -> list[str]:
    found: set[str] = set()
    for reply in session.liveliness().get(SERVERS, timeout=timeout):
        ok = reply.ok
        if ok is None:
            continue
        parts = str(ok.key_expr).split("/")
        if len(parts) == 4 and parts[0] == "openel" and parts[2:] == ["alive", "server"]:
            found.add(parts[1])
    return sorted(found)


async def served_namespaces(session: zenoh.Session, timeout: float = 2.0) -> list[str]:  # noqa: ASYNC109
    """The namespaces of the rigs served on ``session``'s network, sorted: one liveliness
    query, whose replies are waited for (in a worker thread) for at most ``timeout`` s."""
    if not 0 < timeout <= 60:
        raise BadParameterError("timeout", timeout, "seconds in (0, 60]")
    return await run_in_thread(_namespaces, session, timeout, abandon_on_cancel=True)
