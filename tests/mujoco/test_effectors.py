"""MujocoEffector: MuJoCo actuators that do not drive one joint (adhesion, tendon, site)."""

from __future__ import annotations

import math
import pathlib
import re
from contextlib import AsyncExitStack

import anyio
import mujoco
import numpy as np
import pytest
import yaml

from openel_async import (
    Actuator,
    ComponentState,
    DeviceFaultError,
    DeviceKind,
    ErrorId,
    EventId,
    NotImplementedHALError,
    Request,
)
from openel_async.errors import BadParameterError, HALError
from openel_async.testing import EventRecorder
from openel_mujoco import (
    EffectorSpec,
    ModelLoadError,
    MujocoEffector,
    MujocoEventId,
    MujocoSim,
    SimDescription,
    effector_kind,
)

# Three effectors and a joint-driven lift:
# - grip: a position servo on the fixed tendon 'grip' (its length = closure of two slide
#   fingers); the fingers close on the static 'block' at a closure of 0.07 m;
# - thrust: a force actuator with filter dynamics (time constant 20 ms) on a site of a sled;
# - suction: adhesion on the cup, which the 'lift' joint lowers onto a free box.  Adhesion acts
#   through contacts, so the cup geom has a margin (and an equal gap, so the contact holds no
#   force of its own): contacts within 1 cm count, which lets the adhesion keep pulling while
#   the cup rises.
EFFECTORS_XML = """
<mujoco model="effectors">
  <option timestep="0.001" integrator="implicitfast" gravity="0 0 -9.81"/>
  <worldbody>
    <geom name="floor" type="plane" size="1 1 0.1"/>
    <geom name="block" type="box" pos="0 0 0.1" size="0.01 0.02 0.01"/>
    <body name="left" pos="0 0.06 0.1">
      <joint name="left" type="slide" axis="0 -1 0" range="0 0.05" damping="2"/>
      <geom type="box" size="0.01 0.005 0.02" mass="0.05"/>
    </body>
    <body name="right" pos="0 -0.06 0.1">
      <joint name="right" type="slide" axis="0 1 0" range="0 0.05" damping="2"/>
      <geom type="box" size="0.01 0.005 0.02" mass="0.05"/>
    </body>
    <body name="cup" pos="0.5 0 0.2">
      <joint name="lift" type="slide" axis="0 0 1" range="-0.2 0.1" damping="20"/>
      <geom name="cup" type="box" size="0.03 0.03 0.01" mass="0.2" margin="0.01" gap="0.01"/>
    </body>
    <body name="box" pos="0.5 0 0.02">
      <freejoint name="box"/>
      <geom name="box" type="box" size="0.02 0.02 0.02" mass="0.1"/>
    </body>
    <body name="sled" pos="-0.5 0 0.3">
      <joint name="sled" type="slide" axis="1 0 0" damping="1"/>
      <geom type="box" size="0.02 0.02 0.02" mass="0.2" contype="0" conaffinity="0"/>
      <site name="thruster"/>
    </body>
  </worldbody>
  <tendon>
    <fixed name="grip">
      <joint joint="left" coef="1"/>
      <joint joint="right" coef="1"/>
    </fixed>
  </tendon>
  <actuator>
    <position name="grip" tendon="grip" kp="500" kv="20" ctrlrange="0 0.1" forcerange="-5 5"
              group="3"/>
    <general name="thrust" site="thruster" gear="1 0 0 0 0 0" dyntype="filter" dynprm="0.02"
             ctrlrange="-2 2"/>
    <adhesion name="suction" body="cup" gain="30" ctrlrange="0 1"/>
    <position name="lift" joint="lift" kp="2000" kv="200"/>
    <muscle name="muscle" tendon="grip"/>
  </actuator>
  <sensor>
    <jointpos name="left_pos" joint="left"/>
  </sensor>
  <keyframe>
    <key name="ajar" qpos="0.01 0.01 0  0.5 0 0.02 1 0 0 0  0"/>
  </keyframe>
</mujoco>
"""


def _sim(**options: object) -> MujocoSim:
    return MujocoSim(mujoco.MjModel.from_xml_string(EFFECTORS_XML), **options)  # type: ignore[arg-type]


async def _component(
    stack: AsyncExitStack, device: MujocoEffector, events: EventRecorder | None = None
) -> Actuator:
    actuator = await stack.enter_async_context(Actuator(device, clock=device.sim.clock))
    if events is not None:
        actuator.add_observer(events)
    return actuator


# -- mapping and limits ---------------------------------------------------------------------


def test_the_arm6_suction_is_an_adhesion_effector() -> None:
    sim = MujocoSim("arm6", keyframe="home")
    suction = sim.effector("suction")
    assert isinstance(suction, MujocoEffector) and sim.effectors == {"suction": suction}
    assert sim.effector("suction") is suction
    assert suction.kind == "adhesion" and suction.transmission == "body"
    assert suction.supported_requests == {Request.TORQUE, Request.NO_EXCITE}
    assert suction.limits.torque == pytest.approx(20.0)  # gain 20 N x ctrl 1
    assert suction.touch_sensor == "pad_touch"  # the touch sensor on the tool body
    assert suction.info.kind == 0x80 and suction.info.product_name == "Suction"
    assert "adhesion" in repr(suction)
    assert not suction.on and not suction.holding


def test_request_mapping_follows_the_actuator() -> None:
    sim = _sim()
    grip, thrust, suction = (sim.effector(n) for n in ("grip", "thrust", "suction"))
    kinds = {n: effector_kind(sim.model, sim.effector(n).actuator_id) for n in sim.effectors}
    assert kinds == {"grip": "position", "thrust": "force", "suction": "adhesion"}

    # tendon position servo: POSITION of the tendon length, limits from ctrlrange; its own
    # actuator group makes NO_EXCITE possible (the actuator is disabled)
    assert grip.supported_requests == {Request.POSITION, Request.NO_EXCITE}
    assert grip.limits.position == (0.0, 0.1)
    assert grip.has_length and grip.transmission == "tendon"
    assert grip.info.kind is DeviceKind.MOTOR and grip.info.product_name == "Grip"
    # site force actuator: TORQUE = actuator force (gain 1 x ctrlrange)
    assert thrust.supported_requests == {Request.TORQUE, Request.NO_EXCITE}
    assert thrust.limits.torque == 2.0 and not thrust.has_length
    # adhesion: 0 .. gain x ctrl max; no touch sensor on the cup: the contact list decides
    assert suction.limits.torque == pytest.approx(30.0) and suction.touch_sensor is None

    assert grip.read_nowait(Request.POSITION_ACTUAL) == 0.0
    assert thrust.read_nowait(Request.TORQUE_ACTUAL) == 0.0
    with pytest.raises(BadParameterError, match="site transmission has no length"):
        thrust.read_nowait(Request.POSITION_ACTUAL)
    with pytest.raises(BadParameterError, match="request"):
        grip.read_nowait(Request.POSITION)


def test_bad_input_is_refused() -> None:
    sim = _sim()
    with pytest.raises(ModelLoadError, match=r"unknown actuator 'suktion'.*did you mean 'suction'"):
        sim.effector("suktion")
    with pytest.raises(BadParameterError, match=r"drives joint 'lift'.*sim\.actuator\('lift'\)"):
        sim.effector("lift")  # a joint's actuator: sim.actuator("lift") maps it
    with pytest.raises(ModelLoadError, match="muscle dynamics"):
        sim.effector("muscle")
    with pytest.raises(BadParameterError, match=r"gain=2 .*EffectorSpec field"):
        sim.effector("grip", gain=2)
    with pytest.raises(BadParameterError, match="touch_sensor"):
        sim.effector("grip", touch_sensor="left_pos")  # not adhesion
    with pytest.raises(BadParameterError, match="touch sensor"):
        sim.effector("suction", touch_sensor="left_pos")  # not a touch sensor
    with pytest.raises(BadParameterError, match=r"EffectorSpec\.position_tolerance"):
        sim.effector("grip", position_tolerance=0.0)
    grip = sim.effector("grip", position_tolerance=0.002)
    with pytest.raises(BadParameterError, match="options"):
        sim.effector("grip", position_tolerance=0.003)
    with pytest.raises(BadParameterError, match="mapped as 'grip'"):
        sim.effector("grip", name="other")  # one device per actuator
    assert sim.effector("grip") is grip

    # the device checks the exact range (the framework only the symmetric ActuatorLimits)
    suction = sim.effector("suction")
    with pytest.raises(BadParameterError, match=r"adhesion force in \[0, 30\]"):
        suction.command_nowait(Request.TORQUE, -1.0)
    with pytest.raises(BadParameterError, match=r"actuator length in \[0, 0.1\]"):
        grip.command_nowait(Request.POSITION, 0.2)
    with pytest.raises(BadParameterError):
        grip.command_nowait(Request.POSITION, math.nan)
    with pytest.raises(NotImplementedHALError, match="does not support POSITION"):
        suction.command_nowait(Request.POSITION, 0.1)
    with pytest.raises(NotImplementedHALError, match="does not support TORQUE"):
        grip.command_nowait(Request.TORQUE, 1.0)
    assert suction.commands == grip.commands == 0 and not suction.on


async def test_bad_input_through_the_component(stack: AsyncExitStack) -> None:
    sim = _sim()
    await stack.enter_async_context(sim)
    suction = await _component(stack, sim.effector("suction"))
    grip = await _component(stack, sim.effector("grip"))
    with pytest.raises(BadParameterError):
        await suction.set_value(-1.0, Request.TORQUE)  # negative adhesion
    with pytest.raises(BadParameterError):
        await suction.set_value(31.0, Request.TORQUE)  # beyond gain x ctrl max
    with pytest.raises(NotImplementedHALError):
        await suction.set_value(1.0, Request.POSITION)
    with pytest.raises(BadParameterError):
        await grip.set_value(-0.01)  # outside the ctrlrange
    with pytest.raises(NotImplementedHALError):
        await grip.set_value(1.0, Request.VELOCITY)
    assert suction.state is grip.state is ComponentState.ACTIVE


# -- completion from the physics ------------------------------------------------------------


async def test_adhesion_completes_when_the_force_acts_and_holds_through_contact(
    stack: AsyncExitStack,
) -> None:
    sim = _sim()
    await stack.enter_async_context(sim)
    events = EventRecorder(sim.clock)
    effector = sim.effector("suction", settle_s=0.0)
    suction = await _component(stack, effector, events)
    lift = await _component(stack, sim.actuator("lift"))  # type: ignore[arg-type]
    box = sim.data.body("box")
    with anyio.fail_after(20):
        # In the air: the force is applied (completion), but it holds nothing.
        motion = await suction.set_value(12.0, Request.TORQUE)
        assert not motion.done() and effector.pending  # nothing echoed: the physics decides
        await motion
        assert sim.time_ns == 1_000_000  # the next physics step computed the force
        assert await suction.get_value(Request.TORQUE_ACTUAL) == pytest.approx(12.0)
        assert effector.on and not effector.holding
        await suction.set_value(0.0, Request.NO_EXCITE)

        # Lowered onto the box: switching on makes it hold (HOLDING), the box comes up.
        await lift.set_value(-0.15)
        await sim.sleep(0.5)
        assert not effector.holding and events.count("event", MujocoEventId.HOLDING) == 0
        await (await suction.set_value(20.0, Request.TORQUE))
        await events.wait_for("event", MujocoEventId.HOLDING, source=suction)
        assert effector.holding
        await lift.set_value(-0.1)
        await sim.sleep(0.5)
        assert box.xpos[2] > 0.05  # lifted 3 cm and more

        # Off: RELEASED, the box drops back to the floor.
        await suction.set_value(0.0, Request.NO_EXCITE)
        await events.wait_for("event", MujocoEventId.RELEASED, source=suction)
        await sim.sleep(0.5)
    assert box.xpos[2] == pytest.approx(0.02, abs=1e-3)
    assert not effector.holding and effector.force == 0.0
    assert events.count("event", MujocoEventId.HOLDING) == 1
    assert events.count("event", MujocoEventId.RELEASED) == 1
    assert events.count("event", EventId.COMPLETED) == 4  # two forces, two NO_EXCITE


async def test_a_gripper_completes_only_where_the_physics_lets_it(stack: AsyncExitStack) -> None:
    sim = _sim(keyframe="ajar")
    grip_device = sim.effector("grip", position_tolerance=0.002, settle_velocity=0.01)
    assert grip_device.read_nowait(Request.POSITION_ACTUAL) == pytest.approx(0.02)
    assert sim.data.ctrl[grip_device.actuator_id] == pytest.approx(0.02)  # holds, no jump
    await stack.enter_async_context(sim)
    events = EventRecorder(sim.clock)
    grip = await _component(stack, grip_device, events)
    with anyio.fail_after(20):
        started = sim.time_ns
        await (await grip.set_value(0.04))  # free travel: reached
        assert sim.time_ns - started > 50_000_000  # it took the fingers a while
        assert await grip.get_value(Request.POSITION_ACTUAL) == pytest.approx(0.04, abs=0.002)

        # Closing fully: the fingers stop on the block at 0.07, the target stays pending and
        # the servo squeezes at its force limit (SATURATED).
        motion = await grip.set_value(0.1)
        await events.wait_for("event", MujocoEventId.SATURATED, source=grip)
        await sim.sleep(0.5)
        assert not motion.done() and grip_device.pending
        assert await grip.get_value(Request.POSITION_ACTUAL) == pytest.approx(0.07, abs=0.003)
        assert await grip.get_value(Request.TORQUE_ACTUAL) == pytest.approx(5.0)

        # NO_EXCITE disables the servo; the next target enables it again.
        await grip.set_value(0.0, Request.NO_EXCITE)
        await sim.sleep(0.01)
        assert not grip_device.enabled and grip_device.force == 0.0
        await (await grip.set_value(0.03))
        assert grip_device.enabled
    with pytest.raises(Exception, match=r"superseded|replaced"):
        await motion


async def test_a_filtered_force_completes_when_the_force_has_risen(stack: AsyncExitStack) -> None:
    sim = _sim()
    await stack.enter_async_context(sim)
    thrust = await _component(stack, sim.effector("thrust"))
    with anyio.fail_after(20):
        started = sim.time_ns
        await (await thrust.set_value(1.5, Request.TORQUE))
    # 20 ms filter: within 0.05 N of 1.5 N after ~ln(30) x 20 ms, then settle_s (20 ms)
    assert 80_000_000 <= sim.time_ns - started <= 100_000_000
    assert await thrust.get_value(Request.TORQUE_ACTUAL) == pytest.approx(1.5, abs=0.05)
    assert sim.data.qvel[sim.model.joint("sled").dofadr[0]] > 0.0  # pushed along +x


def test_nowait_paths_without_a_component() -> None:
    sim = _sim()
    thrust = sim.effector("thrust")
    thrust.command_nowait(Request.TORQUE, -1.0)
    assert sim.step(200) == 200
    assert thrust.read_nowait(Request.TORQUE_ACTUAL) == pytest.approx(-1.0, abs=1e-3)
    thrust.command_nowait(Request.NO_EXCITE, 0.0)
    assert sim.data.ctrl[thrust.actuator_id] == 0.0 and thrust.commands == 2


# -- faults, reset, lifecycle ---------------------------------------------------------------


async def test_a_fault_moves_the_effector_to_error_and_re_init_recovers(
    stack: AsyncExitStack,
) -> None:
    sim = _sim(keyframe="ajar")
    await stack.enter_async_context(sim)
    events = EventRecorder(sim.clock)
    thrust_device = sim.effector("thrust")
    thrust = await _component(stack, thrust_device, events)
    grip = await _component(stack, sim.effector("grip"), events)
    with anyio.fail_after(10):
        await sim.sleep(0.01)
        motion = await thrust.set_value(2.0, Request.TORQUE)
        sim.data.qvel[0] = np.nan  # something blew up
        with pytest.raises(DeviceFaultError, match="unstable"):
            await motion
        for component in (thrust, grip):
            await events.wait_for("error", ErrorId.DEVICE_ERROR, source=component)
    assert thrust.state is grip.state is ComponentState.ERROR
    with pytest.raises(HALError, match="faulted"):
        thrust_device.command_nowait(Request.TORQUE, 1.0)

    await thrust.re_init()  # resets the simulation: initial state, ctrl 0
    assert sim.fault is None and sim.resets == 1
    assert thrust.state is ComponentState.ACTIVE and grip.state is ComponentState.ERROR
    assert sim.data.ctrl[thrust_device.actuator_id] == 0.0
    assert sim.data.ctrl[sim.effectors["grip"].actuator_id] == pytest.approx(0.02)  # holds
    await grip.re_init()
    with anyio.fail_after(10):
        await (await thrust.set_value(1.0, Request.TORQUE))
        await (await grip.set_value(0.05))


async def test_closing_stops_the_effector(stack: AsyncExitStack) -> None:
    sim = _sim()
    await stack.enter_async_context(sim)
    suction = sim.effector("suction")
    async with Actuator(suction, clock=sim.clock) as component:
        await component.set_value(10.0, Request.TORQUE)
        assert suction.on
        with pytest.raises(HALError, match="already belongs"):
            async with Actuator(suction, clock=sim.clock):
                pass
    assert not suction.on  # closed: the adhesion is off
    async with Actuator(suction, clock=sim.clock):  # and the device is free again
        pass


# -- description ----------------------------------------------------------------------------


def test_effectors_round_trip_through_the_description(tmp_path: pathlib.Path) -> None:
    (tmp_path / "effectors.xml").write_text(EFFECTORS_XML)
    (tmp_path / "rig.yaml").write_text(
        "model: effectors.xml\n"
        "keyframe: ajar\n"
        "joints: [lift]\n"
        "effectors:\n"
        "  - suction\n"
        "  - {actuator: grip, name: gripper, position_tolerance: 0.002}\n"
        "  - {actuator: thrust, torque_tolerance: 0.01, settle_s: 0}\n"
    )
    desc = SimDescription.from_yaml(tmp_path / "rig.yaml")
    assert desc.effectors == (
        EffectorSpec("suction"),
        EffectorSpec("grip", name="gripper", position_tolerance=0.002),
        EffectorSpec("thrust", torque_tolerance=0.01, settle_s=0),
    )
    data = desc.to_dict()
    assert data["effectors"] == [
        "suction",
        {"actuator": "grip", "name": "gripper", "position_tolerance": 0.002},
        {"actuator": "thrust", "torque_tolerance": 0.01, "settle_s": 0},
    ]
    assert SimDescription.from_dict(yaml.safe_load(yaml.safe_dump(data))) == desc
    assert "effectors" not in SimDescription("arm2").to_dict()

    sim = MujocoSim.from_description(desc)
    assert list(sim.effectors) == ["suction", "gripper", "thrust"]
    assert sim.effector("grip") is sim.effectors["gripper"]  # found by actuator name too
    assert sim.effectors["gripper"].spec.position_tolerance == 0.002
    assert list(sim.joints) == ["lift"]

    arm6 = MujocoSim.from_description({"model": "arm6", "effectors": ["suction"]})
    assert arm6.effectors["suction"].kind == "adhesion"


def test_description_errors_name_the_field() -> None:
    with pytest.raises(BadParameterError, match=r"effectors\[\]\.gain"):
        SimDescription.from_dict({"model": "arm6", "effectors": [{"actuator": "x", "gain": 1}]})
    with pytest.raises(BadParameterError, match=r"effectors\[\]\.actuator"):
        SimDescription.from_dict({"model": "arm6", "effectors": [{"name": "x"}]})
    with pytest.raises(BadParameterError, match="effectors"):
        SimDescription.from_dict({"model": "arm6", "effectors": "suction"})
    with pytest.raises(BadParameterError, match="unique names"):
        SimDescription.from_dict({"model": "arm6", "effectors": ["suction", "suction"]})
    with pytest.raises(BadParameterError, match=r"EffectorSpec\.settle_s"):
        SimDescription.from_dict(
            {"model": "arm6", "effectors": [{"actuator": "suction", "settle_s": -1}]}
        )
    with pytest.raises(ModelLoadError, match="unknown actuator 'suktion'"):
        MujocoSim.from_description({"model": "arm6", "effectors": ["suktion"]})
    with pytest.raises(BadParameterError, match="shoulder_pitch"):
        MujocoSim.from_description({"model": "arm6", "effectors": ["shoulder_pitch_pos"]})


def test_the_docs_example_runs(capsys: pytest.CaptureFixture[str]) -> None:
    doc = pathlib.Path(__file__).resolve().parents[2] / "docs" / "mujoco.md"
    section = doc.read_text().split("## 11. Effectors", 1)[1]
    block = re.findall(r"^```python\n(.*?)^```$", section, flags=re.M | re.S)[0]
    exec(block, {"__name__": "docs_mujoco_effectors"})
    printed = [line for line in capsys.readouterr().out.splitlines() if "[" not in line]
    assert printed == ["15.0", "False"]  # (the log lines aside)
