"""Tests of the shipped MuJoCo models (arm2, arm6, so101: tests/mujoco/test_so101_model.py) and of openel_mujoco.models / render."""

from __future__ import annotations

import pathlib

import mujoco
import numpy as np
import numpy.typing as npt
import pytest

from openel_mujoco import models, render
from openel_mujoco.models import ModelLoadError

ARM2_JOINTS = ["shoulder", "elbow"]
ARM6_JOINTS = [
    "base_yaw",
    "shoulder_pitch",
    "elbow_pitch",
    "wrist_roll",
    "wrist_pitch",
    "flange_roll",
]
SO101_ARM_JOINTS = ["shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll"]
JOINTS = {"arm2": ARM2_JOINTS, "arm6": ARM6_JOINTS, "so101": SO101_ARM_JOINTS}
"""The joints with the three actuators of each mode (so101: its arm joints; the gripper's
servo acts on a tendon)."""
EXTRA_ACTUATORS = {"arm2": 0, "arm6": 1, "so101": 1}
"""Actuators besides the joints' three: arm6's suction, so101's gripper."""
TIMESTEP = {"arm2": 0.001, "arm6": 0.001, "so101": 0.002}
SAG = {"arm2": 0.006, "arm6": 0.006, "so101": 0.02}
"""rad: how far gravity moves a position-held joint (so101: servos of kp 50 N m/rad)."""
MODES: tuple[models.ControlMode, ...] = ("position", "velocity", "torque")

Array = npt.NDArray[np.float64]


def make(name: str) -> tuple[mujoco.MjModel, mujoco.MjData]:
    """Fresh model + data (mode switching mutates the model), reset to keyframe 0 if any."""
    model = models.load_model(name)
    data = mujoco.MjData(model)
    if model.nkey:
        mujoco.mj_resetDataKeyframe(model, data, 0)
    mujoco.mj_forward(model, data)
    return model, data


def qpos(model: mujoco.MjModel, data: mujoco.MjData, joints: list[str]) -> Array:
    adr = [model.jnt_qposadr[models.find_id(model, "joint", j)] for j in joints]
    return np.array(data.qpos[adr], dtype=np.float64)


def qvel(model: mujoco.MjModel, data: mujoco.MjData, joints: list[str]) -> Array:
    adr = [model.jnt_dofadr[models.find_id(model, "joint", j)] for j in joints]
    return np.array(data.qvel[adr], dtype=np.float64)


def steps(model: mujoco.MjModel, seconds: float) -> int:
    return round(seconds / float(model.opt.timestep))


# --------------------------------------------------------------------------- loading


@pytest.mark.parametrize("name", models.SHIPPED_MODELS)
def test_shipped_models_load_by_name_and_path(name: str) -> None:
    path = models.model_path(name)
    assert path.is_file()
    assert path.parent == models.MODELS_DIR
    assert models.MODELS_DIR.parent == pathlib.Path(models.__file__).resolve().parent
    for source in (name, path, str(path)):
        model = models.load_model(source)
        assert models.names(model, "joint")[: len(JOINTS[name])] == JOINTS[name]
        assert model.nu == 3 * len(JOINTS[name]) + EXTRA_ACTUATORS[name]
        assert model.opt.timestep == pytest.approx(TIMESTEP[name])


def test_missing_file_error_names_path_and_shipped_models(tmp_path: pathlib.Path) -> None:
    missing = tmp_path / "nope.xml"
    with pytest.raises(ModelLoadError) as info:
        models.load_model(missing)
    message = str(info.value)
    assert str(missing) in message
    assert "arm2" in message and "arm6" in message
    with pytest.raises(ModelLoadError, match="arm2, arm6"):
        models.load_model("arm3")
    with pytest.raises(ModelLoadError, match="unknown shipped model 'arm3'"):
        models.model_path("arm3")


def test_malformed_xml_error_includes_mujoco_message(tmp_path: pathlib.Path) -> None:
    broken = tmp_path / "broken.xml"
    broken.write_text("<mujoco><worldbody><body></worldbody></mujoco>")
    with pytest.raises(ModelLoadError) as info:
        models.load_model(broken)
    message = str(info.value)
    assert str(broken) in message
    assert "XML" in message  # MuJoCo's parser message, e.g. "XML parse error ..."
    assert isinstance(info.value, ValueError)

    invalid = tmp_path / "invalid.xml"
    invalid.write_text('<mujoco><worldbody><geom type="sphere" bogus="1"/></worldbody></mujoco>')
    with pytest.raises(ModelLoadError, match="bogus"):
        models.load_model(invalid)


def test_unknown_name_lists_available_names() -> None:
    model, _ = make("arm2")
    with pytest.raises(ModelLoadError) as info:
        models.find_id(model, "joint", "elbw")
    assert str(info.value).startswith("unknown joint 'elbw'; joints in arm2: shoulder, elbow")
    assert "did you mean 'elbow'" in str(info.value)
    with pytest.raises(
        ModelLoadError, match="unknown actuator 'elbow_position'; actuators in arm2"
    ):
        models.find_id(model, "actuator", "elbow_position")
    with pytest.raises(ValueError, match="unsupported object kind"):
        models.find_id(model, "jnt", "elbow")
    assert models.find_id(model, "site", "tip") >= 0


# --------------------------------------------------------------------------- sensors


def _expected_sensors(name: str) -> dict[str, tuple[mujoco.mjtSensor, int]]:
    s = mujoco.mjtSensor
    expected: dict[str, tuple[mujoco.mjtSensor, int]] = {}
    for joint in JOINTS[name]:
        expected[f"{joint}_pos_sensor"] = (s.mjSENS_JOINTPOS, 1)
        expected[f"{joint}_vel_sensor"] = (s.mjSENS_JOINTVEL, 1)
        expected[f"{joint}_torque_sensor"] = (s.mjSENS_JOINTACTFRC, 1)
    expected["imu_acc"] = (s.mjSENS_ACCELEROMETER, 3)
    expected["imu_gyro"] = (s.mjSENS_GYRO, 3)
    if name == "arm2":
        expected["tip_pos"] = (s.mjSENS_FRAMEPOS, 3)
        expected["tip_touch"] = (s.mjSENS_TOUCH, 1)
    else:
        expected["tool_pos"] = (s.mjSENS_FRAMEPOS, 3)
        expected["pad_touch"] = (s.mjSENS_TOUCH, 1)
        expected["wrist_force"] = (s.mjSENS_FORCE, 3)
        expected["wrist_torque"] = (s.mjSENS_TORQUE, 3)
    return expected


def sensor(model: mujoco.MjModel, data: mujoco.MjData, name: str) -> Array:
    sid = models.find_id(model, "sensor", name)
    adr, dim = int(model.sensor_adr[sid]), int(model.sensor_dim[sid])
    return np.array(data.sensordata[adr : adr + dim], dtype=np.float64)


@pytest.mark.parametrize("name", ["arm2", "arm6"])  # (so101: tests/mujoco/test_so101_model.py)
def test_declared_sensors_exist_with_dimensions(name: str) -> None:
    model, data = make(name)
    expected = _expected_sensors(name)
    assert sorted(models.names(model, "sensor")) == sorted(expected)
    for sensor_name, (kind, dim) in expected.items():
        sid = models.find_id(model, "sensor", sensor_name)
        assert model.sensor_type[sid] == kind, sensor_name
        assert model.sensor_dim[sid] == dim, sensor_name
    # readings agree with the state
    for joint in JOINTS[name]:
        assert sensor(model, data, f"{joint}_pos_sensor")[0] == qpos(model, data, [joint])[0]
    site = "tip" if name == "arm2" else "tool"
    np.testing.assert_allclose(
        sensor(model, data, f"{site}_pos"), data.site_xpos[models.find_id(model, "site", site)]
    )
    # once settled, an accelerometer at rest measures the proper acceleration: +g along world z
    for _ in range(steps(model, 0.5)):
        mujoco.mj_step(model, data)
    mujoco.mj_forward(model, data)
    imu = models.find_id(model, "site", "imu")
    world_acc = data.site_xmat[imu].reshape(3, 3) @ sensor(model, data, "imu_acc")
    np.testing.assert_allclose(world_acc, [0.0, 0.0, 9.81], atol=0.05)


# --------------------------------------------------------------------------- stability


@pytest.mark.parametrize("name", models.SHIPPED_MODELS)
@pytest.mark.parametrize("mode", ["position", "torque"])
def test_two_seconds_zero_control_stay_finite(name: str, mode: models.ControlMode) -> None:
    """Zero ctrl: position mode holds q = 0; torque mode lets gravity drop arm6 onto its limits."""
    model, data = make(name)
    joints = JOINTS[name]
    for joint in joints:
        models.set_control_mode(model, data, joint, mode)
    data.ctrl[:] = 0.0
    low, high = model.jnt_range[: len(joints)].T
    for _ in range(steps(model, 2.0)):
        mujoco.mj_step(model, data)
        q = qpos(model, data, joints)
        assert np.all(q >= low - 0.03) and np.all(q <= high + 0.03)
    assert np.all(np.isfinite(data.qpos)) and np.all(np.isfinite(data.qvel))
    assert np.all(np.isfinite(data.sensordata))
    assert all(w.number == 0 for w in data.warning)  # no instability / auto-reset warnings
    if mode == "position":
        np.testing.assert_allclose(qpos(model, data, joints), 0.0, atol=SAG[name])
    if name == "arm6":  # the box rests where it was put
        box = data.qpos[model.jnt_qposadr[models.find_id(model, "joint", "box")] :][:3]
        np.testing.assert_allclose(box, [0.45, 0.0, 0.02], atol=0.002)


@pytest.mark.parametrize("name", models.SHIPPED_MODELS)
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_joint_limits_hold_against_full_torque(name: str, sign: float) -> None:
    model, data = make(name)
    joints = JOINTS[name]
    for joint in joints:
        act = models.set_control_mode(model, data, joint, "torque")
        data.ctrl[act] = sign * model.actuator_ctrlrange[act, 1]
    low, high = model.jnt_range[: len(joints)].T
    worst = np.zeros(len(joints))
    for _ in range(steps(model, 2.0)):
        mujoco.mj_step(model, data)
        q = qpos(model, data, joints)
        worst = np.maximum(worst, np.maximum(q - high, low - q))
    assert np.all(np.isfinite(data.qpos))
    assert np.all(worst < 0.05)  # brief overshoot when slammed into the stop at full speed
    q = qpos(model, data, joints)
    np.testing.assert_allclose(q, high if sign > 0 else low, atol=0.002)  # resting at the stop


# --------------------------------------------------------------------------- control modes

TARGETS = {
    "arm2": np.array([1.2, -1.5]),
    "arm6": np.array([0.8, 0.9, 0.7, -1.0, 1.2, 1.5]),
    "so101": np.array([0.8, 0.5, -0.6, 1.0, -1.5]),
}


@pytest.mark.parametrize("name", models.SHIPPED_MODELS)
def test_position_mode_reaches_targets_within_2s(name: str) -> None:
    model, data = make(name)
    joints = JOINTS[name]
    for joint, target in zip(joints, TARGETS[name], strict=True):
        act = models.set_control_mode(model, data, joint, "position")
        data.ctrl[act] = target
    for _ in range(steps(model, 2.0)):
        mujoco.mj_step(model, data)
    np.testing.assert_allclose(qpos(model, data, joints), TARGETS[name], atol=max(0.01, SAG[name]))
    np.testing.assert_allclose(qvel(model, data, joints), 0.0, atol=0.01)
    # beyond-range targets are clamped to the joint range by ctrlrange (inheritrange="1");
    # (negative direction: the arm2 tip would hit the post on the way to the upper limits)
    for joint in joints:
        data.ctrl[models.joint_actuators(model, joint)["position"]] = -100.0
    for _ in range(steps(model, 2.0)):
        mujoco.mj_step(model, data)
    low = model.jnt_range[: len(joints), 0]
    np.testing.assert_allclose(qpos(model, data, joints), low, atol=max(0.01, SAG[name]))


VELOCITIES = {
    "arm2": np.array([0.5, -0.8]),
    "arm6": np.array([0.5, -0.5, 0.5, -0.8, 0.8, 1.0]),
    "so101": np.array([0.5, 0.5, -0.5, -0.8, 1.0]),  # (from its keyframe rest)
}


@pytest.mark.parametrize("name", models.SHIPPED_MODELS)
def test_velocity_mode_tracks_within_10_percent(name: str) -> None:
    model, data = make(name)
    joints = JOINTS[name]
    for joint, velocity in zip(joints, VELOCITIES[name], strict=True):
        act = models.set_control_mode(model, data, joint, "velocity")
        data.ctrl[act] = velocity
    samples = []
    for i in range(steps(model, 0.6)):
        mujoco.mj_step(model, data)
        if i >= steps(model, 0.2):
            samples.append(qvel(model, data, joints))
    np.testing.assert_allclose(np.mean(samples, axis=0), VELOCITIES[name], rtol=0.1)
    mujoco.mj_forward(model, data)  # mj_step leaves sensordata of the pre-step state
    for joint in joints:  # the jointvel sensors read the same
        vel = sensor(model, data, f"{joint}_vel_sensor")[0]
        assert vel == qvel(model, data, [joint])[0]


@pytest.mark.parametrize("name", models.SHIPPED_MODELS)
def test_torque_mode_accelerates_in_commanded_direction(name: str) -> None:
    """One joint in torque mode, the others holding position: compare with zero torque."""
    joints = JOINTS[name]
    for index, joint in enumerate(joints):
        end = {}
        for torque_sign in (0.0, 1.0, -1.0):
            model, data = make(name)
            act = models.set_control_mode(model, data, joint, "torque")
            data.ctrl[act] = torque_sign * 0.25 * model.actuator_ctrlrange[act, 1]
            for _ in range(steps(model, 0.05)):
                mujoco.mj_step(model, data)
            end[torque_sign] = qpos(model, data, joints)[index]
            if torque_sign:  # the joint torque sensor reports the commanded torque
                measured = sensor(model, data, f"{joint}_torque_sensor")[0]
                assert measured == pytest.approx(data.ctrl[act])
        assert end[1.0] - end[0.0] > 1e-3, joint
        assert end[-1.0] - end[0.0] < -1e-3, joint


def test_disabled_actuators_produce_no_force_and_switching_is_bumpless() -> None:
    model, data = make("arm2")
    # default: every joint in position mode (option/actuatorgroupdisable)
    assert [models.control_mode(model, j) for j in ARM2_JOINTS] == ["position", "position"]
    acts = models.joint_actuators(model, "shoulder")
    assert [models.names(model, "actuator")[acts[m]] for m in MODES] == [
        "shoulder_pos",
        "shoulder_vel",
        "shoulder_torque",
    ]
    # command all three actuators, only the selected one may act
    models.set_control_mode(model, data, "shoulder", "torque")
    assert models.control_mode(model, "shoulder") == "torque"
    data.ctrl[acts["position"]] = 2.0
    data.ctrl[acts["velocity"]] = -3.0
    data.ctrl[acts["torque"]] = 0.5
    for _ in range(100):
        mujoco.mj_step(model, data)
    assert data.actuator_force[acts["position"]] == 0.0
    assert data.actuator_force[acts["velocity"]] == 0.0
    assert data.actuator_force[acts["torque"]] == 0.5
    dof = model.jnt_dofadr[models.find_id(model, "joint", "shoulder")]
    assert data.qfrc_actuator[dof] == pytest.approx(0.5)
    # the disabled velocity servo adds no (implicit) damping: a free run matches a model
    # without it, i.e. the speed keeps growing under constant torque
    assert qvel(model, data, ["shoulder"])[0] > 0.3

    # torque -> velocity (stop) -> position: the servo starts at the current angle, holds it
    models.set_control_mode(model, data, "shoulder", "velocity")
    data.ctrl[acts["velocity"]] = 0.0
    for _ in range(300):
        mujoco.mj_step(model, data)
    assert abs(qvel(model, data, ["shoulder"])[0]) < 0.01
    angle = qpos(model, data, ["shoulder"])[0]
    models.set_control_mode(model, data, "shoulder", "position")
    assert data.ctrl[acts["position"]] == pytest.approx(angle)
    assert data.ctrl[acts["velocity"]] == 0.0 and data.ctrl[acts["torque"]] == 0.0
    for _ in range(500):
        mujoco.mj_step(model, data)
    assert qpos(model, data, ["shoulder"])[0] == pytest.approx(angle, abs=0.005)
    # the mode lives in the model: groups of other joints are untouched
    assert models.control_mode(model, "elbow") == "position"
    with pytest.raises(ValueError, match="unknown control mode"):
        models.set_control_mode(model, data, "elbow", "current")  # type: ignore[arg-type]


def test_group_convention_is_exclusive_per_joint_and_mode() -> None:
    for name in models.SHIPPED_MODELS:
        model, _ = make(name)
        for index, joint in enumerate(JOINTS[name]):
            for offset, (mode, act) in enumerate(models.joint_actuators(model, joint).items()):
                assert mode == MODES[offset]
                assert model.actuator_group[act] == 3 * index + offset


def _arm2_ik(x: float, y: float) -> tuple[float, float]:
    l1, l2 = 0.3, 0.25
    c2 = (x * x + y * y - l1 * l1 - l2 * l2) / (2 * l1 * l2)
    q2 = float(np.arccos(np.clip(c2, -1.0, 1.0)))
    q1 = float(np.arctan2(y, x) - np.arctan2(l2 * np.sin(q2), l1 + l2 * np.cos(q2)))
    return q1, q2


def test_arm2_follows_a_15cm_square_in_4s() -> None:
    model, data = make("arm2")
    corners = np.array([[0.275, -0.075], [0.425, -0.075], [0.425, 0.075], [0.275, 0.075]])
    corners = np.vstack([corners, corners[:1]])
    data.qpos[:2] = _arm2_ik(*corners[0])
    mujoco.mj_forward(model, data)
    pos_acts = [models.set_control_mode(model, data, j, "position") for j in ARM2_JOINTS]
    tip = models.find_id(model, "site", "tip")
    duration = 4.0
    worst_error = 0.0
    for i in range(steps(model, duration)):
        phase = i * model.opt.timestep / duration * 4
        side = min(int(phase), 3)
        s = phase - side
        s = 3 * s * s - 2 * s**3  # smooth start and stop at each corner
        target = corners[side] * (1 - s) + corners[side + 1] * s
        data.ctrl[pos_acts] = _arm2_ik(*target)
        mujoco.mj_step(model, data)
        worst_error = max(worst_error, float(np.linalg.norm(data.site_xpos[tip][:2] - target)))
        assert np.all(np.abs(data.actuator_force) < 0.5 * model.actuator_forcerange[:, 1])
    assert worst_error < 0.02  # servo lag only (no velocity feed-forward)
    assert np.linalg.norm(data.site_xpos[tip][:2] - corners[-1]) < 0.003


def test_arm2_tip_touch_reads_contact_with_post() -> None:
    model, data = make("arm2")
    acts = [models.set_control_mode(model, data, j, "position") for j in ARM2_JOINTS]
    data.ctrl[acts] = _arm2_ik(0.0, 0.38)  # next to the post at (0, 0.45)
    for _ in range(steps(model, 1.0)):
        mujoco.mj_step(model, data)
    assert sensor(model, data, "tip_touch")[0] == 0.0
    data.ctrl[acts] = _arm2_ik(0.0, 0.44)  # into the post: the servos press the tip on it
    for _ in range(steps(model, 1.0)):
        mujoco.mj_step(model, data)
    assert sensor(model, data, "tip_touch")[0] > 0.1


def test_arm6_suction_picks_the_box_and_wrist_sensors_see_it() -> None:
    model, data = make("arm6")
    joints = ARM6_JOINTS
    acts = [models.joint_actuators(model, j)["position"] for j in joints]
    suction = models.find_id(model, "actuator", "suction")
    box_adr = model.jnt_qposadr[models.find_id(model, "joint", "box")]
    # joint solutions (pad face down over the box centre) for "above" and "on the box"
    above = np.array([0.0, 0.731, -0.097, 0.0, 0.937, 0.0])
    on_box = np.array([0.0, 0.910, -0.097, 0.0, 0.758, 0.0])

    def move(target: Array, seconds: float, grip: float) -> None:
        start = np.array(data.ctrl[acts])
        n = steps(model, seconds)
        for i in range(n):
            s = min(1.0, i / (0.8 * n))
            data.ctrl[acts] = start + (target - start) * (3 * s * s - 2 * s**3)
            data.ctrl[suction] = grip
            mujoco.mj_step(model, data)

    move(above, 1.0, 0.0)
    assert sensor(model, data, "pad_touch")[0] == 0.0
    free_load = sensor(model, data, "wrist_force")
    # tool at rest: the sensor carries the weight of the tool body
    tool_mass = model.body_mass[models.find_id(model, "body", "tool")]
    assert np.linalg.norm(free_load) == pytest.approx(tool_mass * 9.81, rel=0.05)
    move(on_box, 0.8, 0.0)
    assert sensor(model, data, "pad_touch")[0] > 1.0
    move(on_box, 0.2, 1.0)
    move(above, 1.0, 1.0)
    assert data.qpos[box_adr + 2] > 0.08  # lifted ~8 cm
    # the wrist force sensor sees the pad-box contact force, which balances the suction
    # (adhesion) force of ~20 N: MuJoCo applies adhesion as an actuator force, not a body force
    assert np.linalg.norm(sensor(model, data, "wrist_force") - free_load) > 10.0
    move(above, 0.5, 0.0)  # release: the box falls back to the floor
    assert data.qpos[box_adr + 2] == pytest.approx(0.02, abs=0.003)


# --------------------------------------------------------------------------- rendering


@pytest.mark.render
def test_render_snapshot_writes_png_or_returns_none(tmp_path: pathlib.Path) -> None:
    from matplotlib import image as mpl_image

    model, data = make("arm2")
    with pytest.raises(ValueError, match="unknown camera"):
        render.render_snapshot(model, data, tmp_path / "x.png", camera="nope")
    with pytest.raises(ValueError, match="offscreen buffer"):
        render.render_snapshot(model, data, tmp_path / "x.png", width=4000, height=64)
    out = render.render_snapshot(
        model, data, tmp_path / "snap" / "arm2.png", width=96, height=64, camera="overview"
    )
    if out is None:  # no OpenGL on this machine: documented behaviour
        assert not (tmp_path / "snap" / "arm2.png").exists()
        return
    assert out == tmp_path / "snap" / "arm2.png"
    image = mpl_image.imread(out)
    assert image.shape[:2] == (64, 96)
    assert float(np.std(image[..., :3])) > 0.01  # not a blank frame


def test_render_snapshot_returns_none_without_gl(
    tmp_path: pathlib.Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("MUJOCO_GL", "disable")
    monkeypatch.setattr(render, "_backend", None)
    monkeypatch.setattr(render, "_probed", False)
    model, data = make("arm2")
    assert render.render_snapshot(model, data, tmp_path / "none.png") is None
    assert not (tmp_path / "none.png").exists()
