"""The surface's per-request shortcuts (issue 27): replies built from checked parts, a
Device's target looked up once, subscriptions that exclude event types, completions
reported from the component's notifications."""

from __future__ import annotations

import anyio
import anyio.lowlevel
import pytest

from openel_async import Actuator, ReturnCode, WouldBlockError
from openel_async.errors import BadParameterError
from openel_async.surface import (
    ApplicationQueue,
    CommandMessage,
    Device,
    EventNotification,
    Surface,
    compact,
)
from openel_async.surface.messages import (
    DataType,
    Parameter,
    ResultList,
    command_unchecked,
    device_unchecked,
    parameter_unchecked,
    results_unchecked,
    with_value,
)
from openel_async.testing import ComponentStack
from openel_sim import SimMotor


def _one(function_name: str, **arguments: object) -> Device:
    return Device("Motor", (CommandMessage.call(function_name, "", **arguments),))


def _checked(device: Device) -> Device:
    """``device`` built again through the checking constructors."""
    return Device(
        device.device_kind,
        tuple(
            CommandMessage(
                c.function_name,
                c.command_id,
                c.arguments,
                None
                if c.results is None
                else ResultList(
                    tuple(Parameter(p.data_type_id, p.name, p.value) for p in c.results.parameters)
                ),
            )
            for c in device.commands
        ),
    )


def test_unchecked_messages_equal_checked_ones() -> None:
    parameter = parameter_unchecked(DataType.FLOAT, "position", 1.5)
    assert parameter == Parameter(DataType.FLOAT, "position", 1.5)
    assert with_value(parameter, -2.0) == Parameter(DataType.FLOAT, "position", -2.0)
    assert parameter.value == 1.5  # the template is not changed
    command = command_unchecked("GetPosition", "c7", None, results_unchecked((parameter,)))
    device = device_unchecked("Motor", (command,))
    checked = Device(
        "Motor", (CommandMessage("GetPosition", "c7", None, ResultList((parameter,))),)
    )
    assert device == checked
    assert compact.encode(device) == compact.encode(checked)


async def test_execute_nowait_replies_as_the_checked_model_and_refuses_the_same(
    hal_components: ComponentStack,
) -> None:
    motor = SimMotor(max_velocity=2.0, max_acceleration=20.0)
    axis = await hal_components.actuator(motor)
    await (await axis.set_value(0.25))
    async with Surface([axis]) as surface:
        read = _one("GetPosition", logical_id=0)
        for n in (1, 2):  # the same Device object: its target is looked up once
            reply = surface.execute_nowait(read)
            assert reply == _checked(reply)
            assert compact.encode(reply) == compact.encode(_checked(reply))
            assert reply.commands[0].command_id == f"c{n}"
            results = reply.commands[0].results
            assert results is not None
            assert results.as_dict() == {"return_code": 0, "position": await axis.get_value()}
        moved = surface.execute_nowait(_one("SetPosition", logical_id=0, position=0.5))
        assert moved == _checked(moved)
        # Refusals come back every time, whether or not the Device was seen before.
        bad_id = _one("GetPosition", logical_id=5)
        bad_type = _one("SetPosition", logical_id=0, position=1)  # INT, not FLOAT
        for device in (bad_id, bad_type, bad_id, bad_type):
            results = surface.execute_nowait(device).commands[0].results
            assert results is not None
            assert results.value("return_code") == ReturnCode.HAL_BAD_PARAMETER
        assert surface.refused == 4
        with pytest.raises(WouldBlockError):
            surface.execute_nowait(_one("Reset", logical_id=0))
        with pytest.raises(BadParameterError):
            surface.execute_nowait(object())  # type: ignore[arg-type]


async def test_subscribe_excluding_completed_makes_no_event_of_it(
    hal_components: ComponentStack,
) -> None:
    axis = await hal_components.actuator(SimMotor(max_velocity=2.0, max_acceleration=20.0))
    everything, but_completed = ApplicationQueue(), ApplicationQueue()
    async with Surface([axis]) as surface:
        with pytest.raises(BadParameterError):
            surface.subscribe("Motor", "*", but_completed, exclude="COMPLETED")
        with pytest.raises(BadParameterError):
            surface.subscribe("Motor", "*", but_completed, exclude=[""])
        surface.subscribe("Motor", "*", but_completed, exclude=["COMPLETED"])
        await (await axis.set_value(0.1))
        await anyio.lowlevel.checkpoint()
        assert len(but_completed) == 0
        with pytest.raises(BadParameterError):
            surface.get_event_detail("e1")  # no event was made: nobody wanted it
        surface.subscribe("Motor", "*", everything)
        await (await axis.set_value(0.0))
        await anyio.lowlevel.checkpoint()
        notice = everything.get_nowait()
        assert isinstance(notice, EventNotification) and notice.event_type == "COMPLETED"
        assert len(but_completed) == 0


class _Completions:
    """A plain application: completed is called inline."""

    def __init__(self) -> None:
        self.done: list[tuple[str, ReturnCode]] = []
        self.any = anyio.Event()

    def completed(self, command_id: str, status: ReturnCode) -> None:
        self.done.append((command_id, status))
        self.any.set()


async def test_completed_is_reported_when_the_component_tells(
    hal_components: ComponentStack,
) -> None:
    axis: Actuator = await hal_components.actuator(
        SimMotor(max_velocity=2.0, max_acceleration=20.0)
    )
    app = _Completions()
    async with Surface([axis]) as surface:
        reply = surface.execute_nowait(_one("SetPosition", logical_id=0, position=0.2), app)
        command_id = reply.commands[0].command_id
        motion = axis.motion
        assert motion is not None and not app.done
        await motion
        # reported from the COMPLETED notification, before the waiter of the motion ran on
        assert app.done == [(command_id, ReturnCode.HAL_OK)]


async def test_a_command_that_ends_silently_is_still_reported(
    hal_components: ComponentStack,
) -> None:
    axis = await hal_components.actuator(SimMotor(max_velocity=0.5, max_acceleration=5.0))
    app = _Completions()
    async with Surface([axis]) as surface:
        reply = surface.execute_nowait(_one("SetPosition", logical_id=0, position=3.0), app)
        command_id = reply.commands[0].command_id
        await axis.set_value(-3.0)  # superseded by another party: no notification
        with anyio.fail_after(5):
            await app.any.wait()
        assert app.done == [(command_id, ReturnCode.HAL_ERROR)]
