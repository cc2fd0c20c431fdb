"""Service ports: provided and required interfaces (OpenRTM's CorbaPort, in-process).

An interface is a Python protocol class with ``async`` methods. A port *provides* an
object implementing it, or *requires* one::

    class Motor(Protocol):
        async def move_to(self, position: float) -> None: ...

    port.provide("motor", "Motor", MotorImpl(), Motor)       # on the actuator RTC
    motor = port.require("motor", "Motor", Motor)            # on the controller RTC
    connect_services(controller_port, actuator_port)
    await motor.ref.move_to(1.0)                             # the provider's method

Connecting two ports binds every required interface of either port to the provided
interface of the same type name on the other (by instance name when the type is
provided more than once, as OpenRTM matches them). Calling through an unbound required
interface raises :class:`ServiceNotConnectedError` naming it.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

from ...clock import Clock
from ..errors import PreconditionNotMetError, RTCBadParameterError, RTCError
from .base import PortBase

__all__ = [
    "ProvidedInterface",
    "RequiredInterface",
    "ServiceConnection",
    "ServiceNotConnectedError",
    "ServicePort",
    "connect_services",
    "interface_methods",
]

T = TypeVar("T")

_PROTOCOL_BASES = frozenset({"Protocol", "Generic", "object"})


class ServiceNotConnectedError(PreconditionNotMetError):
    """A required interface was used before its port was connected to a provider."""

    def __init__(self, port: str, interface: str, type_name: str) -> None:
        RTCError.__init__(
            self,
            f"required interface {interface!r} ({type_name}) of port {port} is not "
            f"connected: connect {port} to a service port that provides {type_name} first",
        )
        self.operation = "call"
        self.state = "not connected"
        self.allowed = f"a port connected to a provider of {type_name}"
        self.port = port
        self.interface = interface


def interface_methods(protocol: type) -> tuple[str, ...]:
    """The public method names a protocol class declares (its bases included)."""
    names: set[str] = set()
    for klass in protocol.__mro__:
        if klass.__name__ in _PROTOCOL_BASES:
            continue
        for name, member in vars(klass).items():
            if not name.startswith("_") and callable(member):
                names.add(name)
    return tuple(sorted(names))


def _check_implements(parameter: str, impl: object, protocol: type) -> None:
    missing = [
        name
        for name in interface_methods(protocol)
        if not inspect.iscoroutinefunction(getattr(impl, name, None))
    ]
    if missing:
        raise RTCBadParameterError(
            parameter,
            type(impl).__name__,
            f"an object implementing {protocol.__name__} (async methods missing: "
            + ", ".join(missing)
            + ")",
        )


@dataclass(slots=True)
class ProvidedInterface:
    instance_name: str
    type_name: str
    implementation: object
    protocol: type | None


class RequiredInterface(Generic[T]):
    """A required interface; ``ref`` is the provider's object once connected."""

    def __init__(self, port: ServicePort, instance_name: str, type_name: str, protocol: type[T]):
        self.port = port
        self.instance_name = instance_name
        self.type_name = type_name
        self.protocol = protocol
        self._provider: ProvidedInterface | None = None

    def __repr__(self) -> str:
        state = "connected" if self._provider is not None else "not connected"
        return f"RequiredInterface({self.instance_name!r}, {self.type_name}, {state})"

    @property
    def connected(self) -> bool:
        return self._provider is not None

    @property
    def ref(self) -> T:
        """The provider's implementation; ServiceNotConnectedError when unbound."""
        provider = self._provider
        if provider is None:
            raise ServiceNotConnectedError(self.port.full_name, self.instance_name, self.type_name)
        return provider.implementation  # type: ignore[return-value]

    def bind(self, provider: ProvidedInterface | None) -> None:
        self._provider = provider


class ServicePort(PortBase):
    """A port with provided and required interfaces."""

    def __init__(self, name: str, *, clock: Clock | None = None) -> None:
        super().__init__(name, clock=clock)
        self.provided: dict[str, ProvidedInterface] = {}
        self.required: dict[str, RequiredInterface[Any]] = {}
        self.connections: list[ServiceConnection] = []

    def _check_name(self, instance_name: str, type_name: str) -> None:
        for param, value in (("instance_name", instance_name), ("type_name", type_name)):
            if not isinstance(value, str) or not value.strip():
                raise RTCBadParameterError(param, value, "a non-empty string")
        if instance_name in self.provided or instance_name in self.required:
            raise RTCBadParameterError(
                "instance_name", instance_name, f"a name not yet used on port {self.full_name}"
            )

    def provide(
        self, instance_name: str, type_name: str, implementation: object, protocol: type | None
    ) -> None:
        """Offer ``implementation`` (checked against ``protocol`` when given)."""
        self._check_name(instance_name, type_name)
        if protocol is not None:
            _check_implements("implementation", implementation, protocol)
        self.provided[instance_name] = ProvidedInterface(
            instance_name, type_name, implementation, protocol
        )

    def require(
        self, instance_name: str, type_name: str, protocol: type[T]
    ) -> RequiredInterface[T]:
        """Declare a needed interface; the result's ``ref`` works once connected."""
        self._check_name(instance_name, type_name)
        if not isinstance(protocol, type):
            raise RTCBadParameterError("protocol", protocol, "a protocol class")
        req = RequiredInterface(self, instance_name, type_name, protocol)
        self.required[instance_name] = req
        return req


@dataclass(slots=True)
class ServiceConnection:
    """The bindings one :func:`connect_services` made; ``disconnect()`` undoes them."""

    ports: tuple[ServicePort, ServicePort]
    bound: tuple[tuple[RequiredInterface[Any], ProvidedInterface], ...]

    def disconnect(self) -> None:
        for req, _ in self.bound:
            req.bind(None)
        for port in self.ports:
            if self in port.connections:
                port.connections.remove(self)


def _match(req: RequiredInterface[Any], other: ServicePort) -> ProvidedInterface | None:
    candidates = [p for p in other.provided.values() if p.type_name == req.type_name]
    if len(candidates) > 1:
        candidates = [p for p in candidates if p.instance_name == req.instance_name]
    if not candidates:
        return None
    provider = candidates[0]
    _check_implements(
        f"{other.full_name}.{provider.instance_name}", provider.implementation, req.protocol
    )
    return provider


def connect_services(a: ServicePort, b: ServicePort) -> ServiceConnection:
    """Bind the required interfaces of each port to the other's provided ones.

    Raises RTCBadParameterError, binding nothing, when the ports are not service ports,
    are the same port, share no interface type, or a required interface is already
    bound, or a provider lacks a method of the required protocol."""
    for name, port in (("a", a), ("b", b)):
        if not isinstance(port, ServicePort):
            raise RTCBadParameterError(name, port, "a ServicePort")
    if a is b:
        raise RTCBadParameterError("b", b.full_name, "another port than a")
    pairs: list[tuple[RequiredInterface[Any], ProvidedInterface]] = []
    for port, other in ((a, b), (b, a)):
        for req in port.required.values():
            provider = _match(req, other)
            if provider is None:
                continue
            if req.connected:
                raise PreconditionNotMetError(
                    "connect_services",
                    f"{port.full_name}.{req.instance_name} already connected",
                    "an unbound required interface",
                )
            pairs.append((req, provider))
    if not pairs:
        raise RTCBadParameterError(
            "b",
            b.full_name,
            f"a service port providing an interface {a.full_name} requires, or requiring "
            f"one it provides (a requires {sorted(r.type_name for r in a.required.values())}, "
            f"provides {sorted(p.type_name for p in a.provided.values())})",
        )
    for req, provider in pairs:
        req.bind(provider)
    conn = ServiceConnection((a, b), tuple(pairs))
    a.connections.append(conn)
    b.connections.append(conn)
    return conn
