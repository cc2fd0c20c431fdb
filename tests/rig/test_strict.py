"""Strict rig files (issue 21, points 1 and 5): unknown keys at every level are refused
with the file, line and column and a "did you mean"; a YAML syntax error names the rig
file (not ``<unicode string>``)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from openel_async.errors import BadParameterError
from openel_async.rig import build_components, load_rig, parse_rig

RIG = """\
namespace: lab
components:
  - name: MOTOR_1
    driver: sim
    device: motor
    params: {max_velocity: 3.0}
    hal_id: {vendor_id: 0xE1, product_id: 0x100, instance_id: 1}
  - name: ENCODER_1
    driver: sim
    device: encoder
    params: {motor: {ref: MOTOR_1}}
"""


def _refused(tmp_path: Path, text: str) -> BadParameterError:
    rig = tmp_path / "rig.yaml"
    rig.write_text(text)
    with pytest.raises(BadParameterError) as info:
        build_components(load_rig(rig))
    return info.value


def test_the_base_rig_loads(tmp_path: Path) -> None:
    rig = tmp_path / "rig.yaml"
    rig.write_text(RIG)
    spec = load_rig(rig)
    assert spec.namespace == "lab"
    assert [c.name for c in spec.components] == ["MOTOR_1", "ENCODER_1"]
    assert spec.components[0].hal_id == {"vendor_id": 0xE1, "product_id": 0x100, "instance_id": 1}
    assert len(build_components(spec)) == 2


@pytest.mark.parametrize(
    ("wrong", "right", "line", "column", "where"),
    [
        ("namespce", "namespace", 1, 1, "in rig "),
        ("devce", "device", 5, 5, "in rig.components[0] "),
        ("vendor", "vendor_id", 7, 14, "in rig.components[0].hal_id "),
        ("max_velocty", "max_velocity", 6, 14, "in MOTOR_1.params (arguments of SimMotor) "),
    ],
)
def test_an_unknown_key_is_refused_with_position_and_suggestion(
    tmp_path: Path, wrong: str, right: str, line: int, column: int, where: str
) -> None:
    error = _refused(tmp_path, RIG.replace(f"{right}:", f"{wrong}:", 1))
    text = str(error)
    assert text.startswith(f"{tmp_path / 'rig.yaml'}:{line}:{column}: unknown key {wrong!r} ")
    assert where in text
    assert f"did you mean {right!r}?" in text
    assert getattr(error, "line") == line and getattr(error, "column") == column  # noqa: B009


def test_an_unknown_top_level_key_far_from_any_is_refused(tmp_path: Path) -> None:
    text = str(_refused(tmp_path, RIG + "colour: blue\n"))
    assert (
        ":12:1: unknown key 'colour' in rig (allowed: buses, components, description, groups, namespace, safety, timers)"
        in text
    )


def test_other_mistakes_are_located_too(tmp_path: Path) -> None:
    text = str(_refused(tmp_path, RIG.replace("name: ENCODER_1", "name: MOTOR_1")))
    assert ":8:11:" in text and "unique names ('MOTOR_1' twice)" in text
    text = str(_refused(tmp_path, RIG.replace("name: MOTOR_1", "name: 7")))
    assert ":3:11: rig.components[0].name: Expected 'str', got 'int'" in text
    text = str(_refused(tmp_path, RIG.replace("{ref: MOTOR_1}", "{ref: NOPE}")))
    assert ":11:14:" in text and "ENCODER_1.params.motor" in text


def test_a_yaml_syntax_error_names_the_rig_file(tmp_path: Path) -> None:
    text = str(_refused(tmp_path, RIG.replace("params: {max_velocity: 3.0}", "params: {max")))
    assert text.startswith(f"{tmp_path / 'rig.yaml'}:")
    assert "invalid YAML" in text
    assert "<unicode string>" not in text


def test_plain_data_is_strict_without_positions() -> None:
    data = yaml.safe_load(RIG)
    data["colour"] = "blue"
    with pytest.raises(BadParameterError, match=r"^unknown key 'colour' in rig \(allowed"):
        parse_rig(data)


def test_serve_names_the_file_line_and_column(tmp_path: Path) -> None:
    pytest.importorskip("zenoh")
    rig = tmp_path / "rig.yaml"
    rig.write_text(RIG.replace("namespace:", "namespce:"))
    run = subprocess.run(
        [sys.executable, "-m", "openel_async.cli", "serve", str(rig)],
        capture_output=True,
        text=True,
        timeout=60,
        stdin=subprocess.DEVNULL,
    )
    assert run.returncode == 2, run.stderr
    assert f"{rig}:1:1: unknown key 'namespce' in rig (did you mean 'namespace'?" in run.stderr


def test_a_rig_builds_each_device_as_the_component_class_of_its_kind(tmp_path: Path) -> None:
    """A device with its own sensor (the pan-tilt head) becomes a SensingMotor, so the surface
    serves its sensor operations (a plain Motor answered them HAL_NOT_IMPLEMENTED)."""
    from openel_async import Encoder, Motor, SensingMotor

    rig = tmp_path / "rig.yaml"
    rig.write_text(RIG + "  - name: HEAD\n    driver: sim\n    device: pan_tilt_head\n")
    built = {c.device_name: c for c in build_components(load_rig(rig))}
    assert type(built["MOTOR_1"]) is Motor
    assert isinstance(built["ENCODER_1"], Encoder)
    assert type(built["HEAD"]) is SensingMotor
