"""The flight recorder: every message of the tap written to an MCAP file by the Foxglove SDK's
MCAP writer (Rust; zstd chunks), in the writer process (:mod:`.sink_process`).

The writer closes a chunk every ``chunk_size`` bytes and writes it to the file at once, so a
run that is killed leaves a file readable up to its last complete chunk
(:func:`~openel_async.recording.reader.read_recording` reads such a file). At the end the
summary (statistics, indexes) and a ``openel_async.recorder`` metadata record (messages
written and dropped) are written.
"""

from __future__ import annotations

import os
from pathlib import Path

from .tap import Tap

__all__ = ["Recorder"]


class Recorder(Tap):
    """A :class:`~.tap.Tap` writing to the MCAP file ``path`` (and publishing to a Foxglove
    server too with ``foxglove=(host, port)``). See :mod:`openel_async.recording`."""

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        foxglove: tuple[str, int] | None = None,
        joint_period_ms: float = 20.0,
        timer_stats_ms: float = 100.0,
        capacity: int = 100_000,
        logs: bool = True,
        chunk_size: int = 64 * 1024,
    ) -> None:
        self.path = Path(path)
        super().__init__(
            record=self.path,
            foxglove=foxglove,
            joint_period_ms=joint_period_ms,
            timer_stats_ms=timer_stats_ms,
            capacity=capacity,
            logs=logs,
            chunk_size=chunk_size,
        )
