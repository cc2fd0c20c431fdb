"""Data-port semantics on the virtual clock for every combination of dataflow /
subscription, full policy and empty policy (OpenRTM's RingBuffer and connectors)."""

from __future__ import annotations

import itertools

import anyio
import pytest

from openel_async import VirtualClock
from openel_async.rtc.ports import (
    Connector,
    InPort,
    ListenerType,
    OutPort,
    PortEvent,
    PortStatus,
    TimedLong,
)

MS = 1_000_000
FLOWS = {
    "push/flush": {"dataport.dataflow_type": "push", "dataport.subscription_type": "flush"},
    "push/new": {"dataport.dataflow_type": "push", "dataport.subscription_type": "new"},
    "push/periodic": {
        "dataport.dataflow_type": "push",
        "dataport.subscription_type": "periodic",
        "dataport.publisher.push_rate": "1000",
        "dataport.publisher.push_policy": "all",
    },
    "pull": {"dataport.dataflow_type": "pull"},
}
FULL = ("overwrite", "do_nothing", "block")
EMPTY = ("readback", "do_nothing", "block")
WRITE_TIMEOUT_S = 0.3
READ_TIMEOUT_S = 0.5


def ports(clock: VirtualClock) -> tuple[OutPort[TimedLong], InPort[TimedLong]]:
    return OutPort("out", TimedLong, clock=clock), InPort("in", TimedLong, clock=clock)


@pytest.mark.parametrize(
    ("flow", "full", "empty", "listened"),
    list(itertools.product(FLOWS, FULL, EMPTY, (True, False))),
)
async def test_policy_combination(
    virtual_clock: VirtualClock, flow: str, full: str, empty: str, listened: bool
) -> None:
    """Buffer of 2, three values written, then three reads; with listeners on every
    event, and without (the ports' fast path, which must count and answer the same)."""
    clock = virtual_clock
    out, inp = ports(clock)
    props = {
        **FLOWS[flow],
        "dataport.buffer.length": 2,
        "dataport.buffer.write.full_policy": full,
        "dataport.buffer.write.timeout": WRITE_TIMEOUT_S,
        "dataport.buffer.read.empty_policy": empty,
        "dataport.buffer.read.timeout": READ_TIMEOUT_S,
    }
    queued = flow in ("push/new", "push/periodic")
    events: list[PortEvent] = []
    for kind in ListenerType if listened else ():
        out.add_listener(kind, events.append)
        inp.add_listener(kind, events.append)
    async with Connector(out, inp, props) as conn:
        # 1. nothing written yet
        t0 = clock.now_ns()
        assert not inp.is_new()
        assert await inp.read() is None
        if empty == "block":
            assert inp.status is PortStatus.BUFFER_TIMEOUT
            assert clock.now_ns() - t0 == round(READ_TIMEOUT_S * 1e9)
        else:
            assert inp.status is PortStatus.BUFFER_EMPTY
            assert clock.now_ns() == t0
        # 2. three values into a buffer of two
        results = []
        for value in (1, 2, 3):
            t1 = clock.now_ns()
            results.append(await out.write(value))
            waited = clock.now_ns() - t1
            if full == "block" and value == 3 and not queued:
                assert waited == round(WRITE_TIMEOUT_S * 1e9)
            else:
                assert waited == 0
            await clock.sleep(0.002)  # lets a new/periodic publisher send it
        await clock.sleep(1.0)  # a blocked publisher gives up
        kept = [2, 3] if full == "overwrite" else [1, 2]
        if full == "overwrite" or queued:
            assert results == [True, True, True]
        else:
            assert results == [True, True, False]
            assert out.status is (
                PortStatus.BUFFER_FULL
                if flow == "pull" and full == "do_nothing"
                else PortStatus.BUFFER_TIMEOUT
                if flow == "pull"
                else PortStatus.SEND_FULL
                if full == "do_nothing"
                else PortStatus.SEND_TIMEOUT
            )
        stats = conn.stats
        assert stats.written == 3
        assert (stats.overwritten, stats.refused, stats.timeouts - (empty == "block")) == {
            "overwrite": (1, 0, 0),
            "do_nothing": (0, 1, 0),
            "block": (0, 0, 1),
        }[full]
        # 3. read the two kept values, then the empty policy
        got = []
        for _ in kept:
            assert inp.is_new()
            value = await inp.read()
            assert value is not None and inp.status is PortStatus.PORT_OK
            assert value.tm is not None
            got.append(value.data)
        assert got == kept
        assert not inp.is_new()
        t2 = clock.now_ns()
        last = await inp.read()
        if empty == "readback":
            assert last is not None and last.data == kept[-1]
            assert inp.status is PortStatus.PORT_OK
            assert not inp.is_new()
        elif empty == "do_nothing":
            assert last is None and inp.status is PortStatus.BUFFER_EMPTY
        else:
            assert last is None and inp.status is PortStatus.BUFFER_TIMEOUT
            assert clock.now_ns() - t2 == round(READ_TIMEOUT_S * 1e9)
        assert inp.value is not None and inp.value.data == kept[-1]
        stats = conn.stats
        stored = 3 if full == "overwrite" and flow != "pull" else 2
        assert (stats.read, stats.received) == (2, stored)
    if not listened:
        return
    kinds = [e.kind for e in events]
    assert kinds[:2] == [ListenerType.ON_CONNECT] * 2
    assert kinds[-2:] == [ListenerType.ON_DISCONNECT] * 2
    lost = {
        "overwrite": ListenerType.ON_BUFFER_OVERWRITE,
        "do_nothing": ListenerType.ON_BUFFER_FULL,
        "block": ListenerType.ON_BUFFER_WRITE_TIMEOUT,
    }[full]
    assert lost in kinds
    if flow != "pull":
        received = [e.data.data for e in events if e.kind is ListenerType.ON_RECEIVED and e.data]
        assert received == ([1, 2, 3] if full == "overwrite" else [1, 2])


@pytest.mark.parametrize("flow", list(FLOWS))
async def test_blocked_write_resumes_when_read(virtual_clock: VirtualClock, flow: str) -> None:
    out, inp = ports(virtual_clock)
    props = {
        **FLOWS[flow],
        "dataport.buffer.length": 1,
        "dataport.buffer.write.full_policy": "block",
        "dataport.buffer.write.timeout": 5,
    }
    async with Connector(out, inp, props) as conn, anyio.create_task_group() as tg:
        assert await out.write(1)
        await virtual_clock.sleep(0.002)
        done: list[tuple[int, bool]] = []

        async def writer() -> None:
            ok = await out.write(2)
            done.append((virtual_clock.now_ns(), ok))

        tg.start_soon(writer)
        await virtual_clock.sleep(0.1)
        assert (await inp.read()).data == 1  # type: ignore[union-attr]
        await virtual_clock.sleep(0.01)
        assert done and done[0][1] and done[0][0] <= 0.12e9
        assert (await inp.read()).data == 2  # type: ignore[union-attr]
        assert conn.stats.timeouts == 0


@pytest.mark.parametrize("flow", list(FLOWS))
async def test_blocked_read_resumes_when_written(virtual_clock: VirtualClock, flow: str) -> None:
    out, inp = ports(virtual_clock)
    props = {**FLOWS[flow], "dataport.buffer.read.empty_policy": "block"}
    async with Connector(out, inp, props), anyio.create_task_group() as tg:

        async def later() -> None:
            await virtual_clock.sleep(0.2)
            await out.write(42)

        tg.start_soon(later)
        t0 = virtual_clock.now_ns()
        value = await inp.read()
        assert value is not None and value.data == 42
        assert 0.2e9 <= virtual_clock.now_ns() - t0 <= 0.21e9
