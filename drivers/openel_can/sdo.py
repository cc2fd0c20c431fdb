"""SDO client (CiA 301: expedited and segmented transfers) over a :class:`~openel_can.bus.CanBus`.

One :class:`SdoClient` per node and bus (``SdoClient.for_node(bus, node_id)``), shared by
every device of that node: an SDO server serves one transfer at a time, so the client
serializes them (one request slot per node: taken without a checkpoint or an anyio call
when free; waiting transfers queue in order).
Uploads take whatever the server answers: an expedited reply (1..4 bytes) or a
segmented one (any size up to ``max_size``, 7 bytes per segment, toggle bit checked).
Downloads of 1..4 bytes are expedited with the size indicated; any other length (0, or
more than 4 bytes: 64-bit objects, strings) is segmented with the size indicated. Block
transfer is not implemented. Answers reach the client through a port handler (no
queue); each exchange waits on a future that the handler resolves, bounded by its deadline
(the request sent + ``timeout``) through one timer per client that is re-armed only
when it would fire late or fires early. Every exchange (the initiate and each segment) is
bounded by ``timeout``:

* no answer in time -> the client sends an abort (0x05040000, SDO protocol timed out)
  and raises :class:`SdoTimeoutError`, a ``TimeoutError``: for a component, a link
  fault (Error state, ``ErrorId.TIMEOUT``);
* the server aborts -> :class:`SdoAbortError`, a ``HALError`` naming the object and the
  abort code: the drive is there and refused the access, so the caller gets a clear
  error and the component's state does not change;
* the server breaks the protocol (a reply of the wrong kind, a toggle bit that did not
  alternate, more data than announced or than ``max_size``) -> the client aborts the
  transfer itself (0x05040001, 0x05030000, 0x06070010, 0x05040005) and raises
  :class:`SdoAbortError` with ``by_client`` True.

Typed access: :meth:`SdoClient.read` / :meth:`SdoClient.write` take an
:class:`~openel_can.canopen.ObjectEntry` (an int value), or an
:class:`~openel_can.od.OdEntry` or any key of the client's object dictionary ``od`` (a
name such as ``"Target position"``, ``"0x1018:1"``, ``(index, subindex)``): the value is
encoded by the entry's data type and checked against its range and the file's limits,
and a write to an object that is not writable (a read of one that is not readable) is
refused before anything is sent -- ``BadParameterError`` naming the object.
"""

from __future__ import annotations

import asyncio
import math
import struct
from collections import deque
from typing import Final, NoReturn, overload

import anyio
import can

from openel_async.errors import BadParameterError, HALError
from openel_async.logs import get_logger

from . import canopen as co
from .bus import CanBus, NodePort, TxMessage
from .errors import DecodeError
from .od import ObjectDictionary, ObjectKey, OdEntry, OdValue

__all__ = ["DEFAULT_MAX_SIZE", "SdoAbortError", "SdoClient", "SdoTimeoutError"]

log = get_logger(__name__)

_REQUEST_CACHE: Final = 64
"""Encoded upload requests kept per client (then the cache starts again)."""


def _abort_name(code: int) -> str:
    try:
        return co.SdoAbortCode(code).name
    except ValueError:
        return "unknown"


class SdoAbortError(HALError):
    """An SDO transfer was aborted, by the server or (``by_client``) by this client."""

    def __init__(
        self, node_id: int, index: int, subindex: int, code: int, *, by_client: bool = False
    ) -> None:
        who = "aborted by the client" if by_client else f"from node {node_id}"
        super().__init__(
            f"SDO abort {code:#010x} ({_abort_name(code)}) {who} on object "
            f"{index:#06x}:{subindex} of node {node_id}"
        )
        self.node_id = node_id
        self.index = index
        self.subindex = subindex
        self.abort_code = code
        self.by_client = by_client


class SdoTimeoutError(TimeoutError):
    """The SDO server did not answer in time."""


_INITIATE_REPLIES: Final = (
    co.SdoUploadResponse,
    co.SdoSegmentedUploadResponse,
    co.SdoDownloadResponse,
)
_SEGMENT_REPLIES: Final = (co.SdoUploadSegment, co.SdoDownloadSegmentResponse)
_EXPEDITED_UPLOAD_SIZES: Final = {0x43: 4, 0x47: 3, 0x4B: 2, 0x4F: 1}
"""An expedited upload answer's command byte with the size indicated -> its data bytes."""
#: Default largest upload accepted (bytes).
DEFAULT_MAX_SIZE: Final = 65536


class SdoClient:
    """SDO upload/download to one node; see the module docstring."""

    def __init__(
        self,
        bus: CanBus,
        node_id: int,
        *,
        timeout: float = 0.1,
        max_size: int = DEFAULT_MAX_SIZE,
        od: ObjectDictionary | None = None,
    ) -> None:
        if isinstance(node_id, bool) or not isinstance(node_id, int) or not 1 <= node_id <= 127:
            raise BadParameterError("node_id", node_id, "a CANopen node id in 1..127")
        if not (math.isfinite(timeout) and timeout > 0):
            raise BadParameterError("timeout", timeout, "a finite number of seconds > 0")
        if isinstance(max_size, bool) or not isinstance(max_size, int) or not 4 <= max_size < 2**32:
            raise BadParameterError("max_size", max_size, "an int in 4..2**32-1 (bytes)")
        self.bus = bus
        self.node_id = node_id
        self.timeout = timeout
        self.max_size = max_size
        self.od = od
        """The node's object dictionary: objects by name in :meth:`read`/:meth:`write`."""
        self.transfers = 0
        self.segments = 0
        self.aborts = 0
        self.timeouts = 0
        self._lock = _Slot()
        self._port: NodePort | None = None
        # The exchange waiting for an answer (None: answers now are late ones, dropped).
        self._waiting: _Transfer | None = None
        self._replies: tuple[type[co.CanOpenMessage], ...] = ()
        self._answer: asyncio.Future[co.CanOpenMessage | bytes | SdoAbortError | None] | None = None
        # One timer bounds every exchange (see _arm): re-armed only when it would fire
        # after the exchange's deadline, or fires before it.
        self._timer: asyncio.TimerHandle | None = None
        self._timer_loop: asyncio.AbstractEventLoop | None = None
        self._deadline = 0.0
        self._upload_requests: dict[tuple[int, int], tuple[TxMessage, bytes]] = {}

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
                (co.SDO_TX_BASE + self.node_id,),
                name=f"sdo-{self.node_id}",
                handler=self._on_frames,
            )
        return port

    def _on_frames(self, frames: list[can.Message]) -> None:
        """Port handler (event loop): the first frame answering the waiting exchange."""
        transfer, answer, port = self._waiting, self._answer, self._port
        if transfer is None or answer is None or answer.done() or port is None:
            return  # a late answer to an earlier (timed-out) transfer, or a second one
        replies = self._replies
        expedited = transfer.expedited
        for msg in frames:
            if expedited is not None:
                # An upload's initiate: its expedited answer with the size indicated for
                # this object (the usual one) is taken from the bytes, without decoding it
                # into a message; anything else goes the general way below.
                data = msg.data
                if (
                    len(data) == 8
                    and data[0] in _EXPEDITED_UPLOAD_SIZES
                    and data[1:4] == expedited
                    and not msg.is_remote_frame
                ):
                    answer.set_result(bytes(data[4 : 4 + _EXPEDITED_UPLOAD_SIZES[data[0]]]))
                    return
            try:
                reply = transfer.match(port, msg, replies)
            except SdoAbortError as exc:
                answer.set_result(exc)
                return
            if reply is not None:
                answer.set_result(reply)
                return

    # -- typed access ---------------------------------------------------------------------
    def entry(self, key: ObjectKey) -> OdEntry:
        """The entry of :attr:`od` that ``key`` names (``BadParameterError`` when the
        client has no dictionary, :class:`~openel_can.od.ObjectNotFoundError` when the
        dictionary has no such object)."""
        if isinstance(key, OdEntry):
            return key
        if self.od is None:
            raise BadParameterError(
                "object",
                key,
                f"an OdEntry or an ObjectEntry: node {self.node_id}'s SDO client has no object "
                "dictionary to look names up in (SdoClient.od = openel_can.od.load_od(...))",
            )
        return self.od.entry(key)

    @overload
    async def read(self, entry: co.ObjectEntry, *, timeout: float | None = None) -> int: ...  # noqa: ASYNC109

    @overload
    async def read(
        self,
        entry: OdEntry | str | int | tuple[int, int],
        *,
        timeout: float | None = None,  # noqa: ASYNC109
    ) -> OdValue: ...

    async def read(self, entry: ObjectKey, *, timeout: float | None = None) -> OdValue:  # noqa: ASYNC109
        """The object's value: an int for an ObjectEntry, else as its data type says."""
        if isinstance(entry, co.ObjectEntry):
            data = await self.upload(entry.index, entry.subindex, timeout=timeout)
            try:
                return entry.decode(data)
            except DecodeError as exc:
                raise HALError(
                    f"node {self.node_id}: bad SDO value for {entry.index:#06x}:"
                    f"{entry.subindex}: {exc}"
                ) from exc
        od_entry = self.entry(entry)
        if not od_entry.readable:
            raise BadParameterError(
                od_entry.label, "read", f"a readable object: its access is {od_entry.access}"
            )
        data = await self.upload(od_entry.index, od_entry.subindex, timeout=timeout)
        try:
            return od_entry.decode(data)
        except DecodeError as exc:
            raise HALError(
                f"node {self.node_id}: bad SDO value for {od_entry.label}: {exc}"
            ) from exc

    async def write(
        self,
        entry: ObjectKey,
        value: object,
        *,
        timeout: float | None = None,  # noqa: ASYNC109
    ) -> None:
        """Write ``value`` encoded by the entry's data type (checked before sending)."""
        if isinstance(entry, co.ObjectEntry):
            try:
                data = entry.encode(value)  # type: ignore[arg-type]
            except (ValueError, TypeError, struct.error) as exc:
                raise BadParameterError(
                    f"{entry.index:#06x}:{entry.subindex}", value, f"a {entry.data_type.name}"
                ) from exc
            await self.download(entry.index, entry.subindex, data, timeout=timeout)
            return
        od_entry = self.entry(entry)
        if not od_entry.writable:
            raise BadParameterError(
                od_entry.label, value, f"a writable object: its access is {od_entry.access}"
            )
        data = od_entry.encode(value)
        await self.download(od_entry.index, od_entry.subindex, data, timeout=timeout)

    # -- raw transfers --------------------------------------------------------------------
    async def upload(self, index: int, subindex: int, *, timeout: float | None = None) -> bytes:  # noqa: ASYNC109
        """The object's bytes, expedited or segmented as the server chooses."""
        request, expedited = self._upload_request(index, subindex)
        t = _Transfer(self, index, subindex, self.timeout if timeout is None else timeout)
        slot = self._lock
        if slot.busy:
            await slot.wait()
        else:
            slot.busy = True  # free: taken without a coroutine (``async with`` makes two)
        try:
            t.port = self._begin()
            t.expedited = expedited
            reply = await t.exchange_frame(request, _INITIATE_REPLIES)
            t.expedited = None
            if isinstance(reply, bytes):
                return reply
            if isinstance(reply, co.SdoUploadResponse):
                return reply.data
            if not isinstance(reply, co.SdoSegmentedUploadResponse):
                await t.fail(co.SdoAbortCode.INVALID_COMMAND_SPECIFIER)
            assert isinstance(reply, co.SdoSegmentedUploadResponse)
            if reply.size is not None and reply.size > self.max_size:
                await t.fail(co.SdoAbortCode.OUT_OF_MEMORY)
            data = bytearray()
            toggle = False
            while True:
                segment = await t.exchange(
                    co.SdoUploadSegmentRequest(self.node_id, toggle), _SEGMENT_REPLIES
                )
                if not isinstance(segment, co.SdoUploadSegment):
                    await t.fail(co.SdoAbortCode.INVALID_COMMAND_SPECIFIER)
                assert isinstance(segment, co.SdoUploadSegment)
                if segment.toggle is not toggle:
                    await t.fail(co.SdoAbortCode.TOGGLE_BIT_NOT_ALTERNATED)
                data += segment.data
                if len(data) > self.max_size:
                    await t.fail(co.SdoAbortCode.OUT_OF_MEMORY)
                if reply.size is not None and len(data) > reply.size:
                    await t.fail(co.SdoAbortCode.LENGTH_MISMATCH)
                if segment.last:
                    break
                toggle = not toggle
            if reply.size is not None and len(data) != reply.size:
                await t.fail(co.SdoAbortCode.LENGTH_MISMATCH)
            return bytes(data)
        finally:
            slot.release()

    async def download(
        self,
        index: int,
        subindex: int,
        data: bytes,
        *,
        timeout: float | None = None,  # noqa: ASYNC109
    ) -> None:
        """Write ``data``: expedited for 1..4 bytes, segmented otherwise."""
        data = bytes(data)
        if len(data) > self.max_size:
            raise BadParameterError("data", f"{len(data)} bytes", f"at most {self.max_size} bytes")
        t = _Transfer(self, index, subindex, self.timeout if timeout is None else timeout)
        async with self._lock:
            t.port = self._begin()
            if 1 <= len(data) <= 4:
                request: co.CanOpenMessage = co.SdoDownloadRequest(
                    self.node_id, index, subindex, data
                )
            else:
                request = co.SdoSegmentedDownloadRequest(self.node_id, index, subindex, len(data))
            reply = await t.exchange(request, _INITIATE_REPLIES)
            if not isinstance(reply, co.SdoDownloadResponse):
                await t.fail(co.SdoAbortCode.INVALID_COMMAND_SPECIFIER)
            if isinstance(request, co.SdoDownloadRequest):
                return
            toggle = False
            step = co.SDO_SEGMENT_SIZE
            offsets = range(0, max(len(data), 1), step)
            for offset in offsets:
                chunk = data[offset : offset + step]
                last = offset + step >= len(data)
                segment = co.SdoDownloadSegment(self.node_id, toggle, chunk, last)
                answer = await t.exchange(segment, _SEGMENT_REPLIES)
                if not isinstance(answer, co.SdoDownloadSegmentResponse):
                    await t.fail(co.SdoAbortCode.INVALID_COMMAND_SPECIFIER)
                assert isinstance(answer, co.SdoDownloadSegmentResponse)
                if answer.toggle is not toggle:
                    await t.fail(co.SdoAbortCode.TOGGLE_BIT_NOT_ALTERNATED)
                toggle = not toggle

    def _upload_request(self, index: int, subindex: int) -> tuple[TxMessage, bytes]:
        """The upload initiate of ``index``:``subindex`` as a frame, and its bytes 1..3 (the
        index and subindex as the answer carries them): checked, encoded and built once,
        then kept (a node's few polled objects are not encoded again per transfer; the
        frame is never changed, so it is sent again as is)."""
        plain = type(index) is int and type(subindex) is int
        requests = self._upload_requests
        if plain:
            encoded = requests.get((index, subindex))
            if encoded is not None:
                return encoded
        cob_id, data = co.encode(co.SdoUploadRequest(self.node_id, index, subindex))
        encoded = (TxMessage.frame(cob_id, data, False, False), bytes(data[1:4]))
        if plain:
            if len(requests) >= _REQUEST_CACHE:
                requests.clear()
            requests[(index, subindex)] = encoded
        return encoded

    def _arm(self, loop: asyncio.AbstractEventLoop, deadline: float) -> None:
        """Make the exchange in flight end at ``deadline`` (loop time).

        One timer serves every exchange: it is replaced only when it would fire after
        ``deadline`` (or belongs to another loop); when it fires before the deadline of
        the exchange then in flight it is set again for it. Back-to-back exchanges cost
        no timer each (a timer handle pushed on and popped off the loop's heap, whose
        order is Python comparisons), and every wait still ends at its own deadline.
        """
        self._deadline = deadline
        timer = self._timer
        if timer is not None:
            if timer.when() <= deadline and self._timer_loop is loop and not timer.cancelled():
                return
            timer.cancel()
        self._timer = loop.call_at(deadline, self._timer_fired, loop)
        self._timer_loop = loop

    def _timer_fired(self, loop: asyncio.AbstractEventLoop) -> None:
        self._timer = None
        answer = self._answer
        if answer is None or answer.done():
            return  # no exchange in flight: no timer until the next one
        if loop.time() >= self._deadline:
            answer.set_result(None)  # timed out
        else:
            self._timer = loop.call_at(self._deadline, self._timer_fired, loop)

    def _begin(self) -> NodePort:
        port = self._ensure_port()  # answers arriving while no exchange waits are dropped
        self.transfers += 1
        return port


class _Slot:
    """The node's one transfer at a time: a FIFO lock for asyncio that costs two attribute
    writes when free (``anyio.Lock`` asks anyio for the backend and checks for
    cancellation on every acquire: a tenth of an upload's CPU on the virtual bus).

    ``async with slot:``, or (the upload's path, without the two coroutines) ``if
    slot.busy: await slot.wait()`` else ``slot.busy = True``, then ``slot.release()``
    in a ``finally``."""

    __slots__ = ("_waiters", "busy")

    def __init__(self) -> None:
        self.busy = False
        self._waiters: deque[asyncio.Future[None]] = deque()

    async def __aenter__(self) -> None:
        if not self.busy:
            self.busy = True
            return
        await self.wait()

    async def wait(self) -> None:
        """Queue for the busy slot; it is this task's when this returns."""
        waiter: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        self._waiters.append(waiter)
        try:
            await waiter  # the slot is handed over with the result: still busy
        except BaseException:
            if waiter.done() and not waiter.cancelled():
                self.release()  # handed over, but this task was cancelled: pass it on
            elif waiter in self._waiters:  # (a cancelled one may have been skipped already)
                self._waiters.remove(waiter)
            raise

    async def __aexit__(self, *exc: object) -> None:
        self.release()

    def release(self) -> None:
        waiters = self._waiters
        while waiters:
            waiter = waiters.popleft()
            if not waiter.done():
                waiter.set_result(None)
                return
        self.busy = False


class _Transfer:
    """One transfer in progress: its object, its bound per exchange, its port."""

    def __init__(self, client: SdoClient, index: int, subindex: int, limit: float) -> None:
        self.client = client
        self.node_id = client.node_id
        self.index = index
        self.subindex = subindex
        self.limit = limit
        self.port: NodePort | None = None
        self.expedited: bytes | None = None
        """While an upload's initiate waits: the index and subindex as an expedited answer
        carries them (bytes 1..3), to take that answer from its bytes."""

    async def exchange(
        self, request: co.CanOpenMessage, replies: tuple[type[co.CanOpenMessage], ...]
    ) -> co.CanOpenMessage | bytes:
        """Send ``request``; the first answer of the kinds in ``replies`` (or an abort); for
        an upload's initiate (:attr:`expedited` set), an expedited answer's data bytes."""
        cob_id, data = co.encode(request)
        return await self.exchange_frame(TxMessage.frame(cob_id, data, False, False), replies)

    async def exchange_frame(
        self, request: TxMessage, replies: tuple[type[co.CanOpenMessage], ...]
    ) -> co.CanOpenMessage | bytes:
        """:meth:`exchange` of a request already built as a frame (kept unchanged)."""
        port = self.port
        client = self.client
        assert port is not None
        if replies is _SEGMENT_REPLIES:
            client.segments += 1
        # The answer slot: resolved by the port handler with the answer, or with None by
        # the client's timer when ``limit`` passes (a future and a shared timer: the
        # cheapest bounded wait on asyncio; cancelling the task cancels the wait).
        loop = asyncio.get_running_loop()
        answer: asyncio.Future[co.CanOpenMessage | bytes | SdoAbortError | None] = (
            loop.create_future()
        )
        client._waiting, client._replies, client._answer = self, replies, answer
        try:
            if not port.try_send_frame(request):  # inline: no coroutine
                await port.send_frame(request)  # may wait for room (send_timeout), not counted
            client._arm(loop, loop.time() + self.limit)
            outcome = await answer
        finally:
            client._waiting = client._answer = None
        if isinstance(outcome, SdoAbortError):
            client.aborts += 1
            raise outcome
        if outcome is not None:
            return outcome
        client.timeouts += 1
        await self._send_abort(co.SdoAbortCode.TIMEOUT)
        raise SdoTimeoutError(
            f"node {self.node_id}: no SDO answer for {self.index:#06x}:"
            f"{self.subindex} within {self.limit * 1000:.0f} ms"
        )

    def match(
        self, port: NodePort, msg: can.Message, replies: tuple[type[co.CanOpenMessage], ...]
    ) -> co.CanOpenMessage | None:
        if msg.is_remote_frame:
            port.malformed += 1
            return None
        try:
            reply = co.decode(msg.arbitration_id, msg.data)
        except DecodeError:
            port.malformed += 1
            return None
        initiate = replies is _INITIATE_REPLIES
        if isinstance(reply, co.SdoAbort):
            # During the segments any abort is for this transfer (one at a time per server).
            if initiate and (reply.index, reply.subindex) != (self.index, self.subindex):
                return None
            raise SdoAbortError(self.node_id, self.index, self.subindex, reply.code)
        if not isinstance(reply, _INITIATE_REPLIES + _SEGMENT_REPLIES):
            return None
        if initiate:
            if not isinstance(reply, _INITIATE_REPLIES) or (
                reply.index,
                reply.subindex,
            ) != (self.index, self.subindex):
                return None  # an answer to someone else's transfer or a stale one
        elif isinstance(reply, _INITIATE_REPLIES):
            return None  # a stale initiate answer; the segment answer is still due
        return reply

    async def fail(self, code: co.SdoAbortCode) -> NoReturn:
        """Abort the transfer from the client side and raise."""
        await self._send_abort(code)
        self.client.aborts += 1
        raise SdoAbortError(self.node_id, self.index, self.subindex, code, by_client=True)

    async def _send_abort(self, code: int) -> None:
        assert self.port is not None
        abort = co.SdoAbort(self.node_id, self.index, self.subindex, code, from_client=True)
        cob_id, data = co.encode(abort)
        try:
            with anyio.move_on_after(self.client.timeout):
                await self.port.send(cob_id, data)
        except Exception as exc:  # best effort: the bus may be why it timed out
            log.debug("sdo_abort_not_sent", node=self.node_id, error=repr(exc))
