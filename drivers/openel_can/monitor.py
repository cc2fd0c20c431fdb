"""A passive CAN bus monitor (``openel-async bus monitor``): every frame decoded by what the
rig knows, per-id rates and error counters, and optionally a log file python-can reads.

* **ODrive** frames (CANSimple, the nodes the rig names as ODrives, or ``--odrive``) by our
  codec :mod:`openel_can.cansimple`, which tests/can/test_interop_odrive_dbc.py checks byte
  for byte against ODrive's own DBC through cantools: the monitor needs neither cantools nor
  the DBC at run time (both stay test-only dependencies of the ``peers`` group);
* **CANopen** frames by :mod:`openel_can.canopen`: NMT commands, SYNC, heartbeats, EMCY with
  the class of its code (:func:`openel_can.emcy.describe_emcy`), SDO transfers with index and
  subindex (named, and their values decoded by type, when the node's dictionary is known;
  a segmented transfer's value and size at its last segment), and the PDOs of the CiA 402
  drives the rig names (or ``--cia402``) field by field, by the maps the driver writes
  (:mod:`openel_can.monitor_canopen`); other PDOs raw;
* anything else raw.

The monitor sends nothing. It watches the 11-bit ids (the ones these protocols use). Frames that do not decode count as ``malformed``; error frames,
frames dropped by a slow consumer (``overflow``) and the bus's own counters are reported
too. ``log`` is any file python-can's ``can.Logger`` writes by its extension (``.asc``,
``.blf``, ``.trc``, ``.log``, ``.csv``), readable by ``can.LogReader`` and ``can.player``;
the writes run in a worker thread, never in the event loop.
"""

from __future__ import annotations

import copy
import math
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from typing import Any, Final

import anyio
import can

from openel_async.errors import BadParameterError

from . import canopen as co
from . import cansimple as cs
from .bus import CanBus
from .emcy import describe_emcy
from .errors import DecodeError
from .monitor_canopen import CanopenKnowledge, SdoTracker

__all__ = ["LOG_SUFFIXES", "Decoded", "Decoder", "MonitorStats", "monitor"]

LOG_SUFFIXES: Final = (".asc", ".blf", ".trc", ".log", ".csv")
"""The log formats python-can's ``can.Logger`` chooses by extension and ``can.LogReader`` reads."""


@dataclass(frozen=True)
class Decoded:
    """One frame, decoded."""

    timestamp: float
    arbitration_id: int
    data: bytes
    protocol: str
    """``odrive``, ``canopen``, ``raw`` or ``error``."""
    text: str
    """What it says, for people: ``ODrive 1 Heartbeat axis_state=IDLE ...``."""
    malformed: bool = False
    remote: bool = False
    fields: tuple[dict[str, Any], ...] = ()
    """A PDO's objects: ``object`` (``6040:00``), ``name``, ``type``, ``value``."""

    def line(self, since: float = 0.0) -> str:
        """One line for people; the time in seconds since ``since``."""
        data = "R" if self.remote else self.data.hex(" ")
        return f"{self.timestamp - since:10.4f}  {self.arbitration_id:03X}  [{len(self.data)}] {data:<23}  {self.text}"

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "t": round(self.timestamp, 6),
            "id": self.arbitration_id,
            "data": self.data.hex(),
            "remote": self.remote,
            "protocol": self.protocol,
            "text": self.text,
            "malformed": self.malformed,
        }
        if self.fields:
            out["fields"] = list(self.fields)
        return out


def _fields(msg: object) -> str:
    out = []
    for name, value in vars(msg).items():
        if name == "node_id":
            continue
        if isinstance(value, float):
            shown = f"{value:.4g}"
        elif isinstance(value, bytes):
            shown = value.hex()
        elif isinstance(value, Enum):
            shown = value.name
        else:
            shown = str(value)
        out.append(f"{name}={shown}")
    return " ".join(out)


@dataclass
class Decoder:
    """Decodes frames by what is known of the bus's nodes."""

    odrives: frozenset[int] = frozenset()
    """ODrive node ids (CANSimple: ``node << 5 | cmd``)."""
    canopen: frozenset[int] | None = None
    """CANopen node ids (None: any id a CANopen function code explains)."""
    known: CanopenKnowledge = field(default_factory=CanopenKnowledge)
    """The PDO maps (by COB-ID) and dictionaries (by node) of the CiA 402 drives."""
    sdo: SdoTracker = field(init=False)

    def __post_init__(self) -> None:
        self.sdo = SdoTracker(self.known.ods)

    def decode(self, frame: can.Message) -> Decoded:
        arb, data, t = frame.arbitration_id, bytes(frame.data), frame.timestamp
        remote = bool(frame.is_remote_frame)
        if frame.is_error_frame:
            return Decoded(t, arb, data, "error", "error frame", remote=remote)
        if frame.is_extended_id:
            return Decoded(t, arb, data, "raw", "29-bit frame", remote=remote)
        if arb >> 5 in self.odrives or arb == cs.arbitration_id(
            cs.BROADCAST_NODE_ID, cs.CmdId.ADDRESS
        ):
            return self._odrive(t, arb, data, remote)
        layout = self.known.pdos.get(arb)
        if layout is not None and not remote:
            text, fields, malformed = layout.decode(data)
            return Decoded(t, arb, data, "canopen", text, malformed, fields=fields)
        return self._canopen(t, arb, data, remote)

    def _odrive(self, t: float, arb: int, data: bytes, remote: bool) -> Decoded:
        node, cmd = arb >> 5, arb & 0x1F
        name = cs.CmdId(cmd).name if cmd in {c.value for c in cs.CmdId} else f"cmd {cmd:#x}"
        if remote:
            return Decoded(t, arb, data, "odrive", f"ODrive {node} request {name}", remote=True)
        # The same id carries host and axis payloads: the axis's sent messages first.
        for from_host in (False, True):
            try:
                msg = cs.decode(arb, data, from_host=from_host)
            except DecodeError:
                continue
            who = "<-" if from_host else "->"
            text = f"ODrive {node} {who} {type(msg).__name__} {_fields(msg)}".rstrip()
            return Decoded(t, arb, data, "odrive", text)
        return Decoded(t, arb, data, "odrive", f"ODrive {node} {name}: malformed", True)

    def _canopen(self, t: float, arb: int, data: bytes, remote: bool) -> Decoded:
        node = arb & 0x7F
        known = (
            self.canopen is None or arb in (co.NMT_COB_ID, co.SYNC_COB_ID) or node in self.canopen
        )
        if remote or not known:
            return Decoded(t, arb, data, "raw", "remote frame" if remote else "", remote=remote)
        try:
            msg = co.decode(arb, data)
        except DecodeError as exc:
            return Decoded(t, arb, data, "canopen", f"malformed: {exc}", True)
        note, odd = self.sdo.note(msg)
        return Decoded(t, arb, data, "canopen", _canopen_text(msg, self.sdo) + note, odd)


def _canopen_text(msg: co.CanOpenMessage, sdo: SdoTracker) -> str:
    if isinstance(msg, co.NmtControl):
        target = "all nodes" if msg.node_id == 0 else f"node {msg.node_id}"
        command = msg.command.name if isinstance(msg.command, co.NmtCommand) else msg.command
        return f"NMT {command} {target}"
    if isinstance(msg, co.Sync):
        return "SYNC" if msg.counter is None else f"SYNC counter={msg.counter}"
    if isinstance(msg, co.Heartbeat):
        try:
            state = co.NmtState(msg.state).name
        except ValueError:
            state = f"state {msg.state}"
        return f"node {msg.node_id} heartbeat {state}"
    if isinstance(msg, co.Emergency):
        return (
            f"node {msg.node_id} EMCY {describe_emcy(msg.error_code)} "
            f"register={msg.error_register:#04x}"
        )
    if isinstance(msg, co.Pdo):
        kind = "TPDO" if msg.transmit else "RPDO"
        return f"node {msg.node_id} {kind}{msg.number} {msg.data.hex(' ')}"
    name = type(msg).__name__.removeprefix("Sdo")
    node = msg.node_id
    index, subindex = getattr(msg, "index", None), getattr(msg, "subindex", None)
    where = "" if index is None else f" {index:04X}:{subindex:02X}"
    if index is not None and subindex is not None:
        where += sdo.name(node, index, subindex)
    detail = ""
    if isinstance(msg, co.SdoAbort):
        try:
            detail = f" {co.SdoAbortCode(msg.code).name}"
        except ValueError:
            detail = f" {msg.code:#010x}"
    elif isinstance(msg, co.SdoUploadResponse | co.SdoDownloadRequest):
        detail = f" {sdo.value(node, msg.index, msg.subindex, msg.data)}"
    return f"node {node} SDO {name}{where}{detail}"


@dataclass
class MonitorStats:
    """Counters of a monitor run."""

    frames: int = 0
    per_id: Counter[int] = field(default_factory=Counter)
    malformed: int = 0
    error_frames: int = 0
    overflow: int = 0
    seconds: float = 0.0

    def rates(self) -> dict[int, float]:
        """Frames per second of each id over the run."""
        span = max(self.seconds, 1e-9)
        return {arb: n / span for arb, n in sorted(self.per_id.items())}

    def to_dict(self) -> dict[str, Any]:
        return {
            "frames": self.frames,
            "seconds": round(self.seconds, 3),
            "malformed": self.malformed,
            "error_frames": self.error_frames,
            "overflow": self.overflow,
            "rates": {f"{arb:03X}": round(r, 2) for arb, r in self.rates().items()},
        }

    def summary(self) -> str:
        top = sorted(self.rates().items(), key=lambda item: -item[1])[:8]
        rates = ", ".join(f"{arb:03X} {r:.0f}/s" for arb, r in top)
        return (
            f"-- {self.frames} frames in {self.seconds:.1f} s ({self.frames / max(self.seconds, 1e-9):.0f}/s), "
            f"malformed {self.malformed}, error frames {self.error_frames}, overflow {self.overflow}"
            + (f"; busiest: {rates}" if rates else "")
        )


def check_log_path(path: str) -> str | None:
    """Why ``path`` cannot be a log file (None: it can)."""
    suffix = Path(path).suffix.lower()
    if suffix not in LOG_SUFFIXES:
        return f"a file ending in {', '.join(LOG_SUFFIXES)} (python-can's formats)"
    if not Path(path).resolve().parent.is_dir():
        return "a file in an existing folder"
    return None


async def monitor(
    bus: CanBus,
    decoder: Decoder,
    *,
    duration: float,
    on_frame: Callable[[Decoded], None],
    on_summary: Callable[[MonitorStats], None] | None = None,
    summary_every: float = 1.0,
    log: str | None = None,
) -> MonitorStats:
    """Watch ``bus`` for ``duration`` seconds: ``on_frame`` for every frame decoded,
    ``on_summary`` every ``summary_every`` seconds; the counters at the end."""
    if not (math.isfinite(duration) and duration > 0):
        raise BadParameterError("duration", duration, "a finite number of seconds > 0")
    if log is not None and (why := check_log_path(log)) is not None:
        raise BadParameterError("log", log, why)
    stats = MonitorStats()
    port = bus.attach(range(0x800), name="monitor", queue_size=4096)
    writer: can.Listener | None = None
    if log is not None:
        writer = await anyio.to_thread.run_sync(can.Logger, log)
    started = anyio.current_time()
    next_summary = started + summary_every

    def handle(batch: Iterable[can.Message]) -> None:
        for frame in batch:
            decoded = decoder.decode(frame)
            stats.frames += 1
            stats.per_id[frame.arbitration_id] += 1
            stats.malformed += decoded.malformed
            stats.error_frames += frame.is_error_frame
            on_frame(decoded)

    try:
        with anyio.move_on_after(duration):
            while True:
                with anyio.move_on_after(max(0.0, next_summary - anyio.current_time())):
                    batch = await port.receive()
                    handle(batch)
                    if writer is not None:  # a batch received is logged, even at the end
                        with anyio.CancelScope(shield=True):
                            await anyio.to_thread.run_sync(_write, writer, batch)
                now = anyio.current_time()
                if now >= next_summary:
                    stats.seconds = now - started
                    stats.overflow = port.dropped
                    if on_summary is not None:
                        on_summary(stats)
                    next_summary = now + summary_every
    finally:
        port.close()
        stats.seconds = anyio.current_time() - started
        stats.overflow = port.dropped
        if writer is not None:
            with anyio.CancelScope(shield=True):
                await anyio.to_thread.run_sync(writer.stop)
    return stats


def _write(writer: can.Listener, batch: list[can.Message]) -> None:
    """The frames into the log file, on the writer's own channel: python-can's writers turn
    a channel name into a number by its trailing digits (BLF stores it in 16 bits), and a
    bus named ``monitor-3f1234567`` or ``vcan70000`` is one bus, not channel 1234567."""
    for frame in batch:
        logged = copy.copy(frame)
        logged.channel = None
        writer.on_message_received(logged)
