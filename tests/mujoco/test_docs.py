"""The quick-start example of docs/mujoco.md runs as written."""

from __future__ import annotations

import pathlib
import re

import pytest

DOC = pathlib.Path(__file__).resolve().parents[2] / "docs" / "mujoco.md"


def test_quick_start_example_runs(
    tmp_path: pathlib.Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    blocks = re.findall(r"^```python\n(.*?)^```$", DOC.read_text(), flags=re.M | re.S)
    monkeypatch.chdir(tmp_path)
    exec(blocks[0], {"__name__": "docs_mujoco_quick_start"})
    assert (tmp_path / "arm2.png").read_bytes()[:4] == b"\x89PNG"
    assert "TimedValue(values=" in capsys.readouterr().out
