"""What docs/drivers.md promises a driver: DeviceContext, faults inside command_nowait,
recovery from an observer, and a driver bug in the completion watcher."""

from __future__ import annotations

import anyio
import pytest

from openel_async import (
    Actuator,
    ActuatorDevice,
    ComponentState,
    DeviceContext,
    DeviceFaultError,
    DeviceInfo,
    DeviceKind,
    ErrorId,
    HALComponent,
    HALId,
    Outcome,
    Request,
    VirtualClock,
)
from openel_async.testing import ComponentStack, EventRecorder
from openel_sim import SimMotor


class Keyed(ActuatorDevice):
    """Keys per-instance state on the component's HALId, as OpenEL's error 200 + instance."""

    info = DeviceInfo(DeviceKind.MOTOR, vendor_name="Acme", product_name="Keyed")
    reports_completion = True

    def __init__(self) -> None:
        self.trip_in_command = False

    async def open(self, ctx: DeviceContext) -> None:
        self.ctx = ctx
        self.error_id = 200 + ctx.hal_id.instance_id

    async def command(self, request: Request, value: float) -> None:
        self.command_nowait(request, value)

    def command_nowait(self, request: Request, value: float) -> None:
        if self.trip_in_command:
            self.ctx.fault(self.error_id, "tripped on the new command")

    async def read(self, request: Request) -> float:
        return 0.0


async def test_context_gives_the_hal_id(hal_components: ComponentStack) -> None:
    hal_id = HALId(DeviceKind.MOTOR, 0, 0, 7)
    device = Keyed()
    actuator = await hal_components.actuator(device, hal_id=hal_id)
    assert device.ctx.hal_id is actuator.hal_id is hal_id and device.error_id == 207


@pytest.mark.parametrize("nowait", [True, False])
async def test_fault_inside_command_returns_a_faulted_motion(
    hal_components: ComponentStack, virtual_clock: VirtualClock, nowait: bool
) -> None:
    """drivers.md §2: set_value does not raise; its Motion is FAULTED with last_fault."""
    device = Keyed()
    actuator = await hal_components.actuator(device)
    events = EventRecorder(virtual_clock)
    actuator.add_observer(events)
    previous = await actuator.set_value(0.5)
    device.trip_in_command = True
    motion = actuator.set_value_nowait(1.0) if nowait else await actuator.set_value(1.0)
    assert motion.outcome is Outcome.FAULTED and motion.error() is actuator.last_fault
    assert previous.outcome is Outcome.FAULTED  # failed by the fault, not superseded
    assert actuator.state is ComponentState.ERROR and actuator.motion is previous
    await events.wait_for("error", device.error_id)


async def test_an_async_observer_can_re_init_from_notify_error(
    hal_components: ComponentStack, sim_motor: SimMotor
) -> None:
    """The OpenEL sample re-initializes in notify_error: here an async observer does."""
    actuator = await hal_components.actuator(sim_motor)
    recovered = anyio.Event()

    class Recover:
        async def notify_error(self, source: HALComponent, error_id: int) -> None:
            await source.re_init()
            recovered.set()

    actuator.add_observer(Recover())
    sim_motor.inject_fault()
    assert actuator.state is ComponentState.ERROR
    with anyio.fail_after(1):
        await recovered.wait()
    assert actuator.state is ComponentState.ACTIVE and actuator.last_fault is None


async def test_a_driver_bug_in_the_watcher_faults_the_component(
    virtual_clock: VirtualClock,
) -> None:
    """drivers.md §5: not an ExceptionGroup out of ``async with``, a DEVICE_ERROR fault."""

    class Buggy(Keyed):
        reports_completion = False

        buggy = False

        async def read(self, request: Request) -> float:
            if self.buggy:
                raise ZeroDivisionError("driver bug")
            return 0.0

    device = Buggy()
    async with Actuator(device, clock=virtual_clock) as actuator:
        events = EventRecorder(virtual_clock)
        actuator.add_observer(events)
        device.buggy = True
        motion = actuator.set_value_nowait(0.5)
        with pytest.raises(DeviceFaultError, match="ZeroDivisionError") as info:
            await motion
        assert info.value.error_id == ErrorId.DEVICE_ERROR
        assert actuator.state is ComponentState.ERROR
        await events.wait_for("error", ErrorId.DEVICE_ERROR)
    assert actuator.state is ComponentState.FINALIZED


async def test_components_keep_cpython_fast_attribute_layout(
    hal_components: ComponentStack, sim_motor: SimMotor
) -> None:
    """CPython 3.11 shares instance dict keys (fast attribute reads, on every per-call path)
    only up to 29 attributes: an Actuator must stay below."""
    actuator = await hal_components.actuator(sim_motor)
    assert len(vars(actuator)) <= 29, sorted(vars(actuator))
