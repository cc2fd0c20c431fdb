"""The serial bus kind with ``protocol: feetech``, and rigs/so101.yaml (--sim: simulated STS3215s
on a pty served by their own thread)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import anyio
import msgspec
import pytest

from openel_async import ComponentState, ErrorId, MonotonicClock, Request
from openel_async.errors import BadParameterError
from openel_async.rig import FaultInjection, SimulatedDevice, load_rig, open_rig
from openel_async.safety import ExitAction
from openel_async.testing import EventRecorder
from openel_serial import FeetechPort, SerialBusKind, SerialBusOptions
from openel_serial import feetech as ft
from openel_serial.feetech_peers import SimStsServo

from .conftest import WAIT_S

pytestmark = pytest.mark.timeout(30)

S = ft.STS
KIND = SerialBusKind()
SO101 = Path(__file__).parents[2] / "apps" / "openel_apps" / "rigs" / "so101.yaml"
JOINTS = ["shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll", "gripper"]


def options(**fields: Any) -> SerialBusOptions:
    given: dict[str, Any] = {"device": "/dev/ttyACM0", "baudrate": 1_000_000, "protocol": "feetech"}
    given.update(fields)
    return msgspec.convert(given, SerialBusOptions)


def servo(name: str, servo_id: object, device: str = "feetech_sts3215") -> SimulatedDevice:
    return SimulatedDevice(name, "serial", device, {"servo_id": servo_id})


async def wait_until(predicate: Callable[[], bool], timeout: float = WAIT_S) -> None:  # noqa: ASYNC109
    with anyio.fail_after(timeout):
        while not predicate():  # noqa: ASYNC110 - the peers' state has no event to wait on
            await anyio.sleep(0.002)


def test_check_accepts_and_refuses() -> None:
    KIND.check(options(return_delay=0.0), [servo("a", 1), servo("b", 2, "feetech")])
    for baud in ft.BAUD_RATES:
        KIND.check(options(baudrate=baud), [servo("a", 1)])
    with pytest.raises(BadParameterError, match="Feetech STS baud rate"):
        KIND.check(options(baudrate=57_601), [servo("a", 1)])
    with pytest.raises(BadParameterError, match="servo_id"):
        KIND.check(options(), [servo("a", 254)])
    with pytest.raises(BadParameterError, match="an id of its own"):
        KIND.check(options(), [servo("a", 3), servo("b", 3)])
    with pytest.raises(BadParameterError, match="feetech device"):
        KIND.check(options(), [servo("a", 1, "dynamixel")])
    with pytest.raises(msgspec.ValidationError):
        options(latency=1)  # strict: unknown keys refused
    assert KIND.describe(options()) == "serial /dev/ttyACM0 at 1000000 baud, Feetech STS"


async def test_sim_servos_hear_only_the_rig_baud_rate() -> None:
    given = options(baudrate=500_000, return_delay=100e-6)
    async with KIND.simulate("arm", given, [servo("a", 4)]) as sim:
        peer = sim.peers["a"]
        assert isinstance(peer, SimStsServo) and isinstance(peer, FaultInjection)
        assert (peer.baudrate, peer.get_raw(S.RETURN_DELAY), peer.id) == (500_000, 50, 4)
        async with KIND.open("arm", sim.options) as port:
            assert isinstance(port, FeetechPort) and port.return_delay == 100e-6
            assert (await port.ping(4)).model_number == ft.STS3215_MODEL
        wrong = msgspec.structs.replace(sim.options, baudrate=1_000_000)
        async with KIND.open("arm", wrong) as port:
            assert isinstance(port, FeetechPort)
            with pytest.raises(TimeoutError):
                await port.ping(4)


def test_the_so101_rig_checks() -> None:
    rig = load_rig(SO101)
    assert [c.name for c in rig.components] == JOINTS
    (bus,) = rig.buses
    given = msgspec.convert(dict(bus.options), SerialBusOptions)
    assert (bus.name, bus.type) == ("arm", "serial")
    assert (given.protocol, given.baudrate, given.device) == ("feetech", 1_000_000, "/dev/ttyACM0")
    KIND.check(given, [servo(c.name, c.params["servo_id"]) for c in rig.components])
    assert [c.params["servo_id"] for c in rig.components] == [1, 2, 3, 4, 5, 6]


async def test_the_so101_rig_runs_on_simulated_servos() -> None:
    recorder = EventRecorder(MonotonicClock())
    async with open_rig(load_rig(SO101), MonotonicClock(), sim=True) as rig:
        peers = [rig.peers[name] for name in JOINTS]
        assert all(isinstance(p, SimStsServo) for p in peers)
        for actuator in rig.actuators:
            actuator.add_observer(recorder)
        for name in JOINTS[:-1]:  # step 2048: 0 rad, the middle of the range
            assert await rig.actuator(name).get_value(Request.POSITION_ACTUAL) == pytest.approx(
                0.0, abs=0.01
            )
        grip = rig.actuator("gripper")
        assert await grip.get_value(Request.POSITION_ACTUAL) == pytest.approx(0.5, abs=0.01)
        with anyio.fail_after(WAIT_S):
            motions = [await rig.actuator("elbow_flex").set_value(0.8), await grip.set_value(1.0)]
            for motion in motions:
                await motion
        assert await rig.actuator("elbow_flex").get_value(Request.POSITION_ACTUAL) == (
            pytest.approx(0.8, abs=0.01)
        )
        elbow = rig.peers["elbow_flex"]
        assert isinstance(elbow, SimStsServo)
        assert elbow.get_raw(S.GOAL_POSITION) == ft.rad_to_ticks(0.8)
        # The host watchdog is armed from safety.watchdog_timeout.
        port = rig.actuator("elbow_flex").device.port  # type: ignore[attr-defined]
        assert port.host_watchdogs == dict.fromkeys(range(1, 7), 0.5)
        # An injected fault overheats the wrist: its component faults, the others go on.
        wrist = rig.peers["wrist_flex"]
        assert isinstance(wrist, SimStsServo)
        wrist.inject_fault("over-temperature")
        await recorder.wait_for(
            "error", ErrorId.DEVICE_ERROR, source=rig.actuator("wrist_flex"), timeout=WAIT_S
        )
        assert rig.actuator("shoulder_pan").state is ComponentState.ACTIVE
        # The rig's e-stop: every servo's torque off.
        await rig.estop()
        for actuator in rig.actuators:
            if actuator is not rig.actuator("wrist_flex"):
                await recorder.wait_for("error", ErrorId.ESTOP, source=actuator, timeout=WAIT_S)
        await wait_until(lambda: not any(p.torque_enabled for p in peers))  # type: ignore[attr-defined]
        rig.release_estop()
        await rig.actuator("shoulder_pan").re_init()
        assert rig.actuator("shoulder_pan").state is ComponentState.ACTIVE
    assert all(r.action is ExitAction.HOLD for r in rig.exit_report)
    pan = rig.peers["shoulder_pan"]
    assert isinstance(pan, SimStsServo) and pan.torque_enabled  # holding, as on_exit says
    assert port.host_watchdogs == {}  # disarmed before the exit
