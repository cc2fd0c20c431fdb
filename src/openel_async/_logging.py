"""The library's logging default: silent until the application configures logging.

Every module logs through structlog (``get_logger(__name__)``). Unconfigured,
structlog prints every event to stdout, which a library must not do. So, when
``openel_async`` is imported and structlog is not configured yet, :func:`configure_default`
routes every event to the standard :mod:`logging` module, through the logger named after the
module that logs (``openel_async.component``, ``openel_sim.motor``, ...). The standard
``logging`` default then applies: nothing below WARNING is shown until the application
configures logging, e.g.::

    import logging
    logging.basicConfig(level=logging.INFO)  # the framework's info events on stderr

An application that configures structlog itself (before or after the import) keeps its own
configuration: this module never touches a configured structlog.
"""

from __future__ import annotations

import logging
from collections.abc import MutableMapping
from typing import Any

import structlog

__all__ = ["configure_default", "render_for_stdlib"]

_LEVELS = {
    "debug": logging.DEBUG,
    "info": logging.INFO,
    "warning": logging.WARNING,
    "warn": logging.WARNING,
    "error": logging.ERROR,
    "exception": logging.ERROR,
    "critical": logging.CRITICAL,
    "fatal": logging.CRITICAL,
}


def _value(value: object) -> str:
    text = str(value)
    return repr(value) if isinstance(value, str) and (not text or " " in text) else text


def render_for_stdlib(
    logger: Any, method_name: str, event_dict: MutableMapping[str, Any]
) -> tuple[tuple[Any, ...], dict[str, Any]]:
    """The last processor: drop an event its ``logging`` logger would not show (cheaply,
    before formatting), else hand it over as one readable message, ``event key=value ...``,
    with the exception or stack for ``logging`` to format."""
    is_enabled = getattr(logger, "isEnabledFor", None)
    if is_enabled is not None and not is_enabled(_LEVELS.get(method_name, logging.INFO)):
        raise structlog.DropEvent
    fields = dict(event_dict)
    event = fields.pop("event", "")
    kwargs: dict[str, Any] = {}
    exc_info = fields.pop("exc_info", None)
    if exc_info:
        kwargs["exc_info"] = exc_info
    if fields.pop("stack_info", False):
        kwargs["stack_info"] = True
    message = " ".join([str(event), *(f"{k}={_value(v)}" for k, v in fields.items())])
    return (message,), kwargs


def configure_default() -> None:
    """Route structlog to ``logging`` unless structlog is configured already (by the
    application: its configuration is left as it is)."""
    if structlog.is_configured():
        return
    structlog.configure(
        processors=[structlog.contextvars.merge_contextvars, render_for_stdlib],
        logger_factory=structlog.stdlib.LoggerFactory(),
        wrapper_class=structlog.stdlib.BoundLogger,
        # not cached: an application that configures structlog later gets its configuration
        # for every logger, including those that logged before
        cache_logger_on_first_use=False,
    )


configure_default()  # at the first use of a framework logger (openel_async.logs)
