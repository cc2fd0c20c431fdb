"""Rig files: the whole machine -- buses, components, timers, axis groups and safety -- in one
strict YAML file, opened for real or with ``--sim`` against simulated peers (docs/hardware.md).
"""

from .buses import BusKind, FaultInjection, SimulatedBus, SimulatedDevice

__all__ = ["BusKind", "FaultInjection", "SimulatedBus", "SimulatedDevice"]
