"""What the writer process (:mod:`.sink_process`) opens and reports, without the app side's
machinery: a writer for ``--record``/``--foxglove`` imports the Foxglove SDK, msgspec and
these, not the pipeline's (asyncio, subprocess) nor the taps' (the framework, structlog);
the app's process imports them with the pipeline, without the SDK.

:class:`FoxgloveSink` logs nothing: the app's process reports the server's address (the
writer's ready line carries its port)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    import foxglove

__all__ = ["BACKLOG", "DEFAULT_HOST", "DEFAULT_PORT", "FoxgloveSink", "PipelineStats", "Sink"]


class Sink(Protocol):
    """What the writer process opens on its Foxglove SDK context (:class:`~.mcap_sink.McapSink`,
    :class:`~.live.FoxgloveSink`); closed with the final statistics."""

    def close(self, stats: PipelineStats) -> None: ...


@dataclass(frozen=True, slots=True)
class PipelineStats:
    queued: int
    """Records the control loop handed over."""
    written: int
    """Messages written to the sinks."""
    dropped: int
    """Records not written: the queue was full (the writer fell behind)."""
    capacity: int


DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765
BACKLOG = 65_536
"""Messages the server buffers per client (the SDK's ``message_backlog_size``; its default,
1 024, is less than one of the writer process's batches at the control loop's full speed):
beyond it the oldest are dropped for that client."""


class FoxgloveSink:
    """A Foxglove WebSocket server publishing every channel of ``context`` (``port=0``: any
    free port, see :attr:`port`; ``backlog``: messages buffered per client, :data:`BACKLOG`)."""

    def __init__(
        self,
        *,
        context: foxglove.Context,
        host: str = DEFAULT_HOST,
        port: int = DEFAULT_PORT,
        name: str = "openel-async",
        backlog: int = BACKLOG,
    ) -> None:
        import foxglove  # (the app's process imports this module without the SDK)

        self.server = foxglove.start_server(
            name=name, host=host, port=port, context=context, message_backlog_size=backlog
        )
        self.host = host
        self.port: int = self.server.port

    def close(self, stats: PipelineStats) -> None:
        self.server.stop()
