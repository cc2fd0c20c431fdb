"""The joint-state sample: the commanded position the actuator's listener heard and the
device's own actual-position read, taken without reading through the framework (so no
reading records of its own, and no side effect on the actuators)."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import anyio
import pytest

from openel_async import Actuator, ActuatorBank, ComponentState, EventTimer, Request, VirtualClock
from openel_async.cli import main as cli_main
from openel_async.device import DeviceInfo
from openel_async.recording import Recorder, read_recording
from openel_sim import SimMotor

from .schema_check import check_recording


class _GlitchyMotor(SimMotor):
    """A sim motor whose position read returns NaN while ``glitch`` is set."""

    glitch = False

    def read_nowait(self, request: Request) -> float:
        value = super().read_nowait(request)
        return math.nan if self.glitch and request is Request.POSITION_ACTUAL else value


async def _run(path: Path) -> tuple[list[Actuator], list[_GlitchyMotor]]:
    """Two axes streamed by a bank at every 10 ms tick for 0.3 s; the first axis's
    device reads NaN from 0.1 s to 0.2 s."""
    clock = VirtualClock()
    motors = [_GlitchyMotor(max_velocity=3.0, max_acceleration=40.0) for _ in range(2)]
    recorder = Recorder(path, joint_period_ms=10)
    async with clock.autojump(), recorder:
        axes = [Actuator(m, device_name=f"AXIS_{i}", clock=clock) for i, m in enumerate(motors)]
        timer = EventTimer(10, clock=clock, name="loop")
        for axis in axes:
            recorder.observe(axis)
        recorder.observe_timer(timer)
        async with axes[0], axes[1], timer:
            bank = ActuatorBank(axes)
            ticks = 0
            done = anyio.Event()

            def on_tick(t: EventTimer) -> None:
                nonlocal ticks
                ticks += 1
                motors[0].glitch = 10 <= ticks < 20
                bank.set_values_nowait([0.01 * ticks, -0.02 * ticks])
                if ticks == 30:
                    t.stop_timer()
                    done.set()

            timer.add_observer(on_tick)
            timer.start_timer()
            await done.wait()
            states = [axis.state for axis in axes]
    assert states == [ComponentState.ACTIVE, ComponentState.ACTIVE]
    return axes, motors


async def test_joint_states_from_the_listener_and_the_device(tmp_path: Path) -> None:
    path = tmp_path / "joints.mcap"
    await _run(path)
    rec = read_recording(path)
    samples = rec.topic("/joint_states")
    assert len(samples) >= 25
    commanded = {
        name: {
            m["time_ns"]: m["value"] for m in rec.topic(f"/hal/{name}") if m["kind"] == "command"
        }
        for name in ("AXIS_0", "AXIS_1")
    }
    glitched = 0
    for sample in samples:
        t = sample["time_ns"]
        for joint in sample["joints"]:
            sent = commanded[joint["name"]]
            before = [v for when, v in sent.items() if when < t]
            # The latest setpoint streamed (0.0 before any): the tap's timer observer was
            # added first, so the sample precedes the setpoint of its own tick.
            assert joint["commanded"] == (before[-1] if before else 0.0)
            if "position" not in joint:  # unknown: left out, as the schema has it
                glitched += 1
                assert joint["name"] == "AXIS_0"
            else:
                assert math.isfinite(joint["position"])
    assert 5 <= glitched <= 10  # the NaN reads: recorded as unknown, no fault of the axis
    for name in ("AXIS_0", "AXIS_1"):  # the sample's reads are not the application's
        assert not [m for m in rec.topic(f"/hal/{name}") if m["kind"] == "reading"]
        assert [m["state"] for m in rec.topic(f"/hal/{name}") if m["kind"] == "state"] == [
            "Initialized",
            "Active",
            "Finalized",
        ]


class _CountingMotor(SimMotor):
    """A sim motor counting its position reads."""

    reads = 0

    def read_nowait(self, request: Request) -> float:
        if request is Request.POSITION_ACTUAL:
            self.reads += 1
        return super().read_nowait(request)


async def test_the_sample_takes_the_apps_own_read_at_the_same_time(tmp_path: Path) -> None:
    """When the application read the actual position at the sample's clock time, the
    sample takes that value (no second device read); at another time it reads the device."""
    clock = VirtualClock()
    recorder = Recorder(tmp_path / "a.mcap")
    recorder.pipeline.start = lambda: None  # type: ignore[method-assign]  # no writer
    motor = _CountingMotor(max_velocity=3.0)
    axis = Actuator(motor, device_name="AXIS", clock=clock)
    recorder.observe(axis)
    queue = recorder.pipeline.queue

    def sample() -> float | None:
        recorder.sample(clock.now_ns())
        entry = queue.pop()
        ((_, _, actual),) = entry[4]
        return actual  # type: ignore[no-any-return]

    async with clock.autojump(), axis:
        axis.set_value_nowait(1.0, Request.POSITION)
        await clock.sleep(0.1)
        read = axis.get_value_nowait(Request.POSITION_ACTUAL)
        before = motor.reads
        assert sample() == read and motor.reads == before  # the app's read, reused
        await clock.sleep(0.05)  # moving on: the device is read
        actual = sample()
        assert motor.reads == before + 1 and actual is not None and actual > read
    axis.set_listener(None)


async def test_samples_keep_their_period_when_ticks_do_not_divide_it(tmp_path: Path) -> None:
    """A 3 ms timer and 20 ms joint states (and 100 ms statistics): the tap looks every 6
    ticks (18 ms), and the samples stay on a 20 ms grid on average (not one per 36 ms)."""
    clock = VirtualClock()
    path = tmp_path / "grid.mcap"
    async with clock.autojump(), Recorder(path, joint_period_ms=20) as recorder:
        axis = Actuator(SimMotor(), device_name="AXIS", clock=clock)
        timer = EventTimer(3, clock=clock, name="loop")
        recorder.observe(axis)
        recorder.observe_timer(timer)
        async with axis, timer:
            timer.start_timer()
            await clock.sleep(1.2)
            timer.stop_timer()
            delivered = timer.ticks_delivered
    rec = read_recording(path)
    times = [m["time_ns"] for m in rec.topic("/joint_states")]
    assert 59 <= len(times) <= 61  # 1.2 s / 20 ms
    gaps = {b - a for a, b in itertools.pairwise(times)}
    assert gaps <= {18_000_000, 36_000_000} and max(times) - min(times) >= 1_150_000_000
    stats = rec.topic("/timer/loop")
    assert 12 <= len(stats) <= 14  # every 100 ms, and the rest at the exit
    assert sum(m["ticks"] for m in stats) == delivered >= 399


def test_can_joint_states_carry_the_drives_reported_positions(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """On CAN the app reads POSITION_ACTUAL with an awaited ``get_value`` (I/O: the reading
    comes after the sample's instant, and the drive has no synchronous read): every sample
    after the first read carries the app's latest read (every one was null), and every
    message matches its channel's schema."""
    path = tmp_path / "can.mcap"
    code = cli_main(
        ["demo", "--bus", "can", "--duration", "0.6", "--no-live", "--record", str(path)]
    )
    assert code == 0, capsys.readouterr().err
    assert check_recording(path) > 0
    rec = read_recording(path)
    reads = {
        name: [
            (m["time_ns"], m["value"])
            for m in rec.topic(f"/hal/{name}")
            if m["kind"] == "reading" and m["request"] == "POSITION_ACTUAL"
        ]
        for name in ("MOTOR_1", "MOTOR_2")
    }
    samples = rec.topic("/joint_states")
    first_read = min(times[0][0] for times in reads.values())
    later = [s for s in samples if s["time_ns"] > first_read + 100_000_000]
    assert len(later) >= 10
    for sample in later:
        for joint in sample["joints"]:
            latest = [v for t, v in reads[joint["name"]] if t <= sample["time_ns"]][-1]
            assert joint["position"] == latest, sample


class _SuctionCup(SimMotor):
    """An actuator of a HAL extension kind (128): no joint."""

    info = DeviceInfo(kind=0x80, vendor_id=0x0E1, product_id=0x999, product_name="Cup")


async def test_only_joints_go_into_joint_states(tmp_path: Path) -> None:
    """A non-joint actuator (an extension kind, a suction cup) has its channel, not a joint
    state; the channels of the actuators say their unit and whether they are joints."""
    path = tmp_path / "cup.mcap"
    clock = VirtualClock()
    async with clock.autojump(), Recorder(path) as recorder:
        axis = Actuator(SimMotor(), device_name="AXIS", clock=clock)
        cup = Actuator(_SuctionCup(), device_name="CUP", clock=clock)
        timer = EventTimer(10, clock=clock, name="loop")
        for component in (axis, cup):
            recorder.observe(component)
        recorder.observe_timer(timer)
        async with axis, cup, timer:
            timer.start_timer()
            cup.set_value_nowait(1.0, Request.POSITION)
            await clock.sleep(0.1)
            timer.stop_timer()
    rec = read_recording(path)
    samples = rec.topic("/joint_states")
    assert samples and all([j["name"] for j in s["joints"]] == ["AXIS"] for s in samples)
    assert [m["kind"] for m in rec.topic("/hal/CUP")].count("command") == 1
    meta = {c.topic: c.metadata for c in rec.channels.values()}
    assert meta["/hal/AXIS"]["joint"] == "true" and meta["/hal/AXIS"]["unit"] == "rad"
    assert meta["/hal/CUP"]["joint"] == "false"
    check_recording(path)


async def test_glitched_joint_states_match_their_schema(tmp_path: Path) -> None:
    """A position that could not be read is left out of its joint state (it was null where
    the schema says number)."""
    path = tmp_path / "glitch.mcap"
    await _run(path)
    assert check_recording(path) > 0
