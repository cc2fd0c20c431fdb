"""Calibration of Feetech servos (feetech_calibration, ``openel-async calibrate``): the
walk-through against simulated STS3215s moved by a scripted hand, the calibration file (strict,
positioned refusals), a component applying it, a rig's ``calibration:`` option and the command
run in-process with its input from a stream."""

from __future__ import annotations

import io
import json
import math
import threading
from collections.abc import AsyncIterator
from pathlib import Path

import anyio
import anyio.to_thread
import msgspec
import pytest

from openel_async import Actuator, HALError, Request
from openel_async.cli import main
from openel_async.errors import BadParameterError
from openel_async.positioned import DocumentError
from openel_async.rig import SimulatedDevice, load_rig, open_rig, resolve_rig
from openel_serial import FeetechPort, FeetechSTS3215, SerialBusKind, SerialBusOptions
from openel_serial import feetech as ft
from openel_serial.feetech_calibration import (
    CalibrationError,
    CalibrationFile,
    JointCalibration,
    JointReading,
    calibrate_servos,
    homing_offset_for,
    load_calibration,
    write_calibration,
)
from openel_serial.feetech_peers import SimFeetechBus, SimStsServo

from .conftest import BAUD, WAIT_S

pytestmark = pytest.mark.timeout(30)

S = ft.STS
STEP = 2 * math.pi / 4096
SO101 = Path(__file__).parents[2] / "apps" / "openel_apps" / "rigs" / "so101.yaml"
# The scripted arm, rotor steps: where the user's "middle" is (servo 2 already had an offset)
MIDDLE = {1: 2300, 2: 1700, 3: 2048}
# ... and how far each joint goes by hand, in steps from that middle (low, high)
REACH = {1: (-900, 1100), 2: (-1200, 600), 3: (-300, 300)}


@pytest.fixture
async def bus() -> AsyncIterator[SimFeetechBus]:
    servos = [
        SimStsServo(1, position=MIDDLE[1] - 500),
        SimStsServo(2, position=MIDDLE[2] + 300, homing_offset=-300),
        SimStsServo(3, position=MIDDLE[3]),
    ]
    async with SimFeetechBus(servos) as sim:
        yield sim


@pytest.fixture
async def port(bus: SimFeetechBus) -> AsyncIterator[FeetechPort]:
    async with FeetechPort(bus.path, baudrate=BAUD, return_delay=0.0, timeout_margin=0.1) as p:
        yield p


class ScriptedHand:
    """A person at the arm, in a thread: the middle pose, then each joint to both ends and
    back, each pose held until the walk-through has streamed two more samples."""

    def __init__(self, bus: SimFeetechBus) -> None:
        self.bus = bus
        self.samples = 0
        self.seen = threading.Condition()
        self.asked: list[str] = []

    def show(self, readings: list[JointReading]) -> None:
        with self.seen:
            self.samples += 1
            self.seen.notify_all()

    def _hold(self) -> None:
        with self.seen:
            target = self.samples + 2
            assert self.seen.wait_for(lambda: self.samples >= target, timeout=WAIT_S)

    def _move(self) -> None:
        for servo_id, (low, high) in REACH.items():
            for delta in (low, high, 0):
                self.bus[servo_id].set_rotor(MIDDLE[servo_id] + delta)
                self._hold()

    async def ask(self, step: str, prompt: str) -> None:
        self.asked.append(step)
        if step == "middle":
            for servo_id, rotor in MIDDLE.items():
                self.bus[servo_id].set_rotor(rotor)
            return
        await anyio.to_thread.run_sync(self._move)


JOINTS = {"pan": 1, "lift": 2, "elbow": 3}


async def test_the_walkthrough_writes_offsets_and_limits(
    bus: SimFeetechBus, port: FeetechPort
) -> None:
    for servo in bus.servos:
        await port.write_item(servo.id, S.TORQUE_ENABLE, 1)
    hand = ScriptedHand(bus)
    with anyio.fail_after(20):
        result = await calibrate_servos(port, JOINTS, hand.ask, show=hand.show, period=0.005)
    assert hand.asked == ["middle", "range"]
    assert not any(s.torque_enabled for s in bus.servos)
    for name, servo_id in JOINTS.items():
        servo = bus[servo_id]
        offset = MIDDLE[servo_id] - ft.CENTER_TICK  # the encoder's middle reads 2048
        low, high = REACH[servo_id]
        entry = result[name]
        assert entry == JointCalibration(
            id=servo_id,
            homing_offset=offset,
            range_min=ft.CENTER_TICK + low,
            range_max=ft.CENTER_TICK + high,
        )
        servo.power_cycle()  # written behind the lock: kept
        assert servo.get_raw(S.HOMING_OFFSET) == offset
        assert servo.get_raw(S.MIN_ANGLE_LIMIT) == ft.CENTER_TICK + low
        assert servo.get_raw(S.MAX_ANGLE_LIMIT) == ft.CENTER_TICK + high
        assert servo.locked
        assert await port.read_item(servo_id, S.PRESENT_POSITION) == ft.CENTER_TICK
    # the positions were streamed with one SYNC READ of Present Position per cycle
    streamed = [m for m in bus.instructions if isinstance(m, ft.SyncRead)]
    assert len(streamed) >= hand.samples >= 18
    assert all((m.address, m.length, m.ids) == (56, 2, (1, 2, 3)) for m in streamed)


async def test_a_joint_that_did_not_move_is_refused(bus: SimFeetechBus, port: FeetechPort) -> None:
    async def lazy(step: str, prompt: str) -> None:
        return None

    with anyio.fail_after(WAIT_S), pytest.raises(CalibrationError, match="pan, lift, elbow did"):
        await calibrate_servos(port, JOINTS, lazy)
    assert bus[1].get_raw(S.MAX_ANGLE_LIMIT) == 4095  # no range written
    with anyio.fail_after(WAIT_S), pytest.raises(CalibrationError, match="servo 9 does not"):
        await calibrate_servos(port, {"x": 9}, lazy)


def test_homing_offset_for_wraps_into_the_register() -> None:
    assert homing_offset_for(0, 2148) == 100
    assert homing_offset_for(-300, 2048) == -300
    assert homing_offset_for(2000, 2148) == 2100 - 4096
    assert homing_offset_for(0, 0) == -2047  # -2048 does not fit in 11 bits


def test_the_calibration_file_round_trips_and_is_strict(tmp_path: Path) -> None:
    entry = JointCalibration(id=1, homing_offset=-12, range_min=700, range_max=3300)
    calibration = CalibrationFile(joints={"shoulder_pan": entry, "gripper": entry})
    path = tmp_path / "cal.yaml"
    write_calibration(path, calibration, comment="a test")
    assert path.read_text().startswith("# a test\nversion: 1\njoints:\n  shoulder_pan: {id: 1")
    assert load_calibration(path) == calibration
    as_json = tmp_path / "cal.json"
    as_json.write_text(json.dumps(msgspec.to_builtins(calibration)))
    assert load_calibration(as_json) == calibration
    path.write_text(
        "version: 1\njoints:\n  pan: {id: 1, homing_offset: 0, range_min: 1, range_max: 9,\n"
        "        drive_mod: 1}\n"
    )
    with pytest.raises(DocumentError, match=r"cal.yaml:4:9: unknown key 'drive_mod'.*drive_mode"):
        load_calibration(path)
    path.write_text("version: 1\njoints:\n  pan: {id: 1, homing_offset: 0, range_min: 9, range_max: 1}\n")  # fmt: skip
    with pytest.raises(DocumentError, match=r"cal.yaml:3:59: .*range_max \(1\) must be above"):
        load_calibration(path)
    path.write_text("version: 1\njoints:\n  pan: {id: 1, homing_offset: 4000, range_min: 1, range_max: 9}\n")  # fmt: skip
    with pytest.raises(DocumentError, match=r"cal.yaml:3:\d+: .*homing_offset"):
        load_calibration(path)


async def test_a_calibrated_component_reads_zero_in_the_middle_and_keeps_its_range(
    bus: SimFeetechBus, port: FeetechPort
) -> None:
    hand = ScriptedHand(bus)
    with anyio.fail_after(20):
        result = await calibrate_servos(port, JOINTS, hand.ask, show=hand.show, period=0.005)
    entry = result["pan"]
    async with Actuator(FeetechSTS3215(port, 1, calibration=entry)) as pan:
        assert await pan.get_value(Request.POSITION_ACTUAL) == pytest.approx(0.0, abs=STEP)
        low, high = (-900 * STEP, 1100 * STEP)
        assert pan.device.limits.position == pytest.approx((low, high))
        with anyio.fail_after(WAIT_S):
            await (await pan.set_value(high - 0.01))
        assert await pan.get_value(Request.POSITION_ACTUAL) == pytest.approx(high - 0.01, abs=0.01)
        with pytest.raises(BadParameterError, match="a position in"):
            await pan.set_value(high + 0.1)
    # the servo's own angle limit clamps a goal past the range
    await port.write_item(1, S.GOAL_POSITION, 4000)
    with anyio.fail_after(WAIT_S):
        while bus[1].get(S.MOVING):  # noqa: ASYNC110 - the peer has no event to wait on
            await anyio.sleep(0.005)
    assert bus[1].get(S.PRESENT_POSITION) == entry.range_max
    # drive mode 1: the same joint turned the other way
    flipped = msgspec.structs.replace(entry, drive_mode=1)
    async with Actuator(FeetechSTS3215(port, 1, calibration=flipped)) as pan:
        assert pan.device.limits.position == pytest.approx((-high, -low))
        position = await pan.get_value(Request.POSITION_ACTUAL)
        assert position == pytest.approx(-ft.ticks_to_rad(entry.range_max), abs=STEP)


async def test_a_component_writes_a_differing_calibration_only_with_the_torque_off(
    bus: SimFeetechBus, port: FeetechPort
) -> None:
    entry = JointCalibration(id=3, homing_offset=25, range_min=1000, range_max=3000)
    async with Actuator(FeetechSTS3215(port, 3, calibration=entry)):
        assert bus[3].get_raw(S.HOMING_OFFSET) == 25
        assert bus[3].get_raw(S.MAX_ANGLE_LIMIT) == 3000
        assert bus[3].torque_enabled
    other = msgspec.structs.replace(entry, homing_offset=-40)
    with pytest.raises(HALError, match=r"differs from the file's.*torque is on"):
        async with Actuator(FeetechSTS3215(port, 3, calibration=other)):
            pass
    assert bus[3].get_raw(S.HOMING_OFFSET) == 25  # untouched: the servo holds the arm
    with pytest.raises(BadParameterError, match="calibration of servo 1"):
        FeetechSTS3215(port, 1, calibration=entry)


def _so101_with(tmp_path: Path, calibration: str) -> Path:
    text = SO101.read_text().replace(
        "calibration: so101.calibration.yaml", f"calibration: {calibration}"
    )
    assert f"calibration: {calibration}" in text
    rig = tmp_path / "so101.yaml"
    rig.write_text(text)
    return rig


def _run(argv: list[str], stdin: str, monkeypatch: pytest.MonkeyPatch) -> int:
    monkeypatch.setattr("sys.stdin", io.StringIO(stdin))
    return main(argv)


def test_calibrate_through_the_command_line_then_the_rig_speaks_centred_radians(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    calibration = tmp_path / "arm.calibration.yaml"
    rig = _so101_with(tmp_path, str(calibration))
    assert _run(["calibrate", str(rig), "--sim"], "\n\n", monkeypatch) == 0
    out = capsys.readouterr().out
    assert "Move the arm to the middle of its range, then press Enter" in out
    assert f"wrote {calibration} (6 joints)" in out
    written = load_calibration(calibration)
    assert list(written.joints) == [
        "shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll", "gripper"
    ]  # fmt: skip
    pan = written.joints["shoulder_pan"]
    # the simulated hand: the middle 40 x id steps off 2048, the sweep over position_limits
    assert (pan.id, pan.homing_offset) == (1, 40)
    assert pan.radians() == pytest.approx((-1.91986, 1.91986), abs=STEP)
    # rig check reads it; --sim then runs the calibrated arm: centred radians, the range kept
    resolve_rig(load_rig(rig))

    async def check() -> None:
        async with open_rig(load_rig(rig), sim=True) as opened:
            assert "calibrated as" in opened.bus_descriptions["arm"]
            servo = opened.peers["shoulder_pan"]
            assert isinstance(servo, SimStsServo) and servo.get_raw(S.HOMING_OFFSET) == 40
            actuator = opened.actuator("shoulder_pan")
            assert await actuator.get_value(Request.POSITION_ACTUAL) == pytest.approx(0.0, abs=STEP)
            assert actuator.device.limits.position == pytest.approx(pan.radians(), abs=STEP)

    anyio.run(check)
    # a relative calibration path is the rig file's neighbour, whatever the current directory
    rigs, elsewhere = tmp_path / "rigs", tmp_path / "elsewhere"
    rigs.mkdir()
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    relative = _so101_with(rigs, "arm.calibration.yaml")
    assert _run(["calibrate", str(relative), "--sim"], "\n\n", monkeypatch) == 0
    assert f"wrote {rigs / 'arm.calibration.yaml'} (6 joints)" in capsys.readouterr().out
    assert load_calibration(rigs / "arm.calibration.yaml").joints["gripper"].id == 6
    assert not (elsewhere / "arm.calibration.yaml").exists()


def test_calibrate_refuses_a_closed_input_and_other_rigs(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    rig = _so101_with(tmp_path, str(tmp_path / "c.yaml"))
    assert _run(["calibrate", str(rig), "--sim"], "\n", monkeypatch) == 1
    assert "standard input ended before the range step" in capsys.readouterr().err
    assert not (tmp_path / "c.yaml").exists()
    mujoco = SO101.with_name("so101-mujoco.yaml")
    assert _run(["calibrate", str(mujoco)], "", monkeypatch) == 2
    assert "a rig with a serial bus of protocol: feetech" in capsys.readouterr().err
    assert _run(["calibrate", str(rig), "--bus", "nope"], "", monkeypatch) == 2
    assert "--bus" in capsys.readouterr().err


def test_the_rig_option_refuses_a_bad_file_and_a_missing_one_on_a_real_port(
    tmp_path: Path,
) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("version: 1\njoints:\n  shoulder_pan: {id: 1, homing_offset: 0, range_min: 1, range_max: 9, mode: 0}\n")  # fmt: skip
    with pytest.raises(BadParameterError, match=r"bad.yaml:3:\d+: unknown key 'mode'"):
        resolve_rig(load_rig(_so101_with(tmp_path, str(bad))))
    entry = JointCalibration(id=1, homing_offset=0, range_min=1, range_max=9)
    partial = tmp_path / "partial.yaml"
    write_calibration(partial, CalibrationFile(joints={"shoulder_pan": entry}))
    with pytest.raises(BadParameterError, match="an entry for shoulder_lift"):
        resolve_rig(load_rig(_so101_with(tmp_path, str(partial))))
    absent = str(tmp_path / "absent.yaml")
    resolve_rig(load_rig(_so101_with(tmp_path, absent)))  # rig check: calibrate writes it
    options = msgspec.convert(
        {
            "device": "/dev/null",
            "baudrate": 1_000_000,
            "protocol": "feetech",
            "calibration": absent,
        },
        SerialBusOptions,
    )
    with pytest.raises(BadParameterError, match=r"run 'openel-async calibrate RIG\.yaml' first"):
        SerialBusKind().open("arm", options)
    with pytest.raises(BadParameterError, match="only with protocol: feetech"):
        SerialBusKind().check(msgspec.structs.replace(options, protocol="dynamixel"), [])


def test_the_bus_kind_takes_a_relative_calibration_path_from_the_rig_files_directory(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    rigs, elsewhere = tmp_path / "rigs", tmp_path / "elsewhere"
    rigs.mkdir()
    elsewhere.mkdir()
    entry = JointCalibration(id=1, homing_offset=40, range_min=100, range_max=4000)
    written = rigs / "arm.calibration.yaml"
    write_calibration(written, CalibrationFile(joints={"shoulder_pan": entry}))
    monkeypatch.chdir(elsewhere)
    options = msgspec.convert(
        {"device": "/dev/null", "baudrate": 1_000_000, "protocol": "feetech",
         "calibration": "arm.calibration.yaml"},
        SerialBusOptions,
    )  # fmt: skip
    kind = SerialBusKind()
    resolved = kind.resolve_paths(options, rigs)
    assert resolved.calibration == str(written)
    device = SimulatedDevice("shoulder_pan", "serial", "feetech_sts3215", {"servo_id": 1})
    kind.check(resolved, [device])  # reads the file: it exists only next to the rig
    assert kind.device_arguments(None, resolved, device)["calibration"] == entry
    absolute = msgspec.structs.replace(options, calibration=str(written))
    assert kind.resolve_paths(absolute, elsewhere) is absolute
