"""Snapshots rendered out of process: the event loop keeps running, state captured at the call,
the model shipped once per worker, bounded and cancellable waits, no process left behind."""

from __future__ import annotations

import os
import pathlib
import signal
import sys
import time
from collections.abc import AsyncIterator

import anyio
import mujoco
import numpy as np
import numpy.typing as npt
import pytest
from matplotlib import image as mpl_image

from openel_mujoco import MujocoSim, load_model, render
from openel_mujoco.render import RenderWorkerError, SnapshotRenderer, SnapshotRequest

pytestmark = pytest.mark.render  # the module is about rendering

NO_GL = {"MUJOCO_GL": "disable"}
posix_only = pytest.mark.skipif(sys.platform == "win32", reason="SIGSTOP/SIGKILL (POSIX)")


def arm2(shoulder: float = 0.0, elbow: float = 0.0) -> tuple[mujoco.MjModel, mujoco.MjData]:
    model = load_model("arm2")
    data = mujoco.MjData(model)
    data.qpos[:2] = shoulder, elbow
    return model, data


def image(path: pathlib.Path) -> npt.NDArray[np.float32]:
    return np.asarray(mpl_image.imread(path), dtype=np.float32)[..., :3]


def difference(a: pathlib.Path, b: pathlib.Path) -> float:
    return float(np.mean(np.abs(image(a) - image(b))))


def gl_or_skip(out: pathlib.Path | None) -> pathlib.Path:
    if out is None:
        pytest.skip("no OpenGL backend works here (egl/osmesa): rendering returns None")
    return out


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


@pytest.fixture
async def renderer() -> AsyncIterator[SnapshotRenderer]:
    async with SnapshotRenderer() as r:
        yield r


@pytest.fixture
async def renderer_without_gl() -> AsyncIterator[SnapshotRenderer]:
    async with SnapshotRenderer(env=NO_GL) as r:
        yield r


# --------------------------------------------------------------------------- PNG encoder


def test_png_encoder_round_trips(tmp_path: pathlib.Path) -> None:
    rgb = np.random.default_rng(1).integers(0, 256, size=(7, 5, 3), dtype=np.uint8)
    rgb[3:] = rgb[2]  # equal rows: the Up filter's zero case
    render._write_png(tmp_path / "x.png", rgb)
    decoded = np.asarray(mpl_image.imread(tmp_path / "x.png"))
    assert decoded.shape == (7, 5, 3)
    assert np.array_equal(np.round(decoded * 255).astype(np.uint8), rgb)
    assert os.listdir(tmp_path) == ["x.png"]  # the temporary file was renamed


# --------------------------------------------------------------------------- worker, with GL


async def test_snapshot_is_a_png_of_the_requested_size(
    renderer: SnapshotRenderer, tmp_path: pathlib.Path
) -> None:
    model, data = arm2(0.4, -0.6)
    target = tmp_path / "snap" / "arm2.png"
    out = gl_or_skip(
        await renderer.render_snapshot(model, data, target, width=96, height=64, camera="overview")
    )
    assert out == target
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    pixels = image(out)
    assert pixels.shape == (64, 96, 3)
    assert float(np.std(pixels)) > 0.01  # not a blank frame
    assert os.listdir(out.parent) == ["arm2.png"]
    assert renderer.backend is not None
    assert renderer.last_info["pid"] == renderer.pid != os.getpid()
    with pytest.raises(ValueError, match="unknown camera"):
        await renderer.render_snapshot(model, data, tmp_path / "x.png", camera="nope")
    with pytest.raises(ValueError, match="offscreen buffer"):
        await renderer.render_snapshot(model, data, tmp_path / "x.png", width=4000, height=64)
    (tmp_path / "file").write_bytes(b"")
    with pytest.raises(OSError):  # raised in the worker, which stays up
        await renderer.render_snapshot(
            model, data, tmp_path / "file" / "x.png", width=96, height=64
        )
    assert renderer.processes_started == 1


async def test_event_loop_and_realtime_physics_run_while_the_worker_renders(
    tmp_path: pathlib.Path,
) -> None:
    sim = MujocoSim("arm2", pacing="realtime")  # MonotonicClock: real time
    step_times: list[float] = []
    tick_times: list[float] = []
    sim.add_step_hook(lambda: step_times.append(time.monotonic()))

    async def ticker() -> None:
        while True:
            tick_times.append(time.monotonic())
            await anyio.sleep(0.001)

    async with sim, anyio.create_task_group() as tg:
        tg.start_soon(ticker)
        steps = sim.steps
        written = await sim.render_snapshot(tmp_path / "rt.png", width=96, height=64)
        renderer = await render.renderer_for(sim._tg)  # type: ignore[arg-type]  # the sim's
        tg.cancel_scope.cancel()
    assert gl_or_skip(written).is_file()
    assert sim.steps > steps
    # the worker reports when it rendered (time.monotonic is system-wide): the event loop ran
    # and the real-time physics stepped during that window, while the old in-thread renderer
    # held the GIL for most of it
    start, end = renderer.last_info["t_start"], renderer.last_info["t_end"]
    assert renderer.last_info["pid"] != os.getpid()
    assert any(start < t < end for t in tick_times)
    assert any(start < t < end for t in step_times)


async def test_state_is_captured_at_the_call(
    renderer: SnapshotRenderer, tmp_path: pathlib.Path
) -> None:
    model, data = arm2(0.0, 0.0)
    size = {"width": 96, "height": 64, "camera": "overview"}
    pose_a = gl_or_skip(await renderer.render_snapshot(model, data, tmp_path / "a.png", **size))
    data.qpos[:2] = 1.2, -1.5
    pose_b = await renderer.render_snapshot(model, data, tmp_path / "b.png", **size)
    assert pose_b is not None
    gap = difference(pose_a, pose_b)
    assert gap > 0.001  # the two poses look different

    # a request captured now renders the state of now, whatever happens to data afterwards
    data.qpos[:2] = 0.0, 0.0
    request = SnapshotRequest.capture(model, data, tmp_path / "captured.png", **size)
    data.qpos[:2] = 1.2, -1.5
    captured = await renderer.render(request)
    assert captured is not None
    assert difference(captured, pose_a) < gap / 10

    # same through render_snapshot: data changes while the worker renders
    data.qpos[:2] = 0.0, 0.0
    late: list[pathlib.Path | None] = []

    async def take() -> None:
        late.append(await renderer.render_snapshot(model, data, tmp_path / "late.png", **size))

    async with anyio.create_task_group() as tg:
        tg.start_soon(take)
        await anyio.wait_all_tasks_blocked()  # the task took its snapshot and waits for it
        data.qpos[:2] = 1.2, -1.5
    assert late[0] is not None
    assert difference(late[0], pose_a) < gap / 10
    assert renderer.processes_started == 1
    assert renderer.models_sent == 1


# --------------------------------------------------------------------------- worker, any GL


async def test_worker_without_gl_returns_none(
    renderer_without_gl: SnapshotRenderer, tmp_path: pathlib.Path
) -> None:
    model, data = arm2()
    for _ in range(2):
        assert await renderer_without_gl.render_snapshot(model, data, tmp_path / "n.png") is None
    assert not (tmp_path / "n.png").exists()
    assert renderer_without_gl.backend is None
    assert renderer_without_gl.processes_started == 1  # the worker stays up
    assert renderer_without_gl.snapshots == 2


async def test_worker_caches_the_model(
    renderer_without_gl: SnapshotRenderer, tmp_path: pathlib.Path
) -> None:
    r = renderer_without_gl
    model, data = arm2()
    await r.render_snapshot(model, data, tmp_path / "1.png")
    assert (r.models_sent, r.last_info["model_loaded"]) == (1, True)
    data.qpos[0] = 1.0
    await r.render_snapshot(model, data, tmp_path / "2.png")
    assert (r.models_sent, r.last_info["model_loaded"]) == (1, False)  # only the state went
    model.geom_rgba[0] = (1.0, 0.0, 0.0, 1.0)  # an edited model is sent again
    await r.render_snapshot(model, data, tmp_path / "3.png")
    assert (r.models_sent, r.last_info["model_loaded"]) == (2, True)
    other, other_data = arm2()  # another model object: its own entry, sent once
    await r.render_snapshot(other, other_data, tmp_path / "4.png")
    assert r.models_sent == 3 and r.last_info["model_loaded"] is True
    await r.render_snapshot(model, data, tmp_path / "5.png")
    assert (r.models_sent, r.last_info["model_loaded"]) == (3, False)
    assert r.processes_started == 1


async def test_worker_cache_evicts_and_reloads(tmp_path: pathlib.Path) -> None:
    worker = render._WorkerRenderer()
    model, _ = arm2()
    request = SnapshotRequest.capture(model, mujoco.MjData(model), tmp_path / "x.png")
    for token in range(1, render._WORKER_MODELS + 2):
        entry, loaded = worker.model(token, request.mjb)
        assert loaded and entry is not None
    assert list(worker.models) == list(range(2, render._WORKER_MODELS + 2))  # LRU: 1 went
    assert worker.model(1, None) == (None, False)  # the caller is asked for the model again
    assert worker.model(2, None)[1] is False


@posix_only
async def test_timeout_kills_a_hung_worker(tmp_path: pathlib.Path) -> None:
    model, data = arm2()
    async with SnapshotRenderer(env=NO_GL) as r:
        await r.start()
        pid = r.pid
        assert pid is not None
        os.kill(pid, signal.SIGSTOP)  # hung: it never answers
        r.timeout = 0.2
        with pytest.raises(TimeoutError):
            await r.render_snapshot(model, data, tmp_path / "x.png")
        assert r.pid is None and not alive(pid)  # killed and reaped
        r.timeout = render.DEFAULT_TIMEOUT_S
        assert await r.render_snapshot(model, data, tmp_path / "x.png") is None  # a new worker
        assert r.processes_started == 2 and r.models_sent == 1


@posix_only
async def test_cancel_kills_the_worker(tmp_path: pathlib.Path) -> None:
    model, data = arm2()
    async with SnapshotRenderer(env=NO_GL) as r:
        await r.start()
        pid = r.pid
        assert pid is not None
        os.kill(pid, signal.SIGSTOP)
        async with anyio.create_task_group() as tg:
            tg.start_soon(r.render_snapshot, model, data, tmp_path / "x.png")
            await anyio.wait_all_tasks_blocked()
            tg.cancel_scope.cancel()
        assert r.pid is None and not alive(pid)
    with pytest.raises(anyio.ClosedResourceError):
        await r.render_snapshot(model, data, tmp_path / "x.png")


@posix_only
async def test_a_dead_worker_is_an_error_then_replaced(
    renderer_without_gl: SnapshotRenderer, tmp_path: pathlib.Path
) -> None:
    r = renderer_without_gl
    model, data = arm2()
    await r.start()
    assert r.pid is not None
    os.kill(r.pid, signal.SIGKILL)
    with pytest.raises(RenderWorkerError):
        await r.render_snapshot(model, data, tmp_path / "x.png")
    assert await r.render_snapshot(model, data, tmp_path / "x.png") is None
    assert r.processes_started == 2


# --------------------------------------------------------------------------- MujocoSim


@posix_only  # alive(): os.kill(pid, 0) terminates the process on Windows
async def test_sim_shares_one_worker_and_kills_it_at_exit(
    tmp_path: pathlib.Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("MUJOCO_GL", "disable")  # the worker inherits it (no GL needed here)
    sim = MujocoSim("arm2")
    async with sim:
        await sim.sleep(0.01)
        before = sim.clock.now_ns()
        assert await sim.render_snapshot(tmp_path / "1.png") is None
        assert await sim.render_snapshot(tmp_path / "2.png") is None
        assert sim.clock.now_ns() == before  # lockstep: paused while the worker rendered
        renderer = await render.renderer_for(sim._tg)  # type: ignore[arg-type]
        pid = renderer.pid
        assert pid is not None and alive(pid)
        assert (renderer.processes_started, renderer.snapshots, renderer.models_sent) == (1, 2, 1)
    assert renderer.pid is None and not alive(pid)  # no renderer outlives the simulation
    # outside 'async with sim' a snapshot runs in a worker of its own, gone afterwards
    assert await sim.render_snapshot(tmp_path / "3.png") is None
