"""Issue 26 defect 1: the server's client state is bounded. Every distinct query attachment
made a client (a notice publisher attached to the Surface) that stayed until a liveliness
token went away -- which a name that never had one never does: any peer could grow the
server without bound. Now a client without a token is forgotten once idle (displaced by a
newer one when the slots are full, expired after ``client_idle_timeout``), a live client is
never displaced, and a server full of live clients refuses a new one with HAL_NO_MEMORY."""

from __future__ import annotations

from collections.abc import Callable

import anyio
import pytest
import zenoh

from openel_async import ReturnCode
from openel_async.surface import CommandMessage
from openel_zenoh import RemoteSurface, SurfaceServer, wire
from openel_zenoh import server as server_module
from openel_zenoh.keys import Keys

from .conftest import client_cfg, free_port, session, sim_server


async def _until(predicate: Callable[[], bool]) -> None:
    """Poll the server's state (it has no event to wait on), bounded."""
    with anyio.fail_after(10):
        while not predicate():  # noqa: ASYNC110 - the server's state has no event to wait on
            await anyio.sleep(0.01)


def _components(zc: zenoh.Session, client: str) -> bytes:
    """A ``components`` query naming ``client`` in its attachment (no token): the reply."""
    replies = zc.get(Keys("test").components, attachment=client.encode(), timeout=5.0)
    reply = replies.recv()
    assert reply.ok is not None, reply
    return reply.ok.payload.to_bytes()


async def test_fresh_attachments_do_not_grow_the_server() -> None:
    """300 queries, each naming a client never seen: the server knows at most MAX_CLIENTS
    (before: 300 clients, 300 publishers, kept forever), and answered every query."""
    port = free_port()
    async with (
        sim_server(port) as (server, _, _),
        session(client_cfg(port)) as zc,
    ):
        await anyio.sleep(0.2)  # the client's session connects
        for n in range(300):
            payload = await anyio.to_thread.run_sync(_components, zc, f"flood-{n}")
            assert wire.components_decoder.decode(payload).components  # not a refusal
            assert len(server.clients) <= 256  # the default maximum
        assert server_module.MAX_CLIENTS == 256
        assert server.forgotten_clients == 300 - 256
        assert server.refused_clients == 0


async def test_a_live_client_is_never_displaced_and_keeps_its_notices() -> None:
    port = free_port()
    async with (
        sim_server(port, max_clients=3) as (server, _, _),
        session(client_cfg(port)) as zr,
        session(client_cfg(port)) as zc,
        RemoteSurface(zr, "test", timeout=5.0) as remote,
    ):
        await _until(lambda: getattr(server.clients.get(remote.client_id), "alive", False))
        for n in range(20):
            await anyio.to_thread.run_sync(_components, zc, f"raw-{n}")
        assert remote.client_id in server.clients and len(server.clients) <= 3
        # its link survived: a command's COMPLETED still reaches it
        reply = await remote.execute_command(
            "Motor", CommandMessage.call("SetPosition", "", logical_id=0, position=0.01)
        )
        assert reply.results is not None and reply.results.value("return_code") == 0


async def test_a_server_full_of_live_clients_refuses_a_new_one() -> None:
    port = free_port()
    async with (
        sim_server(port, max_clients=1) as (server, _, _),
        session(client_cfg(port)) as zr,
        session(client_cfg(port)) as zc,
        RemoteSurface(zr, "test", timeout=5.0) as remote,
    ):
        await _until(lambda: remote.client_id in server.clients)
        payload = await anyio.to_thread.run_sync(_components, zc, "one-too-many")
        answer = wire.answer_decoder.decode(payload)
        assert answer.return_code == ReturnCode.HAL_NO_MEMORY
        assert "server full: 1 clients known, none idle" in answer.message
        assert server.refused_clients == 1
        assert list(server.clients) == [remote.client_id]


async def test_an_idle_client_without_a_token_is_forgotten() -> None:
    port = free_port()
    async with (
        sim_server(port, client_idle_timeout=0.2) as (server, _, _),
        session(client_cfg(port)) as zc,
    ):
        await anyio.sleep(0.2)
        await anyio.to_thread.run_sync(_components, zc, "passing-by")
        assert "passing-by" in server.clients
        await _until(lambda: "passing-by" not in server.clients)
        assert server.forgotten_clients == 1


@pytest.mark.parametrize(
    ("options", "name"),
    [({"max_clients": 0}, "max_clients"), ({"client_idle_timeout": 0.0}, "client_idle_timeout")],
)
def test_the_bounds_are_checked(options: dict[str, float], name: str) -> None:
    with pytest.raises(Exception, match=name):
        SurfaceServer(None, None, **options)  # type: ignore[arg-type]
