"""A remote client in a process of its own, driven by tests/remote/test_processes.py.

``python client_process.py commander|listener PORT NAMESPACE``: connects to a server on
127.0.0.1:PORT and prints one JSON object per line; reads commands from stdin (one per
line) and ends when stdin closes. Every wait is bounded.

- commander: an ``Actuator(RemoteActuator)`` and a ``Sensor(RemoteSensor)``; commands
  ``move X`` (set_value, wait for COMPLETED, read both), ``start X`` (set_value, no
  wait), ``wait_error``, ``reinit`` (both), ``wait_server``.
- listener: subscribed to the Motors' COMPLETED events; prints each one as it arrives.
"""

from __future__ import annotations

import json
import sys
from typing import Any

import anyio

from openel_async import Actuator, EventId, ObserverQueue, Request, Sensor
from openel_async.cli.logs import configure_logging
from openel_async.observers import ErrorNotice, EventNotice
from openel_async.surface import ApplicationQueue, EventNotification
from openel_zenoh import RemoteActuator, RemoteSensor, RemoteSurface, close_session, open_session
from openel_zenoh.config import client_config, endpoint

WAIT_S = 15.0


def say(**values: Any) -> None:
    print(json.dumps(values), flush=True)


async def commands() -> Any:
    while True:
        line = await anyio.to_thread.run_sync(sys.stdin.readline, abandon_on_cancel=True)
        if not line:
            return
        yield line.split()


async def commander(remote: RemoteSurface) -> None:
    async with (
        Actuator(RemoteActuator(remote, 0)) as axis,
        Sensor(RemoteSensor(remote, 0)) as encoder,
    ):
        notices = ObserverQueue()
        axis.add_observer(notices)
        say(ready=True, units=list(encoder.units), device_name=axis.device_name)
        motion = None
        async for words in commands():
            verb = words[0]
            try:
                if verb == "move":
                    with anyio.fail_after(WAIT_S):
                        motion = await axis.set_value(float(words[1]))
                        while True:
                            notice = await notices.get()
                            if isinstance(notice, EventNotice):
                                break
                        await motion
                    say(
                        completed=notice.event_id == EventId.COMPLETED,
                        position=await axis.get_value(Request.POSITION_ACTUAL),
                        encoder=(await encoder.get_value())[0],
                    )
                elif verb == "start":
                    motion = await axis.set_value(float(words[1]))
                    say(started=True, done=motion.done())
                elif verb == "wait_error":
                    with anyio.fail_after(WAIT_S):
                        while True:
                            notice = await notices.get()
                            if isinstance(notice, ErrorNotice):
                                break
                    fault = axis.last_fault
                    say(
                        error_id=notice.error_id,
                        state=str(axis.state),
                        code=fault.code.name if fault is not None else None,
                        motion_done=motion is not None and motion.done(),
                        outcome=motion.outcome.name if motion is not None else None,
                    )
                elif verb == "wait_server":
                    await remote.wait_server(WAIT_S)
                    say(server=True)
                elif verb == "reinit":
                    try:
                        await axis.re_init()
                        await encoder.re_init()
                        say(reinit="ok", state=str(axis.state), encoder_state=str(encoder.state))
                    except Exception as exc:
                        say(reinit=str(exc), state=str(axis.state))
                else:
                    say(error=f"unknown command {verb!r}")
            except Exception as exc:
                say(error=f"{type(exc).__name__}: {exc}")


async def listener(remote: RemoteSurface) -> None:
    app = ApplicationQueue()
    await remote.subscribe("Motor", "COMPLETED", app)
    remote.on_server(lambda alive: say(server=alive))
    say(ready=True)

    async def report() -> None:
        async for notice in app:
            if isinstance(notice, EventNotification):
                detail = remote.cached_event_detail(notice.event_id)
                say(
                    event=notice.event_type,
                    logical_id=detail.value("logical_id") if detail is not None else None,
                    missed=notice.missed,
                )

    async with anyio.create_task_group() as tg:
        tg.start_soon(report)
        async for _ in commands():
            pass
        tg.cancel_scope.cancel()


async def main(role: str, port: int, namespace: str) -> None:
    configure_logging("console", "warning")
    session = await open_session(client_config([endpoint(port)]))
    try:
        async with RemoteSurface(session, namespace, timeout=1.0) as remote:
            await remote.wait_server(WAIT_S)
            await (commander if role == "commander" else listener)(remote)
    finally:
        await close_session(session)


if __name__ == "__main__":
    anyio.run(main, sys.argv[1], int(sys.argv[2]), sys.argv[3])
