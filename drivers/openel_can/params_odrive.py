"""An ODrive axis's parameters for ``openel-async param``: the endpoints of an endpoint table
(:mod:`openel_can.odrive_firmware`: the axis component's ``endpoints`` file -- the
``flat_endpoints.json`` of its firmware -- else the built-in 0.6.x table of
:mod:`openel_can.odrive_endpoints`), by name (``axis0.controller.config.vel_limit``; the
``axis0.`` may be left out) or id (``390``, ``endpoint 390``), read with CANSimple RxSdo
(opcode read) answered by TxSdo, written with RxSdo (opcode write: the command reads the
endpoint back).

Firmware check: before the first read or write the axis's version is asked with Get_Version
(a remote frame, bounded wait). A write is refused (HALError naming both versions, nothing
sent) unless the firmware is the table's. Reads proceed on a mismatch -- they change nothing
-- with a warning (logged, and in :attr:`ODriveParameters.source`, the header of ``list`` and
``dump``): the values shown may then be those of other endpoints.

Only the node's Get_Version and TxSdo frames are received (a port of its own on the bus);
nothing else is sent, so the axis keeps its state. Every frame addressed to the axis feeds
its watchdog, as any CANSimple frame does.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from typing import Final

import anyio
import can

from openel_async.errors import BadParameterError, HALError
from openel_async.logs import get_logger
from openel_async.params import ParameterInfo, ParamValue, not_found

from . import cansimple as cs
from .bus import CanBus, NodePort
from .errors import DecodeError
from .odrive_endpoints import COMMANDS, Endpoint, endpoint_unit
from .odrive_firmware import BUILTIN_TABLE, EndpointTable, FirmwareVersion

__all__ = ["ODriveParameters", "endpoint_info"]

log = get_logger(__name__)

PARAM_REPLY_TIMEOUT: Final = 0.5
"""Seconds a TxSdo (or Get_Version) answer may take (the command bounds each read more)."""

_FORMATS: Final = {
    "uint8": "<B",
    "int8": "<b",
    "uint16": "<H",
    "int16": "<h",
    "uint32": "<I",
    "int32": "<i",
}
_RANGES: Final[dict[str, tuple[float, float]]] = {
    "uint8": (0, 2**8 - 1),
    "int8": (-(2**7), 2**7 - 1),
    "uint16": (0, 2**16 - 1),
    "int16": (-(2**15), 2**15 - 1),
    "uint32": (0, 2**32 - 1),
    "int32": (-(2**31), 2**31 - 1),
    "float": (-3.4028234663852886e38, 3.4028234663852886e38),
}


def endpoint_info(endpoint: Endpoint) -> ParameterInfo:
    """The :class:`~openel_async.params.ParameterInfo` of an endpoint."""
    low, high = _RANGES.get(endpoint.type, (None, None))
    command = endpoint.name in COMMANDS
    return ParameterInfo(
        name=endpoint.name,
        address=f"endpoint {endpoint.id}",
        type=endpoint.type,
        access="rw" if endpoint.writable else "ro",
        unit="" if endpoint.type == "bool" else endpoint_unit(endpoint.name),
        storage="ram" if endpoint.writable and not command else "volatile",
        description="a command (a state, a set-point): read-only here" if command else "",
        kind=endpoint.type if endpoint.type in ("float", "bool") else "int",
        low=low,
        high=high,
        command=command,
    )


def encode(endpoint: Endpoint, value: ParamValue) -> bytes:
    """The 4-byte value field of ``value`` (a narrower type in the low bytes)."""
    if endpoint.type == "bool":
        return bytes((int(bool(value)), 0, 0, 0))
    if endpoint.type == "float":
        if not isinstance(value, int | float) or isinstance(value, bool):
            raise BadParameterError(endpoint.name, value, "a number")
        return struct.pack("<f", float(value))
    if not isinstance(value, int) or isinstance(value, bool):
        raise BadParameterError(endpoint.name, value, "an integer")
    try:
        return struct.pack(_FORMATS[endpoint.type], value).ljust(4, b"\0")
    except struct.error:
        raise BadParameterError(endpoint.name, value, f"a {endpoint.type}") from None


def decode(endpoint: Endpoint, data: bytes) -> ParamValue:
    """The value of a 4-byte field."""
    if endpoint.type == "bool":
        return data[0] != 0
    if endpoint.type == "float":
        return float(struct.unpack("<f", data)[0])
    fmt = _FORMATS[endpoint.type]
    return int(struct.unpack_from(fmt, data)[0])


class ODriveParameters:
    """The endpoints of one ODrive axis, by RxSdo/TxSdo (see the module docstring)."""

    def __init__(
        self,
        bus: CanBus,
        node_id: int,
        *,
        endpoints: EndpointTable = BUILTIN_TABLE,
        timeout: float = PARAM_REPLY_TIMEOUT,
    ) -> None:
        self.bus = bus
        self.node_id = node_id
        self.timeout = timeout
        self.table = endpoints
        table = endpoints.endpoints
        self._table = table
        self._infos = tuple(endpoint_info(e) for e in table)
        self._endpoints = {e.name: e for e in table}
        self._by_id = {e.id: e for e in table}
        self._folded = {e.name.casefold(): e for e in table}
        self._port: NodePort | None = None
        self._lock = anyio.Lock()
        self._waiting: int | None = None
        self._reply: bytes | None = None
        self._arrived = anyio.Event()
        self._version: FirmwareVersion | None = None
        self._version_asked = False
        self._version_arrived = anyio.Event()
        self.mismatch: str | None = None
        """Why the table's ids may not be the axis's (set by the first read or write)."""

    @property
    def source(self) -> str:
        text = (
            f"ODrive node {self.node_id}, {len(self._infos)} endpoints of firmware "
            f"{self.table.firmware} ({self.table.source})"
        )
        if self.mismatch is not None:
            text += f"; WARNING: {self.mismatch}"
        return text

    def parameters(self) -> Sequence[ParameterInfo]:
        return self._infos

    def parameter(self, key: str) -> ParameterInfo:
        text = key.strip()
        endpoint = self._endpoints.get(text) or self._folded.get(text.casefold())
        if endpoint is None:
            endpoint = self._folded.get(f"axis0.{text}".casefold())
        if endpoint is None:
            number = text.removeprefix("endpoint").strip()
            if number.isdigit():
                endpoint = self._by_id.get(int(number))
        if endpoint is None:
            raise not_found(key, self._endpoints, f"ODrive firmware {self.table.firmware}")
        return self._infos[self._table.index(endpoint)]

    def _ensure_port(self) -> NodePort:
        if self._port is None or not self._port.attached:
            ids = (
                cs.arbitration_id(self.node_id, cs.CmdId.TX_SDO),
                cs.arbitration_id(self.node_id, cs.CmdId.GET_VERSION),
            )
            self._port = self.bus.attach(
                ids, name=f"param-odrive-{self.node_id}", handler=self._on_frames
            )
        return self._port

    def _on_frames(self, frames: list[can.Message]) -> None:
        for frame in frames:
            if frame.is_remote_frame:
                continue
            try:
                msg = cs.decode(frame.arbitration_id, bytes(frame.data), from_host=False)
            except DecodeError:
                continue
            if isinstance(msg, cs.Version) and self._version_asked and self._version is None:
                self._version = FirmwareVersion.of(msg)
                self._version_arrived.set()
            elif isinstance(msg, cs.TxSdo) and msg.endpoint_id == self._waiting:
                self._reply = msg.value
                self._waiting = None
                self._arrived.set()

    async def _check_firmware(self, port: NodePort, what: str) -> str | None:
        """Why writing ``what`` by the table's ids is refused (Get_Version asked once, bounded
        by ``timeout``); a mismatch is kept in :attr:`mismatch` and logged once."""
        if not self._version_asked:
            self._version_asked = True
            await port.send(cs.arbitration_id(self.node_id, cs.CmdId.GET_VERSION), b"", remote=True)
            with anyio.move_on_after(self.timeout):
                await self._version_arrived.wait()
            mismatch = self.table.mismatch(self.node_id, self._version)
            if mismatch is not None:
                self.mismatch = (
                    f"{mismatch}: values read by its ids may be those of other endpoints, and "
                    f"writes are refused; {self.table.fix(self._version)}"
                )
                log.warning("odrive_endpoint_table_mismatch", reason=self.mismatch)
        return self.table.refusal(self.node_id, self._version, what)

    async def read(self, info: ParameterInfo) -> ParamValue:
        endpoint = self._endpoints[info.name]
        async with self._lock:
            port = self._ensure_port()
            await self._check_firmware(port, endpoint.name)  # reads proceed: a warning
            self._reply, self._arrived = None, anyio.Event()
            self._waiting = endpoint.id
            try:
                arb_id, data = cs.encode(cs.RxSdo(self.node_id, cs.SdoOpcode.READ, endpoint.id))
                await port.send(arb_id, data)
                with anyio.move_on_after(self.timeout):
                    await self._arrived.wait()
            finally:
                self._waiting = None
            if self._reply is None:
                raise TimeoutError(
                    f"ODrive node {self.node_id}: no TxSdo for endpoint {endpoint.id} "
                    f"({endpoint.name}) within {self.timeout * 1000:.0f} ms"
                )
            return decode(endpoint, self._reply)

    async def write_blocker(self, info: ParameterInfo) -> str | None:
        return None

    async def write(self, info: ParameterInfo, value: ParamValue, *, unblock: bool = False) -> None:
        endpoint = self._endpoints[info.name]
        field = encode(endpoint, value)
        async with self._lock:
            port = self._ensure_port()
            refusal = await self._check_firmware(port, f"{endpoint.name} (endpoint {endpoint.id})")
            if refusal is not None:
                raise HALError(refusal)
            arb_id, data = cs.encode(cs.RxSdo(self.node_id, cs.SdoOpcode.WRITE, endpoint.id, field))
            await port.send(arb_id, data)
