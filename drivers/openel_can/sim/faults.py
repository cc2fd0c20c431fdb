"""Bus-level fault injection: a host adapter that goes bus-off or is unplugged.

:class:`BusLink` is a switch between the host and a python-can channel. Give
``CanBus(bus_factory=link.open)`` (reopenable, like an interface given by keyword
arguments) or ``CanBus(link.open())`` (a given bus object: recovery retries ``recv`` on
it). :meth:`BusLink.fail` makes every bus of the link raise ``can.CanOperationError`` on
``recv`` and ``send`` (frames arriving meanwhile are lost), and with
``unplugged=True`` opening a new one fails too (``can.CanInitializationError``), like a
USB adapter pulled out; :meth:`BusLink.restore` brings the bus back.
"""

from __future__ import annotations

import time
from typing import Any

import can

__all__ = ["BusLink", "FlakyBus"]

_SLICE_S = 0.005


class BusLink:
    """The switch shared by the :class:`FlakyBus` objects it opens."""

    def __init__(self, channel: str, *, interface: str = "virtual", **bus_kwargs: Any) -> None:
        self.channel = channel
        self.interface = interface
        self.bus_kwargs = bus_kwargs
        self.down = False
        self.unplugged = False
        self.reason = "bus-off"
        self.opened = 0
        self.failed_opens = 0

    def open(self) -> FlakyBus:
        """Open a new bus on the channel (a ``bus_factory`` for :class:`~openel_can.bus.CanBus`)."""
        if self.down and self.unplugged:
            self.failed_opens += 1
            raise can.CanInitializationError(f"{self.channel}: adapter not found ({self.reason})")
        self.opened += 1
        inner = can.Bus(interface=self.interface, channel=self.channel, **self.bus_kwargs)
        return FlakyBus(inner, self)

    def fail(self, reason: str = "bus-off", *, unplugged: bool = False) -> None:
        self.reason = reason
        self.unplugged = unplugged
        self.down = True

    def restore(self) -> None:
        self.down = False
        self.unplugged = False


class FlakyBus(can.BusABC):
    """A python-can bus wrapping another one, failing while its :class:`BusLink` is down."""

    def __init__(self, inner: can.BusABC, link: BusLink) -> None:
        self._inner = inner
        self._link = link
        super().__init__(channel=link.channel)
        self.channel_info = f"flaky {inner.channel_info}"

    def _check(self) -> None:
        if self._link.down:
            while True:  # frames on the wire meanwhile never reach a bus-off controller
                try:
                    if self._inner.recv(0.0) is None:
                        break
                except can.CanError:
                    break
            raise can.CanOperationError(f"{self._link.channel}: {self._link.reason}")

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            self._check()
            remaining = _SLICE_S if deadline is None else deadline - time.monotonic()
            msg = self._inner.recv(max(0.0, min(_SLICE_S, remaining)))
            if msg is not None:
                self._check()
                return msg, False
            if deadline is not None and time.monotonic() >= deadline:
                return None, False

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self._check()
        self._inner.send(msg, timeout)

    def shutdown(self) -> None:
        super().shutdown()
        self._inner.shutdown()
