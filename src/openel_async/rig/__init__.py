"""Rig files: the whole machine -- buses, components, timers, axis groups and safety -- in one
strict YAML file, opened for real or with ``sim=True`` (``--sim``) against simulated peers
that speak the same protocols at the same addresses (docs/hardware.md).

- :func:`load_rig` / :func:`parse_rig`: read a rig (unknown keys refused with file, line and
  column); :func:`resolve_rig`: check it against the installed drivers, opening nothing
  (``openel-async rig check``);
- :func:`open_rig`: open it (an async context manager yielding a :class:`Rig`); at exit
  every actuator is left in the state ``safety.on_exit`` names;
- :class:`BusKind`: what a driver registers to open (and simulate) a kind of bus.
"""

from .build import ResolvedBus, ResolvedRig, build_components, resolve_rig
from .buses import BusKind, BusLoad, FaultInjection, SimulatedBus, SimulatedDevice
from .runtime import Rig, SafeStopReport, open_rig
from .spec import (
    BusSpec,
    ComponentSpec,
    GroupSpec,
    JointLimits,
    RigSpec,
    SafetySpec,
    TimerSpec,
    json_schema,
    load_rig,
    parse_rig,
)

__all__ = [
    "BusKind",
    "BusLoad",
    "BusSpec",
    "ComponentSpec",
    "FaultInjection",
    "GroupSpec",
    "JointLimits",
    "ResolvedBus",
    "ResolvedRig",
    "Rig",
    "RigSpec",
    "SafeStopReport",
    "SafetySpec",
    "SimulatedBus",
    "SimulatedDevice",
    "TimerSpec",
    "build_components",
    "json_schema",
    "load_rig",
    "open_rig",
    "parse_rig",
    "resolve_rig",
]
