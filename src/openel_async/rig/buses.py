"""Bus kinds: how a driver opens the buses a rig file names, and how it simulates them.

A driver registers its bus kinds in :attr:`openel_async.registry.DriverInfo.buses` under the
``type`` a rig file writes (``can``, ``serial``)::

    buses:
      can0: {type: can, interface: socketcan, channel: can0, bitrate: 1000000}

The framework reads the entry's other keys with the kind's :attr:`BusKind.options_type` (a
``msgspec.Struct`` with ``forbid_unknown_fields=True``: an unknown key is refused with its
position), opens the bus with :meth:`BusKind.open` (one bus object, shared by every device
that names it), and builds each device on it with the keyword arguments
:meth:`BusKind.device_arguments` returns. With ``--sim``, :meth:`BusKind.simulate` starts
simulated peers that speak the bus's protocol at the devices' addresses (a python-can
``virtual`` channel, a pseudo-terminal) and returns the options to open instead: the whole
driver stack then runs as on the machine.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from contextlib import AbstractAsyncContextManager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, Protocol, runtime_checkable

import msgspec

if TYPE_CHECKING:
    from ..clock import Clock
    from ..params import ParameterAccess
    from ..timer import EventTimer

__all__ = ["BusKind", "BusLoad", "FaultInjection", "SimulatedBus", "SimulatedDevice"]


@dataclass(frozen=True)
class SimulatedDevice:
    """A device of the rig on the bus being simulated: what a peer must answer as."""

    name: str
    """The component's name in the rig."""
    driver: str
    device: str
    """The device class's name in its driver (``odrive_axis``, ``dynamixel``)."""
    params: Mapping[str, Any]
    """The entry's ``params`` as written (addresses: ``node_id``, ``dxl_id``...)."""
    rig_dir: Path | None = None
    """The directory of the rig file (None: a rig given as plain data); a driver takes the
    file paths of ``params`` relative to it."""


@dataclass
class SimulatedBus:
    """What :meth:`BusKind.simulate` yields: the options to open instead of the rig's, and
    the simulated peers."""

    options: Any
    """An instance of the kind's ``options_type``, e.g. a ``virtual`` channel or a pty path."""
    description: str
    """One line for ``rig show --sim`` and the run's banner."""
    peers: Mapping[str, object] = field(default_factory=dict)
    """The simulated peer of each device, by component name (several components may share
    one peer: an ODrive's axis and its encoder)."""


@dataclass(frozen=True)
class BusLoad:
    """What a bus carries, computed (worst case) from its bit rate and its traffic: what
    :meth:`BusKind.load` returns; ``rig check`` reports it and refuses a bus above 100 %."""

    fraction: float
    """The share of the bus's time the traffic takes (1.0 = the bus is full)."""
    detail: str
    """What was counted, in words (``4 axes in CSP: 4 RPDO + 4 TPDO + SYNC every 2 ms``)."""
    advice: str = ""
    """What fits, said when it does not (``at most 3 such axes every 2 ms, or 4 every 3 ms``)."""
    cycle_s: float | None = None
    """The cycle the traffic was counted for (the rig's timer driving the bus), if any."""


@runtime_checkable
class FaultInjection(Protocol):
    """A simulated peer that can trip on demand (a demo's ``--inject-fault``)."""

    def inject_fault(self, reason: str) -> None:
        """Trip as the real device does on a fault (over-temperature, say): the driver on
        the host must see it through the protocol."""


class BusKind(ABC):
    """One kind of bus a driver opens (see the module docstring)."""

    options_type: ClassVar[type[msgspec.Struct]]
    """The keys of a bus entry besides ``type`` (strict: ``forbid_unknown_fields=True``)."""

    def check(self, options: Any, devices: Sequence[SimulatedDevice]) -> None:
        """Refuse (BadParameterError naming the key) what the schema cannot express: two
        devices at one address, an address the protocol cannot carry, a device class that
        cannot be on this bus. Called by ``rig check``; opens nothing."""
        return None

    def load(
        self,
        options: Any,
        devices: Sequence[SimulatedDevice],
        cyclic: Sequence[SimulatedDevice],
        cycle_s: float | None,
    ) -> BusLoad | None:
        """The bus load of ``devices`` (``cyclic`` of them streamed a set-point every
        ``cycle_s``, the period of the rig's fastest timer driving them; None when no timer
        drives the bus), or None when the kind has no notion of it (a serial port's own
        exchanges, a simulation). Called by ``rig check`` after :meth:`check`."""
        return None

    def resolve_paths(self, options: Any, base: Path) -> Any:
        """``options`` with the relative file paths they name (a calibration file, a model)
        made relative to ``base``, the directory of the rig file they come from, so that
        the files are found from any current directory. The default: ``options`` as they
        are (no file paths)."""
        return options

    def bind_timer(
        self, bus: object, options: Any, timer: EventTimer
    ) -> AbstractAsyncContextManager[object] | None:
        """Tie the opened ``bus`` to ``timer``, the rig's timer driving it (the timer of
        the groups whose axes are on it, the fastest if several, else the rig's fastest
        timer: the cycle :meth:`load` was given). A bus that produces something on every
        tick (a CAN bus's SYNC) returns a context manager: the rig enters it once its
        timers exist, before its groups are made (nothing ticks yet), and exits it
        before the timers stop. None (the default): nothing to bind."""
        return None

    def clock(self, bus: object) -> Clock | None:
        """The clock of a bus that is a simulation of its own (a MuJoCo model steps its own
        time): the rig's components and timers use it unless the caller gives one. None
        (the default): the bus follows the caller's clock."""
        return None

    def parameter_access(
        self, bus: object, options: Any, device: SimulatedDevice
    ) -> ParameterAccess | None:
        """The parameters of ``device`` on the opened ``bus`` (``openel-async param``): its
        table (an EDS, an endpoint list, a control table) and a way to read and write it
        that sends nothing until asked and never enables or moves anything. The device's
        component is not built nor entered. None (the default): none the driver knows."""
        return None

    @abstractmethod
    def describe(self, options: Any) -> str:
        """One line saying what :meth:`open` would open (``rig show``)."""

    @abstractmethod
    def open(self, name: str, options: Any) -> AbstractAsyncContextManager[object]:
        """Open the bus (entering the context) and close it at exit; yields the bus object
        the devices share."""

    @abstractmethod
    def device_arguments(
        self, bus: object, options: Any, device: SimulatedDevice
    ) -> Mapping[str, Any]:
        """The keyword arguments that put ``device`` on ``bus`` (e.g. ``{"bus": bus}``),
        added to the entry's ``params``; a params key of the same name is refused."""

    @abstractmethod
    def simulate(
        self, name: str, options: Any, devices: Sequence[SimulatedDevice]
    ) -> AbstractAsyncContextManager[SimulatedBus]:
        """Start simulated peers for ``devices`` at their addresses, speaking the bus's
        protocol; yields what to open instead. Peers stop at exit."""
