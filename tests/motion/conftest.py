"""The make_rig fixture: SimMotors that record what they are commanded, on the virtual
clock, with an EventTimer and an AxisGroup entered for the test."""

from __future__ import annotations

from collections.abc import AsyncIterator, Sequence
from contextlib import AsyncExitStack
from typing import Any

import pytest

from openel_async import EventTimer, VirtualClock
from openel_async.motion import AxisGroup, AxisLimits
from openel_async.testing import ComponentStack

from .rigs import LIMITS, PERIOD_MS, RecordingMotor, Rig, RigFactory


@pytest.fixture
async def make_rig(
    hal_components: ComponentStack, virtual_clock: VirtualClock
) -> AsyncIterator[RigFactory]:
    async with AsyncExitStack() as stack:

        async def make(
            axes: int = 3,
            *,
            motors: Sequence[RecordingMotor] | None = None,
            limits: AxisLimits | Sequence[AxisLimits] = LIMITS,
            period_ms: float = PERIOD_MS,
            **kwargs: Any,
        ) -> Rig:
            motor_list = (
                list(motors) if motors is not None else [RecordingMotor() for _ in range(axes)]
            )
            actuators = [
                await hal_components.actuator(m, device_name=f"joint{i}")
                for i, m in enumerate(motor_list)
            ]
            timer = await stack.enter_async_context(EventTimer(period_ms, clock=virtual_clock))
            group = await stack.enter_async_context(
                AxisGroup(actuators, timer=timer, limits=limits, **kwargs)
            )
            return Rig(group, actuators, motor_list, timer, virtual_clock)

        yield make
