"""One app, two rigs: the so101 app traces the same poses on the real arm's rig run against
simulated STS3215s (rigs/so101.yaml --sim: the serial stack on a pty, in real time) and on the
MuJoCo model (rigs/so101-mujoco.yaml, lockstep) -- in process, step by step."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from openel_apps import so101 as app
from openel_async.app import AppContext, find_app, run_app

pytestmark = pytest.mark.timeout(60)

RIGS = Path(__file__).parents[2] / "apps" / "openel_apps" / "rigs"


def trace(
    monkeypatch: pytest.MonkeyPatch, argv: list[str], rig: Path, *, sim: bool
) -> app.So101Result:
    """Run the app; the result of its run (every step's actual positions and gripper)."""
    results: list[app.So101Result] = []
    original = app.run_so101

    async def recording(ctx: AppContext, rig: app.So101Rig, **kw: Any) -> app.So101Result:
        result = await original(ctx, rig, **kw)
        results.append(result)
        return result

    monkeypatch.setattr(app, "run_so101", recording)
    status = run_app(find_app("so101"), argv, prog="so101", rig=rig, sim=sim)
    assert status == 0
    (result,) = results
    return result


def test_the_same_poses_on_the_simulated_servos_and_on_the_mujoco_model(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("MUJOCO_GL", "disable")
    monkeypatch.chdir(tmp_path)  # no so101.calibration.yaml here: the servos as shipped
    servos = trace(monkeypatch, [], RIGS / "so101.yaml", sim=True)
    model = trace(monkeypatch, ["--virtual", "--out", str(tmp_path)], RIGS / "so101-mujoco.yaml", sim=False)  # fmt: skip
    out = capsys.readouterr().out
    assert "SO-101 on so101.yaml" in out and "SO-101 on so101-mujoco.yaml" in out
    assert [s.name for s in servos.steps] == [s.name for s in model.steps]
    assert [s.name for s in servos.steps] == [s.name for s in app.SEQUENCE]
    for a, b, step in zip(servos.steps, model.steps, app.SEQUENCE, strict=True):
        assert a.reached and b.reached, step.name
        if step.pose is not None:
            target = app.POSES[step.pose].joints
            for joint, t, x, y in zip(app.ARM, target, a.positions, b.positions, strict=True):
                assert x == pytest.approx(t, abs=app.GOAL_TOLERANCE_RAD), (step.name, joint)
                assert y == pytest.approx(t, abs=app.GOAL_TOLERANCE_RAD), (step.name, joint)
                assert x == pytest.approx(y, abs=2 * app.GOAL_TOLERANCE_RAD), (step.name, joint)
        if a.gripper_target is not None:
            assert a.gripper_target == b.gripper_target
            # the model's fingers may stop on the object; the servo has nothing to close on
            assert a.gripper == pytest.approx(a.gripper_target, abs=app.GRIPPER_TOLERANCE)
            assert b.gripper == pytest.approx(a.gripper, abs=0.5), step.name
    for joint in app.ARM:
        low_a, high_a = servos.joint_ranges[joint]
        low_b, high_b = model.joint_ranges[joint]
        assert low_a == pytest.approx(low_b, abs=2 * app.GOAL_TOLERANCE_RAD), joint
        assert high_a == pytest.approx(high_b, abs=2 * app.GOAL_TOLERANCE_RAD), joint
