"""A hinge or slide joint of a :class:`~openel_mujoco.sim.MujocoSim` as an OpenEL actuator
(:class:`MujocoJoint`): POSITION, VELOCITY, TORQUE and NO_EXCITE through the joint's MuJoCo
actuators (found by :mod:`openel_mujoco.joint_actuators`), or a built-in PD controller over its
motor; speed ramps, limit and saturation events, completion judged from the physics (the
per-step checks and batch commands are compiled by :mod:`openel_mujoco.joint_plans`).

Re-exported by :mod:`openel_mujoco.devices`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, Final, cast

import mujoco

from openel_async.device import (
    ActuatorDevice,
    ActuatorLimits,
    BatchCommander,
    DeviceContext,
    DeviceInfo,
    ErrorId,
    VelocityRamp,
)
from openel_async.errors import BadParameterError, HALError
from openel_async.ids import DeviceKind
from openel_async.logs import get_logger
from openel_async.requests import Request

from .description import JointSpec, spec_of
from .device_base import (
    JOINT_PRODUCT_ID,
    VENDOR_ID,
    VENDOR_NAME,
    MujocoEventId,
    SimActuatorLifecycle,
    own_actuator_group,
    product_name,
)
from .joint_actuators import resolve_actuators
from .joint_plans import DRIVE_PLANS, IDLE, JointBatch
from .models import ControlMode, ModelLoadError, find_id, names

if TYPE_CHECKING:
    from .sim import MujocoSim

__all__ = ["MujocoJoint"]

log = get_logger(__name__)

_MODE_REQUEST: Final[Mapping[ControlMode, Request]] = {
    "position": Request.POSITION,
    "velocity": Request.VELOCITY,
    "torque": Request.TORQUE,
}
_PD_POSITION_HZ: Final = 5.0
_PD_VELOCITY_HZ: Final = 10.0
_SATURATION_RELEASE: Final = 0.98
_LIMIT_RELEASE: Final = 3.0

# Enum members read on the per-command paths, as module constants (a class attribute
# read of an enum member costs ~80 ns on CPython 3.11).
_VELOCITY: Final = Request.VELOCITY
_NO_EXCITE: Final = Request.NO_EXCITE
_LIMIT_REACHED: Final = MujocoEventId.LIMIT_REACHED
_SATURATED: Final = MujocoEventId.SATURATED

_REQUEST_MODE: Final[Mapping[Request, ControlMode]] = {v: k for k, v in _MODE_REQUEST.items()}


def _max_abs(low: float, high: float) -> float:
    return max(abs(low), abs(high))


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
        self._switchable = all(own_actuator_group(model, a) for a in acts.values())
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
            product_name=product_name(self.name, "Joint"),
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
        # The latest target's state, one attribute (a batch stores one per joint): IDLE
        # (nothing pending), -1 (pending, not within tolerance) or the physics step since
        # which the joint is within tolerance.  A pending target's request is the mode.
        self._since = IDLE
        self._at_limit = False
        self._saturated = False
        self._sat_lo = -math.inf
        self._sat_hi = math.inf
        self._sat_lo_off = -math.inf
        self._sat_hi_off = math.inf
        self._commands = 0  # by command_nowait and ramps; batches count their own
        self._batches: list[JointBatch] = []  # every batch commander made for this joint
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
        DRIVE_PLANS.version += 1  # batch plans (JointBatch) are rebuilt
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
        self._since = IDLE
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
        self._since = IDLE

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
                self._since = IDLE
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
        self._since = IDLE  # judged once the ramp has ended
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
        return self._since != IDLE or self._ramp is not None

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
        self._since = IDLE
        ctx = self._ctx
        if ctx is not None:
            ctx.fault(ErrorId.DEVICE_ERROR, reason)

    def _on_sim_reset(self) -> None:
        """The simulation was reset: adopt the model's restored control modes."""
        self._since = IDLE
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
        return cast(BatchCommander, JointBatch(tuple(joints)).send)

    def __repr__(self) -> str:
        return f"MujocoJoint({self.name!r}, mode={self._mode.name}, sim={self.sim.name!r})"
