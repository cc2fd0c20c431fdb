"""Composite components (members share the owner's context and exit with it) and the
SPORADIC execution context."""

from __future__ import annotations

import pytest

from openel_async import VirtualClock
from openel_async.rtc import (
    CallbackResult,
    CompositeRTObject,
    ExecutionKind,
    LifeCycleState,
    ObjectState,
    PeriodicExecutionContext,
    PreconditionNotMetError,
    RTCBadParameterError,
    RTObject,
    SporadicExecutionContext,
    composite_of,
)
from openel_async.rtc.ports import Connector, InPort, ListenerType, OutPort, TimedLong

MS = 1_000_000


class Rec(RTObject):
    def __init__(self, name: str, log: list[str], clock: VirtualClock) -> None:
        super().__init__(name, clock=clock)
        self.journal = log

    def _rec(self, what: str) -> None:
        self.journal.append(f"{self.instance_name}.{what}")

    async def on_activated(self, exec_handle: int) -> CallbackResult:
        self._rec("on_activated")
        return None

    async def on_deactivated(self, exec_handle: int) -> CallbackResult:
        self._rec("on_deactivated")
        return None

    async def on_execute(self, exec_handle: int) -> CallbackResult:
        self._rec(f"on_execute@{self.clock.now_ns() // MS}")
        return None

    async def on_finalize(self) -> CallbackResult:
        self._rec("on_finalize")
        return None


class Group(CompositeRTObject):
    def __init__(self, name: str, log: list[str], clock: VirtualClock) -> None:
        super().__init__(name, clock=clock)
        self.journal = log

    async def on_execute(self, exec_handle: int) -> CallbackResult:
        self.journal.append(f"{self.instance_name}.on_execute@{self.clock.now_ns() // MS}")
        return None

    async def on_finalize(self) -> CallbackResult:
        self.journal.append(f"{self.instance_name}.on_finalize")
        return None


async def test_members_share_the_context_and_exit_with_the_composite(
    virtual_clock: VirtualClock,
) -> None:
    log: list[str] = []
    group = Group("g", log, virtual_clock)
    a, b = Rec("a", log, virtual_clock), Rec("b", log, virtual_clock)
    async with PeriodicExecutionContext(100.0, owner=group, clock=virtual_clock) as ec:
        for rtc in (group, a, b):
            await rtc.initialize()
        await group.add_member(a)
        await ec.add_component(group)  # a joins with it
        await group.add_member(b)  # b joins at once
        assert ec.participants == (group, a, b)
        assert composite_of(a) is group and group.members == (a, b)
        await ec.start()
        await ec.activate_component(group)
        assert log == ["a.on_activated", "b.on_activated"]
        assert ec.get_component_state(b) is LifeCycleState.ACTIVE
        await virtual_clock.sleep(0.015)
        assert log[2:] == ["g.on_execute@10", "a.on_execute@10", "b.on_execute@10"]
        del log[:]
        await group.exit()
    assert log == [
        "a.on_deactivated",
        "b.on_deactivated",
        "g.on_finalize",
        "a.on_finalize",
        "b.on_finalize",
    ]
    assert {r.state for r in (group, a, b)} == {ObjectState.FINALIZED}
    assert ec.participants == ()


async def test_nested_composites_exit_transitively(virtual_clock: VirtualClock) -> None:
    log: list[str] = []
    outer, inner = Group("outer", log, virtual_clock), Group("inner", log, virtual_clock)
    leaf = Rec("leaf", log, virtual_clock)
    for rtc in (outer, inner, leaf):
        await rtc.initialize()
    await inner.add_member(leaf)
    await outer.add_member(inner)
    await outer.exit()
    assert log == ["outer.on_finalize", "inner.on_finalize", "leaf.on_finalize"]


async def test_membership_errors(virtual_clock: VirtualClock) -> None:
    log: list[str] = []
    g1, g2 = Group("g1", log, virtual_clock), Group("g2", log, virtual_clock)
    a = Rec("a", log, virtual_clock)
    for rtc in (g1, g2):
        await rtc.initialize()
    with pytest.raises(PreconditionNotMetError):
        await g1.add_member(a)  # Created
    await a.initialize()
    with pytest.raises(RTCBadParameterError):
        await g1.add_member(g1)
    await g1.add_member(g2)
    with pytest.raises(RTCBadParameterError, match="does not contain"):
        await g2.add_member(g1)
    await g1.add_member(a)
    with pytest.raises(PreconditionNotMetError, match="member of g1"):
        await g2.add_member(a)
    await g1.remove_member(a)
    assert composite_of(a) is None
    await g2.add_member(a)
    with pytest.raises(RTCBadParameterError):
        await g1.remove_member(a)


async def test_sporadic_minimum_interval(virtual_clock: VirtualClock) -> None:
    log: list[str] = []
    rtc = Rec("s", log, virtual_clock)
    await rtc.initialize()
    async with SporadicExecutionContext(0.1, owner=rtc, clock=virtual_clock) as ec:
        assert ec.get_kind() is ExecutionKind.OTHER
        with pytest.raises(PreconditionNotMetError):
            ec.trigger()
        await ec.add_component(rtc)
        await ec.start()
        await ec.activate_component(rtc)
        for at_ms in (0, 30, 50, 250):
            await virtual_clock.sleep_until(at_ms * MS)
            ec.trigger()
        await virtual_clock.sleep(0.5)
        assert [e for e in log if "execute" in e] == [
            "s.on_execute@0",
            "s.on_execute@100",
            "s.on_execute@250",
        ]
        assert ec.stats.skipped == 1 and ec.stats.cycles == 3
        await rtc.exit()


@pytest.mark.parametrize("bad", [-1.0, float("nan"), "0.1", True])
def test_sporadic_bad_interval(bad: object) -> None:
    with pytest.raises(RTCBadParameterError, match="min_interval"):
        SporadicExecutionContext(bad)  # type: ignore[arg-type]


class Consumer(RTObject):
    """Runs when data arrives: its InPort's ON_RECEIVED listener triggers its context."""

    def __init__(self, clock: VirtualClock) -> None:
        super().__init__("consumer", clock=clock)
        self.inp = self.add_port(InPort("in", TimedLong))
        self.seen: list[tuple[int, int]] = []

    async def on_execute(self, exec_handle: int) -> CallbackResult:
        while self.inp.is_new():
            value = await self.inp.read()
            assert value is not None
            self.seen.append((self.clock.now_ns() // MS, value.data))
        return None


async def test_sporadic_component_runs_on_data_arrival(virtual_clock: VirtualClock) -> None:
    consumer = Consumer(virtual_clock)
    out = OutPort("out", TimedLong, clock=virtual_clock)
    await consumer.initialize()
    async with (
        SporadicExecutionContext(0.02, owner=consumer, clock=virtual_clock) as ec,
        Connector(out, consumer.inp),
    ):
        consumer.inp.add_listener(ListenerType.ON_RECEIVED, lambda e: ec.trigger())
        await ec.add_component(consumer)
        await ec.start()
        await ec.activate_component(consumer)
        await out.write(1)
        await virtual_clock.sleep(0.005)
        await out.write(2)  # within 20 ms: deferred to 20 ms
        await out.write(3)
        await virtual_clock.sleep(0.1)
        await consumer.exit()
    assert consumer.seen == [(0, 1), (20, 2), (20, 3)]
