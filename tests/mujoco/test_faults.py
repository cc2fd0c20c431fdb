"""Unstable simulations fault every component; re_init resets; model loading errors."""

from __future__ import annotations

import pathlib
from contextlib import AsyncExitStack

import anyio
import numpy as np
import pytest

from openel_async import ComponentState, DeviceFaultError, ErrorId, Request
from openel_async.errors import BadParameterError, HALError, StateError
from openel_mujoco import JointSpec, ModelLoadError, MujocoSim, SimDescription

from .conftest import start_rig

# explicit Euler, a stiff servo and a coarse step: diverges within a few steps of a move
ABSURD_GAINS_XML = """
<mujoco model="absurd">
  <compiler angle="radian"/>
  <option timestep="0.01" integrator="Euler" gravity="0 0 0"/>
  <worldbody>
    <body name="link">
      <joint name="j" type="hinge" axis="0 0 1" range="-1 1"/>
      <geom type="capsule" fromto="0 0 0 0.2 0 0" size="0.02" mass="0.1"/>
    </body>
  </worldbody>
  <actuator>
    <position name="j_pos" joint="j" kp="1e9" inheritrange="1"/>
  </actuator>
  <sensor><jointpos name="angle" joint="j"/></sensor>
</mujoco>
"""


async def test_nan_in_qvel_faults_every_component_and_re_init_recovers(
    stack: AsyncExitStack,
) -> None:
    sim = MujocoSim("arm2")
    rig = await start_rig(stack, sim, ("shoulder", "elbow"), ("imu_gyro",))
    shoulder, elbow, gyro = (
        rig.actuators["shoulder"],
        rig.actuators["elbow"],
        rig.sensors["imu_gyro"],
    )
    with anyio.fail_after(10):
        await sim.sleep(0.05)
        motion = await shoulder.set_value(1.0)
        sim.data.qvel[1] = np.nan  # something blew up
        with pytest.raises(DeviceFaultError, match="unstable") as caught:
            await motion
        assert caught.value.error_id == ErrorId.DEVICE_ERROR
        for component in (shoulder, elbow, gyro):
            await rig.events.wait_for("error", ErrorId.DEVICE_ERROR, source=component)
    reason = sim.fault
    assert reason is not None and "QVEL" in reason and "elbow" in reason and "re_init" in reason
    assert {c.state for c in (shoulder, elbow, gyro)} == {ComponentState.ERROR}
    assert all(c.last_fault is not None and reason in str(c.last_fault) for c in (shoulder, elbow))
    assert rig.events.count("error") == 3
    steps = sim.steps
    with pytest.raises(StateError):
        await gyro.get_value()
    with pytest.raises(StateError):
        await elbow.set_value(0.1)
    # no physics while faulted, but the lockstep clock still serves sleepers
    before = sim.clock.now_ns()
    with anyio.fail_after(10):
        await sim.sleep(0.5)
    assert sim.clock.now_ns() == before + 500_000_000 and sim.steps == steps
    assert np.isnan(sim.data.qvel).any()  # the bad state is kept for inspection

    # re_init of one component resets the simulation; the others stay in Error
    await shoulder.re_init()
    assert sim.fault is None and sim.resets == 1
    assert shoulder.state is ComponentState.ACTIVE and elbow.state is ComponentState.ERROR
    assert np.all(np.isfinite(sim.data.qvel)) and sim.time_ns == 0
    assert sim.joints["shoulder"].control_mode is Request.POSITION
    await elbow.re_init()
    await gyro.re_init()
    assert sim.resets == 1  # only the first re_init reset the simulation
    with anyio.fail_after(10):
        await (await shoulder.set_value(-0.5))
        await (await elbow.set_value(0.5))
        assert len(await gyro.get_value()) == 3
    assert sim.clock.now_ns() > before + 500_000_000  # the clock never went back


async def test_absurd_gains_fault_the_simulation(
    stack: AsyncExitStack, tmp_path: pathlib.Path
) -> None:
    path = tmp_path / "absurd.xml"
    path.write_text(ABSURD_GAINS_XML)
    sim = MujocoSim(path, sensors=["angle"], joints=["j"])
    rig = await start_rig(stack, sim, ("j",), ("angle",))
    with anyio.fail_after(10):
        motion = await rig.actuators["j"].set_value(0.5)
        with pytest.raises(DeviceFaultError):
            await motion
        await rig.events.wait_for("error", ErrorId.DEVICE_ERROR, count=2)
    assert sim.fault is not None and "unstable" in sim.fault
    assert rig.sensors["angle"].state is ComponentState.ERROR
    with pytest.raises(HALError, match="faulted"):
        await sim.joints["j"].command(Request.POSITION, 0.1)
    with pytest.raises(HALError, match="faulted"):
        await sim.sensors["angle"].read()


async def test_a_component_cannot_start_on_a_faulted_simulation(stack: AsyncExitStack) -> None:
    sim = MujocoSim("arm2")
    sim.data.qacc[0] = np.inf
    sim.data.qvel[0] = np.inf
    assert sim.step(5) == 1
    assert sim.fault is not None
    from openel_async import Actuator

    with pytest.raises(HALError, match="faulted"):
        async with Actuator(sim.actuator("shoulder"), clock=sim.clock):
            pass
    sim.reset()
    assert sim.fault is None and sim.step(5) == 5


# --------------------------------------------------------------------------- loading errors


def test_missing_model_file_and_unknown_model_name(tmp_path: pathlib.Path) -> None:
    missing = tmp_path / "nowhere" / "robot.xml"
    with pytest.raises(ModelLoadError, match="model file not found") as caught:
        MujocoSim(missing)
    assert str(missing) in str(caught.value)
    with pytest.raises(ModelLoadError, match=r"unknown model 'arm3'.*shipped models: arm2, arm6"):
        MujocoSim("arm3")
    broken = tmp_path / "broken.xml"
    broken.write_text("<mujoco><worldbody><body><joint type='hinge'/></body></mujoco>")
    with pytest.raises(ModelLoadError, match="cannot load MuJoCo model"):
        MujocoSim(broken)


def test_unknown_names_list_the_candidates() -> None:
    sim = MujocoSim("arm2")
    with pytest.raises(
        ModelLoadError,
        match=r"unknown joint 'elbw'; joints in arm2: shoulder, elbow \(did you mean 'elbow'\?\)",
    ):
        sim.actuator("elbw")
    with pytest.raises(ModelLoadError, match=r"unknown sensor 'imu'; sensors in arm2: .*imu_acc"):
        sim.sensor("imu")
    with pytest.raises(ModelLoadError, match="unknown key 'rest'"):
        MujocoSim("arm6", keyframe="rest")
    with pytest.raises(ModelLoadError, match="unknown actuator 'nope'"):
        sim.actuator("shoulder", name="sh", actuators={"position": "nope"})
    with pytest.raises(ModelLoadError, match="does not drive joint 'shoulder'"):
        sim.actuator("shoulder", name="sh2", actuators={"position": "elbow_pos"})
    with pytest.raises(ModelLoadError, match="unknown joint 'wrist'"):
        MujocoSim.from_description({"model": "arm2", "joints": ["wrist"]})


def test_joints_that_cannot_be_actuators() -> None:
    sim = MujocoSim("arm6", keyframe="home")
    with pytest.raises(ModelLoadError, match="'box' is a free joint"):
        sim.actuator("box")
    xml = """<mujoco><worldbody><body><joint name="j" type="hinge"/>
      <geom type="sphere" size=".1" mass="1"/></body>
      <body pos="1 0 0"><joint name="k" type="hinge"/><geom type="sphere" size=".1" mass="1"/>
      </body></worldbody>
      <actuator><position name="p" joint="k" kp="10"/><motor name="m" joint="k"/></actuator>
      </mujoco>"""
    import mujoco

    other = MujocoSim(mujoco.MjModel.from_xml_string(xml))
    with pytest.raises(ModelLoadError, match="joint 'j' has no position, velocity or motor"):
        other.actuator("j")
    with pytest.raises(ModelLoadError, match="cannot be switched"):
        other.actuator("k")  # two actuators sharing group 0
    only_servo = other.actuator("k", actuators={"position": "p"})
    assert Request.POSITION in only_servo.supported_requests


def test_bad_description_values_name_the_parameter() -> None:
    with pytest.raises(BadParameterError, match=r"description\.joint=.*expected a known field"):
        SimDescription.from_dict({"model": "arm2", "joint": ["shoulder"]})
    with pytest.raises(BadParameterError, match=r"joints\[\]\.gain"):
        SimDescription.from_dict({"model": "arm2", "joints": [{"joint": "elbow", "gain": 3}]})
    with pytest.raises(BadParameterError, match=r"JointSpec\.max_velocity"):
        JointSpec("elbow", max_velocity=-1.0)
    with pytest.raises(BadParameterError, match="pacing"):
        SimDescription("arm2", pacing="fast")  # type: ignore[arg-type]
    with pytest.raises(BadParameterError, match="joints"):
        SimDescription("arm2", joints=("elbow", "elbow"))  # type: ignore[arg-type]
    with pytest.raises(BadParameterError, match="mode"):
        JointSpec("elbow", mode="current")  # type: ignore[arg-type]
