"""A recording whose process is killed (SIGKILL) is readable: up to its last complete chunk
when the writer process dies with it, whole when only the application dies (the writer
process sees its input end and closes the file)."""

from __future__ import annotations

import itertools
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from openel_async.recording import info_lines, read_recording

SCRIPT = """
import sys
import anyio
from openel_sim import SimMotor
from openel_async import Actuator, EventTimer, VirtualClock
from openel_async.recording import Recorder

async def main(path):
    clock = VirtualClock()
    async with clock.autojump(), Recorder(path, chunk_size=16 * 1024, timer_stats_ms=10) as rec:
        axis = Actuator(SimMotor(), device_name="AXIS", clock=clock)
        timer = EventTimer(1, clock=clock, name="loop")
        rec.observe(axis)
        rec.observe_timer(timer)
        async with axis, timer:
            timer.start_timer()
            k = 0
            while True:  # runs until killed
                k += 1
                axis.set_value_nowait((k % 100) / 100.0)
                await clock.sleep_until(clock.now_ns() + 1_000_000)
                if k % 200 == 0:
                    await anyio.sleep(0.005)  # real time for the writer thread

anyio.run(main, sys.argv[1])
"""


def _record_and_kill(path: Path, *, group: bool) -> None:
    proc = subprocess.Popen(
        [sys.executable, "-c", SCRIPT, str(path)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 60
        # Several complete chunks on disk (16 KiB each, compressed), then kill it mid-write.
        while not (path.exists() and path.stat().st_size > 40_000):
            assert proc.poll() is None, "the recording process ended on its own"
            assert time.monotonic() < deadline, "the recording did not grow"
            time.sleep(0.05)
        if group:  # the application and its writer process
            os.killpg(proc.pid, signal.SIGKILL)
        else:
            os.kill(proc.pid, signal.SIGKILL)
        assert proc.wait(timeout=30) == -signal.SIGKILL
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_killed_recording_is_readable_to_the_last_chunk(tmp_path: Path) -> None:
    path = tmp_path / "killed.mcap"
    _record_and_kill(path, group=True)
    recording = read_recording(path)
    assert not recording.complete  # no footer: cut short
    commands = [m for m in recording.topic("/hal/AXIS") if m["kind"] == "command"]
    ticks = recording.topic("/timer/loop")
    assert len(commands) > 200 and len(ticks) > 20
    # In order and whole up to the cut: consecutive commands, 1 ms apart on the clock.
    values = [round(m["value"] * 100) for m in commands]
    assert values == [(k % 100) for k in range(1, len(values) + 1)]
    # Tick statistics every 10 ms (timer_stats_ms) of the 1 ms timer:
    # each message counts the ticks since the previous one, none skipped.
    indexes = [0] + [m["index"] for m in ticks]
    assert [m["ticks"] for m in ticks] == [b - a for a, b in itertools.pairwise(indexes)]
    assert [m["ticks"] for m in ticks[1:]] == [10] * (len(ticks) - 1)
    assert all(m["missed_ticks"] == 0 and m["lateness_ns"] == 0 for m in ticks)
    assert any(line.startswith("complete    no: cut short") for line in info_lines(recording))


def test_killed_application_leaves_a_complete_recording(tmp_path: Path) -> None:
    path = tmp_path / "app-killed.mcap"
    _record_and_kill(path, group=False)
    deadline = time.monotonic() + 60
    while True:  # the writer process finishes the file once its input ends
        recording = read_recording(path)
        if recording.complete:
            break
        assert time.monotonic() < deadline, recording.problem
        time.sleep(0.1)
    commands = [m for m in recording.topic("/hal/AXIS") if m["kind"] == "command"]
    values = [round(m["value"] * 100) for m in commands]
    assert len(values) > 200 and values == [(k % 100) for k in range(1, len(values) + 1)]
    assert (
        recording.dropped is not None
    )  # its statistics record (the parent could not send its own)
