"""MujocoSim: a MuJoCo model stepped inside the event loop as an OpenEL device layer.

One simulation owns one ``MjModel`` and its ``MjData`` (the control-mode switch of the joints
lives in the model, so a model is never shared) and steps the physics in a task of its own
while ``async with sim:`` runs.  Joints become :class:`~openel_mujoco.joints.MujocoJoint`
actuator devices and MuJoCo sensors :class:`~openel_mujoco.sensors.MujocoSensor` sensor
devices; actuators that do not drive one joint (adhesion, tendon, site ...) become
:class:`~openel_mujoco.effectors.MujocoEffector` actuator devices (``sim.effector(name)``).
Wrap them in ``Actuator``/``Sensor`` components on ``clock=sim.clock``.

Pacing
------
``lockstep`` (default): ``sim.clock`` is a :class:`~openel_mujoco.clock.LockstepClock` whose
time is the simulation time.  The physics advances one step whenever no task of the event loop
is runnable, and sleepers on the clock wake as it passes their deadlines; the simulation runs as
fast as the CPU allows and a run gives the same result every time.

``realtime``: ``sim.clock`` is the real clock (a ``MonotonicClock`` unless one is given, e.g. a
``VirtualClock`` in tests).  The loop sleeps until the deadline of the next physics step (the
clock's sleeper: a timerfd on Linux) and then steps every step that is due, so simulated time
follows the clock at ``realtime_factor``; lateness is recorded, and when more than
``max_catchup_steps`` are due the excess is dropped (simulated time falls behind) instead of
blocking the event loop.

After every physics step the loop runs the built-in PD controllers, checks for instability,
evaluates the joints' completion, limit and saturation conditions, and calls step hooks
(e.g. a :class:`~openel_mujoco.recorder.TrajectoryRecorder`).

Instability
-----------
MuJoCo's automatic reset is disabled.  When a step leaves NaN, infinite or huge (> 1e10) values
in ``qpos``, ``qvel`` or ``qacc`` (MuJoCo's BADQPOS/BADQVEL/BADQACC warnings), or ``mj_step``
raises, the simulation stops stepping and keeps the bad state for inspection, ``sim.fault``
holds the reason, and every component of the simulation goes to Error with
``ErrorId.DEVICE_ERROR`` (observers get ``notify_error``; pending motions fail).  The lockstep
clock keeps running without physics (jumping to deadlines like ``VirtualClock.autojump``), so
timers and timeouts still work.  ``re_init`` of any component (or :meth:`MujocoSim.reset`)
resets the simulation to its initial state (keyframe or ``qpos0``, initial control modes) and
stepping resumes; each other component stays in Error until its own ``re_init``.
"""

from __future__ import annotations

import asyncio
import dataclasses
import math
import os
import pathlib
import time
from collections.abc import AsyncIterator, Callable, Iterable, Mapping
from contextlib import asynccontextmanager
from dataclasses import dataclass
from types import MappingProxyType, TracebackType
from typing import Any, Final, Self, TypeVar, cast

import anyio
import anyio.abc
import mujoco
import numpy as np

from openel_async.clock import Clock, MonotonicClock
from openel_async.device import DeviceContext
from openel_async.errors import BadParameterError, HALError, StateError
from openel_async.logs import get_logger
from openel_async.stats import LatenessRecorder, LatenessSummary

from . import render
from .clock import LockstepClock, settle
from .description import EffectorSpec, JointSpec, Pacing, SensorSpec, SimDescription
from .effectors import MujocoEffector
from .joint_plans import DRIVE_PLANS, FloatItems, monitor_plan
from .joints import MujocoJoint
from .models import find_id, load_model
from .sensors import MujocoSensor, ReadPlan

__all__ = ["MujocoSim", "PacingStats"]

log = get_logger(__name__)

_UNSTABLE: Final = (
    mujoco.mjtWarning.mjWARN_BADQPOS,
    mujoco.mjtWarning.mjWARN_BADQVEL,
    mujoco.mjtWarning.mjWARN_BADQACC,
)
_BADQPOS, _BADQVEL, _BADQACC = (int(w) for w in _UNSTABLE)
_AUTORESET: Final = int(mujoco.mjtDisableBit.mjDSBL_AUTORESET)
LOCKSTEP_BATCH: Final = 256
"""Physics steps the lockstep loop runs back to back before yielding to the event loop."""
_BEHIND_LOG_INTERVAL_NS: Final = 1_000_000_000

_Device = MujocoJoint | MujocoSensor | MujocoEffector
_SpecT = TypeVar("_SpecT", JointSpec, SensorSpec, EffectorSpec)


@dataclass(frozen=True, slots=True)
class PacingStats:
    """How the simulation kept pace (see :attr:`MujocoSim.stats`)."""

    pacing: Pacing
    steps: int
    """Physics steps taken while running."""
    sim_time_s: float
    """Simulated time of those steps."""
    wall_time_s: float
    """Time the loop ran: on the pacing clock (realtime), real perf_counter time (lockstep);
    time paused or faulted is not counted."""
    realtime_factor: float
    """sim_time_s / wall_time_s (lockstep: how many times faster than real time it ran)."""
    lateness: LatenessSummary | None
    """Realtime: how late the loop woke after each step deadline (None in lockstep)."""
    max_catchup: int
    """Most physics steps taken in one wake-up (realtime) or one batch (lockstep)."""
    dropped_steps: int
    """Realtime: steps skipped because more than max_catchup_steps were due."""
    clock_ns: int
    """The clock's time when the stats were taken."""


def _install_warning_handler() -> None:
    """Route MuJoCo's warnings (printed to stderr by default) to structlog, unless the
    application installed its own handler."""
    if mujoco.get_mju_user_warning() is None:
        mujoco.set_mju_user_warning(_on_mujoco_warning)


def _on_mujoco_warning(message: str) -> None:
    log.warning("mujoco_warning", message=" ".join(str(message).split()))


class MujocoSim:
    """A MuJoCo simulation as an OpenEL device layer; see the module docstring.

    ``model`` is a shipped model name (``"arm2"``, ``"arm6"``, ``"so101"``), an MJCF/MJB path, or an
    ``MjModel`` the simulation then owns (it changes ``opt.disableactuator`` and
    ``opt.disableflags``).  ``keyframe`` names the initial state; ``timestep`` overrides
    ``opt.timestep`` (seconds).  ``clock`` is only for ``pacing="realtime"``.
    """

    def __init__(
        self,
        model: str | os.PathLike[str] | mujoco.MjModel = "arm2",
        *,
        pacing: Pacing = "lockstep",
        clock: Clock | None = None,
        keyframe: str | None = None,
        timestep: float | None = None,
        realtime_factor: float = 1.0,
        max_catchup_steps: int = 50,
        name: str | None = None,
        joints: Iterable[str | JointSpec | Mapping[str, Any]] = (),
        sensors: Iterable[str | SensorSpec | Mapping[str, Any]] = (),
        effectors: Iterable[str | EffectorSpec | Mapping[str, Any]] = (),
    ) -> None:
        if pacing not in ("lockstep", "realtime"):
            raise BadParameterError("pacing", pacing, "'lockstep' or 'realtime'")
        if pacing == "lockstep" and clock is not None:
            raise BadParameterError(
                "clock", clock, "None with pacing='lockstep' (the simulation is the clock)"
            )
        if not (
            isinstance(realtime_factor, int | float)
            and math.isfinite(realtime_factor)
            and realtime_factor > 0
        ):
            raise BadParameterError("realtime_factor", realtime_factor, "a finite number > 0")
        if isinstance(max_catchup_steps, bool) or not (
            isinstance(max_catchup_steps, int) and max_catchup_steps >= 1
        ):
            raise BadParameterError("max_catchup_steps", max_catchup_steps, "an int >= 1")
        if isinstance(model, mujoco.MjModel):
            self.model = model
        elif isinstance(model, str | os.PathLike):
            self.model = load_model(model)
        else:
            raise BadParameterError("model", model, "a model name, a file path or an MjModel")
        m = self.model
        if timestep is not None:
            if not (isinstance(timestep, int | float) and math.isfinite(timestep) and timestep > 0):
                raise BadParameterError("timestep", timestep, "a finite number of seconds > 0")
            m.opt.timestep = float(timestep)
        self.timestep_ns = round(float(m.opt.timestep) * 1e9)
        if self.timestep_ns < 1:
            raise BadParameterError("timestep", float(m.opt.timestep), "at least 1 ns")
        m.opt.disableflags = int(m.opt.disableflags) | _AUTORESET
        self.name = name or _model_name(m)
        self.pacing: Pacing = pacing
        self.realtime_factor = float(realtime_factor)
        self.max_catchup_steps = max_catchup_steps
        self.keyframe = keyframe
        self._key_id = find_id(m, "key", keyframe) if keyframe is not None else None
        self.data = mujoco.MjData(m)
        # sensordata as a tuple, as of physics step _sensor_step (see _sensordata_tuple)
        self._sensor_values: tuple[float, ...] | None = None
        self._sensor_step = 0
        self._read_plan: ReadPlan | None = None  # the sensors last read together
        self._initial_disableactuator = int(m.opt.disableactuator)
        self._reset_data()
        self.log = log.bind(sim=self.name)
        _install_warning_handler()

        d = self.data
        self._qpos = d.qpos
        self._qvel = d.qvel
        self._ctrl = d.ctrl
        self._sensordata = d.sensordata
        self._actuator_force = d.actuator_force
        self._qfrc_actuator = d.qfrc_actuator
        self._warnings = tuple(d.warning[int(w)] for w in _UNSTABLE)
        # Item views of the arrays read after every physics step: one item is a float (or
        # an int), with no conversion of the whole array and no numpy scalar.
        self._warning_counts = memoryview(d.warning.number)
        self._qpos_items = memoryview(d.qpos)
        self._qvel_items = memoryview(d.qvel)
        self._force_items = memoryview(d.actuator_force)
        self._ctrl_items = cast(FloatItems, memoryview(d.ctrl))  # streamed setpoints

        self._lockstep: LockstepClock | None = None
        if pacing == "lockstep":
            self._lockstep = LockstepClock()
            self.clock: Clock = self._lockstep
        else:
            self.clock = clock if clock is not None else MonotonicClock()
        self._sensor_clock_ns = self.clock.now_ns()

        self._joints: dict[str, MujocoJoint] = {}
        self._sensors: dict[str, MujocoSensor] = {}
        self._attached: dict[int, tuple[_Device, DeviceContext]] = {}
        self._monitored: list[MujocoJoint] = []
        self._monitor = monitor_plan((), (), (), ())
        self._monitor_version = -1  # DRIVE_PLANS.version the plan was built at
        self._effectors: dict[str, MujocoEffector] = {}
        self._monitored_effectors: list[MujocoEffector] = []
        self._pd_joints: list[MujocoJoint] = []
        self._ramp_joints: list[MujocoJoint] = []
        self._pre_step: list[Callable[[int], None]] = []
        """Called before every physics step with the clock time of the state stepped from:
        the speed ramps of the joints (first), then their built-in PD controllers."""
        self._hooks: list[Callable[[], None]] = []
        self._fault: str | None = None
        self._tg: anyio.abc.TaskGroup | None = None
        self._pause_count = 0
        self._changed = anyio.Event()

        self.steps = 0
        """Physics steps taken since the simulation was created (never reset)."""
        self._reset_at = 0  # ``steps`` at the last reset
        self._plain_step = True  # see _refresh_plain_step
        self._run_steps = 0
        self._run_wall_ns = 0
        self._run_started: int | None = None
        self._lateness = LatenessRecorder()
        self._max_catchup = 0
        self._dropped = 0
        self.resets = 0

        for joint in joints:
            spec = JointSpec.from_value(joint)
            self._add_joint(spec)
        for sensor in sensors:
            self._add_sensor(SensorSpec.from_value(sensor))
        for effector in effectors:
            self._add_effector(EffectorSpec.from_value(effector))

    @classmethod
    def from_description(
        cls,
        description: SimDescription | Mapping[str, Any],
        *,
        clock: Clock | None = None,
        **options: Any,
    ) -> MujocoSim:
        """Build the simulation and its devices from a :class:`SimDescription` (or its dict)."""
        desc = (
            description
            if isinstance(description, SimDescription)
            else SimDescription.from_dict(description)
        )
        return cls(
            desc.model,
            pacing=desc.pacing,
            clock=clock,
            keyframe=desc.keyframe,
            timestep=desc.timestep,
            name=desc.name,
            joints=desc.joints,
            sensors=desc.sensors,
            effectors=desc.effectors,
            **options,
        )

    # -- devices ---------------------------------------------------------------------------
    def actuator(self, joint: str, **options: Any) -> MujocoJoint:
        """The actuator device of ``joint`` (created on first use; ``options`` are JointSpec
        fields and only allowed the first time, or when they match)."""
        spec = _spec(JointSpec, joint=joint, **options)
        existing = self._joints.get(spec.key) or next(
            (j for j in self._joints.values() if j.joint == joint and not options), None
        )
        if existing is not None:
            if options and existing.spec != spec:
                raise BadParameterError(
                    "options", options, f"none, or the ones {spec.key!r} was created with"
                )
            return existing
        return self._add_joint(spec)

    def sensor(self, sensor: str, **options: Any) -> MujocoSensor:
        """The sensor device of the MuJoCo sensor ``sensor`` (created on first use)."""
        spec = _spec(SensorSpec, sensor=sensor, **options)
        existing = self._sensors.get(spec.key) or next(
            (s for s in self._sensors.values() if s.spec.sensor == sensor and not options), None
        )
        if existing is not None:
            if options and existing.spec != spec:
                raise BadParameterError(
                    "options", options, f"none, or the ones {spec.key!r} was created with"
                )
            return existing
        return self._add_sensor(spec)

    def _add_joint(self, spec: JointSpec) -> MujocoJoint:
        return MujocoJoint(self, spec)  # the device checks and registers itself

    def _check_new_joint(self, spec: JointSpec) -> None:
        """Before a joint device is built: its name and its joint not mapped yet."""
        if spec.key in self._joints:
            raise BadParameterError("name", spec.key, "a joint name not mapped yet")
        for other in self._joints.values():
            if other.joint == spec.joint:
                raise BadParameterError(
                    "joint", spec.joint, f"a joint not mapped yet (mapped as {other.name!r})"
                )

    def effector(self, actuator: str, **options: Any) -> MujocoEffector:
        """The actuator device of the MuJoCo actuator ``actuator`` when it does not drive one
        hinge/slide joint: adhesion, tendon, site ... (created on first use; ``options`` are
        EffectorSpec fields and only allowed the first time, or when they match)."""
        spec = _spec(EffectorSpec, actuator=actuator, **options)
        existing = self._effectors.get(spec.key) or next(
            (e for e in self._effectors.values() if e.actuator == actuator and not options), None
        )
        if existing is not None:
            if options and existing.spec != spec:
                raise BadParameterError(
                    "options", options, f"none, or the ones {spec.key!r} was created with"
                )
            return existing
        return self._add_effector(spec)

    def _add_effector(self, spec: EffectorSpec) -> MujocoEffector:
        return MujocoEffector(self, spec)  # the device checks and registers itself

    def _check_new_effector(self, spec: EffectorSpec) -> None:
        if spec.key in self._effectors:
            raise BadParameterError("name", spec.key, "an effector name not mapped yet")
        for other in self._effectors.values():
            if other.actuator == spec.actuator:
                raise BadParameterError(
                    "actuator",
                    spec.actuator,
                    f"an actuator not mapped yet (mapped as {other.name!r})",
                )

    @property
    def effectors(self) -> Mapping[str, MujocoEffector]:
        """The effector devices created so far, by name."""
        return MappingProxyType(self._effectors)

    def _add_sensor(self, spec: SensorSpec) -> MujocoSensor:
        return MujocoSensor(self, spec)  # the device checks and registers itself

    def _check_new_sensor(self, spec: SensorSpec) -> None:
        if spec.key in self._sensors:
            raise BadParameterError("name", spec.key, "a sensor name not mapped yet")

    @property
    def joints(self) -> Mapping[str, MujocoJoint]:
        """The joint devices created so far, by name."""
        return MappingProxyType(self._joints)

    @property
    def sensors(self) -> Mapping[str, MujocoSensor]:
        """The sensor devices created so far, by name."""
        return MappingProxyType(self._sensors)

    # -- time ------------------------------------------------------------------------------
    @property
    def _physics_steps(self) -> int:
        """Physics steps since the last reset: simulated time = this x timestep."""
        return self.steps - self._reset_at

    @property
    def time_ns(self) -> int:
        """Simulated time since the start or the last reset (steps x time step), in ns."""
        return self._physics_steps * self.timestep_ns

    async def sleep(self, seconds: float) -> None:
        """Sleep ``seconds`` on the simulation's clock (simulated seconds in lockstep)."""
        if (
            isinstance(seconds, bool)
            or not isinstance(seconds, int | float)
            or not math.isfinite(seconds)
            or seconds < 0
        ):
            raise BadParameterError("seconds", seconds, "a finite number of seconds >= 0")
        await self.clock.sleep_until(self.clock.now_ns() + round(seconds * 1e9))

    @property
    def lockstep_clock(self) -> LockstepClock | None:
        return self._lockstep

    @property
    def fault(self) -> str | None:
        """Why the simulation stopped (None while healthy)."""
        return self._fault

    @property
    def running(self) -> bool:
        return self._tg is not None

    # -- running ---------------------------------------------------------------------------
    async def __aenter__(self) -> Self:
        if self._tg is not None:
            raise StateError("__aenter__", "running", ["a simulation not running"])
        tg = anyio.create_task_group()
        await tg.__aenter__()
        self._tg = tg
        tg.start_soon(self._run_lockstep if self._lockstep is not None else self._run_realtime)
        self.log.info(
            "simulation_started",
            pacing=self.pacing,
            timestep_ms=self.timestep_ns / 1e6,
            joints=list(self._joints),
            sensors=list(self._sensors),
            effectors=list(self._effectors),
        )
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> bool | None:
        tg, self._tg = self._tg, None
        assert tg is not None
        tg.cancel_scope.cancel()
        try:
            return await tg.__aexit__(exc_type, exc, tb)
        finally:
            self._stop_run_clock()
            self.log.info("simulation_stopped", steps=self.steps, time_s=self.time_ns / 1e9)

    def _wall_ns(self) -> int:
        """Lockstep: real time (perf_counter); realtime: the pacing clock's time."""
        return time.perf_counter_ns() if self._lockstep is not None else self.clock.now_ns()

    def _start_run_clock(self) -> None:
        if self._run_started is None:
            self._run_started = self._wall_ns()

    def _stop_run_clock(self) -> None:
        if self._run_started is not None:
            self._run_wall_ns += self._wall_ns() - self._run_started
            self._run_started = None

    async def _run_lockstep(self) -> None:
        clock = self._lockstep
        assert clock is not None
        loop_ready = getattr(asyncio.get_running_loop(), "_ready", None)
        # without the loop's ready queue to look at, one step per turn of the loop
        most = LOCKSTEP_BATCH if loop_ready is not None else 1
        dt = self.timestep_ns
        step = self._step
        m, d = self.model, self.data
        mj_step = mujoco.mj_step
        w = self._warning_counts
        qpos_bad, qvel_bad, qacc_bad = _BADQPOS, _BADQVEL, _BADQACC
        monitored = self._monitored  # the list itself (attach/detach change it in place)
        plans = DRIVE_PLANS
        try:
            while True:
                await settle()
                if self._pause_count or self._fault is not None:
                    self._stop_run_clock()
                    if self._pause_count or not clock._jump_to_next():
                        await clock._wait_kick()
                    continue
                self._start_run_clock()
                n = 0
                heap = clock._heap
                ok = True  # until a step fails (then the batch ends)
                while True:
                    now = clock._now
                    if self._plain_step:
                        # _step, inline, for a step with no pre-step update, effector or hook
                        try:
                            mj_step(m, d)
                        except Exception as exc:  # MuJoCo errors (e.g. out of arena memory)
                            ok = self._step_failed(exc)
                        else:
                            steps = self.steps = self.steps + 1
                            self._sensor_clock_ns = now
                            if w[qpos_bad] or w[qvel_bad] or w[qacc_bad]:
                                self._on_unstable(self._instability_reason())
                                ok = False
                            elif monitored:
                                if self._monitor_version != plans.version:
                                    self._new_monitor()
                                self._monitor(steps)
                    else:
                        ok = step(now)
                    # LockstepClock._advance, inline: the common step wakes nobody (a due
                    # inline callback, the timer's tick, runs in _wake_due and wakes nobody)
                    now = clock._now = now + dt
                    n += 1
                    if (
                        (heap and heap[0][0] <= now and clock._wake_due(now))
                        or not ok
                        or loop_ready
                        or n >= most
                    ):
                        break
                self._run_steps += n
                if n > self._max_catchup:
                    self._max_catchup = n
        finally:
            self._stop_run_clock()

    async def _run_realtime(self) -> None:
        clock = self.clock
        sleeper = clock.sleeper()
        period = max(1, round(self.timestep_ns / self.realtime_factor))
        record = self._lateness.record
        step = self._step
        last_warning = -_BEHIND_LOG_INTERVAL_NS
        try:
            while True:
                if self._pause_count or self._fault is not None:
                    self._stop_run_clock()
                    await self._changed.wait()
                    continue
                self._start_run_clock()
                anchor = clock.now_ns()
                k = 0  # steps taken since the anchor
                while not self._pause_count and self._fault is None:
                    deadline = anchor + (k + 1) * period
                    await sleeper.sleep_until(deadline)
                    if self._pause_count or self._fault is not None:
                        break
                    now = clock.now_ns()
                    record(now - deadline)
                    due = (now - anchor) // period - k
                    if due > self.max_catchup_steps:
                        dropped = due - self.max_catchup_steps
                        self._dropped += dropped
                        anchor += dropped * period  # simulated time falls behind
                        due = self.max_catchup_steps
                        if now - last_warning >= _BEHIND_LOG_INTERVAL_NS:
                            last_warning = now
                            self.log.warning(
                                "simulation_behind_real_time",
                                dropped_steps=dropped,
                                dropped_total=self._dropped,
                            )
                    if due > self._max_catchup:
                        self._max_catchup = due
                    for _ in range(due):
                        ok = step(anchor + k * period)
                        k += 1
                        self._run_steps += 1
                        if not ok:
                            break
        finally:
            sleeper.close()
            self._stop_run_clock()

    def _step(self, state_clock_ns: int) -> bool:
        """One physics step; ``state_clock_ns`` is the clock time of the state stepped from.

        The lockstep loop runs the same step inline while ``_plain_step`` (no pre-step
        update, no effector, no hook): keep both alike."""
        m, d = self.model, self.data
        if self._pre_step:
            for update in self._pre_step:
                update(state_clock_ns)
        try:
            mujoco.mj_step(m, d)
        except Exception as exc:  # MuJoCo errors (e.g. out of arena memory)
            return self._step_failed(exc)
        self.steps += 1
        self._sensor_clock_ns = state_clock_ns
        w = self._warning_counts
        if w[_BADQPOS] or w[_BADQVEL] or w[_BADQACC]:
            self._on_unstable(self._instability_reason())
            return False
        if self._monitored:
            if self._monitor_version != DRIVE_PLANS.version:
                self._new_monitor()
            self._monitor(self.steps)
        if self._monitored_effectors:
            n = self.steps
            for effector in self._monitored_effectors:
                effector._monitor(n)
        if self._hooks:
            for hook in self._hooks:
                try:
                    hook()
                except Exception:  # a broken hook must not stop the physics
                    self.log.exception("step_hook_failed", hook=repr(hook))
                    self._hooks = [h for h in self._hooks if h != hook]
                    self._refresh_plain_step()
        return True

    def _step_failed(self, exc: Exception) -> bool:
        """``mj_step`` raised: the step counts, the simulation is faulted."""
        self.steps += 1
        self._on_unstable(f"mj_step failed at t={self.time_ns / 1e9:.4f} s: {exc}")
        return False

    def _new_monitor(self) -> None:
        self._monitor_version = DRIVE_PLANS.version
        self._monitor = monitor_plan(
            self._monitored, self._qpos_items, self._qvel_items, self._force_items
        )

    def _refresh_plain_step(self) -> None:
        """Whether a physics step needs no more than the joints' monitor (the lockstep loop
        then runs it inline)."""
        self._plain_step = not (self._pre_step or self._monitored_effectors or self._hooks)

    def step(self, n: int = 1) -> int:
        """Step the physics ``n`` times synchronously, outside ``async with`` (offline use,
        tests); returns the steps taken (fewer if the simulation faulted)."""
        if isinstance(n, bool) or not isinstance(n, int) or n < 0:
            raise BadParameterError("n", n, "an int >= 0")
        if self._tg is not None:
            raise StateError("step", "running", ["a simulation outside 'async with sim'"])
        done = 0
        for _ in range(n):
            if self._fault is not None:
                break
            if self._lockstep is not None:
                ok = self._step(self._lockstep._now)
                self._lockstep._advance(self.timestep_ns)
            else:
                ok = self._step(self.clock.now_ns())
            done += 1
            if not ok:
                break
        return done

    # -- pause and rendering ---------------------------------------------------------------
    @asynccontextmanager
    async def paused(self) -> AsyncIterator[None]:
        """Stop the physics for the duration of the block (lockstep: simulated time stops)."""
        self._pause_count += 1
        self._notify_changed()
        try:
            yield
        finally:
            self._pause_count -= 1
            self._notify_changed()

    async def render_snapshot(
        self,
        path: str | os.PathLike[str],
        *,
        width: int = 640,
        height: int = 480,
        camera: str | int | None = None,
    ) -> pathlib.Path | None:
        """Render the current state to a PNG in a renderer process (``render.SnapshotRenderer``).

        The state is captured at the call (``ValueError`` for a bad camera or size, at once);
        the event loop keeps running while the worker renders.  Lockstep: the simulation is
        paused meanwhile, so the run stays deterministic; realtime: the physics goes on.  While
        the simulation runs, one renderer process serves its snapshots (started by the first
        one, killed when ``async with sim`` ends); outside it, each call starts its own.
        Returns None without GL.  Bounded (``TimeoutError`` after
        ``render.DEFAULT_TIMEOUT_S``, the worker is then killed, as on cancellation);
        ``render.RenderWorkerError`` if the worker fails.
        """
        request = render.SnapshotRequest.capture(
            self.model, self.data, path, width=width, height=height, camera=camera
        )
        if self._lockstep is None:
            return await render.render_in_worker(request, task_group=self._tg)
        async with self.paused():
            return await render.render_in_worker(request, task_group=self._tg)

    # -- faults and reset ------------------------------------------------------------------
    def _instability_reason(self) -> str:
        for warning_id, stat in zip(_UNSTABLE, self._warnings, strict=True):
            if stat.number:
                info = int(stat.lastinfo)
                # "Nan, Inf or huge value in QVEL at DOF 1. The simulation is unstable."
                text = mujoco.mju_warningText(warning_id, info).split(". ")[0].strip().rstrip(".")
                where = ""
                if warning_id != mujoco.mjtWarning.mjWARN_BADQPOS and 0 <= info < self.model.nv:
                    jid = int(self.model.dof_jntid[info])
                    joint = mujoco.mj_id2name(self.model, mujoco.mjtObj.mjOBJ_JOINT, jid)
                    where = f" (joint {joint!r})" if joint else ""
                return (
                    f"simulation unstable at t={self.time_ns / 1e9:.4f} s: {text}{where}; "
                    "stepping stopped, re_init resets the simulation to its initial state"
                )
        return f"simulation unstable at t={self.time_ns / 1e9:.4f} s"

    def _on_unstable(self, reason: str) -> None:
        self._fault = reason
        self.log.error("simulation_fault", reason=reason)
        for joint in self._monitored:
            joint._clear_pending()
        for device, _ in list(self._attached.values()):
            device._fault(reason)
        self._notify_changed()

    def reset(self) -> None:
        """Reset to the initial state (keyframe or qpos0, initial control modes); clears a fault.

        Components already in Error stay there until their own ``re_init``.
        """
        was = self._fault
        self._reset_data()
        self._reset_at = self.steps
        self._sensor_clock_ns = self.clock.now_ns()
        for joint in self._joints.values():
            joint._on_sim_reset()
        for effector in self._effectors.values():
            effector._on_sim_reset()
        self._fault = None
        self.resets += 1
        self.log.info("simulation_reset", after_fault=was is not None)
        self._notify_changed()

    def _reset_data(self) -> None:
        m, d = self.model, self.data
        m.opt.disableactuator = self._initial_disableactuator
        if self._key_id is not None:
            mujoco.mj_resetDataKeyframe(m, d, self._key_id)
        else:
            mujoco.mj_resetData(m, d)
        mujoco.mj_forward(m, d)
        self._sensor_values = None

    def _recover(self) -> None:
        """Device reset (re_init): reset the simulation if it is faulted."""
        if self._fault is not None:
            self.reset()

    def _check_running_state(self) -> None:
        if self._fault is not None:
            raise HALError(f"{self.name}: the simulation is faulted ({self._fault}); reset it")

    def _notify_changed(self) -> None:
        self._changed.set()
        self._changed = anyio.Event()
        if self._lockstep is not None:
            self._lockstep.kick()

    def _sensordata_tuple(self) -> tuple[float, ...]:
        """``sensordata`` as a tuple, converted once per physics step for all sensor reads
        (slices of a tuple are the readings' value tuples, with no further copy)."""
        values = self._sensor_values
        if values is None or self._sensor_step != self.steps:
            values = self._sensor_values = tuple(self._sensordata.tolist())
            self._sensor_step = self.steps
        return values

    # -- bookkeeping used by the devices -----------------------------------------------------
    def _attach(self, device: _Device, ctx: DeviceContext) -> bool:
        """Register the component of a device; False if the device already has one."""
        if id(device) in self._attached:
            return False
        self._attached[id(device)] = (device, ctx)
        DRIVE_PLANS.version += 1
        if isinstance(device, MujocoJoint) and device not in self._monitored:
            self._monitored.append(device)
        if isinstance(device, MujocoEffector) and device not in self._monitored_effectors:
            self._monitored_effectors.append(device)
        self._refresh_plain_step()
        return True

    def _detach(self, device: _Device) -> None:
        self._attached.pop(id(device), None)
        DRIVE_PLANS.version += 1
        if isinstance(device, MujocoJoint) and device in self._monitored:
            self._monitored.remove(device)
        if isinstance(device, MujocoEffector) and device in self._monitored_effectors:
            self._monitored_effectors.remove(device)
        self._refresh_plain_step()

    def _set_pd(self, joint: MujocoJoint, active: bool) -> None:
        self._pd_joints = _updated(self._pd_joints, joint, active)
        self._rebuild_pre_step()

    def _set_ramp(self, joint: MujocoJoint, active: bool) -> None:
        self._ramp_joints = _updated(self._ramp_joints, joint, active)
        self._rebuild_pre_step()

    def _rebuild_pre_step(self) -> None:
        # a new list each time: a ramp that ends inside the loop over the old one is safe
        updates: list[Callable[[int], None]] = [j._ramp_update for j in self._ramp_joints]
        self._pre_step = updates + [j._pd_update for j in self._pd_joints]
        self._refresh_plain_step()

    def _joint_inertia(self, dof: int) -> float:
        """Diagonal of the joint-space inertia (with armature) at the current state."""
        nv = int(self.model.nv)
        full = np.zeros((nv, nv))
        mujoco.mj_fullM(self.model, self.data, full)
        return max(float(full[dof, dof]), 1e-9)

    # -- hooks and stats -------------------------------------------------------------------
    def add_step_hook(self, hook: Callable[[], None]) -> None:
        """Call ``hook()`` after every physics step (synchronous; keep it short).

        A hook that raises is logged and removed; the physics goes on.
        """
        if not callable(hook):
            raise BadParameterError("hook", hook, "a callable taking no arguments")
        self._hooks = [*self._hooks, hook]
        self._refresh_plain_step()

    def remove_step_hook(self, hook: Callable[[], None]) -> None:
        self._hooks = [h for h in self._hooks if h != hook]
        self._refresh_plain_step()

    @property
    def stats(self) -> PacingStats:
        wall = self._run_wall_ns
        if self._run_started is not None:
            wall += self._wall_ns() - self._run_started
        sim_s = self._run_steps * self.timestep_ns / 1e9
        return PacingStats(
            pacing=self.pacing,
            steps=self._run_steps,
            sim_time_s=sim_s,
            wall_time_s=wall / 1e9,
            realtime_factor=sim_s / (wall / 1e9) if wall else 0.0,
            lateness=self._lateness.summary() if self._lockstep is None else None,
            max_catchup=self._max_catchup,
            dropped_steps=self._dropped,
            clock_ns=self.clock.now_ns(),
        )

    def reset_stats(self) -> None:
        self._lateness.reset()
        self._run_steps = 0
        self._run_wall_ns = 0
        if self._run_started is not None:
            self._run_started = self._wall_ns()
        self._max_catchup = 0
        self._dropped = 0

    def __repr__(self) -> str:
        state = "faulted" if self._fault else ("running" if self._tg else "stopped")
        return (
            f"MujocoSim({self.name!r}, pacing={self.pacing}, t={self.time_ns / 1e9:.3f} s, {state})"
        )


def _spec(cls: type[_SpecT], **values: Any) -> _SpecT:
    """A JointSpec/SensorSpec from keyword options; unknown options name themselves."""
    known = {f.name for f in dataclasses.fields(cls)}
    for key, value in values.items():
        if key not in known:
            raise BadParameterError(
                key, value, f"a {cls.__name__} field ({', '.join(sorted(known))})"
            )
    return cls(**values)


def _updated(joints: list[MujocoJoint], joint: MujocoJoint, member: bool) -> list[MujocoJoint]:
    """``joints`` with ``joint`` added (member) or removed, as a new list."""
    others = [j for j in joints if j is not joint]
    return [*others, joint] if member else others


def _model_name(model: mujoco.MjModel) -> str:
    raw = bytes(model.names).split(b"\0", 1)[0]
    return raw.decode("utf-8", "replace") or "model"
