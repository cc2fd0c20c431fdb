"""A 3D scene for the live view and the recorder: body poses as frame transforms and their
geometry as primitives, handed over by whoever knows the bodies (a MuJoCo rig's driver module
``openel_mujoco.foxglove_scene``); the framework never imports a driver.
"""

from __future__ import annotations

from array import array
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal, Protocol

from .schemas import stamp

__all__ = [
    "PoseBytesSource",
    "PoseSource",
    "Primitive",
    "SceneSource",
    "Transform",
    "flat_poses",
    "poses_from_bytes",
    "poses_message",
    "scene_message",
    "transforms_message",
]

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]
"""(x, y, z, w)."""


@dataclass(frozen=True, slots=True)
class Transform:
    """The pose of frame ``child`` in frame ``parent``."""

    parent: str
    child: str
    translation: Vec3
    rotation: Quat


@dataclass(frozen=True, slots=True)
class Primitive:
    """A shape fixed to the frame ``frame``: a cube (size = edge lengths), a sphere (size =
    diameters) or a cylinder along z (size = x/y diameters and height)."""

    shape: Literal["cube", "sphere", "cylinder"]
    frame: str
    position: Vec3
    orientation: Quat
    size: Vec3
    color: tuple[float, float, float, float]


class SceneSource(Protocol):
    """What a rig offers the live view and the recorder."""

    def transforms(self) -> Sequence[Transform]:
        """The current pose of every body (called at the joint-state rate, in the control
        loop's task: it must be cheap)."""
        ...

    def primitives(self) -> Sequence[Primitive]:
        """The geometry, in the bodies' frames (called once)."""
        ...


class PoseSource(SceneSource, Protocol):
    """A :class:`SceneSource` that also hands its poses over as plain numbers (the fast path
    the recorder takes when a source offers it: no :class:`Transform` per body and sample,
    the message built in the writer process)."""

    def frames(self) -> Sequence[tuple[str, str]]:
        """``(parent, child)`` of each transform, in the order of :meth:`poses` (fixed)."""
        ...

    def poses(self) -> list[float]:
        """``x, y, z, qx, qy, qz, qw`` of each frame of :meth:`frames`, one flat list (called
        at the joint-state rate, in the control loop's task: it must be cheap)."""
        ...


class PoseBytesSource(PoseSource, Protocol):
    """A :class:`PoseSource` that hands its poses over as two byte strings (the cheapest:
    no float object per number in the control loop; the writer process unpacks them)."""

    def pose_bytes(self) -> tuple[bytes, bytes]:
        """``(positions, orientations)`` of each frame of :meth:`frames`: float64 in the
        machine's byte order, ``x, y, z`` per frame, then ``w, x, y, z`` per frame."""
        ...


def poses_from_bytes(positions: bytes, orientations: bytes) -> list[float]:
    """The flat ``x, y, z, qx, qy, qz, qw`` list (:meth:`PoseSource.poses`) of
    :meth:`PoseBytesSource.pose_bytes`."""
    xyz = array("d")
    xyz.frombytes(positions)
    wxyz = array("d")
    wxyz.frombytes(orientations)
    n = len(xyz) // 3
    if len(xyz) != 3 * n or len(wxyz) != 4 * n:
        raise ValueError(
            f"pose_bytes: 3 and 4 float64 per frame expected, got {len(xyz)} and {len(wxyz)}"
        )
    out: list[float] = []
    for k in range(n):
        p, q = 3 * k, 4 * k
        out += (xyz[p], xyz[p + 1], xyz[p + 2], wxyz[q + 1], wxyz[q + 2], wxyz[q + 3], wxyz[q])
    return out


def flat_poses(
    transforms: Sequence[Transform],
) -> tuple[tuple[tuple[str, str], ...], list[float]]:
    """``(frames, poses)`` of ``transforms``, as :class:`PoseSource` gives them."""
    frames = tuple((t.parent, t.child) for t in transforms)
    poses = [v for t in transforms for v in (*t.translation, *t.rotation)]
    return frames, poses


def _xyz(v: Vec3) -> dict[str, float]:
    return {"x": v[0], "y": v[1], "z": v[2]}


def _quat(q: Quat) -> dict[str, float]:
    return {"x": q[0], "y": q[1], "z": q[2], "w": q[3]}


def transforms_message(transforms: Sequence[Transform], time_ns: int) -> dict[str, Any]:
    """A ``foxglove.FrameTransforms`` message."""
    ts = stamp(time_ns)
    return {
        "transforms": [
            {
                "timestamp": ts,
                "parent_frame_id": t.parent,
                "child_frame_id": t.child,
                "translation": _xyz(t.translation),
                "rotation": _quat(t.rotation),
            }
            for t in transforms
        ]
    }


def poses_message(
    frames: Sequence[Sequence[str]], poses: Sequence[float], time_ns: int
) -> dict[str, Any]:
    """The ``foxglove.FrameTransforms`` message of :meth:`PoseSource.poses` (the same as
    :func:`transforms_message` of the same transforms)."""
    if len(poses) != 7 * len(frames):
        raise ValueError(f"poses: 7 numbers per frame expected, got {len(poses)} for {len(frames)}")
    ts = stamp(time_ns)
    return {
        "transforms": [
            {
                "timestamp": ts,
                "parent_frame_id": parent,
                "child_frame_id": child,
                "translation": {"x": poses[k], "y": poses[k + 1], "z": poses[k + 2]},
                "rotation": {
                    "x": poses[k + 3],
                    "y": poses[k + 4],
                    "z": poses[k + 5],
                    "w": poses[k + 6],
                },
            }
            for k, (parent, child) in zip(range(0, len(poses), 7), frames, strict=True)
        ]
    }


def scene_message(primitives: Sequence[Primitive], time_ns: int) -> dict[str, Any]:
    """A ``foxglove.SceneUpdate`` message: one entity per frame, locked to it."""
    ts = stamp(time_ns)
    entities: dict[str, dict[str, Any]] = {}
    for p in primitives:
        entity = entities.setdefault(
            p.frame,
            {
                "timestamp": ts,
                "frame_id": p.frame,
                "id": p.frame,
                "lifetime": {"sec": 0, "nsec": 0},
                "frame_locked": True,
                "metadata": [],
                "cubes": [],
                "spheres": [],
                "cylinders": [],
            },
        )
        r, g, b, a = p.color
        item: dict[str, Any] = {
            "pose": {"position": _xyz(p.position), "orientation": _quat(p.orientation)},
            "size": _xyz(p.size),
            "color": {"r": r, "g": g, "b": b, "a": a},
        }
        if p.shape == "cylinder":
            item["bottom_scale"] = item["top_scale"] = 1.0
        entities[p.frame][f"{p.shape}s"].append(item)
        del entity
    return {"deletions": [], "entities": list(entities.values())}
