"""A component's events from its device (``ctx.post_event``) take a fast path while its
observers are all alike; every path delivers the same, in order, counted, isolated."""

from __future__ import annotations

from typing import Any

import anyio
import anyio.lowlevel
import pytest

from openel_async import (
    Actuator,
    ActuatorDevice,
    DeviceContext,
    DeviceInfo,
    DeviceKind,
    ObserverQueue,
    Request,
    VirtualClock,
)
from openel_async.observers import EventNotice


class EventSource(ActuatorDevice):
    info = DeviceInfo(kind=DeviceKind.MOTOR, vendor_name="Test", product_name="EventSource")
    reports_completion = True

    def __init__(self) -> None:
        self.ctx: DeviceContext | None = None

    async def open(self, ctx: DeviceContext) -> None:
        self.ctx = ctx

    async def command(self, request: Request, value: float) -> None:
        pass

    async def read(self, request: Request) -> float:
        return 0.0


class Plain:
    def __init__(self, log: list[Any], name: str, fail: bool = False) -> None:
        self.log, self.name, self.fail = log, name, fail

    def notify_event(self, source: object, event_id: int) -> None:
        self.log.append((self.name, source, event_id))
        if self.fail:
            raise RuntimeError("observer failed")

    def notify_error(self, source: object, error_id: int) -> None:
        pass


class WithNotice:
    def __init__(self, log: list[Any]) -> None:
        self.log = log

    def notify_event(
        self, source: object, event_id: int, notice: EventNotice | None = None
    ) -> None:
        assert notice is not None
        self.log.append(("notice", notice.source is source, notice.event_id, notice.missed))

    def notify_error(self, source: object, error_id: int) -> None:
        pass


class Async:
    def __init__(self, log: list[Any], name: str) -> None:
        self.log, self.name = log, name

    async def notify_event(self, source: object, event_id: int) -> None:
        self.log.append((self.name, source, event_id))

    async def notify_error(self, source: object, error_id: int) -> None:
        pass


async def test_every_observer_shape_gets_every_event_counted() -> None:
    log: list[Any] = []
    async with Actuator(EventSource(), clock=VirtualClock()) as actuator:
        device = actuator.device
        assert isinstance(device, EventSource) and device.ctx is not None
        post = device.ctx.post_event  # kept by the driver, as drivers do
        post(1)  # no observer: published, heard by nobody
        one = Plain(log, "one", fail=True)
        actuator.add_observer(one)  # one bound method: the func/obj path
        post(2)
        actuator.add_observer(Plain(log, "two"))  # several plain: the tuple path
        post(3)
        actuator.remove_observer(one)
        post(4)
        notice = WithNotice(log)
        actuator.add_observer(notice)  # plain, mixed notice: the general path
        post(5)
        stats = actuator.observer_stats
        assert stats.published == 5
        assert stats.failures == 2  # 'one' raised twice; the others still heard
        assert [entry[2] if entry[0] != "notice" else entry for entry in log] == [
            2,
            3,
            3,
            4,
            5,
            ("notice", True, 5, 0),
        ]
        assert all(entry[1] is actuator for entry in log if entry[0] != "notice")


async def test_notice_taking_and_async_paths() -> None:
    log: list[Any] = []
    async with Actuator(EventSource(), clock=VirtualClock()) as actuator:
        device = actuator.device
        assert isinstance(device, EventSource) and device.ctx is not None
        post = device.ctx.post_event
        queue = ObserverQueue(8)  # one plain observer taking the notice
        actuator.add_observer(queue)
        post(7)
        post(7)
        got = [queue.get_nowait(), queue.get_nowait()]
        assert [(n.source, n.event_id) for n in got] == [(actuator, 7)] * 2
        assert got[0] == got[1] == EventNotice(actuator, 7)
        assert got[0] is got[1]  # a value, built once per event id and reused
        actuator.remove_observer(queue)
        queue = ObserverQueue(1)
        actuator.add_observer(queue)
        post(7)
        post(8)  # overflows: the notice reporting it is a new one, the reused one intact
        assert queue.get_nowait() == EventNotice(actuator, 8, missed=1)
        post(8)
        assert queue.get_nowait() == EventNotice(actuator, 8)
        actuator.remove_observer(queue)
        first, second = Async(log, "a"), Async(log, "b")  # async only: mailboxes' put
        actuator.add_observer(first)
        actuator.add_observer(second)
        for event_id in (1, 2, 1):
            post(event_id)
        with anyio.fail_after(5):
            while len(log) < 6:
                await anyio.lowlevel.checkpoint()
        assert [e[2] for e in log if e[0] == "a"] == [1, 2, 1]
        assert [e[2] for e in log if e[0] == "b"] == [1, 2, 1]
        assert actuator.observer_stats.published == 8
        assert actuator.observer_stats.lost == 0  # (the queue's overflow is its own)
        assert queue.missed_total == 1


@pytest.mark.parametrize("shape", ["plain", "async"])
async def test_no_event_once_finalized(shape: str) -> None:
    log: list[Any] = []
    async with Actuator(EventSource(), clock=VirtualClock()) as actuator:
        device = actuator.device
        assert isinstance(device, EventSource) and device.ctx is not None
        actuator.add_observer(Plain(log, "p") if shape == "plain" else Async(log, "a"))
        await actuator.finalize()
        device.ctx.post_event(3)
        await anyio.lowlevel.checkpoint()
        assert log == []
        assert actuator.observer_stats.unpublished == 1


async def test_registering_observers_does_not_rebuild_the_fast_paths_each_time(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Registration stays O(1) per observer past a few: for the first few, the fast paths
    are set at registration (the next event pays nothing); past them, by the first event
    after a change, once."""
    from openel_async import component

    refreshes: list[int] = []
    refresh = component.HALComponent._refresh_events

    def counting(self: component.HALComponent) -> None:
        refreshes.append(len(self.observers))
        refresh(self)

    monkeypatch.setattr(component.HALComponent, "_refresh_events", counting)
    log: list[Any] = []
    async with Actuator(EventSource(), clock=VirtualClock()) as actuator:
        device = actuator.device
        assert isinstance(device, EventSource) and device.ctx is not None
        refreshes.clear()
        actuator.add_observer(Plain(log, "p0"))
        assert refreshes == [1]  # set at registration: the first event pays nothing
        device.ctx.post_event(0)
        assert refreshes == [1]
        for i in range(1, 50):
            actuator.add_observer(Plain(log, f"p{i}"))
        eager = len(refreshes)
        assert 1 < eager < 50
        assert refreshes == list(range(1, eager + 1))  # none past the eager limit
        device.ctx.post_event(1)
        device.ctx.post_event(2)
        assert refreshes == [*range(1, eager + 1), 50]  # once, at the first event
        assert [entry[2] for entry in log] == [0] + [1] * 50 + [2] * 50
        assert actuator.observer_stats.published == 3
