"""The declarative mapping (SimDescription) and the TrajectoryRecorder."""

from __future__ import annotations

import csv
import math
import pathlib
from contextlib import AsyncExitStack

import anyio
import numpy as np
import pytest
import yaml

from openel_async import Actuator, Request
from openel_mujoco import (
    JointSpec,
    MujocoSim,
    SensorSpec,
    SimDescription,
    TrajectoryRecorder,
)
from openel_mujoco.models import MODELS_DIR

from .conftest import start_rig

YAML = """
model: arm6
pacing: lockstep
keyframe: home
joints:
  - base_yaw
  - {joint: shoulder_pitch, max_velocity: 2.0, position_tolerance: 0.005}
  - {joint: wrist_roll, name: roll, mode: velocity}
sensors:
  - imu_acc
  - {sensor: wrist_force, name: ft}
extra: {owner: demo}
"""


def test_description_round_trips_through_yaml(tmp_path: pathlib.Path) -> None:
    path = tmp_path / "rig.yaml"
    path.write_text(YAML)
    desc = SimDescription.from_yaml(path)
    assert desc.model == "arm6" and desc.keyframe == "home"
    assert desc.joints[0] == JointSpec("base_yaw")
    assert desc.joints[1].max_velocity == 2.0 and desc.joints[1].position_tolerance == 0.005
    assert desc.joints[2].key == "roll" and desc.joints[2].mode == "velocity"
    assert desc.sensors == (SensorSpec("imu_acc"), SensorSpec("wrist_force", name="ft"))
    data = desc.to_dict()
    assert data["joints"][0] == "base_yaw" and data["sensors"][0] == "imu_acc"
    assert SimDescription.from_dict(yaml.safe_load(yaml.safe_dump(data))) == desc

    sim = MujocoSim.from_description(desc)
    assert list(sim.joints) == ["base_yaw", "shoulder_pitch", "roll"]
    assert list(sim.sensors) == ["imu_acc", "ft"]
    assert sim.joints["shoulder_pitch"].limits.velocity == 2.0
    assert sim.joints["roll"].control_mode is Request.VELOCITY
    assert sim.joints["base_yaw"].control_mode is Request.POSITION
    assert sim.sensors["ft"].units == ("N",) * 3
    assert sim.actuator("wrist_roll") is sim.joints["roll"]  # found by joint name too


def test_relative_model_path_resolves_against_the_yaml_file(tmp_path: pathlib.Path) -> None:
    (tmp_path / "models").mkdir()
    (tmp_path / "models" / "arm.xml").write_text((MODELS_DIR / "arm2.xml").read_text())
    (tmp_path / "rig.yaml").write_text("model: models/arm.xml\njoints: [elbow]\n")
    desc = SimDescription.from_yaml(tmp_path / "rig.yaml")
    assert desc.model == str(tmp_path / "models" / "arm.xml")
    sim = MujocoSim.from_description(desc, realtime_factor=1.0)
    assert "elbow" in sim.joints


async def test_description_built_sim_runs(stack: AsyncExitStack) -> None:
    sim = MujocoSim.from_description(
        {"model": "arm2", "joints": [{"joint": "elbow", "settle_s": 0.05}], "sensors": ["tip_pos"]}
    )
    await stack.enter_async_context(sim)
    elbow = await stack.enter_async_context(Actuator(sim.joints["elbow"], clock=sim.clock))
    with anyio.fail_after(10):
        motion = await elbow.set_value(-0.7)
        await motion
    assert sim.joints["elbow"].position == pytest.approx(-0.7, abs=0.01)


async def test_trajectory_recorder_samples_plots_and_writes_csv(
    stack: AsyncExitStack, tmp_path: pathlib.Path
) -> None:
    sim = MujocoSim("arm2")
    rig = await start_rig(stack, sim, ("shoulder", "elbow"))
    recorder = TrajectoryRecorder(sim, ["shoulder", "elbow"], every=10)
    with anyio.fail_after(10):
        with recorder:
            motion = await rig.actuators["shoulder"].set_value(0.6)
            await rig.actuators["elbow"].set_value(0.4, Request.VELOCITY)
            await motion
            await rig.actuators["elbow"].set_value(0.2)
            await sim.sleep(0.3)
        samples = len(recorder)
        await sim.sleep(0.1)  # detached: no more samples
    assert len(recorder) == samples
    t, commanded, actual = recorder.arrays()
    assert t.shape == (samples,) and commanded.shape == actual.shape == (samples, 2)
    assert np.all(np.diff(t) == pytest.approx(0.01))  # every 10 steps of 1 ms
    assert t[0] == 0.0
    assert commanded[-1, 0] == 0.6 and actual[-1, 0] == pytest.approx(0.6, abs=0.01)
    assert np.isnan(commanded[5, 1])  # velocity mode: no commanded position
    assert commanded[-1, 1] == 0.2
    assert np.all(np.isfinite(actual))
    csv_path = recorder.to_csv(tmp_path / "out" / "traj.csv")
    rows = list(csv.reader(csv_path.open()))
    assert rows[0] == ["t", "shoulder_cmd", "shoulder_actual", "elbow_cmd", "elbow_actual"]
    assert len(rows) == samples + 1 and float(rows[-1][1]) == 0.6
    png = recorder.plot(tmp_path / "out" / "traj.png", title="arm2")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_recorder_limits_and_manual_sampling() -> None:
    sim = MujocoSim("arm2")
    recorder = TrajectoryRecorder(sim, ["elbow"], max_samples=3)
    for _ in range(5):
        sim.step(2)
        recorder.sample()
    assert len(recorder) == 3 and recorder.dropped == 2
    assert list(recorder.times) == pytest.approx([0.002, 0.004, 0.006])
    assert not math.isnan(recorder.commanded[0, 0])  # position mode at start: holding 0
    with pytest.raises(ValueError, match="every"):
        TrajectoryRecorder(sim, ["elbow"], every=0)
    with pytest.raises(ValueError, match="joints"):
        TrajectoryRecorder(MujocoSim("arm2"))  # nothing mapped yet


async def test_a_failing_step_hook_is_dropped_not_fatal(stack: AsyncExitStack) -> None:
    sim = MujocoSim("arm2")
    await stack.enter_async_context(sim)
    calls: list[int] = []

    def broken() -> None:
        calls.append(sim.steps)
        raise RuntimeError("hook bug")

    sim.add_step_hook(broken)
    with anyio.fail_after(10):
        await sim.sleep(0.01)
    assert len(calls) == 1 and sim.steps >= 10 and sim.fault is None
