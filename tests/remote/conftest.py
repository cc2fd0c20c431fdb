"""Helpers of the remote tests: free loopback ports, sessions and an in-process server."""

from __future__ import annotations

import socket
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

import zenoh

from openel_async import Actuator, HALComponent, Sensor
from openel_async.surface import Surface
from openel_sim import SimEncoder, SimMotor
from openel_zenoh import SurfaceServer, close_session, open_session
from openel_zenoh.config import client_config, endpoint, server_config


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


@asynccontextmanager
async def session(config: zenoh.Config) -> AsyncIterator[zenoh.Session]:
    opened = await open_session(config)
    try:
        yield opened
    finally:
        await close_session(opened)


@asynccontextmanager
async def sim_server(
    port: int, namespace: str = "test", motors: int = 2, **server_options: Any
) -> AsyncIterator[tuple[SurfaceServer, list[SimMotor], list[HALComponent]]]:
    """A server of ``motors`` SimMotors and an encoder on the first, in this process."""
    devices = [SimMotor(max_velocity=4.0, max_acceleration=40.0) for _ in range(motors)]
    components: list[HALComponent] = [Actuator(m) for m in devices]
    components.append(Sensor(SimEncoder(devices[0])))
    async with session(server_config([endpoint(port)])) as zs:
        entered = []
        try:
            for c in components:
                entered.append(await c.__aenter__())
            async with (
                Surface(components) as surface,
                SurfaceServer(surface, zs, namespace, **server_options) as server,
            ):
                yield server, devices, components
        finally:
            for c in reversed(entered):
                await c.__aexit__(None, None, None)


def client_cfg(port: int) -> zenoh.Config:
    return client_config([endpoint(port)])
