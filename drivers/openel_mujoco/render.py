"""Offscreen snapshots of a MuJoCo scene (PNG), degrading to ``None`` without OpenGL.

``mujoco.Renderer`` binds its OpenGL backend once, from ``MUJOCO_GL``, when ``mujoco`` is first
imported; on a headless Linux box without ``MUJOCO_GL`` that backend is GLFW, which cannot open a
context.  This module therefore drives the same classic renderer (``MjrContext`` /
``mjr_render`` / ``mjr_readPixels``, exactly what ``mujoco.Renderer`` does internally) with a GL
context it picks itself, trying in order:

* the backend named by ``MUJOCO_GL`` (``egl``, ``osmesa``, ``glfw``, ``cgl``) if set,
* ``egl`` (headless; Mesa's llvmpipe software device works without a GPU),
* ``osmesa`` (software; needs ``libosmesa6``),
* ``glfw`` (only when ``DISPLAY``/``WAYLAND_DISPLAY`` is set, or on macOS/Windows; without a
  display GLFW "succeeds" in creating a context that MuJoCo then rejects, and the failed
  ``MjrContext`` leaves MuJoCo unable to render with any other backend in that process).

``MUJOCO_GL=disable`` (or ``off``/``0``/...) disables rendering.  The first backend that works
is remembered for the process; if none works every call returns ``None`` without raising.
A context is created and freed per call (~0.3-0.5 s with Mesa llvmpipe), so this is meant for
snapshots, not video.
"""

from __future__ import annotations

import importlib
import os
import pathlib
import platform
import threading
from typing import Any, Final

import mujoco
import numpy as np
import numpy.typing as npt
import structlog

__all__ = ["gl_backend", "render_rgb", "render_snapshot"]

log = structlog.get_logger(__name__)

_DISABLED: Final = frozenset({"disable", "disabled", "off", "false", "0"})
_MODULES: Final = {
    "egl": "mujoco.egl",
    "osmesa": "mujoco.osmesa",
    "glfw": "mujoco.glfw",
    "cgl": "mujoco.cgl",
}

_lock = threading.Lock()
_backend: str | None = None  # name of the backend that worked
_probed = False  # True once every candidate failed (or one worked)


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
    saved_platform = os.environ.get("PYOPENGL_PLATFORM")
    try:
        module = importlib.import_module(_MODULES[backend])
        return module.GLContext(width, height)
    except Exception as exc:
        # mujoco.egl / mujoco.osmesa set PYOPENGL_PLATFORM on import; undo that on failure so
        # that the next backend can still claim PyOpenGL (if it has not been loaded yet)
        if saved_platform is None:
            os.environ.pop("PYOPENGL_PLATFORM", None)
        else:
            os.environ["PYOPENGL_PLATFORM"] = saved_platform
        raise _NoContextError(repr(exc)) from exc


def _free(obj: Any) -> None:
    try:
        obj.free()
    except Exception as exc:  # a failing free must not turn a snapshot into an error
        log.debug("mujoco_render_free_failed", error=repr(exc))


def _camera(model: mujoco.MjModel, camera: str | int | None) -> mujoco.MjvCamera:
    cam = mujoco.MjvCamera()
    if camera is None or camera == -1:
        cam.type = mujoco.mjtCamera.mjCAMERA_FREE
        mujoco.mjv_defaultFreeCamera(model, cam)
        return cam
    cam_id = (
        mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera)
        if isinstance(camera, str)
        else camera
    )
    if not 0 <= cam_id < model.ncam:
        raise ValueError(f"unknown camera {camera!r} (model has {model.ncam} cameras)")
    cam.type = mujoco.mjtCamera.mjCAMERA_FIXED
    cam.fixedcamid = cam_id
    return cam


def _render_with(
    backend: str,
    model: mujoco.MjModel,
    data: mujoco.MjData,
    cam: mujoco.MjvCamera,
    width: int,
    height: int,
) -> npt.NDArray[np.uint8]:
    context = _create_context(backend, width, height)
    try:
        try:
            context.make_current()
        except Exception as exc:
            raise _NoContextError(repr(exc)) from exc
        mjr = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_150.value)
        try:
            mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN.value, mjr)
            scene = mujoco.MjvScene(model, maxgeom=max(1000, 4 * model.ngeom))
            mujoco.mjv_updateScene(
                model,
                data,
                mujoco.MjvOption(),
                None,
                cam,
                mujoco.mjtCatBit.mjCAT_ALL.value,
                scene,
            )
            rect = mujoco.MjrRect(0, 0, width, height)
            mujoco.mjr_render(rect, scene, mjr)
            rgb = np.empty((height, width, 3), dtype=np.uint8)
            mujoco.mjr_readPixels(rgb, None, rect, mjr)
        finally:
            _free(mjr)
    finally:
        _free(context)
    return np.ascontiguousarray(np.flipud(rgb))


def render_rgb(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    *,
    width: int = 640,
    height: int = 480,
    camera: str | int | None = None,
) -> npt.NDArray[np.uint8] | None:
    """Render ``data`` as an ``(height, width, 3)`` uint8 image, or ``None`` without OpenGL.

    ``camera`` is a camera name or id of the model, or ``None`` for the default free camera.
    The scene is taken from ``data`` as it is (call ``mj_forward`` after editing ``qpos``).
    Raises ``ValueError`` for an unknown camera or a size above the model's offscreen buffer
    (``<visual><global offwidth offheight>``); never raises for a missing GL context.
    """
    global _backend, _probed
    if width <= 0 or height <= 0:
        raise ValueError(f"image size must be positive, got {width}x{height}")
    off_w, off_h = int(model.vis.global_.offwidth), int(model.vis.global_.offheight)
    if width > off_w or height > off_h:
        raise ValueError(
            f"image {width}x{height} exceeds the model's offscreen buffer {off_w}x{off_h}; "
            'raise <visual><global offwidth=".." offheight=".."/> in the model'
        )
    cam = _camera(model, camera)
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
                rgb = _render_with(backend, model, data, cam, width, height)
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
    """Name of the GL backend that rendered successfully in this process (``None`` if none yet)."""
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
    """Render ``data`` offscreen and write it as a PNG to ``path``; return the path.

    Returns ``None`` (and writes nothing) when no OpenGL context can be created.  Parent
    directories are created.  See :func:`render_rgb` for ``camera`` and the size limits.
    """
    rgb = render_rgb(model, data, width=width, height=height, camera=camera)
    if rgb is None:
        return None
    from matplotlib import image as mpl_image  # lazy: matplotlib import is slow

    out = pathlib.Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    mpl_image.imsave(out, rgb, format="png")
    return out
