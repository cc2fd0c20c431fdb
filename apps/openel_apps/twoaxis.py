"""twoaxis: the OpenEL synchronous-control demo (spec Figures 7.5-7.8) on two axes.

``openel-async run twoaxis [--bus sim|can|remote] [--duration S] [--period-ms MS]
[--virtual | --realtime] [--inject-fault] [--no-live]``, also ``openel-async demo --bus sim|can``
and ``openel-async demo --remote`` (``--bus remote``); real time by default, as the demo.

Two actuators are initialized with observers (Fig. 7.6), driven in step from an
EventTimer's notify_timer (Fig. 7.7), and two sensors are read with their times to
relate their measurements (Fig. 7.8). With ``--inject-fault`` a drive trips halfway:
the error observer fires, the application calls re_init and carries on. A sensor read
that fails (a drive that stops answering: a CAN SDO timeout) is shown in the progress line
and the summary and survived: the sensor is re-initialized with bounded retries and a
back-off on the demo's clock, and the demo goes on without it if it does not come back.

The devices come from a rig file (:func:`file_rig`: the first two actuators and the first
two sensors): ``rigs/twoaxis-sim.yaml`` (``openel_sim`` motors, ``--bus sim``),
``rigs/twoaxis-can.yaml`` (an ODrive and a CiA 402 drive on ``can0``; ``--bus can`` runs it
with ``--sim``: simulated drives on a python-can virtual bus), any rig given with
``openel-async run twoaxis --rig FILE [--sim]``, or :func:`openel_apps.remote_rig.remote_rig`
(the sim devices served by ``openel-async serve`` in another process, over Zenoh). The rig
leaves the axes as its ``safety.on_exit`` says, and the summary says how.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import AsyncIterator, Callable, Mapping
from contextlib import AbstractAsyncContextManager, AsyncExitStack, asynccontextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import anyio
import anyio.lowlevel

from openel_async import (
    Actuator,
    Clock,
    EventId,
    EventTimer,
    HALComponent,
    HALError,
    MonotonicClock,
    Request,
    Sensor,
    TimedValue,
    VirtualClock,
)
from openel_async.app import AppContext, AppInfo, DemoOptions, LiveLine
from openel_async.clock import NS_PER_S
from openel_async.device import ActuatorDevice, ErrorId
from openel_async.errors import BadParameterError
from openel_async.logs import get_logger

if TYPE_CHECKING:  # the rig package (yaml, msgspec) loads when a rig is: not for --help
    from openel_async.rig import ResolvedRig
    from openel_async.rig import Rig as OpenedRig

log = get_logger(__name__)

NAME = "twoaxis"
DURATION_S = 5.0
"""Default ``--duration``: seconds of synchronized motion."""
PERIOD_MS = 10.0
"""Default ``--period-ms`` of the EventTimer."""
MIN_PERIOD_MS = 0.1
MAX_PERIOD_MS = 1000.0
"""``--period-ms`` range: the EventTimer ticks at most at 10 kHz."""
MAX_VIRTUAL_TICKS = 1_000_000
"""Most timer ticks on the virtual clock (``--duration`` x 1000 / ``--period-ms``): about a
minute of CPU."""
READ_PERIOD_NS = 100_000_000
"""The sensors are read every 100 ms (Fig. 7.8)."""
SENSOR_RETRIES = 3
"""re_init attempts after a failed sensor read before the demo goes on without the sensor."""
SENSOR_BACKOFF_NS = (100_000_000, 200_000_000, 400_000_000)
"""Wait on the demo's clock before each re_init attempt."""


ERROR_NAMES: Mapping[int, str] = {
    ErrorId.DEVICE_ERROR: "device error",
    ErrorId.DISCONNECTED: "disconnected",
    ErrorId.TIMEOUT: "timeout",
    ErrorId.BUS_ERROR: "bus error",
    ErrorId.LIMIT_VIOLATION: "limit violation",
    ErrorId.PROTOCOL_ERROR: "protocol error",
}
"""What the error ids the bundled drivers share mean (others are device-specific)."""
POSITION_UNIT = "rad"
"""The unit of the axes' positions (both rigs' motors are rotary)."""


@dataclass(frozen=True, slots=True)
class ErrorReport:
    """One notify_error: the device, the error id and, for a fault, its reason."""

    device: str
    error_id: int
    reason: str | None = None

    def text(self) -> str:
        """``MOTOR_2 error 1 (device error: over-temperature)``."""
        meaning = ERROR_NAMES.get(self.error_id, "device-specific")
        if self.reason:
            meaning += f": {self.reason}"
        return f"{self.device} error {self.error_id} ({meaning})"


def reading_text(value: float, unit: str) -> str:
    """A sensor value with its unit: ``298.137 K``, ``+0.123 rad``."""
    number = f"{value:.3f}" if unit == "K" else f"{value:+.3f}"
    return f"{number} {unit}".rstrip()


@dataclass
class DemoSummary:
    duration_s: float
    rig: str = ""
    ticks: int = 0
    missed_ticks: int = 0
    lateness_p50_us: float = 0.0
    lateness_p99_us: float = 0.0
    lateness_max_us: float = 0.0
    setpoints: int = 0
    completed_events: int = 0
    device_events: int = 0
    errors: list[ErrorReport] = field(default_factory=list)
    """Every notify_error, in order."""
    recoveries: int = 0
    sensor_reads: int = 0
    sensor_faults: list[tuple[str, str]] = field(default_factory=list)
    """(sensor, error) of every failed read."""
    sensor_recoveries: int = 0
    sensors_lost: list[str] = field(default_factory=list)
    """Sensors that did not come back after :data:`SENSOR_RETRIES` re_init attempts."""
    max_sensor_skew_us: float = 0.0
    max_tracking_error_rad: float = 0.0
    axis_names: tuple[str, str] = ("axis 1", "axis 2")
    final_positions: tuple[float, float] = (0.0, 0.0)
    last_readings: dict[str, str] = field(default_factory=dict)
    """The last value read from each sensor, with its unit."""

    def error_line(self) -> str:
        """``errors 1: MOTOR_2 error 1 (device error: ...)``; repeats are counted once each,
        shown once with their number."""
        if not self.errors:
            return "errors             0"
        counts: dict[str, int] = {}
        for report in self.errors:
            text = report.text()
            counts[text] = counts.get(text, 0) + 1
        shown = "; ".join(text if n == 1 else f"{text} x{n}" for text, n in counts.items())
        return f"errors             {len(self.errors)}: {shown}"

    def events_line(self) -> str:
        return (
            f"events             {self.completed_events} COMPLETED, {self.device_events} "
            "device-specific"
        )

    def sensor_fault_line(self) -> str:
        if not self.sensor_faults:
            return "sensor faults      0"
        names = sorted({name for name, _ in self.sensor_faults})
        line = (
            f"sensor faults      {len(self.sensor_faults)} ({', '.join(names)}; last: "
            f"{self.sensor_faults[-1][1]}), recovered {self.sensor_recoveries} (re_init)"
        )
        if self.sensors_lost:
            line += f", lost {', '.join(self.sensors_lost)}"
        return line

    def readings_line(self) -> str:
        shown = ", ".join(f"{name} {text}" for name, text in self.last_readings.items())
        return f"last readings      {shown or 'none'}"

    def lines(self) -> list[str]:
        (first, second), unit = self.axis_names, POSITION_UNIT
        return [
            f"duration           {self.duration_s:.2f} s",
            f"timer ticks        {self.ticks} (missed {self.missed_ticks})",
            f"tick lateness      p50 {self.lateness_p50_us:.0f} us, p99 {self.lateness_p99_us:.0f} us, max {self.lateness_max_us:.0f} us",
            f"setpoints sent     {self.setpoints}",
            self.events_line(),
            self.error_line(),
            f"recoveries         {self.recoveries} (re_init)",
            f"sensor reads       {self.sensor_reads}, max time skew between sensors {self.max_sensor_skew_us:.0f} us",
            self.readings_line(),
            self.sensor_fault_line(),
            f"tracking error     max {self.max_tracking_error_rad:.4f} {unit}",
            f"final positions    {first} {self.final_positions[0]:+.4f} {unit}, {second} {self.final_positions[1]:+.4f} {unit}",
        ]  # fmt: skip

    def partial_lines(self) -> list[str]:
        """What an interrupted demo did before it stopped."""
        return [
            f"timer ticks        {self.ticks} (missed {self.missed_ticks})",
            f"setpoints sent     {self.setpoints}",
            self.events_line(),
            self.error_line(),
            f"recoveries         {self.recoveries} (re_init)",
            f"sensor reads       {self.sensor_reads}",
            self.readings_line(),
            self.sensor_fault_line(),
        ]


class Application:
    """The HALObserver and TimerObserver of the figures: the upper application."""

    def __init__(self, axes: tuple[Actuator, Actuator], amplitude: float, frequency_hz: float):
        self.axes = axes
        self.amplitude = amplitude
        self.omega = 2 * math.pi * frequency_hz
        self.summary: DemoSummary | None = None
        self.t0_ns = 0
        self.faulted: anyio.Event = anyio.Event()
        self.max_error = 0.0
        self.setpoints = 0

    # HALObserver
    def notify_event(self, source: HALComponent, event_id: int) -> None:
        assert self.summary is not None
        if event_id == EventId.COMPLETED:
            self.summary.completed_events += 1
        else:
            self.summary.device_events += 1

    def notify_error(self, source: HALComponent, error_id: int) -> None:
        assert self.summary is not None
        fault = source.last_fault if source.state.value == "Error" else None
        reason = None
        if fault is not None:  # "MOTOR_2: <reason>": the device is named already
            reason = str(fault).removeprefix(f"{source.device_name}: ")
        self.summary.errors.append(ErrorReport(source.device_name, int(error_id), reason))
        self.faulted.set()

    # TimerObserver: stream synchronized setpoints to both axes (Fig. 7.7).
    async def notify_timer(self, timer: EventTimer) -> None:
        tick = timer.last_tick
        assert tick is not None
        t = (tick.deadline_ns - self.t0_ns) / NS_PER_S
        targets = (
            self.amplitude * math.sin(self.omega * t),
            self.amplitude * math.sin(self.omega * t + math.pi / 2) - self.amplitude,
        )
        for axis, target in zip(self.axes, targets, strict=True):
            if axis.state.value != "Active":
                continue
            actual = await axis.get_value(Request.POSITION_ACTUAL)
            self.max_error = max(
                self.max_error, abs(actual - axis.motion.target) if axis.motion else 0.0
            )
            await axis.set_value(target, Request.POSITION)
            self.setpoints += 1


@dataclass
class Rig:
    """The devices of the demo: two actuators and two sensors, entered (Initialized), not
    yet initialized: the demo registers its observers and calls ``init`` (Fig. 7.6)."""

    name: str
    axes: tuple[Actuator, Actuator]
    sensors: tuple[Sensor, Sensor]
    trip_axis2: Callable[[], None]
    """Trip the second axis's drive (fault injection)."""
    peers: Mapping[str, object] = field(default_factory=dict)
    """The rig's simulated devices by component name, for fault injection in tests."""
    opened: OpenedRig | None = None
    """The rig file's rig, when the devices come from one: it leaves them in its
    ``safety.on_exit`` state when it closes."""


RigFactory = Callable[[Clock], AbstractAsyncContextManager[Rig]]

RIGS = Path(__file__).parent / "rigs"
SIM_RIG = RIGS / "twoaxis-sim.yaml"
"""The demo's rig of simulated devices (``--bus sim``)."""
CAN_RIG = RIGS / "twoaxis-can.yaml"
"""The demo's CAN rig: an ODrive and a CiA 402 drive on ``can0`` (``--bus can`` runs it with
``--sim``)."""


def file_rig(
    rig: str | Path | ResolvedRig, *, sim: bool = False, ctx: AppContext | None = None
) -> RigFactory:
    """The demo's devices from a rig file: its first two actuators and first two sensors,
    in file order. ``sim``: against simulated peers. ``ctx``: the rig is registered with it
    (its summary says how the rig left the actuators)."""

    @asynccontextmanager
    async def factory(clock: Clock) -> AsyncIterator[Rig]:
        from openel_async.rig import FaultInjection, ResolvedRig, load_rig, open_rig, resolve_rig

        spec = rig if isinstance(rig, ResolvedRig) else resolve_rig(load_rig(rig))
        actuators = [
            c.name for c in spec.spec.components if issubclass(spec.classes[c.name], ActuatorDevice)
        ]
        if len(actuators) < 2 or len(spec.spec.components) - len(actuators) < 2:
            raise BadParameterError(
                "rig", spec.spec.source, "a rig with at least two actuators and two sensors"
            )
        async with open_rig(
            spec,
            clock,
            sim=sim,
            init=False,
            handle_sigquit=True,
            on_component=None if ctx is None else ctx.add_component,
            on_timer=None if ctx is None else ctx.add_timer,
        ) as opened:
            if ctx is not None:
                ctx.rigs.append(opened)
            first, second = opened.actuators[:2]
            sensors = opened.sensors[:2]
            peer = opened.peers.get(second.device_name)

            def trip() -> None:
                reason = "injected over-temperature trip"
                if isinstance(peer, FaultInjection):  # a simulated drive on a bus
                    peer.inject_fault(reason)
                elif (inject := getattr(second.device, "inject_fault", None)) is not None:
                    # An openel_sim device: the id the CAN rig's drive reports for the same
                    # over-temperature trip.
                    inject(ErrorId.DEVICE_ERROR, reason)
                else:
                    raise NotImplementedError(f"{second.device_name} is not simulated")

            name = spec.spec.description or Path(spec.spec.source).name
            if sim and opened.bus_descriptions:
                name += ", simulated: " + "; ".join(opened.bus_descriptions.values())
            yield Rig(name, (first, second), (sensors[0], sensors[1]), trip, opened.peers, opened)

    return factory


sim_rig = file_rig(SIM_RIG)
"""Two SimMotors, an encoder on the first and a thermometer on the second."""


def rig_for(bus: str) -> RigFactory:
    """The rig of ``--bus``: ``sim``, ``can`` or ``remote`` (ImportError when its driver
    cannot load)."""
    if bus == "sim":
        import openel_sim  # noqa: F401  (here, before anything runs, when it cannot load)

        return sim_rig
    if bus == "can":
        import openel_can  # noqa: F401

        return file_rig(CAN_RIG, sim=True)
    if bus == "remote":
        from .remote_rig import remote_rig

        return remote_rig
    raise ValueError(f"--bus must be sim, can or remote, not {bus!r}")


async def run_demo(
    *,
    duration_s: float = DURATION_S,
    period_ms: float = PERIOD_MS,
    virtual: bool = False,
    inject_fault: bool = False,
    live: LiveLine | None = None,
    rig: RigFactory = sim_rig,
    summary: DemoSummary | None = None,
    ctx: AppContext | None = None,
) -> DemoSummary:
    """Run the demo; ``summary`` (filled as the demo goes: the caller keeps what a cancelled
    run did) or a new one is returned. ``ctx``: the clock, components and timer are
    registered with it (and so passed on to its hooks)."""
    clock: Clock = VirtualClock() if virtual else MonotonicClock()
    if ctx is not None:
        ctx.use_clock(clock)
    if summary is None:
        summary = DemoSummary(duration_s=duration_s)
    summary.duration_s = duration_s
    async with AsyncExitStack() as stack:
        if isinstance(clock, VirtualClock):
            await stack.enter_async_context(clock.autojump())
        parts = await stack.enter_async_context(rig(clock))
        summary.rig = parts.name
        if ctx is not None:
            ctx.title = parts.name
        await _scenario(clock, parts, summary, period_ms, inject_fault, live, ctx)
    return summary


async def _scenario(
    clock: Clock,
    rig: Rig,
    summary: DemoSummary,
    period_ms: float,
    inject_fault: bool,
    live: LiveLine | None,
    ctx: AppContext | None,
) -> None:
    # Fig. 7.6: the components exist; register the observer and Init them below.
    axes, sensors = rig.axes, rig.sensors
    app = Application(axes, amplitude=0.5, frequency_hz=0.5)
    app.summary = summary
    summary.axis_names = (axes[0].device_name, axes[1].device_name)
    timer = EventTimer(period_ms, clock=clock, name="sync")
    if ctx is not None:
        for component in (*axes, *sensors):
            if component not in ctx.components:  # (a rig file's registered them)
                ctx.add_component(component)
        ctx.add_timer(timer)
    async with timer:
        for component in (*axes, *sensors):
            await component.init()
        for component in (*axes, *sensors):
            component.add_observer(app)
        app.t0_ns = clock.now_ns()
        timer.add_observer(app)
        timer.start_timer()
        try:
            await _run(clock, rig, app, timer, summary, inject_fault, live)
        finally:  # also when cancelled (Ctrl-C): what the demo did so far
            if live is not None:
                live.finish()
            stats = timer.stats
            summary.ticks = stats.ticks
            summary.missed_ticks = stats.missed_ticks
            summary.lateness_p50_us = stats.lateness.p50_ns / 1e3
            summary.lateness_p99_us = stats.lateness.p99_ns / 1e3
            summary.lateness_max_us = stats.lateness.max_ns / 1e3
            summary.setpoints = app.setpoints
            summary.max_tracking_error_rad = app.max_error
        summary.final_positions = (
            await axes[0].get_value(Request.POSITION_ACTUAL),
            await axes[1].get_value(Request.POSITION_ACTUAL),
        )


async def read_sensor(clock: Clock, sensor: Sensor, summary: DemoSummary) -> TimedValue | None:
    """One timed read of ``sensor``; a failed read is recorded in ``summary`` and the sensor
    re-initialized (at most :data:`SENSOR_RETRIES` attempts, each after a back-off on
    ``clock``). None when the read failed (recovered or not); a sensor that stays down is
    added to ``summary.sensors_lost`` and no longer read."""
    try:
        return await sensor.get_timed_value()
    except HALError as exc:
        summary.sensor_faults.append((sensor.device_name, str(exc)))
        log.warning("demo_sensor_fault", device=sensor.device_name, error=str(exc))
    for attempt, backoff_ns in enumerate(SENSOR_BACKOFF_NS[:SENSOR_RETRIES], start=1):
        await clock.sleep_until(clock.now_ns() + backoff_ns)
        if sensor.state.value == "Active":  # a refused read that left the sensor usable
            break
        try:
            await sensor.re_init()
        except HALError as exc:
            log.warning(
                "demo_sensor_re_init_failed",
                device=sensor.device_name,
                attempt=attempt,
                error=str(exc),
            )
            continue
        summary.sensor_recoveries += 1
        log.info("demo_sensor_recovered", device=sensor.device_name, attempt=attempt)
        break
    else:
        summary.sensors_lost.append(sensor.device_name)
        log.error("demo_sensor_lost", device=sensor.device_name, attempts=SENSOR_RETRIES)
    return None


async def _run(
    clock: Clock,
    rig: Rig,
    app: Application,
    timer: EventTimer,
    summary: DemoSummary,
    inject_fault: bool,
    live: LiveLine | None,
) -> None:
    """Stream the setpoints and read the sensors for the demo's duration, then bring both
    axes home."""
    axes, sensors = rig.axes, rig.sensors
    end_ns = app.t0_ns + round(summary.duration_s * NS_PER_S)
    fault_at = app.t0_ns + (end_ns - app.t0_ns) // 2 if inject_fault else None
    shown: list[str] = ["-", "-"]
    async with anyio.create_task_group() as tg:
        if fault_at is not None:
            tg.start_soon(_fault_and_recover, clock, fault_at, rig, app, summary)
        # Fig. 7.8: read the sensors with their times, every 100 ms.
        next_read = app.t0_ns
        while clock.now_ns() < end_ns:
            next_read += READ_PERIOD_NS
            await clock.sleep_until(min(next_read, end_ns))
            timed: list[TimedValue | None] = []
            for i, sensor in enumerate(sensors):
                if sensor.device_name in summary.sensors_lost:
                    timed.append(None)
                    shown[i] = "lost"
                    continue
                value = await read_sensor(clock, sensor, summary)
                timed.append(value)
                if value is None:
                    shown[i] = "fault"
                else:
                    shown[i] = reading_text(value.values[0], _unit(sensor))
                    summary.last_readings[sensor.device_name] = shown[i]
            summary.sensor_reads += sum(value is not None for value in timed)
            first, second = timed
            if first is not None and second is not None:
                skew = abs(first.time_ns - second.time_ns) / 1e3
                summary.max_sensor_skew_us = max(summary.max_sensor_skew_us, skew)
            if live is not None:
                live.update(
                    f"t={(clock.now_ns() - app.t0_ns) / NS_PER_S:5.2f}s ticks={timer.stats.ticks} "
                    f"{sensors[0].device_name} {shown[0]}  {sensors[1].device_name} {shown[1]}  "
                    f"events={summary.completed_events} errors={len(summary.errors)} "
                    f"sensor faults={len(summary.sensor_faults)}"
                )
        tg.cancel_scope.cancel()
    timer.stop_timer()
    await timer.wait_idle()
    # Bring both axes home in step and wait for their COMPLETED.
    with anyio.fail_after(30):
        for axis in axes:
            if axis.state.value == "Error":
                await axis.re_init()
        motions = [await axis.set_value(0.0, Request.POSITION) for axis in axes]
        for motion in motions:
            await motion
        await anyio.lowlevel.checkpoint()


def _unit(sensor: Sensor) -> str:
    """The unit of the sensor's first value ("" when it declares none)."""
    units = sensor.units
    return units[0] if units else ""


async def _fault_and_recover(
    clock: Clock, at_ns: int, rig: Rig, app: Application, summary: DemoSummary
) -> None:
    axis = rig.axes[1]
    await clock.sleep_until(at_ns)
    log.warning("demo_injecting_fault", device=axis.device_name)
    rig.trip_axis2()
    with anyio.fail_after(5):
        await app.faulted.wait()
    await clock.sleep_until(clock.now_ns() + 200_000_000)
    await axis.re_init()
    summary.recoveries += 1
    log.info("demo_recovered", device=axis.device_name)


# -- the app ----------------------------------------------------------------------------------


def build_parser(prog: str = NAME) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=prog,
        description="The two-axis synchronized demo of OpenEL spec Figs. 7.5-7.8 on simulated "
        "motors (--bus sim), simulated CAN drives (--bus can) or sim devices served by another "
        "process (--bus remote). Every option is checked before anything runs.",
    )
    parser.add_argument(
        "--bus",
        choices=("sim", "can", "remote"),
        default=None,
        help="Device layer: openel_sim motors (rigs/twoaxis-sim.yaml), simulated CAN drives "
        "(rigs/twoaxis-can.yaml with --sim), or the sim devices served by another process "
        "over Zenoh (default sim; openel-async's --rig FILE and --sim run the demo on any rig "
        "with two actuators and two sensors instead).",
    )
    parser.add_argument(
        "--duration",
        type=float,
        default=DURATION_S,
        metavar="S",
        help=f"Seconds of synchronized motion (default {DURATION_S:g}).",
    )
    parser.add_argument(
        "--period-ms",
        type=float,
        default=PERIOD_MS,
        metavar="MS",
        help=f"EventTimer period in ms, from {MIN_PERIOD_MS:g} to {MAX_PERIOD_MS:g} "
        f"(default {PERIOD_MS:g}).",
    )
    pacing = parser.add_mutually_exclusive_group()
    pacing.add_argument(
        "--virtual",
        action="store_true",
        help="Run on the virtual clock, as fast as the CPU allows (--bus sim only).",
    )
    pacing.add_argument(
        "--realtime", action="store_true", help="Run on the real clock (the default)."
    )
    parser.add_argument(
        "--inject-fault",
        action="store_true",
        help="Trip the second drive halfway and recover it with re_init (--bus sim or can).",
    )
    parser.add_argument("--no-live", action="store_true", help="Print no live progress line.")
    return parser


def check_options(args: argparse.Namespace) -> str | None:
    """Every option, before anything runs: the problem, or None."""
    duration, period = args.duration, args.period_ms
    if args.virtual and (args.bus or "sim") != "sim":
        return f"--virtual needs --bus sim: --bus {args.bus} runs in real time"
    if args.inject_fault and args.bus == "remote":
        return (
            "--inject-fault needs --bus sim or can: the remote devices are in the server "
            "process, and there is no remote fault injection"
        )
    if not (math.isfinite(duration) and duration > 0):
        return f"--duration {duration:g}: a finite number of seconds > 0"
    if not (math.isfinite(period) and MIN_PERIOD_MS <= period <= MAX_PERIOD_MS):
        return f"--period-ms {period:g}: from {MIN_PERIOD_MS:g} to {MAX_PERIOD_MS:g} ms"
    if duration * 1000.0 < period:
        return (
            f"--duration {duration:g}: at least one timer period (--period-ms {period:g}), "
            f"{period / 1000.0:g} s"
        )
    ticks = duration * 1000.0 / period
    if args.virtual and ticks > MAX_VIRTUAL_TICKS:
        return (
            f"--duration {duration:g} at --period-ms {period:g}: {ticks:.3g} timer ticks "
            f"on the virtual clock, at most {MAX_VIRTUAL_TICKS:,} (a longer period or a "
            "shorter duration)"
        )
    return None


async def main(ctx: AppContext) -> int:
    """Run the demo with ``ctx.argv``; print its summary; the exit status."""
    parser = build_parser(ctx.prog)
    args = parser.parse_args(ctx.argv)
    problem = check_options(args)
    if problem is not None:  # argparse's message and exit status 2
        parser.error(problem)
    if ctx.rig_spec is not None or ctx.sim:
        if args.bus is not None:
            parser.error("--bus chooses one of the demo's own rigs: not with --rig or --sim")
        if args.virtual and (ctx.sim or (ctx.rig_spec is not None and ctx.rig_spec.buses)):
            parser.error("--virtual needs a rig without buses: buses run in real time")
        from openel_async.rig import load_rig, resolve_rig

        rig = file_rig(ctx.rig_spec or resolve_rig(load_rig(CAN_RIG)), sim=ctx.sim, ctx=ctx)
    else:
        bus = args.bus or "sim"
        try:
            rig = rig_for(bus)
        except ImportError as exc:
            print(f"{ctx.prog}: the {bus} rig is not available: {exc}", file=sys.stderr)
            return 2
        if bus != "remote":
            rig = file_rig(SIM_RIG if bus == "sim" else CAN_RIG, sim=bus == "can", ctx=ctx)
    summary = DemoSummary(duration_s=args.duration)
    ctx.progress = summary.partial_lines
    await run_demo(
        duration_s=args.duration,
        period_ms=args.period_ms,
        virtual=args.virtual,
        inject_fault=args.inject_fault,
        live=None if args.no_live else LiveLine(),
        rig=rig,
        summary=summary,
        ctx=ctx,
    )
    print(f"\nsummary ({summary.rig})")
    for line in summary.lines():
        print("  " + line)
    return 0


def demo_args(options: DemoOptions) -> list[str]:
    """``openel-async demo --bus sim|can`` options as this app's command line."""
    if options.bus == "mujoco":
        raise ValueError("the two-axis demo runs on --bus sim or --bus can, not mujoco")
    if options.out is not None:
        raise ValueError("--out needs --bus mujoco (the sim and can demos write no files)")
    argv = [] if options.bus is None else ["--bus", options.bus]
    if options.duration is not None:
        argv += ["--duration", repr(options.duration)]
    if options.period_ms is not None:
        argv += ["--period-ms", repr(options.period_ms)]
    if options.virtual:
        argv.append("--virtual")
    if options.inject_fault:
        argv.append("--inject-fault")
    if not options.live:
        argv.append("--no-live")
    return argv


APP_INFO = AppInfo(
    name=NAME,
    description="two axes in step from an EventTimer, sensors read with their times "
    "(spec Figs. 7.5-7.8), on openel_sim motors or simulated CAN drives",
    main=main,
    demo_args=demo_args,
    takes_rig=True,
    parser=build_parser,
)
