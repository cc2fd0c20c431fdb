"""The ``mujoco`` bus kind: a MuJoCo simulation as a bus of a rig file.

A MuJoCo model is the bus; its joints, effectors and sensors are the components on it::

    buses:
      arm2: {type: mujoco, model: arm2, pacing: realtime}
    components:
      - {name: shoulder, driver: mujoco, device: joint, bus: arm2}     # the joint 'shoulder'
      - {name: grip, driver: mujoco, device: effector, bus: arm2, params: {actuator: suction}}
      - {name: tip_pos, driver: mujoco, device: sensor, bus: arm2}

Opening the bus builds a :class:`~openel_mujoco.MujocoSim` from the options and runs it
(``async with sim``) while the rig is open; the devices get it as their ``sim`` argument and
the component's name as their ``name``. A component's ``params`` are the fields of its spec
(:class:`~openel_mujoco.JointSpec`, :class:`~openel_mujoco.SensorSpec`,
:class:`~openel_mujoco.EffectorSpec`); the model element (``joint``, ``sensor``,
``actuator``) defaults to the component's name. The rig's components and timers run on the
simulation's clock (:meth:`MujocoBusKind.clock`): the simulation time in lockstep.

``rig check`` loads the model and builds every device on a simulation that never runs: a
joint, sensor or actuator the model lacks, a spec field misspelt, two components on one
joint are refused before anything opens. ``--sim`` changes nothing: the bus is a simulation
already.

An app that needs the model before the rig opens (to plan, to take a snapshot of the
initial state) builds the simulation itself from the bus's options (:func:`mujoco_buses`,
:meth:`MujocoBusOptions.sim_arguments`) and opens the rig on it
(:func:`with_simulation`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import AsyncIterator, Mapping, Sequence
from contextlib import AbstractAsyncContextManager, asynccontextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal

import msgspec

from openel_async.errors import BadParameterError
from openel_async.rig import BusKind, ResolvedRig, SimulatedBus, SimulatedDevice

from .models import SHIPPED_MODELS, ModelLoadError, load_model
from .sim import MujocoSim

if TYPE_CHECKING:
    from openel_async.clock import Clock

__all__ = [
    "AttachedSimulation",
    "MujocoBusKind",
    "MujocoBusOptions",
    "mujoco_buses",
    "with_simulation",
]


class MujocoBusOptions(msgspec.Struct, forbid_unknown_fields=True, kw_only=True, frozen=True):
    """A MuJoCo simulation as a bus (the keys of a ``type: mujoco`` bus entry)."""

    model: str
    """A shipped model (``arm2``, ``arm6``, ``so101``) or the path of an MJCF or MJB file
    (relative to the rig file's directory; in a rig given as plain data, to the current
    directory)."""
    pacing: Literal["lockstep", "realtime"] = "lockstep"
    """``lockstep``: the simulation is the clock, as fast as the CPU allows and
    deterministic; ``realtime``: stepped against the real clock."""
    keyframe: str | None = None
    """The model's keyframe giving the initial (and reset) state (default: its qpos0)."""
    timestep: Annotated[float, msgspec.Meta(gt=0)] | None = None
    """The physics step in seconds (default: the model's ``opt.timestep``)."""
    realtime_factor: Annotated[float, msgspec.Meta(gt=0)] = 1.0
    """``realtime``: simulated seconds per real second."""
    max_catchup_steps: Annotated[int, msgspec.Meta(ge=1)] = 50
    """``realtime``: most physics steps taken at once when late (the excess is dropped)."""
    name: str | None = None
    """The simulation's name in logs (default: the model's)."""

    def sim_arguments(self) -> dict[str, Any]:
        """The keyword arguments of :class:`~openel_mujoco.MujocoSim` besides ``model`` and
        ``pacing``, only those given (``MujocoSim(o.model, pacing=o.pacing,
        **o.sim_arguments())``)."""
        defaults = MujocoBusOptions(model=self.model)
        return {
            key: getattr(self, key)
            for key in ("keyframe", "timestep", "realtime_factor", "max_catchup_steps", "name")
            if getattr(self, key) != getattr(defaults, key)
        }

    def build(self) -> MujocoSim:
        """The simulation of these options (not running); ModelLoadError for a model that
        cannot load, BadParameterError for a bad option (an unknown keyframe...)."""
        return MujocoSim(self.model, pacing=self.pacing, **self.sim_arguments())


@dataclasses.dataclass(frozen=True)
class AttachedSimulation:
    """The options of a MuJoCo bus that opens ``sim`` (built by the caller from
    ``options``, see :func:`with_simulation`) instead of a new simulation."""

    options: MujocoBusOptions
    sim: MujocoSim


def _options(options: MujocoBusOptions | AttachedSimulation) -> MujocoBusOptions:
    return options.options if isinstance(options, AttachedSimulation) else options


def describe(options: MujocoBusOptions | AttachedSimulation) -> str:
    """``MuJoCo model arm2 (lockstep)``, ``MuJoCo model arm6, keyframe home (realtime)``."""
    o = _options(options)
    pacing = o.pacing if isinstance(options, MujocoBusOptions) else options.sim.pacing
    keyframe = "" if o.keyframe is None else f", keyframe {o.keyframe}"
    return f"MuJoCo model {o.model}{keyframe} ({pacing})"


class MujocoBusKind(BusKind):
    """The ``mujoco`` bus kind (see the module docstring)."""

    options_type = MujocoBusOptions

    def __init__(self, devices: Mapping[str, type]) -> None:
        self.devices = dict(devices)
        """The driver's device classes by name (what a component's ``device`` names)."""

    def resolve_paths(self, options: Any, base: Path) -> MujocoBusOptions:
        """``options`` with a relative model file path made relative to ``base``, the rig
        file's directory (a name without suffix or folder stays a model's name)."""
        o = _options(options)
        path = Path(o.model).expanduser()
        bare = not path.suffix and len(path.parts) == 1  # a model's name, shipped or not
        if o.model in SHIPPED_MODELS or bare or path.is_absolute():
            return o
        return msgspec.structs.replace(o, model=str(base / path))

    def check(self, options: Any, devices: Sequence[SimulatedDevice]) -> None:
        """Load the model and build every device on a simulation that never runs."""
        o = _options(options)
        try:
            model = load_model(o.model)
        except ModelLoadError as exc:
            raise BadParameterError("model", o.model, f"a model that loads ({exc})") from None
        try:
            sim = MujocoSim(model, pacing=o.pacing, **o.sim_arguments())
        except ModelLoadError as exc:  # the keyframe
            raise BadParameterError(
                "keyframe", o.keyframe, f"a keyframe of model {o.model} ({exc})"
            ) from None
        for device in devices:
            cls = self.devices.get(device.device)
            if cls is None:  # (resolve_rig refuses it first)
                raise BadParameterError(
                    f"{device.name}.device", device.device, f"one of {sorted(self.devices)}"
                )
            for key in ("sim", "name"):
                if key in device.params:
                    raise BadParameterError(
                        f"{device.name}.params",
                        key,
                        f"no {key!r}: the bus gives it (the simulation, the component's name)",
                    )
            try:
                cls(sim, name=device.name, **device.params)
            except (ValueError, TypeError) as exc:  # BadParameterError, ModelLoadError
                raise BadParameterError(
                    f"{device.name}.params",
                    dict(device.params),
                    f"a {device.device} of MuJoCo model {o.model} ({exc})",
                ) from None

    def clock(self, bus: object) -> Clock | None:
        """The simulation's clock (its time, in lockstep)."""
        return bus.clock if isinstance(bus, MujocoSim) else None

    def describe(self, options: Any) -> str:
        return describe(options)

    def open(self, name: str, options: Any) -> AbstractAsyncContextManager[object]:
        return _running(options)

    def device_arguments(
        self, bus: object, options: Any, device: SimulatedDevice
    ) -> Mapping[str, Any]:
        """The simulation (``sim``) and the component's name (``name``: the device's key in
        ``sim.joints``, ``sim.sensors`` or ``sim.effectors``, and its model element by
        default)."""
        return {"sim": bus, "name": device.name}

    def simulate(
        self, name: str, options: Any, devices: Sequence[SimulatedDevice]
    ) -> AbstractAsyncContextManager[SimulatedBus]:
        """The same options: a MuJoCo model is a simulation already (no peers)."""
        return _simulated(options)


@asynccontextmanager
async def _running(options: MujocoBusOptions | AttachedSimulation) -> AsyncIterator[MujocoSim]:
    sim = options.sim if isinstance(options, AttachedSimulation) else options.build()
    async with sim:
        yield sim


@asynccontextmanager
async def _simulated(options: MujocoBusOptions | AttachedSimulation) -> AsyncIterator[SimulatedBus]:
    yield SimulatedBus(options, f"{describe(options)}, a simulation already")


def mujoco_buses(rig: ResolvedRig) -> dict[str, MujocoBusOptions]:
    """The options of each MuJoCo bus of ``rig``, by bus name."""
    return {
        name: _options(bus.options)
        for name, bus in rig.buses.items()
        if isinstance(bus.kind, MujocoBusKind)
    }


def with_simulation(rig: ResolvedRig, sim: MujocoSim, bus: str | None = None) -> ResolvedRig:
    """``rig`` with its MuJoCo bus ``bus`` (default: its only one) opening ``sim`` -- built
    from the bus's options, not running -- instead of a new simulation: an app plans on the
    model and takes a picture of the initial state before the rig opens. The rig runs
    ``sim`` while it is open."""
    buses = mujoco_buses(rig)
    if bus is None:
        if len(buses) != 1:
            raise BadParameterError(
                "bus", None, f"the name of one of the rig's MuJoCo buses ({', '.join(buses)})"
            )
        (bus,) = buses
    if bus not in buses:
        raise BadParameterError("bus", bus, f"a MuJoCo bus of the rig ({', '.join(buses)})")
    if sim.running:
        raise BadParameterError("sim", sim, "a simulation not running yet")
    attached = dataclasses.replace(rig.buses[bus], options=AttachedSimulation(buses[bus], sim))
    return dataclasses.replace(rig, buses={**rig.buses, bus: attached})


def bus_kind() -> MujocoBusKind:
    """The driver's ``mujoco`` bus kind, with its device classes (the driver's registry entry
    builds it on first use)."""
    from . import DEVICES

    return MujocoBusKind(DEVICES)
