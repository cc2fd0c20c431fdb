"""Which of a model's actuators drive a joint, and in which control mode
(:func:`resolve_actuators`): the actuators a JointSpec names, else those named by the
``<joint>_pos`` / ``_vel`` / ``_torque`` convention, else the joint's actuators by their gain
and bias (position servo, velocity servo, motor).

Re-exported by :mod:`openel_mujoco.devices`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Final

import mujoco

from .description import JointSpec
from .models import ControlMode, ModelLoadError, find_id, names

__all__ = ["resolve_actuators"]

_SUFFIX: Final[Mapping[ControlMode, str]] = {
    "position": "_pos",
    "velocity": "_vel",
    "torque": "_torque",
}


def _drives(model: mujoco.MjModel, act: int, joint_id: int) -> bool:
    return (
        int(model.actuator_trntype[act]) == mujoco.mjtTrn.mjTRN_JOINT
        and int(model.actuator_trnid[act, 0]) == joint_id
    )


def _classify(model: mujoco.MjModel, act: int) -> ControlMode | None:
    """Position servo, velocity servo or motor, from the actuator's gain and bias."""
    if int(model.actuator_dyntype[act]) != mujoco.mjtDyn.mjDYN_NONE:
        return None
    if int(model.actuator_gaintype[act]) != mujoco.mjtGain.mjGAIN_FIXED:
        return None
    bias = int(model.actuator_biastype[act])
    b0, b1, b2 = (float(v) for v in model.actuator_biasprm[act, :3])
    if bias == mujoco.mjtBias.mjBIAS_NONE or (b0 == b1 == b2 == 0.0):
        return "torque"
    if bias == mujoco.mjtBias.mjBIAS_AFFINE and b0 == 0.0:
        if b1 != 0.0:
            return "position"
        if b2 != 0.0:
            return "velocity"
    return None


def resolve_actuators(
    model: mujoco.MjModel, joint_id: int, spec: JointSpec
) -> dict[ControlMode, int]:
    """Actuator id per control mode for the joint: explicit names, naming convention, or types."""
    joint = spec.joint
    found: dict[ControlMode, int] = {}
    if spec.actuators:
        for mode, act_name in spec.actuators.items():
            act = find_id(model, "actuator", act_name)
            if not _drives(model, act, joint_id):
                raise ModelLoadError(
                    f"actuator {act_name!r} (mode {mode}) does not drive joint {joint!r}"
                )
            found[mode] = act
        return found
    for mode, suffix in _SUFFIX.items():
        act = int(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, joint + suffix))
        if act >= 0:
            if not _drives(model, act, joint_id):
                raise ModelLoadError(f"actuator {joint + suffix!r} does not drive joint {joint!r}")
            found[mode] = act
    if found:
        return found
    act_names = names(model, "actuator")
    for act in range(int(model.nu)):
        if not _drives(model, act, joint_id):
            continue
        kind = _classify(model, act)
        if kind is None:
            continue
        mode = kind
        if mode in found:
            raise ModelLoadError(
                f"joint {joint!r} has several {mode} actuators "
                f"({act_names[found[mode]]!r}, {act_names[act]!r}); "
                "name the ones to use with JointSpec.actuators"
            )
        found[mode] = act
    if not found:
        raise ModelLoadError(
            f"joint {joint!r} has no position, velocity or motor actuator "
            "(an OpenEL actuator needs at least one)"
        )
    return found
