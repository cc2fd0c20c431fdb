"""The live view: the tap's messages published by the Foxglove SDK's WebSocket server, on
the same channels and schemas as the recorder, so that a live session and a recording look the
same in Foxglove.

The server binds to 127.0.0.1 by default (``host="0.0.0.0"`` to be reached from elsewhere).
Open https://app.foxglove.dev (or Foxglove desktop), "Open connection", Foxglove WebSocket,
``ws://127.0.0.1:8765``, then import the layout :data:`LAYOUT_PATH` (docs/recording.md).
"""

from __future__ import annotations

import os
from pathlib import Path

from .sinks import DEFAULT_HOST, DEFAULT_PORT, FoxgloveSink
from .tap import Tap

__all__ = ["DEFAULT_HOST", "DEFAULT_PORT", "LAYOUT_PATH", "FoxgloveSink", "LiveView"]

LAYOUT_PATH = Path(__file__).with_name("foxglove_layout.json")
"""The Foxglove layout shipped for the demos (joint plots, 3D, log, raw messages)."""


class LiveView(Tap):
    """A :class:`~.tap.Tap` publishing live on a Foxglove WebSocket server on ``host``:
    ``port`` (0: any free port; :attr:`url` once entered), and recording to the MCAP file
    ``record`` too if given."""

    def __init__(
        self,
        *,
        host: str = DEFAULT_HOST,
        port: int = DEFAULT_PORT,
        record: str | os.PathLike[str] | None = None,
        joint_period_ms: float = 20.0,
        timer_stats_ms: float = 100.0,
        capacity: int = 100_000,
        logs: bool = True,
    ) -> None:
        self.host = host
        super().__init__(
            record=record,
            foxglove=(host, port),
            joint_period_ms=joint_period_ms,
            timer_stats_ms=timer_stats_ms,
            capacity=capacity,
            logs=logs,
        )

    @property
    def url(self) -> str:
        """``ws://host:port`` (the port the server got, once entered)."""
        return f"ws://{self.host}:{self.pipeline.port}"
