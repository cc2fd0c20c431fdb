"""Find what is on a CAN bus (``openel-async scan can``): CANopen nodes and ODrive axes.

:func:`scan_can` runs on an open :class:`~openel_can.bus.CanBus` in three bounded steps:

1. **listen** for ``listen`` seconds: CANopen heartbeats and boot-ups (COB-ID 0x700 + node,
   one byte) and ODrive heartbeats (CANSimple ``node << 5 | 0x01``, eight bytes); in the
   same window an ODrive **Address** request (a remote frame to the broadcast node 0x3F)
   makes every ODrive on firmware 0.6.9 or later answer with its node id and serial number,
   heartbeat or not;
2. **ODrive**: a ``Get_Version`` remote frame to every ODrive heard, its reply within
   ``node_timeout``;
3. **CANopen**: an SDO upload of 0x1000 (device type) to node ids 1..127, at most
   ``concurrency`` at a time, each bounded by ``node_timeout`` (a silent node costs nothing else:
   no abort is sent to a node that never answered); then 0x1018 sub 1..4 (vendor id,
   product code, revision, serial number) of every node that answered.

Ids shared by the two protocols: a CANopen heartbeat (0x701..0x77F) is also an ODrive id
(node 56..59), told apart by its length (one byte against eight). The SDO requests to
CANopen nodes 0..127 travel on 0x600..0x67F, which are the command ids of ODrive nodes 48..51
(Set_Input_Pos among them): the sweep skips the node ids whose request an ODrive heard on
the bus would take as a command, and says so (:attr:`CanScan.skipped`). An ODrive at node
48..51 that neither sends heartbeats nor answers Address cannot be seen: ``sdo=False``
skips the sweep altogether.

Every wait is bounded: the whole scan takes at most about ``listen + 2 * node_timeout +
ceil(127 / concurrency) * node_timeout + 4 * node_timeout * nodes``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any, Final

import anyio
import can

from openel_async.errors import BadParameterError
from openel_async.logs import get_logger

from . import canopen as co
from . import cansimple as cs
from .bus import CanBus, NodePort
from .errors import DecodeError
from .sdo import SdoAbortError, SdoClient

__all__ = [
    "IDENTITY",
    "CanOpenNode",
    "CanScan",
    "ODriveNode",
    "scan_can",
]

log = get_logger(__name__)

IDENTITY: Final = 0x1018
"""CiA 301 identity object: sub 1 vendor id, 2 product code, 3 revision, 4 serial number."""
CIA402_PROFILE: Final = 402
"""The device profile number (0x1000 bits 0..15) of a CiA 402 drive."""
_ALL_IDS: Final = range(0x800)
_ODRIVE_SDO_SHADOW: Final = range(48, 52)
"""ODrive node ids whose command ids (node << 5 | cmd) are CANopen SDO request ids."""


@dataclass(frozen=True)
class CanOpenNode:
    """A CANopen node found on the bus."""

    node_id: int
    state: str | None = None
    """The NMT state its last heartbeat said (BOOT_UP, PRE_OPERATIONAL...); None: not heard."""
    device_type: int | None = None
    """Object 0x1000 (bits 0..15: the device profile, 402 for a drive)."""
    vendor_id: int | None = None
    product_code: int | None = None
    revision: int | None = None
    serial_number: int | None = None

    @property
    def profile(self) -> int | None:
        return None if self.device_type is None else self.device_type & 0xFFFF

    def to_dict(self) -> dict[str, Any]:
        return {
            "node_id": self.node_id,
            "state": self.state,
            "device_type": self.device_type,
            "profile": self.profile,
            "vendor_id": self.vendor_id,
            "product_code": self.product_code,
            "revision": self.revision,
            "serial_number": self.serial_number,
        }


@dataclass(frozen=True)
class ODriveNode:
    """An ODrive axis found on the bus (CANSimple)."""

    node_id: int
    axis_state: str | None = None
    """From its heartbeat (None: it answered Address only)."""
    axis_error: int | None = None
    firmware: str | None = None
    """``0.6.10`` from Get_Version (None: no reply)."""
    hardware: str | None = None
    """``4.4-58`` (major.minor-variant) from Get_Version."""
    serial_number: int | None = None
    """From the Address reply (firmware 0.6.9 or later)."""

    def to_dict(self) -> dict[str, Any]:
        return {
            "node_id": self.node_id,
            "axis_state": self.axis_state,
            "axis_error": self.axis_error,
            "firmware": self.firmware,
            "hardware": self.hardware,
            "serial_number": self.serial_number,
        }


@dataclass
class CanScan:
    """What :func:`scan_can` found."""

    canopen: list[CanOpenNode] = field(default_factory=list)
    odrives: list[ODriveNode] = field(default_factory=list)
    frames: int = 0
    """Frames received during the scan."""
    skipped: list[int] = field(default_factory=list)
    """CANopen node ids not swept with SDO (their request ids are an ODrive's commands)."""
    seconds: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        return {
            "canopen": [n.to_dict() for n in self.canopen],
            "odrive": [n.to_dict() for n in self.odrives],
            "frames": self.frames,
            "skipped_sdo_nodes": self.skipped,
            "seconds": round(self.seconds, 3),
        }


class _Listener:
    """Every frame of the bus, through one port handler: heartbeats are recorded, and the
    probes waiting for a reply on an id are woken."""

    def __init__(self, bus: CanBus) -> None:
        self.frames = 0
        self.canopen_states: dict[int, str] = {}
        self.odrive_beats: dict[int, cs.Heartbeat] = {}
        self.addresses: dict[int, int] = {}
        self.waiting: dict[int, tuple[anyio.Event, list[can.Message]]] = {}
        self.port: NodePort = bus.attach(_ALL_IDS, name="scan", handler=self._on_frames)

    def _on_frames(self, frames: list[can.Message]) -> None:
        for frame in frames:
            self.frames += 1
            if frame.is_remote_frame or frame.is_error_frame:
                continue
            arb, data = frame.arbitration_id, bytes(frame.data)
            slot = self.waiting.get(arb)
            if slot is not None and not slot[0].is_set():
                slot[1].append(frame)
                slot[0].set()
            if co.HEARTBEAT_BASE < arb <= co.HEARTBEAT_BASE + co.MAX_NODE_ID and len(data) == 1:
                state = data[0] & 0x7F
                try:
                    name = co.NmtState(state).name
                except ValueError:
                    name = f"state {state}"
                self.canopen_states[arb - co.HEARTBEAT_BASE] = name
            elif len(data) == 8 and arb <= 0x7FF:
                node, cmd = arb >> 5, arb & 0x1F
                try:
                    if cmd == cs.CmdId.HEARTBEAT and node < cs.BROADCAST_NODE_ID:
                        beat = cs.decode(arb, data, from_host=False)
                        assert isinstance(beat, cs.Heartbeat)
                        self.odrive_beats[node] = beat
                    elif cmd == cs.CmdId.ADDRESS:
                        address = cs.decode(arb, data, from_host=False)
                        assert isinstance(address, cs.Address)
                        self.addresses[address.payload_node_id] = address.serial_number
                except DecodeError:
                    continue

    async def request(
        self, arb_id: int, data: bytes, reply_id: int, wait: float, *, remote: bool = False
    ) -> can.Message | None:
        """Send a frame and wait at most ``wait`` seconds for the first frame on ``reply_id``."""
        event = anyio.Event()
        got: list[can.Message] = []
        self.waiting[reply_id] = (event, got)
        try:
            await self.port.send(arb_id, data, remote=remote)
            with anyio.move_on_after(wait):
                await event.wait()
        finally:
            self.waiting.pop(reply_id, None)
        return got[0] if got else None


def _check(name: str, value: float, low: float, high: float) -> None:
    if isinstance(value, bool) or not (math.isfinite(value) and low <= value <= high):
        raise BadParameterError(name, value, f"a number of seconds in {low}..{high}")


async def scan_can(
    bus: CanBus,
    *,
    listen: float = 1.1,
    node_timeout: float = 0.05,
    concurrency: int = 16,
    sdo: bool = True,
    node_ids: Iterable[int] = range(1, co.MAX_NODE_ID + 1),
) -> CanScan:
    """Scan ``bus`` (see the module docstring); BadParameterError for a bound out of range."""
    _check("listen", listen, 0.0, 60.0)
    _check("node_timeout", node_timeout, 0.001, 5.0)
    if isinstance(concurrency, bool) or not 1 <= concurrency <= 127:
        raise BadParameterError("concurrency", concurrency, "an int in 1..127")
    started = anyio.current_time()
    listener = _Listener(bus)
    try:
        await listener.port.send(
            cs.arbitration_id(cs.BROADCAST_NODE_ID, cs.CmdId.ADDRESS), remote=True
        )
        await anyio.sleep(max(listen, node_timeout))
        odrives = await _odrives(listener, node_timeout)
        shadowed = {n.node_id for n in odrives} & set(_ODRIVE_SDO_SHADOW)
        wanted = sorted(set(node_ids))
        skipped = [n for n in wanted if (co.SDO_RX_BASE + n) >> 5 in shadowed] if sdo else []
        nodes = await _canopen(
            bus, listener, [n for n in wanted if n not in skipped] if sdo else [], node_timeout,
            concurrency,
        )  # fmt: skip
    finally:
        listener.port.close()
    result = CanScan(nodes, odrives, listener.frames, skipped, anyio.current_time() - started)
    log.info(
        "can_scanned", canopen=len(nodes), odrive=len(odrives), frames=result.frames,
        seconds=round(result.seconds, 3),
    )  # fmt: skip
    return result


async def _odrives(listener: _Listener, wait: float) -> list[ODriveNode]:
    found: list[ODriveNode] = []
    canopen = set(listener.canopen_states)
    for node in sorted(set(listener.odrive_beats) | set(listener.addresses)):
        beat = listener.odrive_beats.get(node)
        arb = cs.arbitration_id(node, cs.CmdId.GET_VERSION)
        reply = await listener.request(arb, b"", arb, wait, remote=True)
        version: cs.Version | None = None
        if reply is not None:
            try:
                decoded = cs.decode(arb, bytes(reply.data), from_host=False)
            except DecodeError:
                decoded = None
            version = decoded if isinstance(decoded, cs.Version) else None
        heartbeat_id = cs.arbitration_id(node, cs.CmdId.HEARTBEAT)
        if version is None and node not in listener.addresses and (heartbeat_id & 0x7F) in canopen:
            continue  # an eight-byte frame of a CANopen node (a TPDO), not an ODrive
        found.append(
            ODriveNode(
                node,
                cs.value_name(beat.axis_state) if beat is not None else None,
                beat.axis_error if beat is not None else None,
                (
                    f"{version.fw_version_major}.{version.fw_version_minor}."
                    f"{version.fw_version_revision}"
                    if version is not None
                    else None
                ),
                (
                    f"{version.hw_version_major}.{version.hw_version_minor}-"
                    f"{version.hw_version_variant}"
                    if version is not None
                    else None
                ),
                listener.addresses.get(node),
            )
        )
    return found


async def _canopen(
    bus: CanBus, listener: _Listener, node_ids: list[int], wait: float, concurrency: int
) -> list[CanOpenNode]:
    device_types: dict[int, int] = {}
    limiter = anyio.Semaphore(concurrency)
    request = co.encode(co.SdoUploadRequest(1, co.DEVICE_TYPE, 0))[1]

    async def probe(node: int) -> None:
        async with limiter:
            reply = await listener.request(
                co.SDO_RX_BASE + node, request, co.SDO_TX_BASE + node, wait
            )
        if reply is None:
            return
        try:
            answer = co.decode(reply.arbitration_id, bytes(reply.data))
        except DecodeError:
            return
        if isinstance(answer, co.SdoUploadResponse) and answer.index == co.DEVICE_TYPE:
            device_types[node] = int.from_bytes(answer.data, "little")

    async with anyio.create_task_group() as tg:
        for node in node_ids:
            tg.start_soon(probe, node)
    nodes: list[CanOpenNode] = []
    for node in sorted(set(device_types) | set(listener.canopen_states)):
        identity: list[int | None] = [None] * 4
        if node in device_types:
            client = SdoClient(bus, node, timeout=wait)
            for sub in range(1, 5):
                try:
                    raw = await client.upload(IDENTITY, sub)
                except (SdoAbortError, TimeoutError):
                    continue
                identity[sub - 1] = int.from_bytes(raw[:4], "little")
        nodes.append(
            CanOpenNode(node, listener.canopen_states.get(node), device_types.get(node), *identity)
        )
    return nodes
