"""Helpers of the recorder tests: a small sim-motor scenario on the virtual clock."""

from __future__ import annotations

from pathlib import Path

import anyio

from openel_async import Actuator, EventTimer, Request, Sensor, VirtualClock
from openel_async.recording import Recorder
from openel_sim import SimMotor, SimTemperature

TARGETS = ((0.0, 0.8, -0.3), (0.1, -0.5, 0.6))
"""Per motor: three targets, sent 0.6 s apart (the last is the final position)."""
MOTOR_OPTIONS = {"max_velocity": 3.0, "max_acceleration": 40.0}


async def scenario(path: Path, *, capacity: int = 100_000) -> Recorder:
    """Two sim motors and a thermometer observed by a Recorder on the virtual clock: each
    motor gets three targets, the thermometer is read at each of the timer's 10 ms ticks
    for 1.8 s."""
    clock = VirtualClock()
    recorder = Recorder(path, capacity=capacity)
    motors = [SimMotor(**MOTOR_OPTIONS) for _ in TARGETS]  # type: ignore[arg-type]
    async with clock.autojump(), recorder:
        axes = [Actuator(m, device_name=f"AXIS_{i}", clock=clock) for i, m in enumerate(motors)]
        thermo = Sensor(SimTemperature(motors[0], seed=3), device_name="THERMO", clock=clock)
        timer = EventTimer(10, clock=clock, name="loop")
        for component in (*axes, thermo):
            recorder.observe(component)
        recorder.observe_timer(timer)
        async with axes[0], axes[1], thermo, timer:
            reads = 0

            def on_tick(t: EventTimer) -> None:
                nonlocal reads
                thermo.get_value_nowait()
                reads += 1

            timer.add_observer(on_tick)
            timer.start_timer()
            for step in range(3):
                for axis, targets in zip(axes, TARGETS, strict=True):
                    await axis.set_value(targets[step], Request.POSITION)
                await clock.sleep_until(clock.now_ns() + 600_000_000)
            timer.stop_timer()
            for axis in axes:
                await axis.get_value(Request.POSITION_ACTUAL)
    await anyio.lowlevel.checkpoint()
    return recorder
