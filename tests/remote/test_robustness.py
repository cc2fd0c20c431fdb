"""Flooding clients, dropped notices and link timeouts (in-process server on loopback)."""

from __future__ import annotations

import time

import anyio
import pytest

from openel_async import (
    Actuator,
    ActuatorDevice,
    DeviceContext,
    DeviceInfo,
    DeviceKind,
    NotConnectedError,
    Request,
    ReturnCode,
)
from openel_async.surface import ApplicationQueue, CommandMessage, EventNotification, Surface
from openel_zenoh import RemoteSurface, SurfaceServer
from openel_zenoh import links as links_module
from openel_zenoh import server as server_module
from openel_zenoh.config import endpoint, server_config

from .conftest import client_cfg, free_port, session, sim_server


async def test_a_flooding_client_is_refused_while_others_are_served() -> None:
    port = free_port()
    async with (
        sim_server(port) as (server, _, _),
        session(client_cfg(port)) as za,
        session(client_cfg(port)) as zb,
        RemoteSurface(za, "test", timeout=5.0) as flooder,
        RemoteSurface(zb, "test", timeout=5.0) as polite,
    ):
        codes: list[int] = []
        latencies: list[float] = []

        async def flood_one() -> None:
            reply = await flooder.execute_command(
                "Motor", CommandMessage.call("GetPosition", "", logical_id=0)
            )
            assert reply.results is not None
            codes.append(reply.results.value("return_code"))

        async def poll() -> None:
            for _ in range(20):
                t0 = time.perf_counter()
                reply = await polite.execute_command(
                    "Motor", CommandMessage.call("GetPosition", "", logical_id=1)
                )
                latencies.append(time.perf_counter() - t0)
                assert reply.results is not None and reply.results.value("return_code") == 0

        with anyio.fail_after(30):
            async with anyio.create_task_group() as tg:
                for _ in range(400):
                    tg.start_soon(flood_one)
                tg.start_soon(poll)
        assert len(codes) == 400
        assert codes.count(ReturnCode.HAL_NO_MEMORY) > 0  # refused, and told so
        assert codes.count(ReturnCode.HAL_OK) >= server_module.CLIENT_QUEUE
        assert server.refused_busy == codes.count(ReturnCode.HAL_NO_MEMORY)
        assert len(latencies) == 20 and max(latencies) < 2.0


class Poster(ActuatorDevice):
    """Posts bursts of device events on demand."""

    info = DeviceInfo(kind=DeviceKind.MOTOR)
    reports_completion = True

    async def open(self, ctx: DeviceContext) -> None:
        self.ctx = ctx

    async def command(self, request: Request, value: float) -> None:
        self.ctx.target_reached()

    async def read(self, request: Request) -> float:
        return 0.0


async def test_notices_dropped_on_the_way_are_reported(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(links_module, "OUTBOX_SIZE", 10)
    port = free_port()
    device = Poster()
    async with (
        session(server_config([endpoint(port)])) as zs,
        Actuator(device) as axis,
        Surface([axis]) as surface,
        SurfaceServer(surface, zs, "drops"),
        session(client_cfg(port)) as zc,
        RemoteSurface(zc, "drops") as remote,
    ):
        app = ApplicationQueue()
        await remote.subscribe("Motor", "*", app)
        for _ in range(100):  # one event-loop turn: the first is published at once, and
            device.ctx.post_event(5)  # the outbox keeps the last 10 of the 99 after it
        received: list[EventNotification] = []
        with anyio.fail_after(10):
            while len(received) < 11:
                notice = await app.get()
                assert isinstance(notice, EventNotification)
                received.append(notice)
        # (which notice carries the count depends on when the queue is read)
        assert sum(n.missed for n in received) == 89
        assert remote.missed_total == 89
        assert received[-1].event_type == "EVENT_5"


async def test_queries_time_out_when_no_server_answers() -> None:
    port = free_port()
    async with session(client_cfg(port)) as zc, RemoteSurface(zc, "nobody", timeout=0.3) as remote:
        t0 = time.perf_counter()
        with pytest.raises((TimeoutError, NotConnectedError)):
            await remote.components()
        assert time.perf_counter() - t0 < 2.0
        with pytest.raises(TimeoutError):
            await remote.wait_server(0.2)
