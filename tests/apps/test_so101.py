"""The so101 app on the MuJoCo SO-101 (in process, lockstep): every pose of the sequence is
reached within its tolerance, no joint leaves its range, the snapshots are written (or
explained), and the app runs unchanged on another rig with the six components."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from openel_apps import so101 as app
from openel_async import EventTimer
from openel_async.app import AppContext, AppHook, find_app, run_app
from openel_async.component import HALComponent
from openel_mujoco import MujocoSim, load_model

from .conftest import is_png

LINE = re.compile(
    r" *(\d+)  (.{12}) reached at +([\d.]+) s  (max error ([\d.]+) rad \((\w+)\)|gripper to [\d.]+)"
    r" +gripper ([\d.]+)"
)


class Sampler(AppHook):
    """Every component's name, and the simulated joints' extremes at every timer tick."""

    def __init__(self) -> None:
        self.names: list[str] = []
        self.low: list[float] = [float("inf")] * 6
        self.high: list[float] = [float("-inf")] * 6
        self.ticks = 0
        self.ctx: AppContext | None = None

    def component_added(self, ctx: AppContext, component: HALComponent) -> None:
        self.names.append(component.device_name)

    def timer_added(self, ctx: AppContext, timer: EventTimer) -> None:
        self.ctx = ctx
        timer.add_observer(self)

    async def notify_timer(self, timer: EventTimer) -> None:
        assert self.ctx is not None
        sim = next(b for b in self.ctx.rigs[-1].buses.values() if isinstance(b, MujocoSim))
        q = sim.data.qpos[:6]
        self.low = [min(a, float(b)) for a, b in zip(self.low, q, strict=True)]
        self.high = [max(a, float(b)) for a, b in zip(self.high, q, strict=True)]
        self.ticks += 1


def run(
    argv: list[str], capsys: pytest.CaptureFixture[str], rig: Path | None = None
) -> tuple[int, str, Sampler]:
    sampler = Sampler()
    status = run_app(find_app("so101"), argv, prog="so101", hooks=[sampler], rig=rig)
    return status, capsys.readouterr().out, sampler


def check_poses(out: str) -> None:
    """One line per step, in order, each reached within the app's tolerance."""
    lines = [m for m in map(LINE.match, out.splitlines()) if m is not None]
    assert [m[2].strip() for m in lines] == [s.name for s in app.SEQUENCE]
    times = [float(m[3]) for m in lines]
    assert times == sorted(times)
    for m, step in zip(lines, app.SEQUENCE, strict=True):
        if step.pose is not None:
            assert float(m[5]) <= app.GOAL_TOLERANCE_RAD, m[0]
        gripper = float(m[7])
        if step.gripper is not None:
            assert gripper == pytest.approx(step.gripper, abs=app.GRIPPER_TOLERANCE), m[0]
    assert f"steps              {len(app.SEQUENCE)}/{len(app.SEQUENCE)} reached" in out


def check_ranges(sampler: Sampler) -> None:
    model = load_model("so101")
    assert sampler.ticks > 500  # ~12 s of motion at 10 ms
    for i, joint in enumerate((*app.ARM, "gripper")):
        low, high = (float(v) for v in model.joint(joint).range)
        # (a joint pressed against its stop goes past it by the limit's softness: < 1 mrad)
        assert low - 0.001 <= sampler.low[i] and sampler.high[i] <= high + 0.001, joint
    # the sequence goes where it says: the pick to one side, the place to the other
    assert sampler.low[0] == pytest.approx(-0.55, abs=0.04)
    assert sampler.high[0] == pytest.approx(0.55, abs=0.04)


def test_every_pose_is_reached_on_the_mujoco_model(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    status, out, sampler = run(["--virtual", "--out", str(tmp_path)], capsys)
    assert status == 0, out
    assert sampler.names == [*app.ARM, "gripper"]
    check_poses(out)
    check_ranges(sampler)
    assert "group so101, at most 1.5 rad/s, 6 rad/s^2, 60 rad/s^3, period 10 ms" in out
    assert "on exit            hold: shoulder_pan done" in out
    # the snapshots: written, or the summary says why not (no OpenGL context here)
    shots = [tmp_path / "so101_pick.png", tmp_path / "so101_scene.png"]
    if "snapshot           skipped: " in out:
        assert not any(p.exists() for p in shots)
    else:
        assert all(is_png(p) for p in shots)
        assert "snapshot (pick)" in out and "snapshot (end)" in out


RIG_WITHOUT_GROUP = """
namespace: another
buses:
  arm: {type: mujoco, model: so101, keyframe: rest, pacing: realtime}
components:
  - {name: gripper, driver: mujoco, device: effector, bus: arm}
  - {name: wrist_roll, driver: mujoco, device: joint, bus: arm}
  - {name: wrist_flex, driver: mujoco, device: joint, bus: arm}
  - {name: elbow_flex, driver: mujoco, device: joint, bus: arm}
  - {name: shoulder_lift, driver: mujoco, device: joint, bus: arm}
  - {name: shoulder_pan, driver: mujoco, device: joint, bus: arm}
"""


def test_the_app_runs_unchanged_on_a_rig_without_its_group(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Only the six components by name: the app's own group and timer (its defaults)."""
    monkeypatch.setenv("MUJOCO_GL", "disable")
    rig = tmp_path / "another.yaml"
    rig.write_text(RIG_WITHOUT_GROUP)
    status, out, sampler = run(
        ["--virtual", "--period-ms", "20", "--out", str(tmp_path)], capsys, rig
    )
    assert status == 0, out
    check_poses(out)
    check_ranges(sampler)
    assert "the app's group, at most 1.5 rad/s, 6 rad/s^2, 60 rad/s^3, period 20 ms" in out
    assert "snapshot           skipped: rendering disabled" in out


def test_a_rig_without_a_component_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rig = tmp_path / "five.yaml"
    rig.write_text(
        RIG_WITHOUT_GROUP.replace(
            "  - {name: gripper, driver: mujoco, device: effector, bus: arm}\n", ""
        )
    )
    sampler = Sampler()
    status = run_app(find_app("so101"), ["--virtual"], prog="so101", hooks=[sampler], rig=rig)
    assert status == 2 and sampler.names == []  # refused before anything opens
    err = capsys.readouterr().err
    assert "five.yaml has no component 'gripper' (the app takes it by name)" in err


def test_the_poses_lie_inside_the_joint_ranges() -> None:
    model = load_model("so101")
    for name, pose in app.POSES.items():
        for joint, value in zip(app.ARM, pose.joints, strict=True):
            low, high = (float(v) for v in model.joint(joint).range)
            assert low + 0.04 <= value <= high - 0.04, (name, joint)
    assert app.demo_args.__name__ == "demo_args"
    assert find_app("so101") is app.APP_INFO and app.APP_INFO.takes_rig
