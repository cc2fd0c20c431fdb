"""An e-stop arriving while a command is on its way (between the awaited steps of its frame
sequence) is not undone by the command's later steps: the drive stays stopped until
``re_init`` (CiA 402: no controlword back to Enable operation, nothing staged for the next
SYNC; ODrive: no closed-loop request, no set-point). Deterministic: a hook on the driver's
send path starts the e-stop in another task when the command sends its N-th frame, waits
until the e-stop's own frame is out, then lets the command go on."""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import Any

import anyio
import anyio.abc
import can
import pytest

from openel_async import Actuator, ComponentState, EventTimer, Request
from openel_async.errors import HALError
from openel_can import CanBus, CanSync, Cia402CyclicDrive, Cia402Drive, ODriveAxis
from openel_can import cansimple as cs
from openel_can import cia402 as ds
from openel_can.sim.cia402 import SimCia402Drive
from openel_can.sim.odrive import SimODrive

from .conftest import Peers, drain, wait_until

PS = ds.PowerState
QUICK_STOP = int(ds.Command.QUICK_STOP)


def _controlwords(frames: list[can.Message], node: int) -> list[int]:
    """The controlwords sent to ``node`` in RPDOs (the first two bytes of 0x200..0x500+node)."""
    ids = {base + node for base in (0x200, 0x300, 0x400, 0x500)}
    return [int.from_bytes(f.data[:2], "little") for f in frames if f.arbitration_id in ids]


def _hook(
    device: Any,
    name: str,
    trigger: Callable[..., bool],
    estop: Callable[[], Awaitable[None]],
    stopped: Callable[[], bool],
    tg: anyio.abc.TaskGroup,
) -> list[bool]:
    """Wrap ``device.<name>`` (an async send): on the first call ``trigger(*args)`` accepts,
    start ``estop`` in another task, wait (bounded) until ``stopped()``, then send."""
    original = getattr(device, name)
    fired: list[bool] = []

    async def hooked(*args: Any) -> None:
        if not fired and trigger(*args):
            fired.append(True)
            tg.start_soon(estop)
            await wait_until(stopped, 2)  # the e-stop's frame is out (not queued behind us)
        await original(*args)

    setattr(device, name, hooked)
    return fired


async def test_cia402_pp_estop_between_the_set_point_steps_is_not_undone(
    peers: Peers, host_bus: CanBus, raw_bus: can.BusABC
) -> None:
    sim = await peers.start(SimCia402Drive(5))
    sim.od[
        (0x605A, 0)
    ].value = 6  # quick stop, then stay in Quick stop active (transition 16 possible)
    async with Actuator(Cia402Drive(host_bus, 5, state_timeout=1.0)) as axis:
        device = axis.device
        assert isinstance(device, Cia402Drive)
        drain(raw_bus)
        async with anyio.create_task_group() as tg:
            fired = _hook(
                device,
                "_send_rpdo",
                lambda mode, cw, target: bool(cw & int(ds.ControlBit.NEW_SETPOINT)),
                axis.estop,
                lambda: QUICK_STOP in _controlwords(list(sent), 5),
                tg,
            )
            sent: list[can.Message] = []
            tg.start_soon(_capture, raw_bus, sent)
            with pytest.raises(HALError, match="e-stop"):
                await axis.set_value(1.0, Request.POSITION)
            assert fired
            tg.cancel_scope.cancel()
        words = _controlwords(sent + drain(raw_bus), 5)
        after = words[words.index(QUICK_STOP) + 1 :]
        assert all(cw & 0x07 != 0x07 for cw in after), [hex(w) for w in words]
        # Every frame sent before this answer was processed by the drive (one sender, in order).
        await device.sdo.read(ds.STATUSWORD, timeout=1.0)
        assert sim.power_state is PS.QUICK_STOP_ACTIVE
        assert axis.state is ComponentState.ERROR
        axis.release_estop()
        await axis.re_init()  # the way back
        assert sim.power_state is PS.OPERATION_ENABLED


async def _capture(bus: can.BusABC, into: list[can.Message]) -> None:
    """Collect what a raw bus receives, polled (the hook waits on it)."""
    while True:
        into.extend(drain(bus))
        await anyio.sleep(0.001)


async def test_cia402_csp_estop_drops_the_staged_set_point_and_refuses_new_ones(
    peers: Peers, host_bus: CanBus, raw_bus: can.BusABC
) -> None:
    sim = await peers.start(SimCia402Drive(6))
    sim.od[(0x605A, 0)].value = 6
    async with (
        Actuator(Cia402Drive(host_bus, 6, mode="csp")) as axis,
        EventTimer(2.0, name="cycle") as timer,
    ):
        device = axis.device
        assert isinstance(device, Cia402CyclicDrive)
        sync = CanSync.of(host_bus)
        await sync.start(timer)  # the timer does not run yet: the set-point stays staged
        device.command_nowait(Request.POSITION, 0.01)
        await axis.estop()  # quick stop at once; the staged Enable operation must not follow
        with pytest.raises(HALError, match="e-stop"):
            device.command_nowait(Request.POSITION, 0.02)
        drain(raw_bus)
        timer.start_timer()
        await wait_until(lambda: sync.stats.cycles >= 3, 2)
        timer.stop_timer()
        sync.stop()
        words = _controlwords(drain(raw_bus), 6)
        assert all(cw & 0x07 != 0x07 for cw in words), [hex(w) for w in words]
        await device.sdo.read(ds.STATUSWORD, timeout=1.0)
        assert sim.power_state is PS.QUICK_STOP_ACTIVE


async def test_odrive_estop_while_a_command_engages_sends_no_closed_loop_or_set_point(
    peers: Peers, host_bus: CanBus, raw_bus: can.BusABC
) -> None:
    sim = await peers.start(SimODrive(node_id=3))
    async with Actuator(ODriveAxis(host_bus, 3, heartbeat_period=0.02)) as axis:
        device = axis.device
        assert isinstance(device, ODriveAxis)
        await axis.set_value(0.0, Request.NO_EXCITE)  # the next command engages closed loop
        await wait_until(lambda: sim.axis_state is cs.AxisState.IDLE, 2)
        estop_id = (3 << 5) | int(cs.CmdId.ESTOP)
        sent: list[can.Message] = []
        drain(raw_bus)
        async with anyio.create_task_group() as tg:
            tg.start_soon(_capture, raw_bus, sent)

            def engaging(msg: Any) -> bool:
                return isinstance(msg, cs.SetAxisState)

            fired = _hook(
                device._link,
                "send",
                engaging,
                axis.estop,
                lambda: any(f.arbitration_id == estop_id for f in sent),
                tg,
            )
            with pytest.raises(HALError, match="e-stop"):
                await axis.set_value(1.0, Request.POSITION)
            assert fired
            tg.cancel_scope.cancel()
        frames = sent + drain(raw_bus)
        ids = [f.arbitration_id for f in frames]
        after = frames[ids.index(estop_id) + 1 :]
        forbidden = {
            (3 << 5) | int(cmd)
            for cmd in (cs.CmdId.SET_AXIS_STATE, cs.CmdId.SET_INPUT_POS, cs.CmdId.SET_INPUT_VEL)
        }
        assert not [hex(f.arbitration_id) for f in after if f.arbitration_id in forbidden]
        assert sim.axis_state is not cs.AxisState.CLOSED_LOOP_CONTROL
        assert axis.state is ComponentState.ERROR
