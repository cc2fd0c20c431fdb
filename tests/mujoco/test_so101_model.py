"""The shipped SO-101 model (models/so101.xml): LeRobot's joint names, the published ranges
centred on zero (the servo's mid-range), the STS3215's torque and speed on every servo, the
gripper's opening 0..1 through its tendon, and the OpenEL devices the simulation maps."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from openel_async import Actuator, Request
from openel_mujoco import MujocoEffector, MujocoJoint, MujocoSim, models

ARM = ["shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll"]
JOINTS = [*ARM, "gripper"]
RANGES = {  # the published so101_new_calib ranges (rad)
    "shoulder_pan": (-1.91986, 1.91986),
    "shoulder_lift": (-1.74533, 1.74533),
    "elbow_flex": (-1.69, 1.69),
    "wrist_flex": (-1.65806, 1.65806),
    "wrist_roll": (-2.74385, 2.84121),
    "gripper": (0.0, 1.91986),  # the published -10..100 deg, 0 = closed
}
STALL_NM = 1.91  # STS3215 at 7.4 V: 19.5 kg cm
SPEED_RAD_S = 4.72  # 0.222 s / 60 deg
GRIP_COEF = 1 / 1.9198621771937625


@pytest.fixture(scope="module")
def model() -> mujoco.MjModel:
    return models.load_model("so101")


def test_joints_are_lerobots_with_the_published_ranges(model: mujoco.MjModel) -> None:
    assert "so101" in models.SHIPPED_MODELS
    assert models.model_path("so101").name == "so101.xml"
    assert models.names(model, "joint") == JOINTS
    for joint, (low, high) in RANGES.items():
        j = model.joint(joint)
        assert j.type[0] == mujoco.mjtJoint.mjJNT_HINGE and model.jnt_limited[j.id]
        assert tuple(j.range) == pytest.approx((low, high), abs=1e-5), joint
    for joint in ARM[:4]:  # zero = the middle of the range (the servo's 2048 ticks)
        assert sum(model.joint(joint).range) == pytest.approx(0.0, abs=1e-6)
    total = float(model.body_subtreemass[model.body("shoulder").id])
    assert total == pytest.approx(0.100006 + 0.103 + 0.104 + 0.079 + 0.087 + 0.012)


def test_every_servo_has_the_sts3215_torque_and_speed(model: mujoco.MjModel) -> None:
    for joint in ARM:
        acts = models.joint_actuators(model, joint)
        for mode, act in acts.items():
            assert tuple(model.actuator_forcerange[act]) == pytest.approx((-STALL_NM, STALL_NM))
            assert model.actuator_forcelimited[act], (joint, mode)
        # the velocity servo's ctrlrange is the speed limit (MujocoJoint's max_velocity)
        vel = acts["velocity"]
        assert tuple(model.actuator_ctrlrange[vel]) == pytest.approx((-SPEED_RAD_S, SPEED_RAD_S))
        # the position servo's ctrlrange is the joint range (inheritrange)
        pos = acts["position"]
        assert tuple(model.actuator_ctrlrange[pos]) == pytest.approx(
            tuple(model.joint(joint).range)
        )
        assert models.control_mode(model, joint) == "position"
        # back-EMF: the damping of a saturated servo tops it out at the no-load speed
        damping = float(model.dof_damping[model.jnt_dofadr[model.joint(joint).id]])
        assert STALL_NM / damping == pytest.approx(SPEED_RAD_S, rel=0.01)
    # the gripper: a position servo on the tendon, in opening units, with the same stall torque
    grip = model.actuator("gripper")
    assert grip.trntype[0] == mujoco.mjtTrn.mjTRN_TENDON
    assert tuple(grip.ctrlrange) == (0.0, 1.0)
    assert float(grip.forcerange[1]) * GRIP_COEF == pytest.approx(STALL_NM, rel=1e-3)
    assert float(model.tendon("gripper").id) == 0.0
    assert model.wrap_prm[model.tendon_adr[0]] == pytest.approx(GRIP_COEF)


def test_rest_keyframe_and_gravity_sag(model: mujoco.MjModel) -> None:
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("rest").id)
    rest = data.qpos.copy()
    for _ in range(500):  # 1 s: the servos hold the folded arm where it is
        mujoco.mj_step(model, data)
    np.testing.assert_allclose(data.qpos, rest, atol=0.02)
    # at zero (the mid-range pose) the gripper points forward, 0.39 m out at 0.23 m
    mujoco.mj_resetData(model, data)
    mujoco.mj_forward(model, data)
    np.testing.assert_allclose(data.site("gripperframe").xpos, [0.391, 0.0, 0.226], atol=0.002)


def test_a_saturated_servo_tops_out_at_the_no_load_speed(model: mujoco.MjModel) -> None:
    data = mujoco.MjData(model)
    pan = models.joint_actuators(model, "shoulder_pan")["position"]
    data.ctrl[pan] = 1.9  # a step across the range: the servo saturates at its stall torque
    top = 0.0
    for _ in range(400):
        mujoco.mj_step(model, data)
        top = max(top, abs(float(data.qvel[0])))
    assert 0.9 * SPEED_RAD_S < top < 1.02 * SPEED_RAD_S


async def test_the_simulation_maps_joints_in_radians_and_the_gripper_opening() -> None:
    sim = MujocoSim("so101", keyframe="rest")
    for joint in ARM:
        device = sim.actuator(joint)
        assert isinstance(device, MujocoJoint)
        assert device.limits.position == pytest.approx(RANGES[joint], abs=1e-5)
        assert device.limits.velocity == pytest.approx(SPEED_RAD_S)
        assert device.limits.torque == pytest.approx(STALL_NM)
    gripper = sim.effector("gripper")
    assert isinstance(gripper, MujocoEffector) and gripper.kind == "position"
    assert gripper.limits.position == (0.0, 1.0)
    assert gripper.supported_requests == {Request.POSITION, Request.NO_EXCITE}
    async with sim, Actuator(gripper, clock=sim.clock) as grip:
        for opening in (1.0, 0.25):
            motion = await grip.set_value(opening, Request.POSITION)
            await motion  # COMPLETED: the opening is within 0.01 and settled
            actual = await grip.get_value(Request.POSITION_ACTUAL)
            assert actual == pytest.approx(opening, abs=0.01)
            q = float(sim.data.qpos[model_qpos(sim, "gripper")])
            assert q == pytest.approx(opening / GRIP_COEF, abs=0.02)  # radians of the jaw
    assert math.isfinite(sim.time_ns)


def model_qpos(sim: MujocoSim, joint: str) -> int:
    return int(sim.model.jnt_qposadr[sim.model.joint(joint).id])
