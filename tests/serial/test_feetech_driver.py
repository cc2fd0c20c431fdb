"""FeetechPort and FeetechServo end to end: driver -> pyserial-asyncio-fast -> pty -> simulated
STS3215s (feetech_peers), in the test's event loop; every wait bounded."""

from __future__ import annotations

import math
import time
from collections.abc import AsyncIterator, Callable
from contextlib import AsyncExitStack
from typing import Any

import anyio
import anyio.lowlevel
import pytest

from openel_async import (
    Actuator,
    ComponentState,
    ErrorId,
    EventId,
    HALError,
    MonotonicClock,
    NotImplementedHALError,
    Outcome,
    Request,
)
from openel_async.safety import ExitAction
from openel_async.testing import EventRecorder
from openel_serial import DRIVER, FeetechPort, FeetechServo, FeetechSTS3215, PortDisconnectedError
from openel_serial import feetech as ft
from openel_serial.feetech_peers import SimFeetechBus, SimStsServo

from .conftest import BAUD, WAIT_S

pytestmark = pytest.mark.timeout(30)

S = ft.STS
STEP = 2 * math.pi / 4096


async def wait_until(predicate: Callable[[], bool], timeout: float = WAIT_S) -> None:  # noqa: ASYNC109
    with anyio.fail_after(timeout):
        while not predicate():  # noqa: ASYNC110 - the peer's state has no event to wait on
            await anyio.sleep(0.002)


@pytest.fixture
async def bus() -> AsyncIterator[SimFeetechBus]:
    async with SimFeetechBus([SimStsServo(1), SimStsServo(2, position=1000)]) as sim:
        yield sim


@pytest.fixture
async def port(bus: SimFeetechBus) -> AsyncIterator[FeetechPort]:
    async with FeetechPort(
        bus.path, baudrate=BAUD, return_delay=0.0, timeout_margin=0.1, poll_period=0.005
    ) as p:
        yield p


@pytest.fixture
def recorder() -> EventRecorder:
    return EventRecorder(MonotonicClock())


async def open_servos(
    stack: AsyncExitStack, port: FeetechPort, recorder: EventRecorder, *ids: int, **kw: Any
) -> list[Actuator]:
    out = []
    for servo_id in ids:
        actuator = await stack.enter_async_context(
            Actuator(FeetechSTS3215(port, servo_id, speed=20.0, acceleration=30.0, **kw))
        )
        actuator.add_observer(recorder)
        out.append(actuator)
    return out


def test_the_driver_registers_the_feetech_devices() -> None:
    assert DRIVER.devices["feetech"] is FeetechServo
    assert DRIVER.devices["feetech_sts3215"] is FeetechSTS3215


async def test_ping_read_write_sync_read_and_write(bus: SimFeetechBus, port: FeetechPort) -> None:
    info = await port.ping(2)
    assert (info.model_number, info.error) == (777, 0)
    assert await port.read_item(2, S.PRESENT_POSITION) == 1000
    await port.write_item(1, S.GOAL_SPEED, -123)
    assert bus[1].get_raw(S.GOAL_SPEED) == -123
    await port.sync_write_item(S.P_COEFFICIENT, {1: 20, 2: 21})
    data = await port.sync_read([1, 2], S.P_COEFFICIENT.address, 1)
    assert data == {1: b"\x14", 2: b"\x15"}
    assert port.stats.retries == port.stats.timeouts == 0
    with pytest.raises(TimeoutError):
        await port.read_item(9, S.ID)  # nobody there


async def test_eeprom_writes_behind_the_lock_survive_a_power_cycle(
    bus: SimFeetechBus, port: FeetechPort
) -> None:
    # Locked (power-up state): the write takes effect but is lost at power-off.
    await port.write_item(1, S.MAX_ANGLE_LIMIT, 3000)
    assert bus[1].get_raw(S.MAX_ANGLE_LIMIT) == 3000
    bus[1].power_cycle()
    assert bus[1].get_raw(S.MAX_ANGLE_LIMIT) == 4095
    await port.write_eeprom(1, [(S.MAX_ANGLE_LIMIT, 3100), (S.HOMING_OFFSET, -20)])
    assert bus[1].locked
    bus[1].power_cycle()
    assert bus[1].get_raw(S.MAX_ANGLE_LIMIT) == 3100
    assert bus[1].get_raw(S.HOMING_OFFSET) == -20
    assert await port.read_item(1, S.PRESENT_POSITION) == 2048 + 20


async def test_two_servos_move_and_complete_with_one_sync_read_per_cycle(
    bus: SimFeetechBus, port: FeetechPort, recorder: EventRecorder
) -> None:
    async with AsyncExitStack() as stack:
        a1, a2 = await open_servos(stack, port, recorder, 1, 2)
        assert a1.device_name == "HalMotorFeetechSTS3215"
        start = len(bus.instructions)
        with anyio.fail_after(WAIT_S):
            m1 = await a1.set_value(0.5)
            m2 = await a2.set_value(-0.3)
            await m1
            await m2
        assert (m1.outcome, m2.outcome) == (Outcome.REACHED, Outcome.REACHED)
        assert await a1.get_value(Request.POSITION_ACTUAL) == pytest.approx(0.5, abs=8 * STEP)
        assert await a2.get_value(Request.POSITION_ACTUAL) == pytest.approx(-0.3, abs=8 * STEP)
        assert bus[1].get_raw(S.GOAL_POSITION) == ft.rad_to_ticks(0.5)
        assert bus[1].get_raw(S.GOAL_SPEED) == ft.rad_s_to_speed(20.0)
        assert bus[1].get_raw(S.ACCELERATION) == round(30.0 / STEP / 100)
        for _ in range(3):
            await port.poll_once()
        assert recorder.count("event", EventId.COMPLETED, source=a1) == 1
        assert recorder.errors == []
        later = bus.instructions[start:]
        polls = [m for m in later if isinstance(m, ft.SyncRead)]
        assert polls and all(p.address == 56 and p.length == 15 for p in polls)
        assert polls[-1].ids == (1, 2)
        assert not any(isinstance(m, ft.Read) and m.address == 56 for m in later)


async def test_wheel_mode_and_no_excite(
    bus: SimFeetechBus, port: FeetechPort, recorder: EventRecorder
) -> None:
    async with AsyncExitStack() as stack:
        (a1,) = await open_servos(stack, port, recorder, 1)
        with anyio.fail_after(WAIT_S):
            await (await a1.set_value(-3.0, Request.VELOCITY))
        assert bus[1].mode == ft.OperatingMode.WHEEL
        assert bus[1].get_raw(S.GOAL_SPEED) == ft.rad_s_to_speed(-3.0)
        assert bus[1].table[47] & 0x80  # sign-magnitude on the wire
        assert await a1.get_value(Request.VELOCITY_ACTUAL) == pytest.approx(-3.0, abs=0.1)
        await a1.set_value(0.0, Request.NO_EXCITE)
        assert not bus[1].torque_enabled
        with anyio.fail_after(WAIT_S):
            await (await a1.set_value(0.2))  # back to position mode, torque on
        assert bus[1].mode == ft.OperatingMode.POSITION and bus[1].torque_enabled
        with pytest.raises(NotImplementedHALError):
            await a1.get_value(Request.TORQUE_ACTUAL)  # no stall_torque given


async def test_torque_actual_from_present_load(bus: SimFeetechBus, port: FeetechPort) -> None:
    async with Actuator(FeetechSTS3215(port, 1, stall_torque=1.91)) as a1:
        bus[1].external_load = -250  # the arm pulls on the joint
        await port.poll_once()
        assert await a1.get_value(Request.TORQUE_ACTUAL) == pytest.approx(-0.25 * 1.91, abs=0.01)


async def test_the_gripper_speaks_its_opening(bus: SimFeetechBus, port: FeetechPort) -> None:
    span = (-0.95993, 0.95993)
    async with Actuator(FeetechSTS3215(port, 1, gripper=True, position_limits=span)) as grip:
        assert grip.device.limits.position == (0.0, 1.0)
        assert await grip.get_value(Request.POSITION_ACTUAL) == pytest.approx(0.5, abs=1e-3)
        with anyio.fail_after(WAIT_S):
            await (await grip.set_value(1.0))
        assert bus[1].get_raw(S.GOAL_POSITION) == ft.rad_to_ticks(span[1])
        assert await grip.get_value(Request.POSITION_ACTUAL) == pytest.approx(1.0, abs=0.01)


async def test_angle_limits_of_the_servo_are_the_component_limits(
    bus: SimFeetechBus, port: FeetechPort
) -> None:
    await port.write_eeprom(1, [(S.MIN_ANGLE_LIMIT, 1024), (S.MAX_ANGLE_LIMIT, 3072)])
    async with Actuator(FeetechSTS3215(port, 1)) as a1:
        assert a1.device.limits.position == pytest.approx((-math.pi / 2, math.pi / 2))


@pytest.mark.parametrize(
    ("reason", "bit"),
    [("over-temperature", ft.StatusError.OVERHEAT), ("overload", ft.StatusError.OVERLOAD)],
)
async def test_an_unloading_alarm_faults_the_component(
    bus: SimFeetechBus,
    port: FeetechPort,
    recorder: EventRecorder,
    reason: str,
    bit: ft.StatusError,
) -> None:
    async with AsyncExitStack() as stack:
        a1, a2 = await open_servos(stack, port, recorder, 1, 2)
        bus[1].inject_fault(reason)
        await recorder.wait_for("error", ErrorId.DEVICE_ERROR, source=a1, timeout=WAIT_S)
        assert a1.state is ComponentState.ERROR and a2.state is ComponentState.ACTIVE
        assert bit.name in str(a1.last_fault)
        assert not bus[1].torque_enabled  # the servo unloaded itself
        if bit is ft.StatusError.OVERHEAT:
            with pytest.raises(HALError, match="still in force"):
                await a1.re_init()  # too hot still
        bus[1].clear_faults()
        await a1.re_init()
        assert a1.state is ComponentState.ACTIVE and bus[1].torque_enabled


async def test_a_voltage_alarm_is_posted_not_faulted(
    bus: SimFeetechBus, port: FeetechPort, recorder: EventRecorder
) -> None:
    async with AsyncExitStack() as stack:
        (a1,) = await open_servos(stack, port, recorder, 1)
        bus[1].inject_fault("undervoltage")
        await recorder.wait_for("error", ErrorId.DEVICE_ERROR, source=a1, timeout=WAIT_S)
        assert a1.state is ComponentState.ACTIVE  # the torque stays on (not in 19)
        assert bus[1].torque_enabled
        assert port.stats.alarms > 0


async def test_a_silent_servo_times_out_and_re_init_recovers(
    bus: SimFeetechBus, port: FeetechPort, recorder: EventRecorder
) -> None:
    async with AsyncExitStack() as stack:
        a1, a2 = await open_servos(stack, port, recorder, 1, 2)
        bus[2].responsive = False  # unplugged from the chain
        await recorder.wait_for("error", ErrorId.TIMEOUT, source=a2, timeout=WAIT_S)
        assert a1.state is ComponentState.ACTIVE
        bus[2].responsive = True
        await a2.re_init()
        assert a2.state is ComponentState.ACTIVE


async def test_damaged_replies_and_garbage_are_survived(
    bus: SimFeetechBus, port: FeetechPort
) -> None:
    bus.inject_garbage()  # FF FF FF 13 AA: a false header promising 170 bytes
    assert await port.read_item(2, S.PRESENT_POSITION) == 1000
    retries = port.stats.retries
    assert retries <= 1
    bus.corrupt_replies = 1
    bus.drop_replies = 1
    assert await port.read_item(2, S.PRESENT_POSITION) == 1000
    assert port.stats.retries == retries + 2
    assert port.parser.checksum_errors >= 1


async def test_the_port_vanishing_faults_every_servo(
    bus: SimFeetechBus, port: FeetechPort, recorder: EventRecorder
) -> None:
    async with AsyncExitStack() as stack:
        actuators = await open_servos(stack, port, recorder, 1, 2)
        bus.unplug()
        for actuator in actuators:
            await recorder.wait_for("error", ErrorId.DISCONNECTED, source=actuator, timeout=WAIT_S)
        with pytest.raises(PortDisconnectedError):
            await port.ping(1)
        bus.plug()
        for actuator in actuators:
            await actuator.re_init()
            assert actuator.state is ComponentState.ACTIVE


async def test_estop_broadcasts_torque_off_and_re_init_recovers(
    bus: SimFeetechBus, port: FeetechPort, recorder: EventRecorder
) -> None:
    async with AsyncExitStack() as stack:
        actuators = await open_servos(stack, port, recorder, 1, 2)
        for actuator in actuators:
            await actuator.set_value(2.0, Request.VELOCITY)
        await port.estop()
        for actuator in actuators:
            await recorder.wait_for("error", ErrorId.ESTOP, source=actuator, timeout=WAIT_S)
        await port.ping(1)  # handled in order: the broadcast came first
        assert not any(s.torque_enabled for s in bus.servos)
        assert ft.Write(ft.BROADCAST_ID, 40, b"\x00") in bus.instructions
        for actuator in actuators:
            await actuator.re_init()
        assert all(s.torque_enabled for s in bus.servos)


async def test_a_command_on_its_way_when_the_e_stop_comes_leaves_the_torque_off(
    bus: SimFeetechBus, port: FeetechPort, recorder: EventRecorder
) -> None:
    async with AsyncExitStack() as stack:
        (actuator,) = await open_servos(stack, port, recorder, 1)
        servo = actuator.device
        assert isinstance(servo, FeetechServo)
        await servo.command(Request.NO_EXCITE, 0.0)  # torque off: the next command turns it on
        refused: list[Exception] = []

        async def command() -> None:
            try:
                await servo.command(Request.POSITION, 0.5)
            except HALError as exc:
                refused.append(exc)

        async with anyio.create_task_group() as tg:
            tg.start_soon(command)
            await anyio.lowlevel.checkpoint()  # the command's first write is on its way
            await servo.estop()
        assert refused and "e-stopped" in str(refused[0])
        await port.ping(1)  # every packet sent is handled
        assert not bus.servos[0].torque_enabled
        await actuator.re_init()
        assert bus.servos[0].torque_enabled


async def test_the_host_watchdog_turns_the_torque_off_while_the_loop_is_stalled(
    recorder: EventRecorder,
) -> None:
    """The servos are on their own thread (as real ones are); the test's loop blocks for
    longer than the timeout: the port's watchdog thread sends the torque-off meanwhile."""
    from openel_serial.ptypeer import PeerThread

    sim = SimFeetechBus([SimStsServo(1), SimStsServo(2)])
    async with (
        PeerThread(sim) as peer,
        FeetechPort(
            sim.path, baudrate=BAUD, return_delay=0.0, timeout_margin=0.1, poll_period=0.005
        ) as port,
        AsyncExitStack() as stack,
    ):
        actuators = await open_servos(stack, port, recorder, 1, 2)
        for actuator in actuators:
            await actuator.device.arm_watchdog(0.1)  # type: ignore[attr-defined]
            await actuator.set_value(2.0, Request.VELOCITY)
        with pytest.raises(Exception, match="timeout_s"):
            await actuators[0].device.arm_watchdog(0.005)  # type: ignore[attr-defined]
        time.sleep(0.4)  # the event loop stalls (no poll, no feed)  # noqa: ASYNC251
        assert not await peer.call(lambda: any(s.torque_enabled for s in sim.servos))
        for actuator in actuators:
            await recorder.wait_for("error", ErrorId.WATCHDOG, source=actuator, timeout=WAIT_S)
        assert port.stats.watchdog_trips == 1
        for actuator in actuators:
            await actuator.re_init()
            assert actuator.state is ComponentState.ACTIVE
        assert await peer.call(lambda: all(s.torque_enabled for s in sim.servos))
        await anyio.sleep(0.3)  # the loop runs: no trip
        assert port.stats.watchdog_trips == 1


@pytest.mark.parametrize("action", list(ExitAction))
async def test_safe_stop(bus: SimFeetechBus, port: FeetechPort, action: ExitAction) -> None:
    async with Actuator(FeetechSTS3215(port, 1)) as a1:
        await a1.set_value(2.0, Request.VELOCITY)
        await wait_until(lambda: abs(bus[1].rotor()[1]) > 100)
        device = a1.device
        assert isinstance(device, FeetechServo)
        await device.safe_stop(action)
        if action is ExitAction.TORQUE_OFF:
            assert not bus[1].torque_enabled
        elif action is ExitAction.STOP:
            assert bus[1].get_raw(S.GOAL_SPEED) == 0 and bus[1].torque_enabled
        else:
            assert bus[1].mode == ft.OperatingMode.POSITION and bus[1].torque_enabled
