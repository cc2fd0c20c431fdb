"""Reading system files: our YAML form, and OpenRTP RTSystemEditor's rtsys XML.

YAML (docs/rtc.md §14)::

    system:
      name: PanTiltSystem
      components:
        sensor:                                  # instance name
          profile: sensor/RTC.yaml               # relative to the system file
          context: {type: periodic, rate: 50}    # optional: the profile's otherwise
          configuration: {amplitude: "0.4"}      # optional: set "system", made active
          configuration_sets: {fast: {...}}      # optional, with active_set: fast
      connections:
        - from: sensor.target
          to: controller.target
          properties: {dataport.subscription_type: new}
      services:
        - [controller.head, actuator.head]

rtsys XML (``rts:RtsProfile``): ``rts:Components`` (``rts:instanceName``, ``rts:id``,
``rts:activeConfigurationSet``, ``rts:ConfigurationSets``/``rts:ConfigurationData``,
``rts:ExecutionContexts`` with ``rts:kind``/``rts:rate``), ``rts:DataPortConnectors``
(``rts:dataflowType``, ``rts:subscriptionType``, ``rts:interfaceType``,
``rts:dataType``, ``rts:pushInterval``, ``rtsExt:Properties``) and
``rts:ServicePortConnectors``. An rtsys file names components by id, not by file: the
profile is the ``openel.profile`` property of the component (``rtsExt:Properties``),
else the RTC Profile next to the rtsys file (or one directory down) whose id is the
component's ``rts:id``. ``dataport.*`` properties this runtime does not know (e.g.
``dataport.serializer.cdr.endian``) are dropped from rtsys connectors; in YAML they
are errors.

Both forms are strict: an unknown YAML key, or an rtsys element or attribute in the
``rts``/``rtsExt`` namespaces that OpenRTP's RtsProfile schema does not declare
(``rtsys_schema``), is refused with the file, line and column and a "did you mean".
Components and connection ends carry where they are written (``location``), so that
the errors found when the system is built point there too.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any
from xml.etree import ElementTree as ET

import msgspec

from openel_async.logs import get_logger

from ...positioned import DocumentError, Location, YamlDocument, convert, load_yaml, relocate
from ..ports.profile import KNOWN_KEYS
from ..profile import ProfileError, load_profile
from .model import (
    ComponentSpec,
    ContextSpec,
    DataConnectionSpec,
    PortRef,
    ServiceConnectionSpec,
    SystemFileError,
    SystemSpec,
)
from .rtsys_schema import RTS_EXT_NS, RTS_NS, RtsysDocument, check_rtsys, parse_rtsys

__all__ = [
    "RTS_EXT_NS",
    "RTS_NS",
    "is_system_file",
    "load_system",
    "loads_rtsys",
    "loads_system_yaml",
]

log = get_logger(__name__)

PROFILE_PROPERTY = "openel.profile"
_CONTEXT_TYPES = {
    "periodic": "periodic",
    "periodicexecutioncontext": "periodic",
    "event_driven": "event_driven",
    "eventdriven": "event_driven",
    "eventdrivenexecutioncontext": "event_driven",
    "sporadic": "sporadic",
    "sporadicexecutioncontext": "sporadic",
}


def is_system_file(path: Path) -> bool:
    """True when ``path`` looks like a system file (a YAML ``system:`` document or an
    rtsys XML), False for anything else (an RTC Profile...). Never raises."""
    try:
        head = path.read_bytes()[:4096]
    except OSError:
        return False
    text = head.decode("utf-8", "replace")
    if path.suffix.lower() == ".xml":
        return "RtsProfile" in text and RTS_NS in text
    for line in text.splitlines():
        stripped = line.strip()
        if not stripped or stripped.startswith(("#", "---", "%")):
            continue
        return stripped.startswith("system:")
    return False


def load_system(path: Path) -> SystemSpec:
    """Read a system file (``.yaml``/``.yml`` or rtsys ``.xml``); SystemFileError
    naming the field for anything wrong, OSError when it cannot be read."""
    raw = path.read_bytes()
    if path.suffix.lower() == ".xml":
        return loads_rtsys(raw, path)
    return loads_system_yaml(raw, path)


# -- YAML --------------------------------------------------------------------------------


def _mapping(value: object, where: str) -> Mapping[str, Any]:
    if not isinstance(value, Mapping) or not all(isinstance(k, str) for k in value):
        raise SystemFileError(where, f"expected a mapping, got {type(value).__name__}")
    return value


def _string(value: object, where: str) -> str:
    if isinstance(value, bool) or not isinstance(value, str | int | float) or str(value) == "":
        raise SystemFileError(where, f"expected a non-empty string, got {value!r}")
    return str(value)


def _port_ref(value: object, where: str, location: Location | None = None) -> PortRef:
    text = _string(value, where)
    component, dot, port = text.partition(".")
    if not dot or not component or not port:
        raise SystemFileError(where, f"expected 'component.port', got {text!r}")
    return PortRef(component, port, where, location)


def _flatten(props: Mapping[str, Any], where: str, prefix: str = "") -> dict[str, object]:
    out: dict[str, object] = {}
    for key, value in props.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            out.update(_flatten(_mapping(value, f"{where}.{key}"), where, f"{name}."))
        elif value is None or isinstance(value, list):
            raise SystemFileError(f"{where}.{name}", f"expected a scalar, got {value!r}")
        else:
            out[name] = value
    return out


def _context(value: object, where: str) -> ContextSpec:
    if value is None:
        return ContextSpec()
    data = _mapping(value, where)
    kind = None
    if "type" in data:
        text = _string(data["type"], f"{where}.type").strip().lower()
        kind = _CONTEXT_TYPES.get(text)
        if kind is None:
            raise SystemFileError(
                f"{where}.type", f"expected periodic, event_driven or sporadic, got {text!r}"
            )
    rate = None
    if "rate" in data:
        value = data["rate"]
        try:
            rate = (
                float(value)
                if isinstance(value, str | int | float) and not isinstance(value, bool)
                else None
            )
        except (TypeError, ValueError):
            rate = None
        if rate is None:
            raise SystemFileError(f"{where}.rate", f"expected a number of Hz, got {value!r}")
    return ContextSpec(kind, rate)


def _sets(data: Mapping[str, Any], where: str) -> tuple[dict[str, dict[str, str]], str | None]:
    sets: dict[str, dict[str, str]] = {}
    for name, values in _mapping(
        data.get("configuration_sets") or {}, f"{where}.configuration_sets"
    ).items():
        set_where = f"{where}.configuration_sets.{name}"
        sets[name] = {
            k: _string(v, f"{set_where}.{k}") for k, v in _mapping(values, set_where).items()
        }
    active = data.get("active_set")
    if "configuration" in data:
        values = _mapping(data["configuration"], f"{where}.configuration")
        sets["system"] = {k: _string(v, f"{where}.configuration.{k}") for k, v in values.items()}
        if active is None:
            active = "system"
    if active is not None:
        active = _string(active, f"{where}.active_set")
    return sets, active


# The keys of the YAML form (values are checked by hand below, for their messages).
class _ContextKeys(msgspec.Struct, forbid_unknown_fields=True):
    type: Any = None
    rate: Any = None


class _ComponentKeys(msgspec.Struct, forbid_unknown_fields=True):
    profile: Any = None
    context: _ContextKeys | None = None
    configuration: Any = None
    configuration_sets: Any = None
    active_set: Any = None


class _ConnectionKeys(msgspec.Struct, forbid_unknown_fields=True, rename={"source": "from"}):
    name: Any = None
    source: Any = None
    to: Any = None
    properties: Any = None


class _SystemKeys(msgspec.Struct, forbid_unknown_fields=True):
    name: Any = None
    components: dict[str, _ComponentKeys] | None = None
    connections: list[_ConnectionKeys] | None = None
    services: Any = None


class _FileKeys(msgspec.Struct, forbid_unknown_fields=True):
    system: _SystemKeys


_WHERE_PART = re.compile(r"\.([^.\[]+)|\[(\d+)\]")


def _place(doc: YamlDocument, path: str) -> Location:
    """Where the field ``path`` (``system.connections[0].to``) is written, as far as the
    file has it."""
    if path == "<document>":
        return doc.where(doc.data)
    parts: list[str | int] = [
        m.group(1) if m.group(1) is not None else int(m.group(2))
        for m in _WHERE_PART.finditer("." + path)
    ]
    return doc.follow(parts)[1]


def _located(exc: SystemFileError, doc: YamlDocument) -> SystemFileError:
    """``exc`` at the position of the field it names (as far as the file has it)."""
    return relocate(exc, DocumentError(str(exc), path=exc.path, location=_place(doc, exc.path)))


def loads_system_yaml(raw: str | bytes, path: Path) -> SystemSpec:
    """A YAML system file; SystemFileError naming the file, line and column of the field
    (unknown keys with a "did you mean")."""
    try:
        doc = load_yaml(raw, str(path))
    except DocumentError as exc:
        raise relocate(SystemFileError("<document>", exc.message), exc) from None
    if not isinstance(doc.data, Mapping):
        raise _located(
            SystemFileError("<document>", "expected a mapping with the key 'system'"), doc
        )
    try:
        convert(doc, doc.data, _FileKeys, "")
    except DocumentError as exc:
        raise relocate(SystemFileError(exc.path, exc.message), exc) from None
    try:
        return _system_yaml(doc.data, path, doc)
    except SystemFileError as exc:
        raise _located(exc, doc) from None


def _system_yaml(root: Mapping[str, Any], path: Path, doc: YamlDocument) -> SystemSpec:
    system = _mapping(root["system"], "system")
    name = _string(system.get("name", path.stem), "system.name")
    comps_data = _mapping(system.get("components"), "system.components")
    if not comps_data:
        raise SystemFileError("system.components", "at least one component is needed")
    components = []
    for comp_name, value in comps_data.items():
        where = f"system.components.{comp_name}"
        if "." in comp_name or not comp_name.strip():
            raise SystemFileError(where, "a component name must be non-empty, without '.'")
        data = _mapping(value, where)
        profile = path.parent / _string(data.get("profile"), f"{where}.profile")
        sets, active = _sets(data, where)
        components.append(
            ComponentSpec(
                comp_name,
                profile,
                where,
                _context(data.get("context"), f"{where}.context"),
                sets,
                active,
                doc.key(comps_data, comp_name),
            )
        )
    connections = []
    conns = system.get("connections") or []
    if not isinstance(conns, list):
        raise SystemFileError("system.connections", "expected a list")
    for i, value in enumerate(conns):
        where = f"system.connections[{i}]"
        data = _mapping(value, where)
        props = _flatten(
            _mapping(data.get("properties") or {}, f"{where}.properties"), f"{where}.properties"
        )
        connections.append(
            DataConnectionSpec(
                str(data.get("name", "")),
                _port_ref(data.get("from"), f"{where}.from", _place(doc, f"{where}.from")),
                _port_ref(data.get("to"), f"{where}.to", _place(doc, f"{where}.to")),
                props,
                where,
                _place(doc, where),
            )
        )
    services = []
    svcs = system.get("services") or []
    if not isinstance(svcs, list):
        raise SystemFileError("system.services", "expected a list")
    for i, value in enumerate(svcs):
        where = f"system.services[{i}]"
        if not (isinstance(value, list) and len(value) == 2):
            raise SystemFileError(where, "expected a pair [component.port, component.port]")
        services.append(
            ServiceConnectionSpec(
                "",
                _port_ref(value[0], f"{where}[0]", _place(doc, f"{where}[0]")),
                _port_ref(value[1], f"{where}[1]", _place(doc, f"{where}[1]")),
                where,
                _place(doc, where),
            )
        )
    return SystemSpec(name, path, tuple(components), tuple(connections), tuple(services))


# -- rtsys XML ---------------------------------------------------------------------------


def _rts(name: str) -> str:
    return f"{{{RTS_NS}}}{name}"


def _attr(el: ET.Element, name: str, default: str | None = None) -> str | None:
    for key in (_rts(name), f"{{{RTS_EXT_NS}}}{name}"):
        if key in el.attrib:
            return el.attrib[key]
    return default


def _props(el: ET.Element) -> dict[str, str]:
    out: dict[str, str] = {}
    for child in el:
        if child.tag == f"{{{RTS_EXT_NS}}}Properties":
            key = _attr(child, "name")
            if key:
                out[key] = _attr(child, "value", "") or ""
    return out


def _find_profile(directory: Path, rtc_id: str, where: str) -> Path:
    candidates = [
        *sorted(directory.glob("*.*")),
        *sorted(directory.glob("*/*.*")),
    ]
    for file in candidates:
        if file.suffix.lower() not in (".yaml", ".yml", ".xml") or not file.is_file():
            continue
        try:
            if load_profile(file).id == rtc_id:
                return file
        except (ProfileError, OSError):
            continue
    raise SystemFileError(
        where,
        f"no RTC Profile with id {rtc_id!r} in {directory} or its subdirectories "
        f"(or name it with an rtsExt:Properties '{PROFILE_PROPERTY}')",
    )


def _rtsys_port(
    doc: RtsysDocument, el: ET.Element | None, where: str, parent: ET.Element
) -> PortRef:
    if el is None:
        raise SystemFileError(where, "missing").at(doc.element(parent))
    inst = _attr(el, "instanceName")
    port = _attr(el, "portName")
    if not inst or not port:
        raise SystemFileError(where, "needs rts:instanceName and rts:portName").at(doc.element(el))
    return PortRef(inst, port.removeprefix(f"{inst}."), where, doc.attribute(el, _rts("portName")))


def loads_rtsys(raw: str | bytes, path: Path) -> SystemSpec:
    """An rtsys XML; SystemFileError naming the file, line and column for an element or
    attribute OpenRTP's schema does not declare (with a "did you mean") and for any
    other refusal."""
    doc = parse_rtsys(raw, str(path))
    check_rtsys(doc)
    root = doc.root
    parts = (_attr(root, "id") or "").split(":")
    name = parts[2] if len(parts) >= 4 and parts[2] else path.stem  # RTSystem:vendor:name:ver
    components = []
    for i, comp in enumerate(root.findall(_rts("Components"))):
        where = f"rts:Components[{i}]"
        inst = _attr(comp, "instanceName")
        if not inst:
            raise SystemFileError(f"{where}.instanceName", "required").at(doc.element(comp))
        props = _props(comp)
        if PROFILE_PROPERTY in props:
            profile = path.parent / props[PROFILE_PROPERTY]
        else:
            try:
                profile = _find_profile(path.parent, _attr(comp, "id") or "", f"{where}.id")
            except SystemFileError as exc:
                raise exc.at(doc.attribute(comp, _rts("id"))) from None
        sets: dict[str, dict[str, str]] = {}
        for cs in comp.findall(_rts("ConfigurationSets")):
            set_id = _attr(cs, "id") or ""
            if set_id.startswith("__"):
                continue  # OpenRTM's hidden sets (__widget__, __constraints__...)
            sets[set_id] = {
                _attr(d, "name") or "": _attr(d, "data") or ""
                for d in cs.findall(_rts("ConfigurationData"))
            }
        active = _attr(comp, "activeConfigurationSet")
        context = ContextSpec()
        ecs = comp.findall(_rts("ExecutionContexts"))
        if ecs:
            kind = (_attr(ecs[0], "kind") or "").strip().lower()
            rate_text = _attr(ecs[0], "rate")
            ctx_type = _CONTEXT_TYPES.get(kind.replace("_", "")) or _CONTEXT_TYPES.get(kind)
            try:
                rate = float(rate_text) if rate_text else None
            except ValueError:
                raise SystemFileError(
                    f"{where}.ExecutionContexts.rate", f"not a number: {rate_text!r}"
                ).at(doc.attribute(ecs[0], _rts("rate"))) from None
            context = ContextSpec(ctx_type, rate if ctx_type != "event_driven" else None)
        components.append(
            ComponentSpec(
                inst,
                profile,
                where,
                context,
                sets,
                active if active in sets else None,
                doc.element(comp),
            )
        )
    connections = []
    for i, conn in enumerate(root.findall(_rts("DataPortConnectors"))):
        where = f"rts:DataPortConnectors[{i}]"
        conn_props: dict[str, object] = {}
        for attr, key in (
            ("dataflowType", "dataport.dataflow_type"),
            ("subscriptionType", "dataport.subscription_type"),
            ("interfaceType", "dataport.interface_type"),
            ("dataType", "dataport.data_type"),
        ):
            value = _attr(conn, attr)
            if value:
                conn_props[key] = value
        interval = _attr(conn, "pushInterval")
        subscription = str(conn_props.get("dataport.subscription_type", "")).lower()
        if interval and subscription == "periodic":
            conn_props["dataport.publisher.push_rate"] = interval
        for key, value in _props(conn).items():
            if key.lower().startswith("dataport.") and key.lower() not in KNOWN_KEYS:
                log.debug("rtsys_property_dropped", connector=where, key=key)
                continue
            conn_props[key] = value
        connections.append(
            DataConnectionSpec(
                _attr(conn, "name") or "",
                _rtsys_port(
                    doc, conn.find(_rts("sourceDataPort")), f"{where}.sourceDataPort", conn
                ),
                _rtsys_port(
                    doc, conn.find(_rts("targetDataPort")), f"{where}.targetDataPort", conn
                ),
                conn_props,
                where,
                doc.element(conn),
            )
        )
    services = []
    for i, conn in enumerate(root.findall(_rts("ServicePortConnectors"))):
        where = f"rts:ServicePortConnectors[{i}]"
        services.append(
            ServiceConnectionSpec(
                _attr(conn, "name") or "",
                _rtsys_port(
                    doc, conn.find(_rts("sourceServicePort")), f"{where}.sourceServicePort", conn
                ),
                _rtsys_port(
                    doc, conn.find(_rts("targetServicePort")), f"{where}.targetServicePort", conn
                ),
                where,
                doc.element(conn),
            )
        )
    if not components:
        raise SystemFileError("rts:Components", "at least one component is needed").at(
            doc.element(root)
        )
    return SystemSpec(name, path, tuple(components), tuple(connections), tuple(services))
