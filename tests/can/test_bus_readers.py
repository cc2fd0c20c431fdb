"""CanBus readers: python-can virtual and socketcan-like buses read in the loop, one reader
thread otherwise.

Both hand frames to the event loop in order, bound what waits for the loop (``rx_buffer``,
drops counted in ``stats.rx_overflow``), leave no thread behind and survive a reopen.
Also: handler ports, TxMessage's deep copy, inline sends yielding, SDO cancellation.
"""

from __future__ import annotations

import copy
import os
import queue
import socket
import struct
import threading
from collections.abc import AsyncIterator, Iterator
from contextlib import asynccontextmanager

import anyio
import anyio.lowlevel
import can
import pytest
from can.interfaces.virtual import VirtualBus

from openel_async import EventTimer
from openel_async.errors import BadParameterError
from openel_can import BusState, CanBus, CanSync, SdoClient, TxMessage
from openel_can import canopen as co
from openel_can import cia402 as ds
from openel_can.sim.cia402 import SimCia402Drive
from openel_can.sim.faults import BusLink
from openel_can.virtual_rx import WakingQueue, virtual_sender

from .conftest import Peers, drain, wait_until


def _frame(arb_id: int, i: int) -> can.Message:
    return can.Message(arbitration_id=arb_id, data=i.to_bytes(2, "little"), is_extended_id=False)


def _reader_threads() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name.startswith("can-reader-")]


async def _collect(port: object, count: int) -> list[int]:
    from openel_can import NodePort

    assert isinstance(port, NodePort)
    got: list[int] = []
    with anyio.fail_after(5):
        while len(got) < count:
            got += [int.from_bytes(m.data, "little") for m in await port.receive()]
    return got


# -- python-can virtual: read in the event loop --------------------------------------------
async def test_virtual_bus_is_read_in_the_loop_in_order_without_a_thread(
    channel: str, raw_bus: can.BusABC
) -> None:
    async with CanBus(interface="virtual", channel=channel, port_queue_size=4096) as bus:
        port = bus.attach([0x123], name="rx")
        assert bus.reads_in_loop == 1 and bus.reader_threads == 0
        assert isinstance(bus.bus, can.BusABC)
        assert isinstance(bus.bus.queue, WakingQueue)  # type: ignore[attr-defined]
        assert not _reader_threads()

        def produce() -> None:  # another thread, as a peer or a notifier would
            for i in range(3000):
                raw_bus.send(_frame(0x123, i))

        sender = threading.Thread(target=produce)
        sender.start()
        try:
            assert await _collect(port, 3000) == list(range(3000))
        finally:
            sender.join(5)
        assert bus.stats.rx_frames == 3000 and bus.stats.rx_overflow == 0
        if hasattr(os, "eventfd"):  # Linux: the senders wake the loop through an eventfd
            assert bus._virtual_wake_fd is not None
        bus._virtual_wake_pending = True  # as if a wake-up were written and never read
    assert bus._virtual_wake_fd is None  # closed at exit
    assert not bus._virtual_wake_pending  # a reader of a reopened bus can be woken
    bus._wake_virtual()  # a sender late past the unhook: no error, nothing written


async def test_virtual_overflow_beyond_rx_buffer_is_dropped_and_counted(
    channel: str, raw_bus: can.BusABC
) -> None:
    async with CanBus(interface="virtual", channel=channel, rx_buffer=10) as bus:
        port = bus.attach([0x200], name="rx")
        for i in range(25):  # the loop cannot drain between these synchronous puts
            raw_bus.send(_frame(0x200, i))
        assert await _collect(port, 10) == list(range(10))
        await wait_until(lambda: bus.stats.rx_overflow == 15, 1)
        raw_bus.send(_frame(0x200, 99))  # room again
        assert await _collect(port, 1) == [99]
        assert bus.stats.rx_frames == 11


async def test_a_given_virtual_bus_is_unhooked_at_exit(channel: str, raw_bus: can.BusABC) -> None:
    given = can.Bus(interface="virtual", channel=channel)
    try:
        async with CanBus(given) as bus:
            assert type(given.queue) is WakingQueue  # type: ignore[attr-defined]
            port = bus.attach([0x300], name="rx")
            raw_bus.send(_frame(0x300, 1))
            assert await _collect(port, 1) == [1]
        assert type(given.queue) is queue.Queue  # type: ignore[attr-defined]
        raw_bus.send(_frame(0x300, 2))  # still a working python-can bus for its owner
        msg = given.recv(1.0)
        assert msg is not None and msg.data == b"\x02\x00"
    finally:
        given.shutdown()


async def test_a_given_virtual_bus_shut_down_by_its_owner_takes_the_bus_down(
    channel: str,
) -> None:
    given = can.Bus(interface="virtual", channel=channel)
    reasons: list[str] = []
    async with CanBus(given, poll_interval=0.01, reconnect_backoff=(0.01, 0.02)) as bus:
        bus.attach([0x100], name="node", on_bus_error=reasons.append)
        given.shutdown()  # the idle check's recv(0) raises
        await wait_until(lambda: bus.state is BusState.DOWN, 1)
    assert reasons and "receive failed" in reasons[0]


async def test_python_can_filters_apply_on_the_virtual_path(
    channel: str, raw_bus: can.BusABC
) -> None:
    async with CanBus(
        interface="virtual",
        channel=channel,
        can_filters=[{"can_id": 0x100, "can_mask": 0x7FF, "extended": False}],
    ) as bus:
        port = bus.attach([0x100, 0x101], name="rx")
        for i, arb_id in enumerate((0x101, 0x100, 0x101, 0x100)):
            raw_bus.send(_frame(arb_id, i))
        assert await _collect(port, 2) == [1, 3]
        assert bus.stats.unrouted == 0 and bus.stats.rx_frames == 2


# -- every other interface: one reader thread ------------------------------------------------
async def test_reader_thread_delivers_in_order_restarts_on_reopen_and_is_joined(
    channel: str, raw_bus: can.BusABC
) -> None:
    link = BusLink(channel)  # FlakyBus: not a VirtualBus, so read by a thread
    async with CanBus(
        bus_factory=link.open,
        poll_interval=0.01,
        reconnect_backoff=(0.01, 0.02),
        port_queue_size=4096,
    ) as bus:
        port = bus.attach([0x123], name="rx")
        assert bus.reader_threads == 1 and bus.reads_in_loop == 0
        assert len(_reader_threads()) == 1
        for i in range(2000):
            raw_bus.send(_frame(0x123, i))
        assert await _collect(port, 2000) == list(range(2000))
        link.fail()
        await wait_until(lambda: bus.state is BusState.DOWN, 1)
        link.restore()
        await bus.wait_up(1)
        await wait_until(lambda: bus.reader_threads == 2, 1)
        await wait_until(lambda: len(_reader_threads()) == 1, 1)  # the old one has ended
        raw_bus.send(_frame(0x123, 7))
        assert await _collect(port, 1) == [7]
    assert not _reader_threads()


# -- a bus with a file descriptor (socketcan; read_mode="loop"): read in the loop ----------
_PAIR_FRAME = struct.Struct("=IB3x8s")


class _PairBus(can.BusABC):
    """A bus on one end of a SOCK_SEQPACKET pair (one frame a datagram), with a fileno."""

    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock
        sock.setblocking(False)
        super().__init__(channel="pair")

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self.sock.send(_PAIR_FRAME.pack(msg.arbitration_id, msg.dlc, bytes(msg.data)))

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        try:
            data = self.sock.recv(_PAIR_FRAME.size)
        except BlockingIOError:
            return None, False  # the CanBus reads it in the loop: recv(0) only
        if not data:
            raise can.CanOperationError("the other end closed")
        arb, dlc, payload = _PAIR_FRAME.unpack(data)
        return can.Message(arbitration_id=arb, data=payload[:dlc], is_extended_id=False), False

    def fileno(self) -> int:
        return self.sock.fileno()


async def test_a_bus_with_a_fileno_is_read_in_the_loop_in_order_and_its_failure_reported() -> None:
    ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    bus_end, far = _PairBus(ours), _PairBus(theirs)
    try:
        async with CanBus(
            bus_end, read_mode="loop", max_batch=7, poll_interval=0.01, port_queue_size=4096
        ) as bus:
            port = bus.attach([0x123], name="rx")
            assert bus.reads_in_loop == 1 and bus.reader_threads == 0
            assert not _reader_threads()
            for start in (0, 100, 200):  # batches of max_batch, the rest in later drains
                for i in range(start, start + 100):
                    far.send(_frame(0x123, i))
                assert await _collect(port, 100) == list(range(start, start + 100))
            theirs.close()  # the far end goes away: recv raises, the bus goes down
            await wait_until(lambda: bus.state is BusState.DOWN, 2)
            assert "the other end closed" in (bus.last_error or "")
    finally:
        ours.close()
        theirs.close()


def _queued(port: object) -> list[int]:
    """Every frame waiting in ``port`` now (no wait)."""
    from openel_can import NodePort

    assert isinstance(port, NodePort)
    got: list[int] = []
    while True:
        try:
            got += [int.from_bytes(m.data, "little") for m in port.receive_nowait()]
        except anyio.WouldBlock:
            return got


async def _loop_passes(n: int = 5) -> None:
    for _ in range(n):  # a registered reader of a readable socket runs in the first pass
        await anyio.lowlevel.checkpoint()


async def test_read_now_reads_at_once_then_holds_the_socket_until_the_next_call() -> None:
    ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    far = _PairBus(theirs)
    try:
        async with CanBus(_PairBus(ours), read_mode="loop", poll_interval=30.0) as bus:
            port = bus.attach([0x181], name="rx")
            far.send(_frame(0x181, 1))
            assert bus.read_now(30.0)  # read and dispatched before it returns
            assert _queued(port) == [1]
            far.send(_frame(0x181, 2))
            far.send(_frame(0x181, 3))
            await _loop_passes()
            assert _queued(port) == []  # held: left in the socket
            assert bus.read_now(0.05)
            assert _queued(port) == [2, 3]
            far.send(_frame(0x181, 4))  # nobody calls again: read as it arrives once the
            assert await _collect(port, 1) == [4]  # hold ran out
            far.send(_frame(0x181, 5))
            await _loop_passes()
            assert _queued(port) == [5]  # the reader is registered again
            assert bus.read_now(0.0)  # a zero hold: registered again at once
            far.send(_frame(0x181, 6))
            await _loop_passes()
            assert _queued(port) == [6]
            assert bus.reads_on_demand == 3
    finally:
        ours.close()
        theirs.close()


async def test_read_now_is_refused_on_a_bus_not_read_through_its_descriptor() -> None:
    async with CanBus(interface="virtual", channel="read-now", poll_interval=0.01) as bus:
        assert bus.read_now(1.0) is False
    ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    try:
        async with CanBus(_PairBus(ours), read_mode="thread", poll_interval=0.01) as bus:
            assert bus.read_now(1.0) is False and bus.reads_on_demand == 0
    finally:
        ours.close()
        theirs.close()


def _ids(bus: can.BusABC) -> list[int]:
    """The arbitration ids of every frame waiting on a raw bus."""
    return [msg.arbitration_id for msg in drain(bus)]


def _tick(timer: object) -> None:
    """One tick by hand, as the timer delivers it: every observer's ``notify_timer`` in
    registration order (the order taken when the tick starts)."""
    from openel_async import EventTimer

    assert isinstance(timer, EventTimer)
    for observer in timer.observers:
        observer.notify_timer(timer)  # type: ignore[attr-defined]


async def test_can_sync_sends_sync_first_at_each_tick_then_reads_the_bus() -> None:
    from openel_async import EventTimer
    from openel_can import CanSync

    ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    far = _PairBus(theirs)
    try:
        async with CanBus(
            _PairBus(ours), read_mode="loop", send_mode="inline", poll_interval=30.0
        ) as bus:
            port = bus.attach([0x181], name="tpdo")
            timer = EventTimer(2.0, name="by-hand")  # ticked by hand: notify_timer
            sync = CanSync.of(bus)
            await sync.start(timer)
            _tick(timer)  # tick 1: SYNC 1, nothing to read
            assert _ids(far) == [co.SYNC_COB_ID]
            sync.stage(0x201, bytes(6))  # a set-point: out when the stager yields
            sync.stage(0x202, bytes(6))
            sync.stage(0x201, bytes(range(6)))  # a newer one replaces it
            far.send(_frame(0x181, 7))  # a drive's TPDO answering SYNC 1
            await _loop_passes()
            assert _ids(far) == [0x201, 0x202]  # before the next tick, one per drive
            assert _queued(port) == []  # the TPDO: left for the next tick
            sync.stage(0x203, bytes(6))  # staged in the tick's own pass: out before SYNC
            _tick(timer)  # tick 2: SYNC 2, then the read (as cycle 1's)
            assert _ids(far) == [0x203, co.SYNC_COB_ID]
            assert _queued(port) == [7]
            assert sync.cycle == 2 and bus.reads_on_demand == 2
            assert sync.stats.rpdos == 3 and sync.stats.late_feedback == 0
            await _loop_passes()
            assert _ids(far) == []  # nothing staged twice
            sync.stop()  # the bus read as frames arrive again, at once
            far.send(_frame(0x181, 8))
            await _loop_passes()
            assert _queued(port) == [8]
            await sync.start(timer, read_on_tick=False)
            _tick(timer)
            far.send(_frame(0x181, 9))
            await _loop_passes()
            assert _queued(port) == [9] and bus.reads_on_demand == 3  # the stop's
            sync.stop()
    finally:
        ours.close()
        theirs.close()


class _Stager:
    """A plain timer observer staging one RPDO per tick (an AxisGroup's set-point)."""

    def __init__(self, sync: object, cob_id: int) -> None:
        self.sync = sync
        self.cob_id = cob_id
        self.ticks = 0

    def notify_timer(self, timer: object) -> None:
        self.ticks += 1
        self.sync.stage(self.cob_id, bytes([self.ticks] * 6))  # type: ignore[attr-defined]


@asynccontextmanager
async def _synced_by_hand() -> AsyncIterator[tuple[_PairBus, EventTimer, CanSync]]:
    """A CanBus over a socket pair with a CanSync started on a timer ticked by hand: the
    far end of the pair, the timer and the sync."""
    ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    try:
        async with CanBus(
            _PairBus(ours), read_mode="loop", send_mode="inline", poll_interval=30.0
        ) as bus:
            timer = EventTimer(2.0, name="by-hand")
            sync = CanSync.of(bus)
            await sync.start(timer)
            yield _PairBus(theirs), timer, sync
    finally:
        ours.close()
        theirs.close()


async def test_what_an_observer_stages_in_a_tick_goes_out_at_the_tick_end() -> None:
    """Staged by an observer after the producer's SYNC: sent by the producer's tail
    observer, at the end of the same tick (no event-loop pass). An observer added after
    start stages after the tail at first (sent when it yields); the next tick moves the
    tail last."""
    async with _synced_by_hand() as (far, timer, sync):
        head_and_tail = timer.observers
        assert len(head_and_tail) == 2 and head_and_tail[0] is sync
        stager = _Stager(sync, 0x201)
        timer.add_observer(stager)  # after the tail: its first set-point waits a pass
        for _ in range(2):  # the tail is moved last by the tick after a stray stage
            _tick(timer)
            assert _ids(far) == [co.SYNC_COB_ID]
            await _loop_passes()
            assert _ids(far) == [0x201]
        assert timer.observers == (sync, stager, head_and_tail[1])
        for n in (3, 4):
            _tick(timer)  # SYNC, then the set-point staged in the tick, at its end
            frames = drain(far)
            assert [m.arbitration_id for m in frames] == [co.SYNC_COB_ID, 0x201]
            assert frames[1].data[0] == n
        await _loop_passes()
        assert _ids(far) == []  # nothing left for a later pass
        assert sync.stats.rpdos == 4 and sync.stats.dropped_rpdos == 0
        timer.remove_observer(head_and_tail[1])  # the tail removed by someone else:
        _tick(timer)  # this tick's set-point waits for the next tick's SYNC...
        assert _ids(far) == [co.SYNC_COB_ID]
        _tick(timer)  # ... which sends it first and puts the tail back (last)
        assert _ids(far) == [0x201, co.SYNC_COB_ID]
        assert timer.observers[-1] is head_and_tail[1]
        _tick(timer)  # the set-point staged in that tick before this SYNC, then as before
        assert _ids(far) == [0x201, co.SYNC_COB_ID, 0x201]
        sync.stop()
        assert timer.observers == (stager,)


async def test_a_task_staging_every_cycle_has_the_observers_looked_at_once_per_64(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Set-points staged outside the ticks (a task awaiting ``set_value``) go out when it
    yields; the tail's place is looked at again only every 64 cycles, not each tick."""
    from openel_can import sync as sync_module

    looked: list[int] = []
    place = sync_module.CanSync._place_tail
    async with _synced_by_hand() as (far, timer, sync):

        def counted(self: CanSync, timer: EventTimer) -> None:
            looked.append(self.cycle)
            place(self, timer)

        monkeypatch.setattr(sync_module.CanSync, "_place_tail", counted)
        for _ in range(130):
            _tick(timer)
            sync.stage(0x201, bytes(6))  # outside the tick
            await _loop_passes(1)
            assert _ids(far) == [co.SYNC_COB_ID, 0x201]
        assert looked == [1, 65, 129]
        sync.stop()


async def test_read_mode_thread_reads_a_fileno_bus_in_a_thread_and_auto_only_socketcan() -> None:
    for mode, threads in (("thread", 1), ("auto", 1)):
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        try:
            async with CanBus(_PairBus(ours), read_mode=mode, poll_interval=0.01) as bus:  # type: ignore[arg-type]
                assert bus.reader_threads == threads and bus.reads_in_loop == 1 - threads
        finally:
            ours.close()
            theirs.close()
    with pytest.raises(BadParameterError, match="read_mode"):
        CanBus(interface="virtual", channel="x", read_mode="poll")  # type: ignore[arg-type]


class _ListBus(can.BusABC):
    """After ``go``: its frames one per ``recv``, then blocks (bounded) and sets ``exhausted``."""

    def __init__(self, frames: list[can.Message]) -> None:
        super().__init__(channel="list")
        self.frames: Iterator[can.Message] = iter(frames)
        self.go = threading.Event()
        self.exhausted = threading.Event()
        self._idle = threading.Event()

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        pass

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if not self.go.wait(min(timeout or 0.0, 0.01)):
            return None, False
        msg = next(self.frames, None)
        if msg is None:
            self.exhausted.set()
            self._idle.wait(min(timeout or 0.0, 0.01))
        return msg, False


async def test_reader_thread_overflow_beyond_rx_buffer_is_dropped_and_counted() -> None:
    fake = _ListBus([_frame(0x10, i) for i in range(20)])
    try:
        async with CanBus(fake, rx_buffer=5, max_batch=1, poll_interval=0.01) as bus:
            port = bus.attach([0x10], name="rx")
            fake.go.set()
            # Block the loop (deliberately) until the thread has read every frame: it can
            # hand 5 frames over, the other 15 are dropped.
            assert fake.exhausted.wait(5)
            assert await _collect(port, 5) == list(range(5))
            await wait_until(lambda: bus.stats.rx_overflow == 15, 1)
            assert bus.stats.rx_frames == 5
    finally:
        fake.shutdown()


# -- handler ports, TxMessage, inline sends --------------------------------------------------
async def test_a_handler_port_gets_batches_in_the_loop_and_a_failing_handler_is_counted(
    channel: str, raw_bus: can.BusABC
) -> None:
    async with CanBus(interface="virtual", channel=channel) as bus:
        seen: list[int] = []

        def handler(frames: list[can.Message]) -> None:
            for msg in frames:
                if msg.data[0] == 0xFF:
                    raise ValueError("driver bug")
                seen.append(msg.data[0])

        port = bus.attach([0x400], name="handled", handler=handler)
        queued = bus.attach([0x400], name="queued")
        with pytest.raises(RuntimeError, match="handler"):
            await port.receive()
        with pytest.raises(RuntimeError, match="handler"):
            port.receive_nowait()
        raw_bus.send(can.Message(arbitration_id=0x400, data=b"\x01", is_extended_id=False))
        await wait_until(lambda: seen == [1], 1)
        raw_bus.send(can.Message(arbitration_id=0x400, data=b"\xff", is_extended_id=False))
        await wait_until(lambda: port.dropped == 1, 1)
        raw_bus.send(can.Message(arbitration_id=0x400, data=b"\x02", is_extended_id=False))
        await wait_until(lambda: seen == [1, 2], 1)
        got = drain_port(queued)
        assert [m.data[0] for m in got] == [1, 0xFF, 2]  # the other port is unaffected
        assert port.received == 3


def drain_port(port: object) -> list[can.Message]:
    from openel_can import NodePort

    assert isinstance(port, NodePort)
    frames: list[can.Message] = []
    while True:
        try:
            frames += port.receive_nowait()
        except anyio.WouldBlock:
            return frames


def test_tx_message_deep_copy_is_an_equal_independent_plain_message() -> None:
    msg = TxMessage(arbitration_id=0x1ABCDE, data=b"\x01\x02\x03", is_extended_id=True, channel="c")
    dup = copy.deepcopy(msg)
    assert type(dup) is can.Message
    assert dup.equals(msg) and dup.channel == "c" and dup.dlc == 3
    dup.data[0] = 0x7F
    assert msg.data[0] == 0x01  # the data was copied
    for arb_id, data, extended, remote in (
        (0x123, b"\x05\x06", False, False),
        (0x1F, b"", True, True),
    ):
        fast = TxMessage.frame(arb_id, data, extended, remote)
        slow = TxMessage(
            arbitration_id=arb_id, data=data, is_extended_id=extended, is_remote_frame=remote
        )
        fields = [name for name in can.Message.__slots__ if name != "__weakref__"]
        assert {f: getattr(fast, f) for f in fields} == {f: getattr(slow, f) for f in fields}
    odd = TxMessage(arbitration_id=1, data=b"", is_extended_id=False, channel=("a", [1]))  # type: ignore[arg-type]
    dup2 = copy.deepcopy(odd)
    assert dup2.channel == ("a", [1]) and dup2.channel is not odd.channel


def test_virtual_sender_delivers_what_python_can_send_delivers(channel: str) -> None:
    """Same frames to every other queue (own one with receive_own_messages), stamped alike;
    a full bounded receiver and a closed bus raise as python-can's send does."""
    fields = [n for n in can.Message.__slots__ if n not in ("__weakref__", "timestamp")]
    sender = can.Bus(interface="virtual", channel=channel, receive_own_messages=True)
    peer = can.Bus(interface="virtual", channel=channel)
    try:
        fast = virtual_sender(sender, TxMessage)
        assert fast is not None
        msgs: list[can.Message] = [TxMessage.frame(0x601, b"\x40\x41\x60\x00", False, False)]
        msgs.append(can.Message(arbitration_id=0x1ABCDE, data=b"\x01", is_extended_id=True))
        for msg in msgs:
            for send in (sender.send, fast):
                send(msg, 0.0)
            for bus in (peer, sender):
                a, b = bus.recv(0), bus.recv(0)
                assert a is not None and b is not None and a is not msg
                assert {f: getattr(a, f) for f in fields} == {f: getattr(b, f) for f in fields}
                assert type(b) is can.Message and b.is_rx is (bus is peer)
                assert abs(a.timestamp - b.timestamp) < 5
        small = can.Bus(interface="virtual", channel=channel, rx_queue_size=1)
        try:
            fast(msgs[0], 0.0)
            with pytest.raises(can.CanOperationError, match="recipients"):
                fast(msgs[0], 0.0)
        finally:
            small.shutdown()
    finally:
        sender.shutdown()
        peer.shutdown()
    with pytest.raises(can.CanOperationError, match="closed"):
        fast(msgs[0], 0.0)
    other = _SubclassedVirtualBus(channel=channel)
    try:
        assert virtual_sender(other, TxMessage) is None  # only python-can's own class
    finally:
        other.shutdown()


class _SubclassedVirtualBus(VirtualBus):
    pass


async def test_inline_sends_yield_to_the_loop_every_64(channel: str, raw_bus: can.BusABC) -> None:
    async with CanBus(interface="virtual", channel=channel) as bus:
        port = bus.attach([], name="tx")
        turns = 0

        async def other() -> None:
            nonlocal turns
            while True:
                turns += 1
                await anyio.lowlevel.checkpoint()

        async with anyio.create_task_group() as tg:
            tg.start_soon(other)
            await anyio.lowlevel.checkpoint()
            before = turns
            for i in range(640):
                await port.send(0x500, i.to_bytes(2, "little"))
            assert turns - before >= 9  # a loop of sends no longer starves other tasks
            tg.cancel_scope.cancel()
        assert [int.from_bytes(m.data, "little") for m in drain(raw_bus)] == list(range(640))


# -- SDO answer slot -------------------------------------------------------------------------
async def test_a_cancelled_sdo_upload_frees_the_slot_and_is_no_timeout(
    peers: Peers, host_bus: CanBus
) -> None:
    sim = await peers.start(SimCia402Drive(4))
    client = SdoClient(host_bus, 4, timeout=1.0)
    sim.sdo_silent = True
    with anyio.move_on_after(0.02) as scope:
        await client.upload(ds.STATUSWORD.index, 0)
    assert scope.cancelled_caught
    sim.sdo_silent = False
    with anyio.fail_after(1):
        await client.read(ds.STATUSWORD)
        assert await client.read(co.ObjectEntry(0x1018, 1, co.DataType.UNSIGNED32)) == 0x0E1A
    assert client.timeouts == 0 and client.transfers == 3
