"""Setpoint streaming over many actuators: the per-batch paths of an ActuatorBank and an
AxisGroup (split out of :mod:`openel_async.actuator`, which re-exports them).

Each keeps ``Actuator.set_value``'s semantics (sequence numbers, supersession, COMPLETED
only for a final target) while building each ``Motion`` only when someone asks for it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

from .completion import Outcome
from .component import LINK_FAULTS, ComponentState
from .listeners import LISTENING, BatchListener, batch_listener
from .requests import Request

if TYPE_CHECKING:
    from .actuator import Actuator

__all__ = ["StreamBatch", "accept_streamed", "send_targets", "stream_targets"]

_ACTIVE = ComponentState.ACTIVE
_PENDING = Outcome.PENDING
_NO_EXCITE = Request.NO_EXCITE
_LINK_FAULTS = LINK_FAULTS


def stream_targets(
    actuators: Sequence[Actuator],
    req: Request,
    targets: Sequence[float],
    now_ns: int | None,
    posts_completed: bool = True,
) -> None:
    """Setpoint streaming (:class:`~openel_async.ActuatorBank`): ``_send_now`` on every
    actuator in order, with the same semantics, but each Motion is only built if someone asks
    for it (``Actuator.motion``).  ``now_ns`` stamps every command (None: each actuator's clock);
    ``posts_completed``: whether reaching these targets posts COMPLETED (``Motion``).

    One loop rather than a method call per axis: a bank runs it on every control tick.
    """
    lazy = req is not _NO_EXCITE  # NO_EXCITE completes at once: its Motion is needed now
    for actuator, target in zip(actuators, targets, strict=True):
        if actuator._stream is not None:
            actuator._detach()
        sequence = actuator._sequence = actuator._sync_send = actuator._sequence + 1
        try:
            actuator.device.command_nowait(req, target)
        except _LINK_FAULTS as exc:
            raise actuator._fault_from(exc) from exc
        finally:
            actuator._sync_send = 0
        if not (lazy and actuator._reports_completion and actuator.state is _ACTIVE):
            actuator._accept(req, target, sequence, posts_completed)
        else:
            previous = actuator._motion
            if previous is not None:  # built because someone asked: it is replaced
                if previous.outcome is _PENDING:
                    previous._supersede(sequence)
                actuator._motion = None
            stamp = actuator.clock.now_ns() if now_ns is None else now_ns
            actuator._latest = (req, target, sequence, stamp, posts_completed)
            actuator._commanded[req] = target
            listener = actuator._observers.listener
            if listener is not None:
                listener.on_command(actuator, req, target, stamp)
        if actuator._reached_in_send == sequence:
            actuator._reached_in_send = 0
            actuator._on_target_reached()


async def send_targets(
    actuators: Sequence[Actuator],
    req: Request,
    targets: Sequence[float],
    posts_completed: bool = True,
    now_ns: Callable[[], int] | None = None,
) -> None:
    """:func:`stream_targets` over devices without a synchronous path: ``_send`` on every
    actuator in order (one awaited ``device.command`` each), with the same semantics, but
    each Motion is only built if someone asks for it (``Actuator.motion``) and the batch
    runs in one coroutine, not one per actuator.  ``targets`` are validated (an
    ActuatorBank's checks); a command overtaken by another during its await, a device that
    does not report completion, an actuator that left Active or NO_EXCITE take the full
    ``_accept``.  ``now_ns``: the clock every actuator shares, read once for the batch as
    an ActuatorBank stamps its streamed batches (None: each actuator's own, after its
    command).
    """
    lazy = req is not _NO_EXCITE
    active = _ACTIVE
    pending = _PENDING
    listening = LISTENING
    stamp = now_ns() if now_ns is not None else 0
    for actuator, target in zip(actuators, targets, strict=True):
        if actuator._stream is not None:
            actuator._detach()
        sequence = actuator._sequence + 1
        actuator._sequence = sequence
        try:
            await actuator.device.command(req, target)
        except _LINK_FAULTS as exc:
            raise actuator._fault_from(exc) from exc
        if (
            actuator._sequence != sequence  # overtaken during the await
            or not lazy
            or actuator.state is not active
            or not actuator._reports_completion
            or actuator._stream is not None
        ):
            actuator._accept(req, target, sequence, posts_completed)
            continue
        previous = actuator._motion
        if previous is not None:  # built because someone asked: it is replaced
            if previous.outcome is pending:
                previous._supersede(sequence)
            actuator._motion = None
        if now_ns is None:
            stamp = actuator.clock.now_ns()
        actuator._latest = (req, target, sequence, stamp, posts_completed)
        actuator._commanded[req] = target
        if listening.count:
            listener = actuator._observers.listener
            if listener is not None:
                listener.on_command(actuator, req, target, stamp)


def accept_streamed(
    actuators: Sequence[Actuator],
    req: Request,
    targets: Sequence[float],
    now_ns: int | None,
    listening: bool,
    posts_completed: bool = True,
) -> None:
    """The bookkeeping of :func:`stream_targets` after a device batch (``BatchCommander``)
    commanded every actuator: each one's latest command, its Motion built only when asked
    for.  Only for Active actuators whose devices report completion (lazy Motions) and a
    request other than NO_EXCITE; ``listening``: some component has a listener.
    """
    for actuator, target in zip(actuators, targets, strict=True):
        if actuator._stream is not None:
            actuator._detach()
        sequence = actuator._sequence = actuator._sequence + 1
        previous = actuator._motion
        if previous is not None:  # built because someone asked: it is replaced
            if previous.outcome is _PENDING:
                previous._supersede(sequence)
            actuator._motion = None
        stamp = actuator.clock.now_ns() if now_ns is None else now_ns
        actuator._latest = (req, target, sequence, stamp, posts_completed)
        actuator._commanded[req] = target
        if listening:
            listener = actuator._observers.listener
            if listener is not None:
                listener.on_command(actuator, req, target, stamp)


class StreamBatch:
    """A bank's batch stream: the latest batch of targets its device batch commanded.

    Streaming N setpoints per tick, the per-actuator bookkeeping (sequence, commanded value,
    latest command) is what costs; a bank whose driver commands the whole batch at once
    (``ActuatorDevice.batch_commander``) keeps the latest batch here instead, and each
    attached actuator settles its own state from it only when something reads that state
    (``motion``, a commanded value, its next command by another path).  An attached
    actuator's sequence is its sequence at its last settle plus the batches since.

    ``intact``: every member is attached (a member that leaves, e.g. for a ``set_value``,
    clears it: the next batch attaches them all again).  ``built``: members whose Motion
    was built while attached (someone asked for it): the next batch supersedes it.
    ``posts_completed``: whether reaching the batches' targets posts COMPLETED (``Motion``).
    """

    __slots__ = (
        "built",
        "count",
        "intact",
        "listen_at",
        "on_batch",
        "posts_completed",
        "request",
        "stamp",
        "targets",
    )

    def __init__(self, size: int, posts_completed: bool = True) -> None:
        self.posts_completed = posts_completed
        self.listen_at = -1  # LISTENING.changes when on_batch was asked for
        self.on_batch: BatchListener | None = None
        """The members' batch listener (:func:`~openel_async.listeners.batch_listener`)."""
        self.targets: list[float] = [0.0] * size
        self.request = Request.POSITION
        self.stamp = 0
        self.count = 0
        self.intact = False
        self.built: list[Actuator] = []

    def attach(self, actuators: Sequence[Actuator]) -> None:
        """Attach every member at the current batch (each settled and detached first)."""
        count = self.count
        built = self.built
        built.clear()
        for index, actuator in enumerate(actuators):
            actuator._detach()
            actuator._stream = (self, index, count, actuator._sequence)
            if actuator._motion is not None:  # its latest command's: the next batch replaces it
                built.append(actuator)
        self.intact = True

    def accept(
        self,
        actuators: Sequence[Actuator],
        req: Request,
        targets: Sequence[float],
        stamp: int,
        listening: bool,
    ) -> None:
        """Record a batch the device batch commanded (the bookkeeping of
        :func:`stream_targets`, per batch): each member's Motion is built when asked for.

        Only for Active members whose devices report completion, a request other than
        NO_EXCITE, and the members in the order they were attached; ``listening``: some
        component has a listener (each member's hears its command, or the members' batch
        listener hears the batch: :func:`~openel_async.listeners.batch_listener`).
        """
        if not self.intact or req is not self.request:
            self.attach(actuators)  # each settled with the previous request first
            self.request = req
        self.targets[:] = targets
        self.stamp = stamp
        count = self.count = self.count + 1
        built = self.built
        if built:  # Motions built since the last batch: superseded by this one
            for actuator in built:
                link = actuator._stream
                motion = actuator._motion
                if link is None or link[0] is not self or motion is None:
                    continue  # it left the stream: its own command handled its Motion
                if motion.outcome is _PENDING:
                    motion._supersede(link[3] + count - link[2])
                actuator._motion = None
            built.clear()
        if listening:
            if self.listen_at != LISTENING.changes:  # a listener was set or removed
                self.listen_at = LISTENING.changes
                self.on_batch = batch_listener(actuators)
            on_batch = self.on_batch
            if on_batch is not None:  # one call for the batch
                on_batch(req, targets, stamp)
                return
            # one target per member (checked): no strict=, a dict per call
            for actuator, target in zip(actuators, targets):  # noqa: B905
                listener = actuator._observers.listener
                if listener is not None:
                    listener.on_command(actuator, req, target, stamp)
