"""OpenEL device-layer classes over a :class:`~openel_mujoco.sim.MujocoSim`.

:class:`MujocoJoint` maps one hinge or slide joint to an ``ActuatorDevice`` (POSITION,
VELOCITY, TORQUE and NO_EXCITE through the joint's MuJoCo actuators, or a built-in PD
controller over its motor), :class:`MujocoSensor` maps one MuJoCo sensor to a ``SensorDevice``.
Both are created by the simulation (``sim.actuator(name)``, ``sim.sensor(name)``) and read and
write its ``MjData`` directly; the simulation loop evaluates completion, limits and saturation
after every physics step and calls back into the joints.
"""

from __future__ import annotations

import math
import re
import struct
from collections.abc import Callable, Mapping, Sequence
from enum import IntEnum
from operator import itemgetter
from types import CodeType, FunctionType
from typing import TYPE_CHECKING, Any, ClassVar, Final, Protocol, cast

import mujoco
import numpy as np

from openel_async.device import (
    ActuatorDevice,
    ActuatorLimits,
    BatchCommander,
    BatchReader,
    DeviceContext,
    DeviceInfo,
    ErrorId,
    Reading,
    SensorDevice,
    VelocityRamp,
)
from openel_async.direction import MagneticField
from openel_async.errors import BadParameterError, HALError
from openel_async.ids import DeviceKind
from openel_async.logs import get_logger
from openel_async.requests import EventId, Request

from .description import JointSpec, SensorSpec, spec_of
from .models import ControlMode, ModelLoadError, find_id, names

if TYPE_CHECKING:
    from .sim import MujocoSim

__all__ = [
    "EFFECTOR_PRODUCT_ID",
    "JOINT_PRODUCT_ID",
    "KIND_PRODUCT_IDS",
    "OTHER_KIND",
    "SENSOR_DEVICE_CLASSES",
    "SENSOR_PRODUCT_ID",
    "MujocoAccelerometer",
    "MujocoEncoder",
    "MujocoEventId",
    "MujocoForceSensor",
    "MujocoGyro",
    "MujocoJoint",
    "MujocoMagnetometer",
    "MujocoSensor",
    "MujocoTorqueSensor",
    "geomagnetic_field_enu",
    "sensor_kind",
    "sensor_units",
    "set_geomagnetic_field",
]

log = get_logger(__name__)

VENDOR_ID: Final = 0x4D4A  # "MJ"
VENDOR_NAME: Final = "MuJoCo"
JOINT_PRODUCT_ID: Final = 0x1
"""Product id of every :class:`MujocoJoint` (the joint is told by the product name)."""
EFFECTOR_PRODUCT_ID: Final = 0x2
"""Product id of every :class:`~openel_mujoco.effectors.MujocoEffector`."""
SENSOR_PRODUCT_ID: Final = 0x10
"""Product id of a :class:`MujocoSensor` of a kind without a HAL4RT class (below)."""
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


_MODE_REQUEST: Final[Mapping[ControlMode, Request]] = {
    "position": Request.POSITION,
    "velocity": Request.VELOCITY,
    "torque": Request.TORQUE,
}
_SUFFIX: Final[Mapping[ControlMode, str]] = {
    "position": "_pos",
    "velocity": "_vel",
    "torque": "_torque",
}
_PD_POSITION_HZ: Final = 5.0
_PD_VELOCITY_HZ: Final = 10.0
_SATURATION_RELEASE: Final = 0.98
_LIMIT_RELEASE: Final = 3.0


def _camel(name: str, fallback: str) -> str:
    """``imu_acc`` -> ``ImuAcc``: a product name for HAL4RT's component name rule."""
    parts = [p for p in re.split(r"[^A-Za-z0-9]+", name) if p]
    text = "".join(p[:1].upper() + p[1:] for p in parts)
    if not text or not text[0].isalpha():
        text = fallback + text
    return text


# -- actuators of a joint -----------------------------------------------------------------


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


def _own_group(model: mujoco.MjModel, act: int) -> bool:
    group = int(model.actuator_group[act])
    return 0 <= group <= 30 and int(np.count_nonzero(model.actuator_group == group)) == 1


def _max_abs(low: float, high: float) -> float:
    return max(abs(low), abs(high))


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


class MujocoJoint(SimActuatorLifecycle, ActuatorDevice):
    """A hinge or slide joint of a :class:`MujocoSim` as an OpenEL actuator.

    Values are SI: rad, rad/s, N m for hinges; m, m/s, N for slides.  POSITION_ACTUAL and
    VELOCITY_ACTUAL read ``qpos``/``qvel`` of the current state, TORQUE_ACTUAL the total
    actuator force on the joint (``qfrc_actuator``, what a ``jointactuatorfrc`` sensor reads).

    Completion is reported by the device from the physics (``reports_completion``): after every
    physics step the simulation checks the latest target against the simulated state (position
    within ``position_tolerance`` while slower than ``settle_velocity``; velocity within
    ``velocity_tolerance``; actuator torque within ``torque_tolerance``), continuously for
    ``settle_s`` of simulated time.  A target the physics cannot reach never completes.
    """

    reports_completion = True
    info = DeviceInfo(
        kind=DeviceKind.MOTOR,
        vendor_id=VENDOR_ID,
        product_id=JOINT_PRODUCT_ID,
        vendor_name=VENDOR_NAME,
        product_name="Joint",
        functions=("control_mode",),
    )
    velocity_ramp = True
    """``Motor.set_speed(speed, tm_acc)`` ramps inside the simulation loop: the velocity
    setpoint advances before every physics step (:meth:`command_velocity_ramp`); False on a
    joint without VELOCITY."""

    def __init__(
        self,
        sim: MujocoSim,
        spec: JointSpec | str | Mapping[str, Any] | None = None,
        **fields: Any,
    ) -> None:
        """The joint of ``spec`` (a spec, a joint name or a dict of JointSpec fields), or of
        the JointSpec ``fields`` as keywords (a rig file's ``params``: ``joint`` defaults to
        ``name``, see :func:`~openel_mujoco.description.spec_of`); it registers itself in
        ``sim.joints`` (``BadParameterError`` when its name or joint is mapped already).
        ``sim.actuator(name)`` is the usual way."""
        spec = spec_of(JointSpec, spec, fields, "joint")
        sim._check_new_joint(spec)
        model = sim.model
        self.sim = sim
        self.spec = spec
        self.name = spec.key
        self.joint = spec.joint
        self.joint_id = jid = find_id(model, "joint", spec.joint)
        jtype = int(model.jnt_type[jid])
        if jtype not in (mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_SLIDE):
            kind = mujoco.mjtJoint(jtype).name.removeprefix("mjJNT_").lower()
            raise ModelLoadError(
                f"joint {spec.joint!r} is a {kind} joint; only hinge and slide joints "
                "map to one-degree-of-freedom actuators"
            )
        self.rotational = jtype == mujoco.mjtJoint.mjJNT_HINGE
        self.linear = not self.rotational
        self.qadr = int(model.jnt_qposadr[jid])
        self.dof = int(model.jnt_dofadr[jid])
        acts = resolve_actuators(model, jid, spec)
        self.actuators: Mapping[ControlMode, int] = acts
        self._switchable = all(_own_group(model, a) for a in acts.values())
        if len(acts) > 1 and not self._switchable:
            act_names = names(model, "actuator")
            listed = ", ".join(
                f"{act_names[a]!r} (group {int(model.actuator_group[a])})" for a in acts.values()
            )
            raise ModelLoadError(
                f"joint {spec.joint!r} has several actuators ({listed}) but they cannot be "
                "switched: each needs an actuator group in 0..30 of its own (see "
                "openel_mujoco.models); or map only one with JointSpec.actuators"
            )
        self._bits = {mode: 1 << int(model.actuator_group[a]) for mode, a in acts.items()}
        self._scale: dict[Request, float] = {}
        for mode, act in acts.items():
            gear = float(model.actuator_gear[act, 0]) or 1.0
            self._scale[_MODE_REQUEST[mode]] = 1.0 / gear if mode == "torque" else gear
        self._motor = acts.get("torque")

        supported = {_MODE_REQUEST[m] for m in acts}
        if self._motor is not None:
            supported |= {Request.POSITION, Request.VELOCITY}
        motor_only = set(acts) == {"torque"}
        if self._switchable or motor_only:
            supported.add(Request.NO_EXCITE)
        self.supported_requests = frozenset(supported)
        self.velocity_ramp = Request.VELOCITY in supported
        self.limits = self._limits(model, spec)
        self._torque_range = self._motor_torque_range(model)
        self._kp, self._kd, self._kv = self._pd_gains(sim, spec)
        self.info = DeviceInfo(
            kind=DeviceKind.MOTOR,
            vendor_id=VENDOR_ID,
            product_id=JOINT_PRODUCT_ID,
            vendor_name=VENDOR_NAME,
            product_name=_camel(self.name, "Joint"),
            functions=("control_mode",),
        )

        # completion
        dt = float(model.opt.timestep)
        self._settle_steps = max(0, math.ceil(spec.settle_s / dt - 1e-9))
        self._pos_tol = spec.position_tolerance
        self._settle_vel = spec.settle_velocity
        self._vel_tol = spec.velocity_tolerance
        self._torque_tol = spec.torque_tolerance
        # limits: on within margin of the range, released at 3 x margin
        # (an unlimited joint gets an infinite band: the monitor then needs no extra test)
        low, high = (float(v) for v in model.jnt_range[jid])
        if not model.jnt_limited[jid]:
            low, high = -math.inf, math.inf
        margin = spec.limit_margin
        self._lim_lo_on, self._lim_hi_on = low + margin, high - margin
        self._lim_lo_off = low + _LIMIT_RELEASE * margin
        self._lim_hi_off = high - _LIMIT_RELEASE * margin

        # run-time state
        self._ctx: DeviceContext | None = None
        self._rejected = 0
        self._log = log.bind(sim=sim.name, joint=self.name)
        self._mode = Request.NO_EXCITE
        self._drive_act: int | None = None
        self._direct: Request | None = None  # the mode commanded by a plain ctrl write
        self._drive_scale = 1.0  # ctrl per SI unit of the direct mode
        self._pd = False
        self._pd_target = 0.0
        self._pd_saturated = False
        self._ramp: tuple[float, float, int, int] | None = None  # start, target, t0, t1
        self._target = 0.0
        # The latest target's state, one attribute (a batch stores one per joint): _IDLE
        # (nothing pending), -1 (pending, not within tolerance) or the physics step since
        # which the joint is within tolerance.  A pending target's request is the mode.
        self._since = _IDLE
        self._at_limit = False
        self._saturated = False
        self._sat_lo = -math.inf
        self._sat_hi = math.inf
        self._sat_lo_off = -math.inf
        self._sat_hi_off = math.inf
        self._commands = 0  # by command_nowait and ramps; batches count their own
        self._batches: list[_JointBatch] = []  # every batch commander made for this joint
        self._init_mode(spec.mode)
        sim._joints[spec.key] = self

    # -- construction helpers ----------------------------------------------------------
    def _limits(self, model: mujoco.MjModel, spec: JointSpec) -> ActuatorLimits:
        acts = self.actuators
        if spec.position_limits is not None:
            position = spec.position_limits
        elif model.jnt_limited[self.joint_id]:
            low, high = (float(v) for v in model.jnt_range[self.joint_id])
            position = (low, high)
        elif "position" in acts and model.actuator_ctrllimited[acts["position"]]:
            scale = self._scale[Request.POSITION]
            a, b = (float(v) / scale for v in model.actuator_ctrlrange[acts["position"]])
            position = (min(a, b), max(a, b))
        else:
            position = (-math.inf, math.inf)
        velocity = spec.max_velocity
        if velocity is None:
            velocity = math.inf
            if "velocity" in acts and model.actuator_ctrllimited[acts["velocity"]]:
                low, high = (float(v) for v in model.actuator_ctrlrange[acts["velocity"]])
                velocity = _max_abs(low, high) / abs(self._scale[Request.VELOCITY])
        torque = spec.max_torque
        if torque is None:
            low, high = self._motor_torque_range(model)
            torque = _max_abs(low, high)
        try:
            return ActuatorLimits(position, velocity, torque)
        except BadParameterError as exc:
            raise ModelLoadError(f"joint {spec.joint!r}: invalid limits: {exc}") from exc

    def _motor_torque_range(self, model: mujoco.MjModel) -> tuple[float, float]:
        """Joint torque the motor can apply (ctrl and force ranges times gear, actfrcrange)."""
        low, high = -math.inf, math.inf
        motor = self._motor
        if motor is not None:
            gear = float(model.actuator_gear[motor, 0]) or 1.0
            for limited, rng in (
                (model.actuator_ctrllimited[motor], model.actuator_ctrlrange[motor]),
                (model.actuator_forcelimited[motor], model.actuator_forcerange[motor]),
            ):
                if limited:
                    a, b = float(rng[0]) * gear, float(rng[1]) * gear
                    low, high = max(low, min(a, b)), min(high, max(a, b))
        if model.jnt_actfrclimited[self.joint_id]:
            a, b = (float(v) for v in model.jnt_actfrcrange[self.joint_id])
            low, high = max(low, a), min(high, b)
        return low, high

    def _pd_gains(self, sim: MujocoSim, spec: JointSpec) -> tuple[float, float, float]:
        if self._motor is None or ("position" in self.actuators and "velocity" in self.actuators):
            return 0.0, 0.0, 0.0  # no PD needed (or possible)
        inertia = sim._joint_inertia(self.dof)
        wp = 2 * math.pi * _PD_POSITION_HZ
        wv = 2 * math.pi * _PD_VELOCITY_HZ
        kp = spec.kp if spec.kp is not None else inertia * wp * wp
        kd = spec.kd if spec.kd is not None else 2.0 * inertia * wp
        kv = spec.kv if spec.kv is not None else inertia * wv
        return float(kp), float(kd), float(kv)

    def _init_mode(self, mode: ControlMode | None) -> None:
        """Adopt the model's active actuator (or ``mode``) as the current control mode."""
        if mode is not None:
            request = _MODE_REQUEST[mode]
            if request not in self.supported_requests:
                raise BadParameterError(
                    "mode", mode, f"a mode joint {self.joint!r} supports ({self._supported_text()})"
                )
            self._switch(request, force=True)
            return
        disabled = int(self.sim.model.opt.disableactuator)
        enabled = [m for m, bit in self._bits.items() if not disabled & bit]
        if not self._switchable:
            enabled = list(self.actuators)
        if len(enabled) == 1:
            request = _MODE_REQUEST[enabled[0]]
            self._mode = request
            act = self._drive_act = self.actuators[enabled[0]]
            self._refresh_drive()
            ctrl = self.sim._ctrl
            if request is Request.POSITION and self.sim._physics_steps == 0 and ctrl[act] == 0.0:
                # initial state (keyframe without ctrl): hold where the joint is, no jump
                ctrl[act] = self.position * self._scale[Request.POSITION]
        elif not enabled and Request.NO_EXCITE in self.supported_requests:
            self._mode = Request.NO_EXCITE
            self._drive_act = None
            self._refresh_drive()
        else:
            for request in (Request.POSITION, Request.VELOCITY, Request.TORQUE):
                if request in self.supported_requests:
                    self._switch(request, force=True)
                    break

    def _supported_text(self) -> str:
        return ", ".join(r.name for r in sorted(self.supported_requests))

    # -- mode switching ----------------------------------------------------------------
    @property
    def control_mode(self) -> Request:
        """The active control mode (POSITION, VELOCITY, TORQUE or NO_EXCITE)."""
        return self._mode

    @property
    def uses_pd(self) -> bool:
        """True while the mode runs on the built-in PD controller over the joint's motor."""
        return self._pd

    def _switch(self, request: Request, *, force: bool = False) -> None:
        if request is self._mode and not force:
            return
        sim = self.sim
        model, ctrl = sim.model, sim._ctrl
        mode = _REQUEST_MODE.get(request)
        native = self.actuators.get(mode) if mode is not None else None
        drive = native if native is not None else (self._motor if mode is not None else None)
        if self._switchable:
            mask = int(model.opt.disableactuator)
            for m, act in self.actuators.items():
                mask |= self._bits[m]
                ctrl[act] = 0.0
            if drive is not None:
                mask &= ~(1 << int(model.actuator_group[drive]))
            model.opt.disableactuator = mask
        else:
            for act in self.actuators.values():
                ctrl[act] = 0.0
        pd = drive is not None and native is None
        position = self.position
        if pd:
            self._pd_target = position if request is Request.POSITION else 0.0
            self._pd_saturated = False
        elif request is Request.POSITION and drive is not None:
            ctrl[drive] = position * self._scale[Request.POSITION]  # bumpless: hold here
        if pd != self._pd:
            self._pd = pd
            sim._set_pd(self, pd)
        self._mode = request
        self._drive_act = drive
        self._refresh_drive()
        self._log.debug("control_mode", mode=request.name, pd=pd)

    def _refresh_drive(self) -> None:
        """Derive the command fast path and the saturation bands from the current mode."""
        model = self.sim.model
        act = self._drive_act
        direct = act is not None and not self._pd and self._mode is not _NO_EXCITE
        self._direct = self._mode if direct else None
        self._drive_scale = self._scale[self._mode] if direct else 1.0
        DRIVE_PLANS.version += 1  # batch plans (_JointBatch) are rebuilt
        self._saturated = False
        self._sat_lo = self._sat_lo_off = -math.inf
        self._sat_hi = self._sat_hi_off = math.inf
        if act is None or self._pd or not model.actuator_forcelimited[act]:
            return
        low, high = (float(v) for v in model.actuator_forcerange[act])
        if low < 0:
            self._sat_lo, self._sat_lo_off = low * (1 - 1e-9), low * _SATURATION_RELEASE
        if high > 0:
            self._sat_hi, self._sat_hi_off = high * (1 - 1e-9), high * _SATURATION_RELEASE

    def _hold(self) -> None:
        """Stop safely: hold the current position, else de-energize, else zero torque."""
        self._since = _IDLE
        self._stop_ramp()
        if Request.POSITION in self.supported_requests:
            self._switch(Request.POSITION, force=True)
        elif Request.NO_EXCITE in self.supported_requests:
            self._switch(Request.NO_EXCITE, force=True)
        elif self._motor is not None:
            self._switch(Request.TORQUE, force=True)

    # -- lifecycle ---------------------------------------------------------------------
    async def open(self, ctx: DeviceContext) -> None:
        if not self.sim._attach(self, ctx):
            self._rejected += 1  # the failed component's close() must not detach the owner
            raise HALError(f"{self.name}: device already belongs to a component")
        self._ctx = ctx
        DRIVE_PLANS.version += 1  # monitored from now on

    def _safe_stop(self) -> None:
        self._hold()

    def _clear_pending(self) -> None:
        self._since = _IDLE

    # -- commands and readings ---------------------------------------------------------
    async def command(self, request: Request, value: float) -> None:
        self.command_nowait(request, value)

    def command_nowait(self, request: Request, value: float) -> None:
        sim = self.sim
        if sim._fault is not None:
            raise HALError(f"{self.name}: the simulation is faulted: {sim._fault}")
        self._commands += 1
        if request is self._direct:  # streaming setpoints in the current mode: one ctrl write
            sim._ctrl_items[self._drive_act] = value * self._drive_scale  # type: ignore[index]
        else:
            if self._ramp is not None:  # a ramp makes _direct None: every command ends it
                self._stop_ramp()
            if request is not self._mode:
                self._switch(request)
            if request is _NO_EXCITE:
                self._since = _IDLE
                return
            if self._pd:
                self._pd_target = value
            else:
                act = self._drive_act
                if act is None:  # never for a supported request; ctrl[None] would set every ctrl
                    raise HALError(f"{self.name}: no actuator drives {request.name}")
                sim._ctrl[act] = value * self._scale[request]
        self._target = value
        self._since = -1  # pending (request is now the mode)

    async def read(self, request: Request) -> float:
        return self.read_nowait(request)

    def read_nowait(self, request: Request) -> float:
        sim = self.sim
        if request is Request.POSITION_ACTUAL:
            return sim._qpos.item(self.qadr)  # type: ignore[no-any-return]
        if request is Request.VELOCITY_ACTUAL:
            return sim._qvel.item(self.dof)  # type: ignore[no-any-return]
        if request is Request.TORQUE_ACTUAL:
            return sim._qfrc_actuator.item(self.dof)  # type: ignore[no-any-return]
        raise BadParameterError(
            "request", request, "POSITION_ACTUAL, VELOCITY_ACTUAL or TORQUE_ACTUAL"
        )

    # -- speed ramps (HAL4RT SetSpeed with tmAcc) ----------------------------------------
    async def command_velocity_ramp(self, ramp: VelocityRamp) -> None:
        self.command_velocity_ramp_nowait(ramp)

    def command_velocity_ramp_nowait(self, ramp: VelocityRamp) -> None:
        """The joint's own speed ramp, advanced inside the simulation loop.

        From the velocity setpoint in force (when the joint already runs in VELOCITY mode:
        the servo's ``ctrl`` or the PD target, so the setpoint never jumps), else from
        ``ramp.start`` (the actual velocity the framework read), to ``ramp.target`` in
        ``ramp.duration_s`` of the simulation clock: before every physics step the setpoint
        becomes the ramp's value at the time of the state stepped from, and the target from
        ``t0 + duration_s`` on. Completion is judged from then on (``velocity_tolerance``
        for ``settle_s``), never during the ramp. Any later command ends the ramp.
        """
        sim = self.sim
        if sim._fault is not None:
            raise HALError(f"{self.name}: the simulation is faulted: {sim._fault}")
        self._commands += 1
        if self._ramp is not None:
            self._stop_ramp()
        if self._mode is _VELOCITY:
            start = self._velocity_setpoint()
        else:
            self._switch(_VELOCITY)
            start = ramp.start
        t0 = sim.clock.now_ns()
        self._ramp = (start, ramp.target, t0, t0 + max(1, round(ramp.duration_s * 1e9)))
        self._direct = None  # setpoints take the slow path of command_nowait: it ends the ramp
        DRIVE_PLANS.version += 1
        self._set_velocity(start)
        self._target = ramp.target
        self._since = _IDLE  # judged once the ramp has ended
        sim._set_ramp(self, True)
        self._log.debug("velocity_ramp", start=start, target=ramp.target, s=ramp.duration_s)

    def _velocity_setpoint(self) -> float:
        if self._pd:
            return self._pd_target
        act = self._drive_act
        assert act is not None
        return float(self.sim._ctrl.item(act)) / self._scale[_VELOCITY]

    def _set_velocity(self, value: float) -> None:
        if self._pd:
            self._pd_target = value
        else:
            self.sim._ctrl[self._drive_act] = value * self._scale[_VELOCITY]

    def _ramp_update(self, now_ns: int) -> None:
        """Before a physics step from the state at ``now_ns``: the ramp's setpoint."""
        ramp = self._ramp
        assert ramp is not None
        start, target, t0, t1 = ramp
        if now_ns >= t1:
            self._set_velocity(target)
            self._stop_ramp()
            self._since = -1  # the final speed is commanded: completion is judged
            return
        if now_ns <= t0:
            self._set_velocity(start)
        else:
            self._set_velocity(start + (target - start) * ((now_ns - t0) / (t1 - t0)))

    def _stop_ramp(self) -> None:
        """End the ramp (the setpoint stays where it is) and restore the command fast path."""
        if self._ramp is None:
            return
        self._ramp = None
        self.sim._set_ramp(self, False)
        direct = self._drive_act is not None and not self._pd and self._mode is not _NO_EXCITE
        self._direct = self._mode if direct else None
        DRIVE_PLANS.version += 1

    @property
    def ramping(self) -> bool:
        """True while a speed ramp of :meth:`command_velocity_ramp` runs."""
        return self._ramp is not None

    # -- state for recorders and apps ----------------------------------------------------
    @property
    def position(self) -> float:
        return float(self.sim._qpos.item(self.qadr))

    @property
    def velocity(self) -> float:
        return float(self.sim._qvel.item(self.dof))

    @property
    def commanded_position(self) -> float:
        """The position the joint is driven to (NaN outside POSITION mode)."""
        if self._mode is not Request.POSITION:
            return math.nan
        if self._pd:
            return self._pd_target
        act = self._drive_act
        assert act is not None
        return float(self.sim._ctrl.item(act)) / self._scale[Request.POSITION]

    @property
    def pending(self) -> bool:
        """True while the latest target is not reached yet (as judged by the physics), a
        speed ramp included."""
        return self._since != _IDLE or self._ramp is not None

    # -- called by the simulation loop ---------------------------------------------------
    def _pd_update(self, now_ns: int) -> None:
        sim = self.sim
        q = sim._qpos.item(self.qadr)
        v = sim._qvel.item(self.dof)
        if self._mode is Request.POSITION:
            tau = self._kp * (self._pd_target - q) - self._kd * v
        else:
            tau = self._kv * (self._pd_target - v)
        low, high = self._torque_range
        if tau > high:
            tau, sat = high, True
        elif tau < low:
            tau, sat = low, True
        else:
            sat = False
        self._pd_saturated = sat
        act = self._drive_act
        assert act is not None
        sim._ctrl[act] = tau * self._scale[Request.TORQUE]

    def _limit_edge(self, q: float, ctx: DeviceContext) -> None:
        """The position left the band where the limit state cannot change (hysteresis)."""
        if self._at_limit:
            if self._lim_lo_off < q < self._lim_hi_off:
                self._at_limit = False
                DRIVE_PLANS.version += 1
        else:
            self._at_limit = True
            DRIVE_PLANS.version += 1
            ctx.post_event(_LIMIT_REACHED)

    def _force_edge(self, force: float, ctx: DeviceContext) -> None:
        """The actuator force left the band where the saturation state cannot change."""
        if self._saturated:
            if self._sat_lo_off < force < self._sat_hi_off:
                self._saturated = False
                DRIVE_PLANS.version += 1
        else:
            self._saturated = True
            DRIVE_PLANS.version += 1
            ctx.post_event(_SATURATED)

    def _pd_saturation_edge(self, ctx: DeviceContext) -> None:
        saturated = self._saturated = self._pd_saturated
        if saturated:
            ctx.post_event(_SATURATED)

    def _fault(self, reason: str) -> None:
        self._since = _IDLE
        ctx = self._ctx
        if ctx is not None:
            ctx.fault(ErrorId.DEVICE_ERROR, reason)

    def _on_sim_reset(self) -> None:
        """The simulation was reset: adopt the model's restored control modes."""
        self._since = _IDLE
        self._at_limit = False
        DRIVE_PLANS.version += 1
        self._stop_ramp()
        if self._pd:
            self._pd = False
            self.sim._set_pd(self, False)
        self._init_mode(self.spec.mode)

    @property
    def commands(self) -> int:
        """Commands this joint took (``command_nowait``, ramps and batches)."""
        return self._commands + sum([batch.calls for batch in self._batches])

    @classmethod
    def batch_commander(cls, devices: Sequence[ActuatorDevice]) -> BatchCommander | None:
        """Joints of one simulation: an ActuatorBank's setpoints in one loop of ctrl writes."""
        joints = [d for d in devices if isinstance(d, MujocoJoint)]
        if not joints or len(joints) != len(devices):
            return None
        sim = joints[0].sim
        if any(j.sim is not sim for j in joints):
            return None
        return cast(BatchCommander, _JointBatch(tuple(joints)).send)

    def __repr__(self) -> str:
        return f"MujocoJoint({self.name!r}, mode={self._mode.name}, sim={self.sim.name!r})"


class FloatItems(Protocol):
    """Items of a float64 array read and written one at a time (a ``memoryview`` of it:
    each item is a Python float, with no numpy scalar and no conversion of the array)."""

    def __getitem__(self, index: int, /) -> float: ...

    def __setitem__(self, index: int, value: float, /) -> None: ...


class _DriveVersion:
    """Bumped whenever any joint's command fast path (mode, drive actuator, ramp), its limit
    or saturation state or its attachment changes: batch plans (``_JointBatch``) and the
    simulations' monitor plans (:func:`monitor_plan`) are then rebuilt."""

    __slots__ = ("version",)

    def __init__(self) -> None:
        self.version = 0


DRIVE_PLANS: Final = _DriveVersion()


class _JointBatch:
    """``MujocoJoint.command_nowait(request, values[i])`` of every joint, for setpoints in
    every joint's current direct mode (see ``BatchCommander``).  Whether every joint
    streams ``request`` with a plain ctrl write is decided once per mode change, not per
    call; otherwise it declines (False) and the bank commands joint by joint.  The batch
    counts its calls once (``calls``: part of each joint's ``commands``) rather than per
    joint.

    ``send`` (what ``batch_commander`` returns) is generated per plan: the values unpacked
    once, then per joint one ``ctrl`` item write and its two command-state stores, with no
    loop; the addresses and joints are its default arguments.  A new plan rebinds the same
    function's code and defaults (the bank keeps the function it was given).  Its first
    test sends anything else (another request, a changed plan, a faulted simulation) to
    :meth:`_slow`.
    """

    __slots__ = ("_failed", "calls", "joints", "send", "sim")

    def __init__(self, joints: tuple[MujocoJoint, ...]) -> None:
        self.joints = joints
        self.sim = joints[0].sim
        self.calls = 0
        self._failed: tuple[Request, int] | None = None  # a plan found impossible
        # a function of its own (own globals: builtins only), first with no plan: its code
        # and defaults are replaced at each plan
        self.send = _generated("send", _UNPLANNED, (self,), {})
        for joint in joints:
            joint._batches.append(self)

    def _slow(self, request: Request, values: Sequence[float]) -> bool:
        """The first call for a request or after a change: plan, then send (or decline)."""
        sim = self.sim
        if sim._fault is not None:
            raise HALError(f"{sim.name}: the simulation is faulted: {sim._fault}")
        if self._failed == (request, DRIVE_PLANS.version) or not self._replan(request):
            return False
        return bool(self.send(request, values))

    def _replan(self, request: Request) -> bool:
        plan: list[tuple[int, float]] = []
        for joint in self.joints:
            act = joint._drive_act
            if joint._direct is not request or act is None:
                self._failed = (request, DRIVE_PLANS.version)
                return False
            plan.append((act, joint._drive_scale))
        self._failed = None
        n = len(plan)
        values = ", ".join(f"v{i}" for i in range(n))
        lines = [
            "def send(request, values, /, _b=None, _sim=None, _plans=None, _req=None, _version=0, "
            + "".join(f"j{i}=None, s{i}=1.0, " for i in range(n))
            + "ctrl=None):",
            "    if request is not _req or _plans.version != _version or _sim._fault is not None:",
            "        return _b._slow(request, values)",
            "    try:",
            f"        {values}, = values",
            "    except ValueError:",
            f"        raise ValueError(f'{{len(values)}} values for {n} joints') from None",
            "    _b.calls += 1",
        ]
        for i, (act, scale) in enumerate(plan):
            # value * 1.0 is value: the same ctrl as command_nowait's, without the product
            write = f"v{i} * s{i}" if scale != 1.0 else f"v{i}"
            lines += [
                f"    ctrl[{act}] = {write}",
                f"    j{i}._target = v{i}",
                f"    j{i}._since = -1",
            ]
        lines.append("    return True")
        source = "\n".join(lines)
        if source not in _BATCH_CODE:  # compiled once per shape
            if len(_BATCH_CODE) >= _MONITOR_CODE_MAX:
                _BATCH_CODE.clear()
            _BATCH_CODE[source] = _generated("send", source, (), {}).__code__
        defaults: tuple[object, ...] = (self, self.sim, DRIVE_PLANS, request, DRIVE_PLANS.version)
        for joint, (_, scale) in zip(self.joints, plan, strict=True):
            defaults += (joint, scale)
        defaults += (self.sim._ctrl_items,)  # a memoryview: an item write costs less
        # the bank keeps ``send``: it takes the new plan's code and defaults
        send = self.send
        send.__code__ = _BATCH_CODE[source]
        send.__defaults__ = defaults
        return True


def _generated(
    name: str, source: str, defaults: tuple[object, ...], names: dict[str, object]
) -> FunctionType:
    """Function ``name`` defined by ``source`` (our own code only) in a namespace of its own
    holding ``names``, with ``defaults``."""
    namespace = dict(names)
    exec(source, namespace)  # our own names and numbers only: nothing from outside
    function = cast(FunctionType, namespace[name])
    function.__defaults__ = defaults
    return function


_UNPLANNED: Final = """
def send(request, values, /, _b=None):
    return _b._slow(request, values)
"""

_BATCH_CODE: dict[str, CodeType] = {}
"""Joint batches' code by source (one per shape: joint count, ctrl addresses, scales)."""


# Enum members read on the per-step and per-command paths, as module constants (a class
# attribute read of an enum member costs ~80 ns on CPython 3.11).
_POSITION: Final = Request.POSITION
_VELOCITY: Final = Request.VELOCITY
_NO_EXCITE: Final = Request.NO_EXCITE
_IDLE: Final = 0
"""``MujocoJoint._since`` when no target is pending (physics steps count from 1, so a
pending target's ``_since`` is never 0: the monitor tests it for truth)."""
_LIMIT_REACHED: Final = MujocoEventId.LIMIT_REACHED
_SATURATED: Final = MujocoEventId.SATURATED

_REQUEST_MODE: Final[Mapping[Request, ControlMode]] = {v: k for k, v in _MODE_REQUEST.items()}


_NO_BAND: Final = (math.inf, -math.inf)  # no value is inside: the edge is evaluated

Monitor = Callable[[int], None]
"""``monitor(step)``: see :func:`monitor_plan`."""


def monitor_plan(
    joints: Sequence[MujocoJoint],
    qpos: Sequence[float],
    qvel: Sequence[float],
    force: Sequence[float],
) -> Monitor:
    """The per-step monitor of the attached ``joints``: after physics step ``step``, reading
    ``qpos``, ``qvel`` and ``actuator_force`` (memoryviews of MjData's arrays: one item
    read is a float, with no conversion of whole arrays), it posts limit and saturation
    events and reports completion.

    Built once per change (mode, drive, limit or saturation state, attach/detach:
    ``DRIVE_PLANS.version``) rather than looked up joint by joint after every physics
    step: a function with one straight block per joint, the joint's addresses, bands and
    tolerances bound as names of its own namespace (no loop, no tuple unpacking, no call
    per joint).  Per joint: the position band inside which its limit state cannot change
    (none while at a limit: the release is evaluated; no test at all for an unlimited
    joint), its PD saturation or the force band of its actuator inside which its
    saturation state cannot change (no test for an actuator without force limits), then,
    while its latest target is pending, completion by its mode (within tolerance, and at
    rest for POSITION, for ``settle_steps`` physics steps in a row).

    Events and completions call out (observers may command joints from there): when a
    call out changed any plan, the rest of the step is checked by :func:`_check_joints`
    from the joint's state as it is then, not by the plan built before.
    """
    names: dict[str, object] = {
        "_version": DRIVE_PLANS.version,
        "_other": _complete_other,
        "_plans": DRIVE_PLANS,
        "_tail": _check_joints,
        "_joints": tuple(joints),
        "qpos": qpos,
        "qvel": qvel,
        "force": force,
    }
    # the arrays as default arguments: local names, the cheapest to read
    lines = ["def monitor(step, qpos=qpos, qvel=qvel, force=force):"]

    def changed(i: int, stage: int, indent: str) -> list[str]:
        """After a call out: the rest by the joints' current state if a plan changed."""
        return [
            f"{indent}if _plans.version != _version:",
            f"{indent}    return _tail(_joints, step, {i}, {stage})",
        ]

    for i, joint in enumerate(joints):
        ctx = joint._ctx
        if ctx is None:
            continue
        lo, hi = _NO_BAND if joint._at_limit else (joint._lim_lo_on, joint._lim_hi_on)
        position = joint._mode is _POSITION
        names.update(
            {
                f"j{i}": joint,
                f"c{i}": ctx,
                f"lo{i}": lo,
                f"hi{i}": hi,
                f"ptol{i}": joint._pos_tol,
                f"nptol{i}": -joint._pos_tol,
                f"svel{i}": joint._settle_vel,
                f"nsvel{i}": -joint._settle_vel,
                f"settle{i}": joint._settle_steps,
            }
        )
        q = f"q{i}"
        limited = not (lo == -math.inf and hi == math.inf)
        if limited or position:
            lines.append(f"    {q} = qpos[{joint.qadr}]")
        if limited:
            lines += [
                f"    if not lo{i} < {q} < hi{i}:",
                f"        j{i}._limit_edge({q}, c{i})",
                *changed(i, 1, "        "),
            ]
        act = joint._drive_act
        if joint._pd:
            lines += [
                f"    if j{i}._pd_saturated is not j{i}._saturated:",
                f"        j{i}._pd_saturation_edge(c{i})",
                *changed(i, 2, "        "),
            ]
        elif act is not None:
            slo, shi = _NO_BAND if joint._saturated else (joint._sat_lo, joint._sat_hi)
            if not (slo == -math.inf and shi == math.inf):
                names[f"slo{i}"], names[f"shi{i}"] = slo, shi
                lines += [
                    f"    f{i} = force[{act}]",
                    f"    if not slo{i} < f{i} < shi{i}:",
                    f"        j{i}._force_edge(f{i}, c{i})",
                    *changed(i, 2, "        "),
                ]
        if position:
            lines += [
                f"    s = j{i}._since",
                "    if s:",
                f"        if nptol{i} <= {q} - j{i}._target <= ptol{i} "
                f"and nsvel{i} <= qvel[{joint.dof}] <= svel{i}:",
                "            if s < 0:",
                f"                j{i}._since = s = step",
                f"            if step - s >= settle{i}:",
                f"                j{i}._since = {_IDLE}",
                f"                c{i}.target_reached()",
                *changed(i, 3, "                "),
                "        elif s > 0:",
                f"            j{i}._since = -1",
            ]
        else:
            lines += [
                f"    if j{i}._since:",
                f"        _other(j{i}, c{i}, qvel[{joint.dof}], step)",
                *changed(i, 3, "        "),
            ]
    lines.append("    return None")
    source = "\n".join(lines)
    code = _MONITOR_CODE.get(source)
    if code is None:  # compiled once per shape (bands and joints are names, not code)
        if len(_MONITOR_CODE) >= _MONITOR_CODE_MAX:
            _MONITOR_CODE.clear()
        code = _MONITOR_CODE[source] = compile(source, "<joint monitor>", "exec")
    exec(code, names)  # our own names and numbers only: nothing from outside is compiled
    return cast(Monitor, names["monitor"])


def _check_joints(joints: Sequence[MujocoJoint], step: int, index: int, stage: int) -> None:
    """The monitor's checks of ``joints[index]`` from ``stage`` on (1: saturation, 2:
    completion, 3: none) and of every later joint, by their state as it is now (what a
    plan built from it checks): the rest of a step after a call out changed a plan."""
    for k in range(index, len(joints)):
        joint = joints[k]
        ctx = joint._ctx
        if ctx is None:
            continue
        sim = joint.sim
        first = stage if k == index else 0
        q = sim._qpos_items[joint.qadr]
        if first <= 0:
            lo, hi = _NO_BAND if joint._at_limit else (joint._lim_lo_on, joint._lim_hi_on)
            if not lo < q < hi:
                joint._limit_edge(q, ctx)
        if first <= 1:
            act = joint._drive_act
            if joint._pd:
                if joint._pd_saturated is not joint._saturated:
                    joint._pd_saturation_edge(ctx)
            elif act is not None:
                slo, shi = _NO_BAND if joint._saturated else (joint._sat_lo, joint._sat_hi)
                f = sim._force_items[act]
                if not slo < f < shi:
                    joint._force_edge(f, ctx)
        if first <= 2 and joint._since != _IDLE:
            velocity = sim._qvel_items[joint.dof]
            if joint._mode is not _POSITION:
                _complete_other(joint, ctx, velocity, step)
                continue
            tol, vel = joint._pos_tol, joint._settle_vel
            if -tol <= q - joint._target <= tol and -vel <= velocity <= vel:
                since = joint._since
                if since < 0:
                    joint._since = since = step
                if step - since >= joint._settle_steps:
                    joint._since = _IDLE
                    ctx.target_reached()
            else:
                joint._since = -1


_MONITOR_CODE: dict[str, CodeType] = {}
"""Compiled monitors by source: a plan is rebuilt at every limit or saturation edge, and
compiling costs ~0.5 ms where running the cached code costs a few µs."""
_MONITOR_CODE_MAX: Final = 256


def _complete_other(joint: MujocoJoint, ctx: DeviceContext, velocity: float, step: int) -> None:
    """Completion of a pending VELOCITY or TORQUE target after physics step ``step`` (the
    pending target's request is the joint's mode)."""
    if joint._mode is _VELOCITY:
        tol = joint._vel_tol
        ok = -tol <= velocity - joint._target <= tol
    else:
        tol = joint._torque_tol
        ok = -tol <= joint.sim._qfrc_actuator.item(joint.dof) - joint._target <= tol
    if not ok:
        joint._since = -1
        return
    since = joint._since
    if since < 0:
        joint._since = since = step
    if step - since >= joint._settle_steps:
        joint._since = _IDLE
        ctx.target_reached()


# -- sensors ------------------------------------------------------------------------------

_S = mujoco.mjtSensor
_FIXED_UNITS: Final[Mapping[int, str]] = {
    _S.mjSENS_TOUCH: "N",
    _S.mjSENS_ACCELEROMETER: "m/s^2",
    _S.mjSENS_VELOCIMETER: "m/s",
    _S.mjSENS_GYRO: "rad/s",
    _S.mjSENS_FORCE: "N",
    _S.mjSENS_TORQUE: "N m",
    _S.mjSENS_MAGNETOMETER: "T",
    _S.mjSENS_RANGEFINDER: "m",
    _S.mjSENS_CAMPROJECTION: "px",
    _S.mjSENS_BALLQUAT: "1",
    _S.mjSENS_BALLANGVEL: "rad/s",
    _S.mjSENS_TENDONPOS: "m",
    _S.mjSENS_TENDONVEL: "m/s",
    _S.mjSENS_TENDONACTFRC: "N",
    _S.mjSENS_TENDONLIMITPOS: "m",
    _S.mjSENS_TENDONLIMITVEL: "m/s",
    _S.mjSENS_TENDONLIMITFRC: "N",
    _S.mjSENS_FRAMEPOS: "m",
    _S.mjSENS_FRAMEQUAT: "1",
    _S.mjSENS_FRAMEXAXIS: "1",
    _S.mjSENS_FRAMEYAXIS: "1",
    _S.mjSENS_FRAMEZAXIS: "1",
    _S.mjSENS_FRAMELINVEL: "m/s",
    _S.mjSENS_FRAMEANGVEL: "rad/s",
    _S.mjSENS_FRAMELINACC: "m/s^2",
    _S.mjSENS_FRAMEANGACC: "rad/s^2",
    _S.mjSENS_SUBTREECOM: "m",
    _S.mjSENS_SUBTREELINVEL: "m/s",
    _S.mjSENS_SUBTREEANGMOM: "kg m^2/s",
    _S.mjSENS_INSIDESITE: "1",
    _S.mjSENS_GEOMDIST: "m",
    _S.mjSENS_GEOMNORMAL: "1",
    _S.mjSENS_GEOMFROMTO: "m",
    _S.mjSENS_E_POTENTIAL: "J",
    _S.mjSENS_E_KINETIC: "J",
    _S.mjSENS_CLOCK: "s",
}
# joint-space sensors: (unit for hinge, unit for slide)
_JOINT_UNITS: Final[Mapping[int, tuple[str, str]]] = {
    _S.mjSENS_JOINTPOS: ("rad", "m"),
    _S.mjSENS_JOINTVEL: ("rad/s", "m/s"),
    _S.mjSENS_JOINTACTFRC: ("N m", "N"),
    _S.mjSENS_JOINTLIMITPOS: ("rad", "m"),
    _S.mjSENS_JOINTLIMITVEL: ("rad/s", "m/s"),
    _S.mjSENS_JOINTLIMITFRC: ("N m", "N"),
    _S.mjSENS_ACTUATORPOS: ("rad", "m"),
    _S.mjSENS_ACTUATORVEL: ("rad/s", "m/s"),
    _S.mjSENS_ACTUATORFRC: ("N m", "N"),
}
_KINDS: Final[Mapping[int, int]] = {
    _S.mjSENS_ACCELEROMETER: DeviceKind.ACCEL,
    _S.mjSENS_FRAMELINACC: DeviceKind.ACCEL,
    _S.mjSENS_GYRO: DeviceKind.GYRO,
    _S.mjSENS_FRAMEANGVEL: DeviceKind.GYRO,
    _S.mjSENS_FORCE: DeviceKind.FORCE,
    _S.mjSENS_TENDONACTFRC: DeviceKind.FORCE,
    _S.mjSENS_TORQUE: DeviceKind.TORQUE,
    _S.mjSENS_TOUCH: DeviceKind.TOUCH,
    _S.mjSENS_MAGNETOMETER: DeviceKind.COMPASS,
    _S.mjSENS_RANGEFINDER: DeviceKind.DISTANCE,
    _S.mjSENS_FRAMEPOS: DeviceKind.DISTANCE,
    _S.mjSENS_GEOMDIST: DeviceKind.DISTANCE,
    _S.mjSENS_TENDONPOS: DeviceKind.DISTANCE,
    _S.mjSENS_SUBTREECOM: DeviceKind.DISTANCE,
    _S.mjSENS_BALLQUAT: DeviceKind.ROTARY_ANGLE,
}


ReadPlan = tuple[list[SensorDevice], Callable[[tuple[float, ...]], tuple[tuple[float, ...], ...]]]
"""The devices a simulation's sensors were last read together as, and how to cut them out of
``sensordata`` (see ``MujocoSensor.read_values_many_nowait``)."""

# Reading's generated __new__ is Python code (~225 ns); tuple.__new__ builds the same
# named tuple in half the time, on the per-read path.
_new_reading: Final = tuple.__new__


def _cutter(
    slices: Sequence[slice],
) -> Callable[[tuple[float, ...]], tuple[tuple[float, ...], ...]]:
    """One call cutting a flat tuple of sensor values into each sensor's values."""
    if len(slices) == 1:
        one = slices[0]

        def cut(values: tuple[float, ...]) -> tuple[tuple[float, ...], ...]:
            return (values[one],)

        return cut
    return cast(Callable[[tuple[float, ...]], tuple[tuple[float, ...], ...]], itemgetter(*slices))


def _sensor_joint_type(model: mujoco.MjModel, sid: int) -> int | None:
    """Joint type behind a joint or actuator sensor (None if not joint-based)."""
    objtype = int(model.sensor_objtype[sid])
    objid = int(model.sensor_objid[sid])
    if objtype == mujoco.mjtObj.mjOBJ_JOINT:
        return int(model.jnt_type[objid])
    if objtype == mujoco.mjtObj.mjOBJ_ACTUATOR and (
        int(model.actuator_trntype[objid]) == mujoco.mjtTrn.mjTRN_JOINT
    ):
        return int(model.jnt_type[int(model.actuator_trnid[objid, 0])])
    return None


def sensor_units(model: mujoco.MjModel, sid: int) -> tuple[str, ...]:
    """SI unit of each value of sensor ``sid`` ('' where MuJoCo does not define one)."""
    stype = int(model.sensor_type[sid])
    dim = int(model.sensor_dim[sid])
    unit = _FIXED_UNITS.get(stype)
    if unit is None and stype in _JOINT_UNITS:
        jtype = _sensor_joint_type(model, sid)
        hinge, slide = _JOINT_UNITS[stype]
        if jtype == mujoco.mjtJoint.mjJNT_SLIDE:
            unit = slide
        elif jtype in (mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_BALL):
            unit = hinge
    return (unit or "",) * dim


def sensor_kind(model: mujoco.MjModel, sid: int) -> int:
    """HALId device kind for sensor ``sid`` (OTHER_KIND outside the OpenEL registry)."""
    stype = int(model.sensor_type[sid])
    kind = _KINDS.get(stype)
    if kind is not None:
        return kind
    if stype in _JOINT_UNITS:
        slide = _sensor_joint_type(model, sid) == mujoco.mjtJoint.mjJNT_SLIDE
        if stype in (_S.mjSENS_JOINTACTFRC, _S.mjSENS_ACTUATORFRC, _S.mjSENS_JOINTLIMITFRC):
            return DeviceKind.FORCE if slide else DeviceKind.TORQUE
        return DeviceKind.DISTANCE if slide else DeviceKind.ROTARY_ANGLE
    return OTHER_KIND


def geomagnetic_field_enu(field: MagneticField) -> tuple[float, float, float]:
    """A World Magnetic Model field (nT: X north, Y east, Z down) as MuJoCo's
    ``opt.magnetic`` (tesla) in a world frame with x east, y north, z up (ENU)."""
    return (field.y * 1e-9, field.x * 1e-9, -field.z * 1e-9)


def set_geomagnetic_field(model: mujoco.MjModel, field: MagneticField) -> None:
    """Make the model's magnetometers measure ``field`` (the world frame taken as ENU), so
    that a :class:`~openel_async.direction.DirectionSensor` over a magnetometer on a site
    (x forward, y left, z up) gives the site's heading."""
    model.opt.magnetic[:] = geomagnetic_field_enu(field)


class MujocoSensor(SensorDevice):
    """A MuJoCo sensor of a :class:`MujocoSim` as an OpenEL sensor.

    ``read()`` returns the sensor's ``sensordata`` values (SI; MuJoCo applies the sensor's
    ``cutoff``, not its ``noise``).  ``mj_step`` computes sensors in its forward pass, *before*
    integrating, so the values describe the state at the start of the latest physics step:
    the reading's ``time_ns`` is that state's time on the simulation's clock (one time step
    before ``now_ns()`` in lockstep), monotonic from reading to reading.

    ``sim.sensor(name)`` gives a ``MujocoSensor`` of the kind of the MuJoCo sensor
    (``info.kind``: gyro -> GYRO, accelerometer -> ACCEL, ... ``sensor_kind``), whose product
    id is that of the kind's device class below, so that its HALId creates the same device
    through the Device Kind ID registry. (One class for every kind keeps a ``SensorBank`` of
    a simulation's sensors one call: the framework batches devices of one class.)
    """

    info = DeviceInfo(
        kind=OTHER_KIND,
        vendor_id=VENDOR_ID,
        product_id=SENSOR_PRODUCT_ID,
        vendor_name=VENDOR_NAME,
        product_name="Sensor",
    )
    required_kind: ClassVar[int | None] = None
    """The kind a device class of one HAL4RT kind (MujocoGyro...) requires of its sensor."""

    def __init__(
        self,
        sim: MujocoSim,
        spec: SensorSpec | str | Mapping[str, Any] | None = None,
        **fields: Any,
    ) -> None:
        """The sensor of ``spec`` (a spec, a sensor name or a dict of SensorSpec fields), or
        of the SensorSpec ``fields`` as keywords (a rig file's ``params``: ``sensor``
        defaults to ``name``); it registers itself in ``sim.sensors`` (``BadParameterError``
        when its name is mapped already). ``sim.sensor(name)`` is the usual way."""
        spec = spec_of(SensorSpec, spec, fields, "sensor")
        sim._check_new_sensor(spec)
        model = sim.model
        self.sim = sim
        self.spec = spec
        self.name = spec.key
        self.sensor_id = sid = find_id(model, "sensor", spec.sensor)
        self.sensor_type = mujoco.mjtSensor(int(model.sensor_type[sid]))
        self.dim = int(model.sensor_dim[sid])
        self._start = int(model.sensor_adr[sid])
        self._end = self._start + self.dim
        self._slice = slice(self._start, self._end)
        self.units = spec.units if spec.units is not None else sensor_units(model, sid)
        if len(self.units) != self.dim:
            raise BadParameterError(
                "units", self.units, f"{self.dim} unit(s) for sensor {spec.sensor!r}"
            )
        kind = spec.kind_id
        if kind is None:
            kind = sensor_kind(model, sid)
        required = self.required_kind
        if required is not None and kind != required:
            raise BadParameterError(
                "sensor",
                spec.sensor,
                f"a sensor of kind {DeviceKind(required).name} for a {type(self).__name__} "
                f"(a {self.sensor_type.name.removeprefix('mjSENS_').lower()} sensor of kind "
                f"0x{kind:X}: use sim.sensor)",
            )
        self.info = DeviceInfo(
            kind=kind,
            vendor_id=VENDOR_ID,
            product_id=KIND_PRODUCT_IDS.get(kind, SENSOR_PRODUCT_ID),
            vendor_name=VENDOR_NAME,
            product_name=_camel(self.name, "Sensor"),
        )
        self._ctx: DeviceContext | None = None
        self._rejected = 0
        sim._sensors[spec.key] = self

    async def open(self, ctx: DeviceContext) -> None:
        if not self.sim._attach(self, ctx):
            self._rejected += 1  # the failed component's close() must not detach the owner
            raise HALError(f"{self.name}: device already belongs to a component")
        self._ctx = ctx

    async def init(self) -> None:
        self.sim._check_running_state()

    async def reset(self) -> None:
        self.sim._recover()

    async def close(self) -> None:
        if self._rejected:
            self._rejected -= 1
            return
        self.sim._detach(self)
        self._ctx = None

    async def read(self) -> Reading:
        return self.read_nowait()

    def read_nowait(self) -> Reading:
        sim = self.sim
        if sim._fault is not None:
            raise HALError(f"{self.name}: the simulation is faulted: {sim._fault}")
        values = sim._sensordata_tuple()[self._slice]
        return _new_reading(Reading, (values, sim._sensor_clock_ns))

    @classmethod
    def read_values_many_nowait(cls, devices: Sequence[SensorDevice]) -> list[Sequence[float]]:
        """Sensors of one simulation: slices of one conversion of ``sensordata``, cut by one
        ``itemgetter`` planned once per list of devices (a bank reads the same list at every
        step)."""
        first = devices[0] if devices else None
        if type(first) is not cls or not isinstance(first, MujocoSensor):
            return super().read_values_many_nowait(devices)
        sim = first.sim
        if sim._fault is not None:
            raise HALError(f"{sim.name}: the simulation is faulted: {sim._fault}")
        plan = sim._read_plan
        if plan is None or plan[0] != devices:
            plan = cls._read_plan_of(sim, devices)
            if plan is None:
                return super().read_values_many_nowait(devices)  # mixed devices or simulations
        return list(plan[1](sim._sensordata_tuple()))

    @classmethod
    def batch_reader(cls, devices: Sequence[SensorDevice]) -> BatchReader | None:
        """Sensors of one simulation: a SensorBank's read as one copy of their ``sensordata``
        values and one ``itemgetter`` cutting it into each sensor's tuple; None for other
        devices.  The copy is of one numpy view made here, spanning every sensor of the bank
        (and the values between them, when they are fewer than the bank's: the bank's
        finiteness check then covers them too, and looks sensor by sensor only if one is
        not finite), else one gather of exactly the bank's values."""
        sensors = [d for d in devices if type(d) is cls and isinstance(d, MujocoSensor)]
        if not sensors or len(sensors) != len(devices):
            return None
        sim = sensors[0].sim
        if any(s.sim is not sim for s in sensors):
            return None
        count = sum(s.dim for s in sensors)
        low = min(s._start for s in sensors)
        high = max(s._end for s in sensors)
        spanned = high - low <= 2 * count
        cuts: list[slice] = []
        at = 0
        for sensor in sensors:
            start = sensor._start - low if spanned else at
            cuts.append(slice(start, start + sensor.dim))
            at += sensor.dim
        cut = _cutter(cuts)
        sensordata = sim._sensordata
        if spanned:
            # the bytes of MjData's own buffer (never reallocated): the current values,
            # unpacked as they are into a tuple of floats
            span = memoryview(sensordata[low:high]).cast("B")
            unpack = struct.Struct(f"{high - low}d").unpack

            def read() -> tuple[Sequence[float], tuple[tuple[float, ...], ...]]:
                if sim._fault is not None:
                    raise HALError(f"{sim.name}: the simulation is faulted: {sim._fault}")
                flat = unpack(span)
                return flat, cut(flat)

        else:
            gather = np.array([i for s in sensors for i in range(s._start, s._end)], np.intp)

            def read() -> tuple[Sequence[float], tuple[tuple[float, ...], ...]]:
                if sim._fault is not None:
                    raise HALError(f"{sim.name}: the simulation is faulted: {sim._fault}")
                flat = tuple(sensordata[gather].tolist())
                return flat, cut(flat)

        return read

    @classmethod
    def _read_plan_of(cls, sim: MujocoSim, devices: Sequence[SensorDevice]) -> ReadPlan | None:
        slices = []
        for device in devices:
            # type() rather than isinstance(): ABC instance checks cost ~150 ns
            if type(device) is not cls or not isinstance(device, MujocoSensor):
                return None
            if device.sim is not sim:
                return None
            slices.append(device._slice)
        cut = _cutter(slices)
        plan = sim._read_plan = (list(devices), cut)
        return plan

    @property
    def values(self) -> tuple[float, ...]:
        """The current values, without the component (for recorders and tests)."""
        return tuple(self.sim._sensordata[self._start : self._end].tolist())

    def _fault(self, reason: str) -> None:
        ctx = self._ctx
        if ctx is not None:
            ctx.fault(ErrorId.DEVICE_ERROR, reason)

    def __repr__(self) -> str:
        kind = self.sensor_type.name.removeprefix("mjSENS_").lower()
        return f"MujocoSensor({self.name!r}, {kind}, dim={self.dim}, sim={self.sim.name!r})"


# -- one device class per HAL4RT sensor kind: the Device Kind ID registry's entries ----------


def _kind_info(kind: DeviceKind, product_name: str) -> DeviceInfo:
    return DeviceInfo(kind, VENDOR_ID, KIND_PRODUCT_IDS[kind], VENDOR_NAME, product_name)


class MujocoEncoder(MujocoSensor):
    """A ``jointpos`` (or ``actuatorpos``, ``jointvel``...) sensor of a hinge: HAL4RT Encoder
    (``ROTARY_ANGLE``), rad."""

    info = _kind_info(DeviceKind.ROTARY_ANGLE, "Encoder")
    units = ("rad",)
    required_kind = DeviceKind.ROTARY_ANGLE


class MujocoGyro(MujocoSensor):
    """A ``gyro`` (or ``frameangvel``) sensor: HAL4RT Gyro Sensor (``GYRO``), rad/s x3."""

    info = _kind_info(DeviceKind.GYRO, "Gyro")
    units = ("rad/s",) * 3
    required_kind = DeviceKind.GYRO


class MujocoAccelerometer(MujocoSensor):
    """An ``accelerometer`` (or ``framelinacc``) sensor: HAL4RT Acceleration Sensor
    (``ACCEL``), m/s^2 x3."""

    info = _kind_info(DeviceKind.ACCEL, "Accelerometer")
    units = ("m/s^2",) * 3
    required_kind = DeviceKind.ACCEL


class MujocoForceSensor(MujocoSensor):
    """A ``force`` sensor (or a slide's ``jointactuatorfrc``, ``tendonactfrc``...): HAL4RT
    Force Sensor (``FORCE``), N x3."""

    info = _kind_info(DeviceKind.FORCE, "ForceSensor")
    units = ("N",) * 3
    required_kind = DeviceKind.FORCE


class MujocoTorqueSensor(MujocoSensor):
    """A ``torque`` sensor (or a hinge's ``jointactuatorfrc``...): HAL4RT Torque Sensor
    (``TORQUE``), N m x3."""

    info = _kind_info(DeviceKind.TORQUE, "TorqueSensor")
    units = ("N m",) * 3
    required_kind = DeviceKind.TORQUE


class MujocoMagnetometer(MujocoSensor):
    """A ``magnetometer`` sensor: HAL4RT Direction Sensor (``COMPASS``), the raw field
    vector in the site's frame, T x3 (``DirectionSensor(frame="FLU")`` computes the heading;
    :func:`set_geomagnetic_field` sets the field)."""

    info = _kind_info(DeviceKind.COMPASS, "Magnetometer")
    units = ("T",) * 3
    required_kind = DeviceKind.COMPASS


SENSOR_DEVICE_CLASSES: Final[Mapping[int, type[MujocoSensor]]] = {
    cls.info.kind: cls
    for cls in (
        MujocoEncoder,
        MujocoGyro,
        MujocoAccelerometer,
        MujocoForceSensor,
        MujocoTorqueSensor,
        MujocoMagnetometer,
    )
}
"""The device class of each HAL4RT sensor kind MuJoCo simulates (registered by the driver)."""
