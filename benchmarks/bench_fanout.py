"""Fan-out throughput: one component's events to 10 ObserverQueues drained by 10 tasks.

The publisher is an Actuator over a tiny driver that keeps its DeviceContext and posts
device events with ``ctx.post_event(2)`` (LIMIT_REACHED), the public path a driver uses;
the component's fan-out calls ``notify_event`` on each registered ObserverQueue. The
baseline does the same job by hand with 10 anyio memory object streams.

Batching: the publisher posts BATCH events, then yields once to the event loop. The
consumers woken by the batch run before the publisher resumes, and each drains its
whole queue without yielding (an ObserverQueue's iterator only waits when it is empty;
the stream consumer drains with ``receive_nowait``), so a queue never holds more than
BATCH notices and queues of QUEUE_SIZE >= BATCH lose nothing. That is checked, not
assumed: every queue's ``missed_total`` must be 0 and every consumer must count every
event.
"""

from __future__ import annotations

import gc
import statistics
import time
from dataclasses import dataclass

import anyio
import anyio.lowlevel
from anyio.streams.memory import MemoryObjectReceiveStream

from openel_async import (
    Actuator,
    ActuatorDevice,
    DeviceContext,
    DeviceInfo,
    DeviceKind,
    EventId,
    ObserverQueue,
    Request,
)

from .harness import BenchResult, Row, ratio_of

NAME = "fanout"
OBSERVERS = 10
EVENTS = 200_000
QUICK_EVENTS = 40_000
BATCH = 100
QUEUE_SIZE = 1024
ROUNDS = 3
QUICK_ROUNDS = 1
TARGET_RATE = 200_000.0
EVENT = int(EventId.LIMIT_REACHED)


class EventSource(ActuatorDevice):
    """A driver that only posts events: it keeps the context the component gives it."""

    info = DeviceInfo(kind=DeviceKind.MOTOR, vendor_name="Bench", product_name="EventSource")
    reports_completion = True  # no completion-detection task: nothing but the fan-out runs

    def __init__(self) -> None:
        self.ctx: DeviceContext | None = None

    async def open(self, ctx: DeviceContext) -> None:
        self.ctx = ctx

    async def command(self, request: Request, value: float) -> None:
        pass

    async def read(self, request: Request) -> float:
        return 0.0


@dataclass(frozen=True, slots=True)
class Run:
    deliveries: int
    seconds: float
    lost: int

    @property
    def rate(self) -> float:
        return self.deliveries / self.seconds


async def _drain_queue(queue: ObserverQueue, counts: list[int], i: int) -> None:
    n = 0
    lost = 0
    async for notice in queue:
        n += 1
        lost += notice.missed
    counts[i] = n - lost  # a notice that reports missed ones stands for a loss


async def framework_round(events: int) -> Run:
    source = EventSource()
    queues = [ObserverQueue(QUEUE_SIZE, name=f"bench-fanout-{i}") for i in range(OBSERVERS)]
    counts = [0] * OBSERVERS
    async with Actuator(source) as actuator, anyio.create_task_group() as tg:
        for i, queue in enumerate(queues):
            actuator.add_observer(queue)
            tg.start_soon(_drain_queue, queue, counts, i)
        assert source.ctx is not None
        post = source.ctx.post_event
        await anyio.lowlevel.checkpoint()  # consumers are waiting on their empty queues
        t0 = time.perf_counter()
        for _ in range(events // BATCH):
            for _ in range(BATCH):
                post(EVENT)
            await anyio.lowlevel.checkpoint()
        for queue in queues:
            queue.close()  # each consumer ends once it took what is queued
    seconds = time.perf_counter() - t0
    sent = events // BATCH * BATCH
    lost = sum(q.missed_total for q in queues) + sum(sent - c for c in counts)
    return Run(deliveries=sum(counts), seconds=seconds, lost=lost)


async def _drain_stream(stream: MemoryObjectReceiveStream[int], counts: list[int], i: int) -> None:
    n = 0
    async with stream:
        while True:
            try:
                await stream.receive()
            except anyio.EndOfStream:
                break
            n += 1
            while True:  # take what is buffered without yielding, like ObserverQueue
                try:
                    stream.receive_nowait()
                except (anyio.WouldBlock, anyio.EndOfStream):
                    break
                n += 1
    counts[i] = n


async def baseline_round(events: int) -> Run:
    counts = [0] * OBSERVERS
    lost = 0
    async with anyio.create_task_group() as tg:
        senders = []
        for i in range(OBSERVERS):
            send, receive = anyio.create_memory_object_stream[int](QUEUE_SIZE)
            senders.append(send)
            tg.start_soon(_drain_stream, receive, counts, i)
        await anyio.lowlevel.checkpoint()
        t0 = time.perf_counter()
        for _ in range(events // BATCH):
            for _ in range(BATCH):
                for send in senders:
                    try:
                        send.send_nowait(EVENT)
                    except anyio.WouldBlock:
                        lost += 1
            await anyio.lowlevel.checkpoint()
        for send in senders:
            send.close()
    seconds = time.perf_counter() - t0
    sent = events // BATCH * BATCH
    lost += sum(sent - c for c in counts)
    return Run(deliveries=sum(counts), seconds=seconds, lost=lost)


def run(quick: bool) -> BenchResult:
    events = QUICK_EVENTS if quick else EVENTS
    rounds = QUICK_ROUNDS if quick else ROUNDS
    ours: list[Run] = []
    base: list[Run] = []
    for _ in range(rounds):  # alternate, so load changes hit both alike
        gc.collect()
        ours.append(anyio.run(framework_round, events, backend="asyncio"))
        gc.collect()
        base.append(anyio.run(baseline_round, events, backend="asyncio"))

    rate = statistics.median(r.rate for r in ours)
    base_rate = statistics.median(r.rate for r in base)
    lost = sum(r.lost for r in ours)
    base_lost = sum(r.lost for r in base)
    per_delivery = 1e9 / rate
    base_per_delivery = 1e9 / base_rate
    rows = (
        Row(
            "deliveries per second",
            rate,
            "/s",
            baseline=base_rate,
            baseline_label="memory streams",
            ratio=ratio_of(rate, base_rate),
            ratio_label="ours/streams",
            target=f">= {TARGET_RATE:,.0f}/s",
            passed=rate >= TARGET_RATE,
            digits=0,
        ),
        Row(
            "time per delivery",
            per_delivery,
            "ns",
            baseline=base_per_delivery,
            baseline_label="memory streams",
            ratio=ratio_of(base_per_delivery, per_delivery),
            ratio_label="streams/ours",
            digits=0,
        ),
        Row(
            "notifications lost",
            lost,
            baseline=base_lost,
            baseline_label="memory streams",
            target="0",
            passed=lost == 0,
            digits=0,
        ),
    )
    spread = ", ".join(f"{r.rate:,.0f}" for r in ours)
    base_spread = ", ".join(f"{r.rate:,.0f}" for r in base)
    notes = (
        f"Median of {rounds} alternating round(s) of {events:,} events x {OBSERVERS} "
        f"observers = {events * OBSERVERS:,} deliveries each; per-round rates: ours "
        f"{spread}; streams {base_spread}.",
        f"Publisher yields once every {BATCH} events; queues hold {QUEUE_SIZE}; every "
        "queue's `missed_total` and every consumer's count were checked.",
    )
    return BenchResult(
        name=NAME,
        title=f"event fan-out to {OBSERVERS} ObserverQueues vs anyio memory streams",
        rows=rows,
        description=DESCRIPTION,
        notes=notes,
        params={
            "observers": str(OBSERVERS),
            "events per round": f"{events:,}",
            "batch": str(BATCH),
            "queue size": str(QUEUE_SIZE),
            "rounds": str(rounds),
        },
    )


DESCRIPTION = f"""\
One publisher component (an `Actuator` over a tiny driver that keeps its
`DeviceContext` and calls `ctx.post_event(2)`, the public path a driver posts events
on) with {OBSERVERS} `ObserverQueue`s registered by `add_observer`, each drained by its own
consumer task (`async for notice in queue`). Figure: deliveries per second = events x
{OBSERVERS} / wall time from the first event until every consumer finished. Baseline,
in the same run: {OBSERVERS} anyio memory object streams, `send_nowait` to each and one
consumer task per stream.

Batching (both cases): the publisher posts {BATCH} events, then yields once
(`anyio.lowlevel.checkpoint()`); the consumers woken by the batch run before it resumes
and each drains its whole queue without yielding (the ObserverQueue iterator waits only
when the queue is empty; the stream consumer awaits `receive()` then drains with
`receive_nowait()`). A queue thus never holds more than {BATCH} notices, and with
{QUEUE_SIZE}-slot queues nothing is lost, which is checked: `missed_total == 0` for every
queue and every consumer counted every event."""
