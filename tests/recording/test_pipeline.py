"""The pipeline between the tap and the writer process: what the control loop queues, and
the writer process's priority."""

from __future__ import annotations

import asyncio
import contextlib
import gc
import os
import signal
import sys
import threading
import time
from pathlib import Path

import anyio
import pytest

from openel_async import Actuator, Request, VirtualClock
from openel_async.recording import Pipeline, PipelineStats, Recorder, SinkStartError, read_recording
from openel_async.recording import pipeline as pipeline_module
from openel_async.recording.records import BATCH, COMMAND, READING
from openel_async.recording.schemas import HAL_RECORD
from openel_sim import SimMotor


async def test_records_hold_plain_numbers(tmp_path: Path) -> None:
    """The per-tick records (position commands, readings) are numbers in column buffers;
    a queued command holds the Request as a plain int: such a tuple is untracked by the
    garbage collector (a Request member would keep it tracked)."""
    clock = VirtualClock()
    recorder = Recorder(tmp_path / "r.mcap")
    recorder.pipeline.start = lambda: None  # type: ignore[method-assign]  # no writer
    actuator = Actuator(SimMotor(), device_name="AXIS", clock=clock)
    recorder.observe(actuator)
    async with clock.autojump(), actuator:
        actuator.set_value_nowait(0.5, Request.VELOCITY)  # queued (before the others)
        actuator.set_value_nowait(0.25, Request.POSITION)
        actuator.get_value_nowait(Request.POSITION_ACTUAL)
        now = clock.now_ns()
        columns = {(c.kind, c.request): c for c in recorder.pipeline.columns}
        command = columns[(COMMAND, int(Request.POSITION))]
        reading = columns[(READING, int(Request.POSITION_ACTUAL))]
        assert (command.times, command.values) == ([now], [0.25])
        assert reading.times == [now] and len(reading.values) == 1
        assert all(type(v) is float for v in reading.values)
    # the state change at the exit queued them first (a channel's records stay in order)
    assert not command.times and not reading.times
    records = [e for e in recorder.pipeline.queue if e[0] >= 0 and e[2] in (0, 1)]
    assert [(type(e[3]), e[3]) for e in records] == [(int, int(Request.VELOCITY))]
    gc.collect()
    gc.collect()
    assert not any(gc.is_tracked(e) for e in records)
    actuator.set_listener(None)


@pytest.mark.skipif(not hasattr(os, "SCHED_IDLE"), reason="Linux scheduling policies")
@pytest.mark.parametrize("idle", [True, False])
def test_writer_process_runs_under_sched_idle(tmp_path: Path, idle: bool) -> None:
    """The writer takes only CPU time nothing else wants (SCHED_IDLE) unless told not to."""
    pipeline = Pipeline(mcap=tmp_path / "i.mcap", writer_idle=idle)
    pipeline.start()
    try:
        pid = pipeline.writer_pid
        assert pid is not None
        want = os.SCHED_IDLE if idle else os.SCHED_OTHER
        assert os.sched_getscheduler(pid) == want
    finally:
        stats = pipeline.stop()
    assert stats.dropped == 0


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


@pytest.mark.skipif(not hasattr(os, "sched_getaffinity"), reason="CPU affinity (Linux)")
def test_writer_process_runs_on_one_cpu(tmp_path: Path) -> None:
    """By default the writer process (with the Foxglove server's threads, one per core) runs
    on one CPU only, the last this process may use, when it may use several: nice alone let
    the server's threads take time on the loop's core too. ``writer_cpu=None``: not pinned."""
    allowed = sorted(os.sched_getaffinity(0))
    pipeline = Pipeline(foxglove=("127.0.0.1", 0))
    expected = {allowed[-1]} if len(allowed) > 1 else set(allowed)
    assert pipeline.writer_cpu == (allowed[-1] if len(allowed) > 1 else None)
    pipeline.start()
    try:
        pid = pipeline.writer_pid
        assert pid is not None
        threads = os.listdir(f"/proc/{pid}/task")
        assert len(threads) >= 2  # the server's threads started after the pinning
        assert {frozenset(os.sched_getaffinity(int(t))) for t in threads} == {frozenset(expected)}
    finally:
        pipeline.stop()
    free = Pipeline(mcap=tmp_path / "f.mcap", writer_cpu=None)
    assert free.writer_cpu is None and "--cpu" not in free.writer_command()
    chosen = Pipeline(mcap=tmp_path / "c.mcap", writer_cpu=allowed[0])
    command = chosen.writer_command()
    assert command[command.index("--cpu") + 1] == str(allowed[0])
    with pytest.raises(ValueError, match="writer_cpu"):
        Pipeline(mcap=tmp_path / "x.mcap", writer_cpu=max(allowed) + 1)
    with pytest.raises(ValueError, match="writer_cpu"):
        Pipeline(mcap=tmp_path / "x.mcap", writer_cpu=-2)


@pytest.mark.skipif(not hasattr(signal, "SIGSTOP"), reason="Unix signals")
def test_stop_is_bounded_when_the_writer_stops_reading(tmp_path: Path) -> None:
    """A writer process that no longer reads its stdin (hung, or stopped: SIGSTOP here)
    leaves the feeding thread blocked on the full pipe: ``stop(timeout)`` still returns
    after about ``timeout`` (it kills the writer), and the frame that could not be handed
    over is counted as dropped, not as queued and written."""
    pipeline = Pipeline(mcap=tmp_path / "h.mcap")
    pipeline.start()
    pid = pipeline.writer_pid
    assert pid is not None
    os.kill(pid, signal.SIGSTOP)
    produced = 50_000  # about 0.7 MB of msgpack: far more than a pipe holds
    result: list[PipelineStats] = []
    try:
        channel = pipeline.add_channel("/hal/X", HAL_RECORD)
        for i in range(produced):
            pipeline.put((channel, i, COMMAND, int(Request.POSITION), float(i)))
        stopper = threading.Thread(target=lambda: result.append(pipeline.stop(timeout=1.0)))
        started = time.monotonic()
        stopper.start()
        stopper.join(20)
        elapsed = time.monotonic() - started
        assert not stopper.is_alive(), "stop() waits forever for a writer that does not read"
    finally:  # unblock a stop() that hangs (before the fix), so the test run can end
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)
    assert elapsed < 10
    (stats,) = result
    assert stats.dropped > 0 and stats.queued + stats.dropped == produced
    assert stats.written <= stats.queued
    assert pipeline.error is not None and pipeline.writer_pid is None


def test_loop_encodes_a_batch_and_the_thread_writes_it(tmp_path: Path) -> None:
    """``flush_due`` (the tap calls it from the control loop every few ticks) takes a whole
    batch off the queue as one encoded frame and the thread writes it; below ``batch_size``
    it takes nothing (the thread takes those every ``flush_interval``)."""
    pipeline = Pipeline(mcap=tmp_path / "b.mcap", batch_size=100, flush_interval=60.0)
    pipeline.start()
    try:
        channel = pipeline.add_channel("/hal/X", HAL_RECORD)
        for i in range(98):
            pipeline.put((channel, i, COMMAND, int(Request.POSITION), float(i)))
        pipeline.flush_due()
        assert len(pipeline.queue) == 99  # the channel entry and 98 records: not yet
        pipeline.put((channel, 98, COMMAND, int(Request.POSITION), 98.0))
        pipeline.flush_due()
        assert len(pipeline.queue) == 0  # taken at once, in the caller
    finally:
        stats = pipeline.stop()
    assert stats == PipelineStats(99, 99, 0, pipeline.capacity)
    assert pipeline.error is None


@pytest.mark.skipif(not hasattr(signal, "SIGSTOP"), reason="Unix signals")
def test_loop_never_waits_for_a_stuck_writer(tmp_path: Path) -> None:
    """With the writer process stopped, ``flush_due`` still returns at once: beyond
    ``max_frames`` frames it takes nothing more, the records stay in the bounded queue and
    what does not fit is dropped and counted; all of it is accounted for at the end."""
    pipeline = Pipeline(mcap=tmp_path / "s.mcap", batch_size=1000, max_frames=2, capacity=20_000)
    pipeline.start()
    pid = pipeline.writer_pid
    assert pid is not None
    os.kill(pid, signal.SIGSTOP)
    produced = 0
    try:
        channel = pipeline.add_channel("/hal/X", HAL_RECORD)
        started = time.monotonic()
        for _ in range(100):  # 100 000 records: far more than the pipe, frames and queue
            for _ in range(1000):
                produced += 1
                pipeline.put((channel, produced, COMMAND, int(Request.POSITION), 0.5))
            pipeline.flush_due()
        elapsed = time.monotonic() - started
        assert len(pipeline.queue) == pipeline.capacity  # the loop stopped taking
        assert pipeline.dropped > 0
        stats = pipeline.stop(timeout=1.0)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)
    assert elapsed < 10  # (the writer never read: a blocking hand-over would never return)
    assert stats.queued + stats.dropped == produced
    assert stats.written <= stats.queued and pipeline.error is not None


class _Batches:
    """What a bank's batch listener gives the pipeline: BATCH records of ``size`` messages."""

    size = 2

    def __init__(self, pipeline: Pipeline) -> None:
        self.count = 0
        self.pipeline = pipeline
        pipeline.batches.append(self)

    def put(self, entry: tuple[object, ...]) -> None:
        if len(self.pipeline.queue) < self.pipeline.capacity:
            self.pipeline.queue.append(entry)
            self.count += 1
        else:
            self.pipeline.dropped += self.size


def test_batch_records_lost_with_a_stuck_writer_count_their_messages(tmp_path: Path) -> None:
    """BATCH records (two messages each) among single ones, the writer stopped and then
    killed: every message is queued and written, or dropped and counted."""
    pipeline = Pipeline(mcap=tmp_path / "b.mcap", batch_size=1000, max_frames=2, capacity=20_000)
    pipeline.start()
    pid = pipeline.writer_pid
    assert pid is not None
    os.kill(pid, signal.SIGSTOP)
    batches = _Batches(pipeline)
    produced = 0
    try:
        a = pipeline.add_channel("/hal/A", HAL_RECORD)
        b = pipeline.add_channel("/hal/B", HAL_RECORD)
        code = int(Request.POSITION)
        for _ in range(60):
            for i in range(1000):
                if i % 2:
                    batches.put((BATCH, i, COMMAND, code, (a, b), (0.5, 0.6)))
                    produced += 2
                else:
                    pipeline.put((a, i, COMMAND, code, 0.5))
                    produced += 1
            pipeline.flush_due()
        assert pipeline.dropped > 0
        stats = pipeline.stop(timeout=1.0)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)
    assert stats.queued + stats.dropped == produced
    assert stats.written <= stats.queued and pipeline.error is not None


class _SilentWriter(Pipeline):
    """A writer process that never says it is ready (it sleeps)."""

    def writer_command(self) -> list[str]:
        return [sys.executable, "-c", "import time; time.sleep(60)"]


def test_start_is_bounded_when_the_writer_never_says_ready(tmp_path: Path) -> None:
    """``start()`` waited on the writer's first stdout line without a bound; now it raises
    SinkStartError after ``start_timeout`` seconds and kills the writer."""
    pipeline = _SilentWriter(mcap=tmp_path / "s.mcap", start_timeout=0.3)
    result: list[BaseException] = []

    def start() -> None:
        try:
            pipeline.start()
        except BaseException as exc:
            result.append(exc)

    starter = threading.Thread(target=start, daemon=True)
    started = time.monotonic()
    starter.start()
    starter.join(20)
    assert not starter.is_alive(), "start() waits forever for a writer that says nothing"
    assert time.monotonic() - started < 10
    (error,) = result
    assert isinstance(error, SinkStartError) and "ready within 0.3 s" in str(error)
    assert pipeline.writer_pid is None
    with pytest.raises(ValueError, match="start_timeout"):
        Pipeline(mcap=tmp_path / "x.mcap", start_timeout=0)


async def test_a_loop_without_a_timer_hands_its_columns_over(tmp_path: Path) -> None:
    """No timer paces the tap: every flush_interval a callback of the loop hands its column
    buffers over and writes them (a live view sees a slow loop's readings), with no thread
    woken for it."""
    recorder = Recorder(tmp_path / "t.mcap")
    actuator = Actuator(SimMotor(), device_name="AXIS")  # the real clock
    flushed = anyio.Event()
    async with recorder:
        pipeline = recorder.pipeline
        flush_due = pipeline.flush_due

        def traced(force: bool = False) -> None:  # called by the loop's periodic callback
            flush_due(force)
            columns = pipeline.columns
            if len(columns) == 2 and all(c.taken for c in columns):
                flushed.set()  # the records below handed over

        pipeline.flush_due = traced  # type: ignore[method-assign]
        recorder.observe(actuator)
        async with actuator:
            actuator.set_value_nowait(0.25, Request.POSITION)
            actuator.get_value_nowait(Request.POSITION_ACTUAL)
            held = [c for c in pipeline.columns if c.times]
            assert len(held) == 2
            with anyio.fail_after(10):  # flush_interval is 100 ms
                await flushed.wait()
            assert all(c.taken == 1 and not c.times for c in held)
    stats = recorder.final_stats
    assert stats is not None and stats.dropped == 0 and stats.written == stats.queued


@pytest.mark.skipif(not hasattr(signal, "SIGSTOP"), reason="Unix signals")
async def test_loop_driven_writes_never_block_and_lose_nothing_untold(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Driven by the loop, the pipeline writes without blocking: with the writer process
    stopped, the frames wait (the pipe, then ``max_frames``), the column buffer fills to its
    capacity and the rest is dropped and counted; once the writer runs again everything
    held is written, and the file holds exactly what was not dropped."""
    monkeypatch.setattr(pipeline_module, "PIPE_SIZE", 1 << 16)  # (1 MiB holds ~100 000 commands)
    path = tmp_path / "d.mcap"
    recorder = Recorder(path, capacity=5_000)
    actuator = Actuator(SimMotor(), device_name="AXIS", clock=VirtualClock())
    produced = 0
    async with recorder:
        pipeline = recorder.pipeline
        pid = pipeline.writer_pid
        assert pid is not None
        recorder.observe(actuator)
        async with actuator:
            os.kill(pid, signal.SIGSTOP)
            try:
                started = time.monotonic()
                # until the pipe, the frames and the buffer are full and 5 000 more were
                # dropped (values that do not compress: the pipe holds fewer of them)
                k = 0
                while pipeline.dropped < 5_000 and k < 300:
                    k += 1
                    for _ in range(1000):
                        produced += 1
                        noise = produced * 2_654_435_761 % 1_000_003
                        actuator.set_value_nowait(1e-9 * noise, Request.POSITION)
                    pipeline.flush_due()
                elapsed = time.monotonic() - started
                assert pipeline.dropped >= 5_000
            finally:
                os.kill(pid, signal.SIGCONT)
            assert elapsed < 20  # (a blocking write would never have returned)
    stats = recorder.final_stats
    assert stats is not None and stats.dropped > 0
    assert stats.queued + stats.dropped == produced + 3  # and the 3 state changes
    assert stats.written == stats.queued
    rec = read_recording(path)
    assert rec.complete and rec.dropped == stats.dropped
    written = sum(1 for m in rec.topic("/hal/AXIS") if m["kind"] == "command")
    assert written + stats.dropped == produced


@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="Unix signals")
async def test_loop_driven_writer_killed_mid_run_is_told(tmp_path: Path) -> None:
    """Driven by the loop, a writer process killed mid-run: the loop's next write finds the
    pipe broken, the pipeline says why, and every record is written or counted as dropped
    (none is waited for)."""
    recorder = Recorder(tmp_path / "k.mcap", capacity=20_000, logs=False)  # counts exact
    actuator = Actuator(SimMotor(), device_name="AXIS", clock=VirtualClock())
    produced = 0
    async with recorder:
        pipeline = recorder.pipeline
        pid = pipeline.writer_pid
        assert pid is not None
        recorder.observe(actuator)
        async with actuator:
            for k in range(60):
                if k == 20:
                    os.kill(pid, signal.SIGKILL)
                    _wait_exited(pid)  # its pipe closed: the next write must find it broken
                for _ in range(1000):
                    produced += 1
                    actuator.set_value_nowait(1e-6 * (k % 7), Request.POSITION)
                pipeline.flush_due()
            assert pipeline.error is not None  # found by a write from the loop
    stats = recorder.final_stats
    assert stats is not None and stats.dropped > 0
    assert stats.queued + stats.dropped == produced + 3  # and the 3 state changes
    assert stats.written <= stats.queued


def _wait_exited(pid: int, timeout: float = 30.0) -> None:
    """Until process ``pid`` has exited (a zombie or gone: its file descriptors closed)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except (FileNotFoundError, ProcessLookupError):
            return
        if state in ("Z", "X"):
            return
        time.sleep(0.005)
    raise TimeoutError(f"process {pid} still runs {timeout} s after SIGKILL")


def test_hand_over_period_and_batch_by_sinks(tmp_path: Path) -> None:
    """A live view hands over every 20 ms or at 1 024 records (a viewer's latency); an MCAP
    file alone every 100 ms or at 4 096 (fewer frames: each costs the loop about as much as
    its records); either can be given, and a non-positive period is refused."""
    file_only = Pipeline(mcap=tmp_path / "f.mcap")
    assert (file_only.flush_interval, file_only.batch_size) == (0.1, 4096)
    for live in (
        Pipeline(foxglove=("127.0.0.1", 0)),
        Pipeline(mcap=tmp_path / "b.mcap", foxglove=("127.0.0.1", 0)),
    ):
        assert (live.flush_interval, live.batch_size) == (0.02, 1024)
    given = Pipeline(mcap=tmp_path / "g.mcap", flush_interval=0.5, batch_size=10)
    assert (given.flush_interval, given.batch_size) == (0.5, 10)
    with pytest.raises(ValueError, match="flush_interval"):
        Pipeline(mcap=tmp_path / "z.mcap", flush_interval=0)


async def test_a_loop_driven_stop_waits_no_flush_interval(tmp_path: Path) -> None:
    """Stopping a pipeline the loop drove takes what is left at once: its thread, woken for
    the end, does not wait one more ``flush_interval`` (here 30 s) first."""
    pipeline = Pipeline(mcap=tmp_path / "s.mcap", flush_interval=30.0)
    await anyio.to_thread.run_sync(pipeline.start)
    try:
        pipeline.drive_from(asyncio.get_running_loop())
        channel = pipeline.add_channel("/hal/X", HAL_RECORD)
        pipeline.put((channel, 1, COMMAND, int(Request.POSITION), 0.5))
        # The thread takes drive_from's wake-up and then waits for the end only: the state
        # a run leaves it in (not needed for the test to pass, only to catch the bug).
        await anyio.sleep(0.3)
    finally:
        pipeline.release_loop()
        started = time.monotonic()
        stats = await anyio.to_thread.run_sync(pipeline.stop)
    assert time.monotonic() - started < 10  # before the fix: 30 s (killed at 60)
    assert stats == PipelineStats(1, 1, 0, pipeline.capacity)
    assert pipeline.error is None
