"""Threads of the remote path: the server's loop gate (reads answered on Zenoh's thread
while the loop is parked in select) and the client's bounded busy-wait for replies."""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Awaitable, Callable
from typing import Any

import anyio
import pytest

from openel_async import (
    Actuator,
    ActuatorDevice,
    BadParameterError,
    DeviceContext,
    DeviceInfo,
    DeviceKind,
    Request,
)
from openel_async.errors import ReturnCode
from openel_async.surface import CommandMessage, Device, Surface, compact
from openel_sim import SimMotor
from openel_zenoh import RemoteActuator, RemoteSurface, SurfaceServer
from openel_zenoh.config import endpoint, server_config
from openel_zenoh.gate import GatedEventLoop, LoopGate, gate_of, needs_wake, work_marker
from openel_zenoh.keys import Keys
from openel_zenoh.server import THREAD_READS

from .conftest import client_cfg, free_port, session


def run_gated(main: Callable[[], Awaitable[None]]) -> None:
    anyio.run(main, backend="asyncio", backend_options={"loop_factory": GatedEventLoop})


def get_position(logical_id: int = 0) -> Device:
    return Device("Motor", (CommandMessage.call("GetPosition", "", logical_id=logical_id),))


# -- the gate ----------------------------------------------------------------------------------
def test_the_gate_opens_only_while_the_loop_waits_in_select() -> None:
    async def main() -> None:
        loop = asyncio.get_running_loop()
        gate = gate_of(loop)
        assert isinstance(gate, LoopGate)

        def enter_and_leave() -> bool:
            entered = gate.try_enter()
            if entered:
                gate.leave()
            return entered

        # The loop waits in select for the worker thread: granted.
        assert await anyio.to_thread.run_sync(enter_and_leave) is True
        # While the loop runs Python code (this coroutine), another thread is refused.
        result: list[bool] = []
        thread = threading.Thread(target=lambda: result.append(enter_and_leave()))
        thread.start()
        thread.join()  # this coroutine never yielded: the loop never parked
        assert result == [False]

        # A section keeps the loop from resuming: a callback scheduled inside it runs
        # only once the section is left.
        inside = threading.Event()
        ran_inside: list[bool] = []
        done = anyio.Event()

        def callback() -> None:
            ran_inside.append(inside.is_set())
            done.set()

        def section() -> None:
            while not gate.try_enter():  # the loop parks as soon as it awaits
                time.sleep(0.0001)
            inside.set()
            loop.call_soon_threadsafe(callback)
            time.sleep(0.05)  # ample time for the loop to run it if it could
            inside.clear()
            gate.leave()

        worker = threading.Thread(target=section)
        worker.start()
        with anyio.fail_after(5):
            await done.wait()
        worker.join()
        assert ran_inside == [False]
        assert gate.entered >= 2

    run_gated(main)


def test_a_plain_or_debug_loop_has_no_gate() -> None:
    async def main() -> None:
        assert gate_of(asyncio.get_running_loop()) is None

    anyio.run(main, backend="asyncio")

    async def debug() -> None:
        loop = asyncio.get_running_loop()
        loop.set_debug(True)
        try:
            assert gate_of(loop) is None
        finally:
            loop.set_debug(False)

    run_gated(debug)


def test_needs_wake_tells_whether_a_section_scheduled_loop_work() -> None:
    async def main() -> None:
        loop = asyncio.get_running_loop()
        before = work_marker(loop)
        assert not needs_wake(loop, before)
        handle = loop.call_soon(lambda: None)
        assert needs_wake(loop, before)
        handle.cancel()
        assert needs_wake(loop, None)  # a loop it cannot inspect: always

    run_gated(main)


# -- the server's reads on Zenoh's thread ------------------------------------------------------
def test_reads_are_answered_on_zenohs_thread_never_older_than_a_loop_read() -> None:
    async def main() -> None:
        port = free_port()
        motor = SimMotor(max_velocity=0.5, max_acceleration=50.0, position_limits=(-10, 10))
        async with (
            session(server_config([endpoint(port)])) as zs,
            Actuator(motor) as served,
            Surface([served]) as surface,
            SurfaceServer(surface, zs, "gate") as server,
            session(client_cfg(port)) as zc,
            # busy_wait=0: the client sleeps, so this process's loop parks in select
            RemoteSurface(zc, "gate", busy_wait=0) as remote,
        ):
            await remote.wait_server(5)
            async with Actuator(RemoteActuator(remote, 0)) as axis:
                await served.set_value(5.0, Request.POSITION)  # moving in + for seconds
                await anyio.sleep(0.01)
                before_thread = server.served_on_zenoh_thread
                for _ in range(30):
                    earlier = served.get_value_nowait(Request.POSITION_ACTUAL)
                    remote_value = await axis.get_value(Request.POSITION_ACTUAL)
                    later = served.get_value_nowait(Request.POSITION_ACTUAL)
                    # the remote read happened between the two loop-side reads
                    assert earlier <= remote_value <= later
                    assert earlier < later
                # (when the loop happens to be busy, the loop path answers: same values)
                assert server.served_on_zenoh_thread > before_thread
                # A command is never run on Zenoh's thread.
                before_thread = server.served_on_zenoh_thread
                await axis.set_value(0.0)
                assert server.served_on_zenoh_thread == before_thread

    run_gated(main)


def test_an_error_state_is_still_reported_as_an_error_by_the_thread_path() -> None:
    async def main() -> None:
        port = free_port()
        motor = SimMotor()
        async with (
            session(server_config([endpoint(port)])) as zs,
            Actuator(motor) as served,
            Surface([served]) as surface,
            SurfaceServer(surface, zs, "gate") as server,
            session(client_cfg(port)) as zc,
        ):
            payload = compact.encode(get_position())
            key = Keys("gate").execute

            def query() -> CommandMessage:
                # a blocking raw query from a worker thread: this loop waits in select
                replies = list(zc.get(key, payload=payload, timeout=2.0))
                assert replies and replies[0].ok is not None
                return compact.device_from_compact(replies[0].ok.payload.to_bytes()).commands[0]

            async def thread_path_reply() -> CommandMessage:
                for _ in range(50):  # the loop may be busy at a query's arrival: retry
                    before = server.served_on_zenoh_thread
                    reply = await anyio.to_thread.run_sync(query)
                    if server.served_on_zenoh_thread == before + 1:
                        return reply
                raise AssertionError("no read was answered on Zenoh's thread")

            await anyio.sleep(0.2)  # the client's session connects
            ok = await thread_path_reply()
            assert ok.results is not None and ok.results.value("return_code") == 0
            motor.inject_fault()
            assert str(served.state) == "Error"
            failed = await thread_path_reply()
            assert failed.results is not None
            assert failed.results.value("return_code") == int(ReturnCode.HAL_ERROR)
            assert "state Error" in failed.results.value("message")

    run_gated(main)


class SchedulingListener:
    """A listener whose on_reading, off the loop's thread, schedules work on the running
    loop (as a recorder may): that work sets ``scheduled_ran``."""

    def __init__(self, loop_thread: int) -> None:
        self.loop_thread = loop_thread
        self.scheduled_ran = asyncio.Event()

    def on_command(self, component: object, request: object, value: float, t: int) -> None:
        pass

    def on_reading(self, component: object, request: object, values: object) -> None:
        if threading.get_ident() != self.loop_thread:
            asyncio.get_running_loop().call_soon(self.scheduled_ran.set)

    def on_state(self, component: object, old: object, new: object) -> None:
        pass


def test_work_a_read_schedules_on_the_loop_runs_at_once() -> None:
    async def main() -> None:
        port = free_port()
        async with (
            session(server_config([endpoint(port)])) as zs,
            Actuator(SimMotor()) as served,
            Surface([served]) as surface,
            SurfaceServer(surface, zs, "gate") as server,
            session(client_cfg(port)) as zc,
        ):
            listener = SchedulingListener(threading.get_ident())
            served.set_listener(listener)
            payload = compact.encode(get_position())
            key = Keys("gate").execute
            await anyio.sleep(0.2)  # the client's session connects
            stop = threading.Event()

            def reads() -> None:  # a plain thread: its queries alone never wake this loop
                while not stop.is_set():
                    replies = list(zc.get(key, payload=payload, timeout=2.0))
                    assert replies and replies[0].ok is not None
                    time.sleep(0.01)

            thread = threading.Thread(target=reads)
            thread.start()
            try:
                # A read on Zenoh's thread scheduled work here, and the loop, asleep
                # in select, was woken to run it.
                start = time.monotonic()
                with anyio.move_on_after(3):  # nothing else wakes the loop before this
                    await listener.scheduled_ran.wait()
                assert listener.scheduled_ran.is_set()
                assert time.monotonic() - start < 1.5
            finally:
                stop.set()
                await anyio.to_thread.run_sync(thread.join)
            assert server.served_on_zenoh_thread >= 1

    run_gated(main)


class SlowReads(ActuatorDevice):
    """GetPosition suspends (a worker serves it); GetState has a synchronous path."""

    info = DeviceInfo(kind=DeviceKind.MOTOR)
    reports_completion = True

    async def open(self, ctx: DeviceContext) -> None:
        self.ctx = ctx

    async def command(self, request: Request, value: float) -> None:
        self.ctx.target_reached()

    async def read(self, request: Request) -> float:
        await anyio.sleep(0.005)
        return 0.0


def test_a_clients_earlier_requests_are_answered_before_a_read_on_zenohs_thread() -> None:
    async def main() -> None:
        port = free_port()
        async with (
            session(server_config([endpoint(port)])) as zs,
            Actuator(SlowReads()) as served,
            Surface([served]) as surface,
            SurfaceServer(surface, zs, "order") as server,
            session(client_cfg(port)) as zc,
        ):
            key = Keys("order").execute
            slow = compact.encode(get_position())  # 5 ms, served by a worker task
            state = compact.encode(
                Device("Motor", (CommandMessage.call("GetState", "", logical_id=0),))
            )

            def send(payload: bytes) -> Any:
                return zc.get(key, payload=payload, attachment=b"client-1", timeout=2.0)

            def slow_then_state() -> bool:
                first = send(slow)
                second = send(state)  # while the first one is being served
                assert second.recv().ok is not None
                # replies travel in order on the link: the slow one came first
                return first.try_recv() is not None

            await anyio.sleep(0.2)  # the client's session connects
            met = await anyio.to_thread.run_sync(lambda: send(state).recv())
            assert met.ok is not None  # the server meets client-1
            for _ in range(5):
                assert await anyio.to_thread.run_sync(slow_then_state)
            # A read of an idle client: on Zenoh's thread (the loop may be busy at a
            # query's arrival: a few tries)
            for _ in range(50):
                before = server.served_on_zenoh_thread
                assert (await anyio.to_thread.run_sync(lambda: send(state).recv())).ok
                if server.served_on_zenoh_thread == before + 1:
                    break
            else:
                raise AssertionError("no read was answered on Zenoh's thread")

    run_gated(main)


def test_thread_reads_are_reads() -> None:
    assert not any(name.startswith("Set") for name in THREAD_READS)


# -- the client's busy-wait -------------------------------------------------------------------
@pytest.mark.parametrize("bad", [-0.001, 0.5, True, "0.001", float("nan")])
async def test_busy_wait_is_checked(bad: object) -> None:
    async with session(client_cfg(free_port())) as zc:
        with pytest.raises(BadParameterError, match="busy_wait"):
            RemoteSurface(zc, "x", busy_wait=bad)  # type: ignore[arg-type]


async def test_replies_slower_than_the_busy_wait_back_off_to_sleeping_queries() -> None:
    port = free_port()
    async with (
        session(server_config([endpoint(port)])) as zs,
        Actuator(SlowReads()) as served,  # every read takes 5 ms: longer than the budget
        Surface([served]) as surface,
        SurfaceServer(surface, zs, "slow"),
        session(client_cfg(port)) as zc,
        RemoteSurface(zc, "slow", busy_wait=0.0005) as remote,
    ):
        await remote.wait_server(5)
        # probe (miss), 1 sleeping, probe (miss), 2 sleeping, probe (miss), 4 sleeping, probe
        for _ in range(1 + 1 + 1 + 2 + 1 + 4 + 1):
            reply = (await remote.execute(get_position())).commands[0]
            assert reply.results is not None and reply.results.value("return_code") == 0
        assert (remote.busy_hits, remote.busy_misses) == (0, 4)


class SlowCommands(ActuatorDevice):
    """A command takes 30 ms (a worker serves it); a read has a synchronous path."""

    info = DeviceInfo(kind=DeviceKind.MOTOR)
    reports_completion = True

    async def open(self, ctx: DeviceContext) -> None:
        self.ctx = ctx

    async def command(self, request: Request, value: float) -> None:
        await anyio.sleep(0.03)
        self.ctx.target_reached()

    async def read(self, request: Request) -> float:
        return 0.0

    def read_nowait(self, request: Request) -> float:
        return 0.0


async def test_slow_commands_do_not_make_reads_sleep() -> None:
    """Misses of asynchronous commands back off in a lane of their own: reads answered
    within the busy-wait keep being polled."""
    port = free_port()
    async with (
        session(server_config([endpoint(port)])) as zs,
        Actuator(SlowCommands()) as served,
        Surface([served]) as surface,
        SurfaceServer(surface, zs, "lanes"),
        session(client_cfg(port)) as zc,
        RemoteSurface(zc, "lanes", busy_wait=0.01) as remote,
    ):
        await remote.wait_server(5)
        async with Actuator(RemoteActuator(remote, 0)) as axis:
            set_position = Device(
                "Motor", (CommandMessage.call("SetPosition", "", logical_id=0, position=0.1),)
            )
            assert remote.lane_of(set_position) == "commands"
            assert remote.lane_of(get_position()) == ""
            for _ in range(100):  # until a read was polled and hit: its lane is clear
                hits = remote.busy_hits
                await axis.get_value(Request.POSITION_ACTUAL)
                if remote.busy_hits > hits:
                    break
            misses = remote.busy_misses
            for _ in range(3):  # each a miss (30 ms > 10 ms): the commands' lane backs off
                await axis.set_value(0.1)
            assert remote.busy_misses > misses
            polled = remote.busy_hits + remote.busy_misses
            await axis.get_value(Request.POSITION_ACTUAL)
            assert remote.busy_hits + remote.busy_misses == polled + 1  # polled, not asleep


async def test_every_query_is_polled_then_answered_whichever_path() -> None:
    port = free_port()
    async with (
        session(server_config([endpoint(port)])) as zs,
        Actuator(SimMotor()) as served,
        Surface([served]) as surface,
        SurfaceServer(surface, zs, "fast"),
        session(client_cfg(port)) as zc,
        RemoteSurface(zc, "fast", busy_wait=0.002) as remote,
    ):
        await remote.wait_server(5)
        async with Actuator(RemoteActuator(remote, 0)) as axis:
            start = remote.busy_hits + remote.busy_misses
            for _ in range(20):
                assert await axis.get_value(Request.POSITION_ACTUAL) == 0.0
            polled = remote.busy_hits + remote.busy_misses - start
            assert 1 <= polled <= 20  # misses make later queries sleep, never fail


@pytest.mark.parametrize("busy_wait", [0.0, 0.0005])
async def test_a_query_nobody_answers_ends_with_timeout_error(busy_wait: float) -> None:
    async with (
        session(client_cfg(free_port())) as zc,
        RemoteSurface(zc, "nobody", timeout=0.2, busy_wait=busy_wait) as remote,
    ):
        with anyio.fail_after(5), pytest.raises(TimeoutError, match="no reply"):
            await remote.execute(get_position())


def test_a_failing_thread_path_leaves_the_query_to_the_loop(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    def broken(self: SurfaceServer, request: object) -> bool:
        raise RuntimeError("a bug in the thread path")

    monkeypatch.setattr(SurfaceServer, "_answer_here", broken)

    async def main() -> None:
        port = free_port()
        async with (
            session(server_config([endpoint(port)])) as zs,
            Actuator(SimMotor()) as served,
            Surface([served]) as surface,
            SurfaceServer(surface, zs, "gate") as server,
            session(client_cfg(port)) as zc,
            RemoteSurface(zc, "gate", busy_wait=0, timeout=1.0) as remote,
        ):
            await remote.wait_server(5)
            for _ in range(5):
                reply = (await remote.execute(get_position())).commands[0]
                assert reply.results is not None and reply.results.value("return_code") == 0
            assert server.served_on_zenoh_thread == 0

    run_gated(main)


def _thread_path_query(zc: Any, server: SurfaceServer) -> tuple[CommandMessage, int, int]:
    """One raw GetPosition query from this (worker) thread: the reply, and how much
    ``served`` and ``served_on_zenoh_thread`` grew meanwhile."""
    served, on_thread = server.served, server.served_on_zenoh_thread
    replies = list(
        zc.get(Keys("gate").execute, payload=compact.encode(get_position()), timeout=2.0)
    )
    assert replies and replies[0].ok is not None
    reply = compact.device_from_compact(replies[0].ok.payload.to_bytes()).commands[0]
    return reply, server.served - served, server.served_on_zenoh_thread - on_thread


def test_a_read_that_ran_on_zenohs_thread_is_never_run_again_when_its_reply_fails(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A failure after the read (here: encoding its reply on Zenoh's thread) is answered
    there as an error; the query is not handed to the loop to be read and counted again."""
    loop_thread = threading.get_ident()
    encoded = SurfaceServer._encoded

    def failing_off_the_loop(request: Any, device: Device) -> bytes:
        if threading.get_ident() != loop_thread:
            raise RuntimeError("an encoding bug")
        return encoded(request, device)

    monkeypatch.setattr(SurfaceServer, "_encoded", staticmethod(failing_off_the_loop))

    async def main() -> None:
        port = free_port()
        async with (
            session(server_config([endpoint(port)])) as zs,
            Actuator(SimMotor()) as served,
            Surface([served]) as surface,
            SurfaceServer(surface, zs, "gate") as server,
            session(client_cfg(port)) as zc,
        ):
            await anyio.sleep(0.2)  # the client's session connects
            for _ in range(50):  # the loop may be busy at a query's arrival: retry
                reply, served_delta, thread_delta = await anyio.to_thread.run_sync(
                    _thread_path_query, zc, server
                )
                assert reply.results is not None
                assert served_delta == 1  # counted once, whichever path answered
                if thread_delta == 1:
                    assert reply.results.value("return_code") == int(ReturnCode.HAL_ERROR)
                    assert "an encoding bug" in reply.results.value("message")
                    return
                assert reply.results.value("return_code") == 0  # the loop path
            raise AssertionError("no read was answered on Zenoh's thread")

    run_gated(main)


def test_a_loop_put_in_debug_mode_after_start_answers_reads_itself() -> None:
    """asyncio's debug mode checks that loop methods run on the loop's thread: once it is
    on, reads take the loop path (checked at each read, not only at the server's start)."""

    async def main() -> None:
        loop = asyncio.get_running_loop()
        port = free_port()
        async with (
            session(server_config([endpoint(port)])) as zs,
            Actuator(SimMotor()) as served,
            Surface([served]) as surface,
            SurfaceServer(surface, zs, "gate") as server,
            session(client_cfg(port)) as zc,
        ):
            listener = SchedulingListener(threading.get_ident())  # call_soon off the loop
            served.set_listener(listener)
            await anyio.sleep(0.2)  # the client's session connects
            loop.set_debug(True)
            try:
                for _ in range(10):
                    reply, served_delta, thread_delta = await anyio.to_thread.run_sync(
                        _thread_path_query, zc, server
                    )
                    assert reply.results is not None
                    assert reply.results.value("return_code") == 0, reply.results
                    assert (served_delta, thread_delta) == (1, 0)
            finally:
                loop.set_debug(False)

    run_gated(main)
