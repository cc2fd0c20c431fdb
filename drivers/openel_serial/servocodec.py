"""What the servo codecs (:mod:`openel_serial.dynamixel`, :mod:`openel_serial.feetech`) share.

* :class:`DescribedFlag`: an ``IntFlag`` of status or alarm bits that names the bits set
  (``"OVERHEAT|OVERLOAD"``, with the hex value of bits without a name).
* The 12-bit magnetic encoder both X-series and STS servos carry: 4096 ticks per turn, tick
  2048 (mid-range) is 0 rad (:func:`ticks_to_rad`, :func:`rad_to_ticks`).
* :func:`check_item_lengths`: a SYNC WRITE's items all carry ``length`` bytes.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from enum import IntFlag
from typing import Final, Protocol

__all__ = [
    "CENTER_TICK",
    "RAD_PER_TICK",
    "TICKS_PER_REV",
    "DescribedFlag",
    "check_item_lengths",
    "rad_to_ticks",
    "ticks_to_rad",
]

TICKS_PER_REV: Final = 4096
CENTER_TICK: Final = 2048
"""Convention: tick 2048 (the middle of the 0..4095 range) is 0 rad."""
RAD_PER_TICK: Final = 2 * math.pi / TICKS_PER_REV


class DescribedFlag(IntFlag):
    """Status or alarm bits that can name themselves (subclasses add the members)."""

    def describe(self) -> str:
        """``"OVERHEAT|OVERLOAD"``, or the hex value of bits without a name, or ``none``."""
        flags = type(self)
        names = [flag.name for flag in flags if flag in self and flag.name]
        unknown = int(self) & ~sum(int(flag) for flag in flags)
        if unknown:
            names.append(f"{unknown:#04x}")
        return "|".join(names) or "none"


def ticks_to_rad(ticks: int | float) -> float:
    return (ticks - CENTER_TICK) * RAD_PER_TICK


def rad_to_ticks(rad: float) -> int:
    """Nearest tick (+-half a tick, 0.77 mrad)."""
    return round(rad / RAD_PER_TICK) + CENTER_TICK


class _Item(Protocol):
    @property
    def id(self) -> int: ...

    @property
    def data(self) -> bytes: ...


def check_item_lengths(length: int, items: Iterable[_Item]) -> None:
    """ValueError unless every SYNC WRITE item carries ``length`` bytes."""
    for item in items:
        if len(item.data) != length:
            raise ValueError(f"id {item.id}: {len(item.data)} bytes, expected {length}")
