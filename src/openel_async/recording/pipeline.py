"""The recorder's and live view's pipeline: a bounded queue filled by the control loop
without blocking, batches of it encoded (msgpack) and written by a thread to the writer
process (:mod:`.sink_process`), which makes the messages (JSON) and logs them on a Foxglove
SDK context whose sinks write them (an MCAP file, the Foxglove server).

The control loop appends the per-tick records (a bank's setpoints, a sensor's reading, an
actuator's position command) as numbers to column buffers (:mod:`.columns`: flat lists,
no tuple per record) and the rest (state changes, events, samples) as tuples to a
deque (the listeners of :mod:`.tap` do it directly); a full buffer or queue drops the record
and counts it (:attr:`PipelineStats.dropped`). When ``batch_size`` records are held, the
loop itself takes them and encodes them as one msgpack frame (:meth:`Pipeline.flush_due`,
called by the tap every few ticks; it never waits: it skips while ``max_frames`` frames are
still to be written).

Driven by an asyncio loop (:meth:`Pipeline.drive_from`, what a tap does), the loop also
writes the frames to the writer process's stdin itself, without blocking (a pipe of 1 MiB
where Linux allows it; what does not fit waits for the next try), and every
``flush_interval`` seconds a callback of the loop hands over what it holds (a slow loop, or
one whose tap sees no timer) and writes what is pending: no thread wakes up during the run.
A thread that woke every ``flush_interval`` seconds to take records or write, and the
interpreter lock passed to it and back, cost the demo loop 3-5 % of its time (measured),
and a thread taking and encoding thousands of records held that lock while the loop
waited. Without a loop (:meth:`Pipeline.start` alone) the thread does that work: it takes
the queue and writes every ``flush_interval`` seconds or when the loop hands a frame over.
At :meth:`Pipeline.stop` the thread takes what is left, the columns too (only the loop's
thread touches a column until then), and writes it. A channel's records reach the writer in
order. The encoding of the messages and the MCAP writing happen in
the other process, which runs at the lowest priority (``writer_nice``, 19), so it does not
compete with the loop for the CPU either: on a busy machine it falls behind (the queue, the
frames and the pipe hold the backlog) and catches up when there is time.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import select
import subprocess
import sys
import threading
import time
from collections import deque
from dataclasses import dataclass
from itertools import repeat, starmap
from typing import Any

import msgspec

from openel_async.logs import get_logger

from .columns import Columns, column_messages_count
from .records import BATCH, CHANNEL, COLUMNS, HEADER, STATS
from .schemas import ChannelSpec, Schema
from .sinks import PipelineStats, Sink

__all__ = ["Pipeline", "PipelineStats", "Sink", "SinkStartError"]

PIPE_SIZE = 1 << 20
"""Bytes of the pipe to the writer process where Linux lets a process set it
(``F_SETPIPE_SZ``, up to ``/proc/sys/fs/pipe-max-size``): frames wait there, not in the app."""

LIVE_FLUSH_INTERVAL = 0.02
LIVE_BATCH_SIZE = 1024
"""With a Foxglove server: what is held is handed over every 20 ms (a viewer sees the run
with that latency) or at 1 024 records."""
FILE_FLUSH_INTERVAL = 0.1
FILE_BATCH_SIZE = 4096
"""MCAP only: every 100 ms or at 4 096 records. Each frame has a fixed cost in the control
loop (taking, tallying, encoding and writing it; its code cold every time): on the arm2
demo's loop (about 3 records per 140 us tick) the 20 ms callback made a frame of ~430
records every ~140 ticks; frames of 2 150 records cost the loop 1 900 instructions per tick
fewer (cachegrind, of the tick's ~350 000). A killed application (SIGKILL) loses what it
held: at most this long of the run."""

log = get_logger(__name__)

WRITER_BOOTSTRAP = (
    "import signal as s; s.signal(s.SIGINT, s.SIG_IGN); s.signal(s.SIGTERM, s.SIG_IGN)\n"
    "from openel_async.recording.sink_process import main\n"
    "raise SystemExit(main())"
)
"""The writer process's ``python -c`` program (:mod:`.sink_process`): SIGINT and SIGTERM are
ignored before anything is imported (``python -m`` would import the package first, and a
Ctrl-C meanwhile would end it with a traceback); the writer ends when its input does."""


@dataclass(frozen=True, slots=True)
class Tally:
    """What a list of entries holds (:func:`tally`): what is dropped if it is lost."""

    entries: int
    """Entries but the final statistics."""
    records: int
    """Single records (one message each)."""
    controls: int
    """Channel and column entries."""
    batches: int
    """BATCH records ..."""
    batched: int
    """... and their messages."""
    columns: int
    """Messages of the column entries."""


def tally(entries: list[tuple[Any, ...]]) -> Tally:
    """The :class:`Tally` of ``entries``."""
    records = controls = batches = batched = columns = stats = 0
    for entry in entries:
        kind = entry[0]
        if kind >= 0:
            records += 1
        elif kind == COLUMNS:
            controls += 1
            columns += column_messages_count(entry)
        elif kind == CHANNEL:
            controls += 1
        elif kind == BATCH:
            batches += 1
            batched += len(entry[4])
        elif kind == STATS:
            stats += 1
    return Tally(len(entries) - stats, records, controls, batches, batched, columns)


class SinkStartError(RuntimeError):
    """The writer process could not open its sinks (an unwritable file, a port in use)."""


def _writer_cpu(cpu: int | None) -> int | None:
    """The writer's CPU for ``writer_cpu`` (see :attr:`Pipeline.writer_cpu`)."""
    if cpu is None:
        return None
    allowed = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else []
    if cpu == -1:
        return allowed[-1] if len(allowed) > 1 else None
    if cpu not in allowed:
        raise ValueError(
            f"writer_cpu must be -1, None or one of the CPUs this process may use "
            f"{allowed}, got {cpu}"
        )
    return cpu


class Pipeline:
    """See the module docstring. ``start()`` (blocking: from a worker thread in async code)
    before ``put()``, ``stop()`` at the end (blocking too)."""

    def __init__(
        self,
        *,
        mcap: str | os.PathLike[str] | None = None,
        foxglove: tuple[str, int] | None = None,
        capacity: int = 100_000,
        flush_interval: float | None = None,
        chunk_size: int = 64 * 1024,
        writer_nice: int = 19,
        writer_idle: bool = True,
        batch_size: int | None = None,
        max_frames: int = 8,
        start_timeout: float = 30.0,
        writer_cpu: int | None = -1,
    ) -> None:
        if capacity < 1:
            raise ValueError(f"capacity must be >= 1, got {capacity}")
        if not 0 <= writer_nice <= 19:
            raise ValueError(f"writer_nice must be 0..19, got {writer_nice}")
        if not start_timeout > 0:
            raise ValueError(f"start_timeout must be > 0 s, got {start_timeout}")
        if mcap is None and foxglove is None:
            raise ValueError("a pipeline needs an MCAP file, a Foxglove server or both")
        live = foxglove is not None
        if flush_interval is None:
            flush_interval = LIVE_FLUSH_INTERVAL if live else FILE_FLUSH_INTERVAL
        if batch_size is None:
            batch_size = LIVE_BATCH_SIZE if live else FILE_BATCH_SIZE
        if not flush_interval > 0:
            raise ValueError(f"flush_interval must be > 0 s, got {flush_interval}")
        if batch_size < 1 or max_frames < 1:
            raise ValueError(
                f"batch_size and max_frames must be >= 1, got {batch_size}, {max_frames}"
            )
        self.writer_cpu = _writer_cpu(writer_cpu)
        """The one CPU the writer process (and the Foxglove server's threads) runs on, or
        None (anywhere). ``writer_cpu=-1`` (the default): the last CPU this process may run
        on when it may run on several, so that the writer never takes more than one core
        from the control loop (nice only lowers its share of a contended core; the SDK's
        server runs a thread per core); None: not pinned."""
        self.mcap = None if mcap is None else os.fspath(mcap)
        self.foxglove = foxglove
        self.capacity = capacity
        self.flush_interval = flush_interval
        self.chunk_size = chunk_size
        self.start_timeout = start_timeout
        """Seconds :meth:`start` waits for the writer process to say it is ready."""
        self._rest = b""  # stdout bytes read after the ready line
        self.writer_idle = writer_idle
        """Run the writer process under the ``SCHED_IDLE`` policy during the run (Linux): it
        takes only CPU time nothing else wants and never preempts the control loop; at
        :meth:`stop` it is raised back to ``SCHED_OTHER`` (at ``writer_nice``) to drain."""
        self.writer_nice = writer_nice
        """The writer process's niceness (Unix): on a busy machine it yields the CPU to the
        control loop and catches up when there is time (its backlog bounded by ``capacity``)."""
        self.port: int | None = None
        """The Foxglove server's port once started."""
        self.offset_ns = 0
        """Added to every record's clock time to make its log time (wall clock)."""
        self.channels: list[ChannelSpec] = []
        self.queue: deque[tuple[Any, ...]] = deque()
        """The records waiting to be encoded. A listener on a per-command path appends to it
        directly when ``len(queue) < capacity`` and counts :attr:`dropped` otherwise (what
        :meth:`put` does, one call fewer)."""
        self.batch_size = batch_size
        """Records the control loop encodes at once (:meth:`flush_due`)."""
        self.max_frames = max_frames
        """Encoded frames waiting for the thread beyond which the loop takes no more (the
        records wait in the queue, bounded by ``capacity``)."""
        self.batches: list[Any] = []
        """The batch listeners that queue BATCH records (one record for ``size`` messages):
        each counts the records it queued (``count``), so that :attr:`queued` counts
        messages."""
        self.columns: list[Columns] = []
        """The column buffers of the per-tick records (:meth:`add_columns`)."""
        self._loop: asyncio.AbstractEventLoop | None = None  # drive_from's
        self._periodic_call: asyncio.TimerHandle | None = None
        self._last_handover = 0.0  # time.monotonic() of the loop's last frame
        self._offset = 0  # bytes of the first frame already written
        self._io = threading.Lock()  # writing to the pipe
        self._columns_lost = 0  # messages of columns discarded (not written): out of queued
        self._batch_lost = 0  # messages beyond one of the BATCH records discarded
        self._taken = 0  # entries taken from the queue (into frames)
        self._controls = 0  # channel and column entries queued or taken (not records)
        self._frames: deque[tuple[bytearray, Tally]] = deque()
        """Frames (length header and msgpack) still to write, in order, with the tally of
        their entries (what is dropped if they are lost)."""
        self._lock = threading.Lock()  # taking from the queue into _frames
        self._wake = threading.Event()
        self._dead = False  # the writer is gone: nothing is taken any more
        self.dropped = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._process: subprocess.Popen[bytes] | None = None
        self._encode_into = msgspec.msgpack.Encoder().encode_into
        self.error: BaseException | None = None
        self.written: int | None = None
        self.writer_cpu_s: float | None = None
        """CPU time the writer process spent encoding and writing (known after stop())."""

    def add_channel(
        self, topic: str, schema: Schema, metadata: dict[str, str] | None = None
    ) -> int:
        """A new channel; returns its id (registered with the sinks before its messages)."""
        spec = ChannelSpec(len(self.channels), topic, schema, dict(metadata or {}))
        self.channels.append(spec)
        self._controls += 1
        self.queue.append((CHANNEL, self.offset_ns, 0, spec.id, topic, schema.name, spec.metadata))
        return spec.id

    def add_columns(
        self, kind: int, request: int | None, channels: tuple[int, ...], width: int
    ) -> Columns:
        """A new column buffer for records of ``kind`` (COMMAND or READING, request code
        ``request``) on ``channels``, ``width`` values each (:mod:`.columns`), holding at most
        :attr:`capacity` records."""
        if not channels or any(not 0 <= c < len(self.channels) for c in channels):
            raise ValueError(f"channels must be ids of this pipeline's channels, got {channels}")
        if width < 1:
            raise ValueError(f"width must be >= 1, got {width}")
        columns = Columns(kind, request, channels, width, self.capacity)
        self.columns.append(columns)
        return columns

    def hand_over(self, columns: Columns) -> None:
        """Queue what ``columns`` holds now (from the control loop's thread): before a
        record of the same channel goes to the queue, so that the writer gets a channel's
        records in the order they came."""
        entry = columns.entry()
        if entry is not None:
            self.queue.append((*entry[:5], entry[5][:], entry[6][:]))  # copies: it goes on
            columns.taken_all()
            self._controls += 1

    def put(self, entry: tuple[Any, ...]) -> None:
        """Queue a record ``(channel, time_ns, kind, *fields)`` (:mod:`.sink_process`); never
        blocks."""
        queue = self.queue
        if len(queue) < self.capacity:
            queue.append(entry)
        else:
            self.dropped += 1

    @property
    def writer_pid(self) -> int | None:
        """The writer process's id while it runs."""
        return None if self._process is None else self._process.pid

    @property
    def queued(self) -> int:
        """Records handed over so far (taken by the thread or waiting)."""
        extra: int = sum(b.count * (b.size - 1) for b in self.batches) - self._batch_lost
        columns = sum((c.taken + len(c.times)) * c.per_record for c in self.columns)
        return self._taken + len(self.queue) - self._controls + extra + columns - self._columns_lost

    @property
    def stats(self) -> PipelineStats:
        queued = self.queued
        written = min(self._taken, queued) if self.written is None else self.written
        return PipelineStats(queued, written, self.dropped, self.capacity)

    def writer_command(self) -> list[str]:
        """The writer process's command line (:mod:`.sink_process` with this pipeline's
        sinks; it ignores SIGINT and SIGTERM from its first line on)."""
        command = [sys.executable, "-c", WRITER_BOOTSTRAP]
        command += ["--nice", str(self.writer_nice)]
        if self.writer_idle and hasattr(os, "SCHED_IDLE"):
            command += ["--idle"]
        if self.writer_cpu is not None:
            command += ["--cpu", str(self.writer_cpu)]
        if self.mcap is not None:
            command += ["--mcap", self.mcap, "--chunk-size", str(self.chunk_size)]
        if self.foxglove is not None:
            command += ["--foxglove", f"{self.foxglove[0]}:{self.foxglove[1]}"]
        return command

    def start(self) -> None:
        """Start the writer process (it opens the sinks) and the feeding thread; raises
        :class:`SinkStartError` when the sinks cannot open, or when the process has not said
        it is ready within :attr:`start_timeout` seconds (it is killed)."""
        process = subprocess.Popen(
            self.writer_command(), stdin=subprocess.PIPE, stdout=subprocess.PIPE
        )
        assert process.stdout is not None
        try:
            line = self._ready_line(process.stdout.fileno())
        except BaseException:  # a signal meanwhile (KeyboardInterrupt): no writer left behind
            with contextlib.suppress(Exception):
                process.kill()
                process.wait(timeout=10)
            raise
        try:
            if line is None:
                info = {
                    "error": f"the writer process did not say it was ready within "
                    f"{self.start_timeout} s"
                }
            else:
                info = json.loads(line) if line else {"error": "the writer process did not start"}
        except ValueError:
            info = {"error": f"the writer process said {line!r}"}
        if "error" in info:
            with contextlib.suppress(Exception):
                process.kill()
                process.wait(timeout=10)
            raise SinkStartError(info["error"])
        port = info.get("port")
        self.port = None if port is None else int(port)
        self._process = process
        self._thread = threading.Thread(target=self._run, name="openel-recorder", daemon=True)
        self._thread.start()

    def _ready_line(self, fd: int) -> bytes | None:
        """The writer's first stdout line (b"": it exited first), or None if it has not
        written one within :attr:`start_timeout` seconds; what follows it is kept."""
        deadline = time.monotonic() + self.start_timeout
        data = b""
        while b"\n" not in data:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([fd], [], [], left)[0]:
                return None
            chunk = os.read(fd, 4096)
            if not chunk:
                return data
            data += chunk
        line, _, self._rest = data.partition(b"\n")
        return line

    def stop(self, timeout: float = 60.0) -> PipelineStats:
        """Send what is queued, let the process close its sinks; the final statistics.

        Bounded by ``timeout`` seconds: a writer that has not finished by then (hung, or
        no longer reading its stdin, which leaves the thread blocked on the full pipe) is
        killed; what the thread could not hand over is counted as dropped and
        :attr:`error` says why (the file keeps what was written up to its last complete
        chunk). Called once nothing appends any more (the tap has detached): the thread
        takes the columns' last records too."""
        deadline = time.monotonic() + timeout
        process = self._process
        if process is not None and self.writer_idle and hasattr(os, "SCHED_OTHER"):
            with contextlib.suppress(OSError):  # it drains now, at writer_nice
                os.sched_setscheduler(process.pid, os.SCHED_OTHER, os.sched_param(0))
        self._stop.set()
        self._wake.set()
        thread = self._thread
        if thread is not None:
            thread.join(timeout)
            if thread.is_alive() and process is not None:
                self._kill(process, timeout)  # its stdin breaks: the blocked write fails
                thread.join(10.0)
            self._thread = None
        if self._dead:  # what came after the writer died: dropped, and counted
            with self._lock:
                queue = self.queue
                self._discard(list(starmap(queue.popleft, repeat((), len(queue)))))
                self.discard_columns()
        if process is not None:
            self._process = None
            assert process.stdout is not None
            if process.stdin is not None:  # closed by the thread: communicate would flush it
                with contextlib.suppress(OSError):
                    process.stdin.close()
                process.stdin = None
            try:
                out, _ = process.communicate(timeout=max(0.0, deadline - time.monotonic()))
                for line in (self._rest + out).splitlines():
                    with contextlib.suppress(ValueError, KeyError, TypeError):
                        done = json.loads(line)
                        self.written = int(done["written"])
                        self.writer_cpu_s = float(done["cpu_s"])
            except subprocess.TimeoutExpired:
                self._kill(process, timeout)
        return self.stats

    def _kill(self, process: subprocess.Popen[bytes], timeout: float) -> None:
        if process.poll() is None:
            process.kill()
            process.wait()
            log.error("recording_writer_timeout", timeout_s=timeout)
            if self.error is None:
                self.error = TimeoutError(
                    f"the writer process did not finish within {timeout} s: killed"
                )

    def flush_due(self, force: bool = False) -> None:
        """From the control loop's thread, every few ticks: when ``batch_size`` records are
        held (``force``: any), take them (the queue's and the columns'), encode them as one
        frame and write what the pipe takes (driven by a loop) or wake the thread to write
        it. Never blocks: skipped while the thread is taking records itself, while
        ``max_frames`` frames are still to be written, or once the writer is gone."""
        held = len(self.queue)
        if held < self.batch_size:
            for columns in self.columns:
                held += len(columns.times)
            if held < (1 if force else self.batch_size):
                return
        if len(self._frames) < self.max_frames and self._lock.acquire(blocking=False):
            try:
                if self._dead or self._stop.is_set():  # the thread takes no more frames
                    return
                self._take(columns=True)
            finally:
                self._lock.release()
            if self._loop is not None:
                self._last_handover = time.monotonic()
                self._write_available()
            else:
                self._wake.set()
        elif self._loop is not None and self._frames:
            self._write_available()

    def drive_from(self, loop: asyncio.AbstractEventLoop) -> None:
        """Let ``loop`` (running, in this thread) write the frames and hand over what is held
        every ``flush_interval`` seconds (see the module docstring); :meth:`release_loop`
        before :meth:`stop`."""
        process = self._process
        if process is None or process.stdin is None:
            raise RuntimeError("drive_from() needs a started pipeline")
        if self._loop is not None:
            raise RuntimeError("the pipeline is already driven by a loop")
        fd = process.stdin.fileno()
        with contextlib.suppress(ImportError, AttributeError, OSError):  # Linux only
            import fcntl

            fcntl.fcntl(fd, fcntl.F_SETPIPE_SZ, PIPE_SIZE)  # beyond pipe-max-size: as it is
        os.set_blocking(fd, False)
        self._loop = loop
        self._last_handover = time.monotonic()
        self._wake.set()  # the thread now waits for the end only
        self._periodic_call = loop.call_later(self.flush_interval, self._periodic)

    def release_loop(self) -> None:
        """From the loop's thread: stop writing from it (what is left is the thread's, at
        :meth:`stop`)."""
        if self._periodic_call is not None:
            self._periodic_call.cancel()
            self._periodic_call = None
        if self._loop is not None:
            self._loop = None
            process = self._process
            if process is not None and process.stdin is not None:
                with contextlib.suppress(OSError, ValueError):
                    os.set_blocking(process.stdin.fileno(), True)

    def _periodic(self) -> None:
        """Every ``flush_interval`` seconds, in the loop: hand over what was held that long
        and write what is pending."""
        self._periodic_call = None
        loop = self._loop
        if loop is None:
            return
        if time.monotonic() - self._last_handover >= self.flush_interval:
            self.flush_due(force=True)
        elif self._frames:
            self._write_available()
        if self._loop is loop and not self._dead:
            self._periodic_call = loop.call_later(self.flush_interval, self._periodic)

    def _write_available(self) -> None:
        """From the loop: write what the pipe takes now, without blocking (the rest, from
        the same byte, at the next try)."""
        process = self._process
        if process is None or process.stdin is None or not self._io.acquire(blocking=False):
            return
        try:
            self._write_some(process.stdin.fileno())
        except (OSError, ValueError) as exc:  # the writer process is gone
            failed: BaseException | None = exc
        else:
            failed = None
        finally:
            self._io.release()
        if failed is not None:
            self._fail(failed)

    def _write_some(self, fd: int) -> None:
        """Write frames until the pipe is full (the caller holds ``_io``)."""
        frames = self._frames
        while frames:
            data = frames[0][0]
            offset = self._offset
            try:
                n = os.write(fd, memoryview(data)[offset:])
            except BlockingIOError:  # the pipe is full: the writer is behind
                return
            if offset + n < len(data):
                self._offset = offset + n
                return
            self._offset = 0
            frames.popleft()

    def _take(self, final: bool = False, columns: bool = False) -> None:
        """What is queued (and the columns' records when ``columns``: only from the control
        loop's thread, or at the end once nothing appends to them), as one encoded frame
        appended to :attr:`_frames` (the caller holds the lock)."""
        queue = self.queue
        n = len(queue)  # the loop appends meanwhile: take n, each popleft atomic (C loop)
        batch = list(starmap(queue.popleft, repeat((), n)))
        self._taken += n
        taken: list[Columns] = []
        if columns or final:  # after the queue's: each channel's records in order
            for buffer in self.columns:
                entry = buffer.entry()  # its lists themselves: encoded, then emptied
                if entry is not None:
                    batch.append(entry)
                    taken.append(buffer)
                    self._taken += 1
                    self._controls += 1
        if final:
            batch.append((STATS, self.queued, self.dropped, self.capacity))
        if batch:
            frame = bytearray(HEADER.size)
            self._encode_into(batch, frame, HEADER.size)
            HEADER.pack_into(frame, 0, len(frame) - HEADER.size)
            self._frames.append((frame, tally(batch)))
        for buffer in taken:
            buffer.taken_all()

    def _run(self) -> None:
        process = self._process
        assert process is not None and process.stdin is not None
        fd = process.stdin.fileno()
        try:
            while True:
                if self._loop is not None:  # the loop writes: wait for the end only
                    self._wake.wait()
                    self._wake.clear()
                    if not self._stop.is_set():
                        continue
                # At the end, not one more flush_interval: a loop-driven pipeline's first
                # wait above has already taken the stop's wake-up.
                woken = self._stop.is_set() or self._wake.wait(self.flush_interval)
                self._wake.clear()
                stopping = self._stop.is_set()
                if stopping:  # the last records: the tap has detached
                    os.set_blocking(fd, True)
                    with self._lock:
                        self._take(final=True)
                elif not woken:  # the loop handed nothing over for flush_interval
                    with self._lock:
                        self._take()
                self._write_frames(fd)
                if stopping:
                    break
        except BaseException as exc:  # the process died: what is left is dropped, and told
            self._fail(exc)
        finally:
            with contextlib.suppress(OSError):
                process.stdin.close()

    def _fail(self, exc: BaseException) -> None:
        """The writer process is gone: what is left is dropped, and told."""
        if self.error is None:
            self.error = exc
        log.error("recording_failed", error=repr(exc))
        with self._lock:
            self._dead = True
            # The frame being written is lost whole (the writer drops a partial frame), and
            # those after it: their records leave the queued count for the dropped one, like
            # the queue's.
            for _, lost in self._frames:
                self._taken -= lost.entries
                self._discard_tally(lost)
            self._frames.clear()
            self._offset = 0
            queue = self.queue
            self._discard(list(starmap(queue.popleft, repeat((), len(queue)))))
            if self._stop.is_set():  # nothing appends to the columns any more
                self.discard_columns()

    def _write_frames(self, fd: int) -> None:
        """Write the frames in order, blocking (each removed once written whole; the first
        from where the loop's last write left it)."""
        with self._io:
            frames = self._frames
            while frames:
                data = memoryview(frames[0][0])[self._offset :]
                while data:
                    try:
                        n = os.write(fd, data)
                    except BlockingIOError:  # the loop made it non-blocking meanwhile
                        select.select([], [fd], [], 1.0)
                        continue
                    data = data[n:]
                    self._offset += n
                self._offset = 0
                frames.popleft()

    def discard_columns(self) -> None:
        """Count the records the columns hold as dropped (the writer is gone; from the
        control loop's thread, or once nothing appends to them)."""
        for columns in self.columns:
            lost = columns.discard()
            self.dropped += lost
            self._columns_lost += lost

    def _discard(self, entries: list[tuple[Any, ...]]) -> None:
        """Count ``entries`` (taken out of the count of queued ones) as dropped."""
        self._discard_tally(tally(entries))

    def _discard_tally(self, lost: Tally) -> None:
        self.dropped += lost.records + lost.batched + lost.columns
        self._columns_lost += lost.columns  # records handed over in a frame that was lost
        self._controls -= lost.controls
        self._batch_lost += lost.batched - lost.batches
