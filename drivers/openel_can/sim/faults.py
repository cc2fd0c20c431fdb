"""Bus-level fault injection: a host adapter that goes bus-off or is unplugged.

:class:`BusLink` is a switch between the host and a python-can channel. Give
``CanBus(bus_factory=link.open)`` (reopenable, like an interface given by keyword
arguments) or ``CanBus(link.open())`` (a given bus object: recovery retries ``recv`` on
it). :meth:`BusLink.fail` makes every bus of the link raise ``can.CanOperationError`` on
``recv`` and ``send`` (frames arriving meanwhile are lost), and with
``unplugged=True`` opening a new one fails too (``can.CanInitializationError``), like a
USB adapter pulled out; :meth:`BusLink.restore` brings the bus back.

:func:`peers_on_thread` hosts simulated peers on a thread of their own with their own event
loop on the real clock, so they keep running (their watchdogs expire, their heartbeats go
out) while the application's event loop is blocked.
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from functools import partial
from typing import Any, Protocol

import anyio.abc
import can
from anyio.from_thread import BlockingPortal, start_blocking_portal

__all__ = ["BusLink", "FlakyBus", "ServingPeer", "peers_on_thread"]


class ServingPeer(Protocol):
    """A simulated peer that opens its own bus (:class:`~openel_can.sim.odrive.SimODrive`,
    :class:`~openel_can.sim.cia402.SimCiA402Drive`)."""

    async def serve(
        self,
        channel: str,
        *,
        interface: str = ...,
        task_status: anyio.abc.TaskStatus[None] = ...,
    ) -> None: ...


@contextmanager
def peers_on_thread(
    peers: Iterable[ServingPeer], channel: str, *, interface: str = "virtual"
) -> Iterator[BlockingPortal]:
    """Run ``peer.serve(channel)`` for every peer on one thread with its own event loop
    (the peers' clocks must be real-time ones, e.g. the default clock); all have started
    on entry and are cancelled on exit. Touch a peer's state from the test thread only
    through the portal (``portal.call``) when it must be consistent."""
    with start_blocking_portal() as portal:
        try:
            for peer in peers:
                portal.start_task(partial(peer.serve, interface=interface), channel)
            yield portal
        finally:
            portal.call(portal.stop, True)


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
