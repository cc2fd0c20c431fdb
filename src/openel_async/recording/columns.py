"""Column buffers: the per-tick records of a tap kept as two flat lists of numbers, not as a
tuple per record.

A control loop records the same few things every tick: a bank's setpoints, a sensor's
reading, an actuator's position command. For each such stream a tap's listener appends the
record's time to a :class:`Columns`' ``times`` and its ``width`` values to ``values``: two
list appends (the cheapest thing Python does; a tuple per record and an ``array`` append
both cost more), no object per record for the collector, and the batch encodes as two
lists of numbers. The control loop hands a buffer over whole (:meth:`Columns.take`); the
writer process makes the messages (:func:`column_messages`). Only the control loop's
thread appends to or takes from a buffer (the lists stay the same objects: listeners keep
them at hand).

A record: kind COMMAND, ``values[i]`` commanded to the component of ``channels[i]`` (a
bank's batch: one message per channel; an actuator's own command: one channel); or kind
READING, ``width // len(channels)`` values read from the component of each channel, in
channel order (a sensor's reading: one channel, its values; a bank's read: one value per
member), one message per channel.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import Any

from .records import COLUMNS, COMMAND, REQUEST_NAMES

__all__ = ["Columns", "column_messages", "column_messages_count"]


class Columns:
    """The records of one stream (see the module docstring): at most ``capacity`` records
    held; beyond, the listener drops and counts them."""

    __slots__ = (
        "capacity",
        "channels",
        "kind",
        "last_time",
        "last_values",
        "per_record",
        "request",
        "taken",
        "times",
        "values",
        "width",
    )

    def __init__(
        self, kind: int, request: int | None, channels: tuple[int, ...], width: int, capacity: int
    ) -> None:
        if kind == COMMAND and width != len(channels):
            raise ValueError(f"a command column has one value per channel, got width {width}")
        if width % len(channels):
            raise ValueError(f"width {width} is not a multiple of {len(channels)} channels")
        if request not in REQUEST_NAMES:
            raise ValueError(f"unknown request code {request!r}")
        self.kind = kind
        self.request = request
        self.channels = channels
        self.width = width
        self.capacity = capacity
        self.per_record = len(channels)
        """Messages one record makes."""
        self.times: list[int] = []
        self.values: list[float] = []
        self.taken = 0
        """Records handed over so far."""
        self.last_time = 0
        self.last_values: list[float] | None = None  # the latest record handed over

    def append(self, time_ns: int, values: Sequence[float]) -> bool:
        """Hold a record (``values``: ``width`` numbers); False if the buffer is full (the
        listeners inline this)."""
        times = self.times
        if len(times) >= self.capacity:
            return False
        self.values.extend(values)
        times.append(time_ns)
        return True

    def entry(self) -> tuple[Any, ...] | None:
        """The records held as one entry of a frame (:data:`~.records.COLUMNS`), holding the
        buffer's lists themselves (encode it, then :meth:`taken_all`); None if it holds
        none. From the control loop's thread only."""
        if not self.times:
            return None
        return (
            COLUMNS,
            self.kind,
            self.request,
            self.channels,
            self.width,
            self.times,
            self.values,
        )

    def taken_all(self) -> None:
        """The records of :meth:`entry` are handed over: empty the buffer."""
        times = self.times
        n = len(times)
        if not n:
            return
        width = self.width
        values = self.values
        self.last_time = times[n - 1]
        self.last_values = values[(n - 1) * width : n * width]
        times.clear()
        values.clear()
        self.taken += n

    def discard(self) -> int:
        """Empty the buffer; the messages it held."""
        n = len(self.times)
        self.times.clear()
        self.values.clear()
        return n * self.per_record


def column_messages_count(entry: Sequence[Any]) -> int:
    """The messages a :data:`~.records.COLUMNS` entry makes."""
    return len(entry[5]) * len(entry[3])


def column_messages(entry: Sequence[Any]) -> Iterator[tuple[int, int, dict[str, Any]]]:
    """``(channel, time_ns, message)`` for every message of a :data:`~.records.COLUMNS`
    entry (the messages :func:`~.records.to_message` makes of the same records)."""
    _, kind, request, channels, width, times, values = entry
    name = REQUEST_NAMES[request]
    if kind == COMMAND:
        for row, t in enumerate(times):
            base = row * width
            for i, channel in enumerate(channels):
                yield (
                    channel,
                    t,
                    {"kind": "command", "time_ns": t, "request": name, "value": values[base + i]},
                )
    else:
        each = width // len(channels)
        for row, t in enumerate(times):
            base = row * width
            for i, channel in enumerate(channels):
                read = values[base + i * each : base + (i + 1) * each]
                yield (
                    channel,
                    t,
                    {
                        "kind": "reading",
                        "time_ns": t,
                        "request": name,
                        "value": read[0] if read else None,
                        "values": read,
                    },
                )
