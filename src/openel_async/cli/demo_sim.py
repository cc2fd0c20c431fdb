"""The OpenEL synchronous-control demo (spec Figures 7.5-7.8) on simulated devices.

Two actuators are initialized with observers (Fig. 7.6), driven in step from an
EventTimer's notify_timer (Fig. 7.7), and two sensors are read with their times to
relate their measurements (Fig. 7.8). With ``inject_fault`` a drive trips halfway:
the error observer fires, the application calls re_init and carries on.
"""

from __future__ import annotations

import math
from collections.abc import AsyncIterator, Callable
from contextlib import AbstractAsyncContextManager, AsyncExitStack, asynccontextmanager
from dataclasses import dataclass, field

import anyio
import anyio.lowlevel
import structlog

from openel_async import (
    Actuator,
    Clock,
    EventId,
    EventTimer,
    HALComponent,
    HALId,
    MonotonicClock,
    Request,
    Sensor,
    VirtualClock,
)
from openel_async.clock import NS_PER_S
from openel_async.ids import DeviceKind
from openel_sim import SimEncoder, SimMotor, SimTemperature

from .progress import LiveLine

log = structlog.get_logger(__name__)


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
    errors: list[tuple[str, int]] = field(default_factory=list)
    recoveries: int = 0
    sensor_reads: int = 0
    max_sensor_skew_us: float = 0.0
    max_tracking_error_rad: float = 0.0
    final_positions: tuple[float, float] = (0.0, 0.0)

    def lines(self) -> list[str]:
        return [
            f"duration           {self.duration_s:.2f} s",
            f"timer ticks        {self.ticks} (missed {self.missed_ticks})",
            f"tick lateness      p50 {self.lateness_p50_us:.0f} us, p99 {self.lateness_p99_us:.0f} us, max {self.lateness_max_us:.0f} us",
            f"setpoints sent     {self.setpoints}",
            f"events             COMPLETED x{self.completed_events}, device-specific x{self.device_events}",
            f"errors             {len(self.errors)} {self.errors if self.errors else ''}".rstrip(),
            f"recoveries         {self.recoveries} (re_init)",
            f"sensor reads       {self.sensor_reads}, max time skew between sensors {self.max_sensor_skew_us:.0f} us",
            f"tracking error     max {self.max_tracking_error_rad:.4f} rad",
            f"final positions    {self.final_positions[0]:+.4f}, {self.final_positions[1]:+.4f} rad",
        ]

    def partial_lines(self) -> list[str]:
        """What an interrupted demo did before it stopped."""
        return [
            f"timer ticks        {self.ticks} (missed {self.missed_ticks})",
            f"setpoints sent     {self.setpoints}",
            f"events             COMPLETED x{self.completed_events}, device-specific x{self.device_events}",
            f"errors             {len(self.errors)} {self.errors if self.errors else ''}".rstrip(),
            f"recoveries         {self.recoveries} (re_init)",
            f"sensor reads       {self.sensor_reads}",
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
        self.summary.errors.append((source.device_name, int(error_id)))
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
    """The devices of the demo: two actuators and two sensors, not yet entered."""

    name: str
    axes: tuple[Actuator, Actuator]
    sensors: tuple[Sensor, Sensor]
    trip_axis2: Callable[[], None]
    """Trip the second axis's drive (fault injection)."""


RigFactory = Callable[[Clock], AbstractAsyncContextManager[Rig]]


@asynccontextmanager
async def sim_rig(clock: Clock) -> AsyncIterator[Rig]:
    """Two SimMotors, an encoder on the first and a thermometer on the second."""
    motors = (
        SimMotor(max_velocity=3.0, max_acceleration=40.0),
        SimMotor(max_velocity=3.0, max_acceleration=40.0),
    )
    axes = (
        Actuator(motors[0], hal_id=HALId(DeviceKind.MOTOR, 0xE1, 0x100, 1), device_name="MOTOR_1", clock=clock, auto_init=False),
        Actuator(motors[1], hal_id=HALId(DeviceKind.MOTOR, 0xE1, 0x100, 2), device_name="MOTOR_2", clock=clock, auto_init=False),
    )  # fmt: skip
    sensors = (
        Sensor(SimEncoder(motors[0]), hal_id=HALId(DeviceKind.ROTARY_ANGLE, 0xE1, 0x200, 1), device_name="ENCODER_1", clock=clock, auto_init=False),
        Sensor(SimTemperature(motors[1], noise=0.05, seed=7), hal_id=HALId(DeviceKind.TEMPERATURE, 0xE1, 0x400, 1), device_name="TEMP_2", clock=clock, auto_init=False),
    )  # fmt: skip

    def trip() -> None:
        motors[1].inject_fault(error_id=7, reason="demo: over-temperature trip")

    yield Rig("simulated devices, openel_sim", axes, sensors, trip)


async def run_demo(
    *,
    duration_s: float = 5.0,
    period_ms: float = 10.0,
    virtual: bool = False,
    inject_fault: bool = False,
    live: LiveLine | None = None,
    rig: RigFactory = sim_rig,
    summary: DemoSummary | None = None,
) -> DemoSummary:
    """Run the demo; ``summary`` (filled as the demo goes: the caller keeps what a cancelled
    run did) or a new one is returned."""
    clock: Clock = VirtualClock() if virtual else MonotonicClock()
    if summary is None:
        summary = DemoSummary(duration_s=duration_s)
    summary.duration_s = duration_s
    async with AsyncExitStack() as stack:
        if isinstance(clock, VirtualClock):
            await stack.enter_async_context(clock.autojump())
        parts = await stack.enter_async_context(rig(clock))
        summary.rig = parts.name
        await _scenario(clock, parts, summary, period_ms, inject_fault, live)
    return summary


async def _scenario(
    clock: Clock,
    rig: Rig,
    summary: DemoSummary,
    period_ms: float,
    inject_fault: bool,
    live: LiveLine | None,
) -> None:
    # Fig. 7.6: the components exist; register the observer and Init them below.
    axes, sensors = rig.axes, rig.sensors
    app = Application(axes, amplitude=0.5, frequency_hz=0.5)
    app.summary = summary
    async with (
        axes[0],
        axes[1],
        sensors[0],
        sensors[1],
        EventTimer(period_ms, clock=clock, name="sync") as timer,
    ):
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
    async with anyio.create_task_group() as tg:
        if fault_at is not None:
            tg.start_soon(_fault_and_recover, clock, fault_at, rig, app, summary)
        # Fig. 7.8: read the sensors with their times, every 100 ms.
        next_read = app.t0_ns
        while clock.now_ns() < end_ns:
            next_read += 100_000_000
            await clock.sleep_until(min(next_read, end_ns))
            timed = [await s.get_timed_value() for s in sensors]
            summary.sensor_reads += len(timed)
            skew = abs(timed[0].time_ns - timed[1].time_ns) / 1e3
            summary.max_sensor_skew_us = max(summary.max_sensor_skew_us, skew)
            if live is not None:
                live.update(
                    f"t={(clock.now_ns() - app.t0_ns) / NS_PER_S:5.2f}s ticks={timer.stats.ticks} "
                    f"q1={timed[0].values[0]:+.3f} rad T2={timed[1].values[0]:.2f} K "
                    f"events={summary.completed_events} errors={len(summary.errors)}"
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
