"""Component listeners: what a tool attached to a component (a flight recorder, a live view)
is told besides the observers' events and errors.

A :class:`ComponentListener` is set with :meth:`HALComponent.set_listener
<openel_async.component.HALComponent.set_listener>` (one per component). It hears every
command an :class:`~openel_async.Actuator` accepts (``set_value``, ``set_value_nowait``, an
``ActuatorBank``'s streamed setpoints), every value the application reads (``get_value`` and
``get_timed_value`` of a Sensor, the actual values of an Actuator, the banks' reads) and every
state change. Its methods run inline in the caller's task, on the per-command paths: they must
be cheap, must not block and must not raise (an exception would reach the caller). Without a
listener each path pays one attribute test.

A listener may also offer ``batch_listener(components)``: a :data:`BatchListener` for a bank's
streamed batches to those components and for its reads of them (one call per batch instead of
one ``on_command`` or ``on_reading`` per member), or None. An ``ActuatorBank`` asks its first
member's listener for one (:func:`batch_listener`) whenever a listener was set or removed
anywhere, and uses it for every batch its device batch commands (it stands for every member's
``on_command``) and for every ``get_values`` of an actual value when its members share a clock
(it stands for every member's ``on_reading``).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from .component import ComponentState, HALComponent
    from .requests import Request

__all__ = ["LISTENING", "BatchListener", "ComponentListener", "batch_listener", "tell_readings"]


class _Listening:
    """How many components have a listener, process-wide: the banks test it once per call
    rather than every member's listener; ``changes`` counts every listener set or removed
    (a bank re-asks for its batch listener when it changed)."""

    __slots__ = ("changes", "count")

    def __init__(self) -> None:
        self.count = 0
        self.changes = 0


LISTENING = _Listening()


class ComponentListener(Protocol):
    """What a component tells its listener (see the module docstring)."""

    def on_command(
        self, component: HALComponent, request: Request, value: float, time_ns: int
    ) -> None:
        """The actuator accepted the command ``request`` = ``value`` at ``time_ns`` (its clock)."""

    def on_reading(
        self, component: HALComponent, request: Request | None, values: tuple[float, ...]
    ) -> None:
        """The application read ``values`` (a Sensor: ``request`` None; an Actuator: the
        actual-value code and one value), now on the component's clock."""

    def on_state(self, component: HALComponent, old: ComponentState, new: ComponentState) -> None:
        """The component went from ``old`` to ``new``."""


BatchListener = Callable[["Request", Sequence[float], int], None]
"""``f(request, values, time_ns)``: with a command code (``request.is_command``), a bank's
device batch commanded ``values[i]`` to member ``i``; with an actual-value code
(``POSITION_ACTUAL``...), the application read ``values[i]`` from member ``i`` (a bank's
``get_values``); at ``time_ns`` on their clock. It must not keep ``values`` (the caller may
reuse the sequence): copy what it needs."""


def batch_listener(components: Sequence[HALComponent]) -> BatchListener | None:
    """The :data:`BatchListener` for a batch to ``components`` (in order): what the first
    one's listener's ``batch_listener(components)`` gives, or None (no listener, or it has
    none for them: each member's listener is told with ``on_command``)."""
    if not components:
        return None
    make = getattr(components[0].listener, "batch_listener", None)
    if make is None:
        return None
    found: BatchListener | None = make(components)
    return found


def tell_readings(
    components: Iterable[HALComponent],
    request: Request | None,
    values: Iterable[tuple[float, ...]],
) -> None:
    """A bank's read: each component's values to its listener, if it has one."""
    for component, value in zip(components, values, strict=True):
        listener = component.listener
        if listener is not None:
            listener.on_reading(component, request, value)
