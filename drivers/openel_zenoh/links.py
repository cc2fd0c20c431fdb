"""The notice stream of one client of a SurfaceServer (docs/remote.md, "Nothing lost
untold"): its ``completed``, ``notify_event`` and ``notify_error``, numbered and published
from the loop, the first of a loop turn at once and the others of that turn in one batch
at its end, from a bounded buffer (``OUTBOX_SIZE``; what it drops leaves a gap in the
numbering that the client reports)."""

from __future__ import annotations

import contextlib
from collections import deque
from threading import get_ident
from typing import TYPE_CHECKING, Any, cast

import zenoh

from openel_async.errors import ReturnCode
from openel_async.logs import get_logger

from . import wire

if TYPE_CHECKING:
    from .server import SurfaceServer

log = get_logger(__name__)

OUTBOX_SIZE = 65536
"""Notices one client may have waiting to be published; older ones are dropped (counted)."""


class ClientLink:
    """The ApplicationBase of one remote client inside the server's Surface."""

    def __init__(self, server: SurfaceServer, client: str) -> None:
        self.server = server
        self.client = client
        self.publisher = server.session.declare_publisher(
            server.keys.notices(client), congestion_control=zenoh.CongestionControl.DROP
        )
        self.next_index = 0
        self.pending: deque[tuple[int, wire.Notice]] = deque()
        self.dropped = 0
        self.flush_scheduled = False
        self.closed = False

    def completed(self, command_id: str, status: ReturnCode) -> None:
        self._add(wire.CompletedNotice(command_id, int(status)))

    def notify_event(self, event_id: str, event_type: str, subscribe_id: int) -> None:
        detail = self.server.surface.get_event_detail(event_id)
        self._add(wire.EventNotice(event_id, event_type, subscribe_id, detail))

    def notify_error(self, error_id: str, error_type: str) -> None:
        detail = self.server.surface.get_error_detail(error_id)
        self._add(wire.ErrorNotice(error_id, error_type, detail))

    def _add(self, notice: wire.Notice) -> None:
        if self.closed:
            return
        self.pending.append((self.next_index, notice))
        self.next_index += 1
        if len(self.pending) > OUTBOX_SIZE:
            self.pending.popleft()
            self.dropped += 1
        if not self.flush_scheduled:
            # The first notice of a loop turn goes at once (a completion reaches its client
            # without waiting for the rest of the turn), those after it in the turn's batch.
            self.flush_scheduled = True
            self.server.schedule_flush(self)
            if get_ident() == self.server.loop_thread:  # not in a section on Zenoh's thread
                self.publish()

    def flush(self) -> None:
        self.flush_scheduled = False
        self.publish()

    def publish(self) -> None:
        """Publish the pending notices now, in batches of at most 512."""
        if self.closed:
            return
        while self.pending:
            first = self.pending[0][0]
            batch: list[wire.Notice] = []
            index = first
            while self.pending and self.pending[0][0] == index and len(batch) < 512:
                batch.append(self.pending.popleft()[1])
                index += 1
            try:
                self.publisher.put(wire.encoder.encode(wire.NoticeBatch(first, batch)))
            except zenoh.ZError as exc:
                log.warning("notice_publish_failed", client=self.client, error=str(exc))

    def close(self) -> None:
        self.closed = True
        _undeclare(self.publisher)


def _undeclare(entity: object) -> None:
    with contextlib.suppress(zenoh.ZError):
        cast(Any, entity).undeclare()
