"""The SDO server of the simulated drive (:class:`SdoServer`, a base class of
:class:`~openel_can.sim.cia402.SimCia402Drive`) over its object dictionary, with CiA 301
abort codes: expedited and segmented upload and download (one transfer at a time,
:class:`Transfer`), access rights and sizes, and the PDO mapping rules. See the module
docstring of :mod:`openel_can.sim.cia402` for the behaviour.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from .. import canopen as co
from .cia402_motion import SUPPORTED_MODES
from .objects import SimObject

__all__ = ["SdoServer", "Transfer"]


@dataclass
class Transfer:
    """A segmented SDO transfer in progress (one at a time, as on a real server)."""

    index: int
    subindex: int
    upload: bool
    data: bytearray = field(default_factory=bytearray)
    size: int | None = None
    toggle: bool = False


class _SdoAbort(Exception):
    def __init__(self, code: co.SdoAbortCode) -> None:
        super().__init__(code.name)
        self.code = code


class SdoServer:
    """The SDO server of :class:`~openel_can.sim.cia402.SimCia402Drive` (its attributes and
    object access below are the drive's)."""

    node_id: int
    od: dict[tuple[int, int], SimObject]
    _transfer: Transfer | None
    _mappings: dict[int, tuple[co.PdoMapEntry, ...]]

    if TYPE_CHECKING:

        def _get(self, index: int, sub: int = 0) -> int: ...

        def _refresh_actuals(self, now: int) -> None: ...

        def _after_write(self, written: set[int], now: int) -> None: ...

    def _sdo_server(self, msg: co.CanOpenMessage, now: int) -> co.CanOpenMessage | None:
        """One SDO request in, its answer out (None: nothing to send)."""
        if isinstance(msg, co.SdoAbort):
            self._transfer = None  # the client gave up; CiA 301: no answer
            return None
        if isinstance(msg, co.SdoUploadSegmentRequest | co.SdoDownloadSegment):
            return self._sdo_segment(msg, now)
        if not isinstance(
            msg,
            co.SdoUploadRequest
            | co.SdoDownloadRequest
            | co.SdoSegmentedDownloadRequest
            | co.SdoUnsupportedRequest,
        ):
            return None
        self._transfer = None  # a new initiate ends any transfer in progress
        try:
            if isinstance(msg, co.SdoUnsupportedRequest):
                raise _SdoAbort(co.SdoAbortCode.INVALID_COMMAND_SPECIFIER)  # block transfer
            obj = self._object(msg.index, msg.subindex)
            if isinstance(msg, co.SdoUploadRequest):
                if not obj.readable:
                    raise _SdoAbort(co.SdoAbortCode.WRITE_ONLY)
                self._refresh_actuals(now)
                data = self._encoded(msg.index, msg.subindex, obj)
                if len(data) <= 4:
                    return co.SdoUploadResponse(self.node_id, msg.index, msg.subindex, data)
                self._transfer = Transfer(
                    msg.index, msg.subindex, upload=True, data=bytearray(data)
                )
                return co.SdoSegmentedUploadResponse(
                    self.node_id, msg.index, msg.subindex, len(data)
                )
            if not obj.writable:
                raise _SdoAbort(co.SdoAbortCode.READ_ONLY)
            size = obj.size
            if isinstance(msg, co.SdoSegmentedDownloadRequest):
                if msg.size is not None and size is not None:
                    self._check_length(msg.size, size)
                self._transfer = Transfer(msg.index, msg.subindex, upload=False, size=msg.size)
                return co.SdoDownloadResponse(self.node_id, msg.index, msg.subindex)
            data = msg.data
            if not msg.size_indicated and size is not None:
                # CiA 301: without a size indication the object's own size applies.
                if size > len(data):
                    raise _SdoAbort(co.SdoAbortCode.LENGTH_TOO_LOW)
                data = data[:size]
            self._write(msg.index, msg.subindex, obj, data, now)
            return co.SdoDownloadResponse(self.node_id, msg.index, msg.subindex)
        except _SdoAbort as abort:
            return co.SdoAbort(self.node_id, msg.index, msg.subindex, abort.code)

    def _sdo_segment(
        self, msg: co.SdoUploadSegmentRequest | co.SdoDownloadSegment, now: int
    ) -> co.CanOpenMessage:
        transfer = self._transfer
        index, sub = (transfer.index, transfer.subindex) if transfer is not None else (0, 0)
        try:
            upload = isinstance(msg, co.SdoUploadSegmentRequest)
            if transfer is None or transfer.upload is not upload:
                raise _SdoAbort(co.SdoAbortCode.INVALID_COMMAND_SPECIFIER)
            if msg.toggle is not transfer.toggle:
                raise _SdoAbort(co.SdoAbortCode.TOGGLE_BIT_NOT_ALTERNATED)
            transfer.toggle = not transfer.toggle
            if isinstance(msg, co.SdoUploadSegmentRequest):
                chunk = bytes(transfer.data[: co.SDO_SEGMENT_SIZE])
                del transfer.data[: co.SDO_SEGMENT_SIZE]
                last = not transfer.data
                if last:
                    self._transfer = None
                return co.SdoUploadSegment(self.node_id, msg.toggle, chunk, last)
            transfer.data += msg.data
            obj = self._object(index, sub)
            if len(transfer.data) > (
                co.SDO_SEGMENT_SIZE * 0x10000 if obj.size is None else obj.size
            ):
                raise _SdoAbort(co.SdoAbortCode.LENGTH_TOO_HIGH)
            if msg.last:
                self._transfer = None
                if transfer.size is not None and transfer.size != len(transfer.data):
                    raise _SdoAbort(co.SdoAbortCode.LENGTH_MISMATCH)
                self._write(index, sub, obj, bytes(transfer.data), now)
            return co.SdoDownloadSegmentResponse(self.node_id, msg.toggle)
        except _SdoAbort as abort:
            self._transfer = None
            return co.SdoAbort(self.node_id, index, sub, abort.code)

    def _object(self, index: int, sub: int) -> SimObject:
        obj = self.od.get((index, sub))
        if obj is None:
            exists = any(i == index for i, _ in self.od)
            raise _SdoAbort(
                co.SdoAbortCode.SUBINDEX_DOES_NOT_EXIST
                if exists
                else co.SdoAbortCode.OBJECT_DOES_NOT_EXIST
            )
        return obj

    @staticmethod
    def _check_length(length: int, size: int) -> None:
        if length != size:
            raise _SdoAbort(
                co.SdoAbortCode.LENGTH_TOO_HIGH if length > size else co.SdoAbortCode.LENGTH_TOO_LOW
            )

    @staticmethod
    def _encoded(index: int, sub: int, obj: SimObject) -> bytes:
        if obj.data_type is None:
            return obj.data
        return co.ObjectEntry(index, sub, obj.data_type).encode(obj.value)

    def _write(self, index: int, sub: int, obj: SimObject, data: bytes, now: int) -> None:
        if obj.size is not None:
            self._check_length(len(data), obj.size)
        if obj.data_type is None:
            obj.data = data  # a string, domain or other non-integer object: its bytes
            return
        value = co.ObjectEntry(index, sub, obj.data_type).decode(data)
        self._check_write(index, sub, value)
        obj.value = value
        if 0x1600 <= index <= 0x1BFF:
            self._mappings.clear()
        self._after_write({index}, now)

    def _check_write(self, index: int, sub: int, value: int) -> None:
        if index == 0x6060 and value not in {int(m) for m in SUPPORTED_MODES}:
            raise _SdoAbort(co.SdoAbortCode.INVALID_VALUE)
        comm = index & 0xFF00
        if comm in (0x1400, 0x1800) and sub == 1:
            current = self._get(index, 1)
            if not (current & co.PDO_COB_ID_INVALID or value & co.PDO_COB_ID_INVALID) and (
                value & 0x7FF != current & 0x7FF
            ):
                raise _SdoAbort(co.SdoAbortCode.INVALID_VALUE)  # COB-ID change while valid
        if comm in (0x1400, 0x1800) and sub == 2 and not (value <= 240 or value >= 0xFE):
            raise _SdoAbort(co.SdoAbortCode.INVALID_VALUE)
        if comm in (0x1600, 0x1A00):
            pdo_comm = (0x1400 if comm == 0x1600 else 0x1800) + (index & 0xFF)
            if not self._get(pdo_comm, 1) & co.PDO_COB_ID_INVALID:
                raise _SdoAbort(co.SdoAbortCode.CANNOT_TRANSFER_DEVICE_STATE)
            if sub == 0:
                if value > 8:
                    raise _SdoAbort(co.SdoAbortCode.VALUE_TOO_HIGH)
                bits = 0
                for s in range(1, value + 1):
                    raw = self._get(index, s)
                    target = self.od.get((raw >> 16, (raw >> 8) & 0xFF))
                    # The file's PDOMapping and access: RPDOs write, TPDOs read.
                    allowed = (
                        target is not None
                        and target.data_type is not None
                        and (target.rpdo_mappable if comm == 0x1600 else target.tpdo_mappable)
                    )
                    if not allowed:
                        raise _SdoAbort(co.SdoAbortCode.CANNOT_BE_MAPPED)
                    assert target is not None and target.data_type is not None
                    if raw & 0xFF != target.data_type.size * 8:
                        raise _SdoAbort(co.SdoAbortCode.GENERAL_PARAMETER_INCOMPATIBILITY)
                    bits += raw & 0xFF
                if bits > 64:
                    raise _SdoAbort(co.SdoAbortCode.PDO_LENGTH_EXCEEDED)
            elif self._get(index, 0) != 0:
                raise _SdoAbort(co.SdoAbortCode.UNSUPPORTED_ACCESS)
