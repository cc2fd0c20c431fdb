"""BusServo: what every servo on a :class:`~openel_serial.busport.PolledBusPort` shares.

A servo component (:class:`~openel_serial.servo.DynamixelServo`,
:class:`~openel_serial.feetech_servo.FeetechServo`) is an actuator whose actual values come
from its port's poller. The lifecycle (open: attach, identify, read the control table,
refresh the present values; init; reset after a fault; close), the completion of a target
(only a poll sent after the goal write counts), the faults the port reports (a missed poll,
a lost port, a tripped watchdog, an e-stop) and the e-stop itself are the same for every
protocol and live here; a protocol subclass supplies its control table, units and modes
(:meth:`BusServo.identify`, :meth:`BusServo.load_table`, :meth:`BusServo.refresh_state`,
:meth:`BusServo.make_operational`, :meth:`BusServo.reached`, :meth:`BusServo.torque_off`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar, Final, Generic, Protocol, TypeVar

import anyio

from openel_async.device import ActuatorDevice, DeviceContext, ErrorId
from openel_async.errors import BadParameterError, HALError, NotConnectedError, ReturnCode
from openel_async.logs import get_logger
from openel_async.requests import Request
from openel_serial.busport import PolledBusPort

__all__ = [
    "LINK_ERRORS",
    "BusServo",
    "Pending",
    "PolledState",
    "check_position_limits",
    "check_servo_id",
]

log = get_logger(__name__)

LINK_ERRORS: Final = (TimeoutError, NotConnectedError, OSError, anyio.BrokenResourceError)
"""What a lost or silent bus raises: the component faults; polling stops until reset."""


@dataclass(frozen=True, slots=True)
class Pending:
    """The goal whose arrival the poller watches, in raw units."""

    request: Request
    goal: int
    after: int
    """Transaction number at the goal write's acknowledgement: only later polls count."""


class PolledState(Protocol):
    """One poll of one servo, as the port hands it over."""

    @property
    def transaction(self) -> int: ...


def check_servo_id(name: str, value: object, max_id: int) -> int:
    """``value`` if it is a servo id in 0..``max_id``, else BadParameterError naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= max_id:
        raise BadParameterError(name, value, f"a servo id in 0..{max_id}")
    return value


def check_position_limits(
    position_limits: tuple[float, float] | None,
) -> tuple[float, float] | None:
    """``position_limits`` if None or a finite (low, high) pair with low < high."""
    if position_limits is None:
        return None
    try:
        low, high = (float(v) for v in position_limits)
        ok = math.isfinite(low) and math.isfinite(high) and low < high
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise BadParameterError(
            "position_limits", position_limits, "a finite (low, high) pair, low < high"
        )
    return position_limits


PortT = TypeVar("PortT", bound=PolledBusPort[Any, Any])
StateT = TypeVar("StateT", bound=PolledState)


class BusServo(ActuatorDevice, Generic[PortT, StateT]):
    """A servo on a shared polled port (see the module docstring).

    ``port`` must be entered (``async with port``) before the component is.
    """

    reports_completion = True
    log_prefix: ClassVar[str] = "servo"
    """Prefix of the servo's log events (``dynamixel``, ``feetech``)."""
    watchdog_keeps_torque: ClassVar[bool] = False
    """Whether the servo keeps its torque when its watchdog trips (Dynamixel's Bus Watchdog:
    goals ignored, torque kept; Feetech's host watchdog turns it off)."""

    def __init__(self, port: PortT, servo_id: int, *, torque_off_on_close: bool) -> None:
        self.port = port
        self._servo_id = servo_id
        self.torque_off_on_close = torque_off_on_close
        self._ctx: DeviceContext | None = None
        self._polled = False
        self._pending: Pending | None = None
        self._state: StateT | None = None
        self._mode: int = -1
        self._torque = False
        self._ack_writes = True
        self._estop_active = False
        self.return_delay: float | None = None
        """The servo's return delay in seconds, read at open."""
        self.completions = 0
        self.watchdog_trips = 0
        # the logger of the protocol's module (openel_serial.servo, ...feetech_servo)
        self._log = get_logger(type(self).__module__).bind(
            port=port.url, **{port.id_param: servo_id}
        )

    # -- protocol (subclasses) -------------------------------------------------------
    async def identify(self) -> None:
        """PING the servo and check that it is the expected model."""
        raise NotImplementedError

    async def load_table(self) -> None:
        """Read the control table: mode, torque, limits..."""
        raise NotImplementedError

    async def refresh_state(self) -> StateT:
        """Read the present values (what a poll reads) now."""
        raise NotImplementedError

    async def make_operational(self) -> None:
        """Hold the present position with the torque on; resume polling."""
        raise NotImplementedError

    async def torque_off(self) -> None:
        """Torque Enable = 0."""
        raise NotImplementedError

    def reached(self, pending: Pending, state: StateT) -> bool:
        """Whether ``state`` (polled after the goal write) reaches ``pending``."""
        raise NotImplementedError

    def opened_fields(self) -> dict[str, object]:
        """What the "opened" log line reports."""
        return {"mode": self._mode}

    # -- identity --------------------------------------------------------------------
    @property
    def servo_id(self) -> int:
        return self._servo_id

    @property
    def polled(self) -> bool:
        """Whether the port's poller reads this servo (False while faulted or closed)."""
        return self._polled

    @property
    def state(self) -> StateT | None:
        """The latest present values (raw units), from the poller."""
        return self._state

    @property
    def operating_mode(self) -> int:
        return self._mode

    @property
    def torque_enabled(self) -> bool:
        return self._torque

    @property
    def estopped(self) -> bool:
        """Whether the servo was e-stopped (torque off) and not made operational since."""
        return self._estop_active

    def __repr__(self) -> str:
        return f"{type(self).__name__}(id={self._servo_id}, port={self.port.url!r})"

    # -- lifecycle -------------------------------------------------------------------
    async def open(self, ctx: DeviceContext) -> None:
        self._ctx = ctx
        self._log = self._log.bind(component=ctx.name)
        self.port.check_connected()
        self.port.attach(self)
        try:
            await self.identify()
            await self.load_table()
            await self.refresh_state()
        except BaseException:
            self.port.detach(self)
            raise
        self._log.info(f"{self.log_prefix}_opened", **self.opened_fields())

    async def init(self) -> None:
        await self.make_operational()

    async def reset(self) -> None:
        self._polled = False
        self._pending = None
        await self.port.reconnect()
        await self.identify()
        await self.load_table()
        self._estop_active = False  # re_init is what ends an e-stop
        await self.make_operational()

    async def close(self) -> None:
        self._polled = False
        self._pending = None
        self.port.detach(self)
        if self.torque_off_on_close and self.port.connected:
            await self.torque_off()
            self._torque = False

    def check_return_delay(self, return_delay: float) -> None:
        """Record the servo's return delay (s); warn if the port waits less."""
        self.return_delay = return_delay
        if return_delay > self.port.return_delay:
            self._log.warning(
                f"{self.log_prefix}_return_delay_exceeds_port",
                servo_s=return_delay,
                port_s=self.port.return_delay,
            )

    async def present(self) -> StateT:
        """The latest polled state (read now if there is none yet); the port must be up."""
        self.port.check_connected()
        state = self._state
        if state is None:
            state = await self.refresh_state()
        return state

    def resume_polling(self) -> None:
        """Operational again: the e-stop is over, the poller reads the servo."""
        self._estop_active = False
        self._polled = True
        self.port.wake_poller()

    # -- safety ----------------------------------------------------------------------
    async def estop(self) -> None:
        """Torque off now, component to Error with ``ErrorId.ESTOP``."""
        try:
            await self.port.estop([self._servo_id])
        finally:
            self._estopped_now(f"servo {self._servo_id}: e-stop: torque off")

    def check_not_estopped(self) -> None:
        """Refuse to drive the servo while it is e-stopped: a command already on its way when
        the e-stop came must not turn the torque back on (only ``re_init`` does)."""
        if self._estop_active:
            raise HALError(f"servo {self._servo_id}: e-stopped: the torque stays off until re_init")

    def _estopped_now(self, reason: str) -> None:
        self._estop_active = True
        self._torque = False
        self._polled = False
        self._pending = None
        if self._ctx is not None:
            self._ctx.fault(ErrorId.ESTOP, reason)

    def stop_polling(self) -> None:
        """A link fault: the component faults; polling stops until reset."""
        self._polled = False

    def fault(self, error: ErrorId, reason: str, code: ReturnCode = ReturnCode.HAL_ERROR) -> None:
        """Stop polling, drop the pending target and fault the component (once)."""
        if self._polled:
            self._polled = False
            self._pending = None
            self.context().fault(error, reason, code)

    def context(self) -> DeviceContext:
        if self._ctx is None:
            raise HALError(f"servo {self._servo_id} used before open()")
        return self._ctx

    def complete_if_reached(self, state: StateT) -> None:
        """Report the pending target reached if ``state`` (a later poll) reaches it."""
        pending = self._pending
        if pending is None or state.transaction <= pending.after:
            return
        if self.reached(pending, state):
            self._pending = None
            self.completions += 1
            self._log.debug(f"{self.log_prefix}_target_reached", request=pending.request.name)
            self.context().target_reached()

    # -- port callbacks ----------------------------------------------------------------
    def _poll_missed(self, error: TimeoutError) -> None:
        self.fault(ErrorId.TIMEOUT, str(error))

    def _watchdog_tripped(self, reason: str) -> None:
        self.watchdog_trips += 1
        if not self.watchdog_keeps_torque:
            self._torque = False
        self.fault(ErrorId.WATCHDOG, reason)

    def _estopped(self, reason: str) -> None:
        self._estopped_now(reason)

    def _port_lost(self, reason: str) -> None:
        self.fault(ErrorId.DISCONNECTED, reason, ReturnCode.HAL_NO_CONNECTED)
