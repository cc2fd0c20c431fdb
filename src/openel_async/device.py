"""The device-layer seam: what a driver implements and what the framework gives it.

A driver subclasses :class:`ActuatorDevice` or :class:`SensorDevice`. The framework
calls the lifecycle hooks in the HALComponent state machine's order
(``open`` while Initializing, ``init`` on Init, ``reset`` on ReInit, ``close`` on
Finalize) and reaches the driver through :class:`DeviceContext` callbacks.
"""

from __future__ import annotations

import math
from abc import ABC, ABCMeta, abstractmethod
from collections.abc import Awaitable, Callable, Coroutine, Sequence
from dataclasses import dataclass
from enum import Enum, IntEnum
from typing import Any, NamedTuple, Protocol

from .clock import Clock
from .errors import BadParameterError, NotImplementedHALError, ReturnCode, WouldBlockError
from .ids import DeviceKind, HALId
from .requests import Request


class ErrorId(IntEnum):
    """Error ids the bundled drivers share (OpenEL: error ids 1+ are device-specific)."""

    DEVICE_ERROR = 1
    DISCONNECTED = 2
    TIMEOUT = 3
    BUS_ERROR = 4
    LIMIT_VIOLATION = 5
    PROTOCOL_ERROR = 6
    WATCHDOG = 7
    """The device's own watchdog expired: the host went silent for longer than the timeout
    and the device stopped by itself (:mod:`openel_async.safety`)."""
    ESTOP = 8
    """The device was put into its protocol's emergency state (:mod:`openel_async.safety`)."""


@dataclass(frozen=True, slots=True)
class DeviceInfo:
    """Identity a driver declares; the default HALId and device name derive from it."""

    kind: DeviceKind | int
    vendor_id: int = 0
    product_id: int = 0
    vendor_name: str = "Generic"
    product_name: str = "Device"
    functions: tuple[str, ...] = ()


class ValueSource(Enum):
    """Where an Actuator's actual value (``get_value`` of codes 5-7) comes from.

    OpenEL 3.2 §7.4.1.7: "If the actual angle / position / velocity / torque cannot be
    measured, return the estimated value or command value."
    """

    MEASURED = "measured"
    """``read()`` measures it."""
    ESTIMATED = "estimated"
    """The device cannot measure it; ``read()`` returns the device's estimate."""
    COMMANDED = "commanded"
    """The device can neither measure nor estimate it: the last commanded value."""


ACTUAL_REQUESTS: frozenset[Request] = frozenset(
    {Request.POSITION_ACTUAL, Request.VELOCITY_ACTUAL, Request.TORQUE_ACTUAL}
)

# Enum members read as module constants on the per-command path (~80 ns saved each).
_POSITION = Request.POSITION
_VELOCITY = Request.VELOCITY
_TORQUE = Request.TORQUE


@dataclass(frozen=True, slots=True)
class ActuatorLimits:
    """Limits of commanded values in SI units (rad or m, rad/s or m/s, Nm or N)."""

    position: tuple[float, float] = (-math.inf, math.inf)
    velocity: float = math.inf
    """Largest allowed |velocity|."""
    torque: float = math.inf
    """Largest allowed |torque|."""

    def __post_init__(self) -> None:
        low, high = self.position
        if not low < high:
            raise BadParameterError(
                "limits.position", self.position, "a (low, high) pair with low < high"
            )
        for name in ("velocity", "torque"):
            if not getattr(self, name) > 0:
                raise BadParameterError(f"limits.{name}", getattr(self, name), "a value > 0")

    def check(self, request: Request, value: float) -> None:
        """Raise BAD_PARAMETER for a target outside the limits."""
        if request is _POSITION:
            low, high = self.position
            if not low <= value <= high:
                raise BadParameterError("value", value, f"a position in [{low}, {high}]")
        elif request is _VELOCITY and abs(value) > self.velocity:
            raise BadParameterError(
                "value", value, f"a velocity in [-{self.velocity}, {self.velocity}]"
            )
        elif request is _TORQUE and abs(value) > self.torque:
            raise BadParameterError("value", value, f"a torque in [-{self.torque}, {self.torque}]")


class DeviceContext(Protocol):
    """What the framework gives a driver in ``open``."""

    @property
    def clock(self) -> Clock: ...

    @property
    def name(self) -> str: ...

    @property
    def hal_id(self) -> HALId:
        """The component's HALId (e.g. ``instance_id`` to key per-instance state)."""
        ...

    def start_soon(self, func: Callable[..., Coroutine[Any, Any, Any]], *args: Any) -> None:
        """Run a background task owned by the component (cancelled at finalize)."""

    def target_reached(self) -> None:
        """The device reached the target of the latest command (device-reported completion)."""

    def post_event(self, event_id: int) -> None:
        """Notify observers of a device-specific event (ids 2 and up)."""

    def post_error(self, error_id: int) -> None:
        """Notify observers of an error that does not stop the component."""

    def fault(self, error_id: int, reason: str, code: ReturnCode = ReturnCode.HAL_ERROR) -> None:
        """The device failed: the component goes to Error and observers are notified."""


class Device(ABC):  # noqa: B024 - every hook is optional
    """Lifecycle hooks shared by every device; the defaults do nothing."""

    info: DeviceInfo = DeviceInfo(kind=0)
    has_time: bool = True
    """Whether the component offers GetTime (the spec's optional time attribute)."""

    async def open(self, ctx: DeviceContext) -> None:  # noqa: B027 - optional hook
        """Device-specific processing while the component is Initializing (connect, probe)."""

    async def init(self) -> None:  # noqa: B027 - optional hook
        """Init: make the device operational (e.g. enable the drive)."""

    async def reset(self) -> None:  # noqa: B027 - optional hook
        """ReInit: clear the fault and make the device operational again; raise if it cannot."""

    async def close(self) -> None:  # noqa: B027 - optional hook
        """Finalize: stop and release the device. Must not raise for an already broken device."""


@dataclass(frozen=True, slots=True)
class VelocityRamp:
    """A speed change spread over a time (HAL4RT ``SetSpeed(speed, tmAcc)``), in SI units.

    Given to :meth:`ActuatorDevice.command_velocity_ramp` by ``Motor.set_speed``: the device
    should go from its current velocity to ``target`` linearly in ``duration_s`` seconds.
    ``start`` is the velocity the framework saw when the command was issued (the actual
    velocity, or the setpoint of a ramp in progress); a device that knows its own velocity
    better may use it instead, as long as it keeps ``duration_s``.
    """

    start: float
    """rad/s or m/s."""
    target: float
    """rad/s or m/s."""
    duration_s: float
    """tmAcc: seconds, finite and > 0."""

    @property
    def rate(self) -> float:
        """|target - start| / duration_s: the acceleration the ramp needs (rad/s^2 or m/s^2)."""
        return abs(self.target - self.start) / self.duration_s


class LimitsChanges:
    """Counts assignments of every actuator device's :attr:`ActuatorDevice.limits` (a bank
    re-reads its devices' limits when it moved since it last read them: one integer
    comparison per batch instead of one read per device)."""

    __slots__ = ("value",)

    def __init__(self) -> None:
        self.value = 0


LIMITS_CHANGES = LimitsChanges()


def _checked_limits(value: object, name: str) -> ActuatorLimits:
    if not isinstance(value, ActuatorLimits):
        raise BadParameterError(name, value, "an ActuatorLimits")
    return value


class ActuatorDeviceType(ABCMeta):
    """The metaclass of :class:`ActuatorDevice`: ``limits`` declared in a class body
    (``limits = ActuatorLimits(...)``) becomes the class's default instead of shadowing the
    instances' ``limits`` property, and ``SomeDevice.limits`` reads (or sets) that default."""

    def __new__(
        mcls, name: str, bases: tuple[type, ...], namespace: dict[str, Any], **kwargs: Any
    ) -> ActuatorDeviceType:
        if "limits" in namespace and not isinstance(namespace["limits"], property):
            # (None included: left in the class body it would shadow the property)
            namespace = dict(namespace)
            namespace["_actuator_limits"] = _checked_limits(
                namespace.pop("limits"), f"{name}.limits"
            )
        return super().__new__(mcls, name, bases, namespace, **kwargs)

    @property
    def limits(cls) -> ActuatorLimits:
        """The limits of the class's instances that set none of their own."""
        limits: ActuatorLimits = cls._actuator_limits
        return limits

    @limits.setter
    def limits(cls, value: ActuatorLimits) -> None:
        cls._actuator_limits = _checked_limits(value, f"{cls.__name__}.limits")
        LIMITS_CHANGES.value += 1


class ActuatorDevice(Device, metaclass=ActuatorDeviceType):
    """A one-degree-of-freedom actuator.

    ``limits`` may be set at any time (``self.limits = ActuatorLimits(...)`` in ``__init__``,
    ``open`` or ``init``, or later): every assignment counts in :data:`LIMITS_CHANGES`, so
    that a bank over the device checks the next batch against the new limits.  A subclass
    may declare its default as a class attribute (``limits = ActuatorLimits(...)``); it
    becomes the default the property returns until an instance sets its own.
    """

    _actuator_limits: ActuatorLimits = ActuatorLimits()
    linear: bool = False
    """True for a linear axis (m, m/s, N), False for a rotary one (rad, rad/s, Nm). A
    ``Motor``'s scale factor defaults to 2 pi per revolution (rotary) or 1.0 per metre."""
    velocity_ramp: bool = False
    """True when the driver implements :meth:`command_velocity_ramp` with the device's own
    ramp (ODrive VEL_RAMP, CiA 402 profile acceleration, Dynamixel Profile Acceleration...);
    else ``Motor.set_speed(speed, tm_acc)`` streams the ramp itself on the component's
    clock."""
    supported_requests: frozenset[Request] = frozenset(
        {Request.NO_EXCITE, Request.POSITION, Request.VELOCITY, Request.TORQUE}
    )
    reports_completion: bool = False
    """True when the driver calls ``ctx.target_reached()``; else the framework detects
    completion by tolerance and settle time."""
    measured_requests: frozenset[Request] = ACTUAL_REQUESTS
    """The actual quantities (``*_ACTUAL`` codes) that ``read()`` measures."""
    estimated_requests: frozenset[Request] = frozenset()
    """The actual quantities the device cannot measure but estimates: ``read()`` returns the
    estimate. For a code in neither set, ``read()`` is never called and ``get_value``
    returns the last commanded value (OpenEL §7.4.1.7). Both are read when the Actuator
    is constructed."""

    @property
    def limits(self) -> ActuatorLimits:
        """Limits of commanded values; see the class docstring."""
        return self._actuator_limits

    @limits.setter
    def limits(self, value: ActuatorLimits) -> None:
        self._actuator_limits = _checked_limits(value, "limits")
        LIMITS_CHANGES.value += 1

    @abstractmethod
    async def command(self, request: Request, value: float) -> None:
        """Send a new target; return once the device accepted it (not when reached)."""

    @abstractmethod
    async def read(self, request: Request) -> float:
        """Read POSITION_ACTUAL, VELOCITY_ACTUAL or TORQUE_ACTUAL in SI units (a code of
        ``measured_requests`` or ``estimated_requests``)."""

    async def command_velocity_ramp(self, ramp: VelocityRamp) -> None:
        """Start a velocity ramp with the device's own ramp generator (when
        :attr:`velocity_ramp` is True); return once the device accepted it.

        The device is in velocity control afterwards. A driver that reports completion
        calls ``ctx.target_reached()`` when ``ramp.target`` is reached (the end of the ramp),
        not before. Only called with ``duration_s > 0``; a zero tmAcc is a plain
        ``command(VELOCITY, target)``.
        """
        raise NotImplementedHALError(f"{type(self).__name__} has no velocity ramp of its own")

    # The synchronous fast path (``Actuator.set_value_nowait``/``get_value_nowait``), for
    # devices that never wait: simulations writing and reading memory.  Bus drivers keep the
    # defaults, which refuse.
    def command_nowait(self, request: Request, value: float) -> None:
        """``command`` without suspending; only for devices that need no I/O."""
        raise WouldBlockError(f"{type(self).__name__} has no synchronous command path")

    def read_nowait(self, request: Request) -> float:
        """``read`` without suspending; only for devices that need no I/O."""
        raise WouldBlockError(f"{type(self).__name__} has no synchronous read path")

    @classmethod
    def batch_commander(cls, devices: Sequence[ActuatorDevice]) -> BatchCommander | None:
        """A callable commanding several devices of this class at once, or None (the default:
        an :class:`~openel_async.ActuatorBank` then calls ``command_nowait`` one by one).

        Asked once, when a bank over ``devices`` (all of this class, all with a
        ``command_nowait``) is built.  See :class:`BatchCommander` for its contract.
        """
        return None

    @classmethod
    def async_batch_commander(cls, devices: Sequence[ActuatorDevice]) -> AsyncBatchCommander | None:
        """A coroutine function commanding several devices of this class at once (a bus's
        one write for every drive), or None (the default: an
        :class:`~openel_async.ActuatorBank` or an ``AxisGroup`` then awaits ``command``
        device by device, one coroutine for the batch).

        Asked once, when a bank over ``devices`` (all of this class, none with a usable
        ``command_nowait``, all reporting completion) is built.  See
        :class:`AsyncBatchCommander` for its contract.
        """
        return None


class AsyncBatchCommander(Protocol):
    """``await command(request, values[i])`` on device i of a bank, in one coroutine.

    The contract of :class:`BatchCommander`, awaited: all or nothing, False (having
    commanded none) when it cannot take this batch (the bank then awaits ``command``
    device by device), a link fault raised only before commanding any device, never
    ``ctx.target_reached()`` from inside; the values are already validated.  A member that
    is commanded by another path while the batch is awaited keeps that later command as
    its latest (the bank records the batch for the others only).
    """

    def __call__(self, request: Request, values: Sequence[float], /) -> Awaitable[bool]: ...


class BatchCommander(Protocol):
    """``command_nowait(request, values[i])`` on device i of a bank, in one call.

    All or nothing: it either commands every device or none.  It returns False, having
    commanded none, when it cannot take this batch (a device in another control mode, a
    request it does not stream...): the bank then calls ``command_nowait`` device by
    device.  It raises (a link fault) only before commanding any device, and never calls
    ``ctx.target_reached()`` from inside (completion is reported later, from the device's
    own loop).  The values are already validated (finite floats inside the limits).
    """

    def __call__(self, request: Request, values: Sequence[float], /) -> bool: ...


class Reading(NamedTuple):
    """One measurement of a sensor device; ``time_ns`` None means 'use the clock'.

    A named tuple rather than a frozen dataclass: it is built on every read, and a frozen
    dataclass's ``__init__`` costs several times more.
    """

    values: Sequence[float]
    time_ns: int | None = None


class SensorDevice(Device):
    """A sensor returning a fixed-length list of SI values."""

    units: tuple[str, ...] = ()
    """SI unit of each value, e.g. ('rad/s', 'rad/s', 'rad/s')."""

    @abstractmethod
    async def read(self) -> Reading:
        """Take one measurement."""

    def read_nowait(self) -> Reading:
        """``read`` without suspending; only for devices that need no I/O (simulations)."""
        raise WouldBlockError(f"{type(self).__name__} has no synchronous read path")

    @classmethod
    def read_values_many_nowait(cls, devices: Sequence[SensorDevice]) -> list[Sequence[float]]:
        """The values of ``read_nowait()`` of several devices of this class at once (a
        SensorBank's read, which returns values only: no Reading is built per device).

        Override it where one read serves many devices (a simulation converting its sensor
        array once); the default reads them one by one.
        """
        return [device.read_nowait().values for device in devices]

    @classmethod
    def batch_reader(cls, devices: Sequence[SensorDevice]) -> BatchReader | None:
        """A callable reading several devices of this class at once, or None (the default:
        a :class:`~openel_async.SensorBank` then calls :meth:`read_values_many_nowait`).

        Asked once, when a bank over ``devices`` (all of this class, all with a
        ``read_nowait``) is built.  See :class:`BatchReader` for its contract.
        """
        return None


class BatchReader(Protocol):
    """``read_nowait().values`` of device i of a bank, for every device, in one call.

    Returns ``(flat, values)``: ``values[i]`` is device i's values, a tuple of floats, and
    ``flat`` a sequence holding every value of them (it may hold more: the bank checks the
    whole batch for finiteness with one ``sum(flat)``, and checks sensor by sensor only when
    that sum is not a finite float).  It raises a link fault only before reading any device
    (the bank then reads them one by one, so the fault reaches the right component).
    """

    def __call__(self) -> tuple[Sequence[float], tuple[tuple[float, ...], ...]]: ...


def has_nowait(device: Device, nowait: str, blocking: str) -> bool:
    """Whether ``device`` offers a usable synchronous ``nowait`` twin of ``blocking``.

    The class that defines ``nowait`` must be the one that defines ``blocking`` or a subclass
    of it: a subclass that overrides only the async method (to record or delay commands) must
    not be bypassed by the synchronous path.
    """
    mro = type(device).__mro__

    def owner(name: str) -> type:
        return next(cls for cls in mro if name in vars(cls))

    defined = owner(nowait)
    if defined in (ActuatorDevice, SensorDevice):
        return False  # only the refusing default
    return issubclass(defined, owner(blocking))
