"""An ODrive axis's parameters for ``openel-async param``: the endpoints of
:mod:`openel_can.odrive_endpoints` (firmware 0.6.x), by name
(``axis0.controller.config.vel_limit``; the ``axis0.`` may be left out) or id
(``390``, ``endpoint 390``), read with CANSimple RxSdo (opcode read) answered by TxSdo,
written with RxSdo (opcode write, which the firmware does not answer: the command reads the
endpoint back).

Only the node's TxSdo frames are received (a port of its own on the bus); nothing else is
sent, so the axis keeps its state. Every frame addressed to the axis feeds its watchdog, as
any CANSimple frame does.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from typing import Final

import anyio
import can

from openel_async.errors import BadParameterError
from openel_async.params import ParameterInfo, ParamValue, not_found

from . import cansimple as cs
from .bus import CanBus, NodePort
from .errors import DecodeError
from .odrive_endpoints import COMMANDS, ENDPOINTS, FIRMWARE, Endpoint, endpoint_unit

__all__ = ["ODriveParameters", "endpoint_info"]

PARAM_REPLY_TIMEOUT: Final = 0.5
"""Seconds a TxSdo answer may take (the command bounds each read more)."""

_RANGES: Final[dict[str, tuple[float, float]]] = {
    "uint32": (0, 2**32 - 1),
    "int32": (-(2**31), 2**31 - 1),
    "float": (-3.4028234663852886e38, 3.4028234663852886e38),
}
_KINDS: Final = {"float": "float", "uint32": "int", "int32": "int", "bool": "bool"}


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
        kind=_KINDS[endpoint.type],  # type: ignore[arg-type]
        low=low,
        high=high,
        command=command,
    )


def encode(endpoint: Endpoint, value: ParamValue) -> bytes:
    """The 4-byte value field of ``value``."""
    if endpoint.type == "bool":
        return bytes((int(bool(value)), 0, 0, 0))
    if endpoint.type == "float":
        if not isinstance(value, int | float) or isinstance(value, bool):
            raise BadParameterError(endpoint.name, value, "a number")
        return struct.pack("<f", float(value))
    if not isinstance(value, int) or isinstance(value, bool):
        raise BadParameterError(endpoint.name, value, "an integer")
    try:
        return struct.pack("<I" if endpoint.type == "uint32" else "<i", value)
    except struct.error:
        raise BadParameterError(endpoint.name, value, f"a {endpoint.type}") from None


def decode(endpoint: Endpoint, data: bytes) -> ParamValue:
    """The value of a 4-byte field."""
    if endpoint.type == "bool":
        return data[0] != 0
    if endpoint.type == "float":
        return float(struct.unpack("<f", data)[0])
    fmt = "<I" if endpoint.type == "uint32" else "<i"
    return int(struct.unpack(fmt, data)[0])


class ODriveParameters:
    """The endpoints of one ODrive axis, by RxSdo/TxSdo (see the module docstring)."""

    def __init__(self, bus: CanBus, node_id: int, *, timeout: float = PARAM_REPLY_TIMEOUT) -> None:
        self.bus = bus
        self.node_id = node_id
        self.timeout = timeout
        self._infos = tuple(endpoint_info(e) for e in ENDPOINTS)
        self._endpoints = {e.name: e for e in ENDPOINTS}
        self._by_id = {e.id: e for e in ENDPOINTS}
        self._folded = {e.name.casefold(): e for e in ENDPOINTS}
        self._port: NodePort | None = None
        self._lock = anyio.Lock()
        self._waiting: int | None = None
        self._reply: bytes | None = None
        self._arrived = anyio.Event()

    @property
    def source(self) -> str:
        return (
            f"ODrive node {self.node_id}, {len(self._infos)} endpoints of firmware {FIRMWARE} "
            "(openel_can.odrive_endpoints)"
        )

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
            raise not_found(key, self._endpoints, f"ODrive firmware {FIRMWARE}")
        return self._infos[ENDPOINTS.index(endpoint)]

    def _ensure_port(self) -> NodePort:
        if self._port is None or not self._port.attached:
            arb_id = cs.arbitration_id(self.node_id, cs.CmdId.TX_SDO)
            self._port = self.bus.attach(
                (arb_id,), name=f"param-odrive-{self.node_id}", handler=self._on_frames
            )
        return self._port

    def _on_frames(self, frames: list[can.Message]) -> None:
        for frame in frames:
            if frame.is_remote_frame or self._waiting is None:
                continue
            try:
                msg = cs.decode(frame.arbitration_id, bytes(frame.data), from_host=False)
            except DecodeError:
                continue
            if isinstance(msg, cs.TxSdo) and msg.endpoint_id == self._waiting:
                self._reply = msg.value
                self._waiting = None
                self._arrived.set()

    async def read(self, info: ParameterInfo) -> ParamValue:
        endpoint = self._endpoints[info.name]
        async with self._lock:
            port = self._ensure_port()
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
            arb_id, data = cs.encode(cs.RxSdo(self.node_id, cs.SdoOpcode.WRITE, endpoint.id, field))
            await port.send(arb_id, data)
