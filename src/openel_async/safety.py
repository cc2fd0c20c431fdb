"""Device-side safety: what a device's own protocol offers to keep a machine safe when the host
stalls, crashes or is killed, or when someone presses the e-stop.

Drivers implement these optional capabilities on their devices (``isinstance(device,
Watchdog)`` tells whether one does); the framework arms, feeds and triggers them:

- :class:`Watchdog`: the device stops by itself when the host goes silent for longer than a
  timeout (ODrive axis watchdog, CiA 402 heartbeat consumer 0x1016 with abort connection option
  0x6007, Dynamixel Bus Watchdog). It is fed from the event loop -- a task of the component
  (``DeviceContext.start_soon``) or of the bus, never a thread -- so a stalled loop lets it
  expire. A trip is reported as a fault with :attr:`~openel_async.device.ErrorId.WATCHDOG`
  when the device is heard from again.
- :class:`EmergencyStop`: the protocol's emergency state at once (ODrive Estop, CiA 402 Quick
  Stop, Dynamixel torque off), reported as a fault with
  :attr:`~openel_async.device.ErrorId.ESTOP`; and the safe state a run leaves the device in
  (:class:`ExitAction`).
"""

from __future__ import annotations

from enum import StrEnum
from typing import Protocol, runtime_checkable

__all__ = ["EmergencyStop", "ExitAction", "Watchdog"]


class ExitAction(StrEnum):
    """The state a run leaves an actuator in, whatever ends it."""

    HOLD = "hold"
    """Keep holding the last position (closed loop stays on)."""
    STOP = "stop"
    """Brake to standstill with the device's own deceleration, then hold."""
    TORQUE_OFF = "torque_off"
    """Remove torque (the axis may coast or fall under gravity)."""


@runtime_checkable
class Watchdog(Protocol):
    """A device with a watchdog of its own."""

    async def arm_watchdog(self, timeout_s: float) -> None:
        """Arm the device's watchdog with ``timeout_s`` (refused with BadParameterError
        outside the range the protocol can express) and start feeding it from the event loop.
        Called after ``init``."""

    async def disarm_watchdog(self) -> None:
        """Stop feeding and disarm (before a deliberate close)."""


@runtime_checkable
class EmergencyStop(Protocol):
    """A device with an emergency state and a defined safe stop."""

    async def estop(self) -> None:
        """Enter the protocol's emergency state now and report ErrorId.ESTOP; ``re_init``
        recovers only once the e-stop is released."""

    async def safe_stop(self, action: ExitAction) -> None:
        """Leave the device in ``action``'s state (called on every exit path of a run)."""
