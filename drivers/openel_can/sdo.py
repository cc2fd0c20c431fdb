"""Expedited SDO client (CiA 301) over a :class:`~openel_can.bus.CanBus`.

One :class:`SdoClient` per node and bus (``SdoClient.for_node(bus, node_id)``), shared by
every device of that node: an SDO server serves one transfer at a time, so the client
serializes them with a lock. Each transfer is bounded by ``timeout``:

* no answer in time -> the client sends an abort (0x05040000, SDO protocol timed out)
  and raises :class:`SdoTimeoutError`, a ``TimeoutError``: for a component, a link
  fault (Error state, ``ErrorId.TIMEOUT``);
* the server aborts -> :class:`SdoAbortError`, a ``HALError`` naming the object and the
  abort code: the drive is there and refused the access, so the caller gets a clear
  error and the component's state does not change.
"""

from __future__ import annotations

import math

import anyio
import can
import structlog

from openel_async.errors import BadParameterError, HALError

from . import canopen as co
from .bus import CanBus, NodePort
from .errors import DecodeError

__all__ = ["SdoAbortError", "SdoClient", "SdoTimeoutError"]

log = structlog.get_logger(__name__)


def _abort_name(code: int) -> str:
    try:
        return co.SdoAbortCode(code).name
    except ValueError:
        return "unknown"


class SdoAbortError(HALError):
    """The SDO server (or this client) aborted a transfer."""

    def __init__(self, node_id: int, index: int, subindex: int, code: int) -> None:
        super().__init__(
            f"SDO abort {code:#010x} ({_abort_name(code)}) from node {node_id} "
            f"on object {index:#06x}:{subindex}"
        )
        self.node_id = node_id
        self.index = index
        self.subindex = subindex
        self.abort_code = code


class SdoTimeoutError(TimeoutError):
    """The SDO server did not answer in time."""


class SdoClient:
    """Expedited SDO upload/download to one node; see the module docstring."""

    def __init__(self, bus: CanBus, node_id: int, *, timeout: float = 0.1) -> None:
        if isinstance(node_id, bool) or not isinstance(node_id, int) or not 1 <= node_id <= 127:
            raise BadParameterError("node_id", node_id, "a CANopen node id in 1..127")
        if not (math.isfinite(timeout) and timeout > 0):
            raise BadParameterError("timeout", timeout, "a finite number of seconds > 0")
        self.bus = bus
        self.node_id = node_id
        self.timeout = timeout
        self.transfers = 0
        self.aborts = 0
        self.timeouts = 0
        self._lock = anyio.Lock()
        self._port: NodePort | None = None

    @classmethod
    def for_node(cls, bus: CanBus, node_id: int, *, timeout: float = 0.1) -> SdoClient:
        """The bus's shared client of ``node_id`` (created on first use with ``timeout``)."""
        return bus.shared(("sdo", node_id), lambda: cls(bus, node_id, timeout=timeout))

    @property
    def malformed(self) -> int:
        return self._port.malformed if self._port is not None else 0

    def _ensure_port(self) -> NodePort:
        port = self._port
        if port is None or not port.attached:
            port = self._port = self.bus.attach(
                (co.SDO_TX_BASE + self.node_id,), name=f"sdo-{self.node_id}", queue_size=16
            )
        return port

    # -- typed access ---------------------------------------------------------------------
    async def read(self, entry: co.ObjectEntry, *, timeout: float | None = None) -> int:  # noqa: ASYNC109
        data = await self.upload(entry.index, entry.subindex, timeout=timeout)
        try:
            return entry.decode(data)
        except DecodeError as exc:
            raise HALError(
                f"node {self.node_id}: bad SDO value for {entry.index:#06x}:{entry.subindex}: {exc}"
            ) from exc

    async def write(
        self,
        entry: co.ObjectEntry,
        value: int,
        *,
        timeout: float | None = None,  # noqa: ASYNC109
    ) -> None:
        try:
            data = entry.encode(value)
        except ValueError as exc:
            raise BadParameterError(
                f"{entry.index:#06x}:{entry.subindex}", value, f"a {entry.data_type.name}"
            ) from exc
        await self.download(entry.index, entry.subindex, data, timeout=timeout)

    # -- raw transfers --------------------------------------------------------------------
    async def upload(self, index: int, subindex: int, *, timeout: float | None = None) -> bytes:  # noqa: ASYNC109
        request = co.SdoUploadRequest(self.node_id, index, subindex)
        reply = await self._transfer(request, timeout)
        if not isinstance(reply, co.SdoUploadResponse):
            raise HALError(f"node {self.node_id}: unexpected SDO reply {reply!r}")
        return reply.data

    async def download(
        self,
        index: int,
        subindex: int,
        data: bytes,
        *,
        timeout: float | None = None,  # noqa: ASYNC109
    ) -> None:
        request = co.SdoDownloadRequest(self.node_id, index, subindex, bytes(data))
        reply = await self._transfer(request, timeout)
        if not isinstance(reply, co.SdoDownloadResponse):
            raise HALError(f"node {self.node_id}: unexpected SDO reply {reply!r}")

    async def _transfer(
        self,
        request: co.SdoUploadRequest | co.SdoDownloadRequest,
        timeout: float | None,  # noqa: ASYNC109
    ) -> co.CanOpenMessage:
        limit = self.timeout if timeout is None else timeout
        async with self._lock:
            port = self._ensure_port()
            while True:  # drop late answers to earlier (timed-out) transfers
                try:
                    port.receive_nowait()
                except (anyio.WouldBlock, anyio.EndOfStream):
                    break
            cob_id, data = co.encode(request)
            self.transfers += 1
            await port.send(cob_id, data)
            with anyio.move_on_after(limit):
                while True:
                    try:
                        batch = await port.receive()
                    except anyio.EndOfStream:
                        break
                    for msg in batch:
                        reply = self._match(port, msg, request)
                        if reply is not None:
                            return reply
            self.timeouts += 1
            await self._send_abort(port, request, co.SdoAbortCode.TIMEOUT)
            raise SdoTimeoutError(
                f"node {self.node_id}: no SDO answer for {request.index:#06x}:"
                f"{request.subindex} within {limit * 1000:.0f} ms"
            )

    def _match(
        self,
        port: NodePort,
        msg: can.Message,
        request: co.SdoUploadRequest | co.SdoDownloadRequest,
    ) -> co.CanOpenMessage | None:
        if msg.is_remote_frame:
            port.malformed += 1
            return None
        try:
            reply = co.decode(msg.arbitration_id, msg.data)
        except DecodeError:
            port.malformed += 1
            return None
        if not isinstance(reply, co.SdoUploadResponse | co.SdoDownloadResponse | co.SdoAbort) or (
            reply.index,
            reply.subindex,
        ) != (request.index, request.subindex):
            return None  # an answer to someone else's transfer or a stale one
        if isinstance(reply, co.SdoAbort):
            self.aborts += 1
            raise SdoAbortError(self.node_id, reply.index, reply.subindex, reply.code)
        return reply

    async def _send_abort(
        self,
        port: NodePort,
        request: co.SdoUploadRequest | co.SdoDownloadRequest,
        code: int,
    ) -> None:
        abort = co.SdoAbort(self.node_id, request.index, request.subindex, code, from_client=True)
        cob_id, data = co.encode(abort)
        try:
            with anyio.move_on_after(self.timeout):
                await port.send(cob_id, data)
        except Exception as exc:  # best effort: the bus may be why it timed out
            log.debug("sdo_abort_not_sent", node=self.node_id, error=repr(exc))
