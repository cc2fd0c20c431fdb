"""What every MuJoCo device class shares: the vendor, product and event ids, the product
name made from a device's name, the actuator-group test of mode switching, and the ReInit and
Finalize lifecycle of the actuator devices (joints and effectors).

Re-exported by :mod:`openel_mujoco.devices`.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from enum import IntEnum
from typing import TYPE_CHECKING, Final

import mujoco
import numpy as np

from openel_async.device import DeviceContext
from openel_async.ids import DeviceKind
from openel_async.requests import EventId

if TYPE_CHECKING:
    from .sim import MujocoSim

__all__ = [
    "EFFECTOR_PRODUCT_ID",
    "JOINT_PRODUCT_ID",
    "KIND_PRODUCT_IDS",
    "OTHER_KIND",
    "SENSOR_PRODUCT_ID",
    "VENDOR_ID",
    "VENDOR_NAME",
    "MujocoEventId",
    "SimActuatorLifecycle",
    "own_actuator_group",
    "product_name",
]

VENDOR_ID: Final = 0x4D4A  # "MJ"
VENDOR_NAME: Final = "MuJoCo"
JOINT_PRODUCT_ID: Final = 0x1
"""Product id of every :class:`~openel_mujoco.joints.MujocoJoint` (the joint is told by the product name)."""
EFFECTOR_PRODUCT_ID: Final = 0x2
"""Product id of every :class:`~openel_mujoco.effectors.MujocoEffector`."""
SENSOR_PRODUCT_ID: Final = 0x10
"""Product id of a :class:`~openel_mujoco.sensors.MujocoSensor` of a kind without a HAL4RT class (below)."""
KIND_PRODUCT_IDS: Final[Mapping[int, int]] = {
    DeviceKind.ROTARY_ANGLE: 0x11,
    DeviceKind.GYRO: 0x12,
    DeviceKind.ACCEL: 0x13,
    DeviceKind.FORCE: 0x14,
    DeviceKind.TORQUE: 0x15,
    DeviceKind.COMPASS: 0x16,
}
"""Product id of a MuJoCo sensor of each HAL4RT sensor kind (its device class's)."""
OTHER_KIND: Final = 0x80
"""HALId device kind of sensors outside the OpenEL kind registry (contact, user, ...)."""


class MujocoEventId(IntEnum):
    """Device-specific event ids (HALObserver.notify_event) of the MuJoCo joints and effectors."""

    LIMIT_REACHED = EventId.LIMIT_REACHED
    """2: the joint came within ``limit_margin`` of a limit of its range (once per approach)."""
    SATURATED = 3
    """3: the joint's actuator reached its force limit (or the built-in PD its torque limit)."""
    HOLDING = 4
    """4: an adhesion effector is switched on and in contact: it holds something."""
    RELEASED = 5
    """5: an adhesion effector that held something no longer does (switched off, or lost it)."""


def product_name(name: str, fallback: str) -> str:
    """``imu_acc`` -> ``ImuAcc``: a device's product name from its name, for HAL4RT's
    component name rule (``fallback`` first when the name does not start with a letter)."""
    parts = [p for p in re.split(r"[^A-Za-z0-9]+", name) if p]
    text = "".join(p[:1].upper() + p[1:] for p in parts)
    if not text or not text[0].isalpha():
        text = fallback + text
    return text


def own_actuator_group(model: mujoco.MjModel, act: int) -> bool:
    """True when actuator ``act`` is alone in an actuator group in 0..30 (so that
    ``opt.disableactuator`` can switch it on and off by itself)."""
    group = int(model.actuator_group[act])
    return 0 <= group <= 30 and int(np.count_nonzero(model.actuator_group == group)) == 1


class SimActuatorLifecycle:
    """ReInit and Finalize of an actuator device of a simulation (joints and effectors):
    re_init resets a faulted simulation, else stops the device safely; close detaches it and
    stops it safely unless the simulation is faulted."""

    sim: MujocoSim
    _rejected: int
    _ctx: DeviceContext | None

    def _safe_stop(self) -> None:
        raise NotImplementedError

    def _clear_pending(self) -> None:
        """Forget the pending target (no completion is reported for it)."""
        raise NotImplementedError

    async def init(self) -> None:
        self.sim._check_running_state()

    async def reset(self) -> None:
        faulted = self.sim.fault is not None
        self.sim._recover()
        if not faulted:
            self._safe_stop()
        self._clear_pending()

    async def close(self) -> None:
        if self._rejected:
            self._rejected -= 1
            return
        self.sim._detach(self)  # type: ignore[arg-type]
        self._ctx = None
        if self.sim.fault is None:
            self._safe_stop()
        self._clear_pending()
