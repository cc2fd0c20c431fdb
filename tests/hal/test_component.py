"""The HALComponent state machine (OpenEL Fig. 7.4), observers, profile and time."""

from __future__ import annotations

import anyio
import pytest

from openel_async import (
    Actuator,
    BadParameterError,
    ComponentState,
    ErrorId,
    HALError,
    HALId,
    ObserverQueue,
    ReturnCode,
    Sensor,
    StateError,
    VirtualClock,
)
from openel_async.errors import NotConnectedError
from openel_async.observers import ErrorNotice
from openel_async.testing import ComponentStack
from openel_sim import SimMotor, SimTemperature

S = ComponentState


async def test_lifecycle_states_in_order(virtual_clock: VirtualClock) -> None:
    motor = Actuator(SimMotor(), clock=virtual_clock, auto_init=False)
    assert motor.state is S.INITIALIZING
    with pytest.raises(StateError, match="Initializing"):
        await motor.init()
    async with motor:
        assert motor.state is S.INITIALIZED
        await motor.init()
        assert motor.state is S.ACTIVE
        await motor.finalize()
        assert motor.state is S.FINALIZED
    assert motor.state is S.FINALIZED


async def test_context_manager_inits_and_finalizes(virtual_clock: VirtualClock) -> None:
    async with Actuator(SimMotor(), clock=virtual_clock) as motor:
        assert motor.state is S.ACTIVE
    assert motor.state is S.FINALIZED


async def _call(component: Actuator, operation: str) -> None:
    calls = {
        "init": component.init,
        "re_init": component.re_init,
        "finalize": component.finalize,
        "set_value": lambda: component.set_value(0.1),
        "get_value": component.get_value,
    }
    if operation in calls:
        await calls[operation]()
        return
    queue = ObserverQueue()
    sync_calls = {
        "add_observer": lambda: component.add_observer(queue),
        "remove_observer": lambda: component.remove_observer(queue),
        "get_profile": component.get_profile,
        "get_time": component.get_time,
    }
    sync_calls[operation]()


# operation -> states where it is callable (the spec's Fig. 7.4 text).
ALLOWED = {
    "init": {S.INITIALIZED},
    "re_init": {S.ERROR},
    "finalize": {S.ACTIVE, S.ERROR},
    "set_value": {S.ACTIVE},
    "get_value": {S.ACTIVE},
    "add_observer": {S.ACTIVE},
    "remove_observer": {S.ACTIVE},
    "get_profile": {S.ACTIVE},
    "get_time": {S.ACTIVE},
}


async def _in_state(stack: ComponentStack, state: ComponentState) -> tuple[Actuator, SimMotor]:
    device = SimMotor()
    component = await stack.actuator(device, auto_init=state is not S.INITIALIZED)
    if state is S.ERROR:
        device.inject_fault()
    elif state is S.FINALIZED:
        await component.finalize()
    assert component.state is state
    return component, device


@pytest.mark.parametrize("operation", sorted(ALLOWED))
@pytest.mark.parametrize("state", [S.INITIALIZED, S.ACTIVE, S.ERROR, S.FINALIZED])
async def test_every_operation_checks_the_state(
    hal_components: ComponentStack, operation: str, state: ComponentState
) -> None:
    component, _ = await _in_state(hal_components, state)
    if state in ALLOWED[operation]:
        if operation == "remove_observer":
            with pytest.raises(BadParameterError):  # allowed, but nothing registered
                await _call(component, operation)
        else:
            await _call(component, operation)
        return
    with pytest.raises(StateError) as info:
        await _call(component, operation)
    message = str(info.value)
    assert operation in message and str(state) in message
    for allowed in ALLOWED[operation]:
        assert str(allowed) in message
    assert info.value.code is ReturnCode.HAL_ERROR
    assert component.state is state


async def test_double_init_and_double_finalize(hal_components: ComponentStack) -> None:
    motor = await hal_components.actuator(SimMotor())
    with pytest.raises(StateError, match=r"init\(\) is not callable in state Active"):
        await motor.init()
    await motor.finalize()
    with pytest.raises(StateError, match=r"finalize\(\) is not callable in state Finalized"):
        await motor.finalize()


async def test_fault_moves_to_error_notifies_and_re_init_recovers(
    hal_components: ComponentStack,
) -> None:
    device = SimMotor()
    motor = await hal_components.actuator(device)
    errors = ObserverQueue()
    motor.add_observer(errors)
    device.inject_fault(error_id=42, reason="overcurrent")
    assert motor.state is S.ERROR
    notice = await errors.get()
    assert isinstance(notice, ErrorNotice)
    assert (notice.source, notice.error_id) == (motor, 42)
    assert motor.last_fault is not None and motor.last_fault.error_id == 42
    await motor.re_init()
    assert motor.state is S.ACTIVE
    assert motor.last_fault is None
    await (await motor.set_value(0.2))


async def test_disconnect_keeps_error_until_reconnected(hal_components: ComponentStack) -> None:
    device = SimMotor()
    motor = await hal_components.actuator(device)
    errors = ObserverQueue()
    motor.add_observer(errors)
    device.disconnect()
    assert motor.state is S.ERROR
    assert (await errors.get()).error_id == ErrorId.DISCONNECTED  # type: ignore[union-attr]
    with pytest.raises(NotConnectedError):
        await motor.re_init()
    assert motor.state is S.ERROR
    device.reconnect()
    await motor.re_init()
    assert motor.state is S.ACTIVE


async def test_link_failure_during_a_call_faults_the_component(
    hal_components: ComponentStack,
) -> None:
    device = SimMotor()
    motor = await hal_components.actuator(device)
    errors = ObserverQueue()
    motor.add_observer(errors)
    device.connected = False  # the link is gone but nothing noticed yet
    with pytest.raises(HALError) as info:
        await motor.get_value()
    assert info.value.code is ReturnCode.HAL_NO_CONNECTED
    assert motor.state is S.ERROR
    assert len(errors) == 1


async def test_profile_time_and_default_identity(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    motor = await hal_components.actuator(SimMotor(), hal_id=HALId(1, 2, 3, 4), device_name="M")
    profile = motor.get_profile()
    assert profile.id == HALId(1, 2, 3, 4)
    assert profile.device_name == "M"
    assert "inject_fault" in profile.function_list
    await virtual_clock.sleep(1.5)
    assert motor.get_time() == virtual_clock.now_ns() == 1_500_000_000
    default = await hal_components.actuator(SimMotor())
    assert default.device_name == "HalMotorOpenELSimMotor"
    assert default.hal_id.device_kind_id == 1


async def test_component_without_time_raises_hal_error(hal_components: ComponentStack) -> None:
    device = SimTemperature()
    device.has_time = False
    sensor = await hal_components.sensor(device)
    with pytest.raises(HALError) as info:
        sensor.get_time()
    assert info.value.code is ReturnCode.HAL_ERROR
    with pytest.raises(HALError):
        await sensor.get_timed_value()
    assert len(await sensor.get_value()) == 1


async def test_duplicate_and_unknown_observers(hal_components: ComponentStack) -> None:
    motor = await hal_components.actuator(SimMotor())
    queue = ObserverQueue()
    motor.add_observer(queue)
    with pytest.raises(BadParameterError, match="not yet registered"):
        motor.add_observer(queue)
    motor.remove_observer(queue)
    with pytest.raises(BadParameterError, match="registered"):
        motor.remove_observer(queue)
    with pytest.raises(BadParameterError, match="notify_event"):
        motor.add_observer(object())
    assert motor.observers == ()


async def test_async_observer_and_raising_observer_are_isolated(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> None:
    device = SimMotor()
    motor = await hal_components.actuator(device)
    seen: list[tuple[str, int]] = []

    class Broken:
        def notify_event(self, source: object, event_id: int) -> None:
            raise RuntimeError("observer bug")

        def notify_error(self, source: object, error_id: int) -> None:
            raise RuntimeError("observer bug")

    class Slow:
        async def notify_event(self, source: object, event_id: int) -> None:
            await virtual_clock.sleep(10)
            seen.append(("event", event_id))

        async def notify_error(self, source: object, error_id: int) -> None:
            seen.append(("error", error_id))

    fast = ObserverQueue()
    motor.add_observer(Broken())
    motor.add_observer(Slow())
    motor.add_observer(fast)
    motion = await motor.set_value(0.5)
    await motion
    reached = virtual_clock.now_ns()
    assert (await fast.get()).event_id == 1  # type: ignore[union-attr]
    assert virtual_clock.now_ns() == reached  # the slow observer did not hold anyone up
    device.inject_fault(error_id=3)
    with anyio.fail_after(5):
        while len(seen) < 2:
            await virtual_clock.sleep(1)
    assert seen == [("event", 1), ("error", 3)]  # order kept per observer


async def test_sensor_and_actuator_share_the_state_machine(hal_components: ComponentStack) -> None:
    device = SimTemperature()
    sensor = await hal_components.sensor(device)
    assert isinstance(sensor, Sensor)
    device.disconnect()
    with pytest.raises(HALError):
        await sensor.get_value()
    assert sensor.state is S.ERROR
    device.reconnect()
    await sensor.re_init()
    assert sensor.state is S.ACTIVE


async def test_a_component_never_entered_says_so_and_how_to_fix_it(
    virtual_clock: VirtualClock,
) -> None:
    motor = Actuator(SimMotor(), clock=virtual_clock)
    with pytest.raises(StateError, match="never entered: use `async with component:`") as info:
        await motor.set_value(1.0)
    assert info.value.code is ReturnCode.HAL_ERROR
    assert "not callable in state Initializing; allowed in: Active" in str(info.value)
    with pytest.raises(StateError, match="never entered"):
        await Sensor(SimTemperature(SimMotor()), clock=virtual_clock).get_value()
    async with Actuator(SimMotor(), clock=virtual_clock, auto_init=False) as idle:
        with pytest.raises(StateError, match=r"never initialized: `await component.init\(\)`"):
            await idle.get_value()
    with pytest.raises(StateError) as finalized:
        await idle.get_value()
    assert "never" not in str(finalized.value)  # Finalized: entered and left
