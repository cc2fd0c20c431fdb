"""One device of a rig, alone: its bus opened (or simulated) for ``openel-async param``,
nothing else. No component is built or entered, so nothing is initialized, enabled or
stopped: the device is left as it was found, whatever it was doing."""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass

from ..errors import BadParameterError
from ..params import ParameterAccess
from ..positioned import did_you_mean
from .build import ResolvedRig
from .buses import SimulatedDevice

__all__ = ["OpenedDevice", "device_of", "open_parameters"]


@dataclass(frozen=True)
class OpenedDevice:
    """What :func:`open_parameters` yields."""

    name: str
    device: SimulatedDevice
    access: ParameterAccess
    bus: str
    """The bus's name in the rig."""
    description: str
    """What was opened (the simulated bus with ``sim=True``)."""


def device_of(resolved: ResolvedRig, name: str) -> tuple[str, SimulatedDevice]:
    """The bus name and the device entry of component ``name``; BadParameterError (with
    the close names) when the rig has no such component or it is on no bus."""
    names = [c.name for c in resolved.spec.components]
    if name not in names:
        raise BadParameterError(
            "component", name, f"a component of the rig ({did_you_mean(name, names)})"
        )
    spec = resolved.spec.component(name)
    if spec.bus is None:
        raise BadParameterError(
            "component",
            name,
            f"a device on a bus ({name} is a {spec.driver} {spec.device} on no bus: it has no "
            "device parameters)",
        )
    bus = resolved.buses[spec.bus]
    device = next(d for d in bus.devices if d.name == name)
    return spec.bus, device


@asynccontextmanager
async def open_parameters(
    resolved: ResolvedRig, name: str, *, sim: bool = False
) -> AsyncIterator[OpenedDevice]:
    """Open the bus of component ``name`` (``sim=True``: against a simulated peer of that
    device alone) and yield the device's :class:`~openel_async.params.ParameterAccess`; the
    bus closes at exit. BadParameterError when the driver offers no parameters for it."""
    bus_name, device = device_of(resolved, name)
    bus = resolved.buses[bus_name]
    async with _bus(bus_name, resolved, device, sim) as (opened, options, description):
        access = bus.kind.parameter_access(opened, options, device)
        if access is None:
            raise BadParameterError(
                "component",
                name,
                f"a device with parameters (driver {device.driver} offers none for "
                f"{device.device})",
            )
        yield OpenedDevice(name, device, access, bus_name, description)


@asynccontextmanager
async def _bus(
    bus_name: str, resolved: ResolvedRig, device: SimulatedDevice, sim: bool
) -> AsyncIterator[tuple[object, object, str]]:
    bus = resolved.buses[bus_name]
    if not sim:
        async with bus.kind.open(bus_name, bus.options) as opened:
            yield opened, bus.options, bus.kind.describe(bus.options)
        return
    async with (
        bus.kind.simulate(bus_name, bus.options, (device,)) as simulated,
        bus.kind.open(bus_name, simulated.options) as opened,
    ):
        yield opened, simulated.options, simulated.description
