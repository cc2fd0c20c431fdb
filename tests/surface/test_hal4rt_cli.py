"""``openel-async hal4rt validate|show|schema`` (exec is tested against a served rig in
tests/remote/test_processes.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

from openel_async.cli import main

SAMPLES = Path(__file__).parent / "samples"


def test_validate_accepts_the_samples(capsys: pytest.CaptureFixture[str]) -> None:
    files = sorted(str(p) for p in SAMPLES.glob("*.xml"))
    assert main(["hal4rt", "validate", *files]) == 0
    out = capsys.readouterr().out
    assert out.count(": valid ") == len(files)


def test_validate_refuses_an_invalid_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "bad.xml"
    bad.write_text("<Device><device_kind>Motor</device_kind></Device>")
    assert main(["hal4rt", "validate", str(bad)]) == 1
    assert "valid against the HAL4RT schema" in capsys.readouterr().err


def test_show_and_schema(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["hal4rt", "show", str(SAMPLES / "get_position_result.xml")]) == 0
    out = capsys.readouterr().out
    assert "Device Motor" in out and "out position (FLOAT) = -0.25" in out
    assert main(["hal4rt", "schema"]) == 0
    assert "FIX 1" in capsys.readouterr().out
