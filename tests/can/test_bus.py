"""CanBus: dispatch by id, bounded queues, send paths, SYNC, failures and recovery."""

from __future__ import annotations

import contextlib
import threading
import time

import anyio
import can
import pytest

from openel_async import BadParameterError, NotConnectedError
from openel_can import BusState, CanBus
from openel_can.sim.faults import BusLink

from .conftest import drain, wait_until


def _msg(arb_id: int, data: bytes = b"\x01", **kwargs: object) -> can.Message:
    return can.Message(arbitration_id=arb_id, data=data, is_extended_id=False, **kwargs)  # type: ignore[arg-type]


async def test_one_reader_dispatches_by_id_to_every_port(channel: str, raw_bus: can.BusABC) -> None:
    async with CanBus(interface="virtual", channel=channel, poll_interval=0.01) as bus:
        a = bus.attach([0x100, 0x101], name="a")
        b = bus.attach([0x101], name="b")
        ext = bus.attach([0x101], name="ext", extended=True)
        for arb_id in (0x100, 0x101, 0x102):
            raw_bus.send(_msg(arb_id))
        raw_bus.send(can.Message(arbitration_id=0x101, data=b"", is_extended_id=True))
        raw_bus.send(can.Message(is_error_frame=True))
        got: dict[str, list[int]] = {"a": [], "b": [], "ext": []}
        with anyio.fail_after(1):
            while len(got["a"]) < 2 or not got["b"] or not got["ext"]:
                for port in (a, b, ext):
                    with contextlib.suppress(anyio.WouldBlock):
                        got[port.name] += [m.arbitration_id for m in port.receive_nowait()]
                await anyio.sleep(0.001)
        assert got == {"a": [0x100, 0x101], "b": [0x101], "ext": [0x101]}
        await wait_until(lambda: bus.stats.error_frames == 1, 1)
        assert bus.stats.unrouted == 1  # 0x102
        assert bus.stats.rx_frames == 5


async def test_a_full_port_drops_and_counts_and_the_reader_goes_on(
    channel: str, raw_bus: can.BusABC
) -> None:
    async with CanBus(interface="virtual", channel=channel, poll_interval=0.01) as bus:
        slow = bus.attach([0x200], name="slow", queue_size=1)
        other = bus.attach([0x201], name="other")
        for i in range(50):  # one frame per batch: 1 batch fits, 49 are dropped
            raw_bus.send(_msg(0x200))
            await wait_until(lambda i=i: bus.stats.rx_frames == i + 1, 1)
        assert slow.received == 50
        assert slow.dropped == 49 and bus.stats.overflow_frames == 49
        raw_bus.send(_msg(0x201))
        with anyio.fail_after(1):
            batch = await other.receive()
        assert batch[0].arbitration_id == 0x201
        kept = 0
        while True:
            try:
                kept += len(slow.receive_nowait())
            except anyio.WouldBlock:
                break
        assert kept == 1


async def test_frames_go_out_in_order_inline_and_threaded(
    channel: str, raw_bus: can.BusABC
) -> None:
    for mode in ("inline", "thread"):
        async with CanBus(interface="virtual", channel=channel, send_mode=mode) as bus:
            port = bus.attach([], name="tx")
            for i in range(300):
                await port.send(0x300, i.to_bytes(2, "little"))
            received: list[int] = []
            with anyio.fail_after(1):
                while len(received) < 300:
                    received += [int.from_bytes(m.data, "little") for m in drain(raw_bus)]
                    await anyio.sleep(0.001)
            assert received == list(range(300)), mode
            assert bus.stats.tx_frames == 300


class _SlowBus(can.BusABC):
    """A bus whose send blocks its thread for 20 ms (a congested real interface)."""

    def __init__(self) -> None:
        super().__init__(channel="slow")
        self.sent: list[can.Message] = []
        self.threads: set[int] = set()

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self.threads.add(threading.get_ident())
        time.sleep(0.02)
        self.sent.append(msg)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        time.sleep(min(timeout or 0.0, 0.01))
        return None, False


async def test_blocking_sends_run_in_a_thread_and_a_full_queue_times_out() -> None:
    slow = _SlowBus()
    try:
        async with CanBus(slow, tx_queue_size=2, send_timeout=0.05, poll_interval=0.01) as bus:
            port = bus.attach([], name="tx")
            ticks = 0

            async def ticker() -> None:
                nonlocal ticks
                while True:
                    await anyio.sleep(0.001)
                    ticks += 1

            async with anyio.create_task_group() as tg:
                tg.start_soon(ticker)
                with pytest.raises(TimeoutError):
                    for _ in range(20):
                        await port.send(0x123, b"\x00")
                tg.cancel_scope.cancel()
            assert ticks >= 10  # the event loop kept running while sends blocked
            assert threading.get_ident() not in slow.threads
            await wait_until(lambda: len(slow.sent) >= 3, 2)
    finally:
        slow.shutdown()


class _FailingBus(can.BusABC):
    """A bus whose send fails from its ``fail_at``-th frame on (0-based)."""

    def __init__(self, fail_at: int) -> None:
        super().__init__(channel="failing")
        self.fail_at = fail_at
        self.sent: list[can.Message] = []

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if len(self.sent) >= self.fail_at:
            raise can.CanOperationError("transmit buffer overflow")
        self.sent.append(msg)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        time.sleep(min(timeout or 0.0, 0.01))
        return None, False


async def test_a_threaded_batch_failing_midway_counts_what_went_out() -> None:
    """A batch sent from the thread that fails at its third frame: the two before it went
    out and count as sent, only the rest as dropped; the bus goes down."""
    failing = _FailingBus(fail_at=2)
    try:
        async with CanBus(failing, send_mode="thread", poll_interval=0.01) as bus:
            port = bus.attach([], name="tx")
            for k in range(5):  # queued without a pause: the sender takes them as one batch
                await port.send(0x100 + k, b"\x00")
            await wait_until(lambda: bus.stats.tx_frames + bus.stats.tx_dropped == 5, 2)
            assert [m.arbitration_id for m in failing.sent] == [0x100, 0x101]
            assert bus.stats.tx_frames == 2 and bus.stats.tx_dropped == 3
            assert bus.state is not BusState.UP
    finally:
        failing.shutdown()


async def test_sync_producer(channel: str, raw_bus: can.BusABC) -> None:
    async with CanBus(interface="virtual", channel=channel, sync_period=0.005):
        frames: list[can.Message] = []
        with anyio.fail_after(1):
            while len(frames) < 5:
                frames += [m for m in drain(raw_bus) if m.arbitration_id == 0x080]
                await anyio.sleep(0.002)
    assert all(len(m.data) == 0 for m in frames)


async def test_recv_failure_faults_ports_and_reopens_when_the_bus_returns(channel: str) -> None:
    link = BusLink(channel)
    reasons: list[str] = []
    async with CanBus(
        bus_factory=link.open, poll_interval=0.01, reconnect_backoff=(0.01, 0.05)
    ) as bus:
        port = bus.attach([0x100], name="node", on_bus_error=reasons.append)
        link.fail("bus-off", unplugged=True)
        await wait_until(lambda: bus.state is BusState.DOWN, 1)
        assert reasons and "bus-off" in reasons[0]
        with pytest.raises(NotConnectedError, match="down"):
            await port.send(0x100)
        with pytest.raises(NotConnectedError):
            await bus.wait_up(0.05)
        await wait_until(lambda: link.failed_opens >= 2, 1)  # retried with backoff
        link.restore()
        await bus.wait_up(1)
        assert bus.stats.bus_errors == 1 and bus.stats.recoveries == 1 and link.opened >= 2
        peer = can.Bus(interface="virtual", channel=channel)
        try:
            peer.send(_msg(0x100))
            with anyio.fail_after(1):
                assert (await port.receive())[0].arbitration_id == 0x100
            await port.send(0x555)  # sending works again
            with anyio.fail_after(1):
                while not [m for m in drain(peer) if m.arbitration_id == 0x555]:  # noqa: ASYNC110
                    await anyio.sleep(0.001)
        finally:
            peer.shutdown()
    assert len(reasons) == 1


async def test_recv_failure_on_a_given_bus_retries_recv(channel: str) -> None:
    link = BusLink(channel)
    given = link.open()
    try:
        async with CanBus(given, poll_interval=0.01, reconnect_backoff=(0.01, 0.02)) as bus:
            link.fail()
            await wait_until(lambda: bus.state is BusState.DOWN, 1)
            await anyio.sleep(0.05)
            assert bus.state is BusState.DOWN
            link.restore()
            await bus.wait_up(1)
            assert link.opened == 1  # the same object, never reopened
    finally:
        given.shutdown()


def test_bad_parameters_name_the_parameter() -> None:
    with pytest.raises(BadParameterError, match="bus"):
        CanBus()
    with pytest.raises(BadParameterError, match="bus"):
        CanBus(bus_factory=lambda: can.Bus(interface="virtual"), interface="virtual")
    with pytest.raises(BadParameterError, match="poll_interval"):
        CanBus(interface="virtual", channel="x", poll_interval=0)
    with pytest.raises(BadParameterError, match="send_mode"):
        CanBus(interface="virtual", channel="x", send_mode="fast")  # type: ignore[arg-type]
    with pytest.raises(BadParameterError, match="reconnect_backoff"):
        CanBus(interface="virtual", channel="x", reconnect_backoff=(1.0, 0.5))


async def test_attach_checks_ids_and_state(channel: str) -> None:
    bus = CanBus(interface="virtual", channel=channel)
    with pytest.raises(NotConnectedError, match="not open"):
        bus.attach([1])
    async with bus:
        with pytest.raises(BadParameterError, match="ids"):
            bus.attach([0x800])
        with pytest.raises(BadParameterError, match="ids"):
            bus.attach([-1])
        port = bus.attach([0x7FF])
        port.close()
        with pytest.raises(anyio.EndOfStream):
            await port.receive()


async def test_frames_queued_before_the_close_go_out(channel: str, raw_bus: can.BusABC) -> None:
    """A drive's last command (ODrive IDLE, a CiA 402 disable) is queued just before the bus
    closes; on an interface that sends from a thread (slcan, pcan, kvaser) the close
    cancelled the sender first and the frames were lost, uncounted."""
    async with CanBus(
        bus_factory=lambda: _SlowSendBus(channel), send_mode="thread", send_timeout=1.0
    ) as bus:
        port = bus.attach([], name="tx")
        for i in range(5):
            await port.send(0x300, i.to_bytes(2, "little"))
        assert bus.stats.tx_frames < 5  # still queued when the close begins
    received = [int.from_bytes(m.data, "little") for m in drain(raw_bus)]
    assert received == list(range(5))
    assert (bus.stats.tx_frames, bus.stats.tx_dropped) == (5, 0)


class _SlowSendBus(can.BusABC):
    """A virtual bus whose send takes 5 ms in its thread (a serial adapter at work)."""

    def __init__(self, channel: str) -> None:
        super().__init__(channel=channel)
        self._bus = can.Bus(interface="virtual", channel=channel)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        time.sleep(0.005)
        self._bus.send(msg, timeout)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        return self._bus.recv(timeout), False

    def shutdown(self) -> None:
        self._bus.shutdown()
        super().shutdown()


async def test_produced_frames_count_as_pending_until_sent() -> None:
    """A heartbeat producer's frames are counted in and out like any other (the count went
    negative: inline sends were refused for good and the close logged a negative drop)."""
    async with CanBus(interface="virtual", channel="pending-count-test") as bus:
        owner = object()
        bus.produce_heartbeat(127, 0.01, owner)
        await anyio.sleep(0.1)
        bus.release_heartbeat(owner)
        await wait_until(lambda: bus._tx_pending == 0)  # the counter under test
        assert bus.stats.tx_dropped == 0


class _RefusingBus(can.BusABC):
    """A bus whose send refuses its next ``refuse`` frames (a full transmit buffer)."""

    def __init__(self) -> None:
        super().__init__(channel="refusing")
        self.sent: list[can.Message] = []
        self.refuse = 0

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if self.refuse:
            self.refuse -= 1
            raise can.CanOperationError("Transmit buffer full")
        self.sent.append(msg)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        time.sleep(min(timeout or 0.0, 0.01))
        return None, False


async def test_send_all_nowait_sends_in_order_queues_behind_a_refusal_and_drops_beyond() -> None:
    """A burst from synchronous code: inline while the interface takes the frames; from a
    refused frame on, queued behind it (in order) up to the queue's room, the rest dropped
    and counted; a frame built once goes out as often as it is given."""
    from openel_can import TxMessage

    refusing = _RefusingBus()
    try:
        async with CanBus(refusing, send_mode="inline", tx_queue_size=2, poll_interval=0.01) as bus:
            port = bus.attach([], name="tx")
            assert port.send_all_nowait([(0x201, b"\x01"), (0x202, b"\x02")]) == 2
            assert [(m.arbitration_id, bytes(m.data)) for m in refusing.sent] == [
                (0x201, b"\x01"),
                (0x202, b"\x02"),
            ]
            refusing.refuse = 1
            burst = [(0x203 + k, bytes([k])) for k in range(4)]
            assert port.send_all_nowait(burst) == 2  # 0x203 refused: queued, 0x204 behind it
            assert bus.stats.tx_dropped == 2 and bus.stats.tx_frames == 2
            await wait_until(lambda: len(refusing.sent) == 4, 2)
            assert [m.arbitration_id for m in refusing.sent] == [0x201, 0x202, 0x203, 0x204]
            sync = TxMessage.frame(0x080, b"", False, False)
            assert port.send_frame_nowait(sync) and port.send_frame_nowait(sync)
            assert refusing.sent[-2:] == [sync, sync]
            assert bus.stats.tx_frames == 6 and bus.stats.tx_dropped == 2
        with pytest.raises(NotConnectedError):
            port.send_all_nowait([(0x201, b"\x01")])
        with pytest.raises(NotConnectedError):
            port.send_frame_nowait(sync)
        assert len(refusing.sent) == 6
    finally:
        refusing.shutdown()
