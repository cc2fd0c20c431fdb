"""What feeding the device watchdogs costs a 1 kHz AxisGroup loop: the same loop with every
device's watchdog armed and with none armed.

The host (this process) runs one event loop with:

* an ``AxisGroup`` of 2 ``ODriveAxis`` (PASSTHROUGH position input, as for streaming) on a
  CAN bus, ticked by an ``EventTimer(1 ms)`` on the real clock and streaming one long move
  (every tick sends one Set_Input_Pos frame per axis);
* 2 ``Cia402Drive`` on a second CAN bus, enabled and holding (their TPDOs come every 10 ms);
* 2 ``DynamixelServo`` on a ``DynamixelPort`` (pty, 1 Mbaud), holding, polled every 10 ms.

The simulated peers run in child processes, so their CPU time is not the host's: the CAN
drives (:class:`~openel_can.sim.odrive.SimODrive`, :class:`~openel_can.sim.cia402.SimCia402Drive`)
in :mod:`benchmarks.can_peers`, reached over a socket pair per bus (a python-can bus that sends
and receives Linux ``can_frame`` datagrams: the host's ``CanBus`` runs as on ``socketcan``,
with a reader thread and inline sends), the Dynamixel bus in :mod:`benchmarks.serial_bus`.

Rounds: every device's watchdog disarmed, then armed with 100 ms or 40 ms, or left
disarmed, between the measured windows (same devices, same process, same move); each round
measures the three states in one of the six orders. The figure is the CPU time of the host
process (``time.process_time``: the event loop and the CAN buses' reader threads) per 1 ms
period; the overhead is the median over the rounds of the paired difference armed - not
armed, checked against 20 µs (2 % of the tick) for 100 ms directly and as estimated from the
40 ms rounds (x 0.4: the feeding events per second). A second phase repeats the comparison
with the group holding (no setpoints), where every ODrive feed is a heartbeat poll.
"""

from __future__ import annotations

import gc
import itertools
import math
import os
import socket
import statistics
import time
from collections.abc import Sequence
from contextlib import AsyncExitStack
from dataclasses import dataclass, field
from pathlib import Path

import anyio

from openel_async import (
    Actuator,
    ActuatorLimits,
    ComponentState,
    EventTimer,
    MonotonicClock,
    Request,
)
from openel_async.errors import HALError
from openel_async.motion import AxisGroup, AxisLimits, AxisStateError
from openel_async.safety import Watchdog
from openel_can import CanBus, Cia402Drive, ODriveAxis
from openel_can import cansimple as cs
from openel_serial import DynamixelPort, DynamixelServo

from .can_peers import CanPeersProcess, host_bus
from .harness import COMMAND, BenchResult, Row, ratio_of
from .serial_bus import BusProcess

NAME = "watchdog"
PERIOD_MS = 1
ODRIVE_NODES = (1, 2)
CIA402_NODES = (5, 6)
SERVOS = 2
WATCHDOG_S = 0.1
"""The timeout of the target: armed on every device (a multiple of 20 ms, as the Dynamixels
need; CiA 402 wants whole milliseconds)."""
TIGHT_WATCHDOG_S = 0.04
"""A tighter timeout, 2.5 times the feeding events of WATCHDOG_S (informational)."""
STATES: tuple[float | None, ...] = (None, WATCHDOG_S, TIGHT_WATCHDOG_S)
ORDERS = tuple(itertools.permutations(STATES))
"""Round k measures the states in ORDERS[k % 6]: each state comes first, second and last
equally often, so a drift of the machine's load hits every state alike."""
WINDOW_S = 0.6
QUICK_WINDOW_S = 0.3
ROUNDS = 36
QUICK_ROUNDS = 2
IDLE_ROUNDS = 12
QUICK_IDLE_ROUNDS = 1
SETTLE_S = 0.1
"""Streaming before each measured window (the move under way, the arming's frames gone)."""
ATTEMPTS = 5
"""Tries of a window whose devices faulted around it (a loaded machine)."""
PEERS_UP_S = 10.0
LIMITS = AxisLimits(max_velocity=1.0, max_acceleration=5.0, max_jerk=50.0)
FAR = 50.0
"""rad: a target far enough that each round's move is still streaming when the window ends."""
S = ComponentState
TARGET_OVERHEAD_US = 0.02 * PERIOD_MS * 1000
"""Under 2 % of the 1 ms tick: 20 µs of host CPU per tick."""


State = float | None
"""The watchdog timeout armed on every device, or None: none armed."""


@dataclass(frozen=True, slots=True)
class Window:
    """One measured window."""

    state: State
    seconds: float
    host_cpu_s: float
    """CPU of the host process (the event loop and the CAN buses' reader threads)."""
    loop_cpu_s: float
    """CPU of the event-loop thread alone."""
    peer_cpu_s: float
    """CPU of the CAN peers' process (/proc, 10 ms resolution; NaN off Linux)."""
    group_ticks: int
    group_skipped: int
    tx_frames: int
    """Frames the host sent on both CAN buses."""

    @property
    def periods(self) -> float:
        return self.seconds * 1000 / PERIOD_MS

    @property
    def host_us(self) -> float:
        return self.host_cpu_s * 1e6 / self.periods

    @property
    def loop_us(self) -> float:
        return self.loop_cpu_s * 1e6 / self.periods

    @property
    def peer_us(self) -> float:
        return self.peer_cpu_s * 1e6 / self.periods

    @property
    def frames_per_s(self) -> float:
        return self.tx_frames / self.seconds


@dataclass
class Phase:
    """The windows of one phase (streaming, or the group holding), by state; round k's
    windows are at index k of every list."""

    windows: dict[State, list[Window]] = field(
        default_factory=lambda: {state: [] for state in STATES}
    )

    def median(self, state: State, attr: str) -> float:
        return statistics.median(float(getattr(w, attr)) for w in self.windows[state])

    def differences(self, state: State, attr: str) -> list[float]:
        """Per round: armed with ``state`` - not armed."""
        return [
            float(getattr(a, attr)) - float(getattr(d, attr))
            for a, d in zip(self.windows[state], self.windows[None], strict=True)
        ]

    def extra(self, state: State, attr: str) -> float:
        return statistics.median(self.differences(state, attr))


def _cpu_of(pid: int) -> float:
    """CPU seconds (user + system) of process ``pid`` so far (Linux /proc; NaN elsewhere)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return math.nan
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


# -- the host ----------------------------------------------------------------------------------


class WindowLost(Exception):
    """A device faulted around a window (on a loaded machine, a watchdog may trip when the
    host is descheduled for longer than its timeout): the window is measured again."""


async def _window(
    state: State,
    seconds: float,
    group: AxisGroup,
    actuators: Sequence[Actuator],
    buses: Sequence[CanBus],
    peer_pid: int,
    sign: float | None,
) -> Window:
    """One measured window: streaming a move toward ``sign`` x FAR, or (None) the group
    holding while the timer keeps ticking."""
    try:
        motion = None if sign is None else await group.move_to([sign * FAR] * len(group.axes))
    except AxisStateError as exc:  # an axis faulted since the last window
        raise WindowLost(_faults(actuators) or str(exc)) from exc
    await anyio.sleep(SETTLE_S)
    group.reset_stats()
    tx0 = sum(b.stats.tx_frames for b in buses)
    peer0 = _cpu_of(peer_pid)
    wall0, cpu0, loop0 = time.perf_counter(), time.process_time(), time.thread_time()
    await anyio.sleep(seconds)
    wall = time.perf_counter() - wall0
    cpu, loop = time.process_time() - cpu0, time.thread_time() - loop0
    peer = _cpu_of(peer_pid) - peer0
    tx = sum(b.stats.tx_frames for b in buses) - tx0
    stats = group.stats
    faults = _faults(actuators)
    if motion is not None:
        if motion.done():
            faults = faults or f"{motion}: {motion.error()!r}"
        else:
            group.hold()
    if faults:
        raise WindowLost(faults)
    return Window(
        state=state,
        seconds=wall,
        host_cpu_s=cpu,
        loop_cpu_s=loop,
        peer_cpu_s=peer,
        group_ticks=stats.ticks,
        group_skipped=stats.skipped_ticks,
        tx_frames=tx,
    )


async def _measured(
    state: State,
    seconds: float,
    group: AxisGroup,
    actuators: Sequence[Actuator],
    watchdogs: Sequence[Watchdog],
    buses: Sequence[CanBus],
    peer_pid: int,
    sign: float | None,
    lost: list[str],
) -> Window:
    """A window, measured again (at most ATTEMPTS times) after every faulted component was
    recovered (``re_init``) when a device faulted around it; ``lost`` collects the faults."""
    for _ in range(ATTEMPTS):
        try:
            return await _window(state, seconds, group, actuators, buses, peer_pid, sign)
        except WindowLost as exc:
            lost.append(f"{_state_name(state)}: {exc}")
        try:
            for actuator in actuators:
                if actuator.state is S.ERROR:
                    await actuator.re_init()
            await _arm(watchdogs, state)
        except (HALError, TimeoutError) as exc:  # loaded machine: the next attempt retries
            lost.append(f"{_state_name(state)}: recovery failed: {exc}")
    raise RuntimeError(f"{ATTEMPTS} windows in a row lost: {lost[-ATTEMPTS:]}")


def _faults(actuators: Sequence[Actuator]) -> str:
    return "; ".join(str(a.last_fault) for a in actuators if a.state is S.ERROR)


def _state_name(state: State) -> str:
    return "not armed" if state is None else f"{state * 1000:g} ms"


async def _arm(devices: Sequence[Watchdog], state: State) -> None:
    """Disarm every watchdog, then arm each with the timeout ``state`` (None: leave them)."""
    for device in devices:
        await device.disarm_watchdog()
    if state is not None:
        for device in devices:
            await device.arm_watchdog(state)


async def _heard_from(bus: CanBus, nodes: Sequence[int]) -> None:
    """Wait (at most PEERS_UP_S) for a heartbeat of every simulated ODrive: a loaded machine
    may keep the peers' process from sending for a while after it said it was ready."""
    ids = {cs.arbitration_id(node, cs.CmdId.HEARTBEAT) for node in nodes}
    port = bus.attach(sorted(ids), name="bench-peers-up")
    try:
        with anyio.fail_after(PEERS_UP_S):
            async for batch in port:
                ids.difference_update(frame.arbitration_id for frame in batch)
                if not ids:
                    return
    finally:
        port.close()


async def measure(
    odrive_sock: socket.socket,
    cia_sock: socket.socket,
    serial_path: str,
    peer_pid: int,
    rounds: int,
    idle_rounds: int,
    seconds: float,
) -> tuple[Phase, Phase, list[str]]:
    """The streaming phase, the holding phase, and the faults that cost a window."""
    clock = MonotonicClock()
    streaming, holding_phase = Phase(), Phase()
    lost: list[str] = []
    async with AsyncExitStack() as stack:
        bus_a = await stack.enter_async_context(host_bus(stack, odrive_sock, "odrive"))
        bus_b = await stack.enter_async_context(host_bus(stack, cia_sock, "cia402"))
        await _heard_from(bus_a, ODRIVE_NODES)
        port = await stack.enter_async_context(
            DynamixelPort(serial_path, baudrate=1_000_000, return_delay=0.0, poll_period=0.01)
        )
        limits = ActuatorLimits(position=(-2 * FAR, 2 * FAR))
        odrives = [
            ODriveAxis(
                bus_a,
                n,
                position_input_mode=cs.InputMode.PASSTHROUGH,
                limits=limits,
                request_timeout=0.5,
                heartbeat_timeout=1.0,  # a loaded machine delays the peers' heartbeats
            )
            for n in ODRIVE_NODES
        ]
        drives = [Cia402Drive(bus_b, n, sdo_timeout=0.5) for n in CIA402_NODES]
        servos = [DynamixelServo(port, i) for i in range(1, SERVOS + 1)]
        axes = [
            await stack.enter_async_context(Actuator(d, clock=clock, device_name=f"odrive{i}"))
            for i, d in enumerate(odrives)
        ]
        holding = [
            await stack.enter_async_context(Actuator(d, clock=clock)) for d in (*drives, *servos)
        ]
        for actuator in holding:  # enabled, holding where it is
            await actuator.set_value(await actuator.get_value(Request.POSITION_ACTUAL))
        timer = await stack.enter_async_context(EventTimer(PERIOD_MS, clock=clock, name="bench"))
        group = await stack.enter_async_context(AxisGroup(axes, timer=timer, limits=LIMITS))
        watchdogs: list[Watchdog] = [*odrives, *drives, *servos]
        actuators = [*axes, *holding]
        # A full collection stalls this loop for tens of milliseconds, long enough to trip a
        # 0.1 s watchdog with the rest of the stall: collect once and freeze what the set-up
        # made, so the collections during the rounds only look at new objects.
        gc.collect()
        gc.freeze()
        buses = (bus_a, bus_b)
        sign: float | None = 1.0
        for phase, count in ((streaming, rounds), (holding_phase, idle_rounds)):
            for k in range(count):
                for state in ORDERS[k % len(ORDERS)]:
                    await _arm(watchdogs, state)
                    window = await _measured(
                        state, seconds, group, actuators, watchdogs, buses, peer_pid, sign, lost
                    )
                    phase.windows[state].append(window)
                    if sign is not None:
                        sign = -sign
            sign = None  # the holding phase: no move
        await _arm(watchdogs, None)
    return streaming, holding_phase, lost


def run(quick: bool) -> BenchResult:
    rounds = QUICK_ROUNDS if quick else ROUNDS
    idle_rounds = QUICK_IDLE_ROUNDS if quick else IDLE_ROUNDS
    seconds = QUICK_WINDOW_S if quick else WINDOW_S
    peers = CanPeersProcess(ODRIVE_NODES, CIA402_NODES)
    with peers as (odrive_sock, cia_sock), BusProcess(SERVOS) as serial_path:
        try:
            assert peers.process is not None
            streaming, holding, lost = anyio.run(
                measure,
                odrive_sock,
                cia_sock,
                serial_path,
                peers.process.pid,
                rounds,
                idle_rounds,
                seconds,
                backend="asyncio",
            )
        finally:
            odrive_sock.close()
            cia_sock.close()
    return _result(streaming, holding, lost, rounds, idle_rounds, seconds)


def _quartiles(values: Sequence[float]) -> tuple[float, float]:
    if len(values) < 2:
        return values[0], values[0]
    q = statistics.quantiles(values, n=4)
    return q[0], q[2]


def _listing(values: Sequence[float]) -> str:
    return ", ".join(f"{v:.1f}" for v in values)


def _result(
    streaming: Phase,
    holding: Phase,
    lost: Sequence[str],
    rounds: int,
    idle_rounds: int,
    seconds: float,
) -> BenchResult:
    base_us = streaming.median(None, "host_us")
    extra_us = streaming.extra(WATCHDOG_S, "host_us")
    tight_us = streaming.extra(TIGHT_WATCHDOG_S, "host_us")
    # Every feeding event comes once per timeout / 4 (ODrive feeder, CiA 402 heartbeat; the
    # Dynamixel poll runs armed or not): the 40 ms rounds have 2.5x the events of 100 ms, so
    # their overhead, scaled by 40/100, estimates the 100 ms one with 2.5x less noise.
    scale = TIGHT_WATCHDOG_S / WATCHDOG_S
    estimate_us = tight_us * scale
    passed = extra_us < TARGET_OVERHEAD_US
    estimate_passed = estimate_us < TARGET_OVERHEAD_US
    ms = f"{WATCHDOG_S * 1000:g} ms"
    tight_ms = f"{TIGHT_WATCHDOG_S * 1000:g} ms"
    rows = [
        Row(
            f"host CPU per 1 ms tick, watchdogs {ms} (median)",
            streaming.median(WATCHDOG_S, "host_us"),
            "µs",
            baseline=base_us,
            baseline_label="not armed",
            ratio=ratio_of(streaming.median(WATCHDOG_S, "host_us"), base_us),
            ratio_label="armed/not armed",
        ),
        Row(
            f"extra host CPU per tick, watchdogs {ms} (median of paired rounds)",
            extra_us,
            "µs",
            target=f"< {TARGET_OVERHEAD_US:g} µs (2 % of the tick)",
            passed=passed,
            digits=2,
        ),
        Row(
            f"extra host CPU, watchdogs {ms}: share of the 1 ms tick",
            extra_us / (PERIOD_MS * 1000) * 100,
            "%",
            target="< 2 %",
            passed=passed,
            digits=2,
        ),
        Row(
            f"extra host CPU, watchdogs {ms}: relative to the loop not armed",
            extra_us / base_us * 100 if base_us else 0.0,
            "%",
            digits=2,
        ),
        Row(
            f"extra host CPU per tick, watchdogs {tight_ms} (median of paired rounds)",
            tight_us,
            "µs",
            digits=2,
        ),
        Row(
            f"extra host CPU per tick, watchdogs {ms}, estimated from {tight_ms} "
            f"(x {scale:g}: the feeding events per second)",
            estimate_us,
            "µs",
            target=f"< {TARGET_OVERHEAD_US:g} µs (2 % of the tick)",
            passed=estimate_passed,
            digits=2,
        ),
        Row(
            f"extra event-loop thread CPU per tick, watchdogs {ms} (median of paired rounds)",
            streaming.extra(WATCHDOG_S, "loop_us"),
            "µs",
            baseline=streaming.median(None, "loop_us"),
            baseline_label="loop thread CPU per tick, not armed",
            digits=2,
        ),
        Row(
            f"extra frames sent by the host, watchdogs {ms} / {tight_ms}",
            streaming.extra(WATCHDOG_S, "frames_per_s"),
            "/s",
            baseline=streaming.extra(TIGHT_WATCHDOG_S, "frames_per_s"),
            baseline_label=tight_ms,
            digits=0,
        ),
        Row(
            "group holding: extra host CPU per tick, watchdogs "
            f"{ms} / {tight_ms} (median of paired rounds)",
            holding.extra(WATCHDOG_S, "host_us"),
            "µs",
            baseline=holding.extra(TIGHT_WATCHDOG_S, "host_us"),
            baseline_label=tight_ms,
            digits=2,
        ),
        Row(
            "group holding: host CPU per tick, not armed (median)",
            holding.median(None, "host_us"),
            "µs",
        ),
        Row(
            f"group holding: extra frames sent by the host, watchdogs {ms} / {tight_ms}",
            holding.extra(WATCHDOG_S, "frames_per_s"),
            "/s",
            baseline=holding.extra(TIGHT_WATCHDOG_S, "frames_per_s"),
            baseline_label=tight_ms,
            digits=0,
        ),
        Row(
            "CAN peers' process CPU per tick, streaming, not armed (not in the host figures)",
            streaming.median(None, "peer_us"),
            "µs",
        ),
        Row(
            f"CAN peers' process: extra CPU per tick, streaming, watchdogs {ms} / {tight_ms} "
            "(median of paired rounds; the simulated drives' own watchdogs, on the same cores)",
            streaming.extra(WATCHDOG_S, "peer_us"),
            "µs",
            baseline=streaming.extra(TIGHT_WATCHDOG_S, "peer_us"),
            baseline_label=tight_ms,
            digits=1,
        ),
    ]
    diffs = streaming.differences(WATCHDOG_S, "host_us")
    tight = streaming.differences(TIGHT_WATCHDOG_S, "host_us")
    q1, q3 = _quartiles(diffs)
    tq1, tq3 = _quartiles(tight)
    windows = [w for ws in streaming.windows.values() for w in ws]
    ticks = sum(w.group_ticks for w in windows)
    periods = sum(w.periods for w in windows)
    skipped = sum(w.group_skipped for w in windows)
    per_round = "; ".join(
        f"{_state_name(state)} {_listing([w.host_us for w in streaming.windows[state]])}"
        for state in STATES
    )
    notes = [
        f"Streaming, paired differences armed {ms} - not armed, host CPU per tick (µs): "
        f"{_listing(diffs)}; quartiles {q1:.1f} / {q3:.1f}.",
        f"Streaming, paired differences armed {tight_ms} - not armed (µs): {_listing(tight)}; "
        f"quartiles {tq1:.1f} / {tq3:.1f}.",
        f"Streaming, host CPU per tick per round (µs): {per_round}.",
        "Group holding, paired differences (µs per tick): "
        f"{ms} {_listing(holding.differences(WATCHDOG_S, 'host_us'))}; "
        f"{tight_ms} {_listing(holding.differences(TIGHT_WATCHDOG_S, 'host_us'))}.",
        f"Streaming: {ticks:,} group ticks in {periods:,.0f} measured 1 ms periods "
        f"({ticks / periods:.1%}); the group skipped {skipped} tick(s) (a tick still running "
        "when the next came).",
    ]
    notes.append(
        f"Windows measured again after a device faulted around them: {len(lost)}"
        + (f" ({'; '.join(lost)})." if lost else ".")
    )
    if not (passed and estimate_passed):
        notes.append(f"Target missed: see where the time goes with `{COMMAND} {NAME} --profile`.")
    return BenchResult(
        name=NAME,
        title="feeding the device watchdogs in a 1 kHz AxisGroup loop (armed vs not armed)",
        rows=tuple(rows),
        description=DESCRIPTION,
        notes=tuple(notes),
        params={
            "group": f"{len(ODRIVE_NODES)} ODriveAxis, {PERIOD_MS} ms EventTimer, real clock",
            "also on the loop": f"{len(CIA402_NODES)} Cia402Drive, "
            f"{SERVOS} DynamixelServo (pty, 1 Mbaud, polled every 10 ms)",
            "watchdog timeouts": f"not armed, {ms}, {tight_ms} (every device)",
            "window": f"{seconds} s",
            "rounds": f"{rounds} streaming + {idle_rounds} holding, one window per state each",
        },
    )


DESCRIPTION = """\
**The loop.** One host process, one event loop: an `AxisGroup` of 2 `ODriveAxis`
(position input PASSTHROUGH, as for streaming) on a CAN bus, ticked by an `EventTimer(1 ms)`
on the real clock and streaming one long move (every tick one Set_Input_Pos frame per axis);
2 `Cia402Drive` on a second CAN bus, enabled and holding (TPDOs every 10 ms); 2
`DynamixelServo` on a `DynamixelPort` (pty, 1 Mbaud), holding, polled every 10 ms.

**The peers run in child processes**, so their CPU is not counted: the simulated CAN drives
(`SimODrive`, `SimCia402Drive`) in `benchmarks.can_peers`, the Dynamixel bus in
`benchmarks.serial_bus`. A python-can `virtual` bus only links threads of one process (the
peers would then share the host's GIL), so each CAN bus here is a socket pair carrying Linux
`can_frame` datagrams (`benchmarks.can_peers.SocketPairBus`): a send is one system call, a
receive one `select` + `recv` in the `CanBus` reader thread, as on `socketcan`.

**Figure.** CPU time of the host process (`time.process_time`: the event loop and the CAN
buses' reader threads) per 1 ms period, over 0.6 s windows. Between windows every device's
watchdog is disarmed, then armed with 100 ms, armed with 40 ms, or left disarmed; same
devices, same process, same move. Each round measures the three states in one of the six
orders (each order equally often), and the overhead is the median over the rounds of the
paired difference armed - not armed. Target (issue 22: "feeding the watchdogs costs under
2 % of a 1 kHz group tick"): the extra CPU per tick under 2 % of the 1 ms period, 20 µs, with
100 ms watchdogs; the overhead relative to the loop's own CPU is reported beside it. The
target is checked twice: on the 100 ms median, and on the 40 ms median scaled by 0.4. Every
feeding event comes once per timeout / 4, so the 40 ms rounds carry 2.5 times as many events
as the 100 ms ones and their scaled difference estimates the 100 ms overhead with 2.5 times
less of the window-to-window noise.

**What feeding is, per device.** ODrive: one task of the bus (`WatchdogFeeder`) for every
armed axis of the bus wakes every timeout / 4 (25 ms); every CANSimple frame to an axis feeds
the firmware's watchdog, so while the group streams the task finds a frame sent within the
period to each axis and goes back to sleep (no frame); to an axis nothing went out to it sends
a heartbeat request (remote frame), which the ODrive answers. CiA 402: the bus sends the host
heartbeat (COB-ID 0x77F) every timeout / 4 from a task of its own, inline (the send queue
only when frames are queued). Dynamixel: the port's poller, whose SYNC READ every 10 ms runs armed or not, is
the feed; armed, each poll cycle also checks the gap since the previous one (a late one is
followed by a SYNC READ of Bus Watchdog (98)). Arming itself (SDO and RxSdo writes, the Bus
Watchdog write) happens between the windows.

**Group holding.** The same comparison with the group holding (no setpoints, the timer still
ticking): every ODrive feed is then a heartbeat poll and its answer, the watchdogs' worst case
on this loop.

**Reading the figures.** The host's tick costs hundreds of µs here, nearly all of it system
calls and wake-ups (a send per frame, the reader thread, the timer), which are expensive on
this 2-vCPU virtual machine; a bare `asyncio.sleep(0.001)` loop uses about 70 µs of CPU per
iteration on it. The spread of the paired differences (their quartiles are in the notes) is
tens of µs per window, so the 100 ms median alone resolves the overhead to about ten µs;
the estimate from the 40 ms rounds is the sharper figure. What an extra event costs is mostly
an extra wake-up of the loop (a feeder's deadline falls between two ticks), dear on this
virtual machine (bare metal was not measured). The holding rows, where the watchdogs send frames, show what each feeding
event costs on this machine.

**Issue 27 pass (26.7 µs at 100 ms in the run of 07:56, 4.3 µs in the one before).** Fewer
task wake-ups per feeding event: the ODrive axes of a bus share one feeder task
(`WatchdogFeeder`; was a task per axis), and the CiA 402 host heartbeat is sent inline by
its producer (was queued for the bus's sender task, a second wake-up per beat). At 100 ms,
streaming, that is 8 task wake-ups and 4 heartbeat frames per 100 ms (was 16 and 4). In the
holding rows, where feeding sends frames, the extra host CPU per tick went from 42.5 /
96.5 µs (100 / 40 ms; run of 07:56, load average 0.8) to 19.4 / 63.8 µs (a run at 09:10,
commit 68fae26, load average 3.7 rising to 6.4 from other work on the machine). The
measurement: 36 streaming rounds (was 24); a recovery that fails (a loaded machine starves
the simulated Dynamixel bus) costs one of 5 tries instead of the run. In that loaded run
(80.6 % of the periods ticked, 8 windows measured again) the streaming figures were 20.6 µs
at 100 ms and 14.5 µs at 40 ms (5.8 µs estimated for 100 ms), with paired differences
spread from -56 to +181 µs; in a second one at 09:16 (commit 65e9f3f, load average 4.6 to
5.3, 70.7 % ticked, 7 windows measured again) -6.3 µs at 100 ms, -3.9 µs at 40 ms (-1.5 µs
estimated), paired differences from -248 to +270 µs, holding 25.2 / 61.8 µs, and the CAN
peers' process 24.5 / 33.1 µs more CPU per tick when armed (the new row: the simulated
drives' own watchdogs, in a process that shares the two cores with the host). At such
loads a window's CPU moves by far more than what feeding costs, so the 100 ms median alone
does not resolve the 20 µs target; the 40 ms estimate is the figure to read, and a run
for the record wants an idle machine. A third run at 09:21 (commit a7d27d2, load average
2.0 to 2.3, 97.8 % ticked, no window measured again): 13.5 µs at 100 ms, 14.5 µs at 40 ms
(5.8 µs estimated), holding 39.3 / 65.4 µs, the CAN peers 49.8 / 75.7 µs more per tick
when armed (their CPU is read from /proc in 10 ms steps, 16.7 µs per tick of a 0.6 s
window). That the simulated drives work harder when armed, on the same two cores, is a
likely part of the host's "armed" figure that does not scale with the feeding events (100
ms and 40 ms come out alike in every run); the sims' armed path was not looked into.
"""
