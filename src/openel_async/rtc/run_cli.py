"""What ``openel-async run`` does the same for one profile and for a system of components:
the --duration/--virtual check, the message for an unreadable file, and running the
prepared ``main`` to its exit status and printed summary."""

from __future__ import annotations

import math
import signal
import sys
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Protocol

import anyio

from .errors import RTCError

__all__ = ["RunSummaryLike", "duration_problem", "finish_run", "read_problem", "single_error"]

PROG = "openel-async run"


class RunSummaryLike(Protocol):
    """A run's summary: its printed lines and the signal that stopped it, if any."""

    @property
    def stopped_by(self) -> str | None: ...

    def lines(self) -> list[str]: ...


def duration_problem(duration: float | None, virtual: bool) -> str | None:
    """What is wrong with ``--duration`` / ``--virtual``, or None."""
    if duration is not None and not (math.isfinite(duration) and duration > 0):
        return "--duration must be a number of seconds > 0"
    if virtual and duration is None:
        return "--virtual needs --duration (simulated time never ends)"
    return None


def read_problem(exc: OSError) -> str:
    """Why a profile or system file could not be read."""
    if isinstance(exc, FileNotFoundError):
        return f"no such file ({exc.strerror})"
    return f"cannot read: {exc}"


def single_error(exc: BaseException) -> BaseException:
    """The one exception inside (nested) single-exception groups of task groups."""
    while isinstance(exc, BaseExceptionGroup) and len(exc.exceptions) == 1:
        exc = exc.exceptions[0]
    return exc


def finish_run(path: Path, main: Callable[[], Awaitable[RunSummaryLike]]) -> int:
    """Run ``main`` on asyncio and print its summary; the exit status: 0 after a clean
    run, 1 when a lifecycle step failed (an RTCError, printed), 130 on KeyboardInterrupt,
    128 + the signal number when a signal ended the run. Any other error propagates."""
    try:
        summary = anyio.run(main, backend="asyncio")
    except KeyboardInterrupt:
        return 130
    except BaseException as exc:
        error = single_error(exc)
        if not isinstance(error, RTCError):
            raise
        print(
            f"{PROG}: {path}: {type(error).__name__} ({error.code.name}): {error}",
            file=sys.stderr,
        )
        return 1
    print("summary")
    for line in summary.lines():
        print("  " + line)
    if summary.stopped_by is not None:
        return 128 + int(signal.Signals[summary.stopped_by])
    return 0
