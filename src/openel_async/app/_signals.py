"""Exit statuses of a command stopped by a signal, and SIGTERM outside the event loop.

Kept apart from the rest of :mod:`openel_async.app` (and free of anyio) so that the command
line's start (``openel-async --help``) imports only this.
"""

from __future__ import annotations

import contextlib
import signal
from types import FrameType

__all__ = [
    "EXIT_SIGINT",
    "EXIT_SIGTERM",
    "STOP_SIGNALS",
    "exit_code",
    "install_sigterm_handler",
    "interrupt_code",
]

EXIT_SIGINT = 128 + signal.SIGINT  # 130
EXIT_SIGTERM = 128 + signal.SIGTERM  # 143
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


def exit_code(signum: int) -> int:
    """The exit status of a command stopped by ``signum``: 128 + its number (130, 143)."""
    return 128 + int(signum)


def _raise_terminated(signum: int, frame: FrameType | None) -> None:
    raise SystemExit(exit_code(signum))


def install_sigterm_handler() -> None:
    """SIGTERM outside :func:`run_interruptible` raises ``SystemExit(143)`` (clean-ups run,
    no traceback) instead of killing the process on the spot."""
    with contextlib.suppress(ValueError):  # not the main thread: leave it alone
        signal.signal(signal.SIGTERM, _raise_terminated)


def interrupt_code(exc: BaseException) -> int | None:
    """The exit status of a ``KeyboardInterrupt`` or ``SystemExit`` from a signal, also inside
    (nested) exception groups of task groups; None for anything else."""
    while isinstance(exc, BaseExceptionGroup) and len(exc.exceptions) == 1:
        exc = exc.exceptions[0]
    if isinstance(exc, KeyboardInterrupt):
        return EXIT_SIGINT
    if isinstance(exc, SystemExit) and exc.code in (EXIT_SIGINT, EXIT_SIGTERM):
        return int(exc.code)
    return None
