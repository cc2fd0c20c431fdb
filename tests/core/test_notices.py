"""The notices are values: equal by their fields, hashable, copied with a change by
dataclasses.replace (the ObserverQueue's ``missed`` does it), cheap to build."""

from __future__ import annotations

import dataclasses

from openel_async import EventTimer
from openel_async.observers import ErrorNotice, EventNotice, TimerTick


def test_notices_are_values() -> None:
    timer = EventTimer(1, name="t")
    tick = TimerTick(timer, 3, 3_000_000, 3_000_250, 1)
    same = TimerTick(timer, 3, 3_000_000, 3_000_250, 1)
    assert tick == same and hash(tick) == hash(same) and len({tick, same}) == 1
    later = dataclasses.replace(tick, missed=2)
    assert later.missed == 2 and tick.missed == 0 and later != tick
    assert later.lateness_ns == 250 and later.missed_ticks == 1
    assert EventNotice(None, 1) == EventNotice(None, 1) != EventNotice(None, 1, 1)  # type: ignore[arg-type]
    assert len({ErrorNotice(None, 2), ErrorNotice(None, 2)}) == 1  # type: ignore[arg-type]


def test_timer_tick_has_no_frozen_setattr() -> None:
    """A frozen dataclass assigns each field through object.__setattr__ (4x slower to build,
    on every tick): the notices use the plain generated __init__."""
    for cls in (TimerTick, EventNotice, ErrorNotice):
        params = cls.__dataclass_params__  # type: ignore[attr-defined]
        assert not params.frozen and "__slots__" in vars(cls)
