"""The loop gate keeps its one invariant when the loop thread is interrupted: whenever the
loop thread runs loop code, it holds the gate.

A Python-level signal handler runs on the main thread (the loop's) where the interpreter
checks for pending signals: inside a blocking call (``select``, a lock's ``acquire``)
and when a call returns. Each lock below raises KeyboardInterrupt once at one of those
points, as a handler that raises (a second Ctrl-C) would."""

from __future__ import annotations

import selectors
import threading
from collections.abc import Callable
from typing import Any

import pytest

from openel_zenoh.gate import GatedSelector, LoopGate


class Interrupted:
    """A lock whose first blocking ``acquire`` (``when="acquire"``: before taking it;
    ``"acquired"``: once taken) or first ``release`` (``"released"``: once released)
    raises KeyboardInterrupt."""

    def __init__(self, lock: Any, when: str) -> None:
        self.lock = lock
        self.when = when
        self.interrupted = False

    def _interrupt(self, when: str) -> None:
        if self.when == when and not self.interrupted:
            self.interrupted = True
            raise KeyboardInterrupt

    def acquire(self, blocking: bool = True) -> bool:
        if blocking:
            self._interrupt("acquire")
        got: bool = self.lock.acquire(blocking)
        if blocking:
            self._interrupt("acquired")
        return got

    def release(self) -> None:
        self.lock.release()
        self._interrupt("released")


def interrupted_gate(when: str) -> tuple[LoopGate, Interrupted]:
    gate = LoopGate()  # held by this thread, as by a loop thread running loop code
    lock = Interrupted(gate._lock, when)
    gate._lock = lock  # type: ignore[assignment]
    return gate, lock


def assert_held_by_this_thread(gate: LoopGate) -> None:
    """No other thread enters; the next park opens the gate to them (resumed after)."""
    assert lock_owned(gate)
    entered: list[bool] = []
    other = threading.Thread(target=lambda: entered.append(gate.try_enter()))
    other.start()
    other.join()
    assert entered == [False]
    gate.park()

    def section() -> None:
        entered.append(gate.try_enter())
        if entered[-1]:
            gate.leave()

    other = threading.Thread(target=section)
    other.start()
    other.join()
    assert entered == [False, True]
    gate.resume()


def lock_owned(gate: LoopGate) -> bool:
    return gate._owned()


def in_thread(body: Callable[[], None], timeout: float = 5.0) -> None:
    """Run ``body`` in a thread of its own (the gate's owner), failing if it hangs."""
    errors: list[BaseException] = []

    def run() -> None:
        try:
            body()
        except BaseException as exc:
            errors.append(exc)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    thread.join(timeout)
    assert not thread.is_alive(), "the loop thread hangs"
    if errors:
        raise errors[0]


def test_an_interrupt_while_taking_the_gate_back_still_takes_it() -> None:
    def body() -> None:
        gate, lock = interrupted_gate("acquire")
        gate.park()  # the loop waits in select
        with pytest.raises(KeyboardInterrupt):
            gate.resume()  # interrupted while it waited for the gate
        assert lock.interrupted
        assert_held_by_this_thread(gate)

    in_thread(body)


def test_an_interrupt_just_after_the_gate_was_taken_back_does_not_hang() -> None:
    def body() -> None:
        gate, lock = interrupted_gate("acquired")
        gate.park()
        with pytest.raises(KeyboardInterrupt):
            gate.resume()  # acquired, then interrupted as the call returned
        assert lock.interrupted
        assert_held_by_this_thread(gate)

    in_thread(body)


class NoSelect(selectors.BaseSelector):
    def register(self, fileobj: Any, events: int, data: Any = None) -> selectors.SelectorKey:
        raise NotImplementedError

    def unregister(self, fileobj: Any) -> selectors.SelectorKey:
        raise NotImplementedError

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        return []

    def get_map(self) -> Any:
        return {}


def test_an_interrupt_just_after_the_gate_was_opened_still_takes_it_back() -> None:
    def body() -> None:
        gate, lock = interrupted_gate("released")
        selector = GatedSelector(gate, NoSelect())
        with pytest.raises(KeyboardInterrupt):
            selector.select(0)  # released, then interrupted as park's call returned
        assert lock.interrupted
        assert_held_by_this_thread(gate)
        assert selector.select(0) == []  # and the next select parks and resumes as usual
        assert_held_by_this_thread(gate)

    in_thread(body)
