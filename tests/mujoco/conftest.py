"""Helpers shared by the openel_mujoco tests: running a simulation with its components."""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import AsyncExitStack
from dataclasses import dataclass, field

import pytest

from openel_async import Actuator, Sensor
from openel_async.testing import EventRecorder
from openel_mujoco import MujocoSim

ARM6_JOINTS = (
    "base_yaw",
    "shoulder_pitch",
    "elbow_pitch",
    "wrist_roll",
    "wrist_pitch",
    "flange_roll",
)

# A one-joint model with only a motor: POSITION and VELOCITY run on the built-in PD (with
# the default gains, derived from the inertia; no gravity, so no static error).
MOTOR_ONLY_XML = """
<mujoco model="pendulum">
  <compiler angle="radian"/>
  <option timestep="0.001" integrator="implicitfast" gravity="0 0 0"/>
  <worldbody>
    <body name="arm" pos="0 0 1">
      <joint name="hinge" type="hinge" axis="0 1 0" range="-2 2" damping="0.01" armature="0.01"/>
      <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.02" mass="0.5"/>
    </body>
  </worldbody>
  <actuator>
    <motor name="drive" joint="hinge" gear="2" ctrlrange="-2 2"/>
  </actuator>
  <sensor>
    <jointpos name="angle" joint="hinge"/>
  </sensor>
</mujoco>
"""


@dataclass
class Rig:
    """A running simulation and components over some of its devices."""

    sim: MujocoSim
    events: EventRecorder
    actuators: dict[str, Actuator] = field(default_factory=dict)
    sensors: dict[str, Sensor] = field(default_factory=dict)


async def start_rig(
    stack: AsyncExitStack,
    sim: MujocoSim,
    joints: tuple[str, ...] = (),
    sensors: tuple[str, ...] = (),
) -> Rig:
    """Enter ``sim`` and one component per joint/sensor, all observed by one EventRecorder."""
    await stack.enter_async_context(sim)
    rig = Rig(sim, EventRecorder(sim.clock))
    for name in joints:
        actuator = await stack.enter_async_context(Actuator(sim.actuator(name), clock=sim.clock))
        actuator.add_observer(rig.events)
        rig.actuators[name] = actuator
    for name in sensors:
        sensor = await stack.enter_async_context(Sensor(sim.sensor(name), clock=sim.clock))
        sensor.add_observer(rig.events)
        rig.sensors[name] = sensor
    return rig


@pytest.fixture
async def stack() -> AsyncIterator[AsyncExitStack]:
    async with AsyncExitStack() as s:
        yield s
