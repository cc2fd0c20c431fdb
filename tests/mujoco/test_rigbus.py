"""The ``mujoco`` bus kind: strict options, ``rig check`` against the model, a rig opened on a
shipped model (its clock, a joint moved, limits), and a rig opened on a simulation built
beforehand."""

from __future__ import annotations

from pathlib import Path

import anyio
import msgspec
import pytest

from openel_async import BadParameterError, Request
from openel_async.registry import discover_drivers
from openel_async.rig import load_rig, open_rig, resolve_rig
from openel_mujoco import (
    DRIVER,
    AttachedSimulation,
    JointSpec,
    MujocoBusKind,
    MujocoBusOptions,
    MujocoEffector,
    MujocoJoint,
    MujocoSensor,
    MujocoSim,
    mujoco_buses,
    with_simulation,
)

RIG = """\
description: the arm2 model
namespace: arm2
buses:
  arm: {type: mujoco, model: arm2, pacing: lockstep}
components:
  - {name: shoulder, driver: mujoco, device: joint, bus: arm}
  - name: elbow
    driver: mujoco
    device: joint
    bus: arm
    params: {position_tolerance: 0.002}
    limits: {position: [-1.0, 1.0]}
  - {name: tip, driver: mujoco, device: sensor, bus: arm, params: {sensor: tip_pos}}
timers:
  sync: {period_ms: 2}
groups:
  arm: {axes: [shoulder, elbow], timer: sync, limits: {max_velocity: 2, max_acceleration: 10, max_jerk: 100}}
safety: {on_exit: hold}
"""


def _write(tmp_path: Path, text: str = RIG) -> Path:
    path = tmp_path / "rig.yaml"
    path.write_text(text)
    return path


def _refused(tmp_path: Path, old: str, new: str) -> str:
    """The refusal of ``RIG`` with ``old`` replaced by ``new`` (everywhere)."""
    assert old in RIG
    with pytest.raises(BadParameterError) as info:
        resolve_rig(load_rig(_write(tmp_path, RIG.replace(old, new))))
    return str(info.value)


def test_the_driver_registers_the_bus_kind() -> None:
    entries = {e.name: e.info for e in discover_drivers()}
    assert entries["mujoco"] is DRIVER
    assert isinstance(DRIVER.buses["mujoco"], MujocoBusKind)


def test_options_are_strict_and_documented() -> None:
    def convert(data: dict[str, object]) -> MujocoBusOptions:
        return msgspec.convert(data, MujocoBusOptions)

    options = convert({"model": "arm6", "keyframe": "home", "pacing": "realtime"})
    assert options.sim_arguments() == {"keyframe": "home"}  # only what is given
    assert convert({"model": "arm2"}).pacing == "lockstep"  # MujocoSim's default
    for bad in (
        {"model": "arm2", "keyfram": "home"},  # unknown key
        {"model": "arm2", "pacing": "fast"},
        {"model": "arm2", "timestep": 0},
        {"model": "arm2", "max_catchup_steps": 0},
        {"pacing": "lockstep"},  # no model
    ):
        with pytest.raises(msgspec.ValidationError):
            convert(bad)
    from openel_async.cli.rig_cmd import field_docs

    docs = field_docs(MujocoBusOptions)
    assert set(docs) == set(MujocoBusOptions.__struct_fields__)  # `rig schema` describes all


def test_describe_says_what_opens() -> None:
    kind = DRIVER.buses["mujoco"]
    assert kind.describe(MujocoBusOptions(model="arm2")) == "MuJoCo model arm2 (lockstep)"
    assert (
        kind.describe(MujocoBusOptions(model="arm6", keyframe="home", pacing="realtime"))
        == "MuJoCo model arm6, keyframe home (realtime)"
    )
    sim = MujocoSim("arm2", pacing="realtime")  # an attached simulation: its own pacing
    attached = AttachedSimulation(MujocoBusOptions(model="arm2"), sim)
    assert kind.describe(attached) == "MuJoCo model arm2 (realtime)"


def test_rig_check_builds_every_device_on_the_model(tmp_path: Path) -> None:
    resolved = resolve_rig(load_rig(_write(tmp_path)))
    assert resolved.classes["tip"] is MujocoSensor
    assert mujoco_buses(resolved) == {"arm": MujocoBusOptions(model="arm2")}
    assert "expected a model that loads (unknown model 'arm9'" in _refused(
        tmp_path, "model: arm2", "model: arm9"
    )
    assert "keyframe='home' is not allowed: expected a keyframe of model arm2" in _refused(
        tmp_path, "pacing: lockstep}", "pacing: lockstep, keyframe: home}"
    )
    text = _refused(tmp_path, "shoulder", "shouldr")  # the joint of its name
    assert "shouldr.params={} is not allowed: expected a joint of MuJoCo model arm2" in text
    text = _refused(tmp_path, "position_tolerance", "position_tolerence")
    assert "did you mean 'position_tolerance'" in text
    text = _refused(tmp_path, "device: sensor", "device: gyro")
    assert "expected a gyro of MuJoCo model arm2" in text
    text = _refused(tmp_path, "params: {sensor: tip_pos}", "params: {sensor: tip_pos, name: x}")
    assert "no 'name': the bus arm gives it" in text  # the component's name is the device's
    text = _refused(tmp_path, "{name: shoulder,", "{name: shoulder, params: {joint: elbow},")
    assert "a joint not mapped yet" in text  # two components on one joint


def test_a_device_takes_a_spec_or_its_fields() -> None:
    sim = MujocoSim("arm6", keyframe="home")
    joint = MujocoJoint(sim, name="yaw", joint="base_yaw", max_velocity=1.0)
    assert joint.spec == JointSpec("base_yaw", name="yaw", max_velocity=1.0)
    assert MujocoJoint(sim, name="elbow_pitch").joint == "elbow_pitch"  # from its name
    assert MujocoJoint(sim, "wrist_roll", name="roll").name == "roll"
    assert MujocoEffector(sim, name="suction").actuator == "suction"
    with pytest.raises(BadParameterError, match="give either a spec or its fields"):
        MujocoJoint(sim, "flange_roll", max_velocity=1.0)


async def test_a_rig_runs_the_model_on_its_clock_and_moves_a_joint(tmp_path: Path) -> None:
    spec = load_rig(_write(tmp_path))
    with anyio.fail_after(20):
        async with open_rig(spec) as rig:
            sim = rig.buses["arm"]
            assert isinstance(sim, MujocoSim) and sim.running
            assert rig.clock is sim.clock  # the components and timers run on the simulation
            assert rig.timer("sync").clock is sim.clock
            assert rig.bus_descriptions == {"arm": "MuJoCo model arm2 (lockstep)"}
            shoulder, elbow = rig.actuators
            assert isinstance(shoulder.device, MujocoJoint) and shoulder.device.sim is sim
            assert elbow.device.spec.position_tolerance == 0.002  # type: ignore[attr-defined]
            t0 = sim.time_ns
            await (await shoulder.set_value(0.5, Request.POSITION))  # COMPLETED by the physics
            assert sim.time_ns > t0
            assert await shoulder.get_value(Request.POSITION_ACTUAL) == pytest.approx(0.5, abs=0.02)
            with pytest.raises(BadParameterError):  # the rig's limit, on top of the model's
                await elbow.set_value(1.5, Request.POSITION)
            x, y, _ = await rig.sensor("tip").get_value()
            assert (x, y) != pytest.approx((0.55, 0.0), abs=1e-3)  # it moved off +x
            motion = await rig.group("arm").move_to([0.0, 0.3])
            await motion
    assert not sim.running  # closed with the rig
    assert [r.component for r in rig.exit_report] == ["shoulder", "elbow"]
    assert all(r.ok for r in rig.exit_report)


async def test_sim_changes_nothing_on_a_mujoco_bus(tmp_path: Path) -> None:
    with anyio.fail_after(20):
        async with open_rig(load_rig(_write(tmp_path)), sim=True, init=False) as rig:
            assert isinstance(rig.buses["arm"], MujocoSim)
            assert rig.bus_descriptions["arm"].endswith("a simulation already")


async def test_a_rig_opens_on_a_simulation_built_beforehand(tmp_path: Path) -> None:
    resolved = resolve_rig(load_rig(_write(tmp_path)))
    options = mujoco_buses(resolved)["arm"]
    sim = MujocoSim(options.model, pacing="lockstep", **options.sim_arguments())
    with anyio.fail_after(20):
        async with open_rig(with_simulation(resolved, sim)) as rig:
            assert rig.buses["arm"] is sim and sim.running
            assert rig.clock is sim.clock
            assert list(sim.joints) == ["shoulder", "elbow"] and list(sim.sensors) == ["tip"]
    assert not sim.running
    with pytest.raises(BadParameterError, match="a MuJoCo bus of the rig"):
        with_simulation(resolved, sim, "can0")
