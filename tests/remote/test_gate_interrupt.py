"""The loop gate keeps its one invariant when the loop thread is interrupted: whenever the
loop thread runs loop code, it holds the gate."""

from __future__ import annotations

import threading

import pytest

from openel_zenoh.gate import LoopGate


class InterruptedOnce:
    """A lock whose first blocking acquire is interrupted, as a signal handler that raises
    (a second Ctrl-C) interrupts the loop thread waiting for the gate while a section runs."""

    def __init__(self, lock: threading.Lock) -> None:
        self.lock = lock
        self.interrupted = False

    def acquire(self, blocking: bool = True) -> bool:
        if blocking and not self.interrupted:
            self.interrupted = True
            raise KeyboardInterrupt
        return self.lock.acquire(blocking)

    def release(self) -> None:
        self.lock.release()


def test_an_interrupt_while_taking_the_gate_back_still_takes_it() -> None:
    gate = LoopGate()  # held by this thread, as by a loop thread running loop code
    lock = gate._lock
    gate._lock = InterruptedOnce(lock)  # type: ignore[assignment]
    gate.park()  # the loop waits in select
    with pytest.raises(KeyboardInterrupt):
        gate.resume()  # interrupted while it waited for the gate
    # The loop thread holds the gate again before the exception leaves select: no other
    # thread enters while the loop runs its shutdown, and the next park releases it.
    assert lock.locked()
    assert not gate.try_enter()
    gate.park()
    assert gate.try_enter()
    gate.leave()
