"""The live view: a Foxglove WebSocket client connects to the server on 127.0.0.1, subscribes
to /joint_states and receives joint states.

The installed foxglove-sdk's server speaks the Foxglove WebSocket protocol under the
subprotocol ``foxglove.sdk.v1`` (the successor of ``foxglove.websocket.v1``, with the same
advertise -> subscribe -> message data exchange); it refuses the old name with HTTP 400."""

from __future__ import annotations

import json
import struct
from typing import Any

import anyio
import websockets

from openel_async import Actuator, EventTimer, MonotonicClock
from openel_async.device import DeviceInfo
from openel_async.recording import LiveView
from openel_sim import SimMotor

from .schema_check import problems

SUBPROTOCOL = "foxglove.sdk.v1"


async def _until_op(ws: Any, op: str) -> dict[str, Any]:
    while True:
        frame = await ws.recv()
        if isinstance(frame, str):
            message: dict[str, Any] = json.loads(frame)
            if message.get("op") == op:
                return message


class _SuctionCup(SimMotor):
    """An actuator of a HAL extension kind (128): no joint."""

    info = DeviceInfo(kind=0x80, vendor_id=0x0E1, product_id=0x999, product_name="Cup")


async def test_client_receives_joint_states() -> None:
    """... of the joints only (not the suction cup), each matching the advertised schema."""
    clock = MonotonicClock()
    live = LiveView(port=0)
    received: list[dict[str, Any]] = []
    schemas: list[dict[str, Any]] = []
    async with live:
        assert live.url.startswith("ws://127.0.0.1:") and live.pipeline.port
        axis = Actuator(SimMotor(max_velocity=3.0), device_name="AXIS", clock=clock)
        cup = Actuator(_SuctionCup(), device_name="CUP", clock=clock)
        timer = EventTimer(5, clock=clock, name="loop")
        live.observe(axis)
        live.observe(cup)
        live.observe_timer(timer)
        async with axis, cup, timer, anyio.create_task_group() as tg:
            timer.start_timer()
            await axis.set_value(1.0)

            async def client() -> None:
                async with websockets.connect(live.url, subprotocols=[SUBPROTOCOL]) as ws:
                    assert ws.subprotocol == SUBPROTOCOL
                    info = await _until_op(ws, "serverInfo")
                    assert info["name"] == "openel-async"
                    channels: dict[str, dict[str, Any]] = {}
                    wanted = {"/joint_states", "/hal/AXIS", "/timer/loop"}
                    while not wanted <= channels.keys():  # advertised as the writer makes them
                        advertise = await _until_op(ws, "advertise")
                        channels.update({c["topic"]: c for c in advertise["channels"]})
                    channel = channels["/joint_states"]
                    assert channel["encoding"] == "json"
                    assert channel["schemaName"] == "openel_async.JointStates"
                    schemas.append(json.loads(channel["schema"]))
                    subscribe = {"id": 7, "channelId": channel["id"]}
                    await ws.send(json.dumps({"op": "subscribe", "subscriptions": [subscribe]}))
                    while len(received) < 3:
                        frame = await ws.recv()
                        if isinstance(frame, bytes) and frame[0] == 0x01:  # message data
                            (sub_id,) = struct.unpack_from("<I", frame, 1)
                            assert sub_id == 7
                            received.append(json.loads(frame[13:]))

            with anyio.fail_after(20):
                await client()
            tg.cancel_scope.cancel()
    assert all([j["name"] for j in m["joints"]] == ["AXIS"] for m in received)
    assert not [p for m in received for p in problems(schemas[0], m)]
    assert all(m["joints"][0]["commanded"] == 1.0 for m in received)
    positions = [m["joints"][0]["position"] for m in received]
    assert positions == sorted(positions) and 0.0 <= positions[0] <= 1.0  # moving towards 1
    times = [m["time_ns"] for m in received]
    assert times == sorted(times) and len(set(times)) == len(times)
