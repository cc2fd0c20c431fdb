"""Helpers of the app tests: loading an app file as a module, checking PNG files."""

from __future__ import annotations

from pathlib import Path
from types import ModuleType

from openel_apps.arm_demo import Artifacts
from openel_async.cli.run_cmd import load_app

APPS = Path(__file__).resolve().parents[2] / "apps"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def load(name: str) -> ModuleType:
    """``apps/<name>.py`` as a module (as ``openel-async run`` loads it)."""
    return load_app(APPS / f"{name}.py")


def is_png(path: Path | None) -> bool:
    return path is not None and path.is_file() and path.read_bytes()[:8] == PNG_MAGIC


def assert_snapshot_written_or_explained(artifacts: Artifacts) -> None:
    """The snapshot is a PNG, or it was skipped and the summary says why."""
    if artifacts.snapshot is not None:
        assert is_png(artifacts.snapshot)
    else:
        assert artifacts.snapshot_skipped
        assert any(artifacts.snapshot_skipped in line for line in artifacts.lines())
