"""Issue 27: what a tap costs the processes that start. The app's process records and
serves through the pipeline without the Foxglove SDK (only the writer process loads it), and
the writer process loads the SDK, msgspec and its own small modules, not the taps, the
framework's runtime, asyncio or structlog."""

from __future__ import annotations

import subprocess
import sys


def _modules_after(program: str) -> set[str]:
    done = subprocess.run(
        [sys.executable, "-c", program + "\nimport sys\nprint(' '.join(sys.modules))"],
        capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    return set(done.stdout.split())


def test_each_process_of_a_tap_imports_only_what_it_uses() -> None:
    app = _modules_after(
        "import openel_async.recording.tap, openel_async.recording.live, "
        "openel_async.recording.recorder"
    )
    assert "openel_async.recording.pipeline" in app  # (what this test reads)
    assert not {m for m in app if m.split(".")[0] == "foxglove"}
    writer = _modules_after(
        "from openel_async.recording.sink_process import main\n"
        "from openel_async.recording.mcap_sink import McapSink\n"
        "from openel_async.recording.sinks import FoxgloveSink"
    )
    assert "foxglove" in writer
    heavy = {"asyncio", "anyio", "structlog", "subprocess", "openel_async.recording.tap"}
    assert not writer & heavy, sorted(writer & heavy)
