"""Shipped MuJoCo models and small model utilities for the openel_mujoco driver.

The MJCF files live in the ``models/`` directory next to this module (inside the package, so
hatchling ships them in the wheel).  Shipped names: ``arm2`` (planar 2-DoF arm), ``arm6``
(6-DoF arm with gravity) and ``so101`` (the SO-101 arm of LeRobot: five STS3215-like joints and
a gripper whose position servo acts on a tendon in opening units 0..1); each file documents
its joint, actuator, sensor and site names.

Control-mode switching
----------------------
Every joint of the shipped models (so101: every arm joint) has three actuators, ``<joint>_pos`` (position servo),
``<joint>_vel`` (velocity servo) and ``<joint>_torque`` (motor).  Actuators on one joint add
their forces, so exactly one of them may be active.  Each of the three is in its own actuator
group (``3 * joint_index + mode``) and the active set is selected with the run-time bit field
``model.opt.disableactuator`` (MJCF ``option/actuatorgroupdisable``): a disabled actuator
produces no force (``data.actuator_force`` is 0), contributes no implicit damping and ignores its
``ctrl``.  :func:`set_control_mode` flips the bits of one joint and initialises the newly active
actuator's ``ctrl`` (current angle for position mode, 0 otherwise), so the switch is bumpless.
The mode lives in the *model* (``opt.disableactuator``), not in ``MjData``: ``mj_resetData``
and keyframes do not change it.
"""

from __future__ import annotations

import difflib
import os
import pathlib
from collections.abc import Mapping
from typing import Any, Final, Literal, get_args

import mujoco

__all__ = [
    "ACTUATOR_SUFFIX",
    "MODELS_DIR",
    "SHIPPED_MODELS",
    "ControlMode",
    "ModelLoadError",
    "control_mode",
    "find_id",
    "joint_actuators",
    "load_model",
    "model_path",
    "names",
    "set_control_mode",
]

MODELS_DIR: Final[pathlib.Path] = pathlib.Path(__file__).resolve().parent / "models"
"""Directory holding the shipped MJCF files."""

SHIPPED_MODELS: Final[tuple[str, ...]] = ("arm2", "arm6", "so101")
"""Names accepted by :func:`model_path` and :func:`load_model`."""

ControlMode = Literal["position", "velocity", "torque"]
"""Joint control mode; selects which of the joint's three actuators is active."""

ACTUATOR_SUFFIX: Final[Mapping[ControlMode, str]] = {
    "position": "_pos",
    "velocity": "_vel",
    "torque": "_torque",
}
"""Actuator name = joint name + suffix, for each control mode."""

_MODES: Final[tuple[ControlMode, ...]] = get_args(ControlMode)

# object kind accepted by find_id -> (mjtObj, count attribute of MjModel)
_OBJ_KINDS: Final[Mapping[str, tuple[Any, str]]] = {
    "body": (mujoco.mjtObj.mjOBJ_BODY, "nbody"),
    "joint": (mujoco.mjtObj.mjOBJ_JOINT, "njnt"),
    "geom": (mujoco.mjtObj.mjOBJ_GEOM, "ngeom"),
    "site": (mujoco.mjtObj.mjOBJ_SITE, "nsite"),
    "camera": (mujoco.mjtObj.mjOBJ_CAMERA, "ncam"),
    "light": (mujoco.mjtObj.mjOBJ_LIGHT, "nlight"),
    "mesh": (mujoco.mjtObj.mjOBJ_MESH, "nmesh"),
    "material": (mujoco.mjtObj.mjOBJ_MATERIAL, "nmat"),
    "tendon": (mujoco.mjtObj.mjOBJ_TENDON, "ntendon"),
    "actuator": (mujoco.mjtObj.mjOBJ_ACTUATOR, "nu"),
    "sensor": (mujoco.mjtObj.mjOBJ_SENSOR, "nsensor"),
    "equality": (mujoco.mjtObj.mjOBJ_EQUALITY, "neq"),
    "key": (mujoco.mjtObj.mjOBJ_KEY, "nkey"),
}


class ModelLoadError(ValueError):
    """A model could not be loaded, or a named element does not exist in it."""


def model_path(name: str) -> pathlib.Path:
    """Path of the shipped model ``name`` (one of :data:`SHIPPED_MODELS`)."""
    if name not in SHIPPED_MODELS:
        raise ModelLoadError(
            f"unknown shipped model {name!r}; shipped models: {', '.join(SHIPPED_MODELS)}"
        )
    return MODELS_DIR / f"{name}.xml"


def load_model(source: str | os.PathLike[str]) -> mujoco.MjModel:
    """Compile a model from a shipped name (``"arm2"``, ``"arm6"``, ``"so101"``) or an MJCF/MJB
    file path.

    Raises :class:`ModelLoadError` if the file does not exist or MuJoCo rejects it (the message
    then includes MuJoCo's own error text).
    """
    if isinstance(source, str) and source in SHIPPED_MODELS:
        path = model_path(source)
    else:
        path = pathlib.Path(source).expanduser()
    if not path.is_file():
        shipped = ", ".join(SHIPPED_MODELS)
        if isinstance(source, str) and not path.suffix and len(path.parts) == 1:
            raise ModelLoadError(
                f"unknown model {source!r}: not a shipped model (shipped models: {shipped}) "
                f"and no file {path.resolve()}"
            )
        raise ModelLoadError(f"model file not found: {path.resolve()} (shipped models: {shipped})")
    try:
        if path.suffix.lower() == ".mjb":
            return mujoco.MjModel.from_binary_path(str(path))
        return mujoco.MjModel.from_xml_path(str(path))
    except Exception as exc:  # MuJoCo raises ValueError with the parser/compiler message
        message = " ".join(str(exc).split())
        raise ModelLoadError(f"cannot load MuJoCo model {path}: {message}") from exc


def _model_name(model: mujoco.MjModel) -> str:
    # the model name is the first entry of the names buffer
    raw = bytes(model.names).split(b"\0", 1)[0]
    return raw.decode("utf-8", "replace") or "model"


def names(model: mujoco.MjModel, obj_type: str) -> list[str]:
    """Names of all elements of kind ``obj_type`` (``"joint"``, ``"actuator"``, ...), in id order.

    Unnamed elements are listed as ``""``.
    """
    objtype, count_attr = _kind(obj_type)
    count = int(getattr(model, count_attr))
    return [mujoco.mj_id2name(model, objtype, i) or "" for i in range(count)]


def _kind(obj_type: str) -> tuple[Any, str]:
    try:
        return _OBJ_KINDS[obj_type]
    except KeyError:
        raise ValueError(
            f"unsupported object kind {obj_type!r}; supported: {', '.join(_OBJ_KINDS)}"
        ) from None


def find_id(model: mujoco.MjModel, obj_type: str, name: str) -> int:
    """Id of the element ``name`` of kind ``obj_type`` (``"joint"``, ``"actuator"``, ``"site"`` ...).

    Raises :class:`ModelLoadError` naming the kind and the name and listing the available names,
    e.g. ``unknown joint 'elbw'; joints in arm2: shoulder, elbow (did you mean 'elbow'?)``.
    """
    objtype, _ = _kind(obj_type)
    obj_id = int(mujoco.mj_name2id(model, objtype, name))
    if obj_id >= 0:
        return obj_id
    available = [n for n in names(model, obj_type) if n]
    listing = ", ".join(available) if available else "(none)"
    message = f"unknown {obj_type} {name!r}; {obj_type}s in {_model_name(model)}: {listing}"
    close = difflib.get_close_matches(name, available, n=1)
    if close:
        message += f" (did you mean {close[0]!r}?)"
    raise ModelLoadError(message)


def joint_actuators(model: mujoco.MjModel, joint: str) -> dict[ControlMode, int]:
    """Actuator ids of ``joint`` for each control mode, found by the ``<joint><suffix>`` names.

    Checks that each actuator drives ``joint`` and has an actuator group (0..30) of its own, as
    :func:`set_control_mode` requires.
    """
    joint_id = find_id(model, "joint", joint)
    groups = [int(g) for g in model.actuator_group]
    result: dict[ControlMode, int] = {}
    for mode in _MODES:
        act_name = joint + ACTUATOR_SUFFIX[mode]
        act_id = find_id(model, "actuator", act_name)
        if (
            int(model.actuator_trntype[act_id]) != mujoco.mjtTrn.mjTRN_JOINT
            or int(model.actuator_trnid[act_id, 0]) != joint_id
        ):
            raise ModelLoadError(f"actuator {act_name!r} does not drive joint {joint!r}")
        group = groups[act_id]
        if not 0 <= group <= 30 or groups.count(group) != 1:
            raise ModelLoadError(
                f"actuator {act_name!r} needs an actuator group in 0..30 of its own "
                f"for mode switching (group {group} is shared or out of range)"
            )
        result[mode] = act_id
    return result


def control_mode(model: mujoco.MjModel, joint: str) -> ControlMode | None:
    """The joint's active mode, or ``None`` if not exactly one of its actuators is enabled."""
    enabled = [
        mode
        for mode, act_id in joint_actuators(model, joint).items()
        if not model.opt.disableactuator & (1 << int(model.actuator_group[act_id]))
    ]
    return enabled[0] if len(enabled) == 1 else None


def set_control_mode(
    model: mujoco.MjModel, data: mujoco.MjData, joint: str, mode: ControlMode
) -> int:
    """Make ``mode``'s actuator the only active actuator on ``joint``; return its id.

    Sets the group bits of the joint's two other actuators in ``model.opt.disableactuator``,
    clears the bit of the selected one, zeroes the ctrl of the disabled ones and initialises the
    selected ctrl: position -> current joint angle (hold, clipped to ctrlrange), velocity and
    torque -> 0.  Takes effect at the next ``mj_step``/``mj_forward``.
    """
    if mode not in _MODES:
        raise ValueError(f"unknown control mode {mode!r}; expected one of {', '.join(_MODES)}")
    actuators = joint_actuators(model, joint)
    mask = int(model.opt.disableactuator)
    for other_mode, act_id in actuators.items():
        bit = 1 << int(model.actuator_group[act_id])
        if other_mode == mode:
            mask &= ~bit
        else:
            mask |= bit
            data.ctrl[act_id] = 0.0
    model.opt.disableactuator = mask
    act_id = actuators[mode]
    initial = 0.0
    if mode == "position":
        qadr = int(model.jnt_qposadr[find_id(model, "joint", joint)])
        initial = float(data.qpos[qadr])
        if model.actuator_ctrllimited[act_id]:
            low, high = (float(v) for v in model.actuator_ctrlrange[act_id])
            initial = min(max(initial, low), high)
    data.ctrl[act_id] = initial
    return act_id
