"""The declarative mapping (SimDescription) and the TrajectoryRecorder."""

from __future__ import annotations

import csv
import math
import pathlib
from contextlib import AsyncExitStack

import anyio
import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from openel_async import Actuator, BadParameterError, Request
from openel_mujoco import (
    JointSpec,
    MujocoSim,
    SensorSpec,
    SimDescription,
    TrajectoryRecorder,
)
from openel_mujoco.models import MODELS_DIR

from .conftest import start_rig

YAML = """
model: arm6
pacing: lockstep
keyframe: home
joints:
  - base_yaw
  - {joint: shoulder_pitch, max_velocity: 2.0, position_tolerance: 0.005}
  - {joint: wrist_roll, name: roll, mode: velocity}
sensors:
  - imu_acc
  - {sensor: wrist_force, name: ft}
extra: {owner: demo}
"""


def test_description_round_trips_through_yaml(tmp_path: pathlib.Path) -> None:
    path = tmp_path / "rig.yaml"
    path.write_text(YAML)
    desc = SimDescription.from_yaml(path)
    assert desc.model == "arm6" and desc.keyframe == "home"
    assert desc.joints[0] == JointSpec("base_yaw")
    assert desc.joints[1].max_velocity == 2.0 and desc.joints[1].position_tolerance == 0.005
    assert desc.joints[2].key == "roll" and desc.joints[2].mode == "velocity"
    assert desc.sensors == (SensorSpec("imu_acc"), SensorSpec("wrist_force", name="ft"))
    data = desc.to_dict()
    assert data["joints"][0] == "base_yaw" and data["sensors"][0] == "imu_acc"
    assert SimDescription.from_dict(yaml.safe_load(yaml.safe_dump(data))) == desc

    sim = MujocoSim.from_description(desc)
    assert list(sim.joints) == ["base_yaw", "shoulder_pitch", "roll"]
    assert list(sim.sensors) == ["imu_acc", "ft"]
    assert sim.joints["shoulder_pitch"].limits.velocity == 2.0
    assert sim.joints["roll"].control_mode is Request.VELOCITY
    assert sim.joints["base_yaw"].control_mode is Request.POSITION
    assert sim.sensors["ft"].units == ("N",) * 3
    assert sim.actuator("wrist_roll") is sim.joints["roll"]  # found by joint name too


def test_relative_model_path_resolves_against_the_yaml_file(tmp_path: pathlib.Path) -> None:
    (tmp_path / "models").mkdir()
    (tmp_path / "models" / "arm.xml").write_text((MODELS_DIR / "arm2.xml").read_text())
    (tmp_path / "rig.yaml").write_text("model: models/arm.xml\njoints: [elbow]\n")
    desc = SimDescription.from_yaml(tmp_path / "rig.yaml")
    assert desc.model == str(tmp_path / "models" / "arm.xml")
    sim = MujocoSim.from_description(desc, realtime_factor=1.0)
    assert "elbow" in sim.joints


async def test_description_built_sim_runs(stack: AsyncExitStack) -> None:
    sim = MujocoSim.from_description(
        {"model": "arm2", "joints": [{"joint": "elbow", "settle_s": 0.05}], "sensors": ["tip_pos"]}
    )
    await stack.enter_async_context(sim)
    elbow = await stack.enter_async_context(Actuator(sim.joints["elbow"], clock=sim.clock))
    with anyio.fail_after(10):
        motion = await elbow.set_value(-0.7)
        await motion
    assert sim.joints["elbow"].position == pytest.approx(-0.7, abs=0.01)


async def test_trajectory_recorder_samples_plots_and_writes_csv(
    stack: AsyncExitStack, tmp_path: pathlib.Path
) -> None:
    sim = MujocoSim("arm2")
    rig = await start_rig(stack, sim, ("shoulder", "elbow"))
    recorder = TrajectoryRecorder(sim, ["shoulder", "elbow"], every=10)
    with anyio.fail_after(10):
        with recorder:
            motion = await rig.actuators["shoulder"].set_value(0.6)
            await rig.actuators["elbow"].set_value(0.4, Request.VELOCITY)
            await motion
            await rig.actuators["elbow"].set_value(0.2)
            await sim.sleep(0.3)
        samples = len(recorder)
        await sim.sleep(0.1)  # detached: no more samples
    assert len(recorder) == samples
    t, commanded, actual = recorder.arrays()
    assert t.shape == (samples,) and commanded.shape == actual.shape == (samples, 2)
    assert np.all(np.diff(t) == pytest.approx(0.01))  # every 10 steps of 1 ms
    assert t[0] == 0.0
    assert commanded[-1, 0] == 0.6 and actual[-1, 0] == pytest.approx(0.6, abs=0.01)
    assert np.isnan(commanded[5, 1])  # velocity mode: no commanded position
    assert commanded[-1, 1] == 0.2
    assert np.all(np.isfinite(actual))
    csv_path = recorder.to_csv(tmp_path / "out" / "traj.csv")
    rows = list(csv.reader(csv_path.open()))
    assert rows[0] == ["t", "shoulder_cmd", "shoulder_actual", "elbow_cmd", "elbow_actual"]
    assert len(rows) == samples + 1 and float(rows[-1][1]) == 0.6
    png = recorder.plot(tmp_path / "out" / "traj.png", title="arm2")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_recorder_limits_and_manual_sampling() -> None:
    sim = MujocoSim("arm2")
    recorder = TrajectoryRecorder(sim, ["elbow"], max_samples=3)
    for _ in range(5):
        sim.step(2)
        recorder.sample()
    assert len(recorder) == 3 and recorder.dropped == 2
    assert list(recorder.times) == pytest.approx([0.002, 0.004, 0.006])
    assert not math.isnan(recorder.commanded[0, 0])  # position mode at start: holding 0
    with pytest.raises(ValueError, match="every"):
        TrajectoryRecorder(sim, ["elbow"], every=0)
    with pytest.raises(ValueError, match="joints"):
        TrajectoryRecorder(MujocoSim("arm2"))  # nothing mapped yet


async def test_a_failing_step_hook_is_dropped_not_fatal(stack: AsyncExitStack) -> None:
    sim = MujocoSim("arm2")
    await stack.enter_async_context(sim)
    calls: list[int] = []

    def broken() -> None:
        calls.append(sim.steps)
        raise RuntimeError("hook bug")

    sim.add_step_hook(broken)
    with anyio.fail_after(10):
        await sim.sleep(0.01)
    assert len(calls) == 1 and sim.steps >= 10 and sim.fault is None


# -- bad descriptions: BadParameterError naming the field or the file, nothing raw ----------


@pytest.mark.parametrize(
    ("raw", "match"),
    [
        (b"model: arm2\nextra:\n", r"extra=None .*a mapping of application data"),
        (b"model: arm2\nextra: [1, 2]\n", r"extra=\[1, 2\] .*a mapping"),
        (b"?", r"description\.None=None .*a known field"),
        (b"model: arm2\n1: 2\n", r"description\.1=2 .*a known field"),
        (
            b"model: arm2\njoints: [{joint: a, position_limits: 5}]\n",
            r"position_limits=5 .*\(low, high\) pair",
        ),
        (
            b"model: arm2\njoints: [{joint: a, position_limits: [0, 1e999]}]\n",
            r"position_limits=.* finite numbers",
        ),
        (b"model: arm2\nsensors: [{sensor: s, units: 5}]\n", r"units=5 .*unit strings"),
        (b"model: arm2\nsensors: [{sensor: s, units: {a: b}}]\n", r"units=\{'a': 'b'\}"),
        (b"model: arm2\ntimestep: " + b"9" * 400 + b"\n", r"SimDescription\.timestep=9+ "),
        (b"model: arm2\nname: 5\n", r"name=5 .*non-empty string"),
        (
            b"model: [arm2\n",
            r"^\S*rig\.yaml:2:1: path=.*a YAML file \(did not find expected ','.* "
            r"flow sequence started at line 1, column 8\)",
        ),
        (b"model: arm2\n  pacing: lockstep\n", r"^\S*rig\.yaml:2:9: path=.*a YAML file \(mapping"),
        (b"model: \xff\xfe\n", r"a UTF-8 text file \(byte 0xff at offset 7"),
        (b"model: arm2\nkeyframe: 2020-13-45\n", r"a YAML file \(month must be in 1\.\.12\)"),
        (b"- arm2\n", r"a YAML file holding a mapping \(it holds a list\)"),
        (b"", r"a YAML file holding a mapping \(it holds nothing\)"),
        (b"model: ~nosuchuser_h15/x.xml\n", r"model='~nosuchuser_h15/x\.xml' .*file path"),
    ],
)
def test_bad_yaml_raises_bad_parameter(tmp_path: pathlib.Path, raw: bytes, match: str) -> None:
    path = tmp_path / "rig.yaml"
    path.write_bytes(raw)
    with pytest.raises(BadParameterError, match=match):
        SimDescription.from_yaml(path)


def test_a_refused_list_entry_is_named_by_its_index() -> None:
    with pytest.raises(BadParameterError, match="units") as info:
        SimDescription.from_dict(
            {"model": "arm2", "sensors": ["tip_pos", {"sensor": "s", "units": 5}]}
        )
    assert info.value.__notes__ == ["in sensors[1]"]
    with pytest.raises(BadParameterError, match="max_velocity") as info:
        SimDescription.from_dict(
            {"model": "arm2", "joints": ["a", "b", {"joint": "c", "max_velocity": -1}]}
        )
    assert info.value.__notes__ == ["in joints[2]"]


def test_an_unreadable_file_names_its_path(tmp_path: pathlib.Path) -> None:
    with pytest.raises(BadParameterError, match=r"path=.*missing\.yaml.*readable YAML file"):
        SimDescription.from_yaml(tmp_path / "missing.yaml")
    with pytest.raises(BadParameterError, match=r"readable YAML file"):
        SimDescription.from_yaml(tmp_path)  # a directory


# -- fuzzing the loader: only a description or BadParameterError ever comes out ------------

FUZZ = settings(
    max_examples=80,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[
        HealthCheck.function_scoped_fixture,  # one file, rewritten by every example
        HealthCheck.too_slow,
        HealthCheck.data_too_large,
    ],
)

FIELDS = [
    "model", "joints", "sensors", "effectors", "pacing", "keyframe", "timestep", "name", "extra",
    "joint", "sensor", "actuator", "mode", "actuators", "position_limits", "max_velocity",
    "max_torque", "kp", "kd", "kv", "position_tolerance", "settle_velocity",
    "velocity_tolerance", "torque_tolerance", "settle_s", "limit_margin", "kind", "units",
    "touch_sensor", "hold_force", "position", "velocity", "torque", "lockstep", "realtime",
]  # fmt: skip
SCALARS = st.one_of(  # hashable: they are dict keys too
    st.none(),
    st.booleans(),
    st.integers(),
    st.integers(min_value=10**300, max_value=10**400),  # beyond the float range
    st.floats(),  # nan and +-inf included
    st.sampled_from([*FIELDS, "arm2", "arm6", "", "~", "~nosuchuser_h15/m.xml", "m.xml"]),
    st.text(max_size=8),
)
VALUES = st.recursive(
    SCALARS,
    lambda inner: (
        st.lists(inner, max_size=4)
        | st.dictionaries(st.sampled_from(FIELDS) | SCALARS, inner, max_size=5)
    ),
    max_leaves=20,
)


NUMBER = st.floats(0.001, 10.0)
NAME = st.text(min_size=1, max_size=6)
GOOD: dict[str, st.SearchStrategy[object]] = {
    "pacing": st.sampled_from(["lockstep", "realtime"]),
    "keyframe": st.sampled_from(["home", None]),
    "timestep": st.floats(1e-4, 0.01),
    "name": NAME,
    "extra": st.dictionaries(NAME, VALUES, max_size=3),
    "mode": st.sampled_from(["position", "velocity", "torque", None]),
    "actuators": st.dictionaries(st.sampled_from(["position", "velocity", "torque"]), NAME),
    "position_limits": st.tuples(st.floats(-3, -0.1), st.floats(0.1, 3)).map(list),
    "kind": st.integers(0, 2**16) | st.sampled_from(["gyro", "Encoder", "direction", "ACCEL"]),
    "units": st.lists(st.sampled_from(["m", "rad", "N", "m/s^2"]), max_size=3),
    "touch_sensor": NAME,
    "settle_s": st.floats(0.0, 1.0),
}
ENTRIES = {  # list field: (name field, names in arm2/arm6, the other fields of its spec)
    "joints": (
        "joint",
        ["shoulder", "elbow"],
        ["name", "mode", "actuators", "position_limits", "max_velocity", "max_torque", "kp",
         "kd", "kv", "position_tolerance", "settle_velocity", "velocity_tolerance",
         "torque_tolerance", "settle_s", "limit_margin"],
    ),
    "sensors": ("sensor", ["tip_pos"], ["name", "kind", "units"]),
    "effectors": (
        "actuator",
        ["suction"],
        ["name", "position_tolerance", "settle_velocity", "velocity_tolerance",
         "torque_tolerance", "settle_s", "touch_sensor", "hold_force"],
    ),
}  # fmt: skip


def _mostly_good(draw: st.DrawFn, field: str) -> object:
    """A value the field accepts, three times in four; anything at all otherwise."""
    if draw(st.integers(0, 3)) == 3:
        return draw(VALUES)
    return draw(GOOD.get(field, NUMBER))


@st.composite
def descriptions(draw: st.DrawFn) -> dict[object, object]:
    """Mostly well-formed descriptions with a few bad values, unknown or missing keys: the
    checks of every field are reached, not only the first one."""
    data: dict[object, object] = {}
    if draw(st.integers(0, 15)) != 15:
        data["model"] = (
            draw(st.sampled_from(["arm2", "arm6"]))
            if draw(st.integers(0, 3)) != 3
            else draw(VALUES)
        )
    for key in draw(st.lists(st.sampled_from(FIELDS[1:9]), max_size=8, unique=True)):
        if key not in ENTRIES or draw(st.integers(0, 7)) == 7:
            data[key] = _mostly_good(draw, key)
            continue
        name_field, names, others = ENTRIES[key]
        entries: list[object] = []
        for _ in range(draw(st.integers(0, 3))):
            name = draw(st.sampled_from(names)) if draw(st.integers(0, 7)) != 7 else draw(VALUES)
            if draw(st.booleans()):
                entries.append(name)  # a name alone
                continue
            entry = {name_field: name}
            for other in draw(st.lists(st.sampled_from(others), max_size=4, unique=True)):
                entry[other] = _mostly_good(draw, other)
            if draw(st.integers(0, 7)) == 7:
                entry[draw(SCALARS)] = draw(VALUES)  # maybe an unknown field
            entries.append(entry)
        data[key] = entries
    if draw(st.integers(0, 7)) == 7:
        data[draw(SCALARS)] = draw(VALUES)  # maybe an unknown key
    return data


def _load(path: pathlib.Path, raw: bytes) -> None:
    path.write_bytes(raw)
    try:
        desc = SimDescription.from_yaml(path)
    except BadParameterError as exc:
        assert str(exc)  # names the field or the path
        return
    assert isinstance(desc, SimDescription)
    assert SimDescription.from_dict(desc.to_dict()) == desc  # what loads, round-trips


@FUZZ
@given(data=descriptions())
def test_fuzz_description_dicts(data: dict[object, object]) -> None:
    try:
        desc = SimDescription.from_dict(data)
    except BadParameterError:
        return
    assert SimDescription.from_dict(desc.to_dict()) == desc


@FUZZ
@given(data=descriptions())
def test_fuzz_description_yaml_files(tmp_path: pathlib.Path, data: dict[object, object]) -> None:
    raw = yaml.safe_dump(data, allow_unicode=True, sort_keys=False).encode()
    _load(tmp_path / "rig.yaml", raw)


@FUZZ
@given(
    cut=st.integers(0, len(YAML)),
    drop=st.integers(0, 8),
    insert=st.binary(max_size=8)
    | st.sampled_from([b"?", b":", b"[", b"{", b"- ", b"\n  ", b"\xff", b"!!", b"&a", b"*a", b"#"]),
)
def test_fuzz_mutated_yaml_files(
    tmp_path: pathlib.Path, cut: int, drop: int, insert: bytes
) -> None:
    raw = YAML.encode()
    _load(tmp_path / "rig.yaml", raw[:cut] + insert + raw[cut + drop :])


@FUZZ
@given(raw=st.binary(max_size=64) | st.text(max_size=64).map(str.encode))
def test_fuzz_arbitrary_bytes(tmp_path: pathlib.Path, raw: bytes) -> None:
    _load(tmp_path / "rig.yaml", raw)
