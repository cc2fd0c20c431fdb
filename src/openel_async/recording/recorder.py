"""The flight recorder: every message of the tap written to an MCAP file (the ``mcap``
library's writer, zstd chunks), from the pipeline's thread.

The writer closes a chunk every ``chunk_size`` bytes and the thread flushes the file after
each batch, so a run that is killed leaves a file readable up to its last complete chunk
(:func:`~openel_async.recording.reader.read_recording` reads such a file). At the end the
summary (statistics, indexes) and a ``openel_async.recorder`` metadata record (messages
written and dropped) are written.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import IO

from mcap.writer import CompressionType, Writer

from .pipeline import PipelineStats
from .schemas import MESSAGE_ENCODING, SCHEMA_ENCODING, ChannelSpec
from .tap import Tap

__all__ = ["PROFILE", "McapSink", "Recorder"]

PROFILE = "openel_async"
LIBRARY = "openel-async recorder"


class McapSink:
    """Writes to an MCAP file (opened at once: an unwritable path fails here, not later)."""

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        chunk_size: int = 64 * 1024,
        metadata: dict[str, str] | None = None,
    ) -> None:
        self.path = Path(path)
        self._file: IO[bytes] = open(self.path, "wb")  # noqa: SIM115 (closed in close())
        self._writer = Writer(self._file, chunk_size=chunk_size, compression=CompressionType.ZSTD)
        self._writer.start(profile=PROFILE, library=LIBRARY)
        if metadata:
            self._writer.add_metadata("openel_async.run", metadata)
        self._file.flush()
        self._schemas: dict[str, int] = {}
        self._channels: dict[int, int] = {}
        self._sequence = 0

    def add_channel(self, channel: ChannelSpec) -> None:
        schema = channel.schema
        schema_id = self._schemas.get(schema.name)
        if schema_id is None:
            schema_id = self._writer.register_schema(schema.name, SCHEMA_ENCODING, schema.data)
            self._schemas[schema.name] = schema_id
        self._channels[channel.id] = self._writer.register_channel(
            channel.topic, MESSAGE_ENCODING, schema_id, channel.metadata
        )

    def write(self, channel: ChannelSpec, log_time_ns: int, data: bytes) -> None:
        self._sequence += 1
        self._writer.add_message(
            self._channels[channel.id], log_time_ns, data, log_time_ns, self._sequence
        )

    def flush(self) -> None:
        self._file.flush()

    def close(self, stats: PipelineStats) -> None:
        try:
            self._writer.add_metadata(
                "openel_async.recorder",
                {
                    "queued": str(stats.queued),
                    "written": str(stats.written),
                    "dropped": str(stats.dropped),
                    "capacity": str(stats.capacity),
                },
            )
            self._writer.finish()  # type: ignore[no-untyped-call]
        finally:
            self._file.close()


class Recorder(Tap):
    """A :class:`~.tap.Tap` writing to the MCAP file ``path`` (and publishing to a Foxglove
    server too with ``foxglove=(host, port)``). See :mod:`openel_async.recording`."""

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        foxglove: tuple[str, int] | None = None,
        joint_period_ms: float = 10.0,
        capacity: int = 100_000,
        logs: bool = True,
        chunk_size: int = 64 * 1024,
    ) -> None:
        self.path = Path(path)
        super().__init__(
            record=self.path,
            foxglove=foxglove,
            joint_period_ms=joint_period_ms,
            capacity=capacity,
            logs=logs,
            chunk_size=chunk_size,
        )
