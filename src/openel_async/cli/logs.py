"""Logging of the command line: the CLI is the application, so it configures structlog and
the standard ``logging`` module (the library only routes structlog to ``logging``,
``openel_async._logging``).

Log lines go to standard error, one record a line, rendered for people (``console``) or as
JSON, at the level the options select (default: warnings and errors). The handler writes to
``sys.stderr`` as it is when a record is emitted: while a :class:`~openel_async.app.LiveLine`
shows progress on the terminal, that is the live display's stand-in, which prints the line
above the progress line, so a log record and the progress never share a line.
"""

from __future__ import annotations

import logging
import sys
from typing import TYPE_CHECKING

from ..logs import configure_on_first_use, ensure_configured
from .options import DEFAULT_LEVEL, LEVELS

if TYPE_CHECKING:
    import structlog

__all__ = ["LEVELS", "configure_logging"]


class _StderrHandler(logging.Handler):
    """Each record on the current ``sys.stderr``, one line."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            line = self.format(record)
            stream = sys.stderr
            stream.write(line + "\n")
            stream.flush()
        except Exception:
            self.handleError(record)


def configure_logging(
    log_format: str = "console", level: str = DEFAULT_LEVEL, *, defer: bool = False
) -> None:
    """Console (human) or JSON lines on stderr, filtered at ``level``; calling it again
    replaces the previous configuration.

    ``defer``: structlog (and rich, which its console renderer loads: ~0.3 s) is imported and
    configured only when the first logger is used (:func:`openel_async.logs.configure_on_first_use`)
    or the first record is shown -- for the commands that run no application code, which
    could use structlog directly; a process that never logs never loads it."""
    shown = getattr(logging, level.upper())
    # Events from INFO up run through the processors whatever is shown: a recording's /log
    # channel (openel_async.recording.Tap inserts itself before the last processor) keeps them.
    processed = min(shown, logging.INFO)
    handler = _StderrHandler(level=shown)
    handler.setFormatter(_LazyFormatter(log_format))
    root = logging.getLogger()
    for old in [h for h in root.handlers if isinstance(h, _StderrHandler)]:
        root.removeHandler(old)
    root.addHandler(handler)
    root.setLevel(processed)

    def configure() -> None:
        _configure_structlog(processed)

    if defer and "structlog" not in sys.modules:
        configure_on_first_use(configure)
    else:
        configure_on_first_use(None)
        configure()


def _shared() -> list[structlog.typing.Processor]:
    import structlog

    return [
        structlog.contextvars.merge_contextvars,
        structlog.processors.add_log_level,
        structlog.processors.TimeStamper(fmt="iso", utc=True),
        structlog.processors.StackInfoRenderer(),
    ]


def _configure_structlog(processed: int) -> None:
    import structlog

    structlog.configure(
        processors=[*_shared(), structlog.stdlib.ProcessorFormatter.wrap_for_formatter],
        logger_factory=structlog.stdlib.LoggerFactory(),
        wrapper_class=structlog.make_filtering_bound_logger(processed),
        cache_logger_on_first_use=False,
    )


class _LazyFormatter(logging.Formatter):
    """structlog's ProcessorFormatter for ``log_format``, built at the first record shown."""

    def __init__(self, log_format: str) -> None:
        super().__init__()
        self.log_format = log_format
        self._formatter: logging.Formatter | None = None

    def format(self, record: logging.LogRecord) -> str:
        if self._formatter is None:
            self._formatter = _processor_formatter(self.log_format)
        return self._formatter.format(record)


def _processor_formatter(log_format: str) -> logging.Formatter:
    import structlog

    ensure_configured()
    renderer: list[structlog.typing.Processor]
    if log_format == "json":
        renderer = [
            structlog.processors.format_exc_info,
            structlog.processors.JSONRenderer(),
        ]
    else:
        renderer = [
            structlog.dev.ConsoleRenderer(
                colors=sys.stderr.isatty(), exception_formatter=structlog.dev.plain_traceback
            )
        ]
    return structlog.stdlib.ProcessorFormatter(
        processors=[structlog.stdlib.ProcessorFormatter.remove_processors_meta, *renderer],
        foreign_pre_chain=_shared(),  # records of plain logging (asyncio, libraries)
    )


def reset_logging() -> None:
    """Undo :func:`configure_logging` (tests that call the CLI in-process): the library's
    default again."""
    import structlog

    from .._logging import configure_default

    root = logging.getLogger()
    for old in [h for h in root.handlers if isinstance(h, _StderrHandler)]:
        root.removeHandler(old)
    root.setLevel(logging.WARNING)
    configure_on_first_use(None)
    structlog.reset_defaults()
    configure_default()
