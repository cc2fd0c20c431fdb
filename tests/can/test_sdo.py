"""SdoClient protocol rules (segmented transfers) and the simulated drive's SDO server.

A raw python-can bus plays a misbehaving server (or client) frame by frame; every wait is
bounded.
"""

from __future__ import annotations

import anyio
import can
import pytest

from openel_async import BadParameterError
from openel_can import CanBus, SdoAbortError, SdoClient, SdoTimeoutError
from openel_can import canopen as co
from openel_can.sim.cia402 import ENERGY_LIMIT, OPERATING_TIME, SimCia402Drive

from .conftest import Peers, drain

NODE = 7


def _send(raw: can.BusABC, msg: co.CanOpenMessage) -> None:
    cob_id, data = co.encode(msg)
    raw.send(can.Message(arbitration_id=cob_id, data=data, is_extended_id=False))


async def _next(raw: can.BusABC, cob_id: int) -> co.CanOpenMessage:
    """The next frame on ``cob_id`` seen by the raw bus, decoded (bounded wait)."""
    with anyio.fail_after(1):
        while True:
            for frame in drain(raw):
                if frame.arbitration_id == cob_id:
                    return co.decode(cob_id, frame.data)
            await anyio.sleep(0.001)


async def _fake_server(
    raw: can.BusABC, answers: list[co.CanOpenMessage], seen: list[co.CanOpenMessage]
) -> None:
    """Answer each client frame with the next of ``answers``; record what the client sent."""
    for answer in answers:
        seen.append(await _next(raw, co.SDO_RX_BASE + NODE))
        _send(raw, answer)
    seen.append(await _next(raw, co.SDO_RX_BASE + NODE))  # the abort, if any


@pytest.mark.parametrize(
    ("answers", "code"),
    [
        (  # the server repeats toggle 0 on the second segment
            [
                co.SdoSegmentedUploadResponse(NODE, 0x2000, 0, 14),
                co.SdoUploadSegment(NODE, False, b"1234567", False),
                co.SdoUploadSegment(NODE, False, b"1234567", True),
            ],
            co.SdoAbortCode.TOGGLE_BIT_NOT_ALTERNATED,
        ),
        (  # more data than announced
            [
                co.SdoSegmentedUploadResponse(NODE, 0x2000, 0, 3),
                co.SdoUploadSegment(NODE, False, b"1234567", True),
            ],
            co.SdoAbortCode.LENGTH_MISMATCH,
        ),
        (  # announced more than max_size
            [co.SdoSegmentedUploadResponse(NODE, 0x2000, 0, 100_000)],
            co.SdoAbortCode.OUT_OF_MEMORY,
        ),
        (  # a download answer to an upload
            [co.SdoDownloadResponse(NODE, 0x2000, 0)],
            co.SdoAbortCode.INVALID_COMMAND_SPECIFIER,
        ),
    ],
)
async def test_client_aborts_a_server_that_breaks_the_protocol(
    host_bus: CanBus, raw_bus: can.BusABC, answers: list[co.CanOpenMessage], code: int
) -> None:
    client = SdoClient(host_bus, NODE, timeout=0.5)
    seen: list[co.CanOpenMessage] = []
    async with anyio.create_task_group() as tg:
        tg.start_soon(_fake_server, raw_bus, answers, seen)
        with pytest.raises(SdoAbortError) as aborted:
            await client.upload(0x2000, 0)
    assert aborted.value.by_client and aborted.value.abort_code == code
    assert seen[-1] == co.SdoAbort(NODE, 0x2000, 0, code, from_client=True)
    assert client.timeouts == 0


async def test_client_segmented_download_toggles_and_times_out_per_segment(
    host_bus: CanBus, raw_bus: can.BusABC
) -> None:
    client = SdoClient(host_bus, NODE, timeout=0.1)
    seen: list[co.CanOpenMessage] = []
    answers: list[co.CanOpenMessage] = [
        co.SdoDownloadResponse(NODE, 0x2000, 0),
        co.SdoDownloadSegmentResponse(NODE, False),
    ]  # then silence: the second segment is never confirmed
    async with anyio.create_task_group() as tg:
        tg.start_soon(_fake_server, raw_bus, answers, seen)
        with anyio.fail_after(2), pytest.raises(SdoTimeoutError):
            await client.download(0x2000, 0, b"0123456789")
    assert seen == [
        co.SdoSegmentedDownloadRequest(NODE, 0x2000, 0, 10),
        co.SdoDownloadSegment(NODE, False, b"0123456", False),
        co.SdoDownloadSegment(NODE, True, b"789", True),
    ]
    abort = await _next(raw_bus, co.SDO_RX_BASE + NODE)
    assert abort == co.SdoAbort(NODE, 0x2000, 0, co.SdoAbortCode.TIMEOUT, from_client=True)


async def test_each_exchange_ends_at_its_own_deadline_with_the_shared_timer(
    host_bus: CanBus, raw_bus: can.BusABC
) -> None:
    """The client's one timer is replaced for a sooner deadline and set again when it
    fires before the deadline of the exchange in flight."""
    client = SdoClient(host_bus, NODE, timeout=0.05)
    answer = co.SdoUploadResponse(NODE, 0x2000, 0, b"\x01\x02")

    async def serve(delay: float) -> None:
        await _next(raw_bus, co.SDO_RX_BASE + NODE)
        await anyio.sleep(delay)
        _send(raw_bus, answer)

    async with anyio.create_task_group() as tg:
        tg.start_soon(serve, 0.0)
        assert await client.upload(0x2000, 0, timeout=30.0) == b"\x01\x02"  # timer: +30 s
    started = anyio.current_time()
    with anyio.fail_after(2), pytest.raises(SdoTimeoutError):
        await client.upload(0x2001, 0)  # unanswered: its own 50 ms, not the 30 s
    assert anyio.current_time() - started < 1.0
    drain(raw_bus)  # the abort
    async with anyio.create_task_group() as tg:
        tg.start_soon(serve, 0.0)
        assert await client.upload(0x2000, 0) == b"\x01\x02"  # timer: +50 ms
    async with anyio.create_task_group() as tg:
        tg.start_soon(serve, 0.2)  # answered after the earlier deadline passed
        with anyio.fail_after(2):
            assert await client.upload(0x2000, 0, timeout=1.0) == b"\x01\x02"
    assert client.timeouts == 1


async def test_write_of_a_value_that_does_not_fit_is_a_bad_parameter(host_bus: CanBus) -> None:
    client = SdoClient(host_bus, NODE)
    with pytest.raises(BadParameterError, match="0x2031"):
        await client.write(ENERGY_LIMIT, 2**63)
    with pytest.raises(BadParameterError, match="max_size"):
        SdoClient(host_bus, NODE, max_size=2)
    assert client.transfers == 0  # nothing was sent


# -- the simulated drive's server ----------------------------------------------------------
async def test_sim_server_segmented_rules(peers: Peers, raw_bus: can.BusABC) -> None:
    sim = await peers.start(SimCia402Drive(NODE))
    tx = co.SDO_TX_BASE + NODE

    async def ask(msg: co.CanOpenMessage) -> co.CanOpenMessage:
        drain(raw_bus)
        _send(raw_bus, msg)
        return await _next(raw_bus, tx)

    # A segment request with no transfer in progress.
    assert await ask(co.SdoUploadSegmentRequest(NODE, False)) == co.SdoAbort(
        NODE, 0, 0, co.SdoAbortCode.INVALID_COMMAND_SPECIFIER
    )
    # A segmented upload with a wrong toggle on the second segment.
    init = await ask(co.SdoUploadRequest(NODE, OPERATING_TIME.index, 0))
    assert init == co.SdoSegmentedUploadResponse(NODE, OPERATING_TIME.index, 0, 8)
    first = await ask(co.SdoUploadSegmentRequest(NODE, False))
    assert isinstance(first, co.SdoUploadSegment) and len(first.data) == 7 and not first.last
    assert await ask(co.SdoUploadSegmentRequest(NODE, False)) == co.SdoAbort(
        NODE, OPERATING_TIME.index, 0, co.SdoAbortCode.TOGGLE_BIT_NOT_ALTERNATED
    )
    # A segmented download that carries more than the object holds.
    before = sim.od[(ENERGY_LIMIT.index, 0)].value
    assert await ask(co.SdoSegmentedDownloadRequest(NODE, ENERGY_LIMIT.index, 0, None)) == (
        co.SdoDownloadResponse(NODE, ENERGY_LIMIT.index, 0)
    )
    assert await ask(co.SdoDownloadSegment(NODE, False, bytes(7), False)) == (
        co.SdoDownloadSegmentResponse(NODE, False)
    )
    assert await ask(co.SdoDownloadSegment(NODE, True, bytes(7), True)) == co.SdoAbort(
        NODE, ENERGY_LIMIT.index, 0, co.SdoAbortCode.LENGTH_TOO_HIGH
    )
    assert sim.od[(ENERGY_LIMIT.index, 0)].value == before
    # A size that does not match the object is refused at the initiate.
    assert await ask(co.SdoSegmentedDownloadRequest(NODE, ENERGY_LIMIT.index, 0, 9)) == (
        co.SdoAbort(NODE, ENERGY_LIMIT.index, 0, co.SdoAbortCode.LENGTH_TOO_HIGH)
    )
    # Read-only 64-bit object.
    assert await ask(co.SdoSegmentedDownloadRequest(NODE, OPERATING_TIME.index, 0, 8)) == (
        co.SdoAbort(NODE, OPERATING_TIME.index, 0, co.SdoAbortCode.READ_ONLY)
    )


async def test_transfers_of_one_node_run_one_at_a_time_in_call_order(
    host_bus: CanBus, raw_bus: can.BusABC
) -> None:
    """Three uploads at once: the server sees one request at a time, in call order; a
    transfer cancelled while waiting for its turn leaves the others their turns."""
    client = SdoClient(host_bus, NODE, timeout=1.0)
    got: list[bytes] = []

    async def upload(index: int) -> None:
        got.append(await client.upload(index, 0))

    async def server(indexes: list[int]) -> None:
        for index in indexes:
            request = await _next(raw_bus, co.SDO_RX_BASE + NODE)
            assert isinstance(request, co.SdoUploadRequest)
            assert request.index == index
            _send(raw_bus, co.SdoUploadResponse(NODE, index, 0, index.to_bytes(2, "little")))

    with anyio.fail_after(5):
        async with anyio.create_task_group() as tg:
            tg.start_soon(server, [0x2000, 0x2002])
            tg.start_soon(upload, 0x2000)
            await anyio.wait_all_tasks_blocked()
            with anyio.CancelScope() as cancelled:
                cancelled.cancel()  # waits for its turn behind 0x2000, then gives up
                await upload(0x2001)
            tg.start_soon(upload, 0x2002)
    assert got == [b"\x00\x20", b"\x02\x20"]
