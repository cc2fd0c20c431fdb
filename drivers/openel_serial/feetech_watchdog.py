"""HostWatchdog: the Feetech port's watchdog thread (the STS/SCS have no bus watchdog).

Fed by the poller from the event loop; when no cycle completed for ``timeout_s`` (a stalled
loop) it writes :data:`TORQUE_OFF_BROADCAST` (a broadcast WRITE of Torque Enable (40) = 0)
straight to the port's file descriptor, so the servos go limp while the loop is stalled. See
:mod:`openel_serial.feetech_port` for what it cannot cover.
"""

from __future__ import annotations

import os
import threading
import time
from typing import Final

import anyio.to_thread

from openel_serial import feetech as ft
from openel_serial.link import SerialLink

__all__ = ["TORQUE_OFF_BROADCAST", "HostWatchdog"]

TORQUE_OFF_BROADCAST: Final = ft.encode(
    ft.Write(ft.BROADCAST_ID, ft.STS.TORQUE_ENABLE.address, b"\x00")
)
"""``FF FF FE 04 03 28 00 D2``: every servo on the bus, torque off (no status comes back)."""


class HostWatchdog:
    """The port's watchdog thread (see the module docstring): fed by the poller from the
    event loop; past ``timeout_s`` without a feed it writes :data:`TORQUE_OFF_BROADCAST` to
    the port's fd (twice, in case a partial packet was on the wire) and records the trip."""

    def __init__(self, link: SerialLink, url: str) -> None:
        self._link = link
        self._url = url
        self._lock = threading.Lock()
        self._timeout: float | None = None
        self._last_feed = time.monotonic()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.tripped_after: float | None = None
        """Seconds without a feed when it last tripped (None: not tripped since cleared)."""
        self.trips = 0

    @property
    def timeout(self) -> float | None:
        return self._timeout

    def feed(self) -> None:
        self._last_feed = time.monotonic()

    def arm(self, timeout_s: float) -> None:
        with self._lock:
            self._timeout = timeout_s
            self._last_feed = time.monotonic()
            if self._thread is None:
                self._stop.clear()
                self._thread = threading.Thread(
                    target=self._run, name=f"feetech-host-watchdog {self._url}", daemon=True
                )
                self._thread.start()

    def disarm(self) -> None:
        with self._lock:
            self._timeout = None

    def take_trip(self) -> float | None:
        """The trip's duration if it tripped since the last call (then clears it)."""
        with self._lock:
            tripped, self.tripped_after = self.tripped_after, None
            if tripped is not None:
                self._last_feed = time.monotonic()  # the loop that asks is running
            return tripped

    async def stop(self) -> None:
        thread = self._thread
        self._thread = None
        self._timeout = None
        self._stop.set()
        if thread is not None:
            await anyio.to_thread.run_sync(thread.join, 1.0)

    def _run(self) -> None:
        while True:
            timeout = self._timeout
            period = 0.05 if timeout is None else max(0.001, timeout / 4)
            if self._stop.wait(period):
                return
            with self._lock:
                timeout = self._timeout
                if timeout is None or self.tripped_after is not None:
                    continue
                silent = time.monotonic() - self._last_feed
                if silent <= timeout:
                    continue
                fd = self._link.fileno()
                if fd is None:
                    continue
                try:
                    os.write(fd, TORQUE_OFF_BROADCAST * 2)
                except OSError:
                    continue  # the port is gone: the loop will see it
                self.tripped_after = silent
                self.trips += 1
