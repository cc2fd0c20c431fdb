"""The lockstep control step's fast paths keep every check: the SensorBank's batch reader
(``MujocoSensor.batch_reader``), the ActuatorBank's inline tick over joints with different
ranges, and the per-step joint monitor generated per plan (``monitor_plan``)."""

from __future__ import annotations

import math
from collections.abc import Callable
from contextlib import AsyncExitStack

import numpy as np
import pytest

from openel_async import ActuatorBank, ComponentState, DeviceFaultError, Request, SensorBank
from openel_async.errors import BadParameterError, HALError, StateError
from openel_mujoco import MujocoSim, joint_plans
from openel_mujoco import sim as mujoco_sim
from openel_mujoco.devices import MujocoEventId, MujocoJoint, MujocoSensor, monitor_plan

from .conftest import ARM6_JOINTS, start_rig

# sensordata of arm6: imu_acc 28-31, imu_gyro 31-34, wrist_force 18-21, wrist_torque 21-24,
# tool_pos 24-27, pad_touch 27-28
GATHERED = ("imu_acc", "imu_gyro", "wrist_force", "wrist_torque", "tool_pos", "pad_touch")
CONTIGUOUS = ("wrist_force", "wrist_torque", "tool_pos", "pad_touch")
WITH_GAP = ("imu_gyro", "wrist_torque", "pad_touch", "imu_acc")  # tool_pos lies between
SPARSE = ("base_yaw_pos_sensor", "imu_gyro")  # sensordata 0 and 31-34: one gather


# -- SensorBank through MujocoSensor.batch_reader --------------------------------------------


@pytest.mark.parametrize("order", [GATHERED, CONTIGUOUS, WITH_GAP, SPARSE, ("imu_gyro",)])
async def test_batch_reader_reads_what_each_sensor_reads(
    stack: AsyncExitStack, order: tuple[str, ...]
) -> None:
    sim = MujocoSim("arm6", keyframe="home")
    rig = await start_rig(stack, sim, ARM6_JOINTS[:2], order)
    await rig.actuators["shoulder_pitch"].set_value(0.4)
    await sim.sleep(0.05)
    devices = [sim.sensors[name] for name in order]
    reader = MujocoSensor.batch_reader(devices)
    assert reader is not None
    flat, values = reader()
    assert values == tuple(device.values for device in devices)
    assert all(type(v) is tuple and all(type(x) is float for x in v) for v in values)
    held = list(flat)  # every value of the bank (a span may hold the values between)
    for value in sum(values, ()):
        held.remove(value)
    assert len(held) == (3 if order == WITH_GAP else 0)
    bank = SensorBank(rig.sensors[name] for name in order)
    assert bank.get_values_nowait() == values  # no step between: the same state
    assert bank.get_values_nowait() == tuple(rig.sensors[n].get_value_nowait() for n in order)


def test_batch_reader_only_for_sensors_of_one_simulation() -> None:
    one, two = MujocoSim("arm6"), MujocoSim("arm6")
    assert MujocoSensor.batch_reader([one.sensor("imu_acc"), two.sensor("imu_gyro")]) is None
    assert MujocoSensor.batch_reader([one.sensor("imu_acc"), one.sensor("imu_gyro")]) is not None


async def test_a_non_finite_value_in_the_batch_faults_only_its_own_sensor(
    stack: AsyncExitStack,
) -> None:
    sim = MujocoSim("arm6", keyframe="home")
    rig = await start_rig(stack, sim, (), GATHERED)
    bank = SensorBank(rig.sensors[name] for name in GATHERED)
    first = bank.get_values_nowait()  # the fast path is armed (every member seen Active)
    assert len(first) == len(GATHERED)
    # a NaN outside the bank changes nothing; one inside faults its own sensor only
    outside = SensorBank([rig.sensors["imu_acc"]])
    sim.data.sensordata[int(sim.model.sensor_adr[sim.sensors["wrist_torque"].sensor_id]) + 1] = (
        math.nan
    )
    assert outside.get_values_nowait() == (sim.sensors["imu_acc"].values,)
    with pytest.raises(DeviceFaultError, match="non-finite") as info:
        bank.get_values_nowait()
    assert rig.sensors["wrist_torque"].device_name in str(info.value)
    assert [rig.sensors[n].state for n in GATHERED] == [
        ComponentState.ERROR if n == "wrist_torque" else ComponentState.ACTIVE for n in GATHERED
    ]
    with pytest.raises(StateError):
        bank.get_values_nowait()
    assert rig.events.count("error") == 1


async def test_a_non_finite_value_between_the_banks_sensors_faults_nobody(
    stack: AsyncExitStack,
) -> None:
    sim = MujocoSim("arm6", keyframe="home")
    rig = await start_rig(stack, sim, (), WITH_GAP)
    bank = SensorBank(rig.sensors[name] for name in WITH_GAP)
    bank.get_values_nowait()
    tool_pos = int(sim.model.sensor_adr[sim.model.sensor("tool_pos").id])
    sim.data.sensordata[tool_pos] = math.nan  # not a sensor of the bank
    assert bank.get_values_nowait() == tuple(sim.sensors[n].values for n in WITH_GAP)
    assert {rig.sensors[n].state for n in WITH_GAP} == {ComponentState.ACTIVE}
    sim.data.sensordata[int(sim.model.sensor_adr[sim.model.sensor("pad_touch").id])] = math.inf
    with pytest.raises(DeviceFaultError, match="non-finite"):
        bank.get_values_nowait()
    assert [rig.sensors[n].state for n in WITH_GAP] == [
        ComponentState.ERROR if n == "pad_touch" else ComponentState.ACTIVE for n in WITH_GAP
    ]


async def test_a_faulted_simulation_reaches_the_bank_through_the_batch_reader(
    stack: AsyncExitStack,
) -> None:
    sim = MujocoSim("arm6", keyframe="home")
    rig = await start_rig(stack, sim, ("base_yaw",), GATHERED)
    bank = SensorBank(rig.sensors[name] for name in GATHERED)
    bank.get_values_nowait()
    reader = MujocoSensor.batch_reader([sim.sensors[name] for name in GATHERED])
    assert reader is not None
    sim.data.qvel[0] = np.nan
    await sim.sleep(0.01)  # the next step finds the bad state
    assert sim.fault is not None
    with pytest.raises(HALError, match="faulted"):
        reader()
    with pytest.raises(StateError):  # every component went to Error: the bank sees it
        bank.get_values_nowait()
    assert {rig.sensors[n].state for n in GATHERED} == {ComponentState.ERROR}


# -- ActuatorBank inline tick over joints with different ranges ------------------------------


async def test_inline_tick_checks_each_joint_against_its_own_range(
    stack: AsyncExitStack, monkeypatch: pytest.MonkeyPatch
) -> None:
    sim = MujocoSim("arm6", keyframe="home")
    rig = await start_rig(stack, sim, ARM6_JOINTS)
    bank = ActuatorBank(rig.actuators[j] for j in ARM6_JOINTS)
    ranges = [rig.actuators[j].device.limits.position for j in ARM6_JOINTS]
    assert len(set(ranges)) > 1  # arm6's joints do not share one range
    acts = [sim.joints[j]._drive_act for j in ARM6_JOINTS]

    def no_slow_path(*args: object) -> object:
        raise AssertionError("the streaming tick left the inline path")

    targets = [0.1, -0.2, 0.3, -0.1, 0.2, 0.05]
    with monkeypatch.context() as patch:
        patch.setattr(bank, "_check", no_slow_path)
        bank.set_values_nowait(targets, Request.POSITION)
    assert [sim.data.ctrl[a] for a in acts] == targets
    assert all(sim.joints[j].pending for j in ARM6_JOINTS)

    # the joint with the lowest upper limit, just above it: inside another joint's range
    k = min(range(len(ranges)), key=lambda i: ranges[i][1])
    above = ranges[k][1] + 0.01
    assert any(low <= above <= high for low, high in ranges)
    before = sim.data.ctrl.copy()
    for bad in (math.nan, math.inf, -math.inf, above):
        values = [0.0] * len(ARM6_JOINTS)
        values[k] = bad
        with pytest.raises(BadParameterError, match=rf"values\[{k}\]"):
            bank.set_values_nowait(values, Request.POSITION)
        assert sim.data.ctrl.tobytes() == before.tobytes()  # nothing sent
    with pytest.raises(BadParameterError, match=r"values\[0\]"):
        bank.set_values_nowait([math.nan, *targets[1:]], Request.POSITION)
    assert sim.data.ctrl.tobytes() == before.tobytes()


# -- the generated joint monitor ------------------------------------------------------------


async def test_monitor_code_is_compiled_once_per_shape(stack: AsyncExitStack) -> None:
    sim = MujocoSim("arm6", keyframe="home")
    await start_rig(stack, sim, ARM6_JOINTS)
    joints = [sim.joints[j] for j in ARM6_JOINTS]
    views = (sim._qpos_items, sim._qvel_items, sim._force_items)
    first = monitor_plan(joints, *views)
    joints[1]._saturated = True  # an edge rebuilds the plan: other bands, the same code
    joints[2]._at_limit = True
    compiled = len(joint_plans._MONITOR_CODE)
    second = monitor_plan(joints, *views)
    assert second is not first and second.__code__ is first.__code__
    assert len(joint_plans._MONITOR_CODE) == compiled
    fewer = monitor_plan(joints[:3], *views)
    assert fewer.__code__ is not first.__code__


async def test_a_plan_changed_by_a_call_out_is_not_used_for_the_rest_of_the_step(
    stack: AsyncExitStack,
) -> None:
    """An event observer called from the monitor commands a later joint into another mode:
    the rest of that step checks the joint by its new mode, not by the plan built before
    (which would take its VELOCITY target for a position reached at rest)."""
    sim = MujocoSim("arm6", keyframe="home")
    sim.actuator("wrist_pitch", settle_s=0.0)  # completes at the first step within tolerance
    rig = await start_rig(stack, sim, ARM6_JOINTS)
    joints = [sim.joints[j] for j in ARM6_JOINTS]
    first, later = joints[0], sim.joints["wrist_pitch"]
    commanded: list[int] = []

    class Switcher:
        def notify_event(self, source: object, event_id: int) -> None:
            if event_id == MujocoEventId.LIMIT_REACHED:
                commanded.append(event_id)
                rig.actuators["wrist_pitch"].set_value_nowait(0.3, Request.VELOCITY)

    rig.actuators[ARM6_JOINTS[0]].add_observer(Switcher())
    assert later.control_mode is Request.POSITION and not later.pending
    monitor = monitor_plan(joints, sim._qpos_items, sim._qvel_items, sim._force_items)
    sim.data.qpos[first.qadr] = first._lim_hi_on + 1e-3  # the first joint at its limit
    sim.data.qpos[later.qadr] = 0.3  # at rest at 0.3 rad: "reached" if 0.3 were a position
    sim.data.qvel[:] = 0.0
    monitor(sim.steps + 1)
    assert commanded == [MujocoEventId.LIMIT_REACHED]
    assert later.control_mode is Request.VELOCITY
    assert later.pending  # |0 rad/s - 0.3 rad/s| is beyond velocity_tolerance
    assert first._at_limit


async def test_the_generated_monitor_and_the_state_driven_checks_agree(
    stack: AsyncExitStack, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The same run with every step checked by ``_check_joints`` (the joints' state read
    as it is, no plan) gives the same events at the same times and the same physics."""

    async def run(generated: bool) -> tuple[list[tuple[str, int, int, str]], bytes]:
        async with AsyncExitStack() as inner:
            sim = MujocoSim("arm6", keyframe="home")
            if not generated:

                def plan(joints: list[MujocoJoint], *views: object) -> Callable[[int], None]:
                    frozen = tuple(joints)
                    return lambda step: joint_plans._check_joints(frozen, step, 0, 0)

                monkeypatch.setattr(mujoco_sim, "monitor_plan", plan)
            rig = await start_rig(inner, sim, ARM6_JOINTS)
            names = {id(rig.actuators[j]): j for j in ARM6_JOINTS}
            bank = ActuatorBank(rig.actuators[j] for j in ARM6_JOINTS)
            high = sim.joints["elbow_pitch"].limits.position[1]
            bank.set_values_nowait([0.2, -0.3, high, 0.1, -0.2, 0.4])  # one at its limit
            await sim.sleep(0.3)
            rig.actuators["wrist_roll"].set_value_nowait(0.5, Request.VELOCITY)
            rig.actuators["flange_roll"].set_value_nowait(0.0, Request.TORQUE)
            await sim.sleep(0.3)
            bank.set_values_nowait([0.0] * 6, Request.POSITION)
            await sim.sleep(0.4)
            monkeypatch.undo()
            events = [(r.kind, r.id, r.time_ns, names[id(r.source)]) for r in rig.events.records]
            return events, sim.data.qpos.tobytes()

    generated = await run(True)
    by_state = await run(False)
    assert generated == by_state
    assert generated[0]  # events happened (completions, the limit)


# -- the generated joint batch ---------------------------------------------------------------


async def test_the_joint_batch_is_one_function_rebound_per_plan(stack: AsyncExitStack) -> None:
    """The bank keeps the function ``batch_commander`` gave it; each plan (mode change,
    other request) rebinds its code: it writes what ``command_nowait`` writes, declines
    (nothing written) while a joint is in another mode, refuses a wrong count before
    writing anything and raises once the simulation is faulted."""
    sim = MujocoSim("arm6", keyframe="home")
    rig = await start_rig(stack, sim, ARM6_JOINTS)
    bank = ActuatorBank(rig.actuators[j] for j in ARM6_JOINTS)
    send = bank._batch
    assert send is not None
    joints = [sim.joints[j] for j in ARM6_JOINTS]
    targets = [0.1, -0.2, 0.3, -0.1, 0.2, 0.05]
    assert send(Request.POSITION, targets) is True
    assert [sim.data.ctrl[j._drive_act] for j in joints] == targets
    assert [j._target for j in joints] == targets and all(j.pending for j in joints)
    planned = send.__code__  # type: ignore[attr-defined]

    before = sim.data.ctrl.copy()
    with pytest.raises(ValueError, match="5 values for 6 joints"):
        send(Request.POSITION, targets[:5])
    assert sim.data.ctrl.tobytes() == before.tobytes()
    assert send(Request.VELOCITY, [0.0] * 6) is False  # no joint streams VELOCITY now
    assert sim.data.ctrl.tobytes() == before.tobytes()

    rig.actuators["wrist_roll"].set_value_nowait(0.5, Request.VELOCITY)
    before = sim.data.ctrl.copy()
    assert send(Request.POSITION, [0.0] * 6) is False  # one joint in VELOCITY: declined
    assert sim.data.ctrl.tobytes() == before.tobytes()
    assert sim.joints["wrist_roll"]._target == 0.5
    bank.set_values_nowait(targets, Request.POSITION)  # joint by joint: switches it back
    assert bank._batch is send
    calls = joints[0].commands
    assert send(Request.POSITION, targets[::-1]) is True  # a new plan, the same function
    assert send.__code__ is planned  # type: ignore[attr-defined]  # the same shape
    assert [sim.data.ctrl[j._drive_act] for j in joints] == targets[::-1]
    assert joints[0].commands == calls + 1

    sim.data.qvel[0] = np.nan
    await sim.sleep(0.01)  # the next step finds the bad state
    assert sim.fault is not None
    with pytest.raises(HALError, match="faulted"):
        send(Request.POSITION, targets)
    assert not any(j.pending for j in joints)  # the fault cleared every pending target


# -- the lockstep loop's inline step -----------------------------------------------------------


async def _scripted_run(hook: bool) -> tuple[list[tuple[str, int, int]], bytes, int, int]:
    async with AsyncExitStack() as stack:
        sim = MujocoSim("arm6", keyframe="home")
        rig = await start_rig(stack, sim, ARM6_JOINTS)
        hooked: list[int] = []
        if hook:  # a step hook: every step goes through MujocoSim._step
            sim.add_step_hook(lambda: hooked.append(sim.steps))
        assert sim._plain_step is not hook
        bank = ActuatorBank(rig.actuators[j] for j in ARM6_JOINTS)
        bank.set_values_nowait([0.2, -0.3, 0.4, 0.1, -0.2, 0.4])
        await sim.sleep(0.2)
        sim.reset()
        await sim.sleep(0.05)
        rig.actuators["wrist_roll"].set_value_nowait(0.5, Request.VELOCITY)
        await sim.sleep(0.2)
        assert len(hooked) == (sim.steps if hook else 0)
        events = [(r.kind, r.id, r.time_ns) for r in rig.events.records]
        return events, sim.data.qpos.tobytes(), sim.steps, sim.time_ns


async def test_the_inline_step_and_the_full_step_agree() -> None:
    """The lockstep loop's inline step (no pre-step update, effector or hook) and
    ``MujocoSim._step`` give the same physics, events, step count and time."""
    inline = await _scripted_run(hook=False)
    full = await _scripted_run(hook=True)
    assert inline == full
    assert inline[0] and inline[2] == 450 and inline[3] == 250_000_000


async def test_a_hook_added_and_removed_while_running_switches_the_step(
    stack: AsyncExitStack,
) -> None:
    sim = MujocoSim("arm6", keyframe="home")
    await start_rig(stack, sim, ARM6_JOINTS)
    await sim.sleep(0.01)
    seen: list[int] = []

    def hook() -> None:
        seen.append(sim.steps)

    sim.add_step_hook(hook)
    assert not sim._plain_step
    await sim.sleep(0.005)
    sim.remove_step_hook(hook)
    assert sim._plain_step
    await sim.sleep(0.005)
    assert seen == [11, 12, 13, 14, 15]


async def test_an_mj_step_error_in_the_inline_step_faults_the_simulation(
    stack: AsyncExitStack, monkeypatch: pytest.MonkeyPatch
) -> None:
    real = mujoco_sim.mujoco.mj_step
    calls: list[int] = []

    def failing(model: object, data: object) -> None:
        calls.append(1)
        if len(calls) == 3:
            raise mujoco_sim.mujoco.FatalError("out of arena memory")
        real(model, data)

    monkeypatch.setattr(mujoco_sim.mujoco, "mj_step", failing)
    sim = MujocoSim("arm6", keyframe="home")
    rig = await start_rig(stack, sim, ARM6_JOINTS)
    assert sim._plain_step
    rig.actuators["base_yaw"].set_value_nowait(0.3)
    await sim.sleep(0.01)
    assert sim.fault is not None and "mj_step failed" in sim.fault
    assert sim.steps == 3 and not sim.joints["base_yaw"].pending
    assert {a.state for a in rig.actuators.values()} == {ComponentState.ERROR}
