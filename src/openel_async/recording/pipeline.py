"""The recorder's and live view's pipeline: a bounded queue filled by the control loop without
blocking, emptied by a thread of its own that encodes the messages (JSON) and hands them to
the sinks (an MCAP file, the Foxglove server).

The control loop only appends to a deque (one C call); a full queue drops the message and
counts it (:attr:`PipelineStats.dropped`). The thread wakes every ``flush_interval`` seconds,
writes what is queued and flushes the sinks.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import msgspec
import structlog

from .schemas import ChannelSpec

__all__ = ["Pipeline", "PipelineStats", "Sink"]

log = structlog.get_logger(__name__)


class Sink(Protocol):
    """Where the pipeline's thread writes. Every method runs in that thread."""

    def add_channel(self, channel: ChannelSpec) -> None: ...

    def write(self, channel: ChannelSpec, log_time_ns: int, data: bytes) -> None: ...

    def flush(self) -> None: ...

    def close(self, stats: PipelineStats) -> None: ...


@dataclass(frozen=True, slots=True)
class PipelineStats:
    queued: int
    """Messages the control loop handed over."""
    written: int
    """Messages written to the sinks."""
    dropped: int
    """Messages not written: the queue was full (the thread fell behind)."""
    capacity: int


class Pipeline:
    """See the module docstring. ``start()`` then ``put()`` from the loop, ``stop()`` at the
    end (blocking: call it from a worker thread in async code)."""

    def __init__(
        self, sinks: Sequence[Sink], *, capacity: int = 100_000, flush_interval: float = 0.05
    ) -> None:
        if capacity < 1:
            raise ValueError(f"capacity must be >= 1, got {capacity}")
        self.sinks = list(sinks)
        self.capacity = capacity
        self.flush_interval = flush_interval
        self.channels: list[ChannelSpec] = []
        self._queue: deque[tuple[int, int, Any]] = deque()
        self._queued = 0
        self._written = 0
        self.dropped = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._encode = msgspec.json.Encoder().encode
        self.error: BaseException | None = None

    def add_channel(self, topic: str, schema: Any, metadata: dict[str, str] | None = None) -> int:
        """A new channel; returns its id (registered with the sinks before its messages)."""
        spec = ChannelSpec(len(self.channels), topic, schema, dict(metadata or {}))
        self.channels.append(spec)
        self._queue.append((-1, 0, spec))
        return spec.id

    def put(self, channel: int, log_time_ns: int, message: Any) -> None:
        """Queue ``message`` (a dict, encoded as JSON by the thread); never blocks."""
        queue = self._queue
        if len(queue) >= self.capacity:
            self.dropped += 1
            return
        queue.append((channel, log_time_ns, message))
        self._queued += 1

    @property
    def stats(self) -> PipelineStats:
        return PipelineStats(self._queued, self._written, self.dropped, self.capacity)

    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name="openel-recorder", daemon=True)
        self._thread.start()

    def stop(self) -> PipelineStats:
        """Write what is queued, close the sinks; returns the final statistics."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        return self.stats

    def _run(self) -> None:
        try:
            while not self._stop.wait(self.flush_interval):
                if self._drain():
                    for sink in self.sinks:
                        sink.flush()
            self._drain()
        except BaseException as exc:  # a broken sink: reported, the loop is never blocked
            self.error = exc
            log.error("recording_failed", error=repr(exc))
            self._queue.clear()
        finally:
            stats = self.stats
            for sink in self.sinks:
                try:
                    sink.close(stats)
                except Exception as exc:
                    log.error("recording_close_failed", sink=repr(sink), error=repr(exc))

    def _drain(self) -> int:
        queue = self._queue
        popleft = queue.popleft
        encode = self._encode
        channels = self.channels
        sinks = self.sinks
        count = 0
        while queue:
            channel, log_time, message = popleft()
            if channel < 0:
                for sink in sinks:
                    sink.add_channel(message)
                continue
            data = encode(message)
            spec = channels[channel]
            for sink in sinks:
                sink.write(spec, log_time, data)
            count += 1
        self._written += count
        return count
