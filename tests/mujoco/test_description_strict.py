"""Strict MuJoCo descriptions (issue 21, point 1): an unknown key is refused with a
"did you mean"; read from a file, every refusal starts with FILE:LINE:COL."""

from __future__ import annotations

import pathlib

import pytest

from openel_async import BadParameterError
from openel_mujoco import SimDescription

DESCRIPTION = """\
model: arm2
pacing: lockstep
joints:
  - shoulder
  - {joint: elbow, max_velocity: 2.0}
sensors:
  - {sensor: tip_pos, name: tip}
"""


def _refused(tmp_path: pathlib.Path, text: str) -> BadParameterError:
    path = tmp_path / "arm.yaml"
    path.write_text(text)
    with pytest.raises(BadParameterError) as info:
        SimDescription.from_yaml(path)
    return info.value


def test_the_base_description_loads(tmp_path: pathlib.Path) -> None:
    path = tmp_path / "arm.yaml"
    path.write_text(DESCRIPTION)
    desc = SimDescription.from_yaml(path)
    assert [j.key for j in desc.joints] == ["shoulder", "elbow"]


@pytest.mark.parametrize(
    ("old", "new", "line", "column", "suggestion"),
    [
        ("pacing:", "pacng:", 2, 1, "pacing"),
        ("max_velocity:", "max_velocty:", 5, 20, "max_velocity"),
        ("name: tip", "nme: tip", 7, 23, "name"),
    ],
)
def test_an_unknown_key_is_refused_with_position_and_suggestion(
    tmp_path: pathlib.Path, old: str, new: str, line: int, column: int, suggestion: str
) -> None:
    error = _refused(tmp_path, DESCRIPTION.replace(old, new))
    text = str(error)
    assert text.startswith(f"{tmp_path / 'arm.yaml'}:{line}:{column}: ")
    assert f"did you mean {suggestion!r}?" in text
    assert "a known field" in text


def test_a_bad_value_in_a_list_entry_is_located(tmp_path: pathlib.Path) -> None:
    text = str(_refused(tmp_path, DESCRIPTION.replace("max_velocity: 2.0", "max_velocity: -2")))
    assert text.startswith(f"{tmp_path / 'arm.yaml'}:5:34: JointSpec.max_velocity=-2")


def test_duplicate_keys_are_refused(tmp_path: pathlib.Path) -> None:
    text = str(_refused(tmp_path, DESCRIPTION + "pacing: realtime\n"))
    assert ":8:1:" in text and "duplicate key 'pacing'" in text


def test_from_dict_suggests_too() -> None:
    with pytest.raises(BadParameterError, match=r"did you mean 'keyframe'\?"):
        SimDescription.from_dict({"model": "arm2", "keyfrme": "home"})
