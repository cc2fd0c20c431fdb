"""Typed, immutable model of an RTC Profile (basic, document and extended profiles).

Names follow the spec's PIM (§2.3-2.5) in snake_case.  Document-profile blocks
(``doc``) and extension blocks without required fields (``BasicInfoExt``,
``ConfigurationExt``, ``ServiceInterfaceExt``) are never None: an empty block means
"not given", so YAML (which cannot mark an empty block) and XML round trip alike.
Extension blocks with a required field (``DataPortExt.position``,
``ServicePortExt.position``, ``LanguageExt.targets``) are None when absent.

Every element keeps the attributes and children this model does not know in
``extra`` (YAML-style keys such as ``rtcExt::foo``), so nothing is lost on a round trip.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import datetime
from enum import StrEnum
from typing import TypeAlias

from ..constraints import MAX_INT_DIGITS, Constraint
from .errors import ProfileError

ExtraValue: TypeAlias = (
    str | int | float | bool | Sequence["ExtraValue"] | Mapping[str, "ExtraValue"] | None
)
# Unknown attributes/children; excluded from hashing (a dict is not hashable).
Extra: TypeAlias = Mapping[str, ExtraValue]


class ComponentType(StrEnum):
    """component_type (§2.3.3)."""

    STATIC = "STATIC"
    UNIQUE = "UNIQUE"
    COMMUTATIVE = "COMMUTATIVE"


class ActivityType(StrEnum):
    """activity_type (§2.3.4)."""

    PERIODIC = "PERIODIC"
    SPORADIC = "SPORADIC"
    EVENTDRIVEN = "EVENTDRIVEN"


class PortType(StrEnum):
    """port_type (§2.3.10)."""

    DATA_IN_PORT = "DataInPort"
    DATA_OUT_PORT = "DataOutPort"
    EVENT_PORT = "EventPort"
    """Event port of finite-state-machine components (OpenRTP's RtcProfile_basic.xsd)."""


class InterfaceDirection(StrEnum):
    """interface_direction (§2.3.14)."""

    PROVIDED = "Provided"
    REQUIRED = "Required"


class Position(StrEnum):
    """Position of a port in tools (§2.5.6); read in any case, written in upper case."""

    LEFT = "left"
    RIGHT = "right"
    TOP = "top"
    BOTTOM = "bottom"


@dataclass(frozen=True, kw_only=True)
class Property:
    """property (§2.5.10): a user-defined name/value pair."""

    name: str
    value: str | None = None
    extra: Extra = field(default_factory=dict, hash=False)


# --- document profile (§2.4) -------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class BasicDoc:
    """doc_basic."""

    algorithm: str | None = None
    description: str | None = None
    inout: str | None = None
    creator: str | None = None
    license: str | None = None
    reference: str | None = None
    extra: Extra = field(default_factory=dict, hash=False)


@dataclass(frozen=True, kw_only=True)
class ActionDoc:
    """doc_action."""

    description: str | None = None
    pre_condition: str | None = None
    post_condition: str | None = None
    extra: Extra = field(default_factory=dict, hash=False)


@dataclass(frozen=True, kw_only=True)
class ConfigurationDoc:
    """doc_configuration (free text; the machine-readable constraint is elsewhere)."""

    description: str | None = None
    dataname: str | None = None
    default_value: str | None = None
    unit: str | None = None
    range: str | None = None
    constraint: str | None = None
    extra: Extra = field(default_factory=dict, hash=False)


@dataclass(frozen=True, kw_only=True)
class DataPortDoc:
    """doc_dataport."""

    description: str | None = None
    type: str | None = None
    number: str | None = None
    semantics: str | None = None
    unit: str | None = None
    occurrence: str | None = None
    operation: str | None = None
    extra: Extra = field(default_factory=dict, hash=False)


@dataclass(frozen=True, kw_only=True)
class ServicePortDoc:
    """doc_serviceport."""

    description: str | None = None
    ifdescription: str | None = None
    extra: Extra = field(default_factory=dict, hash=False)


@dataclass(frozen=True, kw_only=True)
class ServiceInterfaceDoc:
    """doc_serviceinterface."""

    description: str | None = None
    doc_argument: str | None = None
    doc_return: str | None = None
    doc_exception: str | None = None
    doc_pre_condition: str | None = None
    doc_post_condition: str | None = None
    extra: Extra = field(default_factory=dict, hash=False)


# --- extended profile (§2.5) -------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class BasicInfoExt:
    """basic_info_ext."""

    comment: str | None = None
    save_project: str | None = None
    version_up_logs: tuple[str, ...] = ()
    properties: tuple[Property, ...] = ()


@dataclass(frozen=True, kw_only=True)
class ConfigurationExt:
    """configuration_ext."""

    comment: str | None = None
    variable_name: str | None = None
    properties: tuple[Property, ...] = ()


@dataclass(frozen=True, kw_only=True)
class DataPortExt:
    """dataport_ext; ``position`` is required when the block is present."""

    position: Position
    comment: str | None = None
    variable_name: str | None = None
    properties: tuple[Property, ...] = ()


@dataclass(frozen=True, kw_only=True)
class ServicePortExt:
    """serviceport_ext; ``position`` is required when the block is present."""

    position: Position
    comment: str | None = None
    properties: tuple[Property, ...] = ()


@dataclass(frozen=True, kw_only=True)
class ServiceInterfaceExt:
    """serviceinterface_ext."""

    comment: str | None = None
    variable_name: str | None = None
    properties: tuple[Property, ...] = ()


@dataclass(frozen=True, kw_only=True)
class Library:
    """library (§2.5.9); the PIM calls ``name`` "path", the XSD and samples "name"."""

    name: str
    version: str | None = None
    other: str | None = None
    extra: Extra = field(default_factory=dict, hash=False)


@dataclass(frozen=True, kw_only=True)
class TargetEnvironment:
    """target_environment (§2.5.8)."""

    lang_version: str | None = None
    os: str | None = None
    os_versions: tuple[str, ...] = ()
    other: str | None = None
    cpus: tuple[str, ...] = ()
    cpu_other: str | None = None
    libraries: tuple[Library, ...] = ()
    properties: tuple[Property, ...] = ()
    extra: Extra = field(default_factory=dict, hash=False)


@dataclass(frozen=True, kw_only=True)
class LanguageExt:
    """language_ext: target environments and properties (OpenRTP's schema makes both
    optional; an ext with neither is None)."""

    targets: tuple[TargetEnvironment, ...]
    properties: tuple[Property, ...] = ()


# --- basic profile (§2.3) ----------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class BasicInfo:
    """basic_info with its doc and ext blocks."""

    name: str
    component_type: ComponentType
    activity_type: ActivityType
    component_kind: str
    category: str
    execution_type: str
    vendor: str
    version: str
    creation_date: datetime
    update_date: datetime
    rtc_type: str | None = None
    description: str | None = None
    execution_rate: float | None = None
    max_instances: int | None = None
    abstract: str | None = None
    hardware_profile: str | None = None
    doc: BasicDoc = field(default_factory=BasicDoc)
    ext: BasicInfoExt = field(default_factory=BasicInfoExt)
    extra: Extra = field(default_factory=dict, hash=False)

    @property
    def instance_limit(self) -> int | None:
        """Maximum number of instances; None means unlimited (negative or empty, §2.3.2.10)."""
        if self.max_instances is None or self.max_instances < 0:
            return None
        return self.max_instances


@dataclass(frozen=True, kw_only=True)
class ActionStatus:
    """action_status with its doc block."""

    implemented: bool
    doc: ActionDoc = field(default_factory=ActionDoc)
    extra: Extra = field(default_factory=dict, hash=False)


# Field name -> YAML key (the XML element is the key with a capital first letter).
ACTION_KEYS: Mapping[str, str] = {
    "on_initialize": "onInitialize",
    "on_finalize": "onFinalize",
    "on_startup": "onStartup",
    "on_shutdown": "onShutdown",
    "on_activated": "onActivated",
    "on_deactivated": "onDeactivated",
    "on_aborting": "onAborting",
    "on_error": "onError",
    "on_reset": "onReset",
    "on_execute": "onExecute",
    "on_state_update": "onStateUpdate",
    "on_rate_changed": "onRateChanged",
    "on_action": "onAction",
    "on_mode_changed": "onModeChanged",
}


@dataclass(frozen=True, kw_only=True)
class Actions:
    """actions: the status of each callback; None when the profile does not list it."""

    on_initialize: ActionStatus | None = None
    on_finalize: ActionStatus | None = None
    on_startup: ActionStatus | None = None
    on_shutdown: ActionStatus | None = None
    on_activated: ActionStatus | None = None
    on_deactivated: ActionStatus | None = None
    on_aborting: ActionStatus | None = None
    on_error: ActionStatus | None = None
    on_reset: ActionStatus | None = None
    on_execute: ActionStatus | None = None
    on_state_update: ActionStatus | None = None
    on_rate_changed: ActionStatus | None = None
    on_action: ActionStatus | None = None
    on_mode_changed: ActionStatus | None = None
    extra: Extra = field(default_factory=dict, hash=False)

    def items(self) -> Iterator[tuple[str, ActionStatus]]:
        """(field name, status) of the listed actions, in spec order."""
        for name in ACTION_KEYS:
            status: ActionStatus | None = getattr(self, name)
            if status is not None:
                yield name, status


@dataclass(frozen=True, kw_only=True)
class ConfigurationProfile:
    """configuration: one configuration parameter (name, type, default, constraint)."""

    name: str
    type: str
    default_value: str
    unit: str | None = None
    constraint: Constraint | None = None
    doc: ConfigurationDoc = field(default_factory=ConfigurationDoc)
    ext: ConfigurationExt = field(default_factory=ConfigurationExt)
    extra: Extra = field(default_factory=dict, hash=False)

    @property
    def variable_name(self) -> str:
        """Implementation variable name; defaults to ``name`` (§2.5.2.2)."""
        return self.ext.variable_name or self.name


@dataclass(frozen=True, kw_only=True)
class ConfigurationSetProfile:
    """configuration_set: the parameters of the component's configuration."""

    configurations: tuple[ConfigurationProfile, ...] = ()
    extra: Extra = field(default_factory=dict, hash=False)


@dataclass(frozen=True, kw_only=True)
class DataPortProfile:
    """dataPort."""

    port_type: PortType
    name: str
    type: str
    idl_file: str | None = None
    interface_type: str | None = None
    dataflow_type: str | None = None
    subscription_type: str | None = None
    unit: str | None = None
    constraint: Constraint | None = None
    doc: DataPortDoc = field(default_factory=DataPortDoc)
    ext: DataPortExt | None = None
    extra: Extra = field(default_factory=dict, hash=False)

    @property
    def variable_name(self) -> str:
        """Implementation variable name; defaults to ``name`` (§2.5.3.2)."""
        return (self.ext.variable_name if self.ext else None) or self.name


@dataclass(frozen=True, kw_only=True)
class TransMethod:
    """transmission_method."""

    kind: str
    extra: Extra = field(default_factory=dict, hash=False)


@dataclass(frozen=True, kw_only=True)
class ServiceInterfaceProfile:
    """serviceinterface."""

    name: str
    type: str
    direction: InterfaceDirection
    instance_name: str | None = None
    idl_file: str | None = None
    path: str | None = None
    doc: ServiceInterfaceDoc = field(default_factory=ServiceInterfaceDoc)
    ext: ServiceInterfaceExt = field(default_factory=ServiceInterfaceExt)
    extra: Extra = field(default_factory=dict, hash=False)

    @property
    def varname(self) -> str:
        """Implementation variable name; defaults to ``name``."""
        return self.ext.variable_name or self.name


@dataclass(frozen=True, kw_only=True)
class ServicePortProfile:
    """serviceport."""

    name: str
    interfaces: tuple[ServiceInterfaceProfile, ...] = ()
    trans_methods: tuple[TransMethod, ...] = ()
    doc: ServicePortDoc = field(default_factory=ServicePortDoc)
    ext: ServicePortExt | None = None
    extra: Extra = field(default_factory=dict, hash=False)


@dataclass(frozen=True, kw_only=True)
class Parameter:
    """parameter: a system configuration entry (e.g. ``exec_ctxt.periodic.rate``)."""

    name: str
    default_value: str | None = None
    extra: Extra = field(default_factory=dict, hash=False)


@dataclass(frozen=True, kw_only=True)
class Language:
    """language (+ language_ext)."""

    kind: str
    ext: LanguageExt | None = None
    extra: Extra = field(default_factory=dict, hash=False)


@dataclass(frozen=True, kw_only=True)
class RtcProfile:
    """rtc_profile: the root of an RTC Profile."""

    id: str
    version: str
    basic_info: BasicInfo
    actions: Actions = field(default_factory=Actions)
    configuration_set: ConfigurationSetProfile | None = None
    data_ports: tuple[DataPortProfile, ...] = ()
    service_ports: tuple[ServicePortProfile, ...] = ()
    parameters: tuple[Parameter, ...] = ()
    language: Language | None = None
    extra: Extra = field(default_factory=dict, hash=False)

    @property
    def configurations(self) -> tuple[ConfigurationProfile, ...]:
        """The configuration parameters (empty without a configuration set)."""
        return self.configuration_set.configurations if self.configuration_set else ()


# --- semantic rules the types cannot express ---------------------------------------


def _no_space(path: str, value: str, also: str = "") -> None:
    if any(ch.isspace() or ch in also for ch in value):
        extra = f" or {also!r}" if also else ""
        raise ProfileError(path, f"{value!r} must not contain whitespace{extra}")


def _unique(names: Sequence[tuple[str, str]], what: str) -> None:
    seen: set[str] = set()
    for item_path, name in names:
        if name in seen:
            raise ProfileError(item_path, f"duplicate {what} name {name!r}")
        seen.add(name)


def validate_profile(profile: RtcProfile) -> None:
    """Check the rules of the spec that the types cannot: names without whitespace,
    vendor/version without ':' (they are parts of the id), unique names, finite rate,
    a maxInstances that can be written.  Raises ProfileError naming the field."""
    root = "rtcProfile"
    b = profile.basic_info
    _no_space(f"{root}.basicInfo.vendor", b.vendor, ":")
    _no_space(f"{root}.basicInfo.version", b.version, ":")
    if b.execution_rate is not None and not math.isfinite(b.execution_rate):
        raise ProfileError(f"{root}.basicInfo.executionRate", "must be a finite number")
    configs = profile.configurations
    for i, c in enumerate(configs):
        _no_space(f"{root}.configurationSet.configuration[{i}].name", c.name)
    _unique(
        [
            (f"{root}.configurationSet.configuration[{i}].name", c.name)
            for i, c in enumerate(configs)
        ],
        "configuration",
    )
    ports = [(f"{root}.dataPorts[{i}].name", p.name) for i, p in enumerate(profile.data_ports)]
    ports += [
        (f"{root}.servicePorts[{i}].name", p.name) for i, p in enumerate(profile.service_ports)
    ]
    for path, name in ports:
        _no_space(path, name)
    _unique(ports, "port")
    for i, sp in enumerate(profile.service_ports):
        ifs = [
            (f"{root}.servicePorts[{i}].serviceInterface[{j}].name", s.name)
            for j, s in enumerate(sp.interfaces)
        ]
        for path, name in ifs:
            _no_space(path, name)
        _unique(ifs, "service interface")
    if b.max_instances is not None and abs(b.max_instances) >= 10**MAX_INT_DIGITS:
        raise ProfileError(f"{root}.basicInfo.maxInstances", f"more than {MAX_INT_DIGITS} digits")
    lang = profile.language
    if lang is not None and lang.ext is not None and not (lang.ext.targets or lang.ext.properties):
        # Read back as no ext at all: refuse rather than change on a round trip.
        raise ProfileError(
            f"{root}.language.rtcExt::targets", "an empty language_ext (use ext=None)"
        )
