"""The flight recorder: channels, schemas and message counts read back with the mcap reader."""

from __future__ import annotations

import json
import re
from collections import Counter
from pathlib import Path

import pytest
import structlog
from mcap.reader import make_reader

from openel_async import Actuator, BadParameterError, VirtualClock
from openel_async.cli import main as cli_main
from openel_async.recording import Recorder, info_lines, read_recording
from openel_sim import SimMotor

from .conftest import TARGETS, scenario
from .schema_check import check_recording


def _mcap_counts(path: Path) -> tuple[dict[str, str], Counter[str], list[tuple[str, dict]]]:
    """(topic -> schema name, messages per topic, decoded messages) with the mcap library."""
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        schemas = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
        counts: Counter[str] = Counter()
        decoded = []
        for schema, channel, message in reader.iter_messages():
            assert schema is not None and schema.encoding == "jsonschema"
            assert channel.message_encoding == "json"
            counts[channel.topic] += 1
            decoded.append((channel.topic, json.loads(message.data)))
        assert sum(counts.values()) == summary.statistics.message_count
    return schemas, counts, decoded


def test_virtual_clock_demo_recording(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "demo.mcap"
    code = cli_main(
        ["demo", "--bus", "sim", "--virtual", "--duration", "1", "--no-live", "--record", str(out)]
    )
    assert code == 0
    text = capsys.readouterr().out
    ticks = int(re.search(r"timer ticks\s+(\d+)", text).group(1))  # type: ignore[union-attr]
    setpoints = int(re.search(r"setpoints sent\s+(\d+)", text).group(1))  # type: ignore[union-attr]
    reads = int(re.search(r"sensor reads\s+(\d+)", text).group(1))  # type: ignore[union-attr]
    completed = int(re.search(r"(\d+) COMPLETED", text).group(1))  # type: ignore[union-attr]
    schemas, counts, decoded = _mcap_counts(out)
    assert schemas == {
        "/hal/MOTOR_1": "openel_async.HalRecord",
        "/hal/MOTOR_2": "openel_async.HalRecord",
        "/hal/ENCODER_1": "openel_async.HalRecord",
        "/hal/TEMP_2": "openel_async.HalRecord",
        "/timer/sync": "openel_async.TimerTick",
        "/joint_states": "openel_async.JointStates",
        "/log": "foxglove.Log",
    }
    assert ticks == 100  # of 10 ms: statistics every 100 ms, joint states every 20 ms
    assert counts["/timer/sync"] == ticks // 10 + 1  # from the first tick, and at the exit
    assert counts["/joint_states"] == ticks // 2
    kinds = Counter((topic, m.get("kind")) for topic, m in decoded)
    # Every setpoint of the timer's observer, plus the two commands that bring the axes home
    # and the two of the rig's safe stop at exit (on_exit: hold, a position hold each).
    assert kinds["/hal/MOTOR_1", "command"] + kinds["/hal/MOTOR_2", "command"] == setpoints + 4
    assert kinds["/hal/ENCODER_1", "reading"] + kinds["/hal/TEMP_2", "reading"] == reads
    completions = kinds["/hal/MOTOR_1", "completion"] + kinds["/hal/MOTOR_2", "completion"]
    assert completions == completed  # the demo's own observer counted the same events
    for name in ("MOTOR_1", "MOTOR_2", "ENCODER_1", "TEMP_2"):
        states = [m["state"] for t, m in decoded if t == f"/hal/{name}" and m["kind"] == "state"]
        assert states == ["Initialized", "Active", "Finalized"]
    stats = [m for t, m in decoded if t == "/timer/sync"]
    assert [m["index"] for m in stats] == [*range(1, ticks, 10), ticks]
    assert [m["ticks"] for m in stats] == [1] + [10] * 9 + [9]
    assert not any(m["missed_ticks"] for m in stats)
    assert any("timer_stopped" in m["message"] for t, m in decoded if t == "/log")
    assert check_recording(out) == sum(counts.values())  # every message fits its schema
    info = "\n".join(info_lines(read_recording(out)))
    assert "complete    yes, 0 message(s) dropped" in info
    assert re.search(r"/timer/sync\s+11\s+openel_async.TimerTick", info)


async def test_library_recorder_records_each_kind(tmp_path: Path) -> None:
    path = tmp_path / "lib.mcap"
    recorder = await scenario(path)
    assert recorder.final_stats is not None and recorder.final_stats.dropped == 0
    rec = read_recording(path)
    assert rec.complete and rec.dropped == 0
    for i, targets in enumerate(TARGETS):
        msgs = rec.topic(f"/hal/AXIS_{i}")
        commands = [
            (m["request"], m["value"], m["time_ns"]) for m in msgs if m["kind"] == "command"
        ]
        assert commands == [("POSITION", t, k * 600_000_000) for k, t in enumerate(targets)]
        assert sum(m["kind"] == "completion" for m in msgs) == 3
        last = [m for m in msgs if m["kind"] == "reading"][-1]
        assert last["request"] == "POSITION_ACTUAL" and last["value"] == pytest.approx(targets[2])
    thermo = [m for m in rec.topic("/hal/THERMO") if m["kind"] == "reading"]
    assert len(thermo) == sum(m["ticks"] for m in rec.topic("/timer/loop")) >= 170
    assert all(len(m["values"]) == 1 and m["value"] > 0 for m in thermo)


async def test_full_queue_drops_and_counts(tmp_path: Path) -> None:
    full = await scenario(tmp_path / "full.mcap")
    assert full.final_stats is not None and full.final_stats.dropped == 0
    produced = full.final_stats.queued
    small = await scenario(tmp_path / "small.mcap", capacity=50)
    stats = small.final_stats
    assert stats is not None and stats.dropped > 0
    assert stats.queued + stats.dropped == produced  # nothing lost untold
    rec = read_recording(tmp_path / "small.mcap")
    assert rec.complete and rec.dropped == stats.dropped
    assert len(rec.messages) == stats.written == stats.queued


async def test_one_listener_per_component(tmp_path: Path) -> None:
    clock = VirtualClock()
    actuator = Actuator(SimMotor(), clock=clock)
    async with Recorder(tmp_path / "a.mcap") as first, Recorder(tmp_path / "b.mcap") as second:
        first.observe(actuator)
        with pytest.raises(BadParameterError, match="listener"):
            second.observe(actuator)
        async with clock.autojump(), actuator:
            assert len(vars(actuator)) <= 29  # the listener costs no instance attribute
    assert actuator.listener is None  # detached when the recorder closed


def test_unwritable_record_path_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    target = tmp_path / "missing-dir" / "x.mcap"
    code = cli_main(["demo", "--bus", "sim", "--virtual", "--no-live", "--record", str(target)])
    assert code == 2
    assert f"--record: {target}: no such directory" in capsys.readouterr().err


async def test_log_lines_are_on_the_apps_clock(tmp_path: Path) -> None:
    """``/log`` is on the app's clock shifted to the wall clock, as every other channel: on a
    virtual clock a line logged 5 s later (of virtual time, instant in real time) is 5 s
    later in the file, at the same log time as a command sent with it (it was the wall
    clock: every line within the run's few milliseconds)."""
    path = tmp_path / "log.mcap"
    clock = VirtualClock()
    logger = structlog.get_logger("test_recording_log")
    async with clock.autojump(), Recorder(path) as recorder:
        axis = Actuator(SimMotor(), device_name="AXIS", clock=clock)
        recorder.observe(axis)
        async with axis:
            logger.warning("first_line")
            await clock.sleep(5.0)
            axis.set_value_nowait(0.1)
            logger.warning("second_line")
    rec = read_recording(path)
    logs = {
        m.data["message"]: m
        for m in rec.messages
        if m.topic == "/log" and m.data["message"] in ("first_line", "second_line")
    }
    first, second = logs["first_line"], logs["second_line"]
    assert second.log_time_ns - first.log_time_ns == 5_000_000_000
    stamp = second.data["timestamp"]
    assert stamp["sec"] * 1_000_000_000 + stamp["nsec"] == second.log_time_ns
    (command,) = [m for m in rec.messages if m.topic == "/hal/AXIS" and m.data["kind"] == "command"]
    assert command.log_time_ns == second.log_time_ns
