"""Loggers of the framework and its drivers: structlog, bound on first use.

``get_logger(__name__)`` at module level costs nothing: structlog (and what it loads, rich
among them) is imported, and the library's default configuration applied
(:mod:`openel_async._logging`: events routed to the standard :mod:`logging` module, unless the
application configured structlog), only when a logger is first used. So a process that never
logs -- ``openel-async --help``, a short script -- never pays for it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

__all__ = ["configure_on_first_use", "ensure_configured", "get_logger"]

_pending: list[Callable[[], None]] = []


def configure_on_first_use(configure: Callable[[], None] | None) -> None:
    """Run ``configure`` (an application's structlog configuration) just before the first
    logger is used, instead of now -- a command that never logs never imports structlog.
    None forgets a pending one."""
    _pending[:] = [] if configure is None else [configure]


def ensure_configured() -> None:
    """Run the pending configuration now, if any (before reading or changing structlog's
    configuration from outside a logger)."""
    while _pending:
        _pending.pop()()


class LazyLogger:
    """A structlog logger for ``name``, made when one of its methods is first looked up."""

    __slots__ = ("_logger", "name")

    def __init__(self, name: str) -> None:
        self.name = name
        self._logger: Any = None

    def __getattr__(self, attribute: str) -> Any:
        logger = self._logger
        if logger is None:
            ensure_configured()
            import structlog

            from . import _logging  # noqa: F401  (imports structlog; the library's default)

            logger = self._logger = structlog.get_logger(self.name)
        return getattr(logger, attribute)

    def __repr__(self) -> str:
        return f"<LazyLogger {self.name}>"


def get_logger(name: str) -> Any:
    """The logger of module ``name`` (``log = get_logger(__name__)``): a structlog bound
    logger (``log.info("event", key=value)``), imported and configured on first use."""
    return LazyLogger(name)
