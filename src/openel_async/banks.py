"""ActuatorBank and SensorBank: several components written or read in one call per step.

A control step at 1 kHz over N axes pays Python's per-call cost N times per tick.  A bank
checks its components' state once per call, validates every value before it commands any
(bad input leaves every axis as it was), and dispatches to the devices in one loop: the
``write()``/``read()`` of ros2_control's hardware interfaces, over OpenEL components.

Each component keeps its own semantics: ``ActuatorBank.set_values`` is ``set_value`` on
every actuator in order (one Motion each, COMPLETED per actuator, only for its final
target), ``SensorBank.get_values`` is ``get_value`` on every sensor.  A bank built with
``setpoint_events=False`` streams setpoints rather than targets: reaching them posts no
COMPLETED (an AxisGroup's bank: the group posts one per axis when its motion arrives).  The ``*_nowait`` calls
are for synchronous code (a plain TimerObserver) over devices that need no I/O.
"""

from __future__ import annotations

import functools
import math
import sys
from collections.abc import Awaitable, Callable, Iterable, Iterator, Sequence
from types import CodeType, FunctionType
from typing import Any, TypeVar, cast

from .actuator import Actuator, StreamBatch, accept_streamed, send_targets, stream_targets
from .completion import Motion
from .component import LINK_FAULTS, STATE_CHANGES, ComponentState, HALComponent
from .device import LIMITS_CHANGES
from .errors import BadParameterError, HALError, StateError, WouldBlockError
from .listeners import LISTENING, BatchListener, batch_listener, tell_readings
from .requests import GET_VALUE_REQUESTS, SET_VALUE_REQUESTS, Request, coerce_request
from .sensor import MEASUREMENT_SETTINGS_VERSION, Measurement, Sensor

__all__ = ["ActuatorBank", "SensorBank"]

# Enum members as module constants: read on every call (~80 ns each as class attributes).
_ACTIVE = ComponentState.ACTIVE
_POSITION = Request.POSITION
_SETTABLE = frozenset(SET_VALUE_REQUESTS)
_NO_EXCITE = Request.NO_EXCITE
_ACTUAL_CODES = frozenset(r for r in GET_VALUE_REQUESTS if not r.is_command)
_MAX = sys.float_info.max


_C = TypeVar("_C", bound=HALComponent)


def _members(components: Iterable[_C], kind: type[_C], what: str) -> tuple[_C, ...]:
    members = tuple(components)
    if not members:
        raise BadParameterError(what, members, f"at least one {kind.__name__}")
    for member in members:
        if not isinstance(member, kind):
            raise BadParameterError(what, member, f"{kind.__name__} components only")
    if len({id(m) for m in members}) != len(members):
        raise BadParameterError(what, members, f"distinct {kind.__name__} components")
    return members


def _require_active(members: Sequence[HALComponent], operation: str) -> None:
    for member in members:
        if member.state is not _ACTIVE:
            raise StateError(f"{operation} ({member.device_name})", member.state, (_ACTIVE,))


def _require_all_active(members: Sequence[HALComponent], operation: str, checked_at: int) -> int:
    """Every member Active (else StateError); returns the state-change count at which that
    held.  Skipped while no component changed state since ``checked_at`` (the caller's
    last successful check): a bank's members cannot have left Active meanwhile."""
    changes = STATE_CHANGES.value
    if checked_at != changes:
        _require_active(members, operation)
    return changes


def _require_nowait(members: Sequence[HALComponent], flag: str, operation: str) -> None:
    for member in members:
        if not getattr(member, flag):
            raise WouldBlockError(
                f"{member.device_name}: the device has no synchronous path; use 'await "
                f"{operation}(...)'"
            )


_CHECKER_CODE: dict[int, CodeType] = {}
"""The range checkers' code by member count (bounds are their default arguments)."""


def _range_checker(lows: Sequence[float], highs: Sequence[float]) -> Callable[[Any], bool]:
    """``check(values)``, for a list or tuple ``values``: whether it holds one float per
    bound, each within ``[lows[i], highs[i]]`` (finite bounds: NaN and infinities fail a
    comparison).  One straight-line function per member count, generated once: the values
    unpacked, then per value one type test and one chained comparison, with no loop, no
    temporary tuple and no call."""
    n = len(lows)
    code = _CHECKER_CODE.get(n)
    if code is None:
        values = "".join(f"v{i}, " for i in range(n))
        tests = " and ".join(f"type(v{i}) is F and l{i} <= v{i} <= h{i}" for i in range(n))
        source = (
            "def check(values, /, F=float, type=type, "
            + "".join(f"l{i}=0.0, h{i}=0.0, " for i in range(n))
            + "):\n"
            + "    try:\n"
            + f"        {values}= values\n"
            + "    except ValueError:\n"
            + "        return False\n"
            + f"    return {tests}\n"
        )
        namespace: dict[str, Any] = {}
        exec(compile(source, "<bank range check>", "exec"), namespace)  # our own names only
        code = _CHECKER_CODE[n] = namespace["check"].__code__
    check = FunctionType(code, {"__builtins__": __builtins__})
    defaults: tuple[object, ...] = (float, type)
    for low, high in zip(lows, highs, strict=True):
        defaults += (low, high)
    check.__defaults__ = defaults
    return cast(Callable[[Any], bool], check)


class ActuatorBank:
    """Actuators commanded together; see the module docstring.

    ``setpoint_events``: whether reaching the values sent posts COMPLETED to each actuator's
    observers, as ``set_value`` does (True, the default); False for setpoints streamed along
    a trajectory, whose arrival the caller announces itself (their Motions still complete:
    ``Motion.posts_completed`` is False).
    """

    def __init__(self, actuators: Iterable[Actuator], *, setpoint_events: bool = True) -> None:
        if not isinstance(setpoint_events, bool):
            raise BadParameterError("setpoint_events", setpoint_events, "True or False")
        self.setpoint_events = setpoint_events
        self.actuators = _members(actuators, Actuator, "actuators")
        self._devices = tuple(a.device for a in self.actuators)
        # STATE_CHANGES.value when every actuator was last seen Active (-1: never).
        self._active_at = -1
        self._nowait = all(a._command_nowait for a in self.actuators)
        self._read_nowait = all(a._read_nowait for a in self.actuators)
        # The *_ACTUAL codes every actuator reads from its device (the others answer some
        # with the commanded value).
        self._read_codes = tuple(
            req
            for req in self.actuators[0]._read_codes
            if all(req in a._read_codes for a in self.actuators)
        )
        clocks = {id(a.clock) for a in self.actuators}
        # Streamed commands are stamped with one clock reading when the actuators share it.
        self._now_ns = self.actuators[0].clock.now_ns if len(clocks) == 1 else None
        # Position limits and support: a POSITION batch is checked by one generated function
        # (each value a float within its device's limits).  The limits are re-read whenever
        # any device's were set since (device.LIMITS_CHANGES: one comparison per batch).
        devices = self._devices
        self._limits_at = -1
        self._lows: tuple[float, ...] = ()
        self._highs: tuple[float, ...] = ()
        self._in_range: Callable[[Any], bool] = bool
        self._read_limits()
        self._positions = all(_POSITION in d.supported_requests for d in devices)
        # One device call for the whole batch when the driver offers one (every device of
        # one class); only where the Motions are lazy (devices report completion).
        classes = {type(d) for d in devices}
        classes_of = list(classes)
        self._batch = (
            classes.pop().batch_commander(devices)
            if len(classes) == 1
            and self._nowait
            and all(a._reports_completion for a in self.actuators)
            else None
        )
        # The same over devices that need an await (a bus's one write for every drive).
        self._async_batch = (
            classes_of[0].async_batch_commander(devices)
            if len(classes_of) == 1
            and not self._nowait
            and all(a._reports_completion for a in self.actuators)
            else None
        )
        # The latest batch the device batch commanded, which the actuators settle from
        # lazily (one stamp per batch: only when they share a clock).
        self._streamed = (
            StreamBatch(len(devices), setpoint_events)
            if self._now_ns is not None
            and (self._batch is not None or self._async_batch is not None)
            else None
        )
        # The streaming tick checked inline by set_values_nowait: POSITION batches streamed
        # through the device batch, every device supporting POSITION.
        self._stream_inline = (
            self._streamed is not None and self._batch is not None and self._positions
        )
        # The members' batch listener for reads (asked again when LISTENING.changes moved).
        self._read_listen_at = -1
        self._on_read: BatchListener | None = None

    def __len__(self) -> int:
        return len(self.actuators)

    def __iter__(self) -> Iterator[Actuator]:
        return iter(self.actuators)

    def _read_limits(self) -> None:
        """Read every device's position limits (as they are at LIMITS_CHANGES now).

        Infinite limits become the largest float, so the bounds reject infinities; NaN
        fails every comparison.
        """
        self._limits_at = LIMITS_CHANGES.value
        positions = [d.limits.position for d in self._devices]
        lows = self._lows = tuple([max(p[0], -_MAX) for p in positions])
        highs = self._highs = tuple([min(p[1], _MAX) for p in positions])
        self._in_range = _range_checker(lows, highs)

    # -- SetValue on every actuator ---------------------------------------------------
    async def set_values(
        self, values: Sequence[float], request: Request | int = Request.POSITION
    ) -> None:
        """``set_value(values[i], request)`` on actuator i, all validated before any is sent.

        Each command's Motion is ``actuator.motion`` (see :attr:`motions`); it is built only
        when asked for, so streaming setpoints costs no Motion per axis and tick.
        """
        req, targets = self._check("set_values", values, request)
        if self._nowait:
            self._stream(req, targets)
        else:
            await self._send_awaited(req, targets)

    async def _send_awaited(self, req: Request, targets: Sequence[float]) -> None:
        """Send validated targets over devices that need an await: one awaited device batch
        when the driver offers one (``ActuatorDevice.async_batch_commander``) and takes this
        batch, else one awaited ``command`` per device, all in one coroutine
        (:func:`~openel_async.streaming.send_targets`)."""
        batch = self._async_batch
        streamed = self._streamed
        now_ns = self._now_ns
        if (
            batch is not None
            and streamed is not None
            and now_ns is not None
            and req is not _NO_EXCITE
        ):
            actuators = self.actuators
            if not streamed.intact or req is not streamed.request:
                # Attached before the await: a member commanded by another path meanwhile
                # leaves the stream (``intact`` cleared), so its later command stands.
                streamed.attach(actuators)
                streamed.request = req
            active_at = self._active_at
            stamp = now_ns()
            try:
                sent = await batch(req, targets)
            except LINK_FAULTS:
                sent = False  # nothing was sent: the per-device path reports the fault
            if sent:
                if streamed.intact and active_at == STATE_CHANGES.value:
                    streamed.accept(actuators, req, targets, stamp, LISTENING.count > 0)
                else:
                    self._accept_each(streamed, req, targets, stamp)
                return
        await send_targets(self.actuators, req, targets, self.setpoint_events, now_ns)

    def _accept_each(
        self, streamed: StreamBatch, req: Request, targets: Sequence[float], stamp: int
    ) -> None:
        """An awaited device batch's bookkeeping when something changed during the await:
        a member commanded by another path meanwhile (no longer attached) keeps that later
        command; the others take the batch's, lazily if still Active, else in full."""
        lazy: list[Actuator] = []
        lazy_targets: list[float] = []
        for actuator, target in zip(self.actuators, targets, strict=True):
            link = actuator._stream
            if link is None or link[0] is not streamed:
                continue  # its own later command stands
            if actuator.state is _ACTIVE:
                lazy.append(actuator)
                lazy_targets.append(target)
                continue
            actuator._accept(req, target, actuator._next_sequence(), self.setpoint_events)
        if lazy:
            accept_streamed(
                lazy, req, lazy_targets, stamp, LISTENING.count > 0, self.setpoint_events
            )

    def set_values_nowait(
        self, values: Sequence[float], request: Request | int = Request.POSITION
    ) -> None:
        """:meth:`set_values` without suspending (devices that need no I/O)."""
        if (
            self._stream_inline
            and request is _POSITION
            and (type(values) is list or type(values) is tuple)
        ):  # the streaming tick, inline: a batch of floats within the limits, one device call
            if self._limits_at != LIMITS_CHANGES.value:  # a device's limits were set
                self._read_limits()
            if self._in_range(values):
                actuators = self.actuators
                if self._active_at != STATE_CHANGES.value:
                    self._active_at = _require_all_active(actuators, "set_values_nowait", -1)
                streamed = self._streamed
                now_ns = self._now_ns
                batch = self._batch
                assert streamed is not None and now_ns is not None and batch is not None
                stamp = now_ns()
                try:
                    sent = batch(_POSITION, values)
                except LINK_FAULTS:
                    sent = False  # nothing was sent: the per-device path reports the fault
                if sent:
                    streamed.accept(actuators, _POSITION, values, stamp, LISTENING.count > 0)
                else:
                    stream_targets(actuators, _POSITION, values, stamp, self.setpoint_events)
                return
        if not self._nowait:
            _require_nowait(self.actuators, "_command_nowait", "set_values")
        req, targets = self._check("set_values_nowait", values, request)
        self._stream(req, targets)

    def _stream(self, req: Request, targets: Sequence[float]) -> None:
        """Send validated targets: one device batch when the driver takes it, else one
        ``command_nowait`` per device (which also tells a link fault's own actuator)."""
        now_ns = self._now_ns
        stamp = None if now_ns is None else now_ns()
        batch = self._batch
        if batch is not None and req is not _NO_EXCITE:
            try:
                sent = batch(req, targets)
            except LINK_FAULTS:
                sent = False  # nothing was sent: the per-device path reports the fault
            if sent:
                streamed = self._streamed
                if streamed is not None and stamp is not None:
                    streamed.accept(self.actuators, req, targets, stamp, LISTENING.count > 0)
                else:
                    accept_streamed(
                        self.actuators,
                        req,
                        targets,
                        stamp,
                        LISTENING.count > 0,
                        self.setpoint_events,
                    )
                return
        stream_targets(self.actuators, req, targets, stamp, self.setpoint_events)

    def position_stream(
        self, lows: Sequence[float], highs: Sequence[float]
    ) -> Callable[[list[float]], None] | None:
        """A sender of POSITION batches proven in advance to lie within ``[lows[i], highs[i]]``
        for actuator i (e.g. a planned trajectory's extrema), or None if the bank cannot
        stream that way (no device batch, a device without POSITION, a bound not finite, or
        outside its device's limits).

        ``send(values)``, values a list of one float per actuator each within its bounds
        (the caller's proof), is :meth:`set_values_nowait` without the per-value checks
        that the proof made once: a batch the proof covers passes those checks (types,
        finiteness, limits) as long as no device's limits are set.  Every actuator is still
        checked Active at every batch (``component.STATE_CHANGES``), and the proof is made
        again when a device's limits were set (``device.LIMITS_CHANGES``): while it fails,
        each batch goes through :meth:`set_values_nowait` (a value outside the new limits
        raises its BadParameterError, nothing sent).
        """
        streamed = self._streamed
        batch = self._batch
        now_ns = self._now_ns
        if streamed is None or batch is None or now_ns is None or not self._positions:
            return None
        bounds = self._proof(lows, highs)
        if bounds is None:
            return None
        lows, highs = bounds
        actuators = self.actuators
        setpoint_events = self.setpoint_events
        proves = functools.partial(self._proves, lows, highs)
        proven_at = self._limits_at  # LIMITS_CHANGES.value when the proof last held

        def send(values: list[float]) -> None:
            nonlocal proven_at
            if proven_at != LIMITS_CHANGES.value:  # a device's limits were set: prove again
                if not proves():  # this batch, value by value (else nothing is sent)
                    self.set_values_nowait(values, _POSITION)
                    return
                proven_at = self._limits_at
            if self._active_at != STATE_CHANGES.value:
                self._active_at = _require_all_active(actuators, "set_values_nowait", -1)
            stamp = now_ns()
            try:
                sent = batch(_POSITION, values)
            except LINK_FAULTS:
                sent = False  # nothing was sent: the per-device path reports the fault
            if sent:
                streamed.accept(actuators, _POSITION, values, stamp, LISTENING.count > 0)
            else:
                stream_targets(actuators, _POSITION, values, stamp, setpoint_events)

        return send

    def position_stream_awaited(
        self, lows: Sequence[float], highs: Sequence[float]
    ) -> Callable[[list[float]], Awaitable[None]] | None:
        """:meth:`position_stream` over devices that need an await: ``send(values)`` returns
        the awaitable of :meth:`set_values` without the per-value checks the proof made once
        (one awaited device batch, ``ActuatorDevice.async_batch_commander``).  None when the
        bank has no awaited device batch (or the proof fails, as for :meth:`position_stream`).

        The same checks stay per batch: every actuator Active before anything is sent (a
        ``StateError`` raised by ``send`` itself, nothing sent), the proof made again when a
        device's limits were set (while it fails, the batch goes through :meth:`set_values`).
        ``send`` is a plain function returning the batch's coroutine: no coroutine of its own.
        """
        streamed = self._streamed
        now_ns = self._now_ns
        if streamed is None or self._async_batch is None or now_ns is None or not self._positions:
            return None
        bounds = self._proof(lows, highs)
        if bounds is None:
            return None
        actuators = self.actuators
        proves = functools.partial(self._proves, *bounds)
        proven_at = self._limits_at  # LIMITS_CHANGES.value when the proof last held
        send_awaited = self._send_awaited

        def send(values: list[float]) -> Awaitable[None]:
            nonlocal proven_at
            if proven_at != LIMITS_CHANGES.value:  # a device's limits were set: prove again
                if not proves():  # this batch, value by value (else nothing is sent)
                    return self.set_values(values, _POSITION)
                proven_at = self._limits_at
            if self._active_at != STATE_CHANGES.value:
                self._active_at = _require_all_active(actuators, "set_values", -1)
            return send_awaited(_POSITION, values)

        return send

    def _proof(
        self, lows: Sequence[float], highs: Sequence[float]
    ) -> tuple[tuple[float, ...], tuple[float, ...]] | None:
        """``(lows, highs)`` as tuples if they prove every batch within them (one bound per
        device, finite, within the device's limits), else None."""
        if len(lows) != len(self._devices) or len(highs) != len(self._devices):
            return None
        bounds = tuple(lows), tuple(highs)
        return bounds if self._proves(*bounds) else None

    def _proves(self, lows: Sequence[float], highs: Sequence[float]) -> bool:
        """Whether every ``[lows[i], highs[i]]`` is finite and within device i's position
        limits (as they are now: re-read if any device's were set)."""
        if self._limits_at != LIMITS_CHANGES.value:
            self._read_limits()
        for low, high, bank_low, bank_high in zip(
            lows, highs, self._lows, self._highs, strict=True
        ):
            if not (
                math.isfinite(low) and math.isfinite(high) and bank_low <= low and high <= bank_high
            ):
                return False
        return True

    @property
    def motions(self) -> tuple[Motion | None, ...]:
        """The Motion of every actuator's latest command (None before its first)."""
        return tuple([a.motion for a in self.actuators])

    def _check(
        self, operation: str, values: Sequence[float], request: Request | int
    ) -> tuple[Request, Sequence[float]]:
        """State, request, count, finiteness, support and limits of every value, in one pass.

        The common case (Active actuators, float values inside the limits) is checked inline
        here; anything else goes through each actuator's own checks for the exact error.
        """
        actuators = self.actuators
        if type(request) is Request and request in _SETTABLE:
            req = request
        else:
            req = coerce_request(request, SET_VALUE_REQUESTS)
        try:
            count = len(values)
        except TypeError:  # None, a number, an iterator: not a sequence
            count = -1
        if count != len(actuators):
            raise BadParameterError(
                "values",
                values,
                f"a sequence of {len(actuators)} values, one per actuator of the bank",
            )
        if req is _POSITION:
            if self._in_limits(values):
                self._active_at = _require_all_active(actuators, operation, self._active_at)
                return req, values
            return req, self._check_each(operation, values, req)
        return req, self._check_each(operation, values, req)

    def _in_limits(self, values: Sequence[float]) -> bool:
        """Whether ``values`` (a sequence) are POSITION targets the bank takes as they are:
        one float per actuator, each finite and within its device's limits (one generated check;
        False sends the caller through each actuator's own checks for the exact error)."""
        if not self._positions or not (type(values) is list or type(values) is tuple):
            return False
        if self._limits_at != LIMITS_CHANGES.value:  # a device's limits were set
            self._read_limits()
        return self._in_range(values)

    def _check_each(self, operation: str, values: Sequence[float], req: Request) -> list[float]:
        _require_active(self.actuators, operation)
        targets = []
        for i, (actuator, value) in enumerate(zip(self.actuators, values, strict=True)):
            try:
                targets.append(actuator._check_target(req, value))
            except BadParameterError as exc:
                raise BadParameterError(
                    f"values[{i}]", value, f"{exc.allowed} for {actuator.device_name}"
                ) from None
        return targets

    # -- GetValue on every actuator ---------------------------------------------------
    async def get_values(
        self, request: Request | int = Request.POSITION_ACTUAL
    ) -> tuple[float, ...]:
        """``get_value(request)`` of every actuator."""
        if self._read_nowait:
            return self._get_now("get_values", request)
        return tuple([await a.get_value(request) for a in self.actuators])

    def get_values_nowait(
        self, request: Request | int = Request.POSITION_ACTUAL
    ) -> tuple[float, ...]:
        """:meth:`get_values` without suspending (devices that need no I/O)."""
        return self._get_now("get_values_nowait", request)

    def _get_now(self, operation: str, request: Request | int) -> tuple[float, ...]:
        req = coerce_request(request, GET_VALUE_REQUESTS)
        values = self._values_now(operation, req)
        if LISTENING.count and req in _ACTUAL_CODES:  # the members' listeners hear the read
            if self._read_listen_at != LISTENING.changes:  # a listener was set or removed
                self._read_listener()
            on_read = self._on_read
            if on_read is not None and self._now_ns is not None:  # one call for the read
                on_read(req, values, self._now_ns())
            else:
                tell_readings(self.actuators, req, [(v,) for v in values])
        return values

    def _read_listener(self) -> None:
        """Ask the members' listeners again for a batch listener for the reads (only when
        the members share a clock)."""
        self._read_listen_at = LISTENING.changes
        self._on_read = batch_listener(self.actuators) if self._now_ns is not None else None

    def _values_now(self, operation: str, req: Request) -> tuple[float, ...]:
        actuators = self.actuators
        self._active_at = _require_all_active(actuators, operation, self._active_at)
        if req in self._read_codes:  # every device reads it: one loop, one try
            if not self._read_nowait:
                _require_nowait(actuators, "_read_nowait", "get_values")
            out: list[float] = []
            append = out.append
            try:
                for device in self._devices:
                    append(device.read_nowait(req))
            except LINK_FAULTS as exc:
                raise actuators[len(out)]._fault_from(exc) from exc
            # One sum: a finite float unless a value is non-finite or none is a float (ints
            # among floats pass as they are: Python's numeric tower).
            try:
                total = sum(out)
            except TypeError:
                total = math.nan
            if type(total) is float and total - total == 0.0:
                return tuple(out)
            return tuple([a._checked_actual(req, v) for a, v in zip(actuators, out, strict=True)])
        if req.is_command:
            return tuple([a._commanded_value(req) for a in actuators])
        if not self._read_nowait:
            _require_nowait(actuators, "_read_nowait", "get_values")
        out = []
        append = out.append
        for actuator in actuators:
            if req not in actuator._read_codes:  # neither measured nor estimated
                append(actuator._commanded_value(req))
                continue
            try:
                value = actuator.device.read_nowait(req)
            except LINK_FAULTS as exc:
                raise actuator._fault_from(exc) from exc
            if type(value) is not float or value - value != 0.0:  # not a finite float
                value = actuator._checked_actual(req, value)
            append(value)
        return tuple(out)

    def __repr__(self) -> str:
        return f"ActuatorBank({[a.device_name for a in self.actuators]})"


class SensorBank:
    """Sensors read together; see the module docstring."""

    def __init__(self, sensors: Iterable[Sensor]) -> None:
        self.sensors = _members(sensors, Sensor, "sensors")
        self._nowait = all(s._nowait for s in self.sensors)
        self._active_at = -1  # STATE_CHANGES.value when every sensor was last seen Active
        self._count = len(self.sensors)
        devices = [s.device for s in self.sensors]
        classes = {type(d) for d in devices}
        # One device call for the whole bank when every device is of one class: the driver's
        # batch reader if it offers one (values and one flat sequence to check), else
        # read_values_many_nowait.
        self._devices = devices
        cls = classes.pop() if len(classes) == 1 else None
        self._read_many = None if cls is None else cls.read_values_many_nowait
        self._reader = None if cls is None or not self._nowait else cls.batch_reader(devices)
        # The members' unit/scale/origin settings, re-read when any sensor's changed.
        self._settings_version = -1
        self._measurements: tuple[Measurement | None, ...] | None = None

    def __len__(self) -> int:
        return len(self.sensors)

    def __iter__(self) -> Iterator[Sensor]:
        return iter(self.sensors)

    async def get_values(self) -> tuple[tuple[float, ...], ...]:
        """``get_value()`` of every sensor."""
        if self._nowait:
            return self._get_now("get_values")
        return tuple([await s.get_value() for s in self.sensors])  # each tells its listener

    def get_values_nowait(self) -> tuple[tuple[float, ...], ...]:
        """:meth:`get_values` without suspending (devices that need no I/O)."""
        if (
            self._active_at == STATE_CHANGES.value
            and self._settings_version == MEASUREMENT_SETTINGS_VERSION.value
            and self._measurements is None
            and not LISTENING.count
        ):  # the control-step read, inline: every sensor Active, no conversion, no listener
            reader = self._reader
            if reader is not None:  # one driver call; one finiteness check of the batch
                try:
                    batch, values = reader()
                except LINK_FAULTS:
                    return self._read_each()
                try:
                    total = sum(batch)
                except TypeError:
                    total = math.nan
                if type(total) is float and total - total == 0.0 and len(values) == self._count:
                    return values
                return self._checked_batch(values)
            read_many = self._read_many
            if read_many is None:
                return self._get_now("get_values_nowait")
            try:
                out = tuple(read_many(self._devices))
            except LINK_FAULTS:
                return self._read_each()
            if len(out) == self._count:  # (else _checked_batch raises)
                # One finiteness check over the flat tuple, as in _checked_batch.
                try:
                    flat: object = sum(out, ())  # type: ignore[type-var]
                    total = sum(flat) if type(flat) is tuple else math.nan
                except Exception:  # a driver returned something else than tuples of floats
                    total = math.nan
                if type(total) is float and total - total == 0.0:
                    return cast(tuple[tuple[float, ...], ...], out)
            return self._checked_batch(out)
        return self._get_now("get_values_nowait")

    def _get_now(self, operation: str) -> tuple[tuple[float, ...], ...]:
        values = self._converted_now(operation)
        if LISTENING.count:
            tell_readings(self.sensors, None, values)
        return values

    def _converted_now(self, operation: str) -> tuple[tuple[float, ...], ...]:
        values = self._read_now(operation)
        if self._settings_version != MEASUREMENT_SETTINGS_VERSION.value:
            self._settings_version = MEASUREMENT_SETTINGS_VERSION.value
            measurements = tuple(s._measurement for s in self.sensors)
            self._measurements = measurements if any(m is not None for m in measurements) else None
        if self._measurements is None:
            return values
        return tuple(
            [
                v if m is None else s._converted_values(v)
                for s, m, v in zip(self.sensors, self._measurements, values, strict=True)
            ]
        )

    def _read_now(self, operation: str) -> tuple[tuple[float, ...], ...]:
        sensors = self.sensors
        active_at = _require_all_active(sensors, operation, self._active_at)
        if not self._nowait:
            _require_nowait(sensors, "_nowait", "get_values")
        self._active_at = active_at  # (only for a synchronous bank: get_values_nowait's test)
        reader = self._reader
        if reader is not None:
            try:
                values = reader()[1]
            except LINK_FAULTS:
                pass  # read them one by one below: the fault lands on its own sensor
            else:
                return self._checked_batch(values)
        elif self._read_many is not None:
            try:
                batch = self._read_many(self._devices)
            except LINK_FAULTS:
                pass  # read them one by one below: the fault lands on its own sensor
            else:
                return self._checked_batch(batch)
        return self._read_each()

    def _checked_batch(self, batch: Sequence[Sequence[float]]) -> tuple[tuple[float, ...], ...]:
        """The values of one ``read_values_many_nowait``, checked: one tuple of finite floats
        per sensor (anything else is its sensor's device fault)."""
        sensors = self.sensors
        out = tuple(batch)
        if len(out) != len(sensors):
            raise HALError(
                f"{type(self._devices[0]).__name__}.read_values_many_nowait returned "
                f"{len(out)} values for {len(sensors)} devices"
            )
        # The common case in two C calls: concatenation succeeds only for tuples, and one
        # sum is finite only if every value is (x - x is 0.0 for finite x).  The per-sensor
        # checks find what is wrong otherwise.
        try:
            flat: object = sum(out, ())  # type: ignore[type-var]
            total = sum(flat) if type(flat) is tuple else math.nan
        except Exception:  # a driver returned something else than tuples of floats
            total = math.nan
        if type(total) is float and total - total == 0.0:
            return cast(tuple[tuple[float, ...], ...], out)
        return tuple([s._checked_values(v) for s, v in zip(sensors, out, strict=True)])

    def _read_each(self) -> tuple[tuple[float, ...], ...]:
        """Every sensor's ``read_nowait``, checked (a link fault lands on its own sensor)."""
        sensors = self.sensors
        values_out = []
        for sensor in sensors:
            try:
                values = sensor.device.read_nowait().values
            except LINK_FAULTS as exc:
                raise sensor._fault_from(exc) from exc
            values_out.append(sensor._checked_values(values))
        return tuple(values_out)

    def __repr__(self) -> str:
        return f"SensorBank({[s.device_name for s in self.sensors]})"
