"""The RTC lifecycle and configuration of a served rig's components (``openel-async
activate``, ``deactivate``, ``reset``, ``conf``; docs/remote.md, "Lifecycle and
configuration").

A served component is a HAL component (OpenEL 3.2: Init / ReInit / Finalize, states
Active and Error). :class:`ServedLifecycle` gives each one the lifecycle of an RTC in an
execution context (RTC 1.1 §5.2.2.3, ``LifeCycleState``) and a configuration set (RTC
§5.3.x, OpenRTM's configuration sets), mapped onto what the HAL component has:

- **ACTIVE**: the HAL component is Active and takes commands (as served until now: every
  component starts ACTIVE).
- **INACTIVE** (``deactivate``): an actuator's excitation is off -- ``SetValue(NO_EXCITE)``
  (OpenEL §7.4.1.6: the motor de-energized) -- and every command that would excite it again
  (``SetPosition``, ``SetSpeed``, ``SetTorque``, ``SetControlMode``) is refused by the server
  with a message saying so, until ``activate``; reads go on. A device that cannot take its
  torque off (no NO_EXCITE) cannot be deactivated. A sensor only changes state.
- **ACTIVE again** (``activate``, from INACTIVE only): an actuator holds where it is
  (``SetPosition`` of its actual position; ``SetSpeed 0`` or ``SetTorque 0`` for a device
  that takes no position).
- **ERROR**: the HAL component is in Error (a fault, an e-stop). ``reset`` (from ERROR only,
  RTC ``reset_component``) is the HAL's ReInit; the component comes back INACTIVE, its
  excitation off, whichever way the ReInit came (also the surface layer's ``Reset``): an
  active hook of the component (``HALComponent.add_active_hook``) does it.

Operations in the wrong state are refused as RTC's ``PRECONDITION_NOT_MET`` is (HAL_ERROR,
the state named). The configuration has one set, ``default`` (active), whose parameters are
an actuator's live limits, each with an RTC constraint (OpenRTM's text form, rtc.constraints)
that is the range the device had when the server started -- a value can narrow a limit,
never widen it past the rig file's or the device's own:

| parameter | type | applies to | constraint (e.g.) |
|---|---|---|---|
| ``position_min``, ``position_max`` | double | ``device.limits.position`` | ``-3.14<=x<=3.14`` |
| ``max_velocity`` | double | ``device.limits.velocity`` | ``0<x<=2.0`` |
| ``max_torque`` | double | ``device.limits.torque`` (when finite) | ``0<x<=1.5`` |
| ``max_acceleration`` | double | the device's ``max_acceleration`` (a simulated motor's) | ``0<x<=20.0`` |

``position_min < position_max`` is checked too. A value outside its constraint is refused
with the constraint named, and nothing changes. The values are applied to the device at
once and again after every ReInit (the rig re-applies the rig file's limits then).

This module imports no zenoh: ``lifecycle_server`` serves it.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

import anyio

from openel_async.actuator import Actuator
from openel_async.component import ComponentState, HALComponent
from openel_async.errors import BadParameterError, HALError, ReturnCode
from openel_async.logs import get_logger
from openel_async.requests import Request
from openel_async.rtc.configuration import (
    DEFAULT_SET,
    Configuration,
    ConfigurationError,
    ParameterSpec,
)
from openel_async.surface import LOGICAL_ID, Surface
from openel_async.surface.messages import CommandMessage, DataType, Device, Parameter, ResultList

log = get_logger(__name__)

CALL_TIMEOUT_S = 2.0
"""The bound of each device call an activation or deactivation makes."""
EXCITING = frozenset({"SetPosition", "SetSpeed", "SetTorque", "SetControlMode"})
"""The surface functions refused while a component is INACTIVE."""


class LifecycleState(StrEnum):
    """RTC ``LifeCycleState`` of a served component (CREATED is never seen: it is served)."""

    INACTIVE = "INACTIVE"
    ACTIVE = "ACTIVE"
    ERROR = "ERROR"


def _text(value: float) -> str:
    return repr(float(value))


@dataclass
class Hosted:
    """One served component: its lifecycle flag and configuration."""

    name: str
    kind: str
    logical_id: int
    component: HALComponent
    configuration: Configuration
    apply: dict[str, Callable[[float], None]] = field(default_factory=dict)
    inactive: bool = False

    @property
    def state(self) -> LifecycleState:
        hal = self.component.state
        if hal is ComponentState.ERROR:
            return LifecycleState.ERROR
        if self.inactive or hal is not ComponentState.ACTIVE:
            return LifecycleState.INACTIVE
        return LifecycleState.ACTIVE


def _configuration(
    component: HALComponent,
) -> tuple[Configuration, dict[str, Callable[[float], None]]]:
    """The ``default`` set of a component: its live limits (an actuator), none else."""
    if not isinstance(component, Actuator):
        return Configuration([]), {}
    device = component.device
    limits = device.limits
    specs: list[ParameterSpec] = []
    apply: dict[str, Callable[[float], None]] = {}
    low, high = limits.position
    if math.isfinite(low) and math.isfinite(high):
        bounds = f"{_text(low)}<=x<={_text(high)}"
        specs.append(ParameterSpec.from_text("position_min", "double", _text(low), bounds, "rad"))
        specs.append(ParameterSpec.from_text("position_max", "double", _text(high), bounds, "rad"))

        def position_min(value: float) -> None:
            device.limits = dataclasses.replace(
                device.limits, position=(value, device.limits.position[1])
            )

        def position_max(value: float) -> None:
            device.limits = dataclasses.replace(
                device.limits, position=(device.limits.position[0], value)
            )

        apply["position_min"] = position_min
        apply["position_max"] = position_max

    def max_velocity(value: float) -> None:
        device.limits = dataclasses.replace(device.limits, velocity=value)

    def max_torque(value: float) -> None:
        device.limits = dataclasses.replace(device.limits, torque=value)

    for name, top, unit, setter in (
        ("max_velocity", float(limits.velocity), "rad/s", max_velocity),
        ("max_torque", float(limits.torque), "N.m", max_torque),
    ):
        if math.isfinite(top):
            bound = f"0<x<={_text(top)}"
            specs.append(ParameterSpec.from_text(name, "double", _text(top), bound, unit))
            apply[name] = setter
    acceleration = getattr(device, "max_acceleration", None)
    if isinstance(acceleration, float) and math.isfinite(acceleration) and acceleration > 0:
        specs.append(
            ParameterSpec.from_text(
                "max_acceleration",
                "double",
                _text(acceleration),
                f"0<x<={_text(acceleration)}",
                "rad/s^2",
            )
        )

        def max_acceleration(value: float) -> None:
            device.max_acceleration = value  # type: ignore[attr-defined]

        apply["max_acceleration"] = max_acceleration
    return Configuration(specs), apply


def refusal(device: Device, message: str) -> Device:
    """``device`` with every command refused (HAL_ERROR, ``message``), none executed."""
    results = ResultList(
        (
            Parameter(DataType.INT, "return_code", int(ReturnCode.HAL_ERROR)),
            Parameter(DataType.STRING, "message", message),
        )
    )
    return Device(
        device.device_kind,
        tuple(
            CommandMessage(c.function_name, c.command_id, c.arguments, results)
            for c in device.commands
        ),
    )


class ServedLifecycle:
    """The lifecycle and configuration of every component of ``surface`` (see the module).
    :meth:`admit` is the SurfaceServer's ``admit`` hook."""

    def __init__(self, surface: Surface, *, call_timeout: float = CALL_TIMEOUT_S) -> None:
        self.surface = surface
        self.call_timeout = call_timeout
        self.hosted: dict[str, Hosted] = {}
        self._inactive: set[tuple[str, int]] = set()
        self._closed = False
        for entry in surface.entries:
            component = entry.component
            configuration, apply = _configuration(component)
            hosted = Hosted(
                component.device_name,
                entry.device_kind,
                entry.logical_id,
                component,
                configuration,
                apply,
            )
            self.hosted[hosted.name] = hosted
            component.add_active_hook(self._on_active(hosted))

    def close(self) -> None:
        """Stop acting on ReInit (the hooks stay on the components, doing nothing)."""
        self._closed = True

    # -- admission -----------------------------------------------------------------------
    def admit(self, device: Device) -> Device | None:
        """None: execute ``device``; else the reply refusing it (nothing executed): one of its
        commands would excite an INACTIVE component."""
        if not self._inactive:
            return None
        for command in device.commands:
            if command.function_name not in EXCITING:
                continue
            found = command.arguments.get(LOGICAL_ID) if command.arguments else None
            logical_id = found.value if found is not None else None
            try:
                entry = self.surface.resolve(
                    device.device_kind, logical_id if isinstance(logical_id, int) else None
                )
            except BadParameterError:
                continue  # the surface answers that one
            hosted = self.hosted.get(entry.component.device_name)
            if hosted is not None and hosted.state is LifecycleState.INACTIVE and hosted.inactive:
                return refusal(
                    device,
                    f"{hosted.name} is INACTIVE (deactivated, no torque): "
                    f"{command.function_name} refused; activate it first",
                )
        return None

    # -- lifecycle -------------------------------------------------------------------------
    def find(self, name: str) -> Hosted:
        hosted = self.hosted.get(name)
        if hosted is None:
            raise BadParameterError("name", name, f"one of {', '.join(self.hosted)}")
        return hosted

    def _mark(self, hosted: Hosted, inactive: bool) -> None:
        hosted.inactive = inactive
        key = (hosted.kind.lower(), hosted.logical_id)
        if inactive:
            self._inactive.add(key)
        else:
            self._inactive.discard(key)

    @staticmethod
    def _require(hosted: Hosted, operation: str, state: LifecycleState) -> None:
        if hosted.state is not state:
            raise HALError(
                f"{hosted.name} is {hosted.state}: {operation} needs {state} "
                "(RTC PRECONDITION_NOT_MET)"
            )

    async def activate(self, name: str) -> Hosted:
        """INACTIVE -> ACTIVE: an actuator holds its actual position."""
        hosted = self.find(name)
        self._require(hosted, "activate", LifecycleState.INACTIVE)
        component = hosted.component
        if component.state is not ComponentState.ACTIVE:
            raise HALError(f"{hosted.name} is {component.state} (HAL): it cannot be activated")
        if isinstance(component, Actuator):
            supported = component.device.supported_requests
            with anyio.fail_after(self.call_timeout):
                if Request.POSITION in supported:
                    position = await component.get_value(Request.POSITION_ACTUAL)
                    await component.set_value(position, Request.POSITION)
                elif Request.VELOCITY in supported:
                    await component.set_value(0.0, Request.VELOCITY)
                elif Request.TORQUE in supported:
                    await component.set_value(0.0, Request.TORQUE)
        self._mark(hosted, False)
        log.info("component_activated", name=hosted.name)
        return hosted

    async def deactivate(self, name: str) -> Hosted:
        """ACTIVE -> INACTIVE: an actuator's excitation off (NO_EXCITE)."""
        hosted = self.find(name)
        self._require(hosted, "deactivate", LifecycleState.ACTIVE)
        component = hosted.component
        if isinstance(component, Actuator):
            if Request.NO_EXCITE not in component.device.supported_requests:
                raise HALError(
                    f"{hosted.name}: the device cannot take its torque off (no NO_EXCITE): "
                    "not deactivated",
                    code=ReturnCode.HAL_NOT_IMPLEMENTED,
                )
            self._mark(hosted, True)  # no command gets in from now on
            with anyio.fail_after(self.call_timeout):
                await component.set_value(0.0, Request.NO_EXCITE)
        else:
            self._mark(hosted, True)
        log.info("component_deactivated", name=hosted.name)
        return hosted

    async def reset(self, name: str) -> Hosted:
        """ERROR -> INACTIVE: the HAL's ReInit (refused while the rig's e-stop is latched)."""
        hosted = self.find(name)
        self._require(hosted, "reset", LifecycleState.ERROR)
        with anyio.fail_after(self.call_timeout):
            await hosted.component.re_init()  # the active hook makes it INACTIVE
        return hosted

    def _on_active(self, hosted: Hosted) -> Callable[[HALComponent], Any]:
        async def hook(component: HALComponent) -> None:
            if self._closed:
                return
            self._mark(hosted, True)
            self._apply_all(hosted)
            if isinstance(component, Actuator) and (
                Request.NO_EXCITE in component.device.supported_requests
            ):
                with anyio.fail_after(self.call_timeout):
                    await component.set_value(0.0, Request.NO_EXCITE)
            log.info("component_reset", name=hosted.name, state=str(hosted.state))

        return hook

    # -- configuration -------------------------------------------------------------------
    def configure(self, name: str, set_name: str, parameter: str, value: str) -> Hosted:
        """Set one parameter of a set (the ``default`` set's are applied to the device at
        once). ConfigurationError (constraint named) leaves everything as it was."""
        hosted = self.find(name)
        configuration = hosted.configuration
        if not configuration.parameters:
            raise ConfigurationError(f"{hosted.name} has no configuration parameters")
        if parameter not in configuration.parameters:
            raise ConfigurationError(
                f"{hosted.name}: unknown parameter {parameter!r}: one of "
                f"{', '.join(configuration.parameters)}",
                parameter=parameter,
            )
        if set_name not in configuration.set_names:
            raise ConfigurationError(
                f"{hosted.name}: unknown configuration set {set_name!r}: one of "
                f"{', '.join(configuration.set_names)}"
            )
        before = configuration.get_text(parameter, set_name)
        configuration.set_value(set_name, parameter, value)
        values = configuration.values(set_name)
        low, high = values.get("position_min"), values.get("position_max")
        if isinstance(low, float) and isinstance(high, float) and not low < high:
            configuration.set_value(set_name, parameter, before)
            raise ConfigurationError(
                f"{hosted.name}: parameter {parameter!r}: value {value!r} violates constraint "
                f"'position_min < position_max' ({low!r} >= {high!r})",
                parameter=parameter,
                value=value,
                constraint="position_min < position_max",
            )
        if set_name == configuration.active_set:
            self._apply(hosted, parameter)
        log.info("configuration_set", name=hosted.name, parameter=parameter, value=value)
        return hosted

    def _apply(self, hosted: Hosted, parameter: str) -> None:
        setter = hosted.apply.get(parameter)
        value = hosted.configuration.get(parameter)
        if setter is not None and isinstance(value, float):
            setter(value)

    def _apply_all(self, hosted: Hosted) -> None:
        for parameter in hosted.apply:
            self._apply(hosted, parameter)

    def names(self, names: Sequence[str]) -> list[Hosted]:
        """The hosted components named (every one when ``names`` is empty)."""
        return [self.find(n) for n in names] if names else list(self.hosted.values())


__all__ = [
    "CALL_TIMEOUT_S",
    "DEFAULT_SET",
    "EXCITING",
    "Hosted",
    "LifecycleState",
    "ServedLifecycle",
    "refusal",
]
