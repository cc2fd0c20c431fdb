"""How late an execute arrived (docs/wire.md, "Freshness"), without synchronized clocks.

A client sends each execute with its send time on a clock of its own and a time to live
(the selector parameters ``sent_us`` and ``ttl_us``). The server cannot compare the send time
with its own clock, but it can compare queries of the same client: ``arrival - sent`` is the
one-way delay plus the (unknown, constant) offset between the clocks, so its smallest value
so far, the baseline, is the fastest delivery; a query's age is how much later than that it
arrived. The baseline may rise by CLOCK_DRIFT a second, so a client clock that runs slower
than the server's is not taken for growing delays.
"""

from __future__ import annotations

import math

import zenoh

from openel_async.logs import get_logger

log = get_logger(__name__)

CLOCK_DRIFT = 1e-3
"""How fast (s/s) a client's delay baseline may rise: the rate at which its clock may run
slower than the server's (1000 ppm; real clocks drift < 100 ppm) before fresh commands would
be taken for late ones."""


def freshness(parameters: zenoh.Parameters) -> tuple[float | None, float]:
    """The send time and time to live (seconds) of an execute's ``sent_us`` and ``ttl_us``
    selector parameters (integers of microseconds); (None, 0) without them. A malformed or
    partial pair is (nan, 0): served as if absent, and logged."""
    sent, ttl = parameters.get("sent_us"), parameters.get("ttl_us")
    if sent is None and ttl is None:
        return None, 0.0
    try:
        return int(sent or "") / 1e6, int(ttl or "") / 1e6
    except ValueError:
        log.warning("bad_freshness_parameters", sent_us=sent, ttl_us=ttl)
        return math.nan, 0.0


class DelayBaseline:
    """One client's baseline (see the module); ``deadline()`` judges each of its queries."""

    def __init__(self) -> None:
        self.base: float | None = None
        """The smallest (arrival - send time) so far, as raised by the drift allowance."""
        self.at = 0.0
        """When ``base`` was last updated (the server's clock)."""

    def deadline(self, received: float, sent: float, ttl: float) -> float:
        """When a query that arrived at ``received`` (server's clock), sent at ``sent``
        (client's clock) with time to live ``ttl``, becomes stale, on the server's clock: it
        is already stale on arrival when this is before ``received``. The first query of a
        client is its own baseline: it cannot be judged late."""
        delay = received - sent
        base = self.base
        if base is not None:
            base += CLOCK_DRIFT * max(0.0, received - self.at)
        if base is None or delay < base:
            base = delay
        self.base = base
        self.at = max(self.at, received)
        return received + ttl - (delay - base)
