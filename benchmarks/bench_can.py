"""CAN frames per second vs raw python-can, and a two-axis cycle, on python-can's virtual bus.

1. Frames per second through the driver stack: encode a CANSimple Set_Input_Pos
   (``cansimple.encode``), send it on a :class:`~openel_can.CanBus` port, a second CanBus
   on the same virtual channel receives it (read in its event loop, dispatched by id to
   a port) and a consumer task decodes it (``cansimple.decode``). Peer, in the same run:
   raw python-can on a virtual channel, one synchronous loop of ``struct.pack`` +
   ``can.Message`` + ``send`` on one bus, ``recv`` + ``struct.unpack`` on another (no
   framework, no threads, no event loop). Target: ours >= 1.0x raw.
2. Two-axis cycles per second (informational): an ODrive (CANSimple) and a CiA 402
   drive (CANopen), simulated peers on the same virtual channel, each cycle ``set_value``
   (position) on both axes then ``get_value(POSITION_ACTUAL)`` on both. Floor shown
   beside it: raw python-can request/answer round trips between two threads.

Rounds alternate ours and raw python-can; figures are medians. The notes break one
frame's cost down (measured in the same run): python-can's deep copy in the virtual
``send``, the typed codec, struct.
"""

from __future__ import annotations

import copy
import math
import statistics
import struct
import threading
import time
import timeit
import uuid

import anyio
import can

from openel_async import Actuator, ComponentState, Request
from openel_can import CanBus, Cia402Drive, ODriveAxis, TxMessage
from openel_can import cansimple as cs
from openel_can.sim.cia402 import SimCia402Drive
from openel_can.sim.odrive import SimODrive

from .harness import BenchResult, Row, interleaved, ratio_of

NAME = "can"
FRAMES = 50_000
QUICK_FRAMES = 10_000
CYCLES = 1_000
QUICK_CYCLES = 200
ROUND_TRIPS = 2_000
ROUNDS = 5
QUICK_ROUNDS = 1
TARGET_RATIO = 1.0
TARGET_CYCLES = 200.0
NODE = 3


def _channel(kind: str) -> str:
    return f"bench-{kind}-{uuid.uuid4().hex[:8]}"


# -- 1. throughput -------------------------------------------------------------------------


async def driver_throughput(frames: int) -> float:
    channel = _channel("tp")
    arb_id = cs.arbitration_id(NODE, cs.CmdId.SET_INPUT_POS)
    async with (
        CanBus(interface="virtual", channel=channel, name="bench-tx") as host,
        CanBus(interface="virtual", channel=channel, name="bench-rx", port_queue_size=1024) as peer,
    ):
        tx = host.attach([], name="tx")
        rx = peer.attach([arb_id], name="rx")
        decoded = 0
        done = anyio.Event()

        async def consume() -> None:
            nonlocal decoded
            decode = cs.decode
            async for batch in rx:
                for frame in batch:
                    msg = decode(frame.arbitration_id, frame.data, from_host=True)
                    assert isinstance(msg, cs.SetInputPos)
                decoded += len(batch)
                if decoded >= frames:
                    done.set()
                    return

        async with anyio.create_task_group() as tg:
            tg.start_soon(consume)
            encode = cs.encode
            started = time.perf_counter()
            for i in range(frames):
                frame_id, data = encode(cs.SetInputPos(NODE, i * 1e-3))
                await tx.send(frame_id, data)
            with anyio.fail_after(60):
                await done.wait()
            elapsed = time.perf_counter() - started
        lost = host.stats.tx_dropped + peer.stats.overflow_frames
        if lost or decoded != frames:
            raise AssertionError(f"frames lost: {lost}, decoded {decoded} of {frames}")
    return frames / elapsed


def raw_throughput(frames: int) -> float:
    channel = _channel("raw")
    tx = can.Bus(interface="virtual", channel=channel)
    rx = can.Bus(interface="virtual", channel=channel)
    try:
        arb_id = cs.arbitration_id(NODE, cs.CmdId.SET_INPUT_POS)
        pack, unpack = struct.pack, struct.unpack_from
        started = time.perf_counter()
        for i in range(frames):
            tx.send(
                can.Message(
                    arbitration_id=arb_id, data=pack("<fhh", i * 1e-3, 0, 0), is_extended_id=False
                )
            )
            msg = rx.recv(1.0)
            assert msg is not None
            unpack("<fhh", msg.data)
        return frames / (time.perf_counter() - started)
    finally:
        tx.shutdown()
        rx.shutdown()


# -- 2. two-axis cycle ----------------------------------------------------------------------


async def two_axis_cycles(cycles: int) -> float:
    channel = _channel("axes")
    async with anyio.create_task_group() as peers:
        await peers.start(SimODrive(1, traj_vel_limit=5.0, traj_accel_limit=50.0).serve, channel)
        await peers.start(SimCia402Drive(2).serve, channel)
        async with (
            CanBus(interface="virtual", channel=channel, name="bench-host") as bus,
            Actuator(ODriveAxis(bus, 1)) as axis1,
            Actuator(Cia402Drive(bus, 2, heartbeat_ms=100)) as axis2,
        ):
            position = Request.POSITION
            actual = Request.POSITION_ACTUAL
            for i in range(20):  # warm-up
                await axis1.set_value(0.001 * i, position)
                await axis2.set_value(0.001 * i, position)
            started = time.perf_counter()
            for i in range(cycles):
                target = 0.2 * math.sin(i * 0.01)
                await axis1.set_value(target, position)
                await axis2.set_value(-target, position)
                await axis1.get_value(actual)
                await axis2.get_value(actual)
            elapsed = time.perf_counter() - started
            for axis in (axis1, axis2):
                if axis.state is not ComponentState.ACTIVE:
                    raise AssertionError(f"{axis.device_name} left Active: {axis.last_fault}")
        peers.cancel_scope.cancel()
    return cycles / elapsed


def raw_round_trips(count: int) -> float:
    channel = _channel("ping")
    host = can.Bus(interface="virtual", channel=channel)
    drive = can.Bus(interface="virtual", channel=channel)
    stop = threading.Event()

    def answer() -> None:
        while not stop.is_set():
            msg = drive.recv(0.05)
            if msg is not None:
                drive.send(
                    can.Message(arbitration_id=0x185, data=bytes(msg.data), is_extended_id=False)
                )

    responder = threading.Thread(target=answer, name="raw-can-responder", daemon=True)
    responder.start()
    try:
        request = can.Message(arbitration_id=0x205, data=bytes(6), is_extended_id=False)
        started = time.perf_counter()
        for _ in range(count):
            host.send(request)
            if host.recv(1.0) is None:
                raise AssertionError("raw round trip: no answer within 1 s")
        return count / (time.perf_counter() - started)
    finally:
        stop.set()
        responder.join(1.0)
        host.shutdown()
        drive.shutdown()


# -- the benchmark --------------------------------------------------------------------------


def per_frame_costs() -> dict[str, float]:
    """Microseconds per call of the pieces of one frame (timeit, same run)."""
    arb_id = cs.arbitration_id(NODE, cs.CmdId.SET_INPUT_POS)
    msg = cs.SetInputPos(NODE, 1.5)
    frame_id, data = cs.encode(msg)
    plain = can.Message(arbitration_id=arb_id, data=data, is_extended_id=False)
    ours = TxMessage(arbitration_id=arb_id, data=data, is_extended_id=False)
    raw = bytearray(data)
    number = 20_000
    pieces = {
        "can.Message deep copy": lambda: copy.deepcopy(plain),
        "TxMessage deep copy": lambda: copy.deepcopy(ours),
        "cansimple encode": lambda: cs.encode(msg),
        "cansimple decode": lambda: cs.decode(frame_id, raw, from_host=True),
        "struct pack + unpack": lambda: struct.unpack_from("<fhh", struct.pack("<fhh", 1.5, 0, 0)),
    }
    return {
        name: min(timeit.repeat(fn, number=number, repeat=3)) / number * 1e6
        for name, fn in pieces.items()
    }


def run(quick: bool) -> BenchResult:
    frames = QUICK_FRAMES if quick else FRAMES
    cycles = QUICK_CYCLES if quick else CYCLES
    rounds = QUICK_ROUNDS if quick else ROUNDS
    round_trips = ROUND_TRIPS if not quick else ROUND_TRIPS // 4
    measured = interleaved(  # ours, raw, ours, raw ...
        rounds,
        {
            "ours_tp": lambda: anyio.run(driver_throughput, frames, backend="asyncio"),
            "raw_tp": lambda: raw_throughput(frames),
            "ours_cycles": lambda: anyio.run(two_axis_cycles, cycles, backend="asyncio"),
            "raw_rt": lambda: raw_round_trips(round_trips),
        },
    )
    ours_tp, raw_tp = measured["ours_tp"], measured["raw_tp"]
    ours_cycles, raw_rt = measured["ours_cycles"], measured["raw_rt"]
    costs = per_frame_costs()
    rate, base_rate = statistics.median(ours_tp), statistics.median(raw_tp)
    cycle_rate, rt_rate = statistics.median(ours_cycles), statistics.median(raw_rt)
    # The target's ratio: the median of the rounds' own ratios (each round of ours over the
    # raw round right after it, both under the same load), robust to a drift of the machine
    # over the run, which moves both sides' rates alike.
    pairs = [ratio_of(o, r) for o, r in zip(ours_tp, raw_tp, strict=True)]
    ratio = statistics.median(pairs)
    rows = (
        Row(
            "frames per second (encode+send+receive+decode)",
            rate,
            "/s",
            baseline=base_rate,
            baseline_label="raw python-can",
            ratio=ratio,
            ratio_label="ours/raw, median of rounds' ratios",
            target=f">= {TARGET_RATIO:.1f}x raw python-can",
            passed=ratio >= TARGET_RATIO,
            digits=0,
        ),
        Row(
            "time per frame",
            1e6 / rate,
            "µs",
            baseline=1e6 / base_rate,
            baseline_label="raw python-can",
            digits=1,
        ),
        Row(
            "two-axis cycles per second (2 set_value + 2 get_value)",
            cycle_rate,
            "/s",
            baseline=rt_rate,
            baseline_label="raw request/answer round trips",
            target=f">= {TARGET_CYCLES:,.0f}/s",
            passed=cycle_rate >= TARGET_CYCLES,
            digits=0,
        ),
    )

    def rates(values: list[float]) -> str:
        return ", ".join(f"{v:,.0f}" for v in values)

    notes = (
        f"Median of {rounds} interleaved round(s) (ours, raw, ours, ...) of {frames:,} frames "
        f"(ours: {rates(ours_tp)}; raw python-can: {rates(raw_tp)} frames/s; ours/raw per "
        f"round: {', '.join(f'{p:.2f}' for p in pairs)}, the target's ratio their median); "
        "every frame was decoded and none was dropped (checked).",
        "One frame's pieces, same run (µs per call): python-can's virtual `send` deep-copies "
        f"the frame for every receiving bus: `can.Message` {costs['can.Message deep copy']:.2f} "
        f"(the raw loop pays this), our `TxMessage` {costs['TxMessage deep copy']:.2f}; typed "
        f"codec `cansimple.encode` {costs['cansimple encode']:.2f} + `decode` "
        f"{costs['cansimple decode']:.2f} against `struct` pack + unpack "
        f"{costs['struct pack + unpack']:.2f}. Ours also takes queued frames in one lock per "
        "batch where the raw loop calls `recv` per frame. On an interface that does not copy "
        "frames (socketcan) the copy saving does not exist and the typed codec is the "
        "difference: without it ours would have to hand out raw `can.Message` objects.",
        f"Cycle rounds of {cycles:,} cycles (ours: {rates(ours_cycles)}/s; raw round trips: "
        f"{rates(raw_rt)}/s). A cycle holds two request/answer exchanges with the simulated "
        "CiA 402 drive (set-point acknowledge low, then new set-point -> acknowledge), each "
        "through both buses, both event loops' dispatch and the drive simulation; the ODrive "
        "set-point is one frame sent inline and both feedback reads hit the cache of the "
        "cyclic TPDO/encoder frames. The CiA 402 handshake is compared with canopen-py in "
        "the `can_canopen` section.",
        "The simulated peers share the machine's cores with the host: on real hardware the "
        "peers' work is done by the drives.",
    )
    return BenchResult(
        name=NAME,
        title="CAN frames per second vs raw python-can (virtual bus); two-axis cycle",
        rows=rows,
        description=DESCRIPTION,
        notes=notes,
        params={
            "frames": f"{frames:,}",
            "cycles": f"{cycles:,}",
            "interface": "virtual",
            "python-can": can.__version__,
        },
    )


DESCRIPTION = """\
Peer: **raw python-can** (`can`, the library under every CAN stack in Python), same
process, same run, same `virtual` interface.

**Frames per second.** Ours: a CANSimple Set_Input_Pos is encoded (`cansimple.encode`)
and sent on a `CanBus` port (inline: `send(msg, timeout=0)`); a second `CanBus` on the
same virtual channel is woken by the put and takes every queued frame in its event
loop, dispatches them by arbitration id to a port (a bounded memory object stream),
and a consumer task decodes each (`cansimple.decode`). Figure: frames decoded per
second from the first send to the last decode; no frame may be lost. Raw python-can:
one synchronous loop (`struct.pack`, `can.Message`, `send` on one bus; `recv`,
`struct.unpack` on another), no event loop and no threads. Ratio ours/raw (> 1: ours
faster): the median of the rounds' own ratios (each round of ours over the raw round
right after it), as the rates of both drift together over a run on this shared machine
(one run's rounds: ours 49-105k, raw 38-76k frames/s, rising together).

**Two-axis cycle** (informational). An ODrive (CANSimple, node 1) and a CiA 402 drive
(CANopen, node 2), simulated peers on the same virtual channel, under `Actuator`s on
one `CanBus`: each cycle calls `set_value(POSITION)` on both, then
`get_value(POSITION_ACTUAL)` on both. Shown beside it, not as a ratio: raw python-can
request/answer round trips between the main thread and a responder thread, the floor
of one exchange (a cycle holds two)."""
