"""CANopen request/answer latency: our stack vs canopen-py, same peers, same virtual bus.

1. **SDO upload round trip.** An SDO echo peer (a plain python-can thread on its own
   virtual bus answering every SDO upload request of node 5 with an expedited 4-byte
   response) serves both clients. Ours: ``SdoClient.upload(0x6041, 0)`` on a
   :class:`~openel_can.CanBus`; canopen-py: ``RemoteNode.sdo.upload(0x6041, 0)`` on a
   ``canopen.Network`` (its python-can Notifier thread feeds the SDO response queue).
2. **CiA 402 profile-position set-point handshake.** Our simulated CiA 402 drive
   (:class:`~openel_can.sim.cia402.SimCia402Drive`) runs in its own thread and event loop
   (an anyio blocking portal) on its own virtual bus, for both clients. Each set-point
   is 3 RPDOs and 2 TPDOs: controlword without new set-point -> wait statusword
   set-point acknowledge low; new set-point -> wait acknowledge high; clear new
   set-point. Ours: ``Actuator(Cia402Drive).set_value(x, POSITION)``; canopen-py: the
   same handshake written with its PDO API (``PdoMap`` variables, ``transmit``, the
   TPDO's ``receive_condition``), the drive configured by canopen's SDO client exactly
   as our driver configures it (same mappings, event timer 10 ms, heartbeat 1 s).

Rounds alternate ours and canopen-py; the figures are medians per operation; the
ratio is ours/canopen-py time (< 1: ours is faster), in the target rows the median of the
rounds' own ratios.
"""

from __future__ import annotations

import math
import statistics
import struct
import threading
import time
import uuid
from collections.abc import Callable
from typing import NamedTuple

import anyio
import anyio.from_thread
import can
import canopen
from canopen import objectdictionary as cod

from openel_async import Actuator, ComponentState, Request
from openel_can import CanBus, Cia402Drive, SdoClient
from openel_can.sim.cia402 import SimCia402Drive

from .harness import BenchResult, Row, interleaved, ratio_of

NAME = "can_canopen"
NODE = 5
SDO_COUNT = 1_500
QUICK_SDO_COUNT = 500
SETPOINTS = 500
QUICK_SETPOINTS = 200
ROUNDS = 15
QUICK_ROUNDS = 5
"""Issue 27: a target is met by the median of at least 5 interleaved rounds. The target
rows' ratio is the median of the rounds' own ratios (ours / the canopen-py round run
right after it), so a change of the machine's load between rounds cancels out."""
WARMUP = 50
TARGET_SDO = 1.0
"""Issue 27 (was 1.2x)."""
TARGET_402 = 1.1
SDO_TIMEOUT = 1.0
STATUSWORD = 0x6041
ECHO_VALUE = struct.pack("<I", 0x0237)


class Op(NamedTuple):
    """One round's figures per operation."""

    seconds: float
    """Wall time per operation."""
    cpu: float
    """CPU time of the calling thread (the event loop's, for ours) per operation."""


def _channel(kind: str) -> str:
    return f"bench-co-{kind}-{uuid.uuid4().hex[:8]}"


# -- peers -----------------------------------------------------------------------------------


class SdoEchoPeer:
    """A python-can thread answering every SDO upload request of ``node`` (expedited)."""

    def __init__(self, channel: str, node: int) -> None:
        self.bus = can.Bus(interface="virtual", channel=channel)
        self.node = node
        self.answered = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="sdo-echo-peer", daemon=True)

    def _run(self) -> None:
        request_id, reply_id = 0x600 + self.node, 0x580 + self.node
        bus = self.bus
        while not self._stop.is_set():
            msg = bus.recv(0.05)
            if msg is None or msg.arbitration_id != request_id or msg.data[0] != 0x40:
                continue
            data = b"\x43" + bytes(msg.data[1:4]) + ECHO_VALUE
            bus.send(can.Message(arbitration_id=reply_id, data=data, is_extended_id=False))
            self.answered += 1

    def __enter__(self) -> SdoEchoPeer:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self.bus.shutdown()


def _var(name: str, index: int, data_type: int, subindex: int = 0) -> cod.ODVariable:
    var = cod.ODVariable(name, index, subindex)
    var.data_type = data_type
    var.access_type = "rw"
    return var


def _canopen_od() -> cod.ObjectDictionary:
    od = cod.ObjectDictionary()
    for name, index, dtype in (
        ("Controlword", 0x6040, cod.UNSIGNED16),
        ("Statusword", 0x6041, cod.UNSIGNED16),
        ("Modes of operation", 0x6060, cod.INTEGER8),
        ("Modes of operation display", 0x6061, cod.INTEGER8),
        ("Position actual value", 0x6064, cod.INTEGER32),
        ("Velocity actual value", 0x606C, cod.INTEGER32),
        ("Torque actual value", 0x6077, cod.INTEGER16),
        ("Target position", 0x607A, cod.INTEGER32),
    ):
        od.add_object(_var(name, index, dtype))
    for comm, mapping in ((0x1400, 0x1600), (0x1800, 0x1A00), (0x1801, 0x1A01)):
        record = cod.ODRecord(f"PDO communication {comm:#06x}", comm)
        for sub, dtype in ((0, cod.UNSIGNED8), (1, cod.UNSIGNED32), (2, cod.UNSIGNED8)):
            record.add_member(_var(f"sub{sub}", comm, dtype, sub))
        record.add_member(_var("inhibit time", comm, cod.UNSIGNED16, 3))
        record.add_member(_var("event timer", comm, cod.UNSIGNED16, 5))
        od.add_object(record)
        array = cod.ODRecord(f"PDO mapping {mapping:#06x}", mapping)
        array.add_member(_var("count", mapping, cod.UNSIGNED8, 0))
        for sub in range(1, 9):
            array.add_member(_var(f"entry {sub}", mapping, cod.UNSIGNED32, sub))
        od.add_object(array)
    return od


# -- 1. SDO round trips ------------------------------------------------------------------------


async def ours_sdo(count: int) -> Op:
    """Seconds per SDO upload with our SdoClient."""
    channel = _channel("sdo")
    with SdoEchoPeer(channel, NODE) as peer:
        async with CanBus(interface="virtual", channel=channel, name="bench-sdo") as bus:
            client = SdoClient(bus, NODE, timeout=SDO_TIMEOUT)
            for _ in range(WARMUP):
                await client.upload(STATUSWORD, 0)
            started, cpu = time.perf_counter(), time.thread_time()
            for _ in range(count):
                if await client.upload(STATUSWORD, 0) != ECHO_VALUE:
                    raise AssertionError("ours: wrong SDO answer")
            elapsed, cpu = time.perf_counter() - started, time.thread_time() - cpu
        if peer.answered != count + WARMUP or client.timeouts:
            raise AssertionError(f"ours: {peer.answered} answers, {client.timeouts} timeouts")
    return Op(elapsed / count, cpu / count)


def canopen_sdo(count: int) -> Op:
    """Seconds per SDO upload with canopen-py."""
    channel = _channel("sdo")
    with SdoEchoPeer(channel, NODE) as peer:
        network = canopen.Network()
        network.connect(interface="virtual", channel=channel)
        try:
            node = canopen.RemoteNode(NODE, _canopen_od())
            network.add_node(node)
            node.sdo.RESPONSE_TIMEOUT = SDO_TIMEOUT
            upload = node.sdo.upload
            for _ in range(WARMUP):
                upload(STATUSWORD, 0)
            started, cpu = time.perf_counter(), time.thread_time()
            for _ in range(count):
                if upload(STATUSWORD, 0) != ECHO_VALUE[:2]:  # canopen trims to the OD size
                    raise AssertionError("canopen: wrong SDO answer")
            elapsed, cpu = time.perf_counter() - started, time.thread_time() - cpu
        finally:
            network.disconnect()
        if peer.answered != count + WARMUP:
            raise AssertionError(f"canopen: {peer.answered} answers")
    return Op(elapsed / count, cpu / count)


# -- 2. CiA 402 set-point handshake -----------------------------------------------------------


def _with_sim_drive(body: Callable[[str], Op]) -> Op:
    """Run ``body(channel)`` with a SimCia402Drive served in its own thread and event loop."""
    channel = _channel("402")
    sim = SimCia402Drive(NODE)
    with anyio.from_thread.start_blocking_portal(backend="asyncio") as portal:
        future, _ = portal.start_task(sim.serve, channel)
        try:
            return body(channel)
        finally:
            future.cancel()


def _target(i: int) -> float:
    return 0.2 * math.sin(i * 0.01)


def ours_402(count: int) -> Op:
    """Seconds per set-point with Actuator(Cia402Drive).set_value."""

    async def main(channel: str) -> Op:
        async with (
            CanBus(interface="virtual", channel=channel, name="bench-402") as bus,
            Actuator(Cia402Drive(bus, NODE)) as axis,
        ):
            position = Request.POSITION
            for i in range(WARMUP):
                await axis.set_value(_target(i), position)
            started, cpu = time.perf_counter(), time.thread_time()
            for i in range(count):
                await axis.set_value(_target(i), position)
            elapsed, cpu = time.perf_counter() - started, time.thread_time() - cpu
            if axis.state is not ComponentState.ACTIVE:
                raise AssertionError(f"ours left Active: {axis.last_fault}")
        return Op(elapsed / count, cpu / count)

    return _with_sim_drive(lambda channel: anyio.run(main, channel, backend="asyncio"))


class _CanopenAxis:
    """A CiA 402 drive driven by canopen-py: configured like Cia402Drive, pp set-points."""

    def __init__(self, network: canopen.Network, node_id: int) -> None:
        self.node = canopen.RemoteNode(node_id, _canopen_od())
        network.add_node(self.node)
        self.node.sdo.RESPONSE_TIMEOUT = SDO_TIMEOUT
        self.counts_per_rad = 10_000 / math.tau

    def configure(self) -> None:
        node, n = self.node, self.node.id
        node.nmt.send_command(0x80)  # pre-operational
        node.sdo.download(0x1017, 0, struct.pack("<H", 1000))  # heartbeat 1 s
        rpdo, tpdo1, tpdo2 = node.rpdo[1], node.tpdo[1], node.tpdo[2]
        for pdo, cob, names, event in (
            (rpdo, 0x200 + n, ("Controlword", "Target position"), None),
            (tpdo1, 0x180 + n, ("Statusword", "Position actual value", "Torque actual value"), 10),
            (tpdo2, 0x280 + n, ("Velocity actual value", "Modes of operation display"), 10),
        ):
            pdo.clear()
            for name in names:
                pdo.add_variable(name)
            pdo.cob_id = cob
            pdo.trans_type = 0xFF
            pdo.event_timer = event
            pdo.enabled = True
            pdo.save()  # canopen's SDO client writes the mapping, as our driver does
        node.sdo.download(0x6060, 0, struct.pack("<b", 1))  # profile position
        self.rpdo, self.tpdo = rpdo, tpdo1
        self.controlword = rpdo["Controlword"]
        self.target = rpdo["Target position"]
        self.statusword = tpdo1["Statusword"]
        with tpdo1.receive_condition:
            node.nmt.send_command(0x01)  # start
            if not tpdo1.receive_condition.wait_for(lambda: tpdo1.is_received, 1.0):
                raise AssertionError("canopen: no TPDO1 after NMT start")
        # Shutdown, switch on, enable operation (statusword masks of CiA 402).
        for word, mask, value in ((0x06, 0x6F, 0x21), (0x07, 0x6F, 0x23), (0x0F, 0x6F, 0x27)):
            self.send(word, 0, lambda sw, m=mask, v=value: sw & m == v)

    def send(self, controlword: int, target: int, until: Callable[[int], bool] | None) -> None:
        """Transmit the RPDO; with ``until``, wait (bounded) for a statusword it accepts."""
        self.controlword.raw = controlword
        self.target.raw = target
        condition = self.tpdo.receive_condition
        with condition:
            self.rpdo.transmit()
            if until is not None and not condition.wait_for(
                lambda: until(self.statusword.raw), 0.5
            ):
                raise AssertionError(f"canopen: no statusword for controlword {controlword:#x}")

    def set_position(self, rad: float) -> None:
        """The profile-position set-point handshake (3 RPDO, 2 TPDO)."""
        counts = round(rad * self.counts_per_rad)
        base = 0x0F | 0x20  # enable operation, change set immediately
        self.send(base, counts, lambda sw: not sw & 0x1000)
        self.send(base | 0x10, counts, lambda sw: bool(sw & 0x1000))
        self.send(base, counts, None)


def canopen_402(count: int) -> Op:
    """Seconds per set-point with canopen-py's PDO API."""

    def body(channel: str) -> Op:
        network = canopen.Network()
        network.connect(interface="virtual", channel=channel)
        try:
            axis = _CanopenAxis(network, NODE)
            axis.configure()
            for i in range(WARMUP):
                axis.set_position(_target(i))
            started, cpu = time.perf_counter(), time.thread_time()
            for i in range(count):
                axis.set_position(_target(i))
            elapsed, cpu = time.perf_counter() - started, time.thread_time() - cpu
            return Op(elapsed / count, cpu / count)
        finally:
            network.disconnect()

    return _with_sim_drive(body)


# -- the benchmark ---------------------------------------------------------------------------


def run(quick: bool) -> BenchResult:
    sdo_count = QUICK_SDO_COUNT if quick else SDO_COUNT
    setpoints = QUICK_SETPOINTS if quick else SETPOINTS
    rounds = QUICK_ROUNDS if quick else ROUNDS
    measured = interleaved(  # ours, peer, ours, peer ...
        rounds,
        {
            "ours_s": lambda: anyio.run(ours_sdo, sdo_count, backend="asyncio"),
            "peer_s": lambda: canopen_sdo(sdo_count),
            "ours_h": lambda: ours_402(setpoints),
            "peer_h": lambda: canopen_402(setpoints),
        },
    )
    ours_s, peer_s = measured["ours_s"], measured["peer_s"]
    ours_h, peer_h = measured["ours_h"], measured["peer_h"]

    def median(ops: list[Op], field: str = "seconds") -> float:
        return statistics.median(getattr(op, field) for op in ops)

    sdo, sdo_peer = median(ours_s), median(peer_s)
    hs, hs_peer = median(ours_h), median(peer_h)

    def us(ops: list[Op]) -> str:
        return ", ".join(f"{op.seconds * 1e6:.0f}" for op in ops)

    def ratios(ours: list[Op], peer: list[Op]) -> str:
        return ", ".join(f"{o.seconds / p.seconds:.2f}" for o, p in zip(ours, peer, strict=True))

    def paired(ours: list[Op], peer: list[Op]) -> float:
        """The median of the per-round ratios ours / canopen-py."""
        return statistics.median(o.seconds / p.seconds for o, p in zip(ours, peer, strict=True))

    def row(
        metric: str,
        ours: float,
        peer: float,
        target: float | None = None,
        ratio: float | None = None,
    ) -> Row:
        ratio = ratio_of(ours, peer) if ratio is None else ratio
        return Row(
            metric,
            ours * 1e6,
            "µs",
            baseline=peer * 1e6,
            baseline_label="canopen-py",
            ratio=ratio,
            ratio_label="ours/canopen-py",
            target="" if target is None else f"<= {target:.1f}x canopen-py",
            passed=None if target is None else ratio <= target,
            digits=0 if target is not None else 1,
        )

    rows = (
        row(
            "SDO upload round trip (expedited, echo peer)",
            sdo,
            sdo_peer,
            TARGET_SDO,
            paired(ours_s, peer_s),
        ),
        row(
            "  calling thread's CPU per upload",
            median(ours_s, "cpu"),
            median(peer_s, "cpu"),
        ),
        row(
            "CiA 402 pp set-point handshake (3 RPDO + 2 TPDO)",
            hs,
            hs_peer,
            TARGET_402,
            paired(ours_h, peer_h),
        ),
        row(
            "  calling thread's CPU per set-point",
            median(ours_h, "cpu"),
            median(peer_h, "cpu"),
        ),
    )
    notes = (
        f"Median of {rounds} interleaved round(s) (ours, canopen-py, ours, ...): SDO rounds "
        f"of {sdo_count:,} uploads (ours: {us(ours_s)} µs; canopen-py: {us(peer_s)} µs), "
        f"set-point rounds of {setpoints:,} set-points (ours: {us(ours_h)} µs; canopen-py: "
        f"{us(peer_h)} µs), each after {WARMUP} warm-up operations. Every SDO answer was "
        "checked and counted by the peer; the axis stayed Active.",
        "Target rows: the ratio is the median of the rounds' own ratios (each round of ours "
        f"over the canopen-py round right after it): SDO {ratios(ours_s, peer_s)}; "
        f"set-point {ratios(ours_h, peer_h)}. The value and baseline columns are the "
        "medians of each side's rounds.",
        "CPU rows: CPU time of the calling thread per operation (`time.thread_time`). For "
        "ours that thread is the event loop, which on the `virtual` interface also reads "
        "the bus; canopen-py's Notifier thread (its reader) is not in its figure. Both "
        "clients share the machine's cores and the GIL with the peer (a thread of the same "
        "process): on real hardware the drive's work is done by the drive.",
    )
    return BenchResult(
        name=NAME,
        title="CANopen SDO and CiA 402 set-points: openel_can vs canopen-py",
        rows=rows,
        description=DESCRIPTION,
        notes=notes,
        params={
            "uploads": f"{sdo_count:,}",
            "set-points": f"{setpoints:,}",
            "interface": "virtual",
            "canopen": canopen.__version__,
            "python-can": can.__version__,
        },
    )


DESCRIPTION = """\
Peer library: **canopen-py** (`canopen`), the CANopen stack a Python user would take
instead, on the same python-can `virtual` interface, against the same peers.

**SDO upload round trip.** The peer is an SDO echo: a plain python-can thread on its
own bus answering every upload request of node 5 with an expedited 4-byte response.
Ours: `SdoClient.upload(0x6041, 0)` on a `CanBus`. canopen-py:
`RemoteNode.sdo.upload(0x6041, 0)` on a `canopen.Network`. Figure: time per upload,
from the request to the decoded answer, back to back.

**CiA 402 set-point handshake.** The peer is our simulated CiA 402 drive
(`SimCia402Drive`, node 5) on its own bus, in its own thread and event loop. Each
profile-position set-point is 3 RPDOs and 2 TPDOs: controlword without new set-point
-> wait for statusword set-point acknowledge low; new set-point -> wait for
acknowledge high; clear new set-point. Ours: `Actuator(Cia402Drive(bus, 5))` and
`set_value(x, POSITION)`, the call an application makes. canopen-py: the same
handshake written with its PDO API (`PdoMap` variables, `transmit()`, waiting on the
TPDO's `receive_condition` taken before the RPDO is sent, so no TPDO is missed), the
drive configured by canopen's SDO client exactly as our driver configures it (RPDO1
controlword + target position, TPDO1 statusword + position + torque and TPDO2
velocity + mode display, event-driven with a 10 ms event timer; heartbeat 1 s).
Figure: time per set-point.

Ratios are ours/canopen-py time: below 1, ours is faster. In the target rows the ratio is
the median of the rounds' own ratios (each round of ours over the canopen-py round run right
after it, listed in the notes), so a change of the machine's load between rounds cancels out;
15 rounds.

**Where the SDO upload's time goes (issue 27, target <= 1.0x).** On this 2-core VM,
shared with other work, every exchange is serial: the event loop, the peer's thread and
canopen-py's threads take turns on the GIL, so a round trip is the CPU of both sides plus
the wake-ups. Before this pass the upload took 1.21-1.24x canopen-py's time; timestamps
(3,000 uploads, median) put 42-45 µs between the answer's drain in our loop and the
upload returning. The per-upload work cut since, in the SDO client and the virtual-bus
reader: (1) one timer per `SdoClient` bounds every exchange, re-armed only when it would
fire late or fires early, instead of a timer handle pushed on and popped off the loop's
heap per exchange (whose order is Python comparisons); (2) an upload's initiate is
encoded once per object and kept; (3) a free transfer slot is taken without the two
coroutines of `async with`; (4) python-can's virtual bus wakes the loop through an
eventfd the loop watches (one 8-byte write by the sender, one read by the loop) instead
of `call_soon_threadsafe` (a handle allocated per wake-up, the loop's self-pipe written,
then read twice, the second read ending in `BlockingIOError`). Drain to return is now
~24 µs; our loop's CPU per upload went from 110-140 µs to 67-84 µs (`thread_time`, 2,000
uploads, 3 runs), canopen-py's calling thread's 53-109 µs in the same runs. The
remaining fixed cost is asyncio's: the loop's `epoll` wake-up and a second loop pass to
resume the task the answer's future woke, python-can's `send` (a deep copy per frame
and a `queue.Queue.put` that notifies the peer, paid by both clients). Spinning in the
loop instead of sleeping was tried in an earlier pass and did not help: the peer is
Python in the same process and needs the GIL that the spinning loop holds.

**Second pass (1.01x in the run of 07:40, 0.67-0.99x before).** (5) The upload's initiate
is kept as a built frame (`TxMessage`, never changed after) with the bytes its expedited
answer carries, and sent inline without a coroutine (`NodePort.try_send_frame`; the queued
path only when frames wait); (6) on python-can's `virtual` interface a `CanBus` sends
through `openel_can.virtual_rx.virtual_sender`, python-can's `VirtualBus.send` without the
generic `copy.deepcopy` (a memo dictionary and a keep-alive list per frame) and, for a
receiver's usual unbounded queue, without `Queue.put`'s condition wrapper (the receivers
get the same frames, stamped alike: `tests/can/test_bus_readers.py`). Our loop's CPU per
upload, old and new code alternated 10 times (2,000 uploads each, one process per run, load
average 5 to 6 from other work): median 87 -> 70 µs (best 70 -> 48 µs), wall time per
upload median 319 -> 240 µs. What stays is asyncio's and the kernel's: the `epoll` wake-up,
the eventfd read, a second loop pass to resume the task, and the futex that wakes the peer's
thread (paid by both clients). Under load ours gains (canopen-py's answer crosses three
threads, ours two); on an idle machine the two are close, so the margin there is smaller.
A full run of this benchmark at 09:02 (commit cde16c2, load average 4.8): SDO
0.82x (median of 15 paired rounds; the rounds' ratios spread 0.31-1.29), set-point 1.04x
(0.47-1.60); a second at 09:20 (commit a7d27d2, load average 2.0): SDO 0.69x (123 µs vs
179 µs; every round 0.53-0.83), set-point 0.83x.

**CiA 402 set-point handshake (target <= 1.1x).** Most of a set-point is the simulated
drive's answer time, the same peer for both clients. Timestamps in our bus (300
set-points, 3 runs, medians): from our RPDO to the drive's TPDO 364-532 µs (twice per
set-point: the drive's thread and loop waking, under the GIL with ours), from that TPDO
to our next RPDO 22-31 µs, from a set-point's last RPDO to the next one's first 36-59
µs: our side is about a tenth of the 1.1-1.3 ms, so the ratio follows the drive's
latency under the machine's load (rounds of one run spread 1.0-3.6 ms at load 4). This
pass: the node's statusword waits share one timer (as the SDO client's exchanges do),
and the drive's own `CanBus` is woken by the eventfd too (for both clients)."""
