"""A bank's streamed batches: a POSITION batch is one record of the bank's column buffer in the
control loop (its time and values appended: the bank's batch listener), one command message
per component on its own channel in the file, counted as messages (queued, written,
dropped); a bank's read likewise (one record, a reading message per component); the
joint-state sample takes the latest command heard, a bank's or a single one, and the
application's own read at the same time."""

from __future__ import annotations

from pathlib import Path

from openel_async import Actuator, ActuatorBank, Request, VirtualClock
from openel_async.recording import Recorder, read_recording
from openel_async.recording.records import BATCH, COMMAND, JOINTS, READING
from openel_sim import SimMotor


def _axes(clock: VirtualClock) -> list[Actuator]:
    return [Actuator(SimMotor(), device_name=f"AXIS_{i}", clock=clock) for i in range(2)]


async def test_a_bank_batch_is_one_record_and_a_message_per_component(tmp_path: Path) -> None:
    clock = VirtualClock()
    path = tmp_path / "bank.mcap"
    recorder = Recorder(path)
    async with clock.autojump(), recorder:
        axes = _axes(clock)
        for axis in axes:
            recorder.observe(axis)
        async with axes[0], axes[1]:
            bank = ActuatorBank(axes)
            queue = recorder.pipeline.queue
            before = len(queue)
            for k in range(1, 51):
                bank.set_values_nowait([0.01 * k, -0.01 * k])
            assert len(queue) == before  # nothing queued: the bank's column holds them
            (columns,) = [c for c in recorder.pipeline.columns if len(c.channels) == 2]
            assert columns.kind == COMMAND and len(columns.times) == 50  # a record per batch
            assert columns.values[:4] == [0.01, -0.01, 0.02, -0.02]
            axes[1].set_value_nowait(0.7, Request.POSITION)  # a member's own: after them
            assert queue[-1][2] == COMMAND and queue[-1][4] == 0.7
            axes[1].set_value_nowait(0.2, Request.VELOCITY)  # another request: queued
            stats = recorder.stats
            assert stats.queued >= 102 and stats.dropped == 0
    final = recorder.final_stats
    assert final is not None and final.dropped == 0 and final.queued == final.written
    rec = read_recording(path)
    for i, sign in enumerate((1, -1)):
        commands = [m for m in rec.topic(f"/hal/AXIS_{i}") if m["kind"] == "command"]
        values = [m["value"] for m in commands]
        expected = [sign * 0.01 * k for k in range(1, 51)] + ([0.7, 0.2] if i else [])
        assert values == expected
        requests = ["POSITION"] * 50 + (["POSITION", "VELOCITY"] if i else [])
        assert [m["request"] for m in commands] == requests


async def test_dropped_batches_count_their_messages(tmp_path: Path) -> None:
    """A full column buffer drops a batch and counts its two messages; a full queue drops a
    BATCH record (another request than POSITION) and counts its two messages too."""
    clock = VirtualClock()
    recorder = Recorder(tmp_path / "d.mcap", capacity=30)
    recorder.pipeline.start = lambda: None  # type: ignore[method-assign]  # nothing taken
    axes = _axes(clock)
    for axis in axes:
        recorder.observe(axis)
    async with clock.autojump(), axes[0], axes[1]:
        bank = ActuatorBank(axes)
        queued = recorder.stats.queued
        for k in range(200):  # far more than the buffer holds
            bank.set_values_nowait([0.001 * k, 0.002 * k])
        (columns,) = [c for c in recorder.pipeline.columns if len(c.channels) == 2]
        stats = recorder.stats
        assert len(columns.times) == 30  # capacity
        assert stats.queued - queued == 2 * 30 and stats.dropped == 2 * 170
        for _ in range(200):  # velocity batches: BATCH records in the queue
            bank.set_values_nowait([0.001, 0.002], Request.VELOCITY)
        kept = sum(1 for e in recorder.pipeline.queue if e[0] == BATCH)
        after = recorder.stats
    assert 0 < kept < 200 and len(recorder.pipeline.queue) >= 30
    assert after.queued - stats.queued == 2 * kept
    assert after.dropped - stats.dropped == 2 * (200 - kept)
    for axis in axes:
        axis.set_listener(None)


async def test_the_sample_takes_the_latest_command_bank_or_single(tmp_path: Path) -> None:
    clock = VirtualClock()
    recorder = Recorder(tmp_path / "s.mcap")
    recorder.pipeline.start = lambda: None  # type: ignore[method-assign]  # no writer
    axes = _axes(clock)
    for axis in axes:
        recorder.observe(axis)
    queue = recorder.pipeline.queue

    def sample() -> list[float | None]:
        recorder.sample(clock.now_ns())
        entry = queue.pop()
        assert entry[2] == JOINTS
        return [commanded for _, commanded, _ in entry[4]]

    async with clock.autojump(), axes[0], axes[1]:
        bank = ActuatorBank(axes)
        bank.set_values_nowait([0.1, 0.2])
        assert sample() == [0.1, 0.2]
        axes[0].set_value_nowait(0.3, Request.POSITION)  # a single command after the batch
        assert sample() == [0.3, 0.2]
        bank.set_values_nowait([0.4, 0.5])  # and a batch after it
        assert sample() == [0.4, 0.5]
        axes[1].set_value_nowait(0.25, Request.VELOCITY)  # not a position
        assert sample() == [0.4, 0.5]
    for axis in axes:
        axis.set_listener(None)


async def test_a_bank_read_is_one_record_and_a_reading_per_component(tmp_path: Path) -> None:
    """``get_values`` of actual positions: one call of the bank's batch listener, a record of
    a column buffer of the bank's (no per-member ``on_reading``), a reading message per
    component in the file, in order with its own readings and commands; the joint-state
    sample at the same clock time takes those values (no read of its own)."""
    clock = VirtualClock()
    path = tmp_path / "reads.mcap"
    recorder = Recorder(path)
    async with clock.autojump(), recorder:
        axes = _axes(clock)
        for axis in axes:
            recorder.observe(axis)
        async with axes[0], axes[1]:
            bank = ActuatorBank(axes)
            queue = recorder.pipeline.queue
            heard: list[tuple[float, ...]] = []
            for k in range(1, 21):
                bank.set_values_nowait([0.01 * k, -0.01 * k])
                await clock.sleep(0.01)
                heard.append(bank.get_values_nowait(Request.POSITION_ACTUAL))
            (reads,) = [
                c
                for c in recorder.pipeline.columns
                if len(c.channels) == 2 and c.request == int(Request.POSITION_ACTUAL)
            ]
            assert len(reads.times) == 20 and reads.width == 2
            assert reads.values[:2] == list(heard[0])
            assert not [m for m in queue if m[2] == READING]  # nothing per member
            counts = iter(range(1000))
            for axis in axes:  # from now on each read answers a new value: the order shows
                axis.device.read_nowait = lambda request: 0.5 + next(counts)  # type: ignore[method-assign]
            own = await axes[1].get_value(Request.POSITION_ACTUAL)  # its own read: after them
            later = await bank.get_values(Request.POSITION_ACTUAL)  # the async read: the same
            again = axes[1].get_value_nowait(Request.POSITION_ACTUAL)  # and after it
            last = bank.get_values_nowait(Request.POSITION_ACTUAL)
            devices = [a.device for a in axes]
            for device in devices:  # the sample must take the app's values, not read
                device.read_nowait = _unread  # type: ignore[method-assign]
            recorder.sample(clock.now_ns())
            joints = queue[-1]
            assert joints[2] == JOINTS
            assert [actual for _, _, actual in joints[4]] == list(last)
            for device in devices:
                del device.read_nowait
    final = recorder.final_stats
    assert final is not None and final.dropped == 0 and final.queued == final.written
    rec = read_recording(path)
    for i in range(2):
        readings = [m for m in rec.topic(f"/hal/AXIS_{i}") if m["kind"] == "reading"]
        expected = [h[i] for h in heard] + ([own] if i else []) + [later[i]]
        expected += ([again] if i else []) + [last[i]]
        assert [m["value"] for m in readings] == expected
        assert all(m["request"] == "POSITION_ACTUAL" for m in readings)
        assert [m["values"] for m in readings] == [[v] for v in expected]
        times = [m["time_ns"] for m in readings]
        at_once = 5 if i else 3  # the last bank read, its own, the bank's, its own, the bank's
        assert times == sorted(times) and len(set(times[-at_once:])) == 1


def _unread(request: Request) -> float:
    raise AssertionError("the sample read the device")
