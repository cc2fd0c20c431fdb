"""Actuator: SetValue/GetValue of a one-degree-of-freedom actuator, with completion.

``set_value`` returns as soon as the device accepted the target and gives back a
:class:`Motion`. Reaching the target posts event 1 (COMPLETED) to the observers,
exactly once and only for the final target: a replaced target's Motion raises
:class:`SupersededError` and posts nothing. Setpoints streamed by an AxisGroup are not
targets in that sense: their Motions post nothing (``Motion.posts_completed``) and the
group posts one COMPLETED per axis when its motion arrives.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import anyio

from .clock import Clock
from .completion import Motion, Outcome
from .component import LINK_FAULTS as _LINK_FAULTS
from .component import ComponentState, HALComponent
from .device import ACTUAL_REQUESTS, ActuatorDevice, ErrorId, ValueSource, has_nowait
from .errors import (
    BadParameterError,
    DeviceFaultError,
    HALError,
    NotImplementedHALError,
    StateError,
    WouldBlockError,
)
from .ids import HALId
from .requests import GET_VALUE_REQUESTS, SET_VALUE_REQUESTS, EventId, Request, coerce_request

# The streaming paths (ActuatorBank, AxisGroup) live in openel_async.streaming; re-exported.
from .streaming import StreamBatch as StreamBatch
from .streaming import accept_streamed as accept_streamed
from .streaming import send_targets as send_targets
from .streaming import stream_targets as stream_targets

S = ComponentState
# Enum members read as module constants on the per-command paths (~80 ns saved each).
_ACTIVE = S.ACTIVE
_PENDING = Outcome.PENDING
_SUPERSEDED = Outcome.SUPERSEDED
_NO_EXCITE = Request.NO_EXCITE
_SETTABLE = frozenset(SET_VALUE_REQUESTS)
_POSITION = Request.POSITION
_POSITION_ACTUAL = Request.POSITION_ACTUAL
# get_value of a code the device does not read returns the commanded value of this code.
COMMAND_OF = {
    Request.POSITION: Request.POSITION,
    Request.VELOCITY: Request.VELOCITY,
    Request.TORQUE: Request.TORQUE,
    Request.POSITION_ACTUAL: Request.POSITION,
    Request.VELOCITY_ACTUAL: Request.VELOCITY,
    Request.TORQUE_ACTUAL: Request.TORQUE,
}


@dataclass(frozen=True, slots=True)
class CompletionPolicy:
    """How the framework decides a target is reached for devices that cannot tell.

    The actual value must stay within tolerance of the target for ``settle_ns``,
    sampled every ``poll_ns`` on the component's clock.
    """

    position_tolerance: float = 1e-3
    velocity_tolerance: float = 1e-2
    torque_tolerance: float = 1e-2
    settle_ns: int = 20_000_000
    poll_ns: int = 5_000_000

    def __post_init__(self) -> None:
        for name in ("position_tolerance", "velocity_tolerance", "torque_tolerance"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise BadParameterError(name, value, "a finite value > 0")
        if self.settle_ns < 0:
            raise BadParameterError("settle_ns", self.settle_ns, "an int >= 0")
        if self.poll_ns <= 0:
            raise BadParameterError("poll_ns", self.poll_ns, "an int > 0")

    def tolerance(self, request: Request) -> float:
        if request is Request.POSITION:
            return self.position_tolerance
        if request is Request.VELOCITY:
            return self.velocity_tolerance
        return self.torque_tolerance


def _finite(value: object) -> float:
    if type(value) is float and math.isfinite(value):  # the hot path
        return value
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise BadParameterError("value", value, "a finite real number")
    try:
        result = float(value)
    except OverflowError:  # an int beyond the float range
        result = math.inf
    if not math.isfinite(result):
        raise BadParameterError("value", value, "a finite real number (not NaN or infinity)")
    return result


class Actuator(HALComponent):
    """An OpenEL Actuator over an :class:`ActuatorDevice` driver."""

    device: ActuatorDevice
    device_class = ActuatorDevice

    def __init__(
        self,
        device: ActuatorDevice,
        *,
        hal_id: HALId | None = None,
        device_name: str | None = None,
        function_list: tuple[str, ...] | None = None,
        clock: Clock | None = None,
        auto_init: bool = True,
        open_timeout: float = 10.0,
        completion: CompletionPolicy | None = None,
    ) -> None:
        super().__init__(
            device,
            hal_id=hal_id,
            device_name=device_name,
            function_list=function_list,
            clock=clock,
            auto_init=auto_init,
            open_timeout=open_timeout,
        )
        if completion is not None and not isinstance(completion, CompletionPolicy):
            raise BadParameterError("completion", completion, "a CompletionPolicy or None")
        # The *_ACTUAL codes read from the device; the others are answered with the
        # commanded value. A tuple: ``in`` finds a member by identity, where a set would call
        # Enum.__hash__ (Python code) on every read.  (No more instance attributes than
        # needed: past 29, CPython 3.11 gives up its fast attribute layout.)
        self._read_codes = tuple(
            req
            for req, source in _value_sources(device).items()
            if source is not ValueSource.COMMANDED
        )
        self.completion = completion or CompletionPolicy()
        self._sequence = 0
        # A device may report the target reached from inside command_nowait (it reaches
        # targets at once): that is the command being sent, whose Motion does not exist yet.
        self._sync_send = 0  # sequence of the command inside command_nowait, else 0
        self._reached_in_send = 0  # sequence reported reached from inside command_nowait
        self._motion: Motion | None = None
        self._latest: tuple[Request, float, int, int, bool] | None = None
        """The latest command when no Motion was built for it yet (see ``stream_targets``):
        the arguments of its Motion."""
        self._stream: tuple[StreamBatch, int, int, int] | None = None
        """Attached to a bank's batch stream: (batch, index in it, the batch's count and this
        actuator's sequence when last settled); see :class:`StreamBatch`."""
        self._commanded: dict[Request, float] = {
            Request.POSITION: 0.0,
            Request.VELOCITY: 0.0,
            Request.TORQUE: 0.0,
        }
        self._watch: anyio.Event = anyio.Event()
        self.completed_count = 0
        self._detector_started = False
        self._reports_completion = device.reports_completion
        self._command_nowait = has_nowait(device, "command_nowait", "command")
        self._read_nowait = has_nowait(device, "read_nowait", "read")

    @property
    def actuator_kind(self) -> int:
        """HAL4RT ``actuatorKind``: the device kind id (``DeviceKind.MOTOR`` for a motor)."""
        return self.hal_id.device_kind_id

    @property
    def motion(self) -> Motion | None:
        """The latest command's Motion."""
        link = self._stream
        if link is not None:
            self._settle()
        latest = self._latest
        if latest is not None:  # streamed by an ActuatorBank: built when asked for
            self._latest = None
            self._motion = Motion(*latest)
            if link is not None:  # the bank's next batch supersedes it
                link[0].built.append(self)
        return self._motion

    def _settle(self) -> None:
        """Bring the batches a bank streamed since the last settle into this actuator's own
        state (sequence, commanded value, latest command): see :class:`StreamBatch`."""
        link = self._stream
        if link is None:
            return
        batch, index, count, sequence = link
        behind = batch.count - count
        if behind:
            sequence += behind
            req, target = batch.request, batch.targets[index]
            self._sequence = sequence
            self._latest = (req, target, sequence, batch.stamp, batch.posts_completed)
            self._commanded[req] = target
            self._stream = (batch, index, batch.count, sequence)

    def _detach(self) -> None:
        """Leave the bank's batch stream (a command by another path follows)."""
        link = self._stream
        if link is not None:
            self._settle()
            self._stream = None
            link[0].intact = False

    # -- SetValue ------------------------------------------------------------------
    async def set_value(self, value: float, request: Request | int = Request.POSITION) -> Motion:
        """SetValue: send a new target and return its Motion without waiting for arrival."""
        if self._command_nowait:  # a device that needs no I/O: the same, without suspending
            return self._set_now("set_value", value, request)
        req, target = self._validate("set_value", value, request)
        return await self._send(req, target)

    def set_value_nowait(self, value: float, request: Request | int = Request.POSITION) -> Motion:
        """SetValue without suspending, for synchronous code (a plain TimerObserver).

        Same semantics as :meth:`set_value`; only for devices that need no I/O to accept a
        command (simulations); others raise :class:`WouldBlockError`.
        """
        if not self._command_nowait:
            raise WouldBlockError(
                f"{self.device_name}: the device has no synchronous command path; "
                "use 'await set_value(...)'"
            )
        return self._set_now("set_value_nowait", value, request)

    def _set_now(self, operation: str, value: object, request: Request | int) -> Motion:
        """:meth:`_validate` then :meth:`_send_now` in one call (the per-command path of a
        control loop over a device without I/O): the same checks, in the same order."""
        if self.state is not _ACTIVE:
            raise StateError(operation, self.state, (_ACTIVE,))
        if type(request) is Request and request in _SETTABLE:
            req = request
        else:
            req = coerce_request(request, SET_VALUE_REQUESTS)
        target = value if type(value) is float and value - value == 0.0 else _finite(value)
        device = self.device
        if req not in device.supported_requests:
            raise NotImplementedHALError(f"{self.device_name} does not support {req.name} control")
        limits = device.limits
        if req is not _POSITION:
            limits.check(req, target)
        else:
            low, high = limits.position
            if not low <= target <= high:
                limits.check(req, target)  # raises BAD_PARAMETER
        if self._stream is not None:
            self._detach()
        sequence = self._sequence = self._sync_send = self._sequence + 1
        try:
            device.command_nowait(req, target)
        except _LINK_FAULTS as exc:
            raise self._fault_from(exc) from exc
        finally:
            self._sync_send = 0
        previous = self._motion
        if (
            self.state is _ACTIVE
            and self._stream is None
            and self._latest is None
            and self._observers.listener is None
            and req is not _NO_EXCITE
            and (previous is None or previous.sequence < sequence)
        ):  # _accept's common case, inline: the per-command path of a control loop
            motion = Motion(req, target, sequence, self.clock.now_ns())
            self._motion = motion
            if previous is not None and previous.outcome is _PENDING:
                previous._superseded_by = sequence  # previous._supersede(sequence), inline
                if previous._done is None:  # nobody waits: _finish(_SUPERSEDED), inline
                    previous.outcome = _SUPERSEDED
                else:
                    previous._finish(_SUPERSEDED)
            self._commanded[req] = target
            if not self._reports_completion:
                self._watch.set()
        else:
            motion = self._accept(req, target, sequence)
        if self._reached_in_send == sequence:
            self._reached_in_send = 0
            self._on_target_reached()
        return motion

    def _validate(
        self, operation: str, value: object, request: Request | int
    ) -> tuple[Request, float]:
        """Check state and arguments; returns (request, target)."""
        if self.state is not _ACTIVE:
            raise StateError(operation, self.state, (_ACTIVE,))
        # Inline fast path of coerce_request.
        if type(request) is Request and request in _SETTABLE:
            req = request
        else:
            req = coerce_request(request, SET_VALUE_REQUESTS)
        return req, self._check_target(req, value)

    def _check_target(self, req: Request, value: object) -> float:
        """The target as a float, or BAD_PARAMETER/NOT_IMPLEMENTED (request, finiteness, limits)."""
        # Inline fast path of _finite: x - x is 0.0 exactly for finite floats.
        target = value if type(value) is float and value - value == 0.0 else _finite(value)
        device = self.device
        if req not in device.supported_requests:
            raise NotImplementedHALError(f"{self.device_name} does not support {req.name} control")
        device.limits.check(req, target)
        return target

    async def _send(self, req: Request, target: float, posts_completed: bool = True) -> Motion:
        """Send a validated command and make its Motion the current one."""
        # Commands reach the device in call order; the sequence number taken before the
        # device call decides which target is final if calls overlap (a bus send).
        sequence = self._next_sequence()
        try:
            await self.device.command(req, target)
        except _LINK_FAULTS as exc:
            raise self._fault_from(exc) from exc
        return self._accept(req, target, sequence, posts_completed)

    def _send_now(self, req: Request, target: float) -> Motion:
        """:meth:`_send` through the device's synchronous path."""
        sequence = self._sync_send = self._next_sequence()
        try:
            self.device.command_nowait(req, target)
        except _LINK_FAULTS as exc:
            raise self._fault_from(exc) from exc
        finally:
            self._sync_send = 0
        motion = self._accept(req, target, sequence)
        if self._reached_in_send == sequence:
            self._reached_in_send = 0
            self._on_target_reached()
        return motion

    def _next_sequence(self) -> int:
        """The sequence number of a command about to be sent by this actuator itself (it
        leaves a bank's batch stream first)."""
        if self._stream is not None:
            self._detach()
        self._sequence += 1
        return self._sequence

    def _accept(
        self, req: Request, target: float, sequence: int, posts_completed: bool = True
    ) -> Motion:
        """The device accepted the command: make its Motion the current one."""
        motion = Motion(req, target, sequence, self.clock.now_ns(), posts_completed)
        listener = self._observers.listener
        if listener is not None:
            listener.on_command(self, req, target, motion.issued_ns)
        if self.state is not _ACTIVE:  # faulted or finalized while the command was sent
            if self.last_fault is not None:
                motion._fault(self.last_fault)
            else:
                motion._cancel(f"the actuator left Active ({self.state}) during set_value")
            return motion
        # (the motion property, inline when nothing is left to settle or build)
        previous = self._motion if self._stream is None and self._latest is None else self.motion
        if previous is not None and previous.sequence > sequence:
            motion._supersede(previous.sequence)  # a later command overtook this one
            return motion
        self._motion = motion
        if previous is not None and previous.outcome is _PENDING:
            previous._supersede(sequence)
        if req is _NO_EXCITE:
            commanded = self._commanded
            commanded[Request.VELOCITY] = commanded[Request.TORQUE] = 0.0
            self._complete(motion)
        else:
            self._commanded[req] = target
            if not self._reports_completion:
                self._watch.set()
        return motion

    # -- GetValue ------------------------------------------------------------------
    async def get_value(self, request: Request | int = Request.POSITION_ACTUAL) -> float:
        """GetValue: last commanded value (codes 1-3) or actual value (codes 5-7).

        An actual quantity the device cannot measure is its estimate, or else the commanded
        value (OpenEL §7.4.1.7); :meth:`value_source` tells which.
        """
        if self.state is not _ACTIVE:
            raise StateError("get_value", self.state, (_ACTIVE,))
        req = coerce_request(request, GET_VALUE_REQUESTS)
        if req not in self._read_codes:
            return self._commanded_value(req)
        try:
            if self._read_nowait:  # a device that needs no I/O: the same, without suspending
                value = self.device.read_nowait(req)
            else:
                value = await self.device.read(req)
        except _LINK_FAULTS as exc:
            raise self._fault_from(exc) from exc
        if type(value) is not float or value - value != 0.0:  # not a finite float
            value = self._checked_actual(req, value)
        listener = self._observers.listener
        if listener is not None:
            listener.on_reading(self, req, (value,))
        return value

    def get_value_nowait(self, request: Request | int = Request.POSITION_ACTUAL) -> float:
        """GetValue without suspending (see :meth:`set_value_nowait`)."""
        if self.state is not _ACTIVE:
            raise StateError("get_value_nowait", self.state, (_ACTIVE,))
        req = coerce_request(request, GET_VALUE_REQUESTS)
        if req not in self._read_codes:
            return self._commanded_value(req)
        if not self._read_nowait:
            raise WouldBlockError(
                f"{self.device_name}: the device has no synchronous read path; "
                "use 'await get_value(...)'"
            )
        try:
            value = self.device.read_nowait(req)
        except _LINK_FAULTS as exc:
            raise self._fault_from(exc) from exc
        if type(value) is not float or value - value != 0.0:  # not a finite float
            value = self._checked_actual(req, value)
        listener = self._observers.listener
        if listener is not None:
            listener.on_reading(self, req, (value,))
        return value

    def _commanded_value(self, req: Request) -> float:
        """The commanded value that ``get_value(req)`` answers (codes 1-3, or an actual
        quantity the device does not read)."""
        if self._stream is not None:
            self._settle()
        return self._commanded[COMMAND_OF[req]]

    def value_source(self, request: Request | int = Request.POSITION_ACTUAL) -> ValueSource:
        """Where ``get_value(request)`` comes from: MEASURED, ESTIMATED or COMMANDED.

        Fixed when the component is constructed (the device's ``measured_requests`` and
        ``estimated_requests``); codes 1-3 are always COMMANDED. Callable in any state.
        """
        req = coerce_request(request, GET_VALUE_REQUESTS)
        if req not in self._read_codes:
            return ValueSource.COMMANDED
        if req in self.device.estimated_requests:
            return ValueSource.ESTIMATED
        return ValueSource.MEASURED

    def _checked_actual(self, req: Request, value: object) -> float:
        """A value ``read()`` returned, as a finite float; else the device faulted: the
        component goes to Error and the DeviceFaultError is raised."""
        if isinstance(value, numbers.Real):
            try:
                result = float(value)
            except (TypeError, ValueError, OverflowError):
                result = math.nan
            if math.isfinite(result):
                return result
        raise self._fault(
            ErrorId.DEVICE_ERROR,
            f"read({req.name}) returned a non-finite or non-numeric value {value!r}",
        )

    async def _read_actual(self, req: Request) -> float:
        """``get_value(req)`` of an *_ACTUAL code, whatever the state (the watcher's read)."""
        if req not in self._read_codes:
            return self._commanded_value(req)
        try:
            value = await self.device.read(req)
        except _LINK_FAULTS as exc:
            raise self._fault_from(exc) from exc
        if type(value) is float and value - value == 0.0:
            return value
        return self._checked_actual(req, value)

    # -- completion ----------------------------------------------------------------
    def _complete(self, motion: Motion) -> None:
        if (
            motion is self.motion
            and motion._reach(self.clock.now_ns())
            and motion.posts_completed  # not a setpoint an AxisGroup streamed
        ):
            self.completed_count += 1
            self._publish_event(EventId.COMPLETED)

    def _post_completed(self) -> None:
        """COMPLETED for a target reached through streamed setpoints that posted none
        (an AxisGroup's motion arrived)."""
        self.completed_count += 1
        self._publish_event(EventId.COMPLETED)

    def _on_target_reached(self) -> None:
        if self._sync_send:  # from inside command_nowait: completed once it is accepted
            self._reached_in_send = self._sync_send
            return
        motion = self.motion
        if motion is not None and self.state is S.ACTIVE:
            self._complete(motion)

    async def _on_active(self) -> None:
        self._detach()  # a reset or a new start: the bank attaches it again
        position = self._commanded[Request.POSITION]  # kept if the device cannot read it
        if _POSITION_ACTUAL in self._read_codes:
            try:
                raw: object = await self.device.read(_POSITION_ACTUAL)
            except Exception:  # a device whose position reading fails starts at 0
                raw = 0.0
            position = self._checked_actual(_POSITION_ACTUAL, raw)  # NaN: a device fault
        self._commanded = {Request.POSITION: position, Request.VELOCITY: 0.0, Request.TORQUE: 0.0}
        if not self.device.reports_completion and not self._detector_started:
            self._detector_started = True  # one detector for the component's lifetime
            self._task_group().start_soon(self._detect_completion)

    async def _detect_completion(self) -> None:
        """Tolerance-and-settle detection for devices that do not report completion."""
        policy = self.completion
        clock = self.clock
        while self.state is not S.FINALIZED:
            motion = self.motion
            if motion is None or motion.done() or self.state is not S.ACTIVE:
                self._watch = anyio.Event()
                await self._watch.wait()
                continue
            tolerance = policy.tolerance(motion.request)
            within_since: int | None = None
            next_poll = clock.now_ns()
            while motion is self.motion and not motion.done() and self.state is S.ACTIVE:
                try:
                    actual = await self._read_actual(motion.request.actual)
                except HALError as exc:
                    if self.state is not S.ACTIVE:  # a link fault or a non-finite value
                        break
                    self.log.warning("completion_read_failed", error=str(exc))
                    actual = math.nan
                except Exception as exc:  # a driver bug must not tear the component down
                    self._fault(ErrorId.DEVICE_ERROR, f"reading the actual value failed: {exc!r}")
                    break
                now = clock.now_ns()
                if abs(actual - motion.target) <= tolerance:
                    within_since = now if within_since is None else within_since
                    if now - within_since >= policy.settle_ns:
                        self._complete(motion)
                        break
                else:
                    within_since = None
                next_poll += policy.poll_ns
                await clock.sleep_until(max(next_poll, now))

    def _on_fault(self, error: DeviceFaultError) -> None:
        motion = self.motion
        if motion is not None:
            motion._fault(error)
        self._watch.set()

    def _before_reset(self) -> None:
        motion = self.motion
        if motion is not None:
            motion._cancel("re_init reset the actuator")

    def _before_close(self) -> None:
        motion = self.motion
        if motion is not None:
            motion._cancel("the actuator was finalized")
        self._watch.set()


def _value_sources(device: ActuatorDevice) -> dict[Request, ValueSource]:
    """Where get_value of each code comes from, from the device's declarations."""
    measured, estimated = device.measured_requests, device.estimated_requests
    for name, codes in (("measured_requests", measured), ("estimated_requests", estimated)):
        if not (isinstance(codes, frozenset | set) and codes <= ACTUAL_REQUESTS):
            raise BadParameterError(
                f"device.{name}", codes, "a set of POSITION_ACTUAL, VELOCITY_ACTUAL, TORQUE_ACTUAL"
            )
    if measured & estimated:
        raise BadParameterError(
            "device.estimated_requests", estimated, "no code also in measured_requests"
        )
    sources = dict.fromkeys(COMMAND_OF, ValueSource.COMMANDED)
    sources.update(dict.fromkeys(measured, ValueSource.MEASURED))
    sources.update(dict.fromkeys(estimated, ValueSource.ESTIMATED))
    return sources
