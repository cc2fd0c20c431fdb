"""docs/recording.md: its Python examples run (in order, in one directory)."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

DOC = Path(__file__).resolve().parents[2] / "docs" / "recording.md"


def test_recording_doc_examples_run(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    blocks = re.findall(r"^```python\n(.*?)^```$", DOC.read_text(), flags=re.M | re.S)
    assert len(blocks) == 2
    monkeypatch.chdir(tmp_path)
    for i, block in enumerate(blocks):
        exec(compile(block, f"{DOC.name}[{i}]", "exec"), {"__name__": f"docs_recording_{i}"})
    assert os.path.getsize(tmp_path / "example.mcap") > 0


def test_recording_doc_names_the_shipped_layout() -> None:
    from openel_async.recording import LAYOUT_PATH

    assert LAYOUT_PATH.is_file()
    assert "src/openel_async/recording/foxglove_layout.json" in DOC.read_text()
