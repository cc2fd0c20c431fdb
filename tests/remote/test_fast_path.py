"""The server's synchronous fast path and what it changed on the client: completions
that overtake their reply, synchronous commands that expect no completion, ordering."""

from __future__ import annotations

import anyio

from openel_async import (
    Actuator,
    ActuatorDevice,
    DeviceContext,
    DeviceInfo,
    DeviceKind,
    EventId,
    ObserverQueue,
    Request,
)
from openel_async.surface import CommandMessage, Device, Surface
from openel_sim import SimMotor
from openel_zenoh import RemoteActuator, RemoteSurface, SurfaceServer
from openel_zenoh.config import endpoint, server_config

from .conftest import client_cfg, free_port, session


async def test_completions_that_overtake_their_reply_still_complete_the_motion() -> None:
    # A motor that reaches a 1 mrad target within microseconds: its COMPLETED notice is
    # published right after the reply and often arrives first.
    port = free_port()
    motor = SimMotor(max_velocity=1e6, max_acceleration=1e9, position_limits=(-1e3, 1e3))
    async with (
        session(server_config([endpoint(port)])) as zs,
        Actuator(motor) as served,
        Surface([served]) as surface,
        SurfaceServer(surface, zs, "fast"),
        session(client_cfg(port)) as zc,
        RemoteSurface(zc, "fast") as remote,
    ):
        await remote.wait_server(5)
        async with Actuator(RemoteActuator(remote, 0)) as axis:
            events = ObserverQueue(maxsize=4096)
            axis.add_observer(events)
            target = 0.0
            for _ in range(100):
                target = 0.001 if target == 0.0 else 0.0
                motion = await axis.set_value(target)
                with anyio.fail_after(5):
                    await motion
                    notice = await events.get()
                assert notice.event_id == EventId.COMPLETED
            # Synchronous commands expect no completion: nothing is left waiting for one.
            for _ in range(50):
                await axis.get_value(Request.POSITION_ACTUAL)
            assert remote.awaiting_completion == 0


class SlowReads(ActuatorDevice):
    """A device whose reads suspend (no synchronous path): served by the workers."""

    info = DeviceInfo(kind=DeviceKind.MOTOR)
    reports_completion = True

    async def open(self, ctx: DeviceContext) -> None:
        self.ctx = ctx
        self.position = 0.0

    async def command(self, request: Request, value: float) -> None:
        await anyio.lowlevel.checkpoint()
        self.position = value
        self.ctx.target_reached()

    async def read(self, request: Request) -> float:
        await anyio.sleep(0.001)
        return self.position


async def test_synchronous_and_suspending_commands_of_one_client_stay_in_order() -> None:
    port = free_port()
    device = SlowReads()
    async with (
        session(server_config([endpoint(port)])) as zs,
        Actuator(device) as served,
        Surface([served]) as surface,
        SurfaceServer(surface, zs, "order") as server,
        session(client_cfg(port)) as zc,
        RemoteSurface(zc, "order") as remote,
    ):
        await remote.wait_server(5)
        replies: list[tuple[int, str]] = []

        async def send(index: int, name: str) -> None:
            reply = await remote.execute(
                Device("Motor", (CommandMessage.call(name, "", logical_id=0),))
            )
            replies.append((index, reply.commands[0].command_id))

        with anyio.fail_after(10):
            async with anyio.create_task_group() as tg:
                for index in range(12):  # a read that suspends, then GetState (no I/O)...
                    tg.start_soon(send, index, "GetPosition" if index % 2 == 0 else "GetState")
                    await anyio.lowlevel.checkpoint()
        # The surface numbers commands in the order it runs them: one client's commands
        # ran in the order they were sent, whichever path served them.
        by_index = [command_id for _, command_id in sorted(replies)]
        assert by_index == sorted(by_index, key=lambda c: int(c[1:]))
        assert server.served == 12
