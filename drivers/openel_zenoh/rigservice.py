"""The shape shared by a served rig's own queryables (its e-stop, its lifecycle and
configuration): a few key expressions under ``openel/<ns>/rig/``, each query moved from
Zenoh's threads into the event loop through a bounded inbox (one ``call_soon_threadsafe``
per batch) with the kind of request it is, one task answering them, and every query
answered -- refused when the inbox is full or the server closes."""

from __future__ import annotations

import contextlib
from collections.abc import Sequence
from types import TracebackType
from typing import Any, Generic, Self, TypeVar, cast

import anyio
import anyio.abc
import zenoh

from openel_async.errors import ReturnCode
from openel_async.logs import get_logger

from .bridge import ThreadInbox

__all__ = ["RigQueryService", "reply"]

log = get_logger(__name__)

KindT = TypeVar("KindT")


def reply(query: zenoh.Query, payload: bytes) -> None:
    """Answer ``query`` with ``payload`` and drop it (a failed reply is logged)."""
    try:
        query.reply(query.key_expr, payload)
    except zenoh.ZError as exc:
        log.warning("rig_query_reply_failed", key=str(query.key_expr), error=str(exc))
    finally:
        cast(Any, query).drop()


class RigQueryService(Generic[KindT]):
    """Declares :meth:`queryables` (``async with``) and runs :meth:`serve` on their
    queries; a subclass answers (:meth:`serve`) and refuses (:meth:`refuse`) them."""

    inbox_size = 256

    def __init__(self, session: zenoh.Session) -> None:
        self.session = session
        self._declared: list[Any] = []
        self._inbox: ThreadInbox[tuple[KindT, zenoh.Query]] | None = None
        self._tg: anyio.abc.TaskGroup | None = None

    # -- what a subclass supplies ------------------------------------------------------------
    def queryables(self) -> Sequence[tuple[str, KindT]]:
        """The key expressions to declare, each with the kind its queries are."""
        raise NotImplementedError

    def refuse(self, kind: KindT, query: zenoh.Query, code: ReturnCode, text: str) -> None:
        """An error reply to ``query`` (any thread: touches no component)."""
        raise NotImplementedError

    async def serve(self, inbox: ThreadInbox[tuple[KindT, zenoh.Query]]) -> None:
        """Answer the queries of ``inbox`` (runs until cancelled)."""
        raise NotImplementedError

    async def closing(self) -> None:
        """Called first when the service closes (the default: nothing)."""

    # -- lifetime -----------------------------------------------------------------------------
    async def __aenter__(self) -> Self:
        inbox = self._inbox = ThreadInbox(self.inbox_size, on_drop=self._refuse_dropped)
        tg = anyio.create_task_group()
        await tg.__aenter__()
        self._tg = tg
        try:
            for key, kind in self.queryables():
                self._declared.append(
                    self.session.declare_queryable(
                        key,
                        zenoh.handlers.Callback(self._on_query(inbox, kind), indirect=False),
                        complete=True,
                    )
                )
            tg.start_soon(self.serve, inbox)
        except BaseException:
            await self._close()
            raise
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self._close()

    async def _close(self) -> None:
        await self.closing()
        for entity in self._declared:
            with contextlib.suppress(zenoh.ZError):
                cast(Any, entity).undeclare()
        self._declared.clear()
        if self._inbox is not None:
            self._inbox.close()
            for kind, query in self._inbox.take_all():
                self.refuse(kind, query, ReturnCode.HAL_NO_CONNECTED, "server shutting down")
        if self._tg is not None:
            self._tg.cancel_scope.cancel()
            await self._tg.__aexit__(None, None, None)
            self._tg = None

    # -- Zenoh threads ------------------------------------------------------------------------
    @staticmethod
    def _on_query(inbox: ThreadInbox[tuple[KindT, zenoh.Query]], kind: KindT) -> Any:
        def on_query(query: zenoh.Query) -> None:
            inbox.put((kind, query))

        return on_query

    def _refuse_dropped(self, item: tuple[KindT, zenoh.Query]) -> None:
        self.refuse(item[0], item[1], ReturnCode.HAL_NO_MEMORY, "server busy: dropped")
