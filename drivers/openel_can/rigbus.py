"""The ``can`` bus kind of rig files: a python-can bus shared by the ODrive and CiA 402 devices
that name it, and its simulation for ``--sim``.

```yaml
buses:
  can0: {type: can, interface: socketcan, channel: can0, bitrate: 1000000}
  bench: {type: can, interface: slcan, channel: /dev/ttyACM0, bitrate: 1000000, sleep_after_open: 0.1}
```

With ``--sim`` the bus is a fresh python-can ``virtual`` channel and every node of the rig is a
simulated peer (:class:`~openel_can.sim.odrive.SimODrive`,
:class:`~openel_can.sim.cia402.SimCia402Drive`) at its node id, served on a thread of its own:
it keeps running -- its watchdog too -- while the host's event loop is blocked, as a drive
does.
"""

from __future__ import annotations

import uuid
from collections.abc import AsyncIterator, Iterator, Mapping, Sequence
from contextlib import AbstractAsyncContextManager, asynccontextmanager, contextmanager
from typing import Any

import anyio
import can
import msgspec

from openel_async.errors import BadParameterError
from openel_async.rig import BusKind, SimulatedBus, SimulatedDevice

from . import canopen as co
from . import cansimple as cs
from .bus import CanBus
from .drive402 import DEFAULT_HOST_NODE_ID

__all__ = ["CanBusKind", "CanBusOptions"]

ODRIVE_DEVICES = frozenset(
    {"odrive_axis", "odrive_encoder", "odrive_temperature", "odrive_bus_monitor"}
)
CIA402_DEVICES = frozenset({"cia402_drive", "cia402_temperature"})


class CanBusOptions(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """A CAN bus through python-can."""

    interface: str
    """A python-can interface: socketcan, slcan (CANable, USBtin), gs_usb (candleLight), pcan,
    kvaser, vector, virtual..."""
    channel: str | int | None = None
    """The interface's channel: can0 (socketcan), /dev/ttyACM0 (slcan), PCAN_USBBUS1 (pcan),
    0 (kvaser, gs_usb)."""
    bitrate: int | None = None
    """Bits per second (every node on the bus uses the same); socketcan takes it from
    'ip link' instead."""
    fd: bool = False
    """CAN FD frames."""
    data_bitrate: int | None = None
    """The FD data phase's bits per second (with fd only)."""
    sleep_after_open: float | None = None
    """slcan: seconds to wait after opening the serial port (python-can's default is 2)."""
    send_timeout: float = 0.2
    """Seconds a frame may wait for room in the adapter before the send fails."""
    options: dict[str, Any] = msgspec.field(default_factory=dict)
    """Other keyword arguments of the python-can interface (e.g. receive_own_messages)."""


def _node_ids(devices: Sequence[SimulatedDevice]) -> tuple[dict[int, str], dict[int, str]]:
    """The ODrive and CiA 402 nodes of the devices: node id -> the first component's name."""
    odrives: dict[int, str] = {}
    drives: dict[int, str] = {}
    for d in devices:
        node = d.params.get("node_id")
        if not isinstance(node, int) or isinstance(node, bool):
            raise BadParameterError(f"{d.name}.params.node_id", node, "a node id (an integer)")
        if d.device in ODRIVE_DEVICES:
            if not 0 <= node <= cs.MAX_NODE_ID:
                raise BadParameterError(
                    f"{d.name}.params.node_id", node, f"an ODrive node id in 0..{cs.MAX_NODE_ID}"
                )
            odrives.setdefault(node, d.name)
        elif d.device in CIA402_DEVICES:
            if not 1 <= node <= co.MAX_NODE_ID:
                raise BadParameterError(
                    f"{d.name}.params.node_id", node, f"a CANopen node id in 1..{co.MAX_NODE_ID}"
                )
            drives.setdefault(node, d.name)
        else:
            raise BadParameterError(
                f"{d.name}.device",
                d.device,
                f"a CAN device ({sorted(ODRIVE_DEVICES | CIA402_DEVICES)})",
            )
    return odrives, drives


def _canopen_ids(node: int) -> set[int]:
    return {
        co.EMCY_BASE + node,
        *(base + node for base in co.TPDO_BASES),
        *(base + node for base in co.RPDO_BASES),
        co.SDO_TX_BASE + node,
        co.SDO_RX_BASE + node,
        co.HEARTBEAT_BASE + node,
    }


def _claim(used: dict[int, str], ids: set[int], name: str, owner: str, node: int) -> None:
    """Take ``ids`` for ``owner``; BadParameterError on ``name``'s node id when one is taken
    by another device."""
    for cob_id in sorted(ids):
        other = used.setdefault(cob_id, owner)
        if other != owner:
            raise BadParameterError(
                f"{name}.params.node_id",
                node,
                f"a node whose CAN ids are free ({cob_id:#x} is {other}'s)",
            )


class CanBusKind(BusKind):
    """``type: can`` (see the module docstring)."""

    options_type = CanBusOptions

    def check(self, options: Any, devices: Sequence[SimulatedDevice]) -> None:
        assert isinstance(options, CanBusOptions)
        if options.interface not in can.interfaces.VALID_INTERFACES:
            raise BadParameterError(
                "interface", options.interface,
                f"a python-can interface: {', '.join(sorted(can.interfaces.VALID_INTERFACES))}",
            )  # fmt: skip
        for key in ("bitrate", "data_bitrate"):
            value = getattr(options, key)
            if value is not None and value <= 0:
                raise BadParameterError(key, value, "bits per second > 0")
        if options.data_bitrate is not None and not options.fd:
            raise BadParameterError("data_bitrate", options.data_bitrate, "only with fd: true")
        if options.sleep_after_open is not None and options.interface != "slcan":
            raise BadParameterError(
                "sleep_after_open", options.sleep_after_open, "only with interface: slcan"
            )
        odrives, drives = _node_ids(devices)
        # Arbitration ids in use: an ODrive node takes node << 5 | 0..31, a CANopen node its
        # EMCY, PDO, SDO and heartbeat ids (and the host its heartbeat 0x77F).
        used: dict[int, str] = {co.NMT_COB_ID: "NMT", co.SYNC_COB_ID: "SYNC"}
        if drives:
            used[co.HEARTBEAT_BASE + DEFAULT_HOST_NODE_ID] = "the host's heartbeat"
        for node, name in sorted(drives.items()):
            _claim(used, _canopen_ids(node), name, f"{name} (CANopen node {node})", node)
        for node, name in sorted(odrives.items()):
            _claim(
                used,
                {node << 5 | cmd for cmd in range(32)},
                name,
                f"{name} (ODrive node {node})",
                node,
            )

    def describe(self, options: Any) -> str:
        assert isinstance(options, CanBusOptions)
        rate = ""
        if options.bitrate is not None:
            rate = (
                f" at {options.bitrate / 1e6:g} Mbit/s"
                if options.bitrate >= 1_000_000
                else f" at {options.bitrate / 1e3:g} kbit/s"
            )
        fd = " (FD)" if options.fd else ""
        channel = "" if options.channel is None else f" {options.channel}"
        return f"CAN {options.interface}{channel}{rate}{fd}"

    def open(self, name: str, options: Any) -> AbstractAsyncContextManager[object]:
        assert isinstance(options, CanBusOptions)
        kwargs: dict[str, Any] = dict(options.options)
        kwargs["interface"] = options.interface
        if options.channel is not None:
            kwargs["channel"] = options.channel
        if options.bitrate is not None:
            kwargs["bitrate"] = options.bitrate
        if options.fd:
            kwargs["fd"] = True
        if options.data_bitrate is not None:
            kwargs["data_bitrate"] = options.data_bitrate
        if options.sleep_after_open is not None:
            kwargs["sleep_after_open"] = options.sleep_after_open
        return CanBus(name=name, send_timeout=options.send_timeout, **kwargs)

    def device_arguments(
        self, bus: object, options: Any, device: SimulatedDevice
    ) -> Mapping[str, Any]:
        return {"bus": bus}

    def simulate(
        self, name: str, options: Any, devices: Sequence[SimulatedDevice]
    ) -> AbstractAsyncContextManager[SimulatedBus]:
        return _simulated(name, devices)


@asynccontextmanager
async def _simulated(name: str, devices: Sequence[SimulatedDevice]) -> AsyncIterator[SimulatedBus]:
    from .sim.cia402 import SimCia402Drive
    from .sim.odrive import SimODrive

    odrives, drives = _node_ids(devices)
    peers: dict[int, Any] = {}
    by_name: dict[str, object] = {}
    for node in odrives:
        peers[node] = SimODrive(node, traj_vel_limit=2.0, traj_accel_limit=20.0)
    cia402 = {node: SimCia402Drive(node) for node in drives}
    for d in devices:
        node = d.params["node_id"]
        by_name[d.name] = peers[node] if d.device in ODRIVE_DEVICES else cia402[node]
    channel = f"openel-sim-{name}-{uuid.uuid4().hex[:8]}"
    everyone = [*peers.values(), *cia402.values()]
    cm = _on_thread(everyone, channel)
    await anyio.to_thread.run_sync(cm.__enter__)
    try:
        shown = [f"ODrive node {n}" for n in sorted(odrives)] + [
            f"CiA 402 node {n}" for n in sorted(drives)
        ]
        yield SimulatedBus(
            CanBusOptions(interface="virtual", channel=channel),
            f"python-can virtual channel {channel} with simulated {', '.join(shown) or 'no node'}",
            by_name,
        )
    finally:
        with anyio.CancelScope(shield=True):
            await anyio.to_thread.run_sync(cm.__exit__, None, None, None)


@contextmanager
def _on_thread(peers: Sequence[Any], channel: str) -> Iterator[None]:
    from .sim.faults import peers_on_thread

    with peers_on_thread(peers, channel):
        yield
