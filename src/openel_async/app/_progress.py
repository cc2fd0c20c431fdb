"""A one-line live progress display that degrades to periodic lines off a terminal.

On a terminal the line is a rich ``Live`` region: anything written to ``sys.stdout`` or
``sys.stderr`` meanwhile (log records, an app's prints) is printed above it, so progress and
other output never share a line; :meth:`LiveLine.finish` leaves the last progress line on the
screen. Off a terminal (a pipe, a file) every update at most once per second is one plain line.
"""

from __future__ import annotations

import sys
import time
from typing import TYPE_CHECKING, TextIO

if TYPE_CHECKING:  # rich (~0.1 s to import) loads when a line first shows on a terminal
    from rich.live import Live
    from rich.text import Text

__all__ = ["LiveLine"]


class LiveLine:
    """Progress of a run, one line, on ``stream`` (default ``sys.stdout``).

    :meth:`update` replaces the line (at most every ``interval_s`` seconds unless ``force``:
    0.25 s on a terminal, at least 1 s off one, where each update is a new line);
    :meth:`finish` ends the display (call it in a ``finally``: it restores the terminal)."""

    def __init__(self, stream: TextIO | None = None, *, interval_s: float = 0.25) -> None:
        self.stream = stream or sys.stdout
        self.tty = _is_tty(self.stream)
        self.interval_s = interval_s if self.tty else max(interval_s, 1.0)
        self._last = 0.0
        self._live: Live | None = None

    def update(self, text: str, *, force: bool = False) -> None:
        """Show ``text`` as the progress line (skipped when the last update is more recent
        than ``interval_s``, unless ``force``)."""
        now = time.monotonic()
        if not force and now - self._last < self.interval_s:
            return
        self._last = now
        if not self.tty:
            self.stream.write(text + "\n")
            self.stream.flush()
            return
        from rich.text import Text

        line = Text(text, no_wrap=True, overflow="ellipsis")
        if self._live is None:
            self._live = self._start(line)
        else:
            self._live.update(line, refresh=True)

    def _start(self, line: Text) -> Live:
        from rich.console import Console
        from rich.live import Live

        # soft_wrap: a long line printed above is wrapped by the terminal, not broken by rich
        console = Console(file=self.stream, highlight=False, soft_wrap=True)
        # Output to stdout and stderr is printed above the line while it shows -- when that
        # stream is on the terminal too (stderr redirected to a file stays in the file).
        live = Live(
            line,
            console=console,
            auto_refresh=False,  # refreshed by update(): no thread
            transient=False,  # finish() leaves the last line
            redirect_stdout=self.stream is sys.stdout or _is_tty(sys.stdout),
            redirect_stderr=_is_tty(sys.stderr),
        )
        live.start(refresh=True)
        return live

    def finish(self) -> None:
        """End the display, the last progress line left on the screen."""
        live, self._live = self._live, None
        if live is not None:
            live.stop()


def _is_tty(stream: TextIO | None) -> bool:
    try:
        return stream is not None and stream.isatty()
    except ValueError:  # closed
        return False
