"""Push policies, timestamps, payload checks, bad options, listeners, several
connectors, a serializing transport through the seam, and service ports."""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Protocol

import msgspec
import pytest

from openel_async import VirtualClock
from openel_async.rtc import RTCBadParameterError, RTObject
from openel_async.rtc.ports import (
    Connector,
    ConnectorInfo,
    InPort,
    ListenerType,
    OutPort,
    PortEvent,
    PortStatus,
    PushSink,
    RTCTime,
    ServiceNotConnectedError,
    ServicePort,
    TimedDouble,
    TimedDoubleSeq,
    TimedLong,
    TimedPose2D,
    TimedValue,
    connect_services,
    resolve_data_type,
)


async def collect(clock: VirtualClock, props: dict[str, object], values: list[int]) -> list[int]:
    out, inp = OutPort("o", TimedLong, clock=clock), InPort("i", TimedLong, clock=clock)
    props = {"dataport.buffer.length": 100, **props}
    async with Connector(out, inp, props):
        for v in values:
            await out.write(v)  # no pause: the publisher sees them all at once
        await clock.sleep(0.01)
        got = []
        while inp.is_new():
            got.append((await inp.read()).data)  # type: ignore[union-attr]
    return got


@pytest.mark.parametrize(
    ("policy", "skip", "expected"),
    [("all", 0, [1, 2, 3, 4, 5]), ("new", 0, [5]), ("skip", 1, [1, 3, 5]), ("skip", 3, [1, 5])],
)
async def test_new_publisher_push_policies(
    virtual_clock: VirtualClock, policy: str, skip: int, expected: list[int]
) -> None:
    props = {
        "dataport.subscription_type": "new",
        "dataport.publisher.push_policy": policy,
        "dataport.publisher.skip_count": skip,
    }
    assert await collect(virtual_clock, props, [1, 2, 3, 4, 5]) == expected


async def test_periodic_fifo_sends_one_per_period(virtual_clock: VirtualClock) -> None:
    clock = virtual_clock
    out, inp = OutPort("o", TimedLong, clock=clock), InPort("i", TimedLong, clock=clock)
    arrivals: list[int] = []
    inp.add_listener(ListenerType.ON_RECEIVED, lambda e: arrivals.append(clock.now_ns()))
    props = {
        "dataport.subscription_type": "periodic",
        "dataport.publisher.push_rate": 100,
        "dataport.publisher.push_policy": "fifo",
    }
    async with Connector(out, inp, props):
        start = clock.now_ns()
        for v in (1, 2, 3):
            await out.write(v)
        await clock.sleep(0.035)
    assert [t - start for t in arrivals] == [10_000_000, 20_000_000, 30_000_000]


async def test_skipped_values_are_counted_and_told(virtual_clock: VirtualClock) -> None:
    out, inp = OutPort("o", TimedLong, clock=virtual_clock), InPort("i", TimedLong)
    skipped: list[PortEvent] = []
    out.add_listener(ListenerType.ON_SKIPPED, skipped.append)
    async with Connector(out, inp, {"dataport.subscription_type": "new"}) as conn:
        for v in range(4):
            await out.write(v)
        await virtual_clock.sleep(0.001)
        assert conn.stats.skipped == 3 and conn.stats.sent == 1
    assert [e.data.data for e in skipped if e.data] == [0, 1, 2]


async def test_write_stamps_time_from_the_port_clock(virtual_clock: VirtualClock) -> None:
    rtc = RTObject("comp", clock=virtual_clock)
    out = rtc.add_port(OutPort("out", TimedDoubleSeq))
    inp = InPort("in", TimedDoubleSeq, clock=virtual_clock)
    await virtual_clock.sleep(1.25)
    async with Connector(out, inp):
        await out.write([1, 2, 3, 4, 5, 6])
        await out.write(TimedDoubleSeq(RTCTime(7, 8), (0.5,)))
        first, second = await inp.read(), await inp.read()
    assert first == TimedDoubleSeq(RTCTime(1, 250_000_000), (1.0, 2.0, 3.0, 4.0, 5.0, 6.0))
    assert second is not None and second.tm == RTCTime(7, 8)
    assert out.full_name == "comp.out" and rtc.get_port("out") is out


@pytest.mark.parametrize(
    ("data_type", "bad"),
    [(TimedLong, 2**31), (TimedLong, "7"), (TimedDouble, "x"), (TimedDoubleSeq, [1, "a"])],
)
async def test_bad_payload_refused(data_type: type[TimedValue], bad: object) -> None:
    out = OutPort("o", data_type)
    with pytest.raises(RTCBadParameterError, match=r"o\.write"):
        await out.write(bad)
    assert out.value is None and out.writes == 0


async def test_wrong_struct_type_refused() -> None:
    out = OutPort("o", TimedLong)
    with pytest.raises(RTCBadParameterError, match="RTC::TimedLong"):
        await out.write(TimedDouble(None, 1.0))


async def test_write_and_read_without_connectors() -> None:
    out, inp = OutPort("o", TimedLong), InPort("i", TimedLong)
    assert await out.write(1) is False and out.status is PortStatus.PRECONDITION_NOT_MET
    assert await inp.read() is None and inp.status is PortStatus.PRECONDITION_NOT_MET


def test_different_data_types_refused() -> None:
    with pytest.raises(RTCBadParameterError, match=r"RTC::TimedLong.*RTC::TimedDouble"):
        Connector(OutPort("o", TimedLong), InPort("i", TimedDouble))  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("key", "value", "match"),
    [
        ("dataport.dataflow_type", "shove", "push, pull"),
        ("dataport.subscription_type", "often", "flush, new, periodic"),
        ("dataport.buffer.length", "0", "integer"),
        ("dataport.buffer.length", "2.5", "integer"),
        ("dataport.buffer.write.full_policy", "drop", "overwrite, do_nothing, block"),
        ("dataport.buffer.read.empty_policy", "wait", "readback, do_nothing, block"),
        ("dataport.buffer.write.timeout", "0", "0 < x"),
        ("dataport.buffer.read.timeout", "nan", "0 < x"),
        ("dataport.publisher.push_rate", "0", "1e-06 <= x"),
        ("dataport.publisher.push_policy", "most", "all, fifo, skip, new"),
        ("dataport.bufer.length", "8", "one of"),
        ("dataport.interface_type", "carrier_pigeon", "inprocess"),
        ("dataport.data_type", "RTC::TimedDouble", "RTC::TimedLong"),
        ("dataport.buffer.length", True, "not a bool"),
    ],
)
def test_bad_connector_option(key: str, value: object, match: str) -> None:
    with pytest.raises(RTCBadParameterError, match=match) as info:
        Connector(OutPort("o", TimedLong), InPort("i", TimedLong), {key: value})
    assert info.value.parameter in (key, "connector property")


def test_data_type_names() -> None:
    for name in ("RTC::TimedPose2D", "TimedPose2D", "IDL:RTC/TimedPose2D:1.0"):
        assert resolve_data_type(name) is TimedPose2D
    with pytest.raises(RTCBadParameterError, match="TimedDouble"):
        resolve_data_type("RTC::TimedQuaternion")


async def test_one_inport_two_connectors(virtual_clock: VirtualClock) -> None:
    a, b = OutPort("a", TimedLong), OutPort("b", TimedLong)
    inp = InPort("i", TimedLong, clock=virtual_clock)
    async with Connector(a, inp), Connector(b, inp):
        await b.write(2)
        assert inp.is_new() and inp.readable() == 1
        assert (await inp.read()).data == 2  # type: ignore[union-attr]
        await a.write(1)
        await b.write(3)
        assert [(await inp.read()).data for _ in range(2)] == [1, 3]  # type: ignore[union-attr]


async def test_one_outport_two_inports_fan_out(virtual_clock: VirtualClock) -> None:
    out = OutPort("o", TimedLong)
    x, y = InPort("x", TimedLong), InPort("y", TimedLong)
    full = {"dataport.buffer.length": 1, "dataport.buffer.write.full_policy": "do_nothing"}
    async with Connector(out, x), Connector(out, y, full):
        assert await out.write(1)
        assert not await out.write(2)  # y refused it: write reports the failure
        assert out.status is PortStatus.SEND_FULL
        assert x.readable() == 2 and y.readable() == 1


@pytest.mark.parametrize("flow", ["push", "pull"])
async def test_listeners_added_and_removed_between_writes(
    virtual_clock: VirtualClock, flow: str
) -> None:
    """A listener added after fast-path writes hears the next ones; removed, it hears
    nothing more (writes and reads without listeners skip the event dispatch)."""
    out = OutPort("o", TimedLong, clock=virtual_clock)
    inp = InPort("i", TimedLong, clock=virtual_clock)
    heard: list[tuple[ListenerType, int]] = []

    def listen(event: PortEvent) -> None:
        assert event.data is not None
        heard.append((event.kind, event.data.data))  # type: ignore[attr-defined]

    async with Connector(out, inp, {"dataport.dataflow_type": flow}) as conn:
        assert await out.write(1)
        assert (await inp.read()).data == 1  # type: ignore[union-attr]
        assert heard == []
        out.add_listener(ListenerType.ON_BUFFER_WRITE, listen)
        inp.add_listener(ListenerType.ON_BUFFER_READ, listen)
        assert await out.write(2)
        assert (await inp.read()).data == 2  # type: ignore[union-attr]
        if flow == "push":  # the InPort side holds the buffer: its port hears the write
            assert heard == [(ListenerType.ON_BUFFER_READ, 2)]
        else:
            assert heard == [(ListenerType.ON_BUFFER_WRITE, 2), (ListenerType.ON_BUFFER_READ, 2)]
        inp.add_listener(ListenerType.ON_BUFFER_WRITE, listen)
        heard.clear()
        assert await out.write(3)
        expected = [(ListenerType.ON_BUFFER_WRITE, 3)]
        assert heard == expected
        out.remove_listener(ListenerType.ON_BUFFER_WRITE, listen)
        inp.remove_listener(ListenerType.ON_BUFFER_WRITE, listen)
        inp.remove_listener(ListenerType.ON_BUFFER_READ, listen)
        assert await out.write(4)
        assert [(await inp.read()).data for _ in range(2)] == [3, 4]  # type: ignore[union-attr]
        assert heard == expected
        stats = conn.stats
        assert (stats.written, stats.read) == (4, 4)


class RecordingTransport:
    """A transport that serializes every value, as a network transport would."""

    name = "recording"

    def __init__(self) -> None:
        self.frames: list[bytes] = []

    @asynccontextmanager
    async def push_link(self, info: ConnectorInfo, sink: PushSink) -> AsyncIterator[PushSink]:
        transport = self
        data_type = resolve_data_type(info.data_type)

        class Wire:
            async def put(self, data: TimedValue) -> PortStatus:
                frame = msgspec.msgpack.encode(data)
                transport.frames.append(frame)
                return await sink.put(msgspec.msgpack.decode(frame, type=data_type))

        yield Wire()

    def pull_link(self, info: ConnectorInfo, source: object) -> object:
        raise NotImplementedError


async def test_transport_seam_carries_encoded_values(virtual_clock: VirtualClock) -> None:
    transport = RecordingTransport()
    out = OutPort("o", TimedPose2D, clock=virtual_clock)
    inp = InPort("i", TimedPose2D)
    async with Connector(out, inp, transport=transport) as conn:  # type: ignore[arg-type]
        await out.write(TimedPose2D(RTCTime(1, 2)))
        assert conn.info.key == "o/i"
        assert await inp.read() == TimedPose2D(RTCTime(1, 2))
    assert len(transport.frames) == 1


# -- service ports ------------------------------------------------------------------------


class Motor(Protocol):
    async def move_to(self, position: float) -> float: ...


class MotorImpl:
    def __init__(self) -> None:
        self.targets: list[float] = []

    async def move_to(self, position: float) -> float:
        self.targets.append(position)
        return position * 2


async def test_service_port_call_through_connection() -> None:
    controller, actuator = RTObject("ctl"), RTObject("act")
    cport = controller.add_port(ServicePort("motor"))
    aport = actuator.add_port(ServicePort("motor"))
    impl = MotorImpl()
    aport.provide("motor0", "Motor", impl, Motor)
    motor = cport.require("motor0", "Motor", Motor)
    with pytest.raises(ServiceNotConnectedError, match=r"motor0.*Motor.*ctl\.motor"):
        await motor.ref.move_to(1.0)
    conn = connect_services(cport, aport)
    assert await motor.ref.move_to(1.5) == 3.0 and impl.targets == [1.5]
    conn.disconnect()
    with pytest.raises(ServiceNotConnectedError):
        motor.ref  # noqa: B018


def test_service_port_bad_input() -> None:
    a, b = ServicePort("a"), ServicePort("b")

    class NotMotor:
        def move_to(self, position: float) -> float:  # not async
            return position

    with pytest.raises(RTCBadParameterError, match="move_to"):
        a.provide("m", "Motor", NotMotor(), Motor)
    b.require("m", "Motor", Motor)
    with pytest.raises(RTCBadParameterError, match="interface"):
        connect_services(a, b)  # a provides nothing
    with pytest.raises(RTCBadParameterError, match="a name not yet used"):
        b.require("m", "Motor", Motor)
    with pytest.raises(RTCBadParameterError):
        connect_services(a, OutPort("o", TimedLong))  # type: ignore[arg-type]


def test_port_names_unique_and_known() -> None:
    rtc = RTObject("c")
    rtc.add_port(InPort("in", TimedLong))
    with pytest.raises(RTCBadParameterError, match="not yet used"):
        rtc.add_port(OutPort("in", TimedLong))
    with pytest.raises(RTCBadParameterError, match=r"\['in'\]"):
        rtc.get_port("inn")
