"""RTC Profiles: the component description format of the RTC Profile spec.

``load_profile``/``save_profile`` pick the form by file suffix (``.yaml``/``.yml`` or
``.xml``); ``loads_*``/``dumps_*`` work on text.  Every problem with a document is a
``ProfileError`` whose ``path`` names the field.
"""

from __future__ import annotations

import os
from pathlib import Path

from ...positioned import Location
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
    validate_profile,
)
from .xml_io import dumps_constraint_xml, dumps_xml, loads_constraint_xml, loads_xml
from .yaml_io import dumps_yaml, loads_yaml

__all__ = [
    "ACTION_KEYS",
    "ActionDoc",
    "ActionStatus",
    "Actions",
    "ActivityType",
    "BasicDoc",
    "BasicInfo",
    "BasicInfoExt",
    "ComponentType",
    "ConfigurationDoc",
    "ConfigurationExt",
    "ConfigurationProfile",
    "ConfigurationSetProfile",
    "DataPortDoc",
    "DataPortExt",
    "DataPortProfile",
    "Extra",
    "ExtraValue",
    "InterfaceDirection",
    "Language",
    "LanguageExt",
    "Library",
    "Parameter",
    "PortType",
    "Position",
    "ProfileError",
    "Property",
    "RtcProfile",
    "ServiceInterfaceDoc",
    "ServiceInterfaceExt",
    "ServiceInterfaceProfile",
    "ServicePortDoc",
    "ServicePortExt",
    "ServicePortProfile",
    "TargetEnvironment",
    "TransMethod",
    "dumps_constraint_xml",
    "dumps_xml",
    "dumps_yaml",
    "load_profile",
    "loads_constraint_xml",
    "loads_xml",
    "loads_yaml",
    "save_profile",
    "validate_profile",
]

_YAML_SUFFIXES = (".yaml", ".yml")


def _format_of(path: Path) -> str:
    suffix = path.suffix.lower()
    if suffix in _YAML_SUFFIXES:
        return "yaml"
    if suffix == ".xml":
        return "xml"
    raise ProfileError(str(path), f"unknown profile format {suffix!r} (use .yaml, .yml or .xml)")


def load_profile(path: str | os.PathLike[str]) -> RtcProfile:
    """Read a profile file; the suffix selects YAML or XML.  Raises ProfileError naming
    the file, line and column (and OSError when the file cannot be read)."""
    file = Path(path)
    kind = _format_of(file)
    data = file.read_bytes()  # bytes: the XML parser honours the declared encoding
    if kind == "xml":
        return loads_xml(data, str(path))
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise ProfileError("<document>", f"not UTF-8: {e}", location=Location(str(path))) from None
    return loads_yaml(text, str(path))


def save_profile(profile: RtcProfile, path: str | os.PathLike[str]) -> None:
    """Write a profile file (UTF-8); the suffix selects YAML or XML."""
    file = Path(path)
    text = dumps_xml(profile) if _format_of(file) == "xml" else dumps_yaml(profile)
    file.write_text(text, encoding="utf-8")
