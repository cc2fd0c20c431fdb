"""Offscreen snapshots of a MuJoCo scene (PNG), in-process or in a renderer process.

Two ways to render, with the same GL backend selection and the same ``None`` without OpenGL:

* :func:`render_snapshot` / :func:`render_rgb`: synchronous, in the calling process (offline
  use, scripts).  A GL context is created and freed per call: ~0.3-0.5 s with Mesa's llvmpipe,
  holding the GIL most of the time, so never call them from the event loop (not even through
  ``anyio.to_thread``: the loop would stall for ~0.25-0.5 s).
* :class:`SnapshotRenderer`: a long-lived renderer process (``sys.executable`` running this
  file; ``MujocoSim.render_snapshot`` uses one per running simulation through
  :func:`render_in_worker`).  The caller captures the scene synchronously
  (:meth:`SnapshotRequest.capture`: the model's content token, and ``mj_getState`` with
  ``mjSTATE_INTEGRATION``: time, qpos, qvel, act, ctrl, applied forces, mocap poses, ...) and
  the worker restores the state into its own ``MjData``, runs ``mj_forward`` and renders.  The
  model travels once per worker (as MJB bytes; the caller sends it again only when the model's
  content changed or the worker was restarted) and the worker keeps its GL context and one
  ``MjrContext`` per model (LRU of 4), so only the first snapshot of a worker pays the process
  start and the GL set-up.  The event loop only pickles a few hundred bytes per snapshot (plus
  ``mj_saveModel`` + a compare of the model's MJB, ~0.1-1 ms, to notice model edits).  Every
  snapshot is bounded (``SnapshotRenderer.timeout``, 60 s by default, worker start included);
  a timeout or a cancellation kills the worker (the next snapshot starts a new one).  The worker exits when the owner closes it, when its stdin
  closes, or when its parent process dies.

Costs, measured on 2 cores with Mesa's llvmpipe (arm2, 800x600): the first snapshot of a
worker ~1-2 s (interpreter and imports ~0.8 s, then EGL context, model upload and first render
~0.5 s), the next ones ~0.15-0.4 s (``mjr_render`` + ``mjr_readPixels`` ~0.12-0.3 s, PNG
~40 ms); more on a busy machine, since the worker runs at nice 10 (the application goes
first).  The event loop spends ~1.5 ms of CPU per snapshot, in slices well under 1 ms
(capture ~0.25 ms), plus ~5-10 ms once per worker (process spawn, model upload); rendering in
a worker thread blocked it for ~0.25-0.5 s per snapshot (the GIL).  A worker process is
~300 MB resident (MuJoCo, NumPy, llvmpipe) while it lives.

OpenGL backend: ``mujoco.Renderer`` binds its backend once, from ``MUJOCO_GL``, when ``mujoco``
is first imported; on a headless Linux box without ``MUJOCO_GL`` that backend is GLFW, which
cannot open a context.  This module therefore drives the same classic renderer
(``MjrContext`` / ``mjr_render`` / ``mjr_readPixels``, exactly what ``mujoco.Renderer`` does
internally) with a GL context it picks itself, trying in order:

* the backend named by ``MUJOCO_GL`` (``egl``, ``osmesa``, ``glfw``, ``cgl``) if set,
* ``egl`` (headless; Mesa's llvmpipe software device works without a GPU),
* ``osmesa`` (software; needs ``libosmesa6``),
* ``glfw`` (only when ``DISPLAY``/``WAYLAND_DISPLAY`` is set, or on macOS/Windows; without a
  display GLFW "succeeds" in creating a context that MuJoCo then rejects, and the failed
  ``MjrContext`` leaves MuJoCo unable to render with any other backend in that process).

``MUJOCO_GL=disable`` (or ``off``/``0``/...) disables rendering (the renderer process reads
the environment it was started with).  The first backend that works is remembered for the
process; if none works every call returns ``None`` without raising.  PNGs are written
atomically (temporary file, then rename), with zlib (no matplotlib import).
"""

from __future__ import annotations

import collections
import contextlib
import importlib
import itertools
import os
import pathlib
import pickle
import platform
import signal
import struct
import subprocess
import sys
import threading
import time
import weakref
import zlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import TracebackType
from typing import Any, BinaryIO, Final, Self

import anyio
import anyio.abc
import mujoco
import numpy as np
import numpy.typing as npt
import structlog
from anyio.streams.buffered import BufferedByteReceiveStream

from openel_async.logs import get_logger

__all__ = [
    "RenderWorkerError",
    "SnapshotRenderer",
    "SnapshotRequest",
    "gl_backend",
    "render_in_worker",
    "render_rgb",
    "render_snapshot",
    "renderer_for",
]

log = get_logger(__name__)

_DISABLED: Final = frozenset({"disable", "disabled", "off", "false", "0"})
_MODULES: Final = {
    "egl": "mujoco.egl",
    "osmesa": "mujoco.osmesa",
    "glfw": "mujoco.glfw",
    "cgl": "mujoco.cgl",
}
_STATE_SIG: Final = int(mujoco.mjtState.mjSTATE_INTEGRATION)
"""What a snapshot carries of ``MjData``: everything ``mj_forward`` needs to rebuild the scene."""
DEFAULT_TIMEOUT_S: Final = 60.0
"""Default bound on one out-of-process snapshot, worker start included."""

_lock = threading.Lock()
_backend: str | None = None  # name of the backend that worked (in this process)
_probed = False  # True once every candidate failed (or one worked)


# -- GL backend selection ------------------------------------------------------------------


def _has_display() -> bool:
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def _candidates() -> list[str]:
    requested = os.environ.get("MUJOCO_GL", "").strip().lower()
    if requested in _DISABLED:
        return []
    system = platform.system()
    if system == "Linux":
        # GLFW without a display does not fail cleanly (it leaves MuJoCo's GL state broken
        # for the other backends), so it is only tried when a display is present.
        order = ["egl", "osmesa", "glfw"] if _has_display() else ["egl", "osmesa"]
    elif system == "Darwin":
        order = ["cgl", "glfw"]
    else:
        order = ["glfw"]
    if requested in order:
        order = [requested] + [b for b in order if b != requested]
    return order


class _NoContextError(Exception):
    """The backend could not create a GL context; the next backend may be tried."""


def _create_context(backend: str, width: int, height: int) -> Any:
    """A GL context of ``backend``, made current; ``_NoContextError`` when there is none."""
    saved_platform = os.environ.get("PYOPENGL_PLATFORM")
    try:
        module = importlib.import_module(_MODULES[backend])
        context = module.GLContext(width, height)
    except Exception as exc:
        # mujoco.egl / mujoco.osmesa set PYOPENGL_PLATFORM on import; undo that on failure so
        # that the next backend can still claim PyOpenGL (if it has not been loaded yet)
        if saved_platform is None:
            os.environ.pop("PYOPENGL_PLATFORM", None)
        else:
            os.environ["PYOPENGL_PLATFORM"] = saved_platform
        raise _NoContextError(repr(exc)) from exc
    try:
        context.make_current()
    except Exception as exc:
        _free(context)
        raise _NoContextError(repr(exc)) from exc
    return context


def _free(obj: Any) -> None:
    try:
        obj.free()
    except Exception as exc:  # a failing free must not turn a snapshot into an error
        log.debug("mujoco_render_free_failed", error=repr(exc))


# -- scene -----------------------------------------------------------------------------------


def _check_size(model: mujoco.MjModel, width: int, height: int) -> None:
    if width <= 0 or height <= 0:
        raise ValueError(f"image size must be positive, got {width}x{height}")
    off_w, off_h = int(model.vis.global_.offwidth), int(model.vis.global_.offheight)
    if width > off_w or height > off_h:
        raise ValueError(
            f"image {width}x{height} exceeds the model's offscreen buffer {off_w}x{off_h}; "
            'raise <visual><global offwidth=".." offheight=".."/> in the model'
        )


def _camera_id(model: mujoco.MjModel, camera: str | int | None) -> int:
    """The camera's id, -1 for the default free camera; ``ValueError`` if unknown."""
    if camera is None or camera == -1:
        return -1
    cam_id = (
        mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera)
        if isinstance(camera, str)
        else int(camera)
    )
    if not 0 <= cam_id < model.ncam:
        raise ValueError(f"unknown camera {camera!r} (model has {model.ncam} cameras)")
    return cam_id


def _camera(model: mujoco.MjModel, cam_id: int) -> mujoco.MjvCamera:
    cam = mujoco.MjvCamera()
    if cam_id == -1:
        cam.type = mujoco.mjtCamera.mjCAMERA_FREE
        mujoco.mjv_defaultFreeCamera(model, cam)
    else:
        cam.type = mujoco.mjtCamera.mjCAMERA_FIXED
        cam.fixedcamid = cam_id
    return cam


def _new_mjr(model: mujoco.MjModel) -> Any:
    return mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_150.value)


def _new_scene(model: mujoco.MjModel) -> Any:
    return mujoco.MjvScene(model, maxgeom=max(1000, 4 * model.ngeom))


def _draw(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    mjr: Any,
    scene: Any,
    cam_id: int,
    width: int,
    height: int,
) -> npt.NDArray[np.uint8]:
    """Render ``data`` with ``mjr`` (its GL context current) into an RGB image."""
    mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN.value, mjr)
    mujoco.mjv_updateScene(
        model,
        data,
        mujoco.MjvOption(),
        None,
        _camera(model, cam_id),
        mujoco.mjtCatBit.mjCAT_ALL.value,
        scene,
    )
    rect = mujoco.MjrRect(0, 0, width, height)
    mujoco.mjr_render(rect, scene, mjr)
    rgb = np.empty((height, width, 3), dtype=np.uint8)
    mujoco.mjr_readPixels(rgb, None, rect, mjr)
    return np.ascontiguousarray(np.flipud(rgb))


# -- PNG -------------------------------------------------------------------------------------


def _png_chunk(tag: bytes, body: bytes) -> bytes:
    return struct.pack(">I", len(body)) + tag + body + struct.pack(">I", zlib.crc32(tag + body))


def _png_bytes(rgb: npt.NDArray[np.uint8]) -> bytes:
    """``rgb`` (h, w, 3 uint8) as a PNG file, every row with the "Up" filter."""
    height, width = int(rgb.shape[0]), int(rgb.shape[1])
    rows = rgb.reshape(height, width * 3)
    filtered = np.empty((height, width * 3 + 1), dtype=np.uint8)
    filtered[:, 0] = 2  # Up: each byte minus the byte above it (mod 256)
    filtered[0, 1:] = rows[0]
    np.subtract(rows[1:], rows[:-1], out=filtered[1:, 1:])
    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)  # 8-bit RGB
    return b"".join(
        (
            b"\x89PNG\r\n\x1a\n",
            _png_chunk(b"IHDR", header),
            _png_chunk(b"IDAT", zlib.compress(filtered.tobytes(), 6)),
            _png_chunk(b"IEND", b""),
        )
    )


def _write_png(path: pathlib.Path, rgb: npt.NDArray[np.uint8]) -> None:
    """Write atomically: a reader never sees a partial file, a killed writer leaves none."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        tmp.write_bytes(_png_bytes(rgb))
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


# -- in-process rendering ------------------------------------------------------------------


def _render_once(
    backend: str,
    model: mujoco.MjModel,
    data: mujoco.MjData,
    cam_id: int,
    width: int,
    height: int,
) -> npt.NDArray[np.uint8]:
    context = _create_context(backend, width, height)
    try:
        mjr = _new_mjr(model)
        try:
            return _draw(model, data, mjr, _new_scene(model), cam_id, width, height)
        finally:
            _free(mjr)
    finally:
        _free(context)


def render_rgb(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    *,
    width: int = 640,
    height: int = 480,
    camera: str | int | None = None,
) -> npt.NDArray[np.uint8] | None:
    """Render ``data`` as an ``(height, width, 3)`` uint8 image, or ``None`` without OpenGL.

    In this process, synchronously (~0.3-0.5 s with llvmpipe: a GL context per call).
    ``camera`` is a camera name or id of the model, or ``None`` for the default free camera.
    The scene is taken from ``data`` as it is (call ``mj_forward`` after editing ``qpos``).
    Raises ``ValueError`` for an unknown camera or a size above the model's offscreen buffer
    (``<visual><global offwidth offheight>``); never raises for a missing GL context.
    """
    global _backend, _probed
    _check_size(model, width, height)
    cam_id = _camera_id(model, camera)
    with _lock:
        if _backend is not None:
            candidates = [_backend]
        elif _probed:
            return None
        else:
            candidates = _candidates()
        tried: list[str] = []
        for backend in candidates:
            tried.append(backend)
            try:
                rgb = _render_once(backend, model, data, cam_id, width, height)
            except _NoContextError as exc:  # no GL context with this backend: try the next one
                log.debug("mujoco_render_backend_failed", backend=backend, error=str(exc))
                continue
            except Exception as exc:
                # a context was created but MuJoCo's renderer failed in it; after such a
                # failure MuJoCo's GL state is not trustworthy, so no other backend is tried
                log.warning("mujoco_render_failed", backend=backend, error=repr(exc))
                break
            _backend, _probed = backend, True
            return rgb
        if not _probed:
            log.info("mujoco_render_unavailable", tried=tried)
        _probed = True
        return None


def gl_backend() -> str | None:
    """Name of the GL backend that rendered successfully in this process (``None`` if none yet).

    A :class:`SnapshotRenderer` reports its worker's backend as ``renderer.backend``.
    """
    return _backend


def render_snapshot(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    path: str | os.PathLike[str],
    *,
    width: int = 640,
    height: int = 480,
    camera: str | int | None = None,
) -> pathlib.Path | None:
    """Render ``data`` offscreen in this process and write it as a PNG to ``path``.

    Returns the path, or ``None`` (and writes nothing) when no OpenGL context can be created.
    Parent directories are created.  See :func:`render_rgb` for ``camera`` and the size limits;
    from the event loop use :class:`SnapshotRenderer` (or ``MujocoSim.render_snapshot``).
    """
    rgb = render_rgb(model, data, width=width, height=height, camera=camera)
    if rgb is None:
        return None
    out = pathlib.Path(path)
    _write_png(out, rgb)
    return out


# -- the renderer process (worker side) ----------------------------------------------------

_MAX_FRAME: Final = 1 << 31
_WORKER_MODELS: Final = 4  # models (with their MjrContext) a worker keeps
_PARENT_POLL_S: Final = 1.0
_WORKER_NICE: Final = 10


def _write_frame(out: BinaryIO, message: object) -> None:
    payload = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
    out.write(struct.pack(">I", len(payload)) + payload)
    out.flush()


def _read_frame(inp: BinaryIO) -> Any:
    """The next message, or ``None`` at end of input."""
    header = inp.read(4)
    if len(header) < 4:
        return None
    (size,) = struct.unpack(">I", header)
    payload = inp.read(size)
    if len(payload) < size:
        return None
    return pickle.loads(payload)


@dataclass
class _CachedModel:
    model: mujoco.MjModel
    data: mujoco.MjData
    mjr: Any = None  # MjrContext, created in the worker's GL context on first render
    scene: Any = None

    def free_gl(self) -> None:
        if self.mjr is not None:
            _free(self.mjr)
        self.mjr = self.scene = None


class _WorkerRenderer:
    """The renderer process's state: one GL context, the models it was sent (LRU)."""

    def __init__(self) -> None:
        self.models: collections.OrderedDict[int, _CachedModel] = collections.OrderedDict()
        self.context: Any = None
        self.backend: str | None = None
        self.probed = False

    def model(self, token: int, mjb: bytes | None) -> tuple[_CachedModel | None, bool]:
        """The cached model ``token`` (loaded from ``mjb`` if given); ``(None, _)`` if unknown."""
        entry = self.models.get(token)
        if entry is not None:
            self.models.move_to_end(token)
            return entry, False
        if mjb is None:
            return None, False
        model = mujoco.MjModel.from_binary_path("model.mjb", {"model.mjb": mjb})
        entry = _CachedModel(model, mujoco.MjData(model))
        self.models[token] = entry
        while len(self.models) > _WORKER_MODELS:
            _, evicted = self.models.popitem(last=False)
            evicted.free_gl()
        return entry, True

    def draw(
        self, entry: _CachedModel, cam_id: int, width: int, height: int
    ) -> npt.NDArray[np.uint8]:
        if entry.mjr is None:
            entry.mjr = _new_mjr(entry.model)
            entry.scene = _new_scene(entry.model)
        return _draw(entry.model, entry.data, entry.mjr, entry.scene, cam_id, width, height)

    def render(
        self, entry: _CachedModel, cam_id: int, width: int, height: int
    ) -> npt.NDArray[np.uint8] | None:
        """Same backend rules as :func:`render_rgb`, but the context is kept."""
        if self.context is not None:
            try:
                return self.draw(entry, cam_id, width, height)
            except Exception as exc:
                log.warning("mujoco_render_failed", backend=self.backend, error=repr(exc))
                entry.free_gl()
                return None
        if self.probed:
            return None
        self.probed = True
        tried: list[str] = []
        for backend in _candidates():
            tried.append(backend)
            try:
                context = _create_context(backend, width, height)
            except _NoContextError as exc:
                log.debug("mujoco_render_backend_failed", backend=backend, error=str(exc))
                continue
            try:
                rgb = self.draw(entry, cam_id, width, height)
            except Exception as exc:  # as render_rgb: no other backend after this
                log.warning("mujoco_render_failed", backend=backend, error=repr(exc))
                entry.free_gl()
                _free(context)
                return None
            self.context, self.backend = context, backend
            return rgb
        log.info("mujoco_render_unavailable", tried=tried)
        return None

    def handle(self, message: tuple[Any, ...]) -> tuple[Any, ...]:
        """Answer one request: ``("ok", path | None, info)``, ``("missing",)`` or raise."""
        _, token, mjb, state, path, width, height, cam_id = message
        t_start = time.monotonic()
        entry, loaded = self.model(token, mjb)
        if entry is None:
            return ("missing",)
        model, data = entry.model, entry.data
        _check_size(model, width, height)
        if not -1 <= cam_id < model.ncam:
            raise ValueError(f"unknown camera {cam_id!r} (model has {model.ncam} cameras)")
        mujoco.mj_setState(model, data, np.frombuffer(state, dtype=np.float64).copy(), _STATE_SIG)
        mujoco.mj_forward(model, data)
        t_forward = time.monotonic()
        rgb = self.render(entry, cam_id, width, height)
        t_render = time.monotonic()
        written: str | None = None
        if rgb is not None:
            _write_png(pathlib.Path(path), rgb)
            written = path
        t_end = time.monotonic()
        info = {
            "backend": self.backend,
            "model_loaded": loaded,
            "t_start": t_start,
            "t_end": t_end,
            "render_s": t_render - t_forward,
            "png_s": t_end - t_render,
            "pid": os.getpid(),
        }
        return ("ok", written, info)

    def close(self) -> None:
        for entry in self.models.values():
            entry.free_gl()
        self.models.clear()
        if self.context is not None:
            _free(self.context)
            self.context = None


def _watch_parent() -> None:
    """Exit when the parent process is gone (a hung render must not outlive it)."""
    parent = os.getppid()

    def watch() -> None:
        while True:
            time.sleep(_PARENT_POLL_S)
            if os.getppid() != parent:
                os._exit(1)

    threading.Thread(target=watch, name="parent-watch", daemon=True).start()


def _worker_main() -> None:
    """The renderer process: answer length-prefixed pickled requests on stdin/stdout."""
    # stdout carries the protocol only: anything else writing to fd 1 (MuJoCo's C code,
    # print) goes to stderr, which the worker shares with its parent
    out = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    inp = sys.stdin.buffer
    with contextlib.suppress(ValueError, OSError):  # Ctrl+C is the parent's business
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    events: list[tuple[str, str, dict[str, Any]]] = []

    def collect(_logger: Any, method: str, event_dict: Any) -> Any:
        event = str(event_dict.pop("event", ""))
        fields = {
            k: v if isinstance(v, str | int | float | bool | None) else repr(v)
            for k, v in event_dict.items()
        }
        events.append((method, event, fields))
        raise structlog.DropEvent

    # log records go back to the parent with the answer (its logging configuration applies)
    structlog.configure(processors=[collect], cache_logger_on_first_use=False)
    _watch_parent()
    worker = _WorkerRenderer()
    _write_frame(out, ("ready", os.getpid()))
    try:
        while True:
            message = _read_frame(inp)
            if message is None:
                break
            try:
                reply = worker.handle(message)
            except Exception as exc:
                reply = ("error", type(exc).__name__, str(exc))
            _write_frame(out, (*reply, list(events)))
            events.clear()
    finally:
        worker.close()


# -- the renderer process (caller side) ----------------------------------------------------


class RenderWorkerError(RuntimeError):
    """The renderer process failed (crashed, broken pipe, unexpected error in the worker)."""


_REPLAYED_ERRORS: Final[dict[str, type[Exception]]] = {
    cls.__name__: cls
    for cls in (
        ValueError,
        OSError,
        PermissionError,
        FileNotFoundError,
        FileExistsError,
        IsADirectoryError,
        NotADirectoryError,
    )
}
"""Errors of the worker raised again as such (bad arguments, the PNG cannot be written)."""


@dataclass
class _ModelBytes:
    token: int
    mjb: bytes
    scratch: npt.NDArray[np.uint8]


_models: weakref.WeakKeyDictionary[mujoco.MjModel, _ModelBytes] = weakref.WeakKeyDictionary()
_models_lock = threading.Lock()
_tokens = itertools.count(1)


def _model_bytes(model: mujoco.MjModel) -> _ModelBytes:
    """The model's MJB and a token naming that content (a new token whenever it changes)."""
    with _models_lock:
        size = mujoco.mj_sizeModel(model)
        entry = _models.get(model)
        if entry is not None and entry.scratch.size == size:
            mujoco.mj_saveModel(model, None, entry.scratch)
            if np.array_equal(entry.scratch, np.frombuffer(entry.mjb, dtype=np.uint8)):
                return entry
        buffer = np.empty(size, dtype=np.uint8)
        mujoco.mj_saveModel(model, None, buffer)
        entry = _ModelBytes(next(_tokens), buffer.tobytes(), buffer)
        _models[model] = entry
        return entry


@dataclass(frozen=True, slots=True)
class SnapshotRequest:
    """One snapshot to take: the model (content token and MJB) and the state at capture time."""

    model_token: int
    mjb: bytes = field(repr=False)
    state: bytes = field(repr=False)
    time: float
    path: pathlib.Path
    width: int
    height: int
    camera_id: int

    @classmethod
    def capture(
        cls,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        path: str | os.PathLike[str],
        *,
        width: int = 640,
        height: int = 480,
        camera: str | int | None = None,
    ) -> SnapshotRequest:
        """Capture the scene now (synchronously); ``ValueError`` as :func:`render_rgb`."""
        _check_size(model, width, height)
        cam_id = _camera_id(model, camera)
        model_bytes = _model_bytes(model)
        state = np.empty(mujoco.mj_stateSize(model, _STATE_SIG), dtype=np.float64)
        mujoco.mj_getState(model, data, state, _STATE_SIG)
        return cls(
            model_token=model_bytes.token,
            mjb=model_bytes.mjb,
            state=state.tobytes(),
            time=float(data.time),
            path=pathlib.Path(path).absolute(),
            width=int(width),
            height=int(height),
            camera_id=cam_id,
        )


_WORKER_BOOT: Final = (
    "import importlib.util, os, sys\n"
    "try:\n"
    f"    os.nice({_WORKER_NICE})  # background work: the application goes first\n"
    "except (AttributeError, OSError):\n"
    "    pass\n"
    "path, sys.path[:] = sys.argv[1], sys.argv[2:]\n"
    "spec = importlib.util.spec_from_file_location('_openel_mujoco_render_worker', path)\n"
    "module = importlib.util.module_from_spec(spec)\n"
    "sys.modules[spec.name] = module\n"
    "spec.loader.exec_module(module)\n"
    "module._worker_main()\n"
)
"""The worker lowers its priority, then loads this file by path, without the package (it
needs mujoco, numpy, structlog and anyio, not openel_async)."""


class SnapshotRenderer:
    """A renderer process for snapshots taken from the event loop (see the module docstring).

    ``async with SnapshotRenderer() as renderer:`` (or :meth:`aclose`); the process starts on
    the first snapshot (or :meth:`start`) and again after it was killed.  ``env`` adds to the
    environment the process starts with (e.g. ``{"MUJOCO_GL": "egl"}``).  Snapshots are taken
    one at a time, in call order.  Not thread-safe: use it from one event loop.
    """

    def __init__(
        self, *, env: Mapping[str, str] | None = None, timeout: float = DEFAULT_TIMEOUT_S
    ) -> None:
        if not timeout > 0:
            raise ValueError(f"timeout must be > 0 s, got {timeout!r}")
        self._env = dict(env) if env is not None else None
        self.timeout = float(timeout)
        """Bound on one snapshot (worker start included): ``TimeoutError`` and the worker is
        killed when it passes (wrap a call in ``anyio.fail_after`` for a tighter bound)."""
        self._process: anyio.abc.Process | None = None
        self._stdout: BufferedByteReceiveStream | None = None
        self._sent: set[int] = set()  # model tokens the current process has
        self._lock = anyio.Lock()
        self._closed = False
        self.backend: str | None = None
        """GL backend of the worker (``None``: none yet, or no OpenGL)."""
        self.processes_started = 0
        self.models_sent = 0
        """Models shipped to a worker (once per model content and worker process)."""
        self.snapshots = 0
        self.last_info: dict[str, Any] = {}
        """The worker's report on the last snapshot (``model_loaded``, ``render_s``, ...)."""

    @property
    def pid(self) -> int | None:
        """Process id of the running worker, if any."""
        return self._process.pid if self._process is not None else None

    async def __aenter__(self) -> Self:
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self.aclose()

    async def aclose(self) -> None:
        """Kill the worker (if any) and wait for it; further snapshots raise."""
        self._closed = True
        await self._kill()

    async def start(self) -> None:
        """Start the worker now (otherwise the first snapshot does); no-op if running."""
        with anyio.fail_after(self.timeout):
            async with self._lock:
                self._check_open()
                if self._process is None:
                    try:
                        await self._spawn()
                    except BaseException as exc:
                        await self._kill()
                        wrapped = self._wrap(exc)
                        if wrapped is exc:
                            raise
                        raise wrapped from exc

    async def render_snapshot(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        path: str | os.PathLike[str],
        *,
        width: int = 640,
        height: int = 480,
        camera: str | int | None = None,
    ) -> pathlib.Path | None:
        """Render the state ``data`` has now to a PNG at ``path`` in the worker.

        As :func:`render_snapshot` (``None`` without OpenGL, ``ValueError`` for a bad camera
        or size) but the state is captured at the call, the worker runs ``mj_forward`` on it,
        and the event loop keeps running.  ``TimeoutError`` after :attr:`timeout` seconds (the
        worker is killed, as on cancellation); :class:`RenderWorkerError` if the worker fails.
        """
        request = SnapshotRequest.capture(
            model, data, path, width=width, height=height, camera=camera
        )
        return await self.render(request)

    async def render(self, request: SnapshotRequest) -> pathlib.Path | None:
        """Render a captured :class:`SnapshotRequest` (see :meth:`render_snapshot`)."""
        with anyio.fail_after(self.timeout):
            async with self._lock:
                self._check_open()
                try:
                    answer = await self._exchange(request)
                except BaseException as exc:
                    # cancelled, timed out or broken mid-exchange: the worker's state is
                    # unknown (it may still be rendering), so it goes
                    await self._kill()
                    wrapped = self._wrap(exc)
                    if wrapped is exc:
                        raise
                    raise wrapped from exc
        if answer[0] == "ok":
            _, written, info = answer
            self.snapshots += 1
            self.backend = info["backend"]
            self.last_info = info
            return pathlib.Path(written) if written is not None else None
        if answer[0] == "error":  # raised by the worker, which stays up
            _, kind, text = answer
            raise _REPLAYED_ERRORS.get(kind, RenderWorkerError)(
                text if kind in _REPLAYED_ERRORS else f"{kind}: {text}"
            )
        raise RenderWorkerError(f"unexpected answer from the renderer process: {answer!r}")

    def _check_open(self) -> None:
        if self._closed:
            raise anyio.ClosedResourceError("the snapshot renderer is closed")

    @staticmethod
    def _wrap(exc: BaseException) -> BaseException:
        if isinstance(exc, anyio.BrokenResourceError | anyio.EndOfStream | OSError):
            return RenderWorkerError(f"the renderer process failed: {exc!r}")
        if isinstance(exc, anyio.IncompleteRead):
            return RenderWorkerError("the renderer process exited")
        return exc

    async def _spawn(self) -> None:
        env = {**os.environ, **self._env} if self._env is not None else None
        command = [sys.executable, "-c", _WORKER_BOOT, __file__, *sys.path]
        self._process = await anyio.open_process(
            command, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=None, env=env
        )
        assert self._process.stdout is not None
        self._stdout = BufferedByteReceiveStream(self._process.stdout)
        self._sent.clear()
        self.processes_started += 1
        ready = await self._receive()
        if not (isinstance(ready, tuple) and ready[:1] == ("ready",)):
            raise RenderWorkerError(f"unexpected greeting from the renderer process: {ready!r}")
        log.debug("mujoco_renderer_started", pid=self._process.pid)

    async def _send(self, message: object) -> None:
        assert self._process is not None and self._process.stdin is not None
        payload = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
        await self._process.stdin.send(struct.pack(">I", len(payload)) + payload)

    async def _receive(self) -> Any:
        assert self._stdout is not None
        (size,) = struct.unpack(">I", await self._stdout.receive_exactly(4))
        if size > _MAX_FRAME:
            raise RenderWorkerError(f"oversized answer from the renderer process ({size} B)")
        return pickle.loads(await self._stdout.receive_exactly(size))

    async def _exchange(self, request: SnapshotRequest) -> list[Any]:
        """Send ``request`` (and the model, if the worker lacks it); the worker's answer."""
        if self._process is None:
            await self._spawn()
        while True:
            send_model = request.model_token not in self._sent
            await self._send(
                (
                    "render",
                    request.model_token,
                    request.mjb if send_model else None,
                    request.state,
                    str(request.path),
                    request.width,
                    request.height,
                    request.camera_id,
                )
            )
            *answer, events = await self._receive()
            for method, event, fields in events:
                getattr(log, method, log.info)(event, renderer_pid=self.pid, **fields)
            if send_model:
                self.models_sent += 1
                self._sent.add(request.model_token)
            elif answer[0] == "missing":  # evicted by the worker: send it again
                self._sent.discard(request.model_token)
                continue
            return list(answer)

    async def _kill(self) -> None:
        process, self._process, self._stdout = self._process, None, None
        self._sent.clear()
        if process is None:
            return
        with anyio.CancelScope(shield=True), anyio.move_on_after(10):
            with contextlib.suppress(ProcessLookupError):
                process.kill()
            await process.aclose()
            log.debug("mujoco_renderer_stopped", pid=process.pid, returncode=process.returncode)


# -- one renderer per task group -----------------------------------------------------------

_group_renderers: dict[int, SnapshotRenderer] = {}


async def _keep(
    renderer: SnapshotRenderer,
    key: int,
    *,
    task_status: anyio.abc.TaskStatus[None] = anyio.TASK_STATUS_IGNORED,
) -> None:
    try:
        task_status.started()
        await anyio.sleep_forever()
    finally:
        if _group_renderers.get(key) is renderer:
            del _group_renderers[key]
        await renderer.aclose()


async def renderer_for(task_group: anyio.abc.TaskGroup) -> SnapshotRenderer:
    """The renderer shared by ``task_group``: created on first use, closed (its process
    killed) when the task group ends.  ``MujocoSim`` passes the task group of its run."""
    key = id(task_group)
    renderer = _group_renderers.get(key)
    if renderer is None:
        renderer = SnapshotRenderer()
        _group_renderers[key] = renderer  # before the await: concurrent callers share it
        try:
            await task_group.start(_keep, renderer, key)
        except BaseException:
            if _group_renderers.get(key) is renderer:
                del _group_renderers[key]
            await renderer.aclose()
            raise
    return renderer


async def render_in_worker(
    request: SnapshotRequest,
    *,
    task_group: anyio.abc.TaskGroup | None = None,
) -> pathlib.Path | None:
    """Render ``request`` in the renderer of ``task_group`` (see :func:`renderer_for`), or in
    a renderer process started for this snapshot only when ``task_group`` is ``None``.
    Bounded by :data:`DEFAULT_TIMEOUT_S` (worker start included)."""
    if task_group is None:
        async with SnapshotRenderer() as renderer:
            return await renderer.render(request)
    with anyio.fail_after(DEFAULT_TIMEOUT_S):
        renderer = await renderer_for(task_group)
    return await renderer.render(request)
