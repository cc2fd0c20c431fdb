"""From a SystemSpec to components and connectors, every check done before anything
starts: profiles load, implementations import, configuration values satisfy their
constraints, ports exist with the declared types, connector options are valid, and no
cycle of blocking connectors exists."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from ...clock import Clock
from ...positioned import did_you_mean
from ..configuration import Configuration, ConfigurationError
from ..context import ExecutionKind
from ..errors import RTCError
from ..ports import (
    Connector,
    InPort,
    OutPort,
    PortBase,
    ServiceConnection,
    ServicePort,
    connect_services,
    resolve_data_type,
)
from ..profile import PortType, ProfileError, RtcProfile, load_profile
from ..rtobject import RTObject
from ..runner import ExecutionSpec, execution_spec, load_implementation
from .model import ComponentSpec, DataConnectionSpec, PortRef, SystemFileError, SystemSpec

__all__ = ["PreparedComponent", "PreparedSystem", "blocking_cycle", "prepare_system"]


@dataclass(slots=True)
class PreparedComponent:
    spec: ComponentSpec
    profile: RtcProfile
    execution: ExecutionSpec
    rtc: RTObject


@dataclass(slots=True)
class PreparedSystem:
    spec: SystemSpec
    components: list[PreparedComponent]
    connectors: list[Connector]
    services: list[ServiceConnection] = field(default_factory=list)

    def component(self, name: str) -> RTObject:
        for c in self.components:
            if c.spec.name == name:
                return c.rtc
        raise KeyError(name)


def _execution(comp: ComponentSpec, profile: RtcProfile) -> ExecutionSpec:
    where = f"{comp.where}.context"
    ctx = comp.context
    try:
        spec = execution_spec(profile, ctx.rate_hz)
    except ProfileError as exc:
        raise SystemFileError(f"{comp.where}.profile ({comp.profile})", str(exc)) from None
    if ctx.type is None:
        if spec.ext_trig:
            raise SystemFileError(
                where,
                "the profile's ExtTrigExecutionContext runs a cycle only when ticked, and a "
                "system run ticks nothing: give the component a context (periodic, "
                "event_driven or sporadic)",
            )
        return spec
    kind = {
        "periodic": ExecutionKind.PERIODIC,
        "event_driven": ExecutionKind.EVENT_DRIVEN,
        "sporadic": ExecutionKind.OTHER,
    }[ctx.type]
    if kind is ExecutionKind.EVENT_DRIVEN:
        return ExecutionSpec(kind, None)
    rate = ctx.rate_hz if ctx.rate_hz is not None else spec.rate_hz
    if kind is ExecutionKind.PERIODIC and rate is None:
        raise SystemFileError(f"{where}.rate", "a periodic context needs a rate")
    return ExecutionSpec(kind, rate)


def _configuration(comp: ComponentSpec, profile: RtcProfile) -> Configuration:
    try:
        config = Configuration.from_profile(profile)
        for name, values in comp.configuration_sets.items():
            if name == "default":
                for param, value in values.items():
                    config.set_value("default", param, value)
            else:
                config.add_set(name, dict(values))
        if comp.active_set is not None:
            config.activate_set(comp.active_set)
    except ConfigurationError as exc:
        raise SystemFileError(f"{comp.where}.configuration", str(exc)) from None
    return config


def _profile_ports(rtc: RTObject, profile: RtcProfile, where: str) -> None:
    """Create the ports the profile declares and the class did not; check the others."""
    existing = {p.name: p for p in rtc.ports}
    for i, dp in enumerate(profile.data_ports):
        if dp.port_type is PortType.EVENT_PORT:
            continue
        path = f"{where}: rtcProfile.dataPorts[{i}] ({dp.name})"
        try:
            data_type = resolve_data_type(dp.type)
        except RTCError as exc:
            raise SystemFileError(path, str(exc)) from None
        cls: type[InPort[Any]] | type[OutPort[Any]] = (
            InPort if dp.port_type is PortType.DATA_IN_PORT else OutPort
        )
        port = existing.get(dp.name)
        if port is None:
            rtc.add_port(cls(dp.name, data_type))
        elif type(port) is not cls or port.data_type is not data_type:
            raise SystemFileError(
                path,
                f"the profile declares a {cls.__name__} of {dp.type}; the component has "
                f"{port!r}"
                + (f" of {port.type_name}" if isinstance(port, InPort | OutPort) else ""),
            )
    for i, sp in enumerate(profile.service_ports):
        port = existing.get(sp.name)
        if port is None:
            rtc.add_port(ServicePort(sp.name))
        elif not isinstance(port, ServicePort):
            raise SystemFileError(
                f"{where}: rtcProfile.servicePorts[{i}] ({sp.name})",
                f"the profile declares a service port; the component has {port!r}",
            )


def _prepare_component(comp: ComponentSpec, clock: Clock) -> PreparedComponent:
    try:
        profile = load_profile(comp.profile)
        implementation = load_implementation(profile, comp.profile)
    except FileNotFoundError:
        raise SystemFileError(f"{comp.where}.profile", f"no such file: {comp.profile}") from None
    except OSError as exc:
        raise SystemFileError(
            f"{comp.where}.profile", f"cannot read {comp.profile}: {exc}"
        ) from None
    except ProfileError as exc:
        raise SystemFileError(f"{comp.where}.profile ({comp.profile})", str(exc)) from None
    execution = _execution(comp, profile)
    config = _configuration(comp, profile)
    rtc = implementation(comp.name, configuration=config, clock=clock)
    _profile_ports(rtc, profile, comp.where)
    return PreparedComponent(comp, profile, execution, rtc)


def _port(components: Mapping[str, RTObject], ref: PortRef) -> PortBase:
    rtc = components.get(ref.component)
    if rtc is None:
        raise SystemFileError(
            ref.where,
            f"no component {ref.component!r} in the system "
            f"({did_you_mean(ref.component, components)})",
        ).at(ref.location)
    ports = {p.name: p for p in rtc.ports}
    port = ports.get(ref.port)
    if port is None:
        raise SystemFileError(
            ref.where,
            f"component {ref.component!r} has no port {ref.port!r} "
            f"({did_you_mean(ref.port, ports)})",
        ).at(ref.location)
    return port


def blocking_cycle(edges: Mapping[str, set[str]]) -> list[str] | None:
    """A cycle in a directed graph (component -> components), or None."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(edges.get(node, ())):
            if state.get(nxt) == 1:
                return [*stack[stack.index(nxt) :], nxt]
            if nxt not in state and (found := visit(nxt)) is not None:
                return found
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(edges):
        if node not in state and (found := visit(node)) is not None:
            return found
    return None


def prepare_system(spec: SystemSpec, *, clock: Clock) -> PreparedSystem:
    """Build everything a run needs (components are constructed, not initialized;
    connectors are checked, not connected; service ports are bound).

    Raises SystemFileError naming the field for anything wrong."""
    seen: set[str] = set()
    for comp in spec.components:
        if comp.name in seen:
            raise SystemFileError("components", f"component name {comp.name!r} used twice").at(
                comp.location
            )
        seen.add(comp.name)
    prepared = []
    for comp in spec.components:
        try:
            prepared.append(_prepare_component(comp, clock))
        except SystemFileError as exc:
            raise exc.at(comp.location) from None
    rtcs = {p.spec.name: p.rtc for p in prepared}
    connectors: list[Connector] = []
    edges: dict[str, set[str]] = {}
    blocking: dict[tuple[str, str], DataConnectionSpec] = {}
    for conn in spec.connections:
        out, inp = _port(rtcs, conn.source), _port(rtcs, conn.target)
        if not isinstance(out, OutPort):
            raise SystemFileError(
                conn.source.where, f"{conn.source} is not an OutPort ({out!r})"
            ).at(conn.source.location)
        if not isinstance(inp, InPort):
            raise SystemFileError(
                conn.target.where, f"{conn.target} is not an InPort ({inp!r})"
            ).at(conn.target.location)
        try:
            connector = Connector(out, inp, conn.properties, name=conn.name)
        except RTCError as exc:
            raise SystemFileError(conn.where, str(exc)).at(conn.location) from None
        connectors.append(connector)
        if connector.profile.blocking:
            edges.setdefault(conn.source.component, set()).add(conn.target.component)
            blocking.setdefault((conn.source.component, conn.target.component), conn)
    cycle = blocking_cycle(edges)
    if cycle is not None:
        first = blocking[(cycle[0], cycle[1])]
        raise SystemFileError(
            first.where,
            "a cycle of blocking connectors (full_policy or empty_policy 'block') can "
            "deadlock its components: " + " -> ".join(cycle),
        ).at(first.location)
    services: list[ServiceConnection] = []
    for svc in spec.services:
        a, b = _port(rtcs, svc.a), _port(rtcs, svc.b)
        for ref, port in ((svc.a, a), (svc.b, b)):
            if not isinstance(port, ServicePort):
                raise SystemFileError(ref.where, f"{ref} is not a service port ({port!r})").at(
                    ref.location
                )
        try:
            services.append(connect_services(a, b))  # type: ignore[arg-type]
        except RTCError as exc:
            for done in services:
                done.disconnect()
            raise SystemFileError(svc.where, str(exc)).at(svc.location) from None
    return PreparedSystem(spec, prepared, connectors, services)
