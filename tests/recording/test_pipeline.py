"""The pipeline between the tap and the writer process: what the control loop queues, and
the writer process's priority."""

from __future__ import annotations

import gc
import os
from pathlib import Path

import pytest

from openel_async import Actuator, Request, VirtualClock
from openel_async.recording import Pipeline, Recorder
from openel_sim import SimMotor


async def test_records_hold_plain_numbers(tmp_path: Path) -> None:
    """A queued command or reading holds the Request as a plain int: such a tuple is
    untracked by the garbage collector (a Request member would keep it tracked)."""
    clock = VirtualClock()
    recorder = Recorder(tmp_path / "r.mcap")
    recorder.pipeline.start = lambda: None  # type: ignore[method-assign]  # no writer
    actuator = Actuator(SimMotor(), device_name="AXIS", clock=clock)
    recorder.observe(actuator)
    async with clock.autojump(), actuator:
        actuator.set_value_nowait(0.25, Request.POSITION)
        actuator.get_value_nowait(Request.POSITION_ACTUAL)
    records = [e for e in recorder.pipeline.queue if e[0] >= 0 and e[2] in (0, 1)]
    assert [(type(e[3]), e[3]) for e in records] == [
        (int, int(Request.POSITION)),
        (int, int(Request.POSITION_ACTUAL)),
    ]
    gc.collect()
    gc.collect()  # a reading's values tuple first, then the record holding it
    assert not any(gc.is_tracked(e) for e in records)
    actuator.set_listener(None)


@pytest.mark.skipif(not hasattr(os, "getpriority"), reason="Unix niceness")
def test_writer_process_runs_niced(tmp_path: Path) -> None:
    pipeline = Pipeline(mcap=tmp_path / "n.mcap", writer_nice=7)
    pipeline.start()
    try:
        pid = pipeline.writer_pid
        assert pid is not None
        own = os.getpriority(os.PRIO_PROCESS, 0)
        assert os.getpriority(os.PRIO_PROCESS, pid) == min(own + 7, 19)
    finally:
        stats = pipeline.stop()
    assert stats.dropped == 0 and pipeline.writer_pid is None
    with pytest.raises(ValueError, match="writer_nice"):
        Pipeline(mcap=tmp_path / "x.mcap", writer_nice=20)
