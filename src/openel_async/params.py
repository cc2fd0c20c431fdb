"""Device parameters: what ``openel-async param`` reads and writes on one device.

A device's parameters are the entries of its own table -- a CANopen drive's object
dictionary (its EDS), an ODrive's endpoints, a servo's control table -- each described by a
:class:`ParameterInfo`: name, address, data type, access, unit, where it is kept
(``eeprom``: kept at power-off; ``ram``: a setting lost at power-off; ``volatile``: a value
the device computes) and a description. A driver offers them through a
:class:`ParameterAccess` (the object a bus kind's
:meth:`~openel_async.rig.BusKind.parameter_access` returns for one device of a rig): look a
parameter up by name or address (:meth:`ParameterAccess.parameter`, a
:class:`~openel_async.errors.BadParameterError` naming the close matches otherwise), read it,
write it.

Values are the device's own (``raw``) numbers; :attr:`ParameterInfo.scale` turns them into
:attr:`ParameterInfo.unit` for display (a Dynamixel's Profile Velocity 100 = 22.9 rpm).
:func:`parse_value` reads a value typed on the command line by the parameter's
:attr:`ParameterInfo.kind`, checked against its range; :func:`format_value` shows one with
its unit.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Literal, Protocol, TypeAlias, runtime_checkable

from .errors import BadParameterError

__all__ = [
    "ACCESSES",
    "STORAGES",
    "Access",
    "ParamValue",
    "ParameterAccess",
    "ParameterInfo",
    "Storage",
    "close_matches",
    "format_value",
    "not_found",
    "parse_value",
    "scaled",
]

ParamValue: TypeAlias = int | float | bool | str | bytes
"""A parameter's value as the device holds it."""
Access: TypeAlias = Literal["ro", "rw", "wo", "const"]
Storage: TypeAlias = Literal["eeprom", "ram", "volatile"]
Kind: TypeAlias = Literal["int", "float", "bool", "str", "bytes"]
ACCESSES: tuple[Access, ...] = ("ro", "rw", "wo", "const")
STORAGES: tuple[Storage, ...] = ("eeprom", "ram", "volatile")


@dataclass(frozen=True)
class ParameterInfo:
    """One parameter of a device (see the module docstring)."""

    name: str
    """``Profile velocity``, ``axis0.controller.config.vel_limit``, ``Profile Velocity``."""
    address: str
    """Where the protocol finds it: ``0x6081:00``, ``endpoint 388``, ``112 (4 bytes)``."""
    type: str
    """The protocol's data type: ``UNSIGNED32``, ``float``, ``uint16``."""
    access: Access
    unit: str = ""
    """The unit of the scaled value (``""``: a plain number or a code)."""
    storage: Storage = "ram"
    description: str = ""
    kind: Kind = "int"
    """How a value is typed and shown."""
    low: float | None = None
    """The smallest value the device takes (raw), if known."""
    high: float | None = None
    scale: float = 1.0
    """``raw * scale`` is the value in :attr:`unit`."""
    command: bool = False
    """A command rather than a setting (a controlword, a target, Torque Enable): writing it
    would enable, move or stop the device, so ``openel-async param`` only reads it."""

    @property
    def readable(self) -> bool:
        return self.access != "wo"

    @property
    def writable(self) -> bool:
        return self.access in ("rw", "wo")


@runtime_checkable
class ParameterAccess(Protocol):
    """A device's parameters, as a driver offers them (see the module docstring). Opening
    it sends nothing; each read and write is one exchange with the device (bounded by the
    protocol's own timeouts; ``openel-async param`` bounds each one more)."""

    @property
    def source(self) -> str:
        """Where the table comes from, in words (``EDS openel_servo402.eds``)."""
        ...

    def parameters(self) -> Sequence[ParameterInfo]:
        """Every parameter, in the table's order."""
        ...

    def parameter(self, key: str) -> ParameterInfo:
        """The parameter ``key`` names (its name, ignoring case, or its address);
        BadParameterError naming the closest names otherwise."""
        ...

    async def read(self, info: ParameterInfo) -> ParamValue:
        """The parameter's value, read from the device."""
        ...

    async def write_blocker(self, info: ParameterInfo) -> str | None:
        """Why a write of ``info`` needs something done first that changes the machine
        (a Dynamixel's EEPROM: the torque must be off), read from the device; None: it
        can be written as it is."""
        ...

    async def write(self, info: ParameterInfo, value: ParamValue, *, unblock: bool = False) -> None:
        """Write ``value`` (checked by :func:`parse_value`). ``unblock``: do first what
        :meth:`write_blocker` said (the caller has the user's consent); without it a
        blocked write raises BadParameterError."""
        ...


def close_matches(key: str, names: Iterable[str], n: int = 3) -> list[str]:
    """The names closest to ``key`` (case ignored), best first: those containing it (a part
    of a long dotted name, ``vel_limit``), then the most alike, as a whole or by their last
    dotted part (``vel_limt``)."""
    by_fold: dict[str, str] = {}
    for name in names:
        by_fold.setdefault(name.casefold(), name)
    part = key.strip().casefold()
    found = [f for f in by_fold if part and part in f][:n]

    def score(folded: str) -> float:
        last = folded.rsplit(".", 1)[-1]
        return max(
            difflib.SequenceMatcher(None, part, folded).ratio(),
            difflib.SequenceMatcher(None, part, last).ratio(),
        )

    scored = sorted(((score(f), f) for f in by_fold if f not in found), reverse=True)
    found += [f for s, f in scored[: n - len(found)] if s >= 0.6]
    return [by_fold[f] for f in found]


def not_found(key: str, names: Iterable[str], where: str) -> BadParameterError:
    """The error for an unknown parameter ``key`` of ``where``, naming the close ones."""
    close = close_matches(key, names)
    hint = f"; did you mean {', '.join(repr(c) for c in close)}?" if close else ""
    return BadParameterError("parameter", key, f"a parameter of {where}{hint}")


_TRUE = frozenset({"1", "true", "on", "yes"})
_FALSE = frozenset({"0", "false", "off", "no"})


def parse_value(info: ParameterInfo, text: str) -> ParamValue:
    """``text`` as a value of ``info`` (ints in decimal, ``0x`` hex or ``0b`` binary; bools
    as 1/0, true/false, on/off; bytes as hex), checked against its range;
    BadParameterError naming the parameter and what it takes."""
    text = text.strip()
    what = f"{info.name} ({info.type})"
    if info.kind == "bool":
        folded = text.casefold()
        if folded in _TRUE:
            return True
        if folded in _FALSE:
            return False
        raise BadParameterError(what, text, "a boolean: 1/0, true/false, on/off")
    if info.kind == "str":
        return text
    if info.kind == "bytes":
        try:
            return bytes.fromhex(text.removeprefix("0x"))
        except ValueError:
            raise BadParameterError(what, text, "bytes in hex (0a1b2c)") from None
    value: int | float
    try:
        value = int(text, 0) if info.kind == "int" else float(text)
    except ValueError:
        kind = "an integer" if info.kind == "int" else "a number"
        raise BadParameterError(what, text, kind) from None
    if isinstance(value, float) and not math.isfinite(value):
        raise BadParameterError(what, text, "a finite number")
    low, high = info.low, info.high
    if (low is not None and value < low) or (high is not None and value > high):
        shown_low = "" if low is None else _number(low)
        shown_high = "" if high is None else _number(high)
        raise BadParameterError(what, text, f"a value in {shown_low}..{shown_high}")
    return value


def _number(value: float) -> str:
    return str(int(value)) if float(value).is_integer() else f"{value:.7g}"


def scaled(info: ParameterInfo, value: ParamValue) -> float | None:
    """The value in :attr:`ParameterInfo.unit` (None: not a number, or no scale)."""
    if isinstance(value, bool) or not isinstance(value, int | float) or info.scale == 1.0:
        return None
    return value * info.scale


def format_value(info: ParameterInfo, value: ParamValue) -> str:
    """``22``, ``100 (22.9 rpm)``, ``0.5 s``, ``true``, ``"ODrive"``, ``0a1b``."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, bytes):
        return value.hex() or "(empty)"
    if isinstance(value, str):
        return repr(value)
    shown = _number(value) if isinstance(value, float) else str(value)
    in_unit = scaled(info, value)
    if in_unit is not None:
        return f"{shown} ({in_unit:.6g} {info.unit})".replace(" )", ")")
    return f"{shown} {info.unit}" if info.unit else shown
