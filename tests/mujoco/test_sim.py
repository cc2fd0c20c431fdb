"""MujocoSim in lockstep: determinism, completion from the physics, modes, events, sensors."""

from __future__ import annotations

import itertools
import math
from contextlib import AsyncExitStack

import anyio
import mujoco
import numpy as np
import pytest

from openel_async import (
    Actuator,
    ActuatorBank,
    ComponentState,
    DeviceKind,
    EventId,
    EventTimer,
    NotImplementedHALError,
    Request,
    Sensor,
    SensorBank,
)
from openel_async.errors import BadParameterError, StateError
from openel_async.registry import discover_drivers
from openel_mujoco import (
    DRIVER,
    LockstepClock,
    MujocoEffector,
    MujocoEventId,
    MujocoJoint,
    MujocoSensor,
    MujocoSim,
    TrajectoryRecorder,
)
from openel_mujoco.models import MODELS_DIR

from .conftest import ARM6_JOINTS, MOTOR_ONLY_XML, start_rig

Trace = tuple[np.ndarray, np.ndarray, np.ndarray, list[tuple[float, ...]], list[tuple[int, int]]]


def _arm2_ik(x: float, y: float) -> tuple[float, float]:
    l1, l2 = 0.3, 0.25
    c2 = (x * x + y * y - l1 * l1 - l2 * l2) / (2 * l1 * l2)
    q2 = math.acos(max(-1.0, min(1.0, c2)))
    q1 = math.atan2(y, x) - math.atan2(l2 * math.sin(q2), l1 + l2 * math.cos(q2))
    return q1, q2


# --------------------------------------------------------------------------- determinism


async def _scripted_run() -> Trace:
    """An application mixing a timer-driven stream, awaited moves, a mode switch and reads."""
    sim = MujocoSim("arm6", keyframe="home")
    readings: list[tuple[float, ...]] = []
    async with AsyncExitStack() as stack:
        rig = await start_rig(stack, sim, ARM6_JOINTS, ("imu_acc", "wrist_force"))
        recorder = TrajectoryRecorder(sim, list(ARM6_JOINTS), every=2)
        stack.enter_context(recorder)
        timer = await stack.enter_async_context(EventTimer(2.0, clock=sim.clock))
        streamed = rig.actuators["wrist_pitch"]
        acc, force = rig.sensors["imu_acc"], rig.sensors["wrist_force"]

        async def on_tick(timer: EventTimer) -> None:
            tick = timer.last_tick
            assert tick is not None
            await streamed.set_value(0.4 * math.sin(tick.index * 0.02))
            value = await acc.get_timed_value()
            readings.append((*value.values, float(value.time_ns)))

        timer.add_observer(on_tick)
        timer.start_timer()
        moves = [
            await rig.actuators["base_yaw"].set_value(0.8),
            await rig.actuators["shoulder_pitch"].set_value(0.5),
            await rig.actuators["elbow_pitch"].set_value(0.6),
        ]
        for motion in moves:
            await motion
        await rig.actuators["wrist_roll"].set_value(1.5, Request.VELOCITY)
        await sim.sleep(0.2)
        await rig.actuators["wrist_roll"].set_value(0.0, Request.VELOCITY)
        readings.append(await force.get_value())
        timer.stop_timer()
        await timer.wait_idle()
    t, commanded, actual = recorder.arrays()
    events = [(r.time_ns, r.id) for r in rig.events.records]
    return t, commanded, actual, readings, events


async def test_lockstep_runs_are_identical_bit_for_bit() -> None:
    with anyio.fail_after(30):
        first = await _scripted_run()
        second = await _scripted_run()
    t1, c1, a1, r1, e1 = first
    t2, c2, a2, r2, e2 = second
    assert len(t1) > 100
    assert t1.tobytes() == t2.tobytes()
    assert np.array_equal(c1, c2, equal_nan=True)
    assert c1.tobytes() == c2.tobytes() and a1.tobytes() == a2.tobytes()
    assert r1 == r2 and len(r1) > 50
    assert e1 == e2
    assert any(ident == EventId.COMPLETED for _, ident in e1)
    # the trajectory really moved
    assert np.ptp(a1[:, 0]) > 0.7 and np.ptp(a1[:, 3]) > 0.2


# --------------------------------------------------------------------------- completion


async def test_position_move_completes_from_the_physics(stack: AsyncExitStack) -> None:
    sim = MujocoSim("arm2")
    rig = await start_rig(stack, sim, ("shoulder", "elbow"))
    shoulder = rig.actuators["shoulder"]
    device = sim.joints["shoulder"]
    assert device.reports_completion
    trace: list[tuple[int, float, float]] = []
    sim.add_step_hook(lambda: trace.append((sim.clock.now_ns(), device.position, device.velocity)))
    with anyio.fail_after(10):
        motion = await shoulder.set_value(1.0)
        assert not motion.done() and device.pending
        await motion
    assert motion.reached_ns is not None
    duration_s = (motion.reached_ns - motion.issued_ns) / 1e9
    assert 0.15 < duration_s < 1.0  # a 2-3 Hz servo needs a few hundred ms, not 0
    # at completion the physics state is within tolerance and settled, and was for 20 ms
    spec = device.spec
    settled = [(t, q, v) for t, q, v in trace if t > motion.reached_ns - 20_000_000]
    assert settled and all(
        abs(q - 1.0) <= spec.position_tolerance and abs(v) <= spec.settle_velocity
        for _, q, v in settled
    )
    # ... and was not 40 ms earlier (it moved there)
    early = [q for t, q, _ in trace if t < motion.issued_ns + 40_000_000]
    assert abs(early[-1] - 1.0) > 0.1
    assert rig.events.count("event", EventId.COMPLETED, source=shoulder) == 1
    actual = await shoulder.get_value(Request.POSITION_ACTUAL)
    assert actual == pytest.approx(1.0, abs=spec.position_tolerance)
    assert await shoulder.get_value(Request.POSITION) == 1.0  # commanded value


async def test_blocked_target_never_completes(stack: AsyncExitStack) -> None:
    sim = MujocoSim("arm2")
    rig = await start_rig(stack, sim, ("shoulder", "elbow"))
    shoulder, elbow = rig.actuators["shoulder"], rig.actuators["elbow"]
    near = _arm2_ik(0.0, 0.38)  # next to the post at (0, 0.45)
    with anyio.fail_after(10):
        for motion in [await shoulder.set_value(near[0]), await elbow.set_value(near[1])]:
            await motion
        inside = _arm2_ik(0.0, 0.44)  # inside the post: the tip presses on it
        m1 = await shoulder.set_value(inside[0])
        m2 = await elbow.set_value(inside[1])
        await sim.sleep(2.0)
    assert not m1.done() or not m2.done()
    assert sim.joints["shoulder"].pending or sim.joints["elbow"].pending
    touch = await stack.enter_async_context(Sensor(sim.sensor("tip_touch"), clock=sim.clock))
    assert (await touch.get_value())[0] > 0.05  # pressing on the post


async def test_target_beyond_the_joint_range_never_completes_and_hits_the_limit(
    stack: AsyncExitStack,
) -> None:
    sim = MujocoSim("arm2")
    sim.actuator("elbow", position_limits=(-3.0, 3.0))  # wider than the joint range 2.5
    rig = await start_rig(stack, sim, ("elbow",))
    elbow = rig.actuators["elbow"]
    with anyio.fail_after(10):
        motion = await elbow.set_value(2.9)
        await rig.events.wait_for("event", MujocoEventId.LIMIT_REACHED)
        await sim.sleep(1.0)
    assert not motion.done()
    assert await elbow.get_value(Request.POSITION_ACTUAL) == pytest.approx(2.5, abs=0.01)
    assert rig.events.count("event", MujocoEventId.LIMIT_REACHED) == 1  # once per approach


async def test_superseded_target_completes_only_the_latest(stack: AsyncExitStack) -> None:
    sim = MujocoSim("arm2")
    rig = await start_rig(stack, sim, ("shoulder",))
    shoulder = rig.actuators["shoulder"]
    with anyio.fail_after(10):
        first = await shoulder.set_value(1.0)
        await sim.sleep(0.05)
        second = await shoulder.set_value(-0.5)
        await second
    assert first.outcome.value == "superseded"
    assert rig.events.count("event", EventId.COMPLETED) == 1
    assert sim.joints["shoulder"].position == pytest.approx(-0.5, abs=0.01)


# --------------------------------------------------------------------------- control modes


async def test_velocity_torque_and_no_excite_modes(stack: AsyncExitStack) -> None:
    sim = MujocoSim("arm2")
    rig = await start_rig(stack, sim, ("elbow",))
    elbow = rig.actuators["elbow"]
    device = sim.joints["elbow"]
    model = sim.model
    assert device.control_mode is Request.POSITION
    with anyio.fail_after(10):
        motion = await elbow.set_value(0.5, Request.VELOCITY)
        assert device.control_mode is Request.VELOCITY
        assert mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, device.actuators["velocity"])
        await motion  # the joint spins at 0.5 rad/s within tolerance
        assert await elbow.get_value(Request.VELOCITY_ACTUAL) == pytest.approx(0.5, abs=0.02)
        await sim.sleep(0.2)
        position = await elbow.get_value(Request.POSITION_ACTUAL)
        assert position > 0.1  # it moved: 0.5 rad/s for > 0.2 s

        motion = await elbow.set_value(-0.3, Request.TORQUE)
        assert device.control_mode is Request.TORQUE
        await motion
        assert await elbow.get_value(Request.TORQUE_ACTUAL) == pytest.approx(-0.3, abs=1e-9)
        # only the motor acts on the joint: the servos of the other modes are disabled
        force = sim.data.actuator_force
        assert force[device.actuators["position"]] == 0.0
        assert force[device.actuators["velocity"]] == 0.0

        await elbow.set_value(0.0, Request.NO_EXCITE)
        assert device.control_mode is Request.NO_EXCITE
        await sim.sleep(0.01)
        assert await elbow.get_value(Request.TORQUE_ACTUAL) == 0.0

        # back to position: bumpless switch, then a move
        motion = await elbow.set_value(-1.0)
        await motion
    assert await elbow.get_value(Request.POSITION_ACTUAL) == pytest.approx(-1.0, abs=0.01)
    assert rig.events.count("event", EventId.COMPLETED) == 4  # NO_EXCITE completes at once too


async def test_builtin_pd_over_a_motor_only_joint(stack: AsyncExitStack, tmp_path) -> None:  # type: ignore[no-untyped-def]
    path = tmp_path / "pendulum.xml"
    path.write_text(MOTOR_ONLY_XML)
    sim = MujocoSim(path, joints=["hinge"], sensors=["angle"])
    device = sim.joints["hinge"]
    assert device.supported_requests == frozenset(
        {Request.NO_EXCITE, Request.POSITION, Request.VELOCITY, Request.TORQUE}
    )
    assert device.limits.torque == pytest.approx(4.0)  # ctrlrange 2 x gear 2
    assert device.limits.position == (-2.0, 2.0)
    rig = await start_rig(stack, sim, ("hinge",), ("angle",))
    hinge = rig.actuators["hinge"]
    with anyio.fail_after(10):
        motion = await hinge.set_value(0.8)
        assert device.uses_pd and device.control_mode is Request.POSITION
        await motion
        assert device.commanded_position == 0.8
        assert await hinge.get_value(Request.POSITION_ACTUAL) == pytest.approx(0.8, abs=0.01)
        motion = await hinge.set_value(1.0, Request.VELOCITY)
        await motion
        assert await hinge.get_value(Request.VELOCITY_ACTUAL) == pytest.approx(1.0, abs=0.02)
        motion = await hinge.set_value(-0.5, Request.TORQUE)
        assert not device.uses_pd
        await motion
    assert sim.data.ctrl[0] == pytest.approx(-0.25)  # joint torque / gear
    (angle,) = await rig.sensors["angle"].get_value()
    assert rig.sensors["angle"].units == ("rad",)
    assert math.isfinite(angle)


def test_streamed_commands_write_ctrl_through_the_current_drive(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """Repeated commands in the current mode take the one-write path; every mode switch
    (native actuator, built-in PD, de-energized) re-derives it."""
    path = tmp_path / "pendulum.xml"
    path.write_text(MOTOR_ONLY_XML)
    sim = MujocoSim(path, joints=["hinge"])
    device = sim.joints["hinge"]
    for torque in (0.5, -1.5, 3.0):  # the motor: ctrl = joint torque / gear
        device.command_nowait(Request.TORQUE, torque)
        assert sim.data.ctrl[0] == pytest.approx(torque / 2)
        assert device.pending and not device.uses_pd
    device.command_nowait(Request.POSITION, 0.3)  # built-in PD: the target, not ctrl
    assert device.uses_pd and device.commanded_position == 0.3
    device.command_nowait(Request.POSITION, 0.4)
    assert device.commanded_position == 0.4
    sim.step(1)
    pd_ctrl = float(sim.data.ctrl[0])
    assert pd_ctrl != 0.0
    device.command_nowait(Request.NO_EXCITE, 0.0)
    assert not device.pending and sim.data.ctrl[0] == 0.0
    device.command_nowait(Request.TORQUE, 1.0)
    device.command_nowait(Request.TORQUE, 2.0)
    assert sim.data.ctrl[0] == pytest.approx(1.0) and device.commands == 8


async def test_unsupported_mode_is_refused(stack: AsyncExitStack) -> None:
    xml = """<mujoco><worldbody><body><joint name="j" type="slide" axis="1 0 0"/>
      <geom type="box" size=".1 .1 .1" mass="1"/></body></worldbody>
      <actuator><position name="servo" joint="j" kp="100" kv="10"/></actuator></mujoco>"""
    sim = MujocoSim(mujoco.MjModel.from_xml_string(xml))
    device = sim.actuator("j")
    assert device.supported_requests == frozenset({Request.POSITION, Request.NO_EXCITE})
    assert not device.rotational
    rig = await start_rig(stack, sim, ("j",))
    with pytest.raises(NotImplementedHALError, match="VELOCITY"):
        await rig.actuators["j"].set_value(0.1, Request.VELOCITY)
    with anyio.fail_after(10):
        await (await rig.actuators["j"].set_value(0.05))
    assert sim.joints["j"].position == pytest.approx(0.05, abs=0.01)


# --------------------------------------------------------------------------- events


async def test_joint_limit_event_once_per_approach(stack: AsyncExitStack) -> None:
    sim = MujocoSim("arm2")
    rig = await start_rig(stack, sim, ("elbow",))
    elbow = rig.actuators["elbow"]
    with anyio.fail_after(10):
        await elbow.set_value(0.5, Request.TORQUE)
        first = await rig.events.wait_for("event", MujocoEventId.LIMIT_REACHED)
        assert sim.joints["elbow"].position == pytest.approx(2.5, abs=0.01)
        await sim.sleep(0.5)
        assert rig.events.count("event", MujocoEventId.LIMIT_REACHED) == 1  # resting there
        await elbow.set_value(-0.5, Request.TORQUE)
        second = await rig.events.wait_for("event", MujocoEventId.LIMIT_REACHED, count=2)
    assert sim.joints["elbow"].position == pytest.approx(-2.5, abs=0.01)
    assert first.source is elbow and second.time_ns > first.time_ns
    assert MujocoEventId.LIMIT_REACHED == EventId.LIMIT_REACHED == 2


async def test_an_unlimited_joint_never_reaches_a_limit(stack: AsyncExitStack) -> None:
    xml = """<mujoco><worldbody><body><joint name="spin" type="hinge" axis="0 0 1"/>
      <geom type="cylinder" size=".1 .02" mass="1"/></body></worldbody>
      <actuator><velocity name="spin_vel" joint="spin" kv="0.5"/></actuator></mujoco>"""
    sim = MujocoSim(mujoco.MjModel.from_xml_string(xml))
    assert sim.actuator("spin").limits.position == (-math.inf, math.inf)
    rig = await start_rig(stack, sim, ("spin",))
    with anyio.fail_after(10):
        await (await rig.actuators["spin"].set_value(20.0, Request.VELOCITY))
        await sim.sleep(2.0)  # several turns
    assert sim.joints["spin"].position > 30.0
    assert rig.events.count("event", MujocoEventId.LIMIT_REACHED) == 0
    assert rig.events.count("event", MujocoEventId.SATURATED) == 0  # no force limit
    assert rig.events.count("event", EventId.COMPLETED) == 1


async def test_saturation_event_on_a_large_position_step(stack: AsyncExitStack) -> None:
    sim = MujocoSim("arm6", keyframe="home")
    rig = await start_rig(stack, sim, ("base_yaw",))
    base = rig.actuators["base_yaw"]
    with anyio.fail_after(10):
        motion = await base.set_value(2.0)  # kp 1500 x 2 rad >> forcerange 60 N m
        await rig.events.wait_for("event", MujocoEventId.SATURATED)
        force = sim.data.actuator_force[sim.joints["base_yaw"].actuators["position"]]
        assert abs(force) == pytest.approx(60.0)
        await motion
    # saturated accelerating (+60 N m), then braking (-60 N m): one event per episode
    assert 1 <= rig.events.count("event", MujocoEventId.SATURATED) <= 2
    # the saturation came before completion
    kinds = [r.id for r in rig.events.records]
    assert kinds.index(MujocoEventId.SATURATED) < kinds.index(EventId.COMPLETED)


async def test_monitors_follow_a_mode_switch_made_while_stepping(stack: AsyncExitStack) -> None:
    """The per-step monitors read their bands from a plan rebuilt on every change: after a
    switch to VELOCITY the force of the velocity servo is watched (the position servo's,
    disabled now, stays 0)."""
    sim = MujocoSim("arm6", keyframe="home")
    rig = await start_rig(stack, sim, ("base_yaw",))
    base = rig.actuators["base_yaw"]
    with anyio.fail_after(10):
        await (await base.set_value(0.0))  # POSITION: settles where it is, no saturation
        assert rig.events.count("event", MujocoEventId.SATURATED) == 0
        await base.set_value(2.0, Request.VELOCITY)  # kv 60 x 2 rad/s >> 60 N m
        await rig.events.wait_for("event", MujocoEventId.SATURATED)
    joint = sim.joints["base_yaw"]
    assert sim.data.actuator_force[joint.actuators["velocity"]] == pytest.approx(60.0)
    assert sim.data.actuator_force[joint.actuators["position"]] == 0.0


# --------------------------------------------------------------------------- sensors and clock


async def test_banks_over_different_sensor_lists_read_their_own_slices(
    stack: AsyncExitStack,
) -> None:
    """The simulation plans how to cut ``sensordata`` for the list of sensors read together;
    banks over other lists (another order, a subset, one sensor) alternating with it each
    get their own sensors' values."""
    sim = MujocoSim("arm6", keyframe="home")
    names = ("imu_acc", "imu_gyro", "wrist_force", "tool_pos", "pad_touch")
    rig = await start_rig(stack, sim, (), names)
    orders = [names, names[::-1], ("tool_pos", "imu_acc"), ("pad_touch",)]
    banks = [SensorBank(rig.sensors[n] for n in order) for order in orders]
    await sim.sleep(0.01)
    async with sim.paused():
        for _ in range(2):
            for order, bank in zip(orders, banks, strict=True):
                expected = tuple(sim.sensors[n].values for n in order)
                assert bank.get_values_nowait() == expected
                assert all(type(v) is tuple for v in expected)


async def test_sensors_read_si_values_with_monotonic_sim_timestamps(
    stack: AsyncExitStack,
) -> None:
    sim = MujocoSim("arm2")
    names = ("imu_acc", "imu_gyro", "tip_pos", "tip_touch", "elbow_pos_sensor")
    rig = await start_rig(stack, sim, (), names)
    acc, gyro, tip = rig.sensors["imu_acc"], rig.sensors["imu_gyro"], rig.sensors["tip_pos"]
    assert acc.units == ("m/s^2",) * 3 and gyro.units == ("rad/s",) * 3
    assert tip.units == ("m",) * 3 and rig.sensors["tip_touch"].units == ("N",)
    assert rig.sensors["elbow_pos_sensor"].units == ("rad",)
    assert acc.kind is DeviceKind.ACCEL and gyro.kind is DeviceKind.GYRO
    assert rig.sensors["tip_touch"].kind is DeviceKind.TOUCH
    assert rig.sensors["elbow_pos_sensor"].kind is DeviceKind.ROTARY_ANGLE
    assert acc.device_name == "HalAccelMuJoCoImuAcc"

    clock = sim.clock
    assert isinstance(clock, LockstepClock)
    with anyio.fail_after(10):
        await clock.sleep(0.1)
        first = await acc.get_timed_value()
        # an arm at rest measures the proper acceleration +g along world z (site frame = world)
        assert first.values == pytest.approx((0.0, 0.0, 9.81), abs=0.02)
        assert (await gyro.get_value()) == pytest.approx((0.0, 0.0, 0.0), abs=1e-6)
        assert (await tip.get_value()) == pytest.approx((0.55, 0.0, 0.1), abs=1e-3)
        # the values are those of the state at the start of the latest step: time = now - dt
        assert first.time_ns == clock.now_ns() - sim.timestep_ns
        times = [first.time_ns]
        for _ in range(5):
            await clock.sleep(0.0035)
            times.append((await acc.get_timed_value()).time_ns)
        again = await acc.get_timed_value()
    assert all(b > a for a, b in itertools.pairwise(times))
    assert again.time_ns == times[-1]  # no step in between: same state, same time
    assert times[-1] - times[0] == 5 * 4_000_000  # 3.5 ms sleeps end on 1 ms step boundaries


async def test_event_timer_on_the_sim_clock_ticks_at_the_physics_rate(
    stack: AsyncExitStack,
) -> None:
    sim = MujocoSim("arm2")
    await stack.enter_async_context(sim)
    timer = await stack.enter_async_context(EventTimer(1.0, clock=sim.clock))
    ticks: list[tuple[int, int]] = []
    done = anyio.Event()

    def on_tick(timer: EventTimer) -> None:
        ticks.append((sim.clock.now_ns(), sim.steps))
        if len(ticks) == 100:
            timer.stop_timer()
            done.set()

    timer.add_observer(on_tick)
    timer.start_timer()
    with anyio.fail_after(10):
        await done.wait()
    assert [t for t, _ in ticks] == [1_000_000 * (i + 1) for i in range(100)]
    assert [s for _, s in ticks] == list(range(1, 101))  # one physics step per tick
    assert timer.stats.lateness.max_ns == 0 and timer.stats.missed_ticks == 0


# --------------------------------------------------------------------------- devices and api


def test_device_identity_limits_and_lookup() -> None:
    sim = MujocoSim("arm6", keyframe="home")
    joint = sim.actuator("shoulder_pitch")
    assert isinstance(joint, MujocoJoint)
    assert sim.actuator("shoulder_pitch") is joint and sim.joints["shoulder_pitch"] is joint
    assert joint.limits.position == (-1.9, 1.9)
    assert joint.limits.velocity == 3.0 and joint.limits.torque == 60.0
    assert joint.info.kind is DeviceKind.MOTOR and joint.info.vendor_name == "MuJoCo"
    assert joint.info.product_name == "ShoulderPitch"
    with pytest.raises(BadParameterError, match="options"):
        sim.actuator("shoulder_pitch", max_velocity=1.0)
    with pytest.raises(BadParameterError, match="joint"):
        sim.actuator("shoulder_pitch", name="other")  # a second device on the same joint
    with pytest.raises(BadParameterError, match=r"max_speed=1\.0 .*JointSpec field"):
        sim.actuator("elbow_pitch", max_speed=1.0)
    sensor = sim.sensor("wrist_force")
    assert isinstance(sensor, MujocoSensor) and sensor.dim == 3
    assert sensor.units == ("N",) * 3 and sim.sensor("wrist_force") is sensor
    assert sim.sensor("wrist_torque").units == ("N m",) * 3
    assert sim.sensor("tool_pos").info.kind is DeviceKind.DISTANCE
    assert "HalMotor" not in repr(sensor) and "wrist_force" in repr(sensor)
    custom = sim.sensor("pad_touch", name="pad", units=("newton",), kind=0x99)
    assert custom.units == ("newton",) and custom.info.kind == 0x99 and sim.sensors["pad"] is custom
    with pytest.raises(BadParameterError, match="units"):
        sim.sensor("imu_acc", units=("m/s^2",))


async def test_one_device_per_component_and_no_step_while_running(
    stack: AsyncExitStack,
) -> None:
    sim = MujocoSim("arm2")
    rig = await start_rig(stack, sim, ("shoulder",))
    with pytest.raises(Exception, match="already belongs"):
        async with Actuator(sim.joints["shoulder"], clock=sim.clock):
            pass
    with pytest.raises(StateError, match="step"):
        sim.step()
    with pytest.raises(StateError):
        await sim.__aenter__()
    shoulder = rig.actuators["shoulder"]
    assert shoulder.state is ComponentState.ACTIVE
    with anyio.fail_after(10):  # the first component still owns the device
        await (await shoulder.set_value(0.3))
    assert rig.events.count("event", EventId.COMPLETED, source=shoulder) == 1


def test_offline_stepping_and_lockstep_clock() -> None:
    sim = MujocoSim("arm2")
    assert sim.step(10) == 10
    assert sim.time_ns == 10_000_000 == sim.clock.now_ns()
    assert sim.data.time == pytest.approx(0.01)
    with pytest.raises(BadParameterError, match="clock"):
        MujocoSim("arm2", clock=sim.clock)
    with pytest.raises(BadParameterError, match="pacing"):
        MujocoSim("arm2", pacing="fast")  # type: ignore[arg-type]
    with pytest.raises(BadParameterError, match="timestep"):
        MujocoSim("arm2", timestep=0.0)
    fine = MujocoSim("arm2", timestep=0.0005)
    assert fine.timestep_ns == 500_000


def test_driver_entry_point() -> None:
    assert DRIVER.name == "mujoco"
    assert {"joint": MujocoJoint, "effector": MujocoEffector, "sensor": MujocoSensor}.items() <= (
        DRIVER.devices.items()
    )
    entries = {e.name: e for e in discover_drivers()}
    assert entries["mujoco"].info is DRIVER, entries["mujoco"].error


@pytest.mark.render
async def test_render_snapshot_pauses_lockstep_time(stack: AsyncExitStack, tmp_path) -> None:  # type: ignore[no-untyped-def]
    sim = MujocoSim("arm2")
    await start_rig(stack, sim, ("shoulder",))
    await sim.sleep(0.05)
    before = sim.clock.now_ns()
    with anyio.fail_after(30):
        out = await sim.render_snapshot(tmp_path / "arm2.png", width=96, height=64)
    assert sim.clock.now_ns() == before  # no physics while the worker thread rendered
    if out is not None:  # None: no OpenGL on this machine (documented)
        assert out.stat().st_size > 100


async def test_keyframe_start_holds_the_initial_pose(stack: AsyncExitStack) -> None:
    xml = (MODELS_DIR / "arm2.xml").read_text()
    xml = xml.replace(
        "</mujoco>", '<keyframe><key name="bent" qpos="0.5 -0.7"/></keyframe></mujoco>'
    )
    sim = MujocoSim(mujoco.MjModel.from_xml_string(xml), keyframe="bent")
    rig = await start_rig(stack, sim, ("shoulder", "elbow"))
    with anyio.fail_after(10):
        await sim.sleep(0.5)
    assert sim.joints["shoulder"].position == pytest.approx(0.5, abs=1e-3)
    assert sim.joints["elbow"].position == pytest.approx(-0.7, abs=1e-3)
    assert await rig.actuators["elbow"].get_value(Request.POSITION) == pytest.approx(-0.7)
    sim.reset()  # back to the keyframe, still holding
    assert sim.joints["elbow"].commanded_position == pytest.approx(-0.7)


async def test_a_joint_batch_writes_the_ctrl_of_command_nowait_and_counts_per_batch(
    stack: AsyncExitStack,
) -> None:
    """A bank's joint batch writes each joint's ctrl as ``command_nowait`` would, scaled
    (a geared motor's TORQUE: ctrl = value / gear) or not (POSITION servos: value as it
    is), and counts once per call: every joint's ``commands`` includes every batch of every
    bank it belongs to."""
    geared = MujocoSim(mujoco.MjModel.from_xml_string(MOTOR_ONLY_XML))
    rig = await start_rig(stack, geared, joints=("hinge",))
    hinge = rig.actuators["hinge"]
    hinge.set_value_nowait(0.0, Request.TORQUE)  # TORQUE is the motor's direct mode
    joint = geared.joints["hinge"]
    act = joint._drive_act
    assert act is not None
    torque_bank = ActuatorBank([hinge])
    assert torque_bank._batch is not None
    torque_bank.set_values_nowait([0.3], Request.TORQUE)
    batched = float(geared.data.ctrl[act])
    joint.command_nowait(Request.TORQUE, 0.3)
    assert batched == float(geared.data.ctrl[act]) == 0.3 * 0.5
    assert joint.commands == 3

    arm = MujocoSim("arm2")
    rig2 = await start_rig(stack, arm, joints=("shoulder", "elbow"))
    actuators = [rig2.actuators["shoulder"], rig2.actuators["elbow"]]
    banks = [ActuatorBank(actuators), ActuatorBank(actuators[::-1])]
    joints = [arm.joints["shoulder"], arm.joints["elbow"]]
    assert [j._drive_scale for j in joints] == [1.0, 1.0]  # position servos: ctrl = value
    banks[0].set_values_nowait([0.125, -0.25])
    assert [float(arm.data.ctrl[j._drive_act]) for j in joints] == [0.125, -0.25]
    banks[1].set_values_nowait([0.5, 0.75])
    banks[0].set_values_nowait([0.0, 0.1])
    actuators[0].set_value_nowait(0.2)
    assert [j.commands for j in joints] == [4, 3]
    assert [j._target for j in joints] == [0.2, 0.1]
