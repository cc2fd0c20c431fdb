"""Dynamixel safety: Bus Watchdog (98), e-stop (torque off) and safe stop, on ptys.

The stall test hosts the simulated bus on a thread of its own (:class:`PeerThread`, real
clock), so the servos keep their own time while the application's event loop is blocked
by ``time.sleep``, as real servos do. The other tests give the simulated servos a
:class:`VirtualClock` where the servos' time must be controlled (a Bus Watchdog expiring
exactly when the test says, whatever the machine's load).
"""

from __future__ import annotations

import math
import signal
import subprocess
import sys
import threading
import time
from contextlib import AsyncExitStack

import anyio
import anyio.lowlevel
import dynamixel_sdk as sdk
import pytest

from openel_async import (
    Actuator,
    BadParameterError,
    ComponentState,
    ErrorId,
    HALError,
    NotImplementedHALError,
    Request,
    VirtualClock,
)
from openel_async.safety import EmergencyStop, ExitAction, Watchdog
from openel_async.testing import EventRecorder
from openel_serial import DynamixelPort, DynamixelServo, DynamixelStatusError
from openel_serial import dynamixel as dx
from openel_serial.peers import PeerThread, SimDynamixelBus, SimServo

from .conftest import BAUD, WAIT_S, actuators, in_thread, make_servo

pytestmark = pytest.mark.timeout(30)

X = dx.XSeries
TIMEOUT_S = 0.1
"""The Bus Watchdog timeout of these tests: 5 units of 20 ms."""
NS = 1_000_000_000


def servo_of(actuator: Actuator) -> DynamixelServo:
    device = actuator.device
    assert isinstance(device, DynamixelServo)
    return device


def virtual_bus(clock: VirtualClock, *ids: int) -> SimDynamixelBus:
    return SimDynamixelBus([make_servo(i, clock=clock) for i in ids], clock=clock)


async def run_servo_time(clock: VirtualClock, port: DynamixelPort, seconds: float) -> None:
    """Let ``seconds`` of the servos' virtual time pass in 10 ms steps, each followed by a
    poll (so the Bus Watchdog is fed on time and completions are seen)."""
    for _ in range(round(seconds / 0.01)):
        await clock.advance(10_000_000)
        with anyio.fail_after(WAIT_S):
            await port.poll_once()


def open_port(bus: SimDynamixelBus, poll_period: float = 0.005) -> DynamixelPort:
    return DynamixelPort(
        bus.path, baudrate=BAUD, return_delay=0.0, timeout_margin=0.1, poll_period=poll_period
    )


# -- configuration ---------------------------------------------------------------------------


def test_the_servo_offers_the_safety_protocols() -> None:
    assert issubclass(DynamixelServo, Watchdog)
    assert issubclass(DynamixelServo, EmergencyStop)


async def test_timeouts_the_register_cannot_express_are_refused(
    bus: SimDynamixelBus, port: DynamixelPort, recorder: EventRecorder
) -> None:
    async with AsyncExitStack() as stack:
        (a1,) = await actuators(stack, port, recorder, 1)
        servo = servo_of(a1)
        for bad in (0, -0.1, 0.01, 0.05, 0.11, 2.56, 10.0, math.nan, math.inf, True, "0.1"):
            with pytest.raises(BadParameterError, match=r"timeout_s.*0\.02\.\.2\.54 s"):
                await servo.arm_watchdog(bad)  # type: ignore[arg-type]
        assert bus[1].get_raw(X.BUS_WATCHDOG) == 0 and servo.watchdog_timeout is None
        assert port.bus_watchdogs == {}
        await servo.arm_watchdog(0.02)  # the shortest: one unit (polls every 5 ms)
        await servo.arm_watchdog(2.54)  # the longest: 127 units
        assert bus[1].get_raw(X.BUS_WATCHDOG) == 127 and servo.watchdog_timeout == 2.54


async def test_a_poll_period_that_cannot_feed_in_time_is_refused(
    bus: SimDynamixelBus, recorder: EventRecorder
) -> None:
    async with open_port(bus, poll_period=0.05) as port, AsyncExitStack() as stack:
        (a1,) = await actuators(stack, port, recorder, 1)
        with pytest.raises(BadParameterError, match=r"timeout_s.*twice the poll_period.*0\.05"):
            await servo_of(a1).arm_watchdog(TIMEOUT_S)  # 0.05 is not below 0.1 / 2
        assert bus[1].get_raw(X.BUS_WATCHDOG) == 0 and port.bus_watchdogs == {}
        await servo_of(a1).arm_watchdog(0.12)
        assert bus[1].get_raw(X.BUS_WATCHDOG) == 6


async def test_firmware_without_a_bus_watchdog_is_refused(recorder: EventRecorder) -> None:
    bus = SimDynamixelBus([make_servo(1, firmware_version=37)])
    bus[1].table[X.BUS_WATCHDOG.address] = 0x07  # not an item on this firmware: left alone
    async with bus, open_port(bus) as port, AsyncExitStack() as stack:
        (a1,) = await actuators(stack, port, recorder, 1)
        assert bus[1].table[X.BUS_WATCHDOG.address] == 0x07
        with pytest.raises(NotImplementedHALError, match="firmware v37"):
            await servo_of(a1).arm_watchdog(TIMEOUT_S)


# -- the simulated servo's Bus Watchdog --------------------------------------------------------


async def test_simulated_servo_stops_by_itself_and_refuses_goals_until_cleared() -> None:
    clock = VirtualClock()
    servo = SimServo(1, clock=clock, profile_velocity=0, profile_acceleration=0)

    def write(item: dx.ControlItem, value: int) -> int:
        status = servo.handle(item.write(1, value))
        assert status is not None
        return status.error

    assert write(X.OPERATING_MODE, dx.OperatingMode.VELOCITY) == 0
    assert write(X.TORQUE_ENABLE, 1) == 0
    assert write(X.GOAL_VELOCITY, 100) == 0
    assert write(X.BUS_WATCHDOG, 5) == 0  # 100 ms
    await clock.advance(90_000_000)  # 90 ms: not yet (no instruction since the arm)
    assert servo.handle(X.PRESENT_POSITION.read(1)) is not None  # feeds it
    fed_at = clock.now_ns()
    await clock.advance(90_000_000)
    assert not servo.watchdog_tripped and servo.state()[1] > 0
    await clock.advance(150_000_000)  # silence: expires 100 ms after the last instruction
    p, v = servo.state()
    assert servo.watchdog_tripped and v == 0.0
    assert servo.watchdog_tripped_ns == fed_at + 100_000_000
    assert servo.table[X.BUS_WATCHDOG.address] == 0xFF and servo.get(X.BUS_WATCHDOG) == -1
    assert servo.torque_enabled  # it stops and holds; the torque stays on
    await clock.advance(500_000_000)
    assert servo.state() == (p, 0.0)  # no motion
    assert write(X.GOAL_VELOCITY, 150) == dx.ErrorNumber.DATA_RANGE_ERROR
    assert write(X.GOAL_POSITION, 100) == dx.ErrorNumber.DATA_RANGE_ERROR
    assert write(X.BUS_WATCHDOG, 5) == dx.ErrorNumber.DATA_RANGE_ERROR  # only 0 clears it
    assert write(X.PROFILE_ACCELERATION, 10) == 0  # other items stay writable...
    assert servo.state() == (p, 0.0)  # ...without restarting the motion
    assert write(X.BUS_WATCHDOG, 0) == 0
    assert write(X.GOAL_VELOCITY, 150) == 0
    await clock.advance(100_000_000)
    assert servo.state()[1] > 0 and servo.watchdog_trips == 1
    status = servo.handle(dx.Write(1, X.BUS_WATCHDOG.address, bytes([128])))
    assert status is not None and status.error == dx.ErrorNumber.DATA_RANGE_ERROR


async def test_simulated_servo_with_the_torque_off_is_not_watched() -> None:
    clock = VirtualClock()
    servo = SimServo(1, clock=clock)
    assert servo.handle(X.BUS_WATCHDOG.write(1, 1)) is not None
    await clock.advance(NS)
    assert not servo.watchdog_tripped


# -- the stall ----------------------------------------------------------------------------------


async def test_a_stalled_event_loop_lets_every_servo_stop_by_itself(
    recorder: EventRecorder,
) -> None:
    """Block the loop for 3x the timeout: the servos (on their own thread and clock) stop
    by themselves; each component reports ErrorId.WATCHDOG when the loop resumes;
    re_init clears the Bus Watchdog Error and arms it again."""
    bus = SimDynamixelBus([make_servo(1), make_servo(2)])
    async with PeerThread(bus) as host, open_port(bus) as port, AsyncExitStack() as stack:
        assert host.thread is not None and host.thread is not threading.current_thread()
        a1, a2 = await actuators(stack, port, recorder, 1, 2)
        for actuator in (a1, a2):
            await servo_of(actuator).arm_watchdog(TIMEOUT_S)
            # A constant velocity: the servo would turn for ever if nothing stopped it.
            await (await actuator.set_value(2.0, Request.VELOCITY))
        assert await host.call(lambda: [bus[i].get_raw(X.BUS_WATCHDOG) for i in (1, 2)]) == [5, 5]
        assert all(v > 0 for _, v in await host.call(lambda: [bus[i].state() for i in (1, 2)]))

        stall_start = time.monotonic_ns()
        time.sleep(3 * TIMEOUT_S)  # noqa: ASYNC251 - the point: the event loop is blocked
        stall_end = time.monotonic_ns()

        for actuator in (a1, a2):
            await recorder.wait_for("error", ErrorId.WATCHDOG, source=actuator, timeout=WAIT_S)
            assert actuator.state is ComponentState.ERROR
            assert actuator.last_fault is not None
            assert "Bus Watchdog expired" in str(actuator.last_fault)

        def observe() -> list[tuple[int | None, int, float, float]]:
            return [
                (
                    bus[i].watchdog_tripped_ns,
                    bus[i].table[X.BUS_WATCHDOG.address],
                    *bus[i].state(),
                )
                for i in (1, 2)
            ]

        first = await host.call(observe)
        await anyio.sleep(0.05)
        second = await host.call(observe)
        for (tripped_ns, register, position, velocity), later in zip(first, second, strict=True):
            # Stopped during the stall, by itself, one timeout after the last poll.
            assert tripped_ns is not None
            # (+20 ms: the last poll before the stall may reach the peer's thread late)
            assert stall_start < tripped_ns <= stall_start + round((TIMEOUT_S + 0.02) * NS)
            assert tripped_ns < stall_end
            assert register == 0xFF and velocity == 0.0
            assert later[2:] == (position, 0.0)  # no motion since
        assert recorder.count("error", ErrorId.WATCHDOG) == 2

        for actuator in (a1, a2):
            await actuator.re_init()
            assert actuator.state is ComponentState.ACTIVE
        registers = await host.call(lambda: [bus[i].table[X.BUS_WATCHDOG.address] for i in (1, 2)])
        assert registers == [5, 5]  # cleared (0) and armed again
        with anyio.fail_after(WAIT_S):
            await (await a1.set_value(0.3))
            await (await a2.set_value(-0.3))
        assert recorder.count("error", ErrorId.WATCHDOG) == 2


async def test_normal_polling_never_trips(
    bus: SimDynamixelBus, port: DynamixelPort, recorder: EventRecorder
) -> None:
    # A real-time test: the timeout leaves room for a scheduling hiccup of a loaded machine
    # (0.1 s tripped once under load), the run lasts five of them.
    timeout = 0.3
    async with AsyncExitStack() as stack:
        a1, a2 = await actuators(stack, port, recorder, 1, 2)
        for actuator in (a1, a2):
            await servo_of(actuator).arm_watchdog(timeout)
        cycles = port.stats.poll_cycles
        end = time.monotonic() + 5 * timeout
        target = 0.3
        while time.monotonic() < end:  # moves back and forth for 5x the timeout
            with anyio.fail_after(WAIT_S):
                await (await a1.set_value(target))
                await (await a2.set_value(-target))
            target = -target
        assert port.stats.poll_cycles - cycles >= 5 * timeout / 0.005 / 4
        assert recorder.count("error") == 0
        assert (bus[1].watchdog_trips, bus[2].watchdog_trips) == (0, 0)
        assert (servo_of(a1).watchdog_trips, servo_of(a2).watchdog_trips) == (0, 0)
        assert a1.state is ComponentState.ACTIVE and a2.state is ComponentState.ACTIVE


async def test_a_refused_goal_reveals_the_trip(recorder: EventRecorder) -> None:
    """The servo's clock passes the timeout while the host polls on time (its time is
    virtual here): the next goal is refused with Data Range Error, which the driver
    recognises as the Bus Watchdog's."""
    clock = VirtualClock()
    async with virtual_bus(clock, 1) as bus, open_port(bus) as port, AsyncExitStack() as stack:
        (a1,) = await actuators(stack, port, recorder, 1)
        await servo_of(a1).arm_watchdog(TIMEOUT_S)
        await clock.advance(round(2 * TIMEOUT_S * NS))
        with pytest.raises(DynamixelStatusError, match="DATA_RANGE_ERROR"):
            await a1.set_value(0.4)
        await recorder.wait_for("error", ErrorId.WATCHDOG, source=a1, timeout=WAIT_S)
        assert a1.state is ComponentState.ERROR and bus[1].watchdog_tripped
        await a1.re_init()
        assert bus[1].get_raw(X.BUS_WATCHDOG) == 5
        motion = await a1.set_value(0.4)
        await run_servo_time(clock, port, 0.3)
        assert motion.done() and not bus[1].watchdog_tripped


async def test_init_clears_a_bus_watchdog_error_left_by_an_earlier_run(
    recorder: EventRecorder,
) -> None:
    clock = VirtualClock()
    async with virtual_bus(clock, 1) as bus:
        servo = bus[1]
        servo.handle(X.TORQUE_ENABLE.write(1, 1))
        servo.handle(X.BUS_WATCHDOG.write(1, 5))  # armed by a process that was killed
        await clock.advance(NS)
        assert servo.watchdog_tripped
        async with open_port(bus) as port, AsyncExitStack() as stack:
            (a1,) = await actuators(stack, port, recorder, 1)
            assert a1.state is ComponentState.ACTIVE
            assert servo.get_raw(X.BUS_WATCHDOG) == 0  # cleared: goals accepted again
            motion = await a1.set_value(0.2)
            await run_servo_time(clock, port, 0.3)
            assert motion.done()


CHILD = """
import sys

import anyio

from openel_async import Actuator, Request
from openel_serial import DynamixelPort, DynamixelServo


async def main() -> None:
    port = DynamixelPort(
        sys.argv[1], baudrate=1_000_000, return_delay=0.0, timeout_margin=0.1, poll_period=0.005
    )
    async with (
        port,
        Actuator(DynamixelServo(port, 1)) as a1,
        Actuator(DynamixelServo(port, 2)) as a2,
    ):
        for actuator, speed in ((a1, 2.0), (a2, -2.0)):
            await actuator.device.arm_watchdog(0.1)
            await (await actuator.set_value(speed, Request.VELOCITY))
        sys.stderr.write("READY\\n")
        sys.stderr.flush()
        await anyio.sleep_forever()


anyio.run(main)
"""


async def test_kill_9_of_the_app_stops_every_servo_within_the_timeout() -> None:
    """The app (a child process) arms the Bus Watchdogs and turns both servos; kill -9:
    every servo stops by itself within the timeout, with nobody left to tell it."""
    bus = SimDynamixelBus([make_servo(1), make_servo(2)])
    async with PeerThread(bus) as host:
        async with await anyio.open_process(
            [sys.executable, "-c", CHILD, bus.path],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
        ) as child:
            assert child.stderr is not None
            output = b""
            with anyio.fail_after(20):
                while b"READY\n" not in output:
                    output += await child.stderr.receive()
            moving = await host.call(lambda: [bus[i].state()[1] for i in (1, 2)])
            assert all(v != 0 for v in moving)
            killed_ns = time.monotonic_ns()
            child.send_signal(signal.SIGKILL)
            with anyio.fail_after(WAIT_S):
                assert await child.wait() == -signal.SIGKILL
        # Let the timeout pass on the servos' (real) clock; no instruction reaches them.
        deadline_ns = killed_ns + round((TIMEOUT_S + 0.02) * NS)
        await anyio.sleep((deadline_ns - time.monotonic_ns()) / NS + 0.01)

        def look() -> list[tuple[bool, int | None, float, bool]]:
            return [
                (s.watchdog_tripped, s.watchdog_tripped_ns, s.state()[1], s.torque_enabled)
                for s in (bus[1], bus[2])
            ]

        for tripped, tripped_ns, velocity, torque in await host.call(look):
            assert tripped and tripped_ns is not None
            # Within the timeout of the kill (+20 ms: a poll in flight when it was killed).
            assert tripped_ns <= deadline_ns
            assert velocity == 0.0 and torque  # stopped, holding


# -- dynamixel-sdk reads what we armed -----------------------------------------------------------


async def test_dynamixel_sdk_reads_the_bus_watchdog_we_armed(recorder: EventRecorder) -> None:
    clock = VirtualClock()
    async with virtual_bus(clock, 1) as bus:
        async with open_port(bus) as port, AsyncExitStack() as stack:
            (a1,) = await actuators(stack, port, recorder, 1)
            await servo_of(a1).arm_watchdog(TIMEOUT_S)
        # Our port is closed: the SDK takes the bus over.
        handler = sdk.PortHandler(bus.path)
        packets = sdk.PacketHandler(2.0)
        assert await in_thread(handler.openPort)
        try:
            assert await in_thread(lambda: handler.setBaudRate(BAUD))
            value, result, error = await in_thread(
                lambda: packets.read1ByteTxRx(handler, 1, X.BUS_WATCHDOG.address)
            )
            assert (value, result, error) == (5, sdk.COMM_SUCCESS, 0)  # 5 x 20 ms
            await clock.advance(round(2 * TIMEOUT_S * NS))  # the servo's time: silence
            value, result, error = await in_thread(
                lambda: packets.read1ByteTxRx(handler, 1, X.BUS_WATCHDOG.address)
            )
            assert (value, result, error) == (0xFF, sdk.COMM_SUCCESS, 0)  # -1: expired
            result, error = await in_thread(
                lambda: packets.write4ByteTxRx(handler, 1, X.GOAL_POSITION.address, 2500)
            )
            assert (result, error) == (sdk.COMM_SUCCESS, dx.ErrorNumber.DATA_RANGE_ERROR)
            result, error = await in_thread(
                lambda: packets.write1ByteTxRx(handler, 1, X.BUS_WATCHDOG.address, 0)
            )
            assert (result, error) == (sdk.COMM_SUCCESS, 0)
            result, error = await in_thread(
                lambda: packets.write4ByteTxRx(handler, 1, X.GOAL_POSITION.address, 2500)
            )
            assert (result, error) == (sdk.COMM_SUCCESS, 0)
        finally:
            handler.closePort()


# -- e-stop -----------------------------------------------------------------------------------------


def _torque_sync_writes(bus: SimDynamixelBus) -> list[dx.SyncWrite]:
    return [
        m
        for m in bus.instructions
        if isinstance(m, dx.SyncWrite) and m.address == X.TORQUE_ENABLE.address
    ]


async def test_port_estop_turns_every_torque_off_in_one_sync_write(
    bus: SimDynamixelBus, port: DynamixelPort, recorder: EventRecorder
) -> None:
    async with AsyncExitStack() as stack:
        a1, a2 = await actuators(stack, port, recorder, 1, 2)
        await a1.set_value(1.0, Request.VELOCITY)
        await a2.set_value(-1.0, Request.VELOCITY)
        await port.estop()
        for actuator in (a1, a2):
            await recorder.wait_for("error", ErrorId.ESTOP, source=actuator, timeout=WAIT_S)
            assert actuator.state is ComponentState.ERROR
            assert servo_of(actuator).estopped and not servo_of(actuator).torque_enabled
        await port.ping(1)  # the peer handles packets in order: the e-stop came first
        (estop,) = _torque_sync_writes(bus)
        assert [(i.id, i.data) for i in estop.items] == [(1, b"\x00"), (2, b"\x00")]
        assert not bus[1].torque_enabled and not bus[2].torque_enabled
        # Safe stop keeps an e-stopped servo's torque off.
        await servo_of(a1).safe_stop(ExitAction.HOLD)
        assert not bus[1].torque_enabled
        for actuator in (a1, a2):
            await actuator.re_init()
            assert not servo_of(actuator).estopped
        assert bus[1].torque_enabled and bus[2].torque_enabled
        with anyio.fail_after(WAIT_S):
            await (await a1.set_value(0.3))


async def test_a_command_on_its_way_when_the_e_stop_comes_leaves_the_torque_off(
    bus: SimDynamixelBus, port: DynamixelPort, recorder: EventRecorder
) -> None:
    """The command's writes (mode, profile, goal, torque on) are awaited one by one; an
    e-stop that comes between them must not be undone by its torque-on (a race seen once
    in a loaded suite run: a servo e-stopped by SIGQUIT had its torque on again)."""
    async with AsyncExitStack() as stack:
        (a1,) = await actuators(stack, port, recorder, 1)
        servo = servo_of(a1)
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
        assert not bus[1].torque_enabled and servo.estopped
        with pytest.raises(HALError, match="e-stopped"):
            await servo.command(Request.POSITION, 0.5)  # and the next one is refused too
        await a1.re_init()
        assert bus[1].torque_enabled


async def test_concurrent_servo_estops_share_one_packet(
    bus: SimDynamixelBus, port: DynamixelPort, recorder: EventRecorder
) -> None:
    async with AsyncExitStack() as stack:
        a1, a2 = await actuators(stack, port, recorder, 1, 2)
        async with anyio.create_task_group() as tg:
            for actuator in (a1, a2):
                tg.start_soon(servo_of(actuator).estop)
        assert a1.state is ComponentState.ERROR and a2.state is ComponentState.ERROR
        assert a1.last_fault is not None and a1.last_fault.error_id == ErrorId.ESTOP
        await port.ping(1)
        (estop,) = _torque_sync_writes(bus)
        assert sorted(i.id for i in estop.items) == [1, 2]
        assert not bus[1].torque_enabled and not bus[2].torque_enabled
        await a2.re_init()
        assert bus[2].torque_enabled and not bus[1].torque_enabled


async def test_estop_refuses_bad_ids(port: DynamixelPort) -> None:
    for bad in ([253], [-1], [True], ["1"]):
        with pytest.raises(BadParameterError, match=r"ids.*0\.\.252"):
            await port.estop(bad)  # type: ignore[list-item]


async def test_estop_goes_ahead_of_queued_transactions(
    bus: SimDynamixelBus, port: DynamixelPort
) -> None:
    async with anyio.create_task_group() as tg:
        for _ in range(5):
            tg.start_soon(port.read, 1, X.PRESENT_POSITION.address, 4)
        await anyio.lowlevel.checkpoint()
        await anyio.lowlevel.checkpoint()
        tg.start_soon(port.estop, [1, 2])
    await port.ping(1)  # the peer handles packets in order: everything before is in
    kinds = [type(m).__name__ for m in bus.instructions if not isinstance(m, dx.SyncRead)]
    # At most the exchange already on the wire goes before it.
    assert "SyncWrite" in kinds[:2], kinds


# -- safe stop -----------------------------------------------------------------------------------


async def test_safe_stop_hold_stop_and_torque_off(
    bus: SimDynamixelBus, port: DynamixelPort, recorder: EventRecorder
) -> None:
    async with AsyncExitStack() as stack:
        (a1,) = await actuators(stack, port, recorder, 1)
        servo = servo_of(a1)
        # STOP in velocity mode: Goal Velocity 0, the servo brakes at Profile Acceleration.
        await a1.set_value(2.0, Request.VELOCITY)
        await servo.safe_stop(ExitAction.STOP)
        assert bus[1].mode == dx.OperatingMode.VELOCITY and bus[1].torque_enabled
        assert bus[1].get_raw(X.GOAL_VELOCITY) == 0
        # HOLD from velocity mode: position mode, Goal Position = the present position read
        # during the stop (the servo moves one way meanwhile: between before and after; a
        # bound on a later poll's position would depend on how loaded the machine is).
        await a1.set_value(2.0, Request.VELOCITY)
        before = bus[1].state()[0]
        await servo.safe_stop(ExitAction.HOLD)
        after = bus[1].state()[0]
        assert bus[1].mode == dx.OperatingMode.POSITION and bus[1].torque_enabled
        goal = bus[1].get_raw(X.GOAL_POSITION)
        assert min(before, after) - 2 <= goal <= max(before, after) + 2
        # STOP in position mode is the same: hold where the stop was asked.
        await a1.set_value(1.0)
        before = bus[1].state()[0]
        await servo.safe_stop(ExitAction.STOP)
        after = bus[1].state()[0]
        goal = bus[1].get_raw(X.GOAL_POSITION)
        assert min(before, after) - 2 <= goal <= max(before, after) + 2
        assert abs(goal - dx.rad_to_ticks(1.0)) > 100
        # TORQUE_OFF.
        await servo.safe_stop(ExitAction.TORQUE_OFF)
        assert not bus[1].torque_enabled and not servo.torque_enabled
        # Disarm: Bus Watchdog 0.
        await servo.arm_watchdog(TIMEOUT_S)
        await servo.disarm_watchdog()
        assert bus[1].get_raw(X.BUS_WATCHDOG) == 0 and port.bus_watchdogs == {}
