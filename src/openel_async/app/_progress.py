"""A one-line live progress display that degrades to periodic lines off a terminal."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class LiveLine:
    def __init__(self, stream: TextIO | None = None, *, interval_s: float = 0.25) -> None:
        self.stream = stream or sys.stdout
        self.tty = self.stream.isatty()
        self.interval_s = interval_s if self.tty else max(interval_s, 1.0)
        self._last = 0.0
        self._width = 0

    def update(self, text: str, *, force: bool = False) -> None:
        now = time.monotonic()
        if not force and now - self._last < self.interval_s:
            return
        self._last = now
        if self.tty:
            pad = max(0, self._width - len(text))
            self.stream.write("\r" + text + " " * pad)
            self._width = len(text)
        else:
            self.stream.write(text + "\n")
        self.stream.flush()

    def finish(self) -> None:
        if self.tty and self._width:
            self.stream.write("\n")
            self.stream.flush()
            self._width = 0
