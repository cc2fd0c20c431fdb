"""A RemoteActuator's command payloads: the bytes compact.encode makes of the message
(its head and tail are encoded once per request, the value spliced in)."""

from __future__ import annotations

from typing import Any, cast

import pytest

from openel_async.requests import Request
from openel_async.surface import compact
from openel_async.surface.messages import CommandMessage, Device
from openel_zenoh import wire
from openel_zenoh.device import RemoteActuator


@pytest.mark.parametrize(
    ("request_", "name", "argument"),
    [
        (Request.POSITION, "SetPosition", "position"),
        (Request.VELOCITY, "SetSpeed", "speed"),
        (Request.TORQUE, "SetTorque", "torque"),
    ],
)
def test_command_payloads_are_the_encoded_messages(
    request_: Request, name: str, argument: str
) -> None:
    actuator = RemoteActuator(cast(Any, None), 3)
    for value in (0.0, 0.001, -2.5, 1e300, -0.0, float("inf")):
        expected = Device(
            "Motor", (CommandMessage.call(name, "", logical_id=3, **{argument: value}),)
        )
        assert actuator.command_payload(request_, value) == compact.encode(expected)
    stop = Device("Motor", (CommandMessage.call("SetControlMode", "", logical_id=3, mode=0),))
    assert actuator.command_payload(Request.NO_EXCITE, 0.0) == compact.encode(stop)


def test_subscribe_payload_is_two_items_unless_something_is_excluded() -> None:
    assert wire.subscribe_payload("Motor", "COMPLETED") == bytes.fromhex(
        "92a54d6f746f72a9434f4d504c45544544"
    )  # as in docs/wire.md
    both = wire.subscribe_payload("Motor", "*", ["COMPLETED"])
    assert wire.subscribe_decoder.decode(both) == wire.SubscribeRequest(
        "Motor", "*", ("COMPLETED",)
    )
    assert wire.subscribe_decoder.decode(wire.subscribe_payload("Motor", "*")).exclude == ()
