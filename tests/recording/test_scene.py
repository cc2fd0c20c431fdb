"""The scene's body poses on /tf: handed over as plain numbers (PoseSource) or as Transform
objects, the FrameTransforms message built in the writer process the same either way."""

from __future__ import annotations

import math
from array import array
from collections.abc import Sequence
from pathlib import Path

import anyio
import pytest

from openel_async import Actuator, EventTimer, Request, VirtualClock
from openel_async.recording import Primitive, Recorder, Transform, read_recording
from openel_async.recording.scene import (
    flat_poses,
    poses_from_bytes,
    poses_message,
    transforms_message,
)
from openel_sim import SimMotor

from .schema_check import check_recording


class _Arm:
    """A one-link "arm": its link's pose follows a sim motor's position (Transform objects
    only: the recorder flattens them itself)."""

    def __init__(self, motor: SimMotor) -> None:
        self.motor = motor

    def transforms(self) -> Sequence[Transform]:
        angle = self.motor.read_nowait(Request.POSITION_ACTUAL)
        half = angle / 2
        return [
            Transform("world", "base", (0.0, 0.0, 0.1), (0.0, 0.0, 0.0, 1.0)),
            Transform("base", "link", (0.2, 0.0, 0.0), (0.0, 0.0, math.sin(half), math.cos(half))),
        ]

    def primitives(self) -> Sequence[Primitive]:
        return [
            Primitive("cube", "link", (0.1, 0, 0), (0, 0, 0, 1), (0.2, 0.02, 0.02), (1, 0, 0, 1))
        ]


class _FastArm(_Arm):
    """The same arm, offering its poses as plain numbers (PoseSource)."""

    def frames(self) -> Sequence[tuple[str, str]]:
        return [("world", "base"), ("base", "link")]

    def poses(self) -> list[float]:
        return flat_poses(self.transforms())[1]


class _BytesArm(_FastArm):
    """The same arm, offering its poses as bytes (PoseBytesSource: w, x, y, z quaternions)."""

    def pose_bytes(self) -> tuple[bytes, bytes]:
        flat = self.poses()
        xyz = array("d", [v for k in range(0, len(flat), 7) for v in flat[k : k + 3]])
        wxyz = array(
            "d", [v for k in range(0, len(flat), 7) for v in (flat[k + 6], *flat[k + 3 : k + 6])]
        )
        return xyz.tobytes(), wxyz.tobytes()


@pytest.mark.parametrize("source_class", [_Arm, _FastArm, _BytesArm])
async def test_tf_messages_match_the_transforms(tmp_path: Path, source_class: type[_Arm]) -> None:
    clock = VirtualClock()
    motor = SimMotor(max_velocity=3.0, max_acceleration=40.0)
    path = tmp_path / "scene.mcap"
    expected: list[dict[str, object]] = []
    async with clock.autojump(), Recorder(path, joint_period_ms=10) as recorder:
        axis = Actuator(motor, clock=clock)
        timer = EventTimer(10, clock=clock, name="loop")
        recorder.observe(axis)
        recorder.observe_timer(timer)
        async with axis, timer:
            source = source_class(motor)
            recorder.add_scene(source)
            expected.append(transforms_message(source.transforms(), 0))
            done = anyio.Event()

            def on_tick(t: EventTimer) -> None:
                expected.append(transforms_message(source.transforms(), 0))
                if len(expected) == 20:
                    t.stop_timer()
                    done.set()

            timer.add_observer(on_tick)  # after the recorder's: the same poses it sampled
            await axis.set_value(1.0, Request.POSITION)
            timer.start_timer()
            await done.wait()
    tf = read_recording(path).topic("/tf")
    assert len(tf) == 20  # the first at add_scene, then one per joint-state sample
    for message, want in zip(tf, expected, strict=True):
        for got, transform in zip(message["transforms"], want["transforms"], strict=True):  # type: ignore[call-overload]
            assert got["timestamp"]["sec"] > 0  # wall-clock log time
            del got["timestamp"], transform["timestamp"]
            assert got == transform
    angles = [m["transforms"][1]["rotation"]["z"] for m in tf]
    assert angles[0] == 0.0 and angles[-1] > angles[1] > 0.0  # the link turned
    assert read_recording(path).topic("/scene")[0]["entities"][0]["frame_id"] == "link"
    assert check_recording(path) > 0  # /tf and /scene fit their schemas too


def test_poses_message_checks_its_numbers() -> None:
    with pytest.raises(ValueError, match="7 numbers per frame"):
        poses_message([("world", "a")], [0.0] * 6, 0)
    with pytest.raises(ValueError, match="3 and 4 float64 per frame"):
        poses_from_bytes(array("d", [0.0] * 3).tobytes(), array("d", [1.0] * 3).tobytes())


def test_mujoco_scene_poses_are_its_transforms() -> None:
    pytest.importorskip("mujoco")
    from openel_mujoco import MujocoSim
    from openel_mujoco.foxglove_scene import MujocoScene

    sim = MujocoSim("arm2", pacing="lockstep")
    scene = MujocoScene(sim)
    sim.data.qpos[:] = [0.3, -0.7]
    import mujoco

    mujoco.mj_forward(sim.model, sim.data)
    transforms = scene.transforms()
    assert poses_message(scene.frames(), scene.poses(), 5) == transforms_message(transforms, 5)
    assert poses_from_bytes(*scene.pose_bytes()) == scene.poses()
    assert any(t.rotation != (0.0, 0.0, 0.0, 1.0) for t in transforms)


def test_arm6_hands_its_scene_over_to_the_hooks() -> None:
    """arm6 gives a recorder or a live view its MuJoCo scene, as arm2 does (its recordings
    had no /tf and no /scene: the shipped layout's 3D panel was empty); without hooks it
    builds none."""
    pytest.importorskip("mujoco")
    from openel_apps.arm6_pick_place import open_sim
    from openel_async.app import AppContext, AppHook

    class Spy(AppHook):
        def __init__(self) -> None:
            self.scenes: list[object] = []

        def scene_added(self, ctx: AppContext, source: object) -> None:
            self.scenes.append(source)

    spy = Spy()
    sim = open_sim(realtime=False, ctx=AppContext(hooks=[spy]))
    (scene,) = spy.scenes
    frames = [child for _, child in scene.frames()]  # type: ignore[attr-defined]
    assert len(frames) >= 7 and len(scene.primitives()) > 0  # type: ignore[attr-defined]
    assert scene.sim is sim  # type: ignore[attr-defined]
    spy.scenes.clear()
    open_sim(realtime=False, ctx=AppContext())
    assert spy.scenes == []
