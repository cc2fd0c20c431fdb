"""Which ODrive firmware an endpoint table is for, and the check made before an endpoint write.

ODrive's RxSdo/TxSdo address endpoints by numeric id, and the ids change between firmware
builds: a host must use the ``flat_endpoints.json`` published for the exact firmware the axis
runs (ODrive's firmware release page). Its shape, as ODrive publishes it::

    {"fw_version": "0.6.10", "hw_version": "4.4.58",
     "endpoints": {"axis0.config.watchdog_timeout": {"id": 200, "type": "float", "access": "rw"},
                   ...}}

``fw_version`` is the firmware (``major.minor.revision``, a ``-suffix`` allowed),
``hw_version`` the board as Get_Version reports it (``product_line.version.variant``),
``endpoints`` maps each path to its ``id`` (0..65535), ``type`` and, optionally, ``access``
(``r``, ``w``, ``rw``). Entries whose type does not fit the 4-byte RxSdo value (functions,
64-bit integers, ...) are kept out of the table (:attr:`EndpointTable.skipped`).

:class:`EndpointTable` knows the firmware it is for; :func:`load_endpoints` reads a file
(BadParameterError naming the file and what is wrong). :data:`BUILTIN_TABLE` is the built-in
table of :mod:`openel_can.odrive_endpoints` (firmware 0.6.x, exact revision unknown): it
matches no firmware version an ODrive reports, only the simulated ODrive's
(:data:`SIMULATED_FIRMWARE`).

Before writing an endpoint, a host reads the axis's version with Get_Version (a remote frame,
a bounded wait) and compares it with the table's (:meth:`EndpointTable.refusal`): the firmware
``major.minor.revision`` must equal the table's ``fw_version`` (its part before any ``-``, as
ODrive's own CAN examples compare) and, when the table names one, the hardware version must
equal its ``hw_version``. Otherwise the write is refused.
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any, Final, get_args

from openel_async.errors import BadParameterError

from . import cansimple as cs
from .odrive_endpoints import ENDPOINTS, FIRMWARE, Endpoint, EndpointType

__all__ = [
    "BUILTIN_TABLE",
    "DRIVER_ENDPOINTS",
    "SIMULATED_FIRMWARE",
    "SIM_UNRELEASED_MARK",
    "EndpointTable",
    "FirmwareVersion",
    "driver_endpoint_ids",
    "endpoint_table",
    "load_endpoints",
]

SIM_UNRELEASED_MARK: Final = 0xFF
"""The ``fw_version_unreleased`` byte of the simulated ODrive's default Get_Version (an ODrive
reports 0 for a release, 1 for a development build)."""

DRIVER_ENDPOINTS: Final = {
    "vel_ramp_rate_endpoint": ("axis0.controller.config.vel_ramp_rate", "float"),
    "watchdog_timeout_endpoint": ("axis0.config.watchdog_timeout", "float"),
    "enable_watchdog_endpoint": ("axis0.config.enable_watchdog", "bool"),
}
"""The endpoints :class:`~openel_can.odrive.ODriveAxis` writes, by its option naming an id:
(path, type)."""
_SCALAR_TYPES: Final = frozenset(get_args(EndpointType))
_ACCESS: Final = frozenset({"r", "w", "rw"})
_VERSION: Final = re.compile(r"(\d+)\.(\d+)\.(\d+)(-[0-9A-Za-z.+_-]+)?")


@dataclass(frozen=True)
class FirmwareVersion:
    """What an axis reports with Get_Version: firmware and hardware versions."""

    fw: tuple[int, int, int]
    """major, minor, revision."""
    hw: tuple[int, int, int]
    """product line, version, variant (Get_Version's hw_version_major/minor/variant)."""
    unreleased: int = 0
    """0: a release; else a development build (:data:`SIM_UNRELEASED_MARK`: the simulation)."""
    protocol: int = 2

    @classmethod
    def of(cls, msg: cs.Version) -> FirmwareVersion:
        return cls(
            (msg.fw_version_major, msg.fw_version_minor, msg.fw_version_revision),
            (msg.hw_version_major, msg.hw_version_minor, msg.hw_version_variant),
            msg.fw_version_unreleased,
            msg.protocol_version,
        )

    def message(self, node_id: int) -> cs.Version:
        """The Get_Version reply of ``node_id`` reporting this version."""
        return cs.Version(node_id, self.protocol, *self.hw, *self.fw, self.unreleased)

    @property
    def fw_text(self) -> str:
        return ".".join(str(n) for n in self.fw)

    @property
    def hw_text(self) -> str:
        return ".".join(str(n) for n in self.hw)

    def __str__(self) -> str:
        if self == SIMULATED_FIRMWARE:
            return f"{self.fw_text}-sim (the simulated ODrive)"
        suffix = "" if not self.unreleased else " (a development build)"
        return f"{self.fw_text} on hardware {self.hw_text}{suffix}"


SIMULATED_FIRMWARE: Final = FirmwareVersion((0, 6, 10), (4, 4, 58), SIM_UNRELEASED_MARK)
"""The simulated ODrive's default Get_Version: firmware 0.6.10 on an ODrive Pro (hardware
4.4.58) with the unreleased byte :data:`SIM_UNRELEASED_MARK`, an identity no ODrive reports
(a release reports 0, a development build 1). The built-in table is declared for it (the
simulation implements the built-in ids by construction)."""


@dataclass(frozen=True)
class EndpointTable:
    """Endpoints by name and id, with the firmware (and board) they are the ids of."""

    endpoints: tuple[Endpoint, ...]
    fw_version: str | None
    """``flat_endpoints.json``'s ``fw_version``; None: the built-in table (matches none)."""
    hw_version: str | None
    source: str
    """Where the table comes from, in words (a file's path)."""
    skipped: tuple[str, ...] = field(default=())
    """The file's endpoints left out: their type does not fit an RxSdo value."""

    @property
    def firmware(self) -> str:
        """The firmware the table is for, in words."""
        if self.fw_version is None:
            return FIRMWARE
        board = "" if self.hw_version is None else f" on hardware {self.hw_version}"
        return f"{self.fw_version}{board}"

    @cached_property
    def by_name(self) -> Mapping[str, Endpoint]:
        return {e.name: e for e in self.endpoints}

    def get(self, name: str) -> Endpoint | None:
        return self.by_name.get(name)

    def matches(self, version: FirmwareVersion) -> bool:
        """The ids are those of the firmware ``version`` reports (module docstring)."""
        if self.fw_version is None:
            return version == SIMULATED_FIRMWARE
        if version.fw_text != self.fw_version.partition("-")[0]:
            return False
        return self.hw_version is None or version.hw_text == self.hw_version

    def mismatch(self, node_id: int, version: FirmwareVersion | None) -> str | None:
        """How the axis's firmware differs from the table's (None: the ids are its)."""
        if version is not None and self.matches(version):
            return None
        reported = (
            "does not answer Get_Version (its firmware cannot be checked)"
            if version is None
            else f"reports firmware {version}"
        )
        return (
            f"ODrive node {node_id} {reported}, but the endpoint table ({self.source}) is for "
            f"firmware {self.firmware}"
        )

    def fix(self, version: FirmwareVersion | None) -> str:
        """What to do about a mismatch."""
        which = "the firmware the axis runs" if version is None else f"firmware {version.fw_text}"
        return (
            f"name the flat_endpoints.json of {which} (its release page at "
            "docs.odriverobotics.com) in the rig: params: {endpoints: path/to/flat_endpoints.json}"
        )

    def refusal(self, node_id: int, version: FirmwareVersion | None, what: str) -> str | None:
        """Why writing ``what`` by this table's ids to the axis is refused (None: it is not)."""
        mismatch = self.mismatch(node_id, version)
        if mismatch is None:
            return None
        return (
            f"{mismatch}: endpoint ids change between firmware builds, so writing {what} by "
            f"its ids could change another setting; refused. To fix: {self.fix(version)}"
        )


BUILTIN_TABLE: Final = EndpointTable(
    ENDPOINTS, None, None, "the built-in table, openel_can.odrive_endpoints"
)


def _problem(path: Path, what: str) -> BadParameterError:
    return BadParameterError(
        "endpoints", str(path), f"a flat_endpoints.json of an ODrive firmware ({what})"
    )


def _version(raw: Mapping[str, Any], key: str, path: Path) -> str:
    value = raw.get(key)
    if not isinstance(value, str) or _VERSION.fullmatch(value) is None:
        raise _problem(path, f"{key} {value!r} is not a version such as '0.6.10'")
    return value


def _entry(name: object, entry: object, path: Path) -> Endpoint | str:
    """The endpoint of one entry, or its name when its type does not fit an RxSdo value."""
    if not isinstance(name, str) or not name:
        raise _problem(path, f"endpoint name {name!r} is not a path such as 'axis0.config.x'")
    if not isinstance(entry, dict):
        raise _problem(path, f"endpoints[{name!r}] is not an object with id and type")
    ident = entry.get("id")
    if isinstance(ident, bool) or not isinstance(ident, int) or not 0 <= ident <= 0xFFFF:
        raise _problem(path, f"endpoints[{name!r}].id {ident!r} is not an integer in 0..65535")
    kind = entry.get("type")
    if not isinstance(kind, str) or not kind:
        raise _problem(path, f"endpoints[{name!r}].type {kind!r} is not a type name")
    access = entry.get("access")
    if access is not None and access not in _ACCESS:
        raise _problem(path, f"endpoints[{name!r}].access {access!r} is not r, w or rw")
    if kind not in _SCALAR_TYPES:
        return name
    return Endpoint(name, ident, kind, access)  # type: ignore[arg-type]


def load_endpoints(path: str | os.PathLike[str]) -> EndpointTable:
    """The table of a ``flat_endpoints.json`` (module docstring); BadParameterError naming
    ``endpoints``, the file and what is wrong with it."""
    file = Path(path)
    try:
        text = file.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise _problem(file, f"cannot be read: {exc}") from None
    try:
        raw = json.loads(text)
    except json.JSONDecodeError as exc:
        raise _problem(file, f"not JSON: line {exc.lineno} column {exc.colno}: {exc.msg}") from None
    if not isinstance(raw, dict):
        raise _problem(file, "its top level is not an object with fw_version and endpoints")
    fw_version = _version(raw, "fw_version", file)
    hw_version = _version(raw, "hw_version", file)
    entries = raw.get("endpoints")
    if not isinstance(entries, dict) or not entries:
        raise _problem(file, "no 'endpoints' object mapping names to {id, type}")
    endpoints: list[Endpoint] = []
    skipped: list[str] = []
    seen: dict[int, str] = {}
    for name, entry in entries.items():
        endpoint = _entry(name, entry, file)
        if isinstance(endpoint, str):
            skipped.append(endpoint)
            continue
        other = seen.setdefault(endpoint.id, endpoint.name)
        if other != endpoint.name:
            raise _problem(file, f"endpoint id {endpoint.id} is both {other!r} and {name!r}")
        endpoints.append(endpoint)
    endpoints.sort(key=lambda e: e.id)
    return EndpointTable(tuple(endpoints), fw_version, hw_version, str(file), tuple(skipped))


def endpoint_table(
    endpoints: str | os.PathLike[str] | EndpointTable | None,
    files_dir: str | os.PathLike[str] | None = None,
) -> EndpointTable:
    """The table a device's ``endpoints`` names: a table, a file (a relative path is relative
    to ``files_dir``, the rig file's directory), or None for :data:`BUILTIN_TABLE`."""
    if endpoints is None:
        return BUILTIN_TABLE
    if isinstance(endpoints, EndpointTable):
        return endpoints
    if not isinstance(endpoints, str | os.PathLike) or not str(endpoints):
        raise BadParameterError("endpoints", endpoints, "the path of a flat_endpoints.json")
    path = Path(endpoints)
    if not path.is_absolute() and files_dir is not None:
        path = Path(files_dir) / path
    return load_endpoints(path)


def driver_endpoint_ids(table: EndpointTable, given: Mapping[str, object]) -> dict[str, int]:
    """The ids of :data:`DRIVER_ENDPOINTS`: ``given[option]`` when not None, else the table's
    (BadParameterError naming ``endpoints`` when the table lacks one or types it otherwise)."""
    ids: dict[str, int] = {}
    missing: list[str] = []
    for key, (name, kind) in DRIVER_ENDPOINTS.items():
        value = given.get(key)
        if value is not None:
            ids[key] = value  # type: ignore[assignment]  # checked by the driver
            continue
        endpoint = table.get(name)
        if endpoint is None or endpoint.type != kind:
            missing.append(f"{name} ({kind})")
            continue
        ids[key] = endpoint.id
    if missing:
        raise BadParameterError(
            "endpoints", table.source, f"an endpoint table with {', '.join(missing)}"
        )
    return ids
