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

An ODrive axis's ``endpoints: FILE`` (the ``flat_endpoints.json`` of the firmware it runs; a
relative path is relative to the rig file) is read by ``rig check`` (a file it cannot use is
refused, naming the file and what is wrong); its ids are what the driver writes and what
``openel-async param`` reads and writes for that axis component, and with
``--sim`` the simulated node has the file's ids and reports its firmware version.
"""

from __future__ import annotations

import math
import uuid
from collections.abc import AsyncIterator, Iterator, Mapping, Sequence
from contextlib import AbstractAsyncContextManager, asynccontextmanager, contextmanager
from typing import Any

import anyio
import can
import msgspec

from openel_async.errors import BadParameterError
from openel_async.params import ParameterAccess
from openel_async.rig import BusKind, BusLoad, SimulatedBus, SimulatedDevice
from openel_async.timer import EventTimer

from . import canopen as co
from . import cansimple as cs
from .bus import CanBus
from .busload import Traffic, bus_load, frame_time
from .drive402 import DEFAULT_HOST_NODE_ID
from .layout402 import DriveLayout, drive_file, load_drive_files, plan_layout
from .odrive_firmware import EndpointTable, driver_endpoint_ids, endpoint_table
from .sync import CanSync

__all__ = ["CanBusKind", "CanBusOptions", "SyncOptions"]

ODRIVE_DEVICES = frozenset(
    {"odrive_axis", "odrive_encoder", "odrive_temperature", "odrive_bus_monitor"}
)
CIA402_DEVICES = frozenset({"cia402_drive", "cia402_temperature"})


class SyncOptions(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """The bus produces CANopen SYNC on the rig's timer driving it."""

    counter: int = 0
    """0: SYNC without data; 2..240: the SYNC counter overflow (CiA 301 0x1019, written to
    the cyclic drives too): one byte counting 1..counter."""


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
    sync: SyncOptions | None = None
    """The bus's SYNC producer (``{counter: 0}``): a SYNC on every tick of the rig's timer
    driving the bus (its axis groups' timer; else the rig's fastest timer), after the RPDOs
    the cyclic drives staged for it. None: no SYNC from the rig (an app may start
    ``CanSync.of(bus)`` itself)."""


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


def _odrive_table(devices: Sequence[SimulatedDevice], node: int) -> EndpointTable:
    """The endpoint table of the ODrive at ``node``: its axis's ``endpoints`` file (relative
    to the rig file), else the built-in table; BadParameterError naming
    ``<component>.params.endpoints`` for a file that cannot be used."""
    for d in devices:
        if d.device == "odrive_axis" and d.params.get("node_id") == node:
            value = d.params.get("endpoints")
            if value is None:
                break
            try:
                table = endpoint_table(value, d.rig_dir)
                driver_endpoint_ids(table, d.params)  # the ids the driver writes are in it
                return table
            except BadParameterError as exc:
                raise BadParameterError(
                    f"{d.name}.params.{exc.parameter}", exc.value, exc.allowed
                ) from None
    return endpoint_table(None)


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


CYCLIC_MODES = frozenset({"csp", "csv", "cst"})
"""The ``mode`` params of a CiA 402 drive that stream a set-point every SYNC."""
_FILE_PARAMS = ("eds", "dcf", "pdos")


def _layout(d: SimulatedDevice) -> DriveLayout | None:
    """The PDO maps of a CiA 402 drive that names its files (``eds``, ``dcf``, ``pdos``),
    checked as the driver will (BadParameterError naming ``<component>.params.<key>``)."""
    if d.device != "cia402_drive" or not any(k in d.params for k in _FILE_PARAMS):
        return None
    node = d.params.get("node_id")
    mode = d.params.get("mode", "pp")
    sync = d.params.get("sync", False)
    event_ms = d.params.get("tpdo_event_ms", 10)
    try:
        if mode not in ("pp", *CYCLIC_MODES):
            raise BadParameterError("mode", mode, "one of pp, csp, csv, cst")
        assert isinstance(node, int)
        files = load_drive_files(
            node,
            mode,
            eds=d.params.get("eds"),
            dcf=d.params.get("dcf"),
            pdos=d.params.get("pdos"),
            files_dir=d.rig_dir,
            sync=sync is True,
            tpdo_event_ms=event_ms if isinstance(event_ms, int) else 10,
        )
        return None if files is None else plan_layout(files, node, mode)
    except BadParameterError as exc:
        raise BadParameterError(
            f"{d.name}.params.{exc.parameter}", exc.value, exc.allowed
        ) from None


def _param(d: SimulatedDevice, key: str, default: float) -> float:
    value = d.params.get(key, default)
    return (
        float(value) if isinstance(value, int | float) and not isinstance(value, bool) else default
    )


def _traffic(
    devices: Sequence[SimulatedDevice], cyclic: Sequence[SimulatedDevice], cycle_s: float | None
) -> tuple[list[Traffic], list[Traffic], int]:
    """The periodic frames of the bus's nodes: (background, per-cycle, streamed axes).
    Background: heartbeats, event-driven TPDOs, an ODrive's encoder estimates. Per cycle
    (``cycle_s``): each streamed axis's set-point frame and the TPDOs a SYNC triggers, and
    the SYNC itself."""
    background: list[Traffic] = []
    per_cycle: list[Traffic] = []
    streamed = {d.name for d in cyclic}
    axes = 0
    sync = False
    seen: set[tuple[str, int]] = set()
    for d in devices:
        node = d.params.get("node_id")
        if not isinstance(node, int):
            continue
        if d.device in CIA402_DEVICES:
            if ("cia402", node) not in seen:
                seen.add(("cia402", node))
                heartbeat = _param(d, "heartbeat_ms", 1000) / 1000
                background.append(Traffic(f"heartbeat of node {node}", 1, heartbeat))
            if d.device != "cia402_drive":
                continue
            mode = d.params.get("mode")
            layout = _layout(d)
            if layout is not None:
                sync = (
                    _layout_traffic(
                        layout, node, d.name in streamed, cycle_s, background, per_cycle
                    )
                    or sync
                )
                axes += d.name in streamed and cycle_s is not None
                continue
            if mode in CYCLIC_MODES and cycle_s is not None:
                # Cia402CyclicDrive: TPDO1 after every SYNC, TPDO2 (status, mode) on change only
                sync = True
                per_cycle.append(Traffic(f"TPDO1 of node {node}", 8, cycle_s))
            elif d.params.get("sync") is True and cycle_s is not None:
                sync = True
                per_cycle.append(Traffic(f"TPDO1 of node {node}", 8, cycle_s))
                per_cycle.append(Traffic(f"TPDO2 of node {node}", 5, cycle_s))
            else:
                event = _param(d, "tpdo_event_ms", 10) / 1000
                background.append(Traffic(f"TPDO1 of node {node}", 8, event))
                background.append(Traffic(f"TPDO2 of node {node}", 5, event))
            if d.name in streamed and cycle_s is not None:
                axes += 1
                payload = (
                    4 if mode == "cst" else 6
                )  # controlword + target torque / position, velocity
                per_cycle.append(Traffic(f"RPDO of node {node}", payload, cycle_s))
        elif d.device in ODRIVE_DEVICES:
            if ("odrive", node) not in seen:
                seen.add(("odrive", node))
                background.append(
                    Traffic(f"heartbeat of ODrive {node}", 8, _param(d, "heartbeat_period", 0.1))
                )
                background.append(
                    Traffic(f"encoder of ODrive {node}", 8, _param(d, "encoder_period", 0.01))
                )
            if d.name in streamed and cycle_s is not None:
                axes += 1
                per_cycle.append(Traffic(f"set-point of ODrive {node}", 8, cycle_s))
    if sync and cycle_s is not None:
        per_cycle.append(Traffic("SYNC", 0, cycle_s))
    return background, per_cycle, axes


def _layout_traffic(
    layout: DriveLayout,
    node: int,
    streamed: bool,
    cycle_s: float | None,
    background: list[Traffic],
    per_cycle: list[Traffic],
) -> bool:
    """The frames of a drive's configured PDOs (True when some run on SYNC): synchronous
    TPDOs every ``every`` cycles, event TPDOs at their event timer (on change only: not
    counted), the set-point RPDO of a streamed axis every cycle."""
    on_sync = False
    for tpdo in layout.tpdos.values():
        pdo = tpdo.pdo
        if tpdo.synchronous:
            if cycle_s is not None:
                on_sync = True
                what = f"{pdo.name} of node {node}"
                per_cycle.append(Traffic(what, tpdo.codec.size, cycle_s * pdo.transmission_type))
        elif pdo.event_ms:
            background.append(
                Traffic(f"{pdo.name} of node {node}", tpdo.codec.size, pdo.event_ms / 1000)
            )
    if streamed and cycle_s is not None and layout.rpdo_of_mode:
        rpdo = next(iter(layout.rpdo_of_mode.values()))
        on_sync = on_sync or rpdo.synchronous
        per_cycle.append(Traffic(f"{rpdo.pdo.name} of node {node}", rpdo.codec.size, cycle_s))
    return on_sync


def _ms(seconds: float) -> str:
    return f"{seconds * 1e3:.3g} ms"


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
        if options.sync is not None and not (
            options.sync.counter == 0 or 2 <= options.sync.counter <= 240
        ):
            raise BadParameterError(
                "sync.counter", options.sync.counter, "0 (no counter) or 2..240 (0x1019)"
            )
        if options.sleep_after_open is not None and options.interface != "slcan":
            raise BadParameterError(
                "sleep_after_open", options.sleep_after_open, "only with interface: slcan"
            )
        odrives, drives = _node_ids(devices)
        layouts = {d.params.get("node_id"): layout for d in devices if (layout := _layout(d))}
        # Arbitration ids in use: an ODrive node takes node << 5 | 0..31, a CANopen node its
        # EMCY, PDO, SDO and heartbeat ids (and the host its heartbeat 0x77F).
        used: dict[int, str] = {co.NMT_COB_ID: "NMT", co.SYNC_COB_ID: "SYNC"}
        if drives:
            used[co.HEARTBEAT_BASE + DEFAULT_HOST_NODE_ID] = "the host's heartbeat"
        for node, name in sorted(drives.items()):
            ids = _canopen_ids(node)
            if node in layouts:
                ids |= {p.cob_id for p in layouts[node].pdos if p.spec.enabled}
            _claim(used, ids, name, f"{name} (CANopen node {node})", node)
        for node, name in sorted(odrives.items()):
            _claim(
                used,
                {node << 5 | cmd for cmd in range(32)},
                name,
                f"{name} (ODrive node {node})",
                node,
            )
            _odrive_table(devices, node)  # a named flat_endpoints.json must be usable

    def load(
        self,
        options: Any,
        devices: Sequence[SimulatedDevice],
        cyclic: Sequence[SimulatedDevice],
        cycle_s: float | None,
    ) -> BusLoad | None:
        assert isinstance(options, CanBusOptions)
        if options.sync is not None and cycle_s is None:
            raise BadParameterError(
                "sync",
                msgspec.to_builtins(options.sync),
                "a timer driving the bus: a group of its axes with a timer, or a timer in "
                "the rig's 'timers'",
            )
        if options.bitrate is None or not devices:
            return None
        bitrate, fd, data_bitrate = options.bitrate, options.fd, options.data_bitrate

        def load_of(traffic: Sequence[Traffic]) -> float:
            return bus_load(traffic, bitrate, fd=fd, data_bitrate=data_bitrate)

        def cycle_time_of(traffic: Sequence[Traffic]) -> float:
            return sum(
                t.count * frame_time(t.payload, bitrate, fd=fd, data_bitrate=data_bitrate)
                for t in traffic
            )

        background, per_cycle, axes = _traffic(devices, cyclic, cycle_s)
        if options.sync is not None and cycle_s is not None:  # the rig's SYNC, every cycle
            per_cycle = [t for t in per_cycle if t.what != "SYNC"]
            per_cycle.append(Traffic("SYNC", 1 if options.sync.counter else 0, cycle_s))
        fraction = load_of([*background, *per_cycle])
        rate = self.describe(options).rsplit(" at ", 1)[-1]
        if cycle_s is None or not per_cycle:
            detail = f"{len(background)} periodic frame streams, worst case at {rate}"
            advice = "fewer or slower periodic frames (heartbeat_ms, tpdo_event_ms, encoder_period)"
            return BusLoad(fraction, detail, advice if fraction > 1 else "", cycle_s)
        cycle_time = cycle_time_of(per_cycle)
        detail = (
            f"{axes} axes streamed every {_ms(cycle_s)}: {len(per_cycle)} frames a cycle, "
            f"{cycle_time * 1e6:.0f} us worst case at {rate}, "
            f"{fraction:.0%} with the periodic frames"
        )
        advice = ""
        spare = 1 - load_of(background)
        if fraction > 1 and spare <= 0:
            advice = "fewer or slower periodic frames first: they alone fill the bus"
        elif fraction > 1:
            sync_time = cycle_time_of([t for t in per_cycle if t.what == "SYNC"])
            per_axis = (cycle_time - sync_time) / max(axes, 1)
            fits = max(0, math.floor((spare * cycle_s - sync_time) / per_axis))
            shortest = cycle_time / spare
            advice = (
                f"at most {fits} such axes every {_ms(cycle_s)}, or these {axes} every "
                f"{_ms(math.ceil(shortest * 1e4) / 1e4)} or more (a faster bit rate, or "
                "fewer PDOs per axis)"
            )
        return BusLoad(fraction, detail, advice, cycle_s)

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

    def bind_timer(
        self, bus: object, options: Any, timer: EventTimer
    ) -> AbstractAsyncContextManager[object] | None:
        """With ``sync``: the bus's :class:`~openel_can.sync.CanSync` on ``timer`` (every
        cyclic drive's 0x60C2 and 0x1019 written first), stopped at exit."""
        assert isinstance(options, CanBusOptions)
        if options.sync is None:
            return None
        assert isinstance(bus, CanBus)
        return _sync_on(bus, timer, options.sync.counter)

    def device_arguments(
        self, bus: object, options: Any, device: SimulatedDevice
    ) -> Mapping[str, Any]:
        if device.rig_dir is not None and device.device in ("cia402_drive", "odrive_axis"):
            # eds/dcf/endpoints paths are relative to the rig file
            return {"bus": bus, "files_dir": device.rig_dir}
        return {"bus": bus}

    def simulate(
        self, name: str, options: Any, devices: Sequence[SimulatedDevice]
    ) -> AbstractAsyncContextManager[SimulatedBus]:
        assert isinstance(options, CanBusOptions)
        return _simulated(name, devices, options.sync)

    def parameter_access(
        self, bus: object, options: Any, device: SimulatedDevice
    ) -> ParameterAccess | None:
        """A CiA 402 drive's objects (:mod:`openel_can.params402`), an ODrive's endpoints
        (:mod:`openel_can.params_odrive`)."""
        assert isinstance(bus, CanBus)
        if device.device in CIA402_DEVICES:
            from .params402 import CanOpenParameters

            return CanOpenParameters.for_device(bus, device.params, device.rig_dir)
        if device.device in ODRIVE_DEVICES:
            from .params_odrive import ODriveParameters

            node = int(device.params["node_id"])
            # an axis's flat_endpoints.json, if the rig names one (other ODrive devices:
            # the built-in table)
            table = _odrive_table([device], node)
            return ODriveParameters(bus, node, endpoints=table)
        return None


@asynccontextmanager
async def _sync_on(bus: CanBus, timer: EventTimer, counter: int) -> AsyncIterator[CanSync]:
    sync = CanSync.of(bus)
    await sync.start(timer, counter_overflow=counter)
    try:
        yield sync
    finally:
        sync.stop()


@asynccontextmanager
async def _simulated(
    name: str, devices: Sequence[SimulatedDevice], sync: SyncOptions | None
) -> AsyncIterator[SimulatedBus]:
    from .sim.cia402 import SimCia402Drive
    from .sim.odrive import SimODrive

    odrives, drives = _node_ids(devices)
    peers: dict[int, Any] = {}
    by_name: dict[str, object] = {}
    for node in odrives:
        peers[node] = SimODrive(
            node,
            traj_vel_limit=2.0,
            traj_accel_limit=20.0,
            endpoints=_odrive_table(devices, node),  # the rig's file: its ids and version
        )
    cia402 = {node: SimCia402Drive(node, eds=_sim_eds(devices, node)) for node in drives}
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
            CanBusOptions(interface="virtual", channel=channel, sync=sync),
            f"python-can virtual channel {channel} with simulated {', '.join(shown) or 'no node'}",
            by_name,
        )
    finally:
        with anyio.CancelScope(shield=True):
            await anyio.to_thread.run_sync(cm.__exit__, None, None, None)


def _sim_eds(devices: Sequence[SimulatedDevice], node: int) -> str | None:
    """The EDS (else the DCF) a rig's drive at ``node`` names: the simulated drive's
    dictionary is the same file's."""
    for d in devices:
        if d.device == "cia402_drive" and d.params.get("node_id") == node:
            for key in ("eds", "dcf"):
                value = d.params.get(key)
                if isinstance(value, str) and value:
                    return drive_file(key, value, d.rig_dir)
    return None


@contextmanager
def _on_thread(peers: Sequence[Any], channel: str) -> Iterator[None]:
    from .sim.faults import peers_on_thread

    with peers_on_thread(peers, channel):
        yield
