"""Strict system files (issue 21, point 1): an unknown key anywhere is refused with the
file, line and column and a "did you mean"; the loader's other refusals are located."""

from __future__ import annotations

from pathlib import Path

import pytest

from openel_async.rtc.system import SystemFileError, load_system

SYSTEM = """\
system:
  name: S
  components:
    sensor:
      profile: sensor.yaml
    controller:
      profile: controller.yaml
      context: {type: periodic, rate: 100}
  connections:
    - from: sensor.out
      to: controller.in
      properties: {dataport.buffer.length: 1}
  services:
    - [controller.head, sensor.head]
"""


def _load(tmp_path: Path, text: str) -> SystemFileError:
    path = tmp_path / "system.yaml"
    path.write_text(text)
    with pytest.raises(SystemFileError) as info:
        load_system(path)
    return info.value


def test_the_base_file_loads(tmp_path: Path) -> None:
    path = tmp_path / "system.yaml"
    path.write_text(SYSTEM)
    spec = load_system(path)
    assert [c.name for c in spec.components] == ["sensor", "controller"]


@pytest.mark.parametrize(
    ("old", "new", "line", "column", "message"),
    [
        ("  name: S", "  nme: S", 2, 3, "unknown key 'nme' in system (did you mean 'name'?"),
        (
            "      profile: controller.yaml",
            "      profle: controller.yaml",
            7,
            7,
            "unknown key 'profle' in system.components.controller (did you mean 'profile'?",
        ),
        (
            "{type: periodic, rate: 100}",
            "{type: periodic, rte: 100}",
            8,
            33,
            "unknown key 'rte' in system.components.controller.context (did you mean 'rate'?",
        ),
        (
            "    - from: sensor.out",
            "    - form: sensor.out",
            10,
            7,
            "unknown key 'form' in system.connections[0] (did you mean 'from'?",
        ),
    ],
)
def test_unknown_keys_are_refused_with_position_and_suggestion(
    tmp_path: Path, old: str, new: str, line: int, column: int, message: str
) -> None:
    assert old in SYSTEM
    error = _load(tmp_path, SYSTEM.replace(old, new))
    assert str(error).startswith(f"{tmp_path / 'system.yaml'}:{line}:{column}: {message}")
    assert (getattr(error, "line"), getattr(error, "column")) == (line, column)  # noqa: B009


def test_other_refusals_are_located(tmp_path: Path) -> None:
    error = _load(tmp_path, SYSTEM.replace("to: controller.in", "to: controller"))
    assert str(error).startswith(f"{tmp_path / 'system.yaml'}:11:11: system.connections[0].to:")
    assert "component.port" in str(error)
    error = _load(tmp_path, SYSTEM.replace("rate: 100", "rate: fast"))
    assert ":8:39: system.components.controller.context.rate: expected a number" in str(error)


def test_a_yaml_syntax_error_names_the_file(tmp_path: Path) -> None:
    error = _load(tmp_path, SYSTEM.replace("{type: periodic", "{type: [periodic"))
    assert str(error).startswith(f"{tmp_path / 'system.yaml'}:")
    assert "invalid YAML" in str(error) and "<unicode string>" not in str(error)
