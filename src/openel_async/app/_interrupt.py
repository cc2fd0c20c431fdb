"""Stopping a command on SIGINT (Ctrl-C) or SIGTERM: promptly, cleanly, with a known status.

Every long-running command runs its work through :func:`run_interruptible`: the first SIGINT
or SIGTERM cancels the work (its ``finally`` blocks and ``async with`` exits run: devices
closed, live line ended); further signals while it cleans up are logged and ignored.  The
command then prints a short summary and exits with :func:`exit_code` (130 for SIGINT, 143
for SIGTERM: 128 + the signal number, as a shell reports a process killed by it).

Outside the event loop (imports, argument checks, printing), :func:`install_sigterm_handler`
turns SIGTERM into ``SystemExit(143)`` and the CLI's ``main`` turns ``KeyboardInterrupt`` into
130, so no signal ends a command with a traceback.

Output files are written through :func:`atomic_output`: a file is either complete or absent
(a temporary name, renamed when written; removed when interrupted or failed).  The files a
command wrote are collected by :func:`collect_written` for its summary; a file written by
other means (a recording, closed by its writer process) is counted with :func:`note_written`.
"""

from __future__ import annotations

import contextlib
import os
import signal
import time
from collections.abc import Awaitable, Callable, Iterator
from contextvars import ContextVar
from dataclasses import dataclass, field
from pathlib import Path
from typing import TypeVar

import anyio
from anyio.abc import TaskStatus

from openel_async.logs import get_logger

from ._signals import STOP_SIGNALS, exit_code

__all__ = [
    "Interrupted",
    "atomic_output",
    "collect_written",
    "note_written",
    "run_interruptible",
]

log = get_logger(__name__)

T = TypeVar("T")

_written: ContextVar[list[Path] | None] = ContextVar("openel_cli_written", default=None)
_details: ContextVar[dict[Path, str] | None] = ContextVar("openel_cli_details", default=None)


@dataclass(frozen=True, slots=True)
class Interrupted:
    """The work was stopped by a signal before it finished."""

    signum: signal.Signals
    elapsed_s: float
    """Real time from the start of the work to the end of its clean-up."""
    cleanup_error: str | None = None
    """An error raised while the work was being cancelled (logged, not raised)."""
    files: list[Path] = field(default_factory=list)
    """Complete files the work wrote before it was stopped."""
    details: dict[Path, str] = field(default_factory=dict)
    """What the summary says of some of them (:func:`note_written`)."""

    @property
    def exit_code(self) -> int:
        return exit_code(self.signum)

    def lines(self) -> list[str]:
        """The summary of an interrupted command."""
        out = [f"interrupted        by {self.signum.name} after {self.elapsed_s:.2f} s"]
        if self.cleanup_error is not None:
            out.append(f"clean-up error     {self.cleanup_error}")
        if self.files:
            for path in self.files:
                detail = self.details.get(path)
                out.append(f"file written       {path}" + (f" ({detail})" if detail else ""))
        else:
            out.append("files              none written")
        return out


async def _watch(
    work: anyio.CancelScope,
    caught: list[signal.Signals],
    before_cancel: Callable[[], Awaitable[None]] | None,
    *,
    task_status: TaskStatus[None] = anyio.TASK_STATUS_IGNORED,
) -> None:
    with anyio.open_signal_receiver(*STOP_SIGNALS) as signals:
        task_status.started()
        async for signum in signals:
            if caught:
                log.warning("signal_ignored", signal=signum.name, reason="already stopping")
                continue
            log.info("signal_received", signal=signum.name)
            caught.append(signum)
            if before_cancel is not None:
                try:
                    await before_cancel()
                except Exception as exc:  # the work is cancelled all the same
                    log.error("before_cancel_failed", error=repr(exc))
            work.cancel()


async def run_interruptible(
    work: Callable[[], Awaitable[T]],
    before_cancel: Callable[[], Awaitable[None]] | None = None,
) -> T | Interrupted:
    """Run ``work()`` until it returns or SIGINT/SIGTERM arrives (then cancel it and wait for
    its clean-up, bounded only by the work's own bounded waits).

    Returns the work's result, or :class:`Interrupted` when a signal stopped it.  The signal
    handlers are installed (through ``anyio.open_signal_receiver``) before the work starts and
    kept until its clean-up is over, so a second Ctrl-C cannot interrupt the clean-up; the
    previous SIGTERM handler is restored afterwards. ``before_cancel`` (bounded by its own
    waits) runs when the signal arrives, before the work is cancelled: what needs the work's
    tasks alive (a rig's safe stop, whose replies come through its buses' tasks).
    """
    previous_sigterm = signal.getsignal(signal.SIGTERM)
    caught: list[signal.Signals] = []
    written: list[Path] = []
    details: dict[Path, str] = {}
    token = _written.set(written)
    details_token = _details.set(details)
    start = time.monotonic()
    scope = anyio.CancelScope()
    results: list[T] = []
    error: str | None = None
    try:
        async with anyio.create_task_group() as tg:
            await tg.start(_watch, scope, caught, before_cancel)
            try:
                with scope:
                    results.append(await work())
            except Exception as exc:
                if not caught:
                    raise
                error = f"{type(exc).__name__}: {exc}"
                log.warning("interrupted_cleanup_failed", error=error)
            tg.cancel_scope.cancel()
    finally:
        _written.reset(token)
        _details.reset(details_token)
        with contextlib.suppress(ValueError, TypeError, OSError):
            signal.signal(signal.SIGTERM, previous_sigterm)
    if results:
        return results[0]
    # Not finished: cancelled by the signal caught (the work cannot return without a result).
    return Interrupted(caught[0], time.monotonic() - start, error, written, details)


@contextlib.contextmanager
def atomic_output(path: Path) -> Iterator[Path]:
    """Yield a temporary path next to ``path`` (same suffix, so writers that go by the suffix
    pick the same format); when the block ends normally the temporary file, if written,
    replaces ``path``; on any exception or cancellation it is removed.  ``path`` is thus either
    complete or untouched.  Records ``path`` for :func:`collect_written`."""
    temporary = path.with_name(f".{path.stem}.partial-{os.getpid()}{path.suffix}")
    try:
        yield temporary
        if temporary.exists():
            os.replace(temporary, path)
            written = _written.get()
            if written is not None:
                written.append(path)
    finally:
        with contextlib.suppress(FileNotFoundError):
            temporary.unlink()


def note_written(path: Path, detail: str = "") -> None:
    """Count ``path``, a complete file written by other means than :func:`atomic_output` (a
    recording), among this command's files (:func:`collect_written`); ``detail`` is what its
    summary line says of it."""
    written = _written.get()
    if written is not None:
        written.append(path)
        details = _details.get()
        if details is not None and detail:
            details[path] = detail


def collect_written() -> list[Path]:
    """The files written through :func:`atomic_output` so far in this command (empty outside
    :func:`run_interruptible`)."""
    return list(_written.get() or [])
