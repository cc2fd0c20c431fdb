"""MuJoCo actuators that do not drive one joint, as OpenEL actuators (:class:`MujocoEffector`).

:class:`~openel_mujoco.joints.MujocoJoint` maps a hinge or slide *joint* (with its position,
velocity and motor actuators) to an OpenEL Actuator.  Grippers, suction cups, thrusters and
tendon drives are MuJoCo *actuators* with other transmissions (body, tendon, site, slider-crank,
ball joint); :class:`MujocoEffector` maps one such actuator to an ``ActuatorDevice``.  Create it
with ``sim.effector(actuator_name)`` or declare it in ``SimDescription.effectors``.

The request mapping follows from the actuator (gain, bias and transmission), in the model's SI
units (``kind`` tells which applies):

- **adhesion** (an ``adhesion`` actuator, body transmission): TORQUE = the adhesion force in N,
  0 to gain x the largest ctrl (a negative force is refused); NO_EXCITE = off (ctrl 0).
- **force** (fixed gain, no bias: ``motor``, a ``general`` force actuator; no or filter
  dynamics): TORQUE = the actuator force (``actuator_force``, before the gear: gain x ctrl in
  the steady state); NO_EXCITE = zero force.
- **position** (affine bias ``-kp x length``: a ``position`` servo, e.g. on a tendon):
  POSITION = the actuator length the servo settles at (a tendon's length x gear); NO_EXCITE =
  the actuator disabled through ``opt.disableactuator`` (it needs an actuator group of its
  own, as joints that switch modes do).
- **velocity** (affine bias ``-kv x velocity``): VELOCITY = the actuator velocity; NO_EXCITE
  as for position servos.

Actuators with a hinge or slide joint transmission are joints' business
(``sim.actuator(joint)``) and refused here; muscles and actuators with integrator or user
dynamics do not map (``ModelLoadError``).

Limits come from ``ctrlrange`` (scaled to the commanded quantity) and ``forcerange``; a target
outside them raises :class:`~openel_async.errors.BadParameterError` (the framework checks the
symmetric ``ActuatorLimits``, the effector the exact range, e.g. a negative adhesion force).
TORQUE_ACTUAL reads ``actuator_force``; POSITION_ACTUAL and VELOCITY_ACTUAL read
``actuator_length``/``actuator_velocity`` where the transmission has a length (tendon,
slider-crank, joint, site with a reference site), and are refused otherwise.

Completion comes from the physics (``reports_completion``), never from the command: after every
physics step the simulation checks the latest target against the actuator's state (force within
``torque_tolerance``; length within ``position_tolerance`` while slower than
``settle_velocity``; velocity within ``velocity_tolerance``), continuously for ``settle_s``.  An
adhesion force (no dynamics) is reached at the next step; a gripper closing on an object never
reaches a length inside the object, so its POSITION target stays pending (SATURATED tells that
it squeezes at its force limit).

Adhesion acts only through contacts: the force is applied (TORQUE_ACTUAL reads it) whether or
not the body touches anything, but it pulls only on bodies in contact with the adhesion body's
geoms.  Giving those geoms a small ``margin`` with an equal ``gap`` makes contacts (and the
adhesion) start a little before touching, without contact forces of their own, so that the
adhesion keeps pulling during the first millimetres of a lift.  The effector therefore
tells when it *holds* something: ``holding`` is true while the adhesion force acts (at the
latest physics step) and its touch sensor reads at least ``hold_force`` (the first touch sensor
on a site of the adhesion body, or ``EffectorSpec.touch_sensor``), or, without a touch sensor,
while a contact involves one of the body's geoms; the component posts
``MujocoEventId.HOLDING`` (4) and ``RELEASED`` (5) on the edges.  Per physics step an attached
effector costs well under a microsecond (a few array reads; about 2 us for the contact-list
check of an adhesion without a touch sensor while it is on).

``close()`` (finalize) and ``re_init`` stop the effector: zero force for adhesion and force
actuators (a suction cup lets go), hold the current length for a position servo, zero velocity
for a velocity servo.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, Final, Literal

import mujoco
import numpy as np

from openel_async.device import (
    ActuatorDevice,
    ActuatorLimits,
    DeviceContext,
    DeviceInfo,
    ErrorId,
)
from openel_async.errors import BadParameterError, HALError, NotImplementedHALError
from openel_async.ids import DeviceKind
from openel_async.requests import Request

from .description import EffectorSpec, spec_of
from .device_base import (
    EFFECTOR_PRODUCT_ID,
    OTHER_KIND,
    VENDOR_ID,
    VENDOR_NAME,
    MujocoEventId,
    SimActuatorLifecycle,
    own_actuator_group,
    product_name,
)
from .models import ModelLoadError, find_id, names

if TYPE_CHECKING:
    from .sim import MujocoSim

__all__ = ["EffectorKind", "MujocoEffector", "effector_kind"]

EffectorKind = Literal["adhesion", "force", "position", "velocity"]
"""How an effector's actuator is commanded (see the module docstring)."""

_T = mujoco.mjtTrn
_LENGTH_TRANSMISSIONS: Final = frozenset(
    {int(_T.mjTRN_JOINT), int(_T.mjTRN_JOINTINPARENT), int(_T.mjTRN_TENDON),
     int(_T.mjTRN_SLIDERCRANK)}
)  # fmt: skip
_STEADY_DYNAMICS: Final = frozenset(
    {int(mujoco.mjtDyn.mjDYN_NONE), int(mujoco.mjtDyn.mjDYN_FILTER),
     int(mujoco.mjtDyn.mjDYN_FILTEREXACT)}
)  # fmt: skip
_COMMAND: Final[dict[EffectorKind, Request]] = {
    "adhesion": Request.TORQUE,
    "force": Request.TORQUE,
    "position": Request.POSITION,
    "velocity": Request.VELOCITY,
}
_SATURATION_RELEASE: Final = 0.98


def _transmission(model: mujoco.MjModel, act: int) -> str:
    return str(mujoco.mjtTrn(int(model.actuator_trntype[act])).name).removeprefix("mjTRN_").lower()


def effector_kind(model: mujoco.MjModel, act: int) -> EffectorKind:
    """The kind of actuator ``act`` (see the module docstring); raises
    :class:`~openel_mujoco.models.ModelLoadError` for one that cannot be mapped (muscle,
    integrator or user dynamics, non-fixed gain, other biases)."""
    name = names(model, "actuator")[act] or f"#{act}"
    if int(model.actuator_trntype[act]) == _T.mjTRN_BODY:
        return "adhesion"
    dyn = int(model.actuator_dyntype[act])
    if dyn not in _STEADY_DYNAMICS:
        kind = mujoco.mjtDyn(dyn).name.removeprefix("mjDYN_").lower()
        raise ModelLoadError(
            f"actuator {name!r} has {kind} dynamics: its ctrl is not a force, length or velocity "
            "target, so it does not map to an OpenEL actuator"
        )
    gain = float(model.actuator_gainprm[act, 0])
    if int(model.actuator_gaintype[act]) != mujoco.mjtGain.mjGAIN_FIXED or gain == 0.0:
        raise ModelLoadError(
            f"actuator {name!r} needs a fixed, nonzero gain to map to an OpenEL actuator"
        )
    bias = int(model.actuator_biastype[act])
    b0, b1, b2 = (float(v) for v in model.actuator_biasprm[act, :3])
    if bias == mujoco.mjtBias.mjBIAS_NONE or b0 == b1 == b2 == 0.0:
        return "force"
    if bias == mujoco.mjtBias.mjBIAS_AFFINE and b0 == 0.0:
        if b1 < 0.0:
            return "position"
        if b1 == 0.0 and b2 < 0.0:
            return "velocity"
    raise ModelLoadError(
        f"actuator {name!r} has a bias ({b0:g}, {b1:g}, {b2:g}) that is neither a motor, a "
        "position servo (0, -kp, -kv) nor a velocity servo (0, 0, -kv)"
    )


def _ordered(a: float, b: float) -> tuple[float, float]:
    return (a, b) if a <= b else (b, a)


class MujocoEffector(SimActuatorLifecycle, ActuatorDevice):
    """A MuJoCo actuator that does not drive one hinge/slide joint, as an OpenEL actuator.

    See the module docstring for the request mapping, limits, completion and the adhesion
    events.  ``command_nowait``/``read_nowait`` are the synchronous paths (the async
    ``command``/``read`` call them).
    """

    reports_completion = True
    linear = True
    """Lengths in m, forces in N (False for an actuator on a ball joint: rad, N m)."""
    info = DeviceInfo(
        kind=DeviceKind.MOTOR,
        vendor_id=VENDOR_ID,
        product_id=EFFECTOR_PRODUCT_ID,
        vendor_name=VENDOR_NAME,
        product_name="Effector",
    )

    def __init__(
        self,
        sim: MujocoSim,
        spec: EffectorSpec | str | Mapping[str, Any] | None = None,
        **fields: Any,
    ) -> None:
        """The effector of ``spec`` (a spec, an actuator name or a dict of EffectorSpec
        fields), or of the EffectorSpec ``fields`` as keywords (a rig file's ``params``:
        ``actuator`` defaults to ``name``); it registers itself in ``sim.effectors``
        (``BadParameterError`` when its name or actuator is mapped already).
        ``sim.effector(name)`` is the usual way."""
        spec = spec_of(EffectorSpec, spec, fields, "actuator")
        sim._check_new_effector(spec)
        model = sim.model
        self.sim = sim
        self.spec = spec
        self.name = spec.key
        self.actuator = spec.actuator
        self.actuator_id = act = find_id(model, "actuator", spec.actuator)
        trn = int(model.actuator_trntype[act])
        if trn in (_T.mjTRN_JOINT, _T.mjTRN_JOINTINPARENT):
            jid = int(model.actuator_trnid[act, 0])
            if int(model.jnt_type[jid]) in (
                mujoco.mjtJoint.mjJNT_HINGE,
                mujoco.mjtJoint.mjJNT_SLIDE,
            ):
                joint = names(model, "joint")[jid]
                raise BadParameterError(
                    "actuator",
                    spec.actuator,
                    f"an actuator that does not drive a single hinge or slide joint (it drives "
                    f"joint {joint!r}: map the joint with sim.actuator({joint!r}))",
                )
        self.transmission = _transmission(model, act)
        if trn in (_T.mjTRN_JOINT, _T.mjTRN_JOINTINPARENT):
            self.linear = False  # a ball joint: rad, N m
        self.kind: EffectorKind = effector_kind(model, act)
        self.request = request = _COMMAND[self.kind]
        self.has_length = trn in _LENGTH_TRANSMISSIONS or (
            trn == _T.mjTRN_SITE and int(model.actuator_trnid[act, 1]) >= 0
        )
        if self.kind in ("position", "velocity") and not self.has_length:
            raise ModelLoadError(
                f"actuator {spec.actuator!r} is a {self.kind} servo on a {self.transmission} "
                "transmission without a length; it does not map to an OpenEL actuator"
            )

        group = int(model.actuator_group[act])
        self._own_group = own_actuator_group(model, act)
        self._bit = 1 << group if 0 <= group <= 30 else 0
        if self._disabled() and not self._own_group:
            raise ModelLoadError(
                f"actuator {spec.actuator!r} is disabled (group {group} in "
                "opt.disableactuator) and shares its group, so it cannot be enabled alone"
            )

        # value <-> ctrl: value = ctrl * gain / divisor at equilibrium
        gain = float(model.actuator_gainprm[act, 0])
        b1, b2 = (float(v) for v in model.actuator_biasprm[act, 1:3])
        divisor = {"position": -b1, "velocity": -b2}.get(self.kind, 1.0)
        self._scale = divisor / gain  # ctrl per unit of the commanded value
        self._range = self._value_range(model, gain / divisor)
        self.limits = self._limits()

        supported = {request}
        if self.kind in ("adhesion", "force") or self._own_group:
            supported.add(Request.NO_EXCITE)
        self.supported_requests = frozenset(supported)
        self.info = DeviceInfo(
            kind=OTHER_KIND if self.kind == "adhesion" else DeviceKind.MOTOR,
            vendor_id=VENDOR_ID,
            product_id=EFFECTOR_PRODUCT_ID,
            vendor_name=VENDOR_NAME,
            product_name=product_name(self.name, "Effector"),
        )

        # adhesion: what tells that it holds something
        self._touch_adr = -1
        self._geoms: frozenset[int] = frozenset()
        self.touch_sensor: str | None = None
        """The touch sensor that tells when an adhesion effector holds something (None:
        the contact list of the adhesion body)."""
        if spec.touch_sensor is not None and self.kind != "adhesion":
            raise BadParameterError(
                "touch_sensor", spec.touch_sensor, f"None ({spec.actuator!r} is not adhesion)"
            )
        if self.kind == "adhesion":
            body = int(model.actuator_trnid[act, 0])
            sid = self._touch_sensor(model, body, spec.touch_sensor)
            if sid >= 0:
                self._touch_adr = int(model.sensor_adr[sid])
                self.touch_sensor = names(model, "sensor")[sid]
            else:
                self._geoms = frozenset(np.flatnonzero(model.geom_bodyid == body).tolist())

        # saturation of servos at their force range
        self._sat_lo = self._sat_hi = math.nan
        self._check_saturation = self.kind in ("position", "velocity") and bool(
            model.actuator_forcelimited[act]
        )
        if self._check_saturation:
            low, high = (float(v) for v in model.actuator_forcerange[act])
            self._sat_lo, self._sat_hi = low * (1 - 1e-9), high * (1 - 1e-9)
            self._sat_lo_off, self._sat_hi_off = (
                low * _SATURATION_RELEASE,
                high * _SATURATION_RELEASE,
            )

        dt = float(model.opt.timestep)
        self._settle_steps = max(0, math.ceil(spec.settle_s / dt - 1e-9))
        self._tolerance = {
            Request.TORQUE: spec.torque_tolerance,
            Request.POSITION: spec.position_tolerance,
            Request.VELOCITY: spec.velocity_tolerance,
        }[request]
        self._settle_velocity = spec.settle_velocity
        self._hold_force = spec.hold_force

        data = sim.data
        self._ctrl = sim._ctrl
        self._force = sim._actuator_force
        self._length = data.actuator_length
        self._velocity = data.actuator_velocity
        self._sensordata = sim._sensordata
        self._data = data

        self._ctx: DeviceContext | None = None
        self._rejected = 0
        self._target = 0.0
        self._pending = False
        self._within_since = -1
        self._holding = False
        self._saturated = False
        self.commands = 0
        self._init_state()
        sim._effectors[spec.key] = self

    # -- construction helpers ----------------------------------------------------------
    def _value_range(self, model: mujoco.MjModel, per_ctrl: float) -> tuple[float, float]:
        act = self.actuator_id
        low, high = -math.inf, math.inf
        if model.actuator_ctrllimited[act]:
            a, b = (float(v) * per_ctrl for v in model.actuator_ctrlrange[act])
            low, high = _ordered(a, b)
        if self.request is Request.TORQUE and model.actuator_forcelimited[act]:
            a, b = (float(v) for v in model.actuator_forcerange[act])
            low, high = max(low, min(a, b)), min(high, max(a, b))
        if self.kind == "adhesion":
            low = max(low, 0.0)
        if not low < high:
            raise ModelLoadError(
                f"actuator {self.actuator!r}: empty {self.request.name.lower()} range "
                f"[{low:g}, {high:g}] from its ctrlrange and forcerange"
            )
        return low, high

    def _limits(self) -> ActuatorLimits:
        low, high = self._range
        largest = max(abs(low), abs(high))
        if self.request is Request.POSITION:
            return ActuatorLimits(position=(low, high))
        if self.request is Request.VELOCITY:
            return ActuatorLimits(velocity=largest)
        return ActuatorLimits(torque=largest)

    @staticmethod
    def _touch_sensor(model: mujoco.MjModel, body: int, name: str | None) -> int:
        touch = mujoco.mjtSensor.mjSENS_TOUCH
        if name is not None:
            sid = find_id(model, "sensor", name)
            if int(model.sensor_type[sid]) != touch:
                raise BadParameterError("touch_sensor", name, "the name of a touch sensor")
            return sid
        for sid in range(int(model.nsensor)):
            if (
                int(model.sensor_type[sid]) == touch
                and int(model.sensor_objtype[sid]) == mujoco.mjtObj.mjOBJ_SITE
                and int(model.site_bodyid[int(model.sensor_objid[sid])]) == body
            ):
                return sid
        return -1

    def _disabled(self) -> bool:
        return bool(int(self.sim.model.opt.disableactuator) & self._bit)

    def _set_enabled(self, enabled: bool) -> None:
        model = self.sim.model
        mask = int(model.opt.disableactuator)
        model.opt.disableactuator = mask & ~self._bit if enabled else mask | self._bit

    def _init_state(self) -> None:
        """At creation and after a simulation reset: a position servo at the initial state
        with ctrl 0 holds the current length (no jump)."""
        sim, act = self.sim, self.actuator_id
        if self.kind == "position" and sim._physics_steps == 0 and self._ctrl[act] == 0.0:
            self._hold()

    def _hold(self) -> None:
        low, high = self._range
        length = min(max(float(self._length[self.actuator_id]), low), high)
        self._ctrl[self.actuator_id] = length * self._scale

    def _stop(self) -> None:
        """Safe state: no force (adhesion, force, velocity servo) or hold the length."""
        self._pending = False
        if self.kind == "position":
            if not self._disabled():
                self._hold()
        else:
            self._ctrl[self.actuator_id] = 0.0

    # -- lifecycle ---------------------------------------------------------------------
    async def open(self, ctx: DeviceContext) -> None:
        if not self.sim._attach(self, ctx):
            self._rejected += 1  # the failed component's close() must not detach the owner
            raise HALError(f"{self.name}: device already belongs to a component")
        self._ctx = ctx
        self._holding = False
        self._saturated = False

    def _safe_stop(self) -> None:
        self._stop()

    def _clear_pending(self) -> None:
        self._pending = False

    # -- commands and readings ---------------------------------------------------------
    async def command(self, request: Request, value: float) -> None:
        self.command_nowait(request, value)

    def command_nowait(self, request: Request, value: float) -> None:
        sim = self.sim
        if sim._fault is not None:
            raise HALError(f"{self.name}: the simulation is faulted: {sim._fault}")
        if request is self.request:
            low, high = self._range
            if not low <= value <= high:
                raise BadParameterError("value", value, self._range_text())
            if self._bit and self._disabled():
                self._set_enabled(True)
            self._ctrl[self.actuator_id] = value * self._scale
            self._target = value
            self._within_since = -1
            self._pending = True
        elif request is Request.NO_EXCITE and request in self.supported_requests:
            self._pending = False
            if self.kind in ("position", "velocity"):
                self._set_enabled(False)
            else:
                self._ctrl[self.actuator_id] = 0.0
        else:
            supported = ", ".join(r.name for r in sorted(self.supported_requests))
            raise NotImplementedHALError(
                f"{self.name}: {self.kind} effector does not support {request.name} "
                f"(supported: {supported})"
            )
        self.commands += 1

    def _range_text(self) -> str:
        low, high = self._range
        what = {
            "adhesion": "an adhesion force",
            "force": "an actuator force",
            "position": "an actuator length",
            "velocity": "an actuator velocity",
        }[self.kind]
        return f"{what} in [{low:g}, {high:g}]"

    async def read(self, request: Request) -> float:
        return self.read_nowait(request)

    def read_nowait(self, request: Request) -> float:
        act = self.actuator_id
        if request is Request.TORQUE_ACTUAL:
            return float(self._force.item(act))
        if self.has_length:
            if request is Request.POSITION_ACTUAL:
                return float(self._length.item(act))
            if request is Request.VELOCITY_ACTUAL:
                return float(self._velocity.item(act))
            allowed = "POSITION_ACTUAL, VELOCITY_ACTUAL or TORQUE_ACTUAL"
        else:
            allowed = f"TORQUE_ACTUAL (a {self.transmission} transmission has no length)"
        raise BadParameterError("request", request, allowed)

    # -- state for apps and tests ------------------------------------------------------
    @property
    def pending(self) -> bool:
        """True while the latest target is not reached yet (as judged by the physics)."""
        return self._pending

    @property
    def enabled(self) -> bool:
        """False while the actuator is disabled (NO_EXCITE of a servo)."""
        return not self._disabled()

    @property
    def on(self) -> bool:
        """Adhesion and force effectors: a nonzero force is commanded; servos: enabled."""
        if self._disabled():
            return False
        return self.kind in ("position", "velocity") or self._ctrl.item(self.actuator_id) != 0.0

    @property
    def force(self) -> float:
        """The actuator force (``actuator_force``) of the latest physics step."""
        return float(self._force.item(self.actuator_id))

    @property
    def holding(self) -> bool:
        """Adhesion: its force acted and it was in contact at the latest physics step (see the
        module docstring); else False."""
        return self.kind == "adhesion" and self._holds()

    def _holds(self) -> bool:
        if self._force.item(self.actuator_id) <= 0.0:  # off (or disabled) at the latest step
            return False
        if self._touch_adr >= 0:
            return bool(self._sensordata.item(self._touch_adr) >= self._hold_force)
        data = self._data
        return data.ncon > 0 and not self._geoms.isdisjoint(data.contact.geom.ravel().tolist())

    # -- called by the simulation loop -------------------------------------------------
    def _monitor(self, step: int) -> None:
        ctx = self._ctx
        if ctx is None:
            return
        act = self.actuator_id
        if self.kind == "adhesion":
            held = self._holds()
            if held is not self._holding:
                self._holding = held
                ctx.post_event(MujocoEventId.HOLDING if held else MujocoEventId.RELEASED)
        elif self._check_saturation:
            f = self._force.item(act)
            if self._saturated:
                if self._sat_lo_off < f < self._sat_hi_off:
                    self._saturated = False
            elif f <= self._sat_lo or f >= self._sat_hi:
                self._saturated = True
                ctx.post_event(MujocoEventId.SATURATED)
        if not self._pending:
            return
        request = self.request
        if request is Request.TORQUE:
            ok = abs(self._force.item(act) - self._target) <= self._tolerance
        elif request is Request.POSITION:
            ok = (
                abs(self._length.item(act) - self._target) <= self._tolerance
                and abs(self._velocity.item(act)) <= self._settle_velocity
            )
        else:
            ok = abs(self._velocity.item(act) - self._target) <= self._tolerance
        if not ok:
            self._within_since = -1
            return
        if self._within_since < 0:
            self._within_since = step
        if step - self._within_since >= self._settle_steps:
            self._pending = False
            ctx.target_reached()

    def _fault(self, reason: str) -> None:
        self._pending = False
        ctx = self._ctx
        if ctx is not None:
            ctx.fault(ErrorId.DEVICE_ERROR, reason)

    def _on_sim_reset(self) -> None:
        """The simulation was reset (initial state and actuator groups restored)."""
        self._pending = False
        self._holding = False
        self._saturated = False
        self._init_state()

    def __repr__(self) -> str:
        return (
            f"MujocoEffector({self.name!r}, {self.kind}, {self.transmission} transmission, "
            f"sim={self.sim.name!r})"
        )
