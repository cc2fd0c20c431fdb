"""A MuJoCo simulation's bodies for the live view and the recorder: their poses as frame
transforms and their geoms as scene primitives (``openel_async.recording.SceneSource``), so
that the arm moves in Foxglove's 3D panel; and a replay rig over the same models.

The framework never imports this module: an app hands the scene over
(``ctx.add_scene(MujocoScene(sim))``), ``openel-async replay --rig
openel_mujoco.foxglove_scene:replay_rig --rig-arg arm2`` names the rig.
"""

from __future__ import annotations

from collections.abc import AsyncIterator, Sequence
from contextlib import AsyncExitStack, asynccontextmanager

import mujoco
import numpy as np

from openel_async import Actuator
from openel_async.recording.reader import Recording
from openel_async.recording.replay import ReplayRig, RigFactory, actuator_channels
from openel_async.recording.scene import Primitive, Transform

from .sim import MujocoSim

__all__ = ["WORLD_FRAME", "MujocoScene", "replay_rig"]

WORLD_FRAME = "world"
_XYZW = [1, 2, 3, 0]  # MuJoCo's quaternions are (w, x, y, z)


class MujocoScene:
    """The bodies of ``sim``: one frame per body (its name, child of ``world``), one
    primitive per box, sphere, cylinder or capsule geom (a capsule drawn as a cylinder over
    its whole length), planes as thin slabs."""

    def __init__(self, sim: MujocoSim) -> None:
        self.sim = sim
        m = sim.model
        self._bodies = [
            (b, mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b) or f"body{b}")
            for b in range(1, m.nbody)
        ]
        self._poses = np.empty((m.nbody - 1, 7))
        self._data = sim.data
        self._xpos = sim.data.xpos[1:]  # views: every body but the world
        self._xquat = sim.data.xquat[1:]

    def _frame(self, body: int) -> str:
        if body == 0:
            return WORLD_FRAME
        return mujoco.mj_id2name(self.sim.model, mujoco.mjtObj.mjOBJ_BODY, body) or f"body{body}"

    def frames(self) -> Sequence[tuple[str, str]]:
        """``(world, body)`` for every body but the world, in the order of :meth:`poses`."""
        return [(WORLD_FRAME, name) for _, name in self._bodies]

    def poses(self) -> list[float]:
        """Every body's position and orientation (x, y, z, qx, qy, qz, qw), flat: one gather
        of ``xpos`` and ``xquat`` (the recorder's fast path; :meth:`transforms` gives the
        same as objects)."""
        d = self.sim.data
        poses = self._poses
        poses[:, :3] = d.xpos[1:]
        poses[:, 3:] = d.xquat[1:, _XYZW]
        return poses.ravel().tolist()

    def pose_bytes(self) -> tuple[bytes, bytes]:
        """Every body's position (x, y, z) and orientation (w, x, y, z: MuJoCo's order) as
        float64 bytes (``openel_async.recording.PoseBytesSource``: the recorder's cheapest
        path, two C calls; the writer process unpacks them)."""
        if self.sim.data is not self._data:  # a new MjData: new views
            self._data = self.sim.data
            self._xpos, self._xquat = self._data.xpos[1:], self._data.xquat[1:]
        return self._xpos.tobytes(), self._xquat.tobytes()

    def transforms(self) -> Sequence[Transform]:
        d = self.sim.data
        out = []
        for b, name in self._bodies:
            x, y, z = d.xpos[b]
            w, qx, qy, qz = d.xquat[b]
            out.append(
                Transform(
                    WORLD_FRAME,
                    name,
                    (float(x), float(y), float(z)),
                    (float(qx), float(qy), float(qz), float(w)),
                )
            )
        return out

    def primitives(self) -> Sequence[Primitive]:
        m = self.sim.model
        g = mujoco.mjtGeom
        out = []
        for i in range(m.ngeom):
            kind = int(m.geom_type[i])
            s = [float(v) for v in m.geom_size[i]]
            if kind == g.mjGEOM_BOX:
                shape, size = "cube", (2 * s[0], 2 * s[1], 2 * s[2])
            elif kind == g.mjGEOM_SPHERE:
                shape, size = "sphere", (2 * s[0],) * 3
            elif kind == g.mjGEOM_CYLINDER:
                shape, size = "cylinder", (2 * s[0], 2 * s[0], 2 * s[1])
            elif kind == g.mjGEOM_CAPSULE:
                shape, size = "cylinder", (2 * s[0], 2 * s[0], 2 * (s[1] + s[0]))
            elif kind == g.mjGEOM_PLANE:
                shape = "cube"
                size = (2 * s[0] if s[0] > 0 else 4.0, 2 * s[1] if s[1] > 0 else 4.0, 0.002)
            else:  # meshes, ellipsoids, height fields: not drawn
                continue
            px, py, pz = (float(v) for v in m.geom_pos[i])
            w, qx, qy, qz = (float(v) for v in m.geom_quat[i])
            r, gr, b, a = (float(v) for v in m.geom_rgba[i])
            out.append(
                Primitive(
                    shape,  # type: ignore[arg-type]
                    self._frame(int(m.geom_bodyid[i])),
                    (px, py, pz),
                    (qx, qy, qz, w),
                    size,
                    (r, gr, b, a),
                )
            )
        return out


def replay_rig(model: str = "arm2") -> RigFactory:
    """A replay rig: the shipped model (or MJCF path) ``model`` in lockstep, one Actuator per
    recorded actuator on the joint the recording names (channel metadata ``device``)."""

    @asynccontextmanager
    async def factory(recording: Recording) -> AsyncIterator[ReplayRig]:
        sim = MujocoSim(model, pacing="lockstep")
        async with AsyncExitStack() as stack:
            await stack.enter_async_context(sim)
            actuators = {}
            for name, metadata in actuator_channels(recording).items():
                joint = metadata.get("device", name)
                actuator = Actuator(sim.actuator(joint), device_name=name, clock=sim.clock)
                actuators[name] = await stack.enter_async_context(actuator)
            yield ReplayRig(sim.clock, actuators, f"MuJoCo {model} (lockstep)")

    return factory
