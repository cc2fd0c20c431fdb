"""The compiled fast paths of the MuJoCo joints: an ActuatorBank's setpoints as one generated
function of ctrl writes (:class:`JointBatch`) and the simulation's per-step monitor of limits,
saturation and completion (:func:`monitor_plan`), both rebuilt when a joint's plan changes
(:data:`DRIVE_PLANS`).

Re-exported by :mod:`openel_mujoco.devices`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from types import CodeType, FunctionType
from typing import TYPE_CHECKING, Final, Protocol, cast

from openel_async.device import DeviceContext
from openel_async.errors import HALError
from openel_async.requests import Request

if TYPE_CHECKING:
    from .joints import MujocoJoint

__all__ = ["DRIVE_PLANS", "IDLE", "FloatItems", "JointBatch", "Monitor", "monitor_plan"]

# Enum members read on the per-step paths, as module constants (a class attribute read of
# an enum member costs ~80 ns on CPython 3.11).
_POSITION: Final = Request.POSITION
_VELOCITY: Final = Request.VELOCITY
IDLE: Final = 0
"""``MujocoJoint._since`` when no target is pending (physics steps count from 1, so a
pending target's ``_since`` is never 0: the monitor tests it for truth)."""


class FloatItems(Protocol):
    """Items of a float64 array read and written one at a time (a ``memoryview`` of it:
    each item is a Python float, with no numpy scalar and no conversion of the array)."""

    def __getitem__(self, index: int, /) -> float: ...

    def __setitem__(self, index: int, value: float, /) -> None: ...


class _DriveVersion:
    """Bumped whenever any joint's command fast path (mode, drive actuator, ramp), its limit
    or saturation state or its attachment changes: batch plans (``JointBatch``) and the
    simulations' monitor plans (:func:`monitor_plan`) are then rebuilt."""

    __slots__ = ("version",)

    def __init__(self) -> None:
        self.version = 0


DRIVE_PLANS: Final = _DriveVersion()


class JointBatch:
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
                f"                j{i}._since = {IDLE}",
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
        if first <= 2 and joint._since != IDLE:
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
                    joint._since = IDLE
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
        joint._since = IDLE
        ctx.target_reached()
