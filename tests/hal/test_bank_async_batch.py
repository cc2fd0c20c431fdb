"""ActuatorDevice.async_batch_commander: a bank (and an AxisGroup) over devices without a
synchronous path awaits one device batch per call instead of one ``command`` per device,
with the semantics of ``set_value`` on every member (lazy Motions, supersession, COMPLETED
for the final target); a member commanded by another path during the awaited batch keeps
that later command; a declined batch or a link fault goes device by device."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import ClassVar

import anyio
import anyio.lowlevel
import pytest

from openel_async import (
    Actuator,
    ActuatorBank,
    ActuatorDevice,
    ActuatorLimits,
    ComponentState,
    DeviceContext,
    DeviceFaultError,
    EventId,
    EventTimer,
    NotConnectedError,
    Outcome,
    Request,
    VirtualClock,
)
from openel_async.device import AsyncBatchCommander
from openel_async.motion import AxisGroup, AxisLimits
from openel_async.testing import ComponentStack, EventRecorder

COMPLETED = EventId.COMPLETED


class BusServo(ActuatorDevice):
    """A servo on a bus: every command is awaited; the driver writes a whole bank at once."""

    limits = ActuatorLimits((-2.0, 2.0), 1.0, 1.0)
    supported_requests = frozenset({Request.POSITION, Request.VELOCITY})
    reports_completion = True
    batches: ClassVar[list[tuple[Request, tuple[float, ...]]]] = []
    accept: ClassVar[bool] = True
    connected: ClassVar[bool] = True
    gate: ClassVar[anyio.Event | None] = None
    """When set, a batch waits on it (something else runs during the awaited batch)."""

    def __init__(self) -> None:
        self.position = 0.0
        self.commands: list[tuple[Request, float]] = []
        self.ctx: DeviceContext | None = None

    async def open(self, ctx: DeviceContext) -> None:
        self.ctx = ctx

    async def command(self, request: Request, value: float) -> None:
        await anyio.lowlevel.checkpoint()
        if not BusServo.connected:
            raise NotConnectedError("bus down")
        self.commands.append((request, value))
        self.position = value

    async def read(self, request: Request) -> float:
        await anyio.lowlevel.checkpoint()
        return self.position

    @classmethod
    def async_batch_commander(cls, devices: Sequence[ActuatorDevice]) -> AsyncBatchCommander:
        servos = [d for d in devices if isinstance(d, BusServo)]

        async def command(request: Request, values: Sequence[float], /) -> bool:
            if not BusServo.connected:
                raise NotConnectedError("bus down")
            if not BusServo.accept:
                return False
            gate = BusServo.gate
            if gate is not None:
                await gate.wait()
            else:
                await anyio.lowlevel.checkpoint()
            cls.batches.append((request, tuple(values)))
            for servo, value in zip(servos, values, strict=True):
                servo.position = value
            return True

        return command


@pytest.fixture(autouse=True)
def _bus() -> Iterator[None]:
    BusServo.batches.clear()
    BusServo.accept = BusServo.connected = True
    BusServo.gate = None
    yield
    BusServo.accept = BusServo.connected = True
    BusServo.gate = None


async def _servos(stack: ComponentStack, count: int) -> tuple[list[BusServo], list[Actuator]]:
    servos = [BusServo() for _ in range(count)]
    actuators = [await stack.actuator(s, device_name=f"Bus{i}") for i, s in enumerate(servos)]
    return servos, actuators


async def test_one_awaited_batch_per_call_with_set_values_semantics(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    events = EventRecorder(virtual_clock)
    servos, actuators = await _servos(hal_components, 3)
    for actuator in actuators:
        actuator.add_observer(events)
    bank = ActuatorBank(actuators)
    await bank.set_values([0.1, 0.2, 0.3])
    first = bank.motions
    await bank.set_values([0.4, 0.5, 0.6])
    assert BusServo.batches == [
        (Request.POSITION, (0.1, 0.2, 0.3)),
        (Request.POSITION, (0.4, 0.5, 0.6)),
    ]
    assert all(s.commands == [] for s in servos)  # no command one by one
    assert all(m is not None and m.outcome is Outcome.SUPERSEDED for m in first)
    final = bank.motions
    assert [(m.target, m.sequence) for m in final if m is not None] == [
        (0.4, 2),
        (0.5, 2),
        (0.6, 2),
    ]
    assert bank.get_values_nowait(Request.POSITION) == (0.4, 0.5, 0.6)
    for servo in servos:
        assert servo.ctx is not None
        servo.ctx.target_reached()
    for motion in final:
        assert motion is not None
        await motion
    assert events.count("event", COMPLETED) == 3 and not events.errors


async def test_a_member_commanded_during_the_awaited_batch_keeps_that_command(
    hal_components: ComponentStack,
) -> None:
    _, actuators = await _servos(hal_components, 2)
    bank = ActuatorBank(actuators)
    await bank.set_values([0.1, 0.2])
    BusServo.gate = gate = anyio.Event()
    own = None

    async def overtake() -> None:  # while the batch is on the bus
        nonlocal own
        own = await actuators[1].set_value(0.9)
        gate.set()

    async with anyio.create_task_group() as tg:
        tg.start_soon(bank.set_values, [0.3, 0.4])
        await anyio.lowlevel.checkpoint()
        tg.start_soon(overtake)
    assert own is not None and own.outcome is Outcome.PENDING
    assert actuators[1].motion is own and own.target == 0.9
    assert bank.get_values_nowait(Request.POSITION) == (0.3, 0.9)
    first = actuators[0].motion
    assert first is not None and first.target == 0.3 and first.outcome is Outcome.PENDING
    BusServo.gate = None
    await bank.set_values([0.5, 0.6])  # every member attached again: the batch replaces it
    assert own.outcome is Outcome.SUPERSEDED and first.outcome is Outcome.SUPERSEDED
    assert bank.get_values_nowait(Request.POSITION) == (0.5, 0.6)


async def test_a_member_leaving_active_during_the_awaited_batch_takes_the_full_path(
    hal_components: ComponentStack,
) -> None:
    servos, actuators = await _servos(hal_components, 2)
    bank = ActuatorBank(actuators)
    BusServo.gate = gate = anyio.Event()

    async def fault() -> None:
        assert servos[1].ctx is not None
        servos[1].ctx.fault(2, "cable pulled")
        gate.set()

    async with anyio.create_task_group() as tg:
        tg.start_soon(bank.set_values, [0.3, 0.4])
        await anyio.lowlevel.checkpoint()
        tg.start_soon(fault)
    assert actuators[1].state is ComponentState.ERROR
    assert actuators[1].motion is None  # the batch's command did not become its Motion
    assert actuators[1].last_fault is not None
    kept = actuators[0].motion
    assert kept is not None and kept.target == 0.3 and kept.outcome is Outcome.PENDING


async def test_a_declined_batch_or_a_link_fault_goes_device_by_device(
    hal_components: ComponentStack,
) -> None:
    servos, actuators = await _servos(hal_components, 2)
    bank = ActuatorBank(actuators)
    BusServo.accept = False
    await bank.set_values([0.1, 0.2])
    assert BusServo.batches == [] and [s.commands for s in servos] == [
        [(Request.POSITION, 0.1)],
        [(Request.POSITION, 0.2)],
    ]
    BusServo.accept = True
    BusServo.connected = False
    with pytest.raises(DeviceFaultError) as info:
        await bank.set_values([0.3, 0.4])
    assert "Bus0" in str(info.value) and isinstance(info.value.__cause__, NotConnectedError)
    assert actuators[0].state is ComponentState.ERROR  # the first device the path tried
    assert actuators[1].state is ComponentState.ACTIVE


async def test_an_axis_group_over_bus_servos_sends_one_batch_per_tick(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    servos, actuators = await _servos(hal_components, 3)
    limits = AxisLimits(max_velocity=1.0, max_acceleration=5.0, max_jerk=50.0)
    async with (
        EventTimer(1, clock=virtual_clock) as timer,
        AxisGroup(actuators, timer=timer, limits=limits) as group,
    ):
        motion = await group.move_to([0.2, -0.1, 0.05])
        with anyio.fail_after(10):
            await motion
    assert len(BusServo.batches) > 10
    assert all(s.commands == [] for s in servos)
    assert BusServo.batches[-1] == (Request.POSITION, (0.2, -0.1, 0.05))
