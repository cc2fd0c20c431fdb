"""Format-independent reading and writing of the profile model.

Both PSMs (§3) map the same PIM: a class is a YAML mapping / an XML element, an
attribute is a YAML scalar / an XML attribute, a relationship is a nested mapping or
sequence / child elements.  The readers and writers here speak in YAML keys
(``name``, ``rtcExt::position``, ``rtcDoc::doc``); ``yaml_io`` and ``xml_io`` adapt
those keys to their format through ``Source`` and ``Sink``, so required fields, enums
and error paths are defined once.
"""

from __future__ import annotations

import difflib
import re
from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from datetime import date, datetime, timedelta, timezone
from enum import StrEnum
from typing import Any, TypeVar

from ...positioned import Location, did_you_mean, is_namespaced
from ..constraints import RTC_NS, Constraint, parse_bool, parse_int, parse_number
from .errors import ProfileError
from .model import (
    ACTION_KEYS,
    ActionDoc,
    Actions,
    ActionStatus,
    ActivityType,
    BasicDoc,
    BasicInfo,
    BasicInfoExt,
    ComponentType,
    ConfigurationDoc,
    ConfigurationExt,
    ConfigurationProfile,
    ConfigurationSetProfile,
    DataPortDoc,
    DataPortExt,
    DataPortProfile,
    Extra,
    ExtraValue,
    InterfaceDirection,
    Language,
    LanguageExt,
    Library,
    Parameter,
    PortType,
    Position,
    Property,
    RtcProfile,
    ServiceInterfaceDoc,
    ServiceInterfaceExt,
    ServiceInterfaceProfile,
    ServicePortDoc,
    ServicePortExt,
    ServicePortProfile,
    TargetEnvironment,
    TransMethod,
)

SinkScalar = str | int | float | bool | datetime


def is_extension_key(key: str) -> bool:
    """True for a key that marks itself as an extension: ``prefix::name`` or
    ``prefix:name`` (YAML), ``{uri}name`` (an XML name in a foreign namespace), except
    the RTC namespace itself (``rtc:``), whose names are all known.  Unknown keys that
    are extensions are kept (``extra``); any other unknown key is an error."""
    if not is_namespaced(key):
        return False
    if key.startswith("{"):
        return not key.startswith(f"{{{RTC_NS}}}")
    return key.partition(":")[0] != "rtc"


class Source(ABC):
    """One mapping/element being read; every accessor marks its key as consumed."""

    path: str

    @abstractmethod
    def raw(self, key: str) -> object:
        """The scalar under key (None when absent)."""

    @abstractmethod
    def child(self, key: str) -> Source | None:
        """The single nested mapping/element under key."""

    @abstractmethod
    def children(self, key: str) -> list[Source]:
        """The sequence of nested mappings/elements under key."""

    @abstractmethod
    def texts(self, key: str) -> list[object]:
        """A sequence of scalars (YAML list / repeated text elements)."""

    @abstractmethod
    def constraint(self, key: str) -> Constraint | None:
        """The constraint tree under key."""

    @abstractmethod
    def has_ext(self, keys: Sequence[str]) -> bool:
        """True when the element uses the extended profile (one of ``keys`` is present)."""

    @abstractmethod
    def extras(self) -> dict[str, ExtraValue]:
        """The extension keys not consumed so far (any other unknown key is refused)."""

    @abstractmethod
    def unread(self) -> list[str]:
        """The keys present and not read so far (YAML-style, as ``extras`` names them)."""

    @abstractmethod
    def locate(self, key: str) -> Location | None:
        """Where ``key`` is written (None when unknown)."""

    def missing(self, key: str) -> ProfileError:
        """The error for a required ``key`` that is absent; when an unknown key present
        is close to it, the error points at that key as a likely misspelling."""
        path = f"{self.path}.{key}"
        present = [k for k in self.unread() if not is_extension_key(k)]
        lowered = [k.lower() for k in present]
        close = difflib.get_close_matches(key.lower(), lowered, n=1, cutoff=0.75)
        if not close:
            return ProfileError(path, "required field missing")
        found = next(k for k in present if k.lower() == close[0])
        return ProfileError(
            path,
            f"required field missing (did you mean it by {found!r}?)",
            location=self.locate(found),
        )


class Sink(ABC):
    """One mapping/element being written."""

    @abstractmethod
    def scalar(self, key: str, value: SinkScalar | None) -> None:
        """Write a scalar; None writes nothing."""

    @abstractmethod
    def position(self, key: str, value: Position) -> None:
        """Write a port position (the formats spell it differently)."""

    @abstractmethod
    def child(self, key: str) -> Sink:
        """Start the single nested mapping/element under key."""

    @abstractmethod
    def add(self, key: str) -> Sink:
        """Append a nested mapping/element to the sequence under key."""

    @abstractmethod
    def texts(self, key: str, values: Sequence[str]) -> None:
        """Write a sequence of strings (nothing when empty)."""

    @abstractmethod
    def constraint(self, key: str, value: Constraint | None) -> None:
        """Write a constraint tree (nothing when None)."""

    @abstractmethod
    def declare(self, base: str, *, doc: bool, ext: bool) -> None:
        """Say which profiles the element uses (XML's xsi:type)."""

    @abstractmethod
    def extras(self, extra: Extra) -> None:
        """Write back unknown attributes/children."""


# --- scalar conversion -------------------------------------------------------------

_E = TypeVar("_E", bound=StrEnum)


def _kind(raw: object) -> str:
    if raw is None:
        return "null"
    if isinstance(raw, Mapping):
        return "a mapping"
    if isinstance(raw, list | tuple):
        return "a sequence"
    return type(raw).__name__


def _as_str(raw: object, path: str) -> str:
    if isinstance(raw, str):
        return raw
    if isinstance(raw, bool):
        return "true" if raw else "false"
    if isinstance(raw, int):
        return str(raw)
    if isinstance(raw, float):
        return repr(raw)
    raise ProfileError(path, f"expected a string, got {_kind(raw)}")


def opt_str(src: Source, key: str) -> str | None:
    raw = src.raw(key)
    return None if raw is None else _as_str(raw, f"{src.path}.{key}")


def req_str(src: Source, key: str, *, allow_empty: bool = False) -> str:
    path = f"{src.path}.{key}"
    raw = src.raw(key)
    if raw is None:
        raise src.missing(key)
    value = _as_str(raw, path)
    if not value and not allow_empty:
        raise ProfileError(path, "must not be empty")
    return value


def req_enum(src: Source, key: str, enum: type[_E], *, fold: bool = False) -> _E:
    value = req_str(src, key)
    for member in enum:
        if member.value == value or (fold and member.value.lower() == value.lower()):
            return member
    allowed = ", ".join(m.value for m in enum)
    raise ProfileError(f"{src.path}.{key}", f"expected one of {allowed}, got {value!r}")


def opt_int(src: Source, key: str) -> int | None:
    """An optional integer; empty text counts as absent (maxInstances, §2.3.2.10)."""
    path = f"{src.path}.{key}"
    raw = src.raw(key)
    if raw is None or (isinstance(raw, str) and not raw.strip()):
        return None
    if isinstance(raw, int) and not isinstance(raw, bool):
        return raw
    value = parse_int(raw) if isinstance(raw, str) else None
    if value is None:
        raise ProfileError(path, f"expected an integer, got {_shown(raw)}")
    return value


def _shown(raw: object) -> str:
    """repr of a bad value for a one-line message (long text clipped)."""
    text = repr(raw)
    return text if len(text) <= 80 else text[:80] + "..."


def opt_float(src: Source, key: str) -> float | None:
    path = f"{src.path}.{key}"
    raw = src.raw(key)
    if raw is None:
        return None
    if isinstance(raw, int | float) and not isinstance(raw, bool):
        return float(raw)
    if not isinstance(raw, str) or parse_number(raw) is None:
        raise ProfileError(path, f"expected a number, got {_shown(raw)}")
    return float(raw)  # validated decimal text: huge magnitudes become inf, never raise


def req_bool(src: Source, key: str) -> bool:
    path = f"{src.path}.{key}"
    raw = src.raw(key)
    if raw is None:
        raise src.missing(key)
    if isinstance(raw, bool):
        return raw
    value = parse_bool(raw) if isinstance(raw, str) else None
    if value is None:
        raise ProfileError(path, f"expected a boolean (true/false), got {raw!r}")
    return value


_DATE_PARTS = ("year", "month", "day", "hour", "minute", "second")
# RTCBuilder's YAML export adds XMLGregorianCalendar's fields to the mapping.
_DATE_EXTRA = ("fractionalSecond", "millisecond", "timezone")
_TZ_UNDEFINED = -2147483648  # javax.xml.datatype.DatatypeConstants.FIELD_UNDEFINED
_FRACTION = re.compile(r"\s*0*(?:\.(\d*))?\s*")


def _date_int(value: object, path: str) -> int:
    if isinstance(value, str):
        parsed = parse_int(value)
        if parsed is not None:
            return parsed
    if isinstance(value, int) and not isinstance(value, bool):
        return value
    raise ProfileError(path, f"expected an integer, got {_shown(value)}")


def _date_from_mapping(raw: Mapping[Any, Any], path: str) -> datetime:
    unknown = [k for k in raw if k not in _DATE_PARTS + _DATE_EXTRA]
    if unknown:
        key = str(unknown[0])
        raise ProfileError(
            f"{path}.{key}",
            f"unknown date field {key!r} ({did_you_mean(key, _DATE_PARTS + _DATE_EXTRA)})",
        )
    parts: list[int] = []
    for part in _DATE_PARTS:
        value = raw.get(part)
        if value is None:
            raise ProfileError(f"{path}.{part}", "required field missing")
        parts.append(_date_int(value, f"{path}.{part}"))
    micro: int | None = None
    fraction = raw.get("fractionalSecond")
    if fraction is not None:
        m = _FRACTION.fullmatch(fraction) if isinstance(fraction, str) else None
        if m is None:
            raise ProfileError(
                f"{path}.fractionalSecond", f"expected a fraction 0.xxx, got {_shown(fraction)}"
            )
        micro = int(((m.group(1) or "") + "000000")[:6])
    millis = raw.get("millisecond")
    if millis is not None:
        ms = _date_int(millis, f"{path}.millisecond")
        if not 0 <= ms <= 999:
            raise ProfileError(f"{path}.millisecond", f"expected 0..999, got {ms}")
        if micro is None:
            micro = ms * 1000
        elif micro // 1000 != ms:
            raise ProfileError(f"{path}.millisecond", "disagrees with fractionalSecond")
    tz: timezone | None = None
    zone = raw.get("timezone")
    if zone is not None:
        minutes = _date_int(zone, f"{path}.timezone")
        if minutes != _TZ_UNDEFINED:
            if not -14 * 60 <= minutes <= 14 * 60:
                raise ProfileError(f"{path}.timezone", f"expected minutes -840..840, got {minutes}")
            tz = timezone(timedelta(minutes=minutes))
    try:
        year, month, day, hour, minute, second = parts
        return datetime(year, month, day, hour, minute, second, micro or 0, tzinfo=tz)
    except (ValueError, OverflowError) as e:
        raise ProfileError(path, f"invalid date: {e}") from None


def req_datetime(src: Source, key: str) -> datetime:
    """xsd:dateTime text, or the YAML mapping of year..second (§3.2.1) with
    RTCBuilder's optional fractionalSecond, millisecond and timezone (minutes)."""
    path = f"{src.path}.{key}"
    raw = src.raw(key)
    if raw is None:
        raise src.missing(key)
    if isinstance(raw, datetime):
        return raw
    if isinstance(raw, date):
        return datetime(raw.year, raw.month, raw.day)
    if isinstance(raw, str):
        try:
            return datetime.fromisoformat(raw.strip())
        except ValueError:
            raise ProfileError(path, f"expected an ISO 8601 date-time, got {_shown(raw)}") from None
    if isinstance(raw, Mapping):
        return _date_from_mapping(raw, path)
    raise ProfileError(path, f"expected a date-time, got {_kind(raw)}")


def _strings(src: Source, key: str) -> tuple[str, ...]:
    return tuple(_as_str(v, f"{src.path}.{key}[{i}]") for i, v in enumerate(src.texts(key)))


def is_empty(block: object) -> bool:
    """True for a doc/ext block equal to its default (i.e. not given)."""
    return block == type(block)()


# --- doc blocks --------------------------------------------------------------------

_D = TypeVar(
    "_D",
    BasicDoc,
    ActionDoc,
    ConfigurationDoc,
    DataPortDoc,
    ServicePortDoc,
    ServiceInterfaceDoc,
)

# field name -> key, per doc class (§2.4).
_DOC_KEYS: dict[type[Any], tuple[tuple[str, str], ...]] = {
    BasicDoc: tuple(
        (f, f) for f in ("algorithm", "description", "inout", "creator", "license", "reference")
    ),
    ActionDoc: (
        ("description", "description"),
        ("pre_condition", "preCondition"),
        ("post_condition", "postCondition"),
    ),
    ConfigurationDoc: (
        ("description", "description"),
        ("dataname", "dataname"),
        ("default_value", "defaultValue"),
        ("unit", "unit"),
        ("range", "range"),
        ("constraint", "constraint"),
    ),
    DataPortDoc: tuple(
        (f, f)
        for f in ("description", "type", "number", "semantics", "unit", "occurrence", "operation")
    ),
    ServicePortDoc: (("description", "description"), ("ifdescription", "ifdescription")),
    ServiceInterfaceDoc: (
        ("description", "description"),
        ("doc_argument", "docArgument"),
        ("doc_return", "docReturn"),
        ("doc_exception", "docException"),
        ("doc_pre_condition", "docPreCondition"),
        ("doc_post_condition", "docPostCondition"),
    ),
}


def _read_doc(src: Source, cls: type[_D]) -> _D:
    doc = src.child("rtcDoc::doc")
    if doc is None:
        return cls()
    values = {name: opt_str(doc, key) for name, key in _DOC_KEYS[cls]}
    if cls is DataPortDoc:
        # OpenRTP's RtcProfile_doc.xsd (and so RTCBuilder) spells it "occerrence".
        misspelt = opt_str(doc, "occerrence")
        if misspelt is not None:
            if values["occurrence"] is not None and values["occurrence"] != misspelt:
                raise ProfileError(
                    f"{doc.path}.occerrence", "disagrees with occurrence (give one of them)"
                )
            values["occurrence"] = misspelt
    return cls(**values, extra=doc.extras())


def _write_doc(sink: Sink, doc: object) -> None:
    if is_empty(doc):
        return
    out = sink.child("rtcDoc::doc")
    for name, key in _DOC_KEYS[type(doc)]:
        out.scalar(key, getattr(doc, name))
    out.extras(getattr(doc, "extra"))  # noqa: B009 - every doc class has it


def _read_properties(src: Source) -> tuple[Property, ...]:
    # The spec's YAML says rtcExt::property, RTCBuilder writes rtcExt::properties (the
    # XML element is Properties for both): read both.
    items = src.children("rtcExt::property") or src.children("rtcExt::properties")
    return tuple(
        Property(name=req_str(p, "name"), value=opt_str(p, "value"), extra=p.extras())
        for p in items
    )


def _write_properties(sink: Sink, properties: Sequence[Property]) -> None:
    for prop in properties:
        out = sink.add("rtcExt::property")
        out.scalar("name", prop.name)
        out.scalar("value", prop.value)
        out.extras(prop.extra)


# --- reading -----------------------------------------------------------------------


def read_profile(src: Source) -> RtcProfile:
    """Build the model from the ``rtcProfile`` mapping/element."""
    profile_id = req_str(src, "id")
    version = req_str(src, "version")
    basic = src.child("basicInfo")
    if basic is None:
        raise src.missing("basicInfo")
    basic_info = _read_basic_info(basic)
    actions = src.child("actions")
    if actions is None:
        raise src.missing("actions")
    config_set = src.child("configurationSet")
    language = src.child("language")
    return RtcProfile(
        id=profile_id,
        version=version,
        basic_info=basic_info,
        actions=_read_actions(actions),
        configuration_set=_read_configuration_set(config_set) if config_set else None,
        data_ports=tuple(_read_data_port(p) for p in src.children("dataPorts")),
        service_ports=tuple(_read_service_port(p) for p in src.children("servicePorts")),
        parameters=tuple(
            Parameter(
                name=req_str(p, "name"), default_value=opt_str(p, "defaultValue"), extra=p.extras()
            )
            for p in src.children("parameters")
        ),
        language=_read_language(language) if language else None,
        extra=src.extras(),
    )


def _read_basic_info(src: Source) -> BasicInfo:
    # Keyword arguments evaluate left to right: extras() must come last.
    return BasicInfo(
        name=req_str(src, "name"),
        component_type=req_enum(src, "componentType", ComponentType),
        activity_type=req_enum(src, "activityType", ActivityType),
        component_kind=req_str(src, "componentKind"),
        rtc_type=opt_str(src, "rtcType"),
        category=req_str(src, "category"),
        description=opt_str(src, "description"),
        execution_rate=opt_float(src, "executionRate"),
        execution_type=req_str(src, "executionType"),
        max_instances=opt_int(src, "maxInstances"),
        vendor=req_str(src, "vendor"),
        version=req_str(src, "version"),
        abstract=opt_str(src, "abstract"),
        hardware_profile=opt_str(src, "hardwareProfile"),
        creation_date=req_datetime(src, "creationDate"),
        update_date=req_datetime(src, "updateDate"),
        doc=_read_doc(src, BasicDoc),
        ext=BasicInfoExt(
            comment=opt_str(src, "rtcExt::comment"),
            save_project=opt_str(src, "rtcExt::saveProject"),
            version_up_logs=_strings(src, "rtcExt::versionUpLogs"),
            properties=_read_properties(src),
        ),
        extra=src.extras(),
    )


def _read_actions(src: Source) -> Actions:
    statuses: dict[str, ActionStatus] = {}
    for name, key in ACTION_KEYS.items():
        action = src.child(key)
        if action is not None:
            implemented = req_bool(action, "implemented")
            doc = _read_doc(action, ActionDoc)
            statuses[name] = ActionStatus(implemented=implemented, doc=doc, extra=action.extras())
    return Actions(**statuses, extra=src.extras())


def _read_configuration_set(src: Source) -> ConfigurationSetProfile:
    configs = tuple(_read_configuration(c) for c in src.children("configuration"))
    return ConfigurationSetProfile(configurations=configs, extra=src.extras())


def _read_configuration(src: Source) -> ConfigurationProfile:
    return ConfigurationProfile(
        name=req_str(src, "name"),
        type=req_str(src, "type"),
        default_value=req_str(src, "defaultValue", allow_empty=True),
        unit=opt_str(src, "unit"),
        constraint=src.constraint("constraint"),
        doc=_read_doc(src, ConfigurationDoc),
        ext=ConfigurationExt(
            comment=opt_str(src, "rtcExt::comment"),
            variable_name=opt_str(src, "rtcExt::variableName"),
            properties=_read_properties(src),
        ),
        extra=src.extras(),
    )


_DATA_PORT_EXT = (
    "rtcExt::position",
    "rtcExt::comment",
    "rtcExt::variableName",
    "rtcExt::property",
    "rtcExt::properties",
)
_SERVICE_PORT_EXT = (
    "rtcExt::position",
    "rtcExt::comment",
    "rtcExt::property",
    "rtcExt::properties",
)
_LANGUAGE_EXT = ("rtcExt::targets", "rtcExt::property", "rtcExt::properties")


def _read_data_port(src: Source) -> DataPortProfile:
    has_ext = src.has_ext(_DATA_PORT_EXT)
    return DataPortProfile(
        port_type=req_enum(src, "portType", PortType),
        name=req_str(src, "name"),
        type=req_str(src, "type"),
        idl_file=opt_str(src, "idlFile"),
        interface_type=opt_str(src, "interfaceType"),
        dataflow_type=opt_str(src, "dataflowType"),
        subscription_type=opt_str(src, "subscriptionType"),
        unit=opt_str(src, "unit"),
        constraint=src.constraint("constraint"),
        doc=_read_doc(src, DataPortDoc),
        ext=DataPortExt(
            position=req_enum(src, "rtcExt::position", Position, fold=True),
            comment=opt_str(src, "rtcExt::comment"),
            variable_name=opt_str(src, "rtcExt::variableName"),
            properties=_read_properties(src),
        )
        if has_ext
        else None,
        extra=src.extras(),
    )


def _read_service_port(src: Source) -> ServicePortProfile:
    has_ext = src.has_ext(_SERVICE_PORT_EXT)
    name = req_str(src, "name")
    interfaces = tuple(_read_interface(i) for i in src.children("serviceInterface"))
    trans = tuple(
        TransMethod(kind=req_str(t, "kind"), extra=t.extras()) for t in src.children("transMethod")
    )
    doc = _read_doc(src, ServicePortDoc)
    ext = None
    if has_ext:
        ext = ServicePortExt(
            position=req_enum(src, "rtcExt::position", Position, fold=True),
            comment=opt_str(src, "rtcExt::comment"),
            properties=_read_properties(src),
        )
    return ServicePortProfile(
        name=name, interfaces=interfaces, trans_methods=trans, doc=doc, ext=ext, extra=src.extras()
    )


def _read_interface(src: Source) -> ServiceInterfaceProfile:
    return ServiceInterfaceProfile(
        name=req_str(src, "name"),
        type=req_str(src, "type"),
        direction=req_enum(src, "direction", InterfaceDirection),
        instance_name=opt_str(src, "instanceName"),
        idl_file=opt_str(src, "idlFile"),
        path=opt_str(src, "path"),
        doc=_read_doc(src, ServiceInterfaceDoc),
        ext=ServiceInterfaceExt(
            comment=opt_str(src, "rtcExt::comment"),
            variable_name=opt_str(src, "rtcExt::variableName"),
            properties=_read_properties(src),
        ),
        extra=src.extras(),
    )


def _read_language(src: Source) -> Language:
    has_ext = src.has_ext(_LANGUAGE_EXT)
    kind = req_str(src, "kind")
    ext = None
    if has_ext:
        # OpenRTP's schema makes targets optional (spec 0.2 required one); RTCBuilder
        # writes a bare <rtc:Language xsi:type="rtcExt:language_ext" rtc:kind="C++"/>.
        targets = tuple(_read_target(t) for t in src.children("rtcExt::targets"))
        properties = _read_properties(src)
        if targets or properties:
            ext = LanguageExt(targets=targets, properties=properties)
    return Language(kind=kind, ext=ext, extra=src.extras())


def _read_target(src: Source) -> TargetEnvironment:
    return TargetEnvironment(
        lang_version=opt_str(src, "langVersion"),
        os=opt_str(src, "os"),
        os_versions=_strings(src, "osVersions"),
        other=opt_str(src, "other"),
        cpus=_strings(src, "cpus"),
        cpu_other=opt_str(src, "cpuOther"),
        libraries=tuple(
            Library(
                name=req_str(lib, "name"),
                version=opt_str(lib, "version"),
                other=opt_str(lib, "other"),
                extra=lib.extras(),
            )
            for lib in src.children("libraries")
        ),
        properties=_read_properties(src),
        extra=src.extras(),
    )


# --- writing -----------------------------------------------------------------------


def write_profile(profile: RtcProfile, sink: Sink) -> None:
    """Write the model into the ``rtcProfile`` mapping/element (in XSD child order)."""
    sink.scalar("id", profile.id)
    sink.scalar("version", profile.version)
    _write_basic_info(sink.child("basicInfo"), profile.basic_info)
    _write_actions(sink.child("actions"), profile.actions)
    if profile.configuration_set is not None:
        out = sink.child("configurationSet")
        for config in profile.configuration_set.configurations:
            _write_configuration(out.add("configuration"), config)
        out.extras(profile.configuration_set.extra)
    for port in profile.data_ports:
        _write_data_port(sink.add("dataPorts"), port)
    for sport in profile.service_ports:
        _write_service_port(sink.add("servicePorts"), sport)
    for param in profile.parameters:
        out = sink.add("parameters")
        out.scalar("name", param.name)
        out.scalar("defaultValue", param.default_value)
        out.extras(param.extra)
    if profile.language is not None:
        _write_language(sink.child("language"), profile.language)
    sink.extras(profile.extra)


def _write_basic_info(sink: Sink, b: BasicInfo) -> None:
    sink.declare("basic_info", doc=not is_empty(b.doc), ext=not is_empty(b.ext))
    for key, value in (
        ("name", b.name),
        ("componentType", b.component_type),
        ("activityType", b.activity_type),
        ("componentKind", b.component_kind),
        ("rtcType", b.rtc_type),
        ("category", b.category),
        ("description", b.description),
        ("executionRate", b.execution_rate),
        ("executionType", b.execution_type),
        ("maxInstances", b.max_instances),
        ("vendor", b.vendor),
        ("version", b.version),
        ("abstract", b.abstract),
        ("hardwareProfile", b.hardware_profile),
        ("creationDate", b.creation_date),
        ("updateDate", b.update_date),
        ("rtcExt::comment", b.ext.comment),
        ("rtcExt::saveProject", b.ext.save_project),
    ):
        sink.scalar(key, value)
    _write_doc(sink, b.doc)
    sink.texts("rtcExt::versionUpLogs", b.ext.version_up_logs)
    _write_properties(sink, b.ext.properties)
    sink.extras(b.extra)


def _write_actions(sink: Sink, actions: Actions) -> None:
    for name, status in actions.items():
        out = sink.child(ACTION_KEYS[name])
        out.declare("action_status", doc=not is_empty(status.doc), ext=False)
        out.scalar("implemented", status.implemented)
        _write_doc(out, status.doc)
        out.extras(status.extra)
    sink.extras(actions.extra)


def _write_configuration(sink: Sink, c: ConfigurationProfile) -> None:
    sink.declare("configuration", doc=not is_empty(c.doc), ext=not is_empty(c.ext))
    sink.scalar("name", c.name)
    sink.scalar("type", c.type)
    sink.scalar("defaultValue", c.default_value)
    sink.scalar("unit", c.unit)
    sink.scalar("rtcExt::comment", c.ext.comment)
    sink.scalar("rtcExt::variableName", c.ext.variable_name)
    sink.constraint("constraint", c.constraint)
    _write_doc(sink, c.doc)
    _write_properties(sink, c.ext.properties)
    sink.extras(c.extra)


def _write_data_port(sink: Sink, p: DataPortProfile) -> None:
    sink.declare("dataport", doc=not is_empty(p.doc), ext=p.ext is not None)
    for key, value in (
        ("portType", p.port_type),
        ("name", p.name),
        ("type", p.type),
        ("idlFile", p.idl_file),
        ("interfaceType", p.interface_type),
        ("dataflowType", p.dataflow_type),
        ("subscriptionType", p.subscription_type),
        ("unit", p.unit),
    ):
        sink.scalar(key, value)
    if p.ext is not None:
        sink.position("rtcExt::position", p.ext.position)
        sink.scalar("rtcExt::comment", p.ext.comment)
        sink.scalar("rtcExt::variableName", p.ext.variable_name)
    sink.constraint("constraint", p.constraint)
    _write_doc(sink, p.doc)
    if p.ext is not None:
        _write_properties(sink, p.ext.properties)
    sink.extras(p.extra)


def _write_service_port(sink: Sink, p: ServicePortProfile) -> None:
    sink.declare("serviceport", doc=not is_empty(p.doc), ext=p.ext is not None)
    sink.scalar("name", p.name)
    if p.ext is not None:
        sink.position("rtcExt::position", p.ext.position)
        sink.scalar("rtcExt::comment", p.ext.comment)
    for i in p.interfaces:
        out = sink.add("serviceInterface")
        out.declare("serviceinterface", doc=not is_empty(i.doc), ext=not is_empty(i.ext))
        for key, value in (
            ("name", i.name),
            ("type", i.type),
            ("direction", i.direction),
            ("instanceName", i.instance_name),
            ("idlFile", i.idl_file),
            ("path", i.path),
            ("rtcExt::comment", i.ext.comment),
            ("rtcExt::variableName", i.ext.variable_name),
        ):
            out.scalar(key, value)
        _write_doc(out, i.doc)
        _write_properties(out, i.ext.properties)
        out.extras(i.extra)
    for t in p.trans_methods:
        out = sink.add("transMethod")
        out.scalar("kind", t.kind)
        out.extras(t.extra)
    _write_doc(sink, p.doc)
    if p.ext is not None:
        _write_properties(sink, p.ext.properties)
    sink.extras(p.extra)


def _write_language(sink: Sink, lang: Language) -> None:
    sink.declare("language", doc=False, ext=lang.ext is not None)
    sink.scalar("kind", lang.kind)
    if lang.ext is not None:
        for t in lang.ext.targets:
            out = sink.add("rtcExt::targets")
            out.scalar("langVersion", t.lang_version)
            out.scalar("os", t.os)
            out.scalar("other", t.other)
            out.scalar("cpuOther", t.cpu_other)
            out.texts("osVersions", t.os_versions)
            out.texts("cpus", t.cpus)
            for lib in t.libraries:
                lib_out = out.add("libraries")
                lib_out.scalar("name", lib.name)
                lib_out.scalar("version", lib.version)
                lib_out.scalar("other", lib.other)
                lib_out.extras(lib.extra)
            _write_properties(out, t.properties)
            out.extras(t.extra)
        _write_properties(sink, lang.ext.properties)
    sink.extras(lang.extra)
