"""The SYNC READ fast path: fastcrc's CRC, bulk status decoding, the port's waits, fd I/O.

Every shortcut is compared with the general path it replaces (the same packets, the same
counters, the same exceptions) or with dynamixel-sdk (the CRC), and the port's
timeouts and cancellation are checked on the real serial stack against the simulated
bus on a pty (real time: every wait bounded).
"""

from __future__ import annotations

import asyncio
import dataclasses
import itertools
import os
import time
import tty
from typing import Any

import anyio
import dynamixel_sdk as sdk
import fastcrc
import pytest
from fastcrc import crc16
from hypothesis import given, settings
from hypothesis import strategies as st

from openel_async import BadParameterError
from openel_serial import (
    DynamixelPort,
    DynamixelStatusError,
    DynamixelTimeoutError,
    PortDisconnectedError,
)
from openel_serial import dynamixel as dx
from openel_serial.link import SerialLink
from openel_serial.peers import SimDynamixelBus, SimServo
from openel_serial.port import POLL_ADDRESS, POLL_LENGTH

from .conftest import BAUD, WAIT_S

pytestmark = pytest.mark.timeout(30)

X = dx.XSeries
PH = sdk.PacketHandler(2.0)


# -- CRC: fastcrc's CRC-16/UMTS is the ROBOTIS updateCRC --------------------------------------


def test_fastcrc_check_value_is_the_sdk_one() -> None:
    check = b"123456789"
    assert fastcrc.crc16.umts(check) == PH.updateCRC(0, list(check), len(check)) == 0xFEE8
    assert dx.crc16(check) == 0xFEE8


@settings(max_examples=100, deadline=None)
@given(st.binary(max_size=300), st.binary(max_size=64))
def test_fastcrc_umts_matches_sdk_update_crc(data: bytes, more: bytes) -> None:
    sdk_crc = PH.updateCRC(0, list(data), len(data))
    assert fastcrc.crc16.umts(data) == sdk_crc
    # Continued from a previous value (the ``crc`` argument of dx.crc16).
    chained = PH.updateCRC(sdk_crc, list(more), len(more))
    assert dx.crc16(more, dx.crc16(data)) == chained
    assert dx.crc16(bytearray(data)) == dx.crc16(memoryview(data)) == sdk_crc


# -- the parser's status fast paths -------------------------------------------------------------

STATUS_IDS = st.integers(0, dx.MAX_ID) | st.just(dx.BROADCAST_ID)
STUFFY = st.sampled_from([b"", b"\xff\xff\xfd", b"\xff\xff", b"\xfd\x00", b"\xff\xff\xfd\x00"])


def _params(size: int) -> st.SearchStrategy[bytes]:
    """``size`` bytes, often with the stuffing pattern or a header inside."""
    return st.tuples(st.binary(min_size=size, max_size=size), STUFFY, st.integers(0, size)).map(
        lambda t: (t[0][: t[2]] + t[1] + t[0][t[2] :])[:size]
    )


STATUSES = st.builds(dx.Status, STATUS_IDS, st.integers(0, 255), st.binary(max_size=40))


@settings(max_examples=100, deadline=None)
@given(STATUSES)
def test_status_fast_path_equals_the_full_decode(status: dx.Status) -> None:
    packet = dx.encode(status)
    got = dx.PacketParser().feed(packet)
    assert got == [status] == [dx.decode(packet)]
    fast = got[0]
    assert type(fast) is dx.Status and hash(fast) == hash(status) and repr(fast) == repr(status)
    assert (fast.alert, fast.error_number) == (status.alert, status.error_number)
    with pytest.raises(dataclasses.FrozenInstanceError):
        fast.id = 3  # type: ignore[misc]


def _status_of(param_length: int) -> st.SearchStrategy[bytes]:
    return st.builds(
        lambda i, e, p: dx.encode(dx.Status(i, e, p)),
        STATUS_IDS,
        st.integers(0, 255),
        _params(param_length),
    )


def _damage(packet: bytes, where: int, bit: int) -> bytes:
    data = bytearray(packet)
    data[where % len(data)] ^= 1 << bit
    return bytes(data)


def _segments(param_length: int) -> st.SearchStrategy[bytes]:
    expected = _status_of(param_length)
    return st.one_of(
        expected,
        expected,
        expected,
        st.builds(_damage, expected, st.integers(0, 1000), st.integers(0, 7)),
        st.tuples(expected, st.integers(1, 12)).map(lambda t: t[0][: -t[1]]),
        _status_of(param_length + 1),  # another length: an answer to another request
        STATUSES.map(dx.encode),
        st.builds(lambda i: dx.encode(dx.Ping(i)), st.integers(0, dx.MAX_ID)),
        st.binary(max_size=16),
        st.sampled_from([dx.HEADER, dx.HEADER[:3], b"\xff\xff\xfd\xfd"]),
    )


def _counters(parser: dx.PacketParser) -> tuple[int, ...]:
    return (
        parser.packets,
        parser.crc_errors,
        parser.length_errors,
        parser.interrupted,
        parser.malformed,
        parser.dropped_bytes,
        parser.buffered,
    )


@settings(max_examples=100, deadline=None)
@given(st.integers(0, 20), st.data())
def test_feed_statuses_is_feed_split_in_two(param_length: int, data: st.DataObject) -> None:
    stream = b"".join(data.draw(st.lists(_segments(param_length), max_size=40)))
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=6)))
    general, fast = dx.PacketParser(max_length=64), dx.PacketParser(max_length=64)
    for start, end in zip([0, *cuts], [*cuts, len(stream)], strict=True):
        chunk = stream[start:end]
        expected = general.feed(chunk)
        statuses, others = fast.feed_statuses(chunk, param_length)
        assert statuses + others == expected
        assert all(type(s) is dx.Status and len(s.params) == param_length for s in statuses)
        assert _counters(fast) == _counters(general)


@pytest.mark.parametrize("count", [1, 2, 3, 8, 32])
def test_back_to_back_replies_are_decoded_in_bulk(count: int) -> None:
    replies = [dx.Status(i, 0x80 if i == 2 else 0, bytes(range(i, i + 14))) for i in range(count)]
    stream = b"".join(map(dx.encode, replies))
    parser = dx.PacketParser()
    assert parser.feed_statuses(stream + dx.HEADER[:2], 14) == (replies, [])
    assert parser.packets == count and parser.buffered == 2 and parser.dropped_bytes == 0
    # A damaged reply among them: the general path, which drops it and counts it.
    damaged = bytearray(stream)
    damaged[-5] ^= 0x10  # a param byte of the last reply
    parser = dx.PacketParser()
    statuses, others = parser.feed_statuses(bytes(damaged), 14)
    assert statuses == [] and others == replies[:-1]
    assert parser.crc_errors == 1 and parser.packets == count - 1


@settings(max_examples=100, deadline=None)
@given(st.integers(0, 20), st.data())
def test_feed_bulk_is_feed_or_nothing(param_length: int, data: st.DataObject) -> None:
    stream = b"".join(data.draw(st.lists(_segments(param_length), min_size=1, max_size=40)))
    general, bulk = dx.PacketParser(max_length=64), dx.PacketParser(max_length=64)
    expected = general.feed(stream)
    got = bulk.feed_bulk(stream, param_length)
    if got is None:  # nothing consumed, nothing counted
        assert _counters(bulk) == _counters(dx.PacketParser())
    else:
        ids, errors, params = got
        assert [dx.Status(*s) for s in zip(ids, errors, params, strict=True)] == expected
        assert _counters(bulk) == _counters(general)


@settings(max_examples=100, deadline=None)
@given(st.integers(1, 40), st.lists(st.integers(0, 10**6), min_size=1, max_size=3, unique=True))
def test_feed_bulk_finds_up_to_three_flipped_bits_anywhere(count: int, bits: list[int]) -> None:
    # Every packet's CRC checked: any error of up to 3 bits, within one packet or across
    # several, is found.
    replies = [dx.Status(i, i % 3, bytes(range(i, i + 14))) for i in range(1, count + 1)]
    stream = bytearray(b"".join(map(dx.encode, replies)))
    assert dx.PacketParser().feed_bulk(bytes(stream), 14) == (
        bytes(r.id for r in replies),
        bytes(r.error for r in replies),
        tuple(r.params for r in replies),
    )
    flipped = {bit % (len(stream) * 8) for bit in bits}
    for bit in flipped:
        stream[bit // 8] ^= 1 << bit % 8
    parser = dx.PacketParser()
    assert parser.feed_bulk(bytes(stream), 14) is None
    assert parser.packets == 0


def test_feed_bulk_checks_every_crc_on_its_own() -> None:
    """Four bits flipped in the params of two packets, chosen so that they cancel out in
    one CRC over the whole run (with each CRC's bytes swapped, the shortcut not taken): each
    packet's own CRC still finds its two."""
    replies = [dx.Status(i, 0, bytes(14)) for i in (1, 2, 3)]
    stream = bytearray(b"".join(map(dx.encode, replies)))
    size = len(stream) // 3
    assert dx.PacketParser().feed_bulk(bytes(stream), 14) is not None

    def syndrome(bit: int) -> int:  # the CRC of one flipped bit over the run's length
        error = bytearray(len(stream))
        error[bit // 8] ^= 0x80 >> bit % 8
        return crc16.umts(bytes(error))

    first = range(9 * 8, 23 * 8)  # the params of packet 1
    second = range((size + 9) * 8, (size + 23) * 8)  # the params of packet 2
    pairs = {syndrome(a) ^ syndrome(b): (a, b) for a, b in itertools.combinations(first, 2)}
    bits = next(
        pairs[s] + (c, d)
        for c, d in itertools.combinations(second, 2)
        if (s := syndrome(c) ^ syndrome(d)) in pairs
    )
    for bit in bits:
        stream[bit // 8] ^= 0x80 >> bit % 8
    swapped = bytearray(stream)
    for j in range(0, len(stream), size):  # one CRC over the run would pass it
        swapped[j + size - 2], swapped[j + size - 1] = stream[j + size - 1], stream[j + size - 2]
    assert crc16.umts(bytes(swapped)) == 0
    parser = dx.PacketParser()
    assert parser.feed_bulk(bytes(stream), 14) is None and parser.packets == 0
    assert parser.feed(bytes(stream)) == [replies[2]]  # packets 1 and 2 fail their CRC


async def test_the_direct_path_takes_only_the_ids_asked_for_each_once() -> None:
    # Reception with sync_read's exchange in flight, driven directly: a bulk reply with a
    # repeated id or an id not asked for goes to the per-status path (stray counted).
    port = DynamixelPort("/dev/null", baudrate=BAUD)
    loop = asyncio.get_running_loop()

    def reply(*ids: int) -> bytes:
        return b"".join(dx.encode(dx.Status(i, 0, bytes([i]) * 14)) for i in ids)

    for ids, stray, taken in (((1, 1), 1, {1}), ((1, 3), 1, {1}), ((2, 1), 0, {1, 2})):
        waiter = loop.create_future()
        port._expect, port._replies, port._param_length = {1, 2}, {}, 14
        port._waiter, port._params_wanted, port.stats.stray = waiter, True, 0
        port._on_data(reply(*ids))
        if taken == {1, 2}:
            assert port._params == {1: bytes([1]) * 14, 2: bytes([2]) * 14}
            assert port._replies == {} and waiter.done()
        else:
            assert port._params is None and set(port._replies) == taken
            assert port.stats.stray == stray and not waiter.done()
        port._params = None


def test_stuffed_reply_goes_through_the_general_path() -> None:
    reply = dx.Status(4, 0, b"\xff\xff\xfd" + bytes(11))  # stuffed on the wire: 15 bytes
    stream = dx.encode(dx.Status(3, 0, bytes(14))) + dx.encode(reply)
    statuses, others = dx.PacketParser().feed_statuses(stream, 14)
    assert statuses + others == [dx.Status(3, 0, bytes(14)), reply]


# -- the port ----------------------------------------------------------------------------------


async def test_sync_read_packet_is_built_once_and_checked() -> None:
    async with SimDynamixelBus([1, 2]) as bus, DynamixelPort(bus.path, baudrate=BAUD) as port:
        ids = (1, 2)
        packet = port.sync_read_packet(ids, POLL_ADDRESS, POLL_LENGTH)
        assert packet == dx.encode(dx.SyncRead(POLL_ADDRESS, POLL_LENGTH, ids))
        assert port.sync_read_packet(ids, POLL_ADDRESS, POLL_LENGTH) is packet
        assert port.sync_read_packet([1, 2], POLL_ADDRESS, POLL_LENGTH) is packet
        assert port.sync_read_packet((2, 1), POLL_ADDRESS, POLL_LENGTH) == dx.encode(
            dx.SyncRead(POLL_ADDRESS, POLL_LENGTH, (2, 1))
        )
        for bad in ((), (1, 1)):
            with pytest.raises(BadParameterError, match="ids"):
                port.sync_read_packet(bad, POLL_ADDRESS, POLL_LENGTH)
        with pytest.raises(ValueError, match="253"):
            port.sync_read_packet((1, 253), POLL_ADDRESS, POLL_LENGTH)
        with pytest.raises(ValueError, match="address"):
            await port.sync_read(ids, 0x10000, 4)
        # Refused requests were not sent; the cached one goes out as built.
        await port.sync_read(ids, POLL_ADDRESS, POLL_LENGTH)
        assert bus.instructions == [dx.SyncRead(POLL_ADDRESS, POLL_LENGTH, ids)]
        assert bytes(bus.received) == packet


async def test_sync_read_of_32_servos_in_bulk_with_a_damaged_reply_retried() -> None:
    servos = [SimServo(i, position=100 * i) for i in range(1, 33)]
    async with (
        SimDynamixelBus(servos) as bus,
        DynamixelPort(bus.path, baudrate=BAUD, return_delay=0.0, timeout_margin=0.1) as port,
    ):
        ids = tuple(range(1, 33))
        data = await port.sync_read(ids, X.PRESENT_POSITION.address, 4)
        assert {i: X.PRESENT_POSITION.decode(d) for i, d in data.items()} == {
            i: 100 * i for i in ids
        }
        assert list(data) == list(ids)
        bus.corrupt_replies = 1  # the last reply's CRC: dropped, counted, asked again
        data = await port.sync_read(ids, X.PRESENT_POSITION.address, 4)
        assert len(data) == 32 and X.PRESENT_POSITION.decode(data[32]) == 3200
        assert port.stats.retries == 1 and port.parser.crc_errors == 1
        assert bus.instructions[-1] == dx.SyncRead(X.PRESENT_POSITION.address, 4, (32,))
        # An error status and an alert in the middle of a bulk reply.
        bus[5].inject_status_error(dx.ErrorNumber.DATA_RANGE_ERROR)
        with pytest.raises(DynamixelStatusError, match="servo 5"):
            await port.sync_read(ids, X.PRESENT_POSITION.address, 4)
        bus[7].inject_hardware_error()
        with pytest.raises(DynamixelStatusError, match="servo 7"):
            await port.sync_read(ids, X.PRESENT_POSITION.address, 4)
        data = await port.sync_read(ids, X.PRESENT_POSITION.address, 4, check_alert=False)
        assert len(data) == 32
        statuses = await port.sync_read_statuses(ids, X.PRESENT_POSITION.address, 4)
        assert statuses[7].alert and not statuses[6].alert
        assert port.stats.timeouts == 0 and port.parser.dropped_bytes == 15  # the damaged reply


async def test_sync_read_of_more_bytes_than_one_read() -> None:
    # 200 replies of 25 bytes: several reads, a packet cut between two of them.
    ids = tuple(range(1, 201))
    servos = [SimServo(i, position=i) for i in ids]
    async with (
        SimDynamixelBus(servos) as bus,
        DynamixelPort(bus.path, baudrate=BAUD, return_delay=0.0, timeout_margin=0.5) as port,
    ):
        for _ in range(3):
            with anyio.fail_after(WAIT_S):
                data = await port.sync_read(ids, POLL_ADDRESS, POLL_LENGTH)
            assert [int.from_bytes(d[10:], "little") for d in data.values()] == list(ids)
        assert port.parser.packets == 600 and port.parser.dropped_bytes == 0
        assert port.stats.retries == 0 and port.link.bytes_in == 600 * 25


SLOW_BAUD = 9600
"""Long wire times: a 1000-byte READ waits ~1.07 s, a PING ~45 ms (margin 20 ms)."""


async def test_each_exchange_times_out_at_its_own_deadline() -> None:
    async with (
        SimDynamixelBus([1, 2]) as bus,
        DynamixelPort(
            bus.path, baudrate=SLOW_BAUD, return_delay=0.0, timeout_margin=0.02, retries=0
        ) as port,
    ):
        # A long wait that ends at once (the servo refuses the length): the port's timer
        # stays armed for ~1.07 s ...
        with pytest.raises(DynamixelStatusError):
            await port.read(1, 0, 1000)
        # ... and a short wait on a silent servo still ends at its own deadline.
        bus[2].responsive = False
        ping_timeout = port.response_timeout(10, 1, 3)
        start = time.perf_counter()
        with pytest.raises(DynamixelTimeoutError, match="servo 2"):
            await port.ping(2)
        elapsed = time.perf_counter() - start
        assert ping_timeout <= elapsed < 0.5
        # A long wait after short ones lasts its whole timeout, not the earlier timer's.
        await port.ping(1)
        read_timeout = port.response_timeout(14, 1, 147)
        start = time.perf_counter()
        with pytest.raises(DynamixelTimeoutError, match="servo 2"):
            await port.read(2, 0, 147)
        elapsed = time.perf_counter() - start
        assert read_timeout <= elapsed < read_timeout + 0.5
        assert port.stats.timeouts == 2


async def test_a_cancelled_exchange_leaves_the_port_usable() -> None:
    async with (
        SimDynamixelBus([1, 2]) as bus,
        DynamixelPort(bus.path, baudrate=SLOW_BAUD, return_delay=0.0, retries=0) as port,
    ):
        bus[2].responsive = False
        start = time.perf_counter()
        with anyio.move_on_after(0.05) as scope:
            await port.read(2, 0, 147)  # would wait ~0.2 s
        assert scope.cancelled_caught and time.perf_counter() - start < 0.15
        assert port.stats.timeouts == 0  # cancelled, not timed out
        bus[2].responsive = True
        with anyio.fail_after(WAIT_S):
            assert (await port.ping(2)).model_number == 1020
            assert len(await port.sync_read((1, 2), POLL_ADDRESS, POLL_LENGTH)) == 2
        # Cancelled before it started: nothing is sent (the lock checks the caller).
        sent = len(bus.instructions)
        with anyio.CancelScope() as scope:
            scope.cancel()
            await port.ping(1)
        with anyio.fail_after(WAIT_S):
            await port.ping(1)  # answered after anything sent before it
        assert bus.instructions[sent:] == [dx.Ping(1)]


async def test_the_bus_lock_is_fifo_and_a_cancelled_waiter_sends_nothing() -> None:
    # Transactions queue on the port's lock in arrival order; a caller cancelled while
    # queued never reaches the bus, and the lock passes to the next one in line.
    async with (
        SimDynamixelBus([1, 2]) as bus,
        DynamixelPort(bus.path, baudrate=SLOW_BAUD, return_delay=0.0, retries=0) as port,
    ):
        bus[2].responsive = False
        done: list[str] = []
        sent = len(bus.instructions)

        async def hold() -> None:
            with pytest.raises(DynamixelTimeoutError):
                await port.read(2, 0, 147)  # holds the lock for its ~0.2 s timeout
            done.append("read")

        async def ping(name: str, scope: anyio.CancelScope | None = None) -> None:
            with scope or anyio.CancelScope():
                await port.ping(1)
                done.append(name)

        queued = anyio.CancelScope()
        with anyio.fail_after(WAIT_S):
            async with anyio.create_task_group() as tg:
                tg.start_soon(hold)
                await anyio.sleep(0.02)
                for name, scope in (("cancelled", queued), ("second", None), ("third", None)):
                    tg.start_soon(ping, name, scope)
                    await anyio.sleep(0.01)
                assert port.stats.transactions == 1  # all three wait for the lock
                queued.cancel()
        assert done == ["read", "second", "third"]
        assert queued.cancelled_caught
        assert bus.instructions[sent:] == [dx.Read(2, 0, 147), dx.Ping(1), dx.Ping(1)]


async def test_port_lost_while_waiting_raises_at_once() -> None:
    async with (
        SimDynamixelBus([1, 2]) as bus,
        DynamixelPort(bus.path, baudrate=SLOW_BAUD, return_delay=0.0, retries=0) as port,
    ):
        bus[2].responsive = False

        async def unplug_soon() -> None:
            await anyio.sleep(0.03)
            bus.unplug()

        start = time.perf_counter()
        async with anyio.create_task_group() as tg:
            tg.start_soon(unplug_soon)
            with pytest.raises(PortDisconnectedError):
                await port.read(2, 0, 147)  # would wait ~0.2 s
        assert time.perf_counter() - start < 0.15
        assert port.stats.timeouts == 0 and port.stats.losses == 1


# -- the fd transport ----------------------------------------------------------------------------


async def test_fd_transport_reads_writes_and_reports_errors_like_pyserial() -> None:
    master, slave = os.openpty()
    tty.setraw(slave)
    received: list[bytes] = []
    lost: list[str] = []
    got_data, got_lost = anyio.Event(), anyio.Event()

    def on_data(data: bytes) -> None:
        received.append(data)
        got_data.set()

    def on_lost(reason: str) -> None:
        lost.append(reason)
        got_lost.set()

    link = SerialLink(os.ttyname(slave), baudrate=BAUD, on_data=on_data, on_lost=on_lost)
    # A write error is a disconnect, reported through on_lost only: nothing reaches the
    # loop's exception handler (it did, as "Fatal write error on serial transport").
    loop = asyncio.get_running_loop()
    handler = loop.get_exception_handler()
    reported: list[dict[str, Any]] = []
    loop.set_exception_handler(lambda _loop, context: reported.append(context))
    try:
        await link.open()
        os.write(master, b"status bytes")
        link.write(b"instruction")
        with anyio.fail_after(WAIT_S):
            await got_data.wait()
        assert b"".join(received) == b"status bytes"
        assert os.read(master, 64) == b"instruction"
        os.close(master)
        master = -1
        link.write(b"x")  # the device is gone: EIO
        with anyio.fail_after(WAIT_S):
            await got_lost.wait()
        assert len(lost) == 1 and lost[0].startswith("port lost: write failed: [Errno 5]")
        assert not link.is_open
        assert reported == []
    finally:
        loop.set_exception_handler(handler)
        await link.close()
        if master >= 0:
            os.close(master)
        os.close(slave)
