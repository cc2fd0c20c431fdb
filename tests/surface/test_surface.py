"""The in-process surface layer over sim components (virtual clock)."""

from __future__ import annotations

import anyio
import anyio.lowlevel
import pytest

from openel_async import Actuator, ReturnCode, Sensor, VirtualClock
from openel_async.surface import (
    ApplicationQueue,
    CommandMessage,
    Completed,
    Device,
    ErrorNotification,
    EventNotification,
    Surface,
    xml_psm,
)
from openel_async.surface.messages import ResultList
from openel_async.testing import ComponentStack
from openel_sim import SimEncoder, SimMotor


async def _rig(stack: ComponentStack) -> tuple[list[SimMotor], list[Actuator], Sensor]:
    motors = [SimMotor(max_velocity=2.0, max_acceleration=20.0) for _ in range(2)]
    axes = [await stack.actuator(m) for m in motors]
    encoder = await stack.sensor(SimEncoder(motors[0]))
    return motors, axes, encoder


def _results(device: Device, index: int = 0) -> dict[str, object]:
    results = device.commands[index].results
    assert results is not None
    return results.as_dict()


async def test_sync_command_returns_results_in_the_message(hal_components: ComponentStack) -> None:
    _, axes, _ = await _rig(hal_components)
    async with Surface([*axes]) as surface:
        await axes[1].set_value(0.5)
        reply = await surface.execute(
            Device("Motor", (CommandMessage.call("GetPosition", "", logical_id=1),))
        )
        results = _results(reply)
        assert results["return_code"] == ReturnCode.HAL_OK
        assert results["position"] == await axes[1].get_value()
        assert reply.commands[0].command_id.startswith("c")


async def test_async_command_returns_at_once_and_completes_later(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    _, axes, _ = await _rig(hal_components)
    app = ApplicationQueue()
    async with Surface(axes) as surface:
        t0 = virtual_clock.now_ns()
        reply = await surface.execute(
            Device("Motor", (CommandMessage.call("SetPosition", "", logical_id=0, position=1.0),)),
            app,
        )
        assert virtual_clock.now_ns() == t0  # returned before the motion
        command_id = reply.commands[0].command_id
        assert _results(reply) == {"return_code": 0}
        with anyio.fail_after(5):
            notice = await app.get()
        assert notice == Completed(command_id, ReturnCode.HAL_OK)
        assert virtual_clock.now_ns() > t0
        assert await axes[0].get_value() == pytest.approx(1.0)


async def test_superseded_command_completes_with_an_error(hal_components: ComponentStack) -> None:
    _, axes, _ = await _rig(hal_components)
    app = ApplicationQueue()
    async with Surface(axes) as surface:
        first = await surface.execute_command(
            "Motor", CommandMessage.call("SetPosition", "", logical_id=0, position=1.0), app
        )
        second = await surface.execute_command(
            "Motor", CommandMessage.call("SetPosition", "", logical_id=0, position=-1.0), app
        )
        with anyio.fail_after(5):
            notices = [await app.get(), await app.get()]
        assert Completed(first.command_id, ReturnCode.HAL_ERROR) in notices
        assert Completed(second.command_id, ReturnCode.HAL_OK) in notices


@pytest.mark.parametrize(
    ("device_kind", "command", "code", "fragment"),
    [
        (
            "Motor",
            CommandMessage.call("Fly", "", logical_id=0),
            ReturnCode.HAL_NOT_IMPLEMENTED,
            "no function 'Fly'",
        ),
        (
            "Motor",
            CommandMessage.call("SetPosition", "", logical_id=7, position=1.0),
            ReturnCode.HAL_BAD_PARAMETER,
            "logical_id=7",
        ),
        (
            "Motor",
            CommandMessage.call("SetPosition", "", position=1.0),
            ReturnCode.HAL_BAD_PARAMETER,
            "logical_id=None",
        ),
        (
            "Motor",
            CommandMessage.call("SetPosition", "", logical_id=0, position=1),
            ReturnCode.HAL_BAD_PARAMETER,
            "position.data_type_id=1",
        ),
        (
            "Motor",
            CommandMessage.call("SetPosition", "", logical_id=0),
            ReturnCode.HAL_NULL_PARAMETER,
            "'position' is missing",
        ),
        (
            "Motor",
            CommandMessage.call("SetPosition", "", logical_id=0, position=99.0),
            ReturnCode.HAL_BAD_PARAMETER,
            "position in",
        ),
        (
            "Gripper",
            CommandMessage.call("Open", ""),
            ReturnCode.HAL_BAD_PARAMETER,
            "device_kind='Gripper'",
        ),
        (
            "Encoder",
            CommandMessage.call("SetScaleFactor", "", values=[0.0]),
            ReturnCode.HAL_BAD_PARAMETER,
            "values[0]=0.0",
        ),
        (
            "Motor",
            CommandMessage.call("SetOrigin", "", logical_id=0),
            ReturnCode.HAL_NOT_IMPLEMENTED,
            "plain Actuator (no origin)",
        ),
    ],
)
async def test_bad_commands_get_the_matching_return_code(
    hal_components: ComponentStack,
    device_kind: str,
    command: CommandMessage,
    code: ReturnCode,
    fragment: str,
) -> None:
    _, axes, encoder = await _rig(hal_components)
    async with Surface([*axes, encoder]) as surface:
        reply = await surface.execute(Device(device_kind, (command,)))
        results = _results(reply, 0)
        assert results["return_code"] == code
        assert fragment in str(results["message"])
        after = await surface.execute(
            Device("Motor", (CommandMessage.call("GetPosition", "", logical_id=0),))
        )
        assert _results(after)["return_code"] == ReturnCode.HAL_OK  # still serving
        assert surface.refused == 1


async def test_sensor_kind_and_xml_execute(hal_components: ComponentStack) -> None:
    _, axes, encoder = await _rig(hal_components)
    async with Surface([*axes, encoder]) as surface:
        request = xml_psm.to_xml(
            Device(
                "Encoder",
                (
                    CommandMessage.call("GetValueOfMeasurement"),
                    CommandMessage.call("GetUnitOfMeasurement"),
                ),
            )
        )
        reply = await surface.execute(xml_psm.device_from_xml(request))
        reply = xml_psm.device_from_xml(xml_psm.to_xml(reply))
        values = _results(reply, 0)
        assert values["values"] == tuple(await encoder.get_value())
        assert isinstance(values["time_ns"], int)
        assert _results(reply, 1)["units"] == tuple(encoder.units)
        assert [e.device_kind for e in surface.entries] == ["Motor", "Motor", "Encoder"]
        assert [e.logical_id for e in surface.entries] == [0, 1, 0]


async def test_subscribe_event_detail_and_unsubscribe(hal_components: ComponentStack) -> None:
    _, axes, _ = await _rig(hal_components)
    app = ApplicationQueue()
    async with Surface(axes) as surface:
        sid = surface.subscribe("motor", "COMPLETED", app)
        motion = await axes[1].set_value(0.3)
        await motion
        await anyio.lowlevel.checkpoint()
        notice = app.get_nowait()
        assert isinstance(notice, EventNotification)
        assert (notice.event_type, notice.subscribe_id) == ("COMPLETED", sid)
        detail = surface.get_event_detail(notice.event_id).as_dict()
        assert detail["logical_id"] == 1 and detail["event_code"] == 1
        assert detail["device_name"] == axes[1].device_name
        surface.unsubscribe(sid)
        await (await axes[1].set_value(0.0))
        await anyio.lowlevel.checkpoint()
        assert len(app) == 0
        with pytest.raises(Exception, match="subscribe_id"):
            surface.unsubscribe(sid)
        with pytest.raises(Exception, match="event_id"):
            surface.get_event_detail("e999")


async def test_errors_reach_attached_applications_with_detail(
    hal_components: ComponentStack,
) -> None:
    motors, axes, _ = await _rig(hal_components)
    app = ApplicationQueue()
    async with Surface(axes) as surface:
        surface.attach(app)
        motors[0].inject_fault(error_id=77, reason="over-temperature")  # a device-specific id
        with anyio.fail_after(5):
            notice = await app.get()
        assert isinstance(notice, ErrorNotification)
        assert notice.error_type == "ERROR_77"
        detail = surface.get_error_detail(notice.error_id).as_dict()
        assert detail["faulted"] is True and detail["logical_id"] == 0
        assert "over-temperature" in str(detail["message"])
        reply = await surface.execute_command(
            "Motor", CommandMessage.call("Reset", "", logical_id=0)
        )
        assert reply.results is not None and reply.results.value("return_code") == 0
        assert str(axes[0].state) == "Active"


async def test_async_application_methods_are_called() -> None:
    calls: list[tuple[str, ReturnCode]] = []
    called = anyio.Event()

    class App:
        async def completed(self, command_id: str, status: ReturnCode) -> None:
            calls.append((command_id, status))
            called.set()

    clock = VirtualClock()
    async with (
        clock.autojump(),
        Actuator(SimMotor(), clock=clock) as axis,
        Surface([axis]) as surface,
    ):
        reply = await surface.execute_command(
            "Motor", CommandMessage.call("SetPosition", "", position=0.2), App()
        )
        with anyio.fail_after(5):
            await called.wait()
        assert calls == [(reply.command_id, ReturnCode.HAL_OK)]


def test_application_queue_reports_missed_notices() -> None:
    queue = ApplicationQueue(maxsize=2)
    for i in range(5):
        queue.completed(f"c{i}", ReturnCode.HAL_OK)
    first = queue.get_nowait()
    assert first == Completed("c3", ReturnCode.HAL_OK, missed=3)
    assert queue.get_nowait() == Completed("c4", ReturnCode.HAL_OK)
    assert queue.missed_total == 3
    assert ResultList.of(a=1).value("a") == 1


class _SuspendingReads(SimMotor):
    """A SimMotor whose reads and commands suspend: no synchronous path."""

    async def read(self, request):  # type: ignore[no-untyped-def]
        await anyio.lowlevel.checkpoint()
        return self.read_nowait(request)

    async def command(self, request, value):  # type: ignore[no-untyped-def]
        await anyio.lowlevel.checkpoint()
        self.command_nowait(request, value)


def _one(name: str, **arguments: object) -> Device:
    return Device("Motor", (CommandMessage.call(name, "", **arguments),))


async def test_execute_nowait_runs_synchronous_paths_and_refuses_the_rest(
    hal_components: ComponentStack,
) -> None:
    from openel_async import WouldBlockError

    fast = await hal_components.actuator(SimMotor(max_velocity=2.0, max_acceleration=20.0))
    slow = await hal_components.actuator(_SuspendingReads())
    app = ApplicationQueue()
    async with Surface([fast, slow]) as surface:
        reply = surface.execute_nowait(_one("GetPosition", logical_id=0))
        assert _results(reply) == {"return_code": 0, "position": await fast.get_value()}
        assert reply.commands[0].command_id == "c1"
        moved = surface.execute_nowait(_one("SetPosition", logical_id=0, position=0.25), app)
        assert _results(moved) == {"return_code": 0} and not fast.motion.done()  # type: ignore[union-attr]
        # Refusals are answers, as in execute().
        refused = surface.execute_nowait(_one("Fly", logical_id=0))
        assert _results(refused)["return_code"] == ReturnCode.HAL_NOT_IMPLEMENTED
        assert surface.refused == 1
        # What would suspend is refused with nothing done, and numbers no command.
        for device in (
            _one("GetPosition", logical_id=1),  # the device needs I/O
            _one("SetPosition", logical_id=1, position=0.1),
            _one("Reset", logical_id=0),  # no synchronous path at all
            Device("Motor", (*_one("GetPosition", logical_id=0).commands,) * 2),
        ):
            with pytest.raises(WouldBlockError):
                surface.execute_nowait(device, app)
        assert slow.motion is None
        reply = await surface.execute(_one("GetPosition", logical_id=1))
        assert reply.commands[0].command_id == "c4"  # c1-c3 above, nothing since
        with anyio.fail_after(5):
            assert await app.get() == Completed(moved.commands[0].command_id, ReturnCode.HAL_OK)


async def test_completions_are_watched_by_one_task_per_component(
    hal_components: ComponentStack,
) -> None:
    import asyncio

    _, axes, _ = await _rig(hal_components)
    app = ApplicationQueue(maxsize=4096)
    async with Surface(axes) as surface:
        before = len(asyncio.all_tasks())
        ids: list[list[str]] = [[], []]
        for n in range(50):  # each command supersedes the previous one of its axis
            for axis in (0, 1):
                reply = surface.execute_nowait(
                    _one("SetPosition", logical_id=axis, position=0.01 * (n + 1)), app
                )
                ids[axis].append(reply.commands[0].command_id)
        assert len(asyncio.all_tasks()) <= before + 2  # not one task per command
        with anyio.fail_after(10):
            done = [await app.get() for _ in range(100)]
        for axis in (0, 1):
            mine = [c for c in done if isinstance(c, Completed) and c.command_id in ids[axis]]
            assert [c.command_id for c in mine] == ids[axis]  # in the order they were sent
            assert [c.status for c in mine] == [ReturnCode.HAL_ERROR] * 49 + [ReturnCode.HAL_OK]
