"""The MCAP file of the flight recorder, written by the Foxglove SDK's MCAP writer (Rust; zstd
chunks) in the writer process (:mod:`.sink_process`), which imports only this of the recorder.

The writer closes a chunk every ``chunk_size`` bytes and writes it to the file at once, so a
run that is killed leaves a file readable up to its last complete chunk. At the end the
summary (statistics, indexes) and a ``openel_async.recorder`` metadata record (messages
written and dropped) are written.
"""

from __future__ import annotations

import os
from pathlib import Path

import foxglove
from foxglove.mcap import MCAPWriteOptions

from .sinks import PipelineStats

__all__ = ["PROFILE", "McapSink"]

PROFILE = "openel_async"


class McapSink:
    """An MCAP file written from every channel of ``context`` (opened at once: an unwritable
    path fails here, not later)."""

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        context: foxglove.Context,
        chunk_size: int = 64 * 1024,
        metadata: dict[str, str] | None = None,
    ) -> None:
        self.path = Path(path)
        options = MCAPWriteOptions(
            chunk_size=chunk_size, profile=PROFILE, compression_threads=0
        )  # compression in this thread: the writer process is the recorder's one core
        self._writer = foxglove.open_mcap(
            self.path, allow_overwrite=True, context=context, writer_options=options
        )
        if metadata:
            self._writer.write_metadata("openel_async.run", metadata)

    def close(self, stats: PipelineStats) -> None:
        try:
            self._writer.write_metadata(
                "openel_async.recorder",
                {
                    "queued": str(stats.queued),
                    "written": str(stats.written),
                    "dropped": str(stats.dropped),
                    "capacity": str(stats.capacity),
                },
            )
        finally:
            self._writer.close()
