"""The ``openel_sim`` pytest plugin (registered through the ``pytest11`` entry point
``openel_sim``): simulated devices on the framework plugin's ``virtual_clock``.

- ``sim_motor`` / ``sim_actuator``: a SimMotor and an active Actuator over it on the
  virtual clock, with ``hal_events`` recording its notifications;
- ``sim_encoder`` and ``sim_imu``: active Sensors attached to that motor.

They build on the fixtures of :mod:`openel_async.testing` (``hal_components``,
``hal_events``); docs/testing.md describes them all.
"""

from __future__ import annotations

import pytest

from openel_async import Actuator, Sensor
from openel_async.testing import ComponentStack, EventRecorder

from .motor import SimMotor
from .sensors import SimEncoder, SimIMU


@pytest.fixture
def sim_motor() -> SimMotor:
    return SimMotor()


@pytest.fixture
async def sim_actuator(
    hal_components: ComponentStack, sim_motor: SimMotor, hal_events: EventRecorder
) -> Actuator:
    actuator = await hal_components.actuator(sim_motor)
    actuator.add_observer(hal_events)
    return actuator


@pytest.fixture
async def sim_encoder(hal_components: ComponentStack, sim_motor: SimMotor) -> Sensor:
    return await hal_components.sensor(SimEncoder(sim_motor))


@pytest.fixture
async def sim_imu(hal_components: ComponentStack, sim_motor: SimMotor) -> Sensor:
    return await hal_components.sensor(SimIMU(sim_motor, radius=0.1))
