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
    BadParameterError,
    ComponentState,
    DeviceContext,
    DeviceFaultError,
    EventId,
    EventTimer,
    NotConnectedError,
    Outcome,
    Request,
    StateError,
    VirtualClock,
)
from openel_async.device import AsyncBatchCommander
from openel_async.motion import AxisFaultError, AxisGroup, AxisLimits
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


def _proven_awaited(group: AxisGroup) -> bool:
    """Whether the running motion streams through the proven awaited tick."""
    return group._fast_step is not None and group._fast_motion is group.current


async def test_a_proven_group_move_over_bus_servos_sends_the_plan_unchecked_per_value(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    """A move whose whole path lies within every servo's limits streams through the proven
    awaited tick: one batch per tick, each the plan's positions at that tick, the last the
    exact target (taken by the general path, which starts the goal check)."""
    _, actuators = await _servos(hal_components, 3)
    limits = AxisLimits(max_velocity=1.0, max_acceleration=5.0, max_jerk=50.0)
    async with (
        EventTimer(1, clock=virtual_clock) as timer,
        AxisGroup(actuators, timer=timer, limits=limits) as group,
    ):
        motion = await group.move_to([0.5, -0.25, 1.0])
        assert _proven_awaited(group)
        with anyio.fail_after(10):
            await motion
        assert group._fast_step is None  # ended on the general path
    plan = motion._plan
    sent = [values for _, values in BusServo.batches]
    assert len(sent) > 100 and sent[-1] == (0.5, -0.25, 1.0)
    times = [plan.start_ns + k * 1_000_000 for k in range(1, len(sent))]
    assert [tuple(plan.positions(t)) for t in times] == sent[:-1]


async def test_an_axis_finalized_mid_proven_awaited_move_stops_the_next_batch(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    _, actuators = await _servos(hal_components, 3)
    limits = AxisLimits(max_velocity=1.0, max_acceleration=5.0, max_jerk=50.0)
    async with (
        EventTimer(1, clock=virtual_clock) as timer,
        AxisGroup(actuators, timer=timer, limits=limits) as group,
    ):
        motion = await group.move_to([1.0, 1.0, 1.0])
        assert _proven_awaited(group)
        await virtual_clock.sleep(0.2)
        await actuators[1].finalize()
        sent = len(BusServo.batches)
        with pytest.raises(AxisFaultError) as info, anyio.fail_after(10):
            await motion
        assert info.value.axis == 1 and "Finalized" in str(info.value)
        await virtual_clock.sleep(0.05)
        assert len(BusServo.batches) == sent  # not one batch after the axis left Active


async def test_limits_narrowed_mid_proven_awaited_move_stop_the_next_batch(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    """The proof is made again when a servo's limits are set mid-move; a batch outside the
    new limits is refused value by value (AxisFaultError caused by the bank's
    BadParameterError), nothing sent."""
    servos, actuators = await _servos(hal_components, 2)
    limits = AxisLimits(max_velocity=1.0, max_acceleration=5.0, max_jerk=50.0)
    async with (
        EventTimer(1, clock=virtual_clock) as timer,
        AxisGroup(actuators, timer=timer, limits=limits) as group,
    ):
        motion = await group.move_to([1.5, 0.5])
        assert _proven_awaited(group)
        while group.commanded[0] < 0.5:
            await virtual_clock.sleep(0.01)
        for servo in servos:  # narrowed but around the path: the move goes on
            servo.limits = ActuatorLimits((-1.8, 1.8), 1.0, 1.0)
        while group.commanded[0] < 0.8:
            await virtual_clock.sleep(0.01)
        assert not motion.done()
        servos[0].limits = ActuatorLimits((-1.0, 1.0), 1.0, 1.0)  # across the path
        with pytest.raises(AxisFaultError) as info, anyio.fail_after(10):
            await motion
        cause = info.value.cause
        assert info.value.axis == 0 and isinstance(cause, BadParameterError)
        assert cause.parameter == "values[0]"
        last = BusServo.batches[-1][1]
        assert 0.9 < last[0] <= 1.0 and tuple(group.commanded) == last
        sent = len(BusServo.batches)
        await virtual_clock.sleep(0.05)
        assert len(BusServo.batches) == sent


async def test_the_awaited_stream_needs_an_awaited_batch_and_a_proof(
    hal_components: ComponentStack,
) -> None:
    servos, actuators = await _servos(hal_components, 2)
    bank = ActuatorBank(actuators)
    assert bank.position_stream([-0.5, -0.5], [0.5, 0.5]) is None  # no synchronous path
    assert bank.position_stream_awaited([-0.5, -0.5], [0.5, 2.5]) is None  # outside
    assert bank.position_stream_awaited([-0.5], [0.5]) is None  # one bound per actuator
    send = bank.position_stream_awaited([-0.5, -0.5], [0.5, 0.5])
    assert send is not None
    await send([0.25, -0.25])
    assert BusServo.batches == [(Request.POSITION, (0.25, -0.25))]
    assert bank.get_values_nowait(Request.POSITION) == (0.25, -0.25)
    await actuators[1].finalize()
    with pytest.raises(StateError):
        await send([0.3, -0.3])  # refused before anything is sent
    assert len(BusServo.batches) == 1 and servos[1].position == -0.25
