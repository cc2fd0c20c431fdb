"""ODriveAxis and the ODrive sensors against the simulated ODrive on a virtual bus."""

from __future__ import annotations

import math

import anyio
import can
import pytest

from openel_async import (
    ComponentState,
    DeviceFaultError,
    ErrorId,
    EventId,
    HALError,
    NotConnectedError,
    Outcome,
    Request,
    SupersededError,
)
from openel_async.testing import EventRecorder
from openel_can import CanBus, ODriveAxis, ODriveBusMonitor, ODriveEncoder, ODriveTemperature
from openel_can import cansimple as cs
from openel_can.odrive import ODriveError, rad_to_turns, turns_to_rad
from openel_can.sim.odrive import SimODrive

from .conftest import Components, Peers, drain, wait_until

NODE = 3
HB = 0.02  # heartbeat period of the simulated ODrive in these tests (real default: 0.1 s)
COMPLETED = EventId.COMPLETED


def _sim(**kwargs: object) -> SimODrive:
    kwargs.setdefault("heartbeat_period", HB)
    return SimODrive(NODE, **kwargs)  # type: ignore[arg-type]


def _axis(bus: CanBus, **kwargs: object) -> ODriveAxis:
    kwargs.setdefault("heartbeat_period", HB)
    return ODriveAxis(bus, NODE, **kwargs)  # type: ignore[arg-type]


def _frame(msg: cs.CanSimpleMessage) -> tuple[int, str]:
    arb, data = cs.encode(msg)
    return arb, data.hex(" ")


def test_units_are_exact() -> None:
    assert turns_to_rad(1.0) == math.tau
    assert rad_to_turns(math.tau) == 1.0
    assert rad_to_turns(turns_to_rad(1.5)) == 1.5


async def test_golden_frames_sent_by_the_driver(
    peers: Peers, host_bus: CanBus, components: Components, raw_bus: can.BusABC
) -> None:
    await peers.start(_sim())
    axis = await components.actuator(_axis(host_bus))
    drain(raw_bus)
    device = axis.device
    assert isinstance(device, ODriveAxis)
    # Set_Input_Pos to node 3: 1.5 turns, vel_ff 0.5 turn/s, torque_ff 0.1 Nm.
    device.set_feedforward(velocity=turns_to_rad(0.5), torque=0.1)
    await axis.set_value(turns_to_rad(1.5), Request.POSITION)
    device.set_feedforward()
    await axis.set_value(turns_to_rad(1.0), Request.VELOCITY)
    await axis.set_value(0.5, Request.TORQUE)
    await axis.set_value(0.0, Request.NO_EXCITE)
    setpoints = {0x06B, 0x06C, 0x06D, 0x06E, 0x067}
    idle = (0x067, "01 00 00 00 00 00 00 00")
    host: list[tuple[int, str]] = []
    with anyio.fail_after(1):
        while idle not in host:
            host += [
                (m.arbitration_id, bytes(m.data).hex(" "))
                for m in drain(raw_bus)
                if m.arbitration_id in setpoints and not m.is_remote_frame
            ]
            await anyio.sleep(0.002)
    # The init sequence ends with Set_Controller_Mode POSITION, TRAP_TRAJ (if it was still
    # queued when the capture started).
    if host[0] == (0x06B, "03 00 00 00 05 00 00 00"):
        host = host[1:]
    assert host == [
        (0x06C, "00 00 c0 3f f4 01 64 00"),  # Set_Input_Pos (the brief's golden frame)
        (0x06B, "02 00 00 00 02 00 00 00"),  # Set_Controller_Mode VELOCITY, VEL_RAMP
        (0x06D, "00 00 80 3f 00 00 00 00"),  # Set_Input_Vel 1 turn/s
        (0x06B, "01 00 00 00 01 00 00 00"),  # Set_Controller_Mode TORQUE, PASSTHROUGH
        (0x06E, "00 00 00 3f 00 00 00 00"),  # Set_Input_Torque 0.5 Nm
        (0x067, "01 00 00 00 00 00 00 00"),  # Set_Axis_State IDLE
    ]


async def test_init_engages_closed_loop_and_close_idles(
    peers: Peers, host_bus: CanBus, components: Components
) -> None:
    sim = await peers.start(_sim())
    axis = await components.actuator(_axis(host_bus))
    assert sim.axis_state is cs.AxisState.CLOSED_LOOP_CONTROL  # confirmed by a heartbeat
    # Set_Controller_Mode is queued last; the peer applies it a moment later.
    await wait_until(lambda: sim.input_mode is cs.InputMode.TRAP_TRAJ, 1)
    assert sim.control_mode is cs.ControlMode.POSITION
    await axis.finalize()
    await wait_until(lambda: sim.axis_state is cs.AxisState.IDLE, 1)


async def test_position_move_completes_exactly_once(
    peers: Peers, host_bus: CanBus, components: Components, recorder: EventRecorder
) -> None:
    sim = await peers.start(_sim())
    axis = await components.actuator(_axis(host_bus))
    motion = await axis.set_value(1.0, Request.POSITION)
    with anyio.fail_after(2):
        await motion
    # Reported when the trajectory really ended, not from a stale done flag.
    assert sim.position == pytest.approx(rad_to_turns(1.0), abs=1e-6)
    assert await axis.get_value(Request.POSITION_ACTUAL) == pytest.approx(1.0, abs=1e-5)
    # More heartbeats (done flag still set) post nothing more.
    heartbeats = axis.device._heartbeats  # type: ignore[attr-defined]
    await wait_until(lambda: axis.device._heartbeats >= heartbeats + 3)  # type: ignore[attr-defined]
    assert recorder.count("event", COMPLETED, source=axis) == 1


async def test_stale_done_flag_is_ignored_until_acknowledged(
    peers: Peers,
    host_bus: CanBus,
    components: Components,
    recorder: EventRecorder,
    raw_bus: can.BusABC,
) -> None:
    sim = await peers.start(_sim(heartbeat_period=0.05))
    axis = await components.actuator(_axis(host_bus, heartbeat_period=0.05))
    with anyio.fail_after(2):
        await (await axis.set_value(0.2))
    second = await axis.set_value(1.2)
    # A heartbeat the ODrive sent before it read the new setpoint, still showing the
    # previous trajectory done, arrives after the command: it must not complete it.
    arb, data = cs.encode(cs.Heartbeat(NODE, 0, cs.AxisState.CLOSED_LOOP_CONTROL, 0, True))
    raw_bus.send(can.Message(arbitration_id=arb, data=data, is_extended_id=False))
    with anyio.fail_after(2):
        await second
    assert sim.position == pytest.approx(rad_to_turns(1.2), abs=1e-6)
    assert sim.trajectory_done(sim.now())
    assert recorder.count("event", COMPLETED, source=axis) == 2


async def test_superseded_targets_complete_only_the_last(
    peers: Peers, host_bus: CanBus, components: Components, recorder: EventRecorder
) -> None:
    sim = await peers.start(_sim())
    axis = await components.actuator(_axis(host_bus))
    first = await axis.set_value(2.0)
    second = await axis.set_value(-1.0)
    third = await axis.set_value(0.5)
    with anyio.fail_after(2):
        await third
    for replaced in (first, second):
        with pytest.raises(SupersededError):
            await replaced
    assert sim.position == pytest.approx(rad_to_turns(0.5), abs=1e-6)
    assert recorder.count("event", COMPLETED, source=axis) == 1
    assert third.outcome is Outcome.REACHED


async def test_velocity_mode(peers: Peers, host_bus: CanBus, components: Components) -> None:
    sim = await peers.start(_sim())
    axis = await components.actuator(_axis(host_bus))
    motion = await axis.set_value(3.0, Request.VELOCITY)
    with anyio.fail_after(2):
        await motion
    assert sim.control_mode is cs.ControlMode.VELOCITY
    assert await axis.get_value(Request.VELOCITY_ACTUAL) == pytest.approx(3.0, abs=0.05)


@pytest.mark.parametrize("torque_constant", [None, 0.0827])
async def test_torque_mode(
    peers: Peers, host_bus: CanBus, components: Components, torque_constant: float | None
) -> None:
    sim = await peers.start(_sim(vel_limit=50.0))
    axis = await components.actuator(_axis(host_bus, torque_constant=torque_constant))
    motion = await axis.set_value(0.02, Request.TORQUE)
    with anyio.fail_after(2):
        await motion
    assert sim.control_mode is cs.ControlMode.TORQUE
    assert await axis.get_value(Request.TORQUE_ACTUAL) == pytest.approx(0.02, abs=1e-4)
    await axis.set_value(0.0, Request.TORQUE)


async def test_no_excite_idles_and_next_command_re_engages(
    peers: Peers, host_bus: CanBus, components: Components
) -> None:
    sim = await peers.start(_sim())
    axis = await components.actuator(_axis(host_bus))
    await axis.set_value(0.0, Request.NO_EXCITE)
    await wait_until(lambda: sim.axis_state is cs.AxisState.IDLE, 1)
    await anyio.sleep(3 * HB)  # idle heartbeats are expected now, not a fault
    assert axis.state is ComponentState.ACTIVE
    motion = await axis.set_value(0.3)
    assert sim.axis_state is cs.AxisState.CLOSED_LOOP_CONTROL
    with anyio.fail_after(2):
        await motion


async def test_axis_error_faults_and_re_init_clears_it(
    peers: Peers, host_bus: CanBus, components: Components, recorder: EventRecorder
) -> None:
    sim = await peers.start(_sim())
    axis = await components.actuator(_axis(host_bus))
    motion = await axis.set_value(3.0)
    sim.inject_error(ODriveError.DRV_FAULT)
    record = await recorder.wait_for("error", source=axis, timeout=1)
    assert record.id == ErrorId.DEVICE_ERROR
    assert axis.state is ComponentState.ERROR
    assert axis.last_fault is not None and "DRV_FAULT" in str(axis.last_fault)
    with pytest.raises(DeviceFaultError):
        await motion
    await axis.re_init()
    assert any(isinstance(c, cs.ClearErrors) for c in sim.commands)
    assert sim.axis_state is cs.AxisState.CLOSED_LOOP_CONTROL and sim.disarm_reason == 0
    with anyio.fail_after(2):
        await (await axis.set_value(0.5))
    assert recorder.count("error", source=axis) == 1


async def test_error_that_does_not_disarm_is_posted_not_faulted(
    peers: Peers, host_bus: CanBus, components: Components, recorder: EventRecorder
) -> None:
    sim = await peers.start(_sim())
    axis = await components.actuator(_axis(host_bus))
    sim.inject_error(ODriveError.MOTOR_OVER_TEMP, disarm=False)
    record = await recorder.wait_for("error", source=axis, timeout=1)
    assert record.id == ErrorId.DEVICE_ERROR
    assert axis.state is ComponentState.ACTIVE
    with anyio.fail_after(2):
        await (await axis.set_value(0.2))


async def test_estop_faults(
    peers: Peers, host_bus: CanBus, components: Components, recorder: EventRecorder
) -> None:
    sim = await peers.start(_sim())
    axis = await components.actuator(_axis(host_bus))
    device = axis.device
    assert isinstance(device, ODriveAxis)
    await device.estop()
    await recorder.wait_for("error", source=axis, timeout=1)
    assert "ESTOP_REQUESTED" in str(axis.last_fault)
    assert sim.axis_state is cs.AxisState.IDLE
    await axis.re_init()
    assert axis.state is ComponentState.ACTIVE


async def test_heartbeat_loss_faults_disconnected(
    peers: Peers, host_bus: CanBus, components: Components, recorder: EventRecorder
) -> None:
    sim = await peers.start(_sim())
    axis = await components.actuator(_axis(host_bus, engage_timeout=0.2))
    sim.set_silent()
    record = await recorder.wait_for("error", source=axis, timeout=1)
    assert record.id == ErrorId.DISCONNECTED
    assert axis.state is ComponentState.ERROR
    with pytest.raises(HALError):
        await axis.re_init()  # still silent
    assert axis.state is ComponentState.ERROR
    sim.set_silent(False)
    await axis.re_init()
    with anyio.fail_after(2):
        await (await axis.set_value(0.2))
    assert recorder.count("error", source=axis) == 1  # one fault per episode


async def test_read_timeout_faults_with_timeout(
    peers: Peers, host_bus: CanBus, components: Components, recorder: EventRecorder
) -> None:
    sim = await peers.start(_sim(heartbeat_period=0.1))
    axis = await components.actuator(_axis(host_bus, heartbeat_period=0.1))
    sim.set_silent()
    await anyio.sleep(0.04)  # the cached estimate (10 ms period) is now stale: polled
    with pytest.raises(DeviceFaultError) as info:
        await axis.get_value(Request.POSITION_ACTUAL)
    assert info.value.error_id == ErrorId.TIMEOUT
    assert axis.state is ComponentState.ERROR
    assert (await recorder.wait_for("error", source=axis, timeout=1)).id == ErrorId.TIMEOUT


async def test_corrupt_frames_are_counted_and_dropped(
    peers: Peers,
    host_bus: CanBus,
    components: Components,
    raw_bus: can.BusABC,
    recorder: EventRecorder,
) -> None:
    await peers.start(_sim())
    axis = await components.actuator(_axis(host_bus))
    device = axis.device
    assert isinstance(device, ODriveAxis)
    heartbeat = cs.arbitration_id(NODE, cs.CmdId.HEARTBEAT)
    encoder = cs.arbitration_id(NODE, cs.CmdId.GET_ENCODER_ESTIMATES)
    raw_bus.send(can.Message(arbitration_id=heartbeat, data=b"\x00\x00\x00", is_extended_id=False))
    raw_bus.send(can.Message(arbitration_id=encoder, data=b"\x01\x02", is_extended_id=False))
    remote_reply = can.Message(arbitration_id=heartbeat, is_remote_frame=True, dlc=8)
    raw_bus.send(remote_reply)  # a poll by another host: ignored, not counted
    bad_dlc = can.Message(arbitration_id=heartbeat, data=bytes(9)[:6], is_extended_id=False)
    raw_bus.send(bad_dlc)  # 6 bytes: the heartbeat needs 7
    await wait_until(lambda: device.malformed_frames == 3, 1)
    assert axis.state is ComponentState.ACTIVE
    with anyio.fail_after(2):
        await (await axis.set_value(0.2))
    assert recorder.errors == []


async def test_open_without_node_fails_cleanly(host_bus: CanBus) -> None:
    from openel_async import Actuator

    with anyio.fail_after(2), pytest.raises(NotConnectedError, match="no heartbeat"):
        async with Actuator(_axis(host_bus, engage_timeout=0.1)):
            pass


async def test_sensors(peers: Peers, host_bus: CanBus, components: Components) -> None:
    sim = await peers.start(_sim())
    await components.actuator(_axis(host_bus))
    encoder = await components.sensor(ODriveEncoder(host_bus, NODE))
    thermometer = await components.sensor(ODriveTemperature(host_bus, NODE))
    monitor = await components.sensor(ODriveBusMonitor(host_bus, NODE))
    position, velocity = await encoder.get_value()
    assert position == pytest.approx(turns_to_rad(sim.position), abs=1e-4)
    assert velocity == pytest.approx(0.0, abs=1e-6)
    timed = await encoder.get_timed_value()
    assert 0 <= encoder.get_time() - timed.time_ns < 50_000_000
    fet, motor = await thermometer.get_value()
    assert thermometer.units == ("K", "K")
    assert 290 < fet < 320 and 290 < motor < 320
    volts, amps = await monitor.get_value()
    assert volts == pytest.approx(24.0, abs=0.5) and amps >= 0


@pytest.mark.parametrize("state", [15, 16])
async def test_unknown_axis_states_are_heartbeats_not_malformed_frames(
    peers: Peers,
    host_bus: CanBus,
    components: Components,
    recorder: EventRecorder,
    state: int,
) -> None:
    """Firmware 0.6.11 reports axis states 15 and 16. Before: each such heartbeat was
    dropped as malformed, so a run of them ended in a false DISCONNECTED fault."""
    sim = await peers.start(_sim())
    axis = await components.actuator(_axis(host_bus))
    device = axis.device
    assert isinstance(device, ODriveAxis)
    await axis.set_value(0.0, Request.NO_EXCITE)  # closed loop no longer wanted
    await wait_until(lambda: sim.axis_state is cs.AxisState.IDLE, 1)
    sim.axis_state = state  # e.g. a calibration started by another tool
    await anyio.sleep(4 * device.heartbeat_timeout)  # the condition: time without a fault
    assert device.malformed_frames == 0
    assert device.last_heartbeat is not None and device.last_heartbeat.axis_state == state
    assert axis.state is ComponentState.ACTIVE and recorder.errors == []
    # While closed loop is wanted, the same state is a drop out of closed loop, named.
    sim.axis_state = cs.AxisState.IDLE
    with anyio.fail_after(2):
        await (await axis.set_value(0.1))
    sim.axis_state = state
    record = await recorder.wait_for("error", source=axis, timeout=1)
    assert record.id == ErrorId.DEVICE_ERROR
    assert f"unknown ({state})" in str(axis.last_fault)


def test_one_limit_alone_is_refused() -> None:
    """Set_Limits carries both limits: before, velocity_limit alone sent current = +inf
    (and the reverse), wiping the drive's configured limit."""
    from openel_async import BadParameterError

    bus = CanBus(interface="virtual", channel="unused")
    with pytest.raises(BadParameterError, match="current_limit"):
        ODriveAxis(bus, 1, velocity_limit=10.0)
    with pytest.raises(BadParameterError, match="velocity_limit"):
        ODriveAxis(bus, 1, current_limit=5.0)


async def test_both_limits_are_sent_as_given(
    peers: Peers, host_bus: CanBus, components: Components
) -> None:
    sim = await peers.start(_sim(current_limit=7.5))
    await components.actuator(_axis(host_bus, velocity_limit=turns_to_rad(3.0), current_limit=12))
    limits = [c for c in sim.commands if isinstance(c, cs.SetLimits)]
    assert limits == [cs.SetLimits(NODE, 3.0, 12.0)]
    assert sim.current_limit == 12.0 and sim.vel_limit == 3.0


async def test_sim_command_history_is_bounded_and_counts_what_it_dropped(
    peers: Peers, host_bus: CanBus, components: Components
) -> None:
    sim = await peers.start(_sim(history=8))
    axis = await components.actuator(_axis(host_bus))
    for n in range(20):
        await axis.set_value(0.001 * n, Request.VELOCITY)
    last = rad_to_turns(0.019)

    def arrived() -> bool:
        command = sim.commands[-1]
        return isinstance(command, cs.SetInputVel) and command.vel == pytest.approx(last)

    await wait_until(arrived, 1)
    assert len(sim.commands) == 8
    assert sim.commands.total >= 21  # the init commands + 20 Set_Input_Vel
    assert sim.commands.discarded == sim.commands.total - 8


def test_bad_parameters_name_the_parameter() -> None:
    from openel_async import BadParameterError

    bus = CanBus(interface="virtual", channel="unused")
    with pytest.raises(BadParameterError, match="node_id"):
        ODriveAxis(bus, 0x3F)
    with pytest.raises(BadParameterError, match="heartbeat_period"):
        ODriveAxis(bus, 1, heartbeat_period=0)
    with pytest.raises(BadParameterError, match="bus"):
        ODriveAxis("can0", 1)  # type: ignore[arg-type]
    axis = ODriveAxis(bus, 1)
    with pytest.raises(BadParameterError, match="velocity"):
        axis.set_feedforward(velocity=math.inf)


def test_history_keeps_the_newest_and_counts_the_rest() -> None:
    from openel_can.sim.history import History

    history: History[int] = History(3)
    for n in range(5):
        history.append(n)
    assert list(history) == [2, 3, 4] and history[:2] == [2, 3] and history[-1] == 4
    assert (len(history), history.discarded, history.total) == (3, 2, 5)
    history.clear()
    assert (len(history), history.discarded, history.total) == (0, 5, 5)
    with pytest.raises(ValueError, match="maxlen"):
        History(0)
