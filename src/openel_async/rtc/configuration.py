"""Configuration sets: typed parameters with defaults, units and constraints.

A ``ParameterSpec`` is one configuration parameter of a component (the profile's
``configuration`` element).  A ``Configuration`` holds several named sets of values
for those parameters, one of them active, as OpenRTM's configuration sets do.  Values
are given as text (as in profiles and rtc.conf) or as Python values; text is parsed
with the parameter's type, and a value that is not of the type or violates the
constraint is refused with ``ConfigurationError`` and the previous value stays.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from enum import Enum
from types import MappingProxyType
from typing import TypeAlias

from .constraints import (
    Constraint,
    HashConstraint,
    ListConstraint,
    Scalar,
    TypedValue,
    Value,
    describe,
    parse_bool,
    parse_constraint,
    parse_int,
    parse_number,
    scalar_text,
)
from .profile.model import ConfigurationProfile, ConfigurationSetProfile, RtcProfile

__all__ = [
    "DEFAULT_SET",
    "ConfigValue",
    "Configuration",
    "ConfigurationError",
    "Container",
    "ParamType",
    "ParameterSpec",
    "ParsedValue",
    "ScalarKind",
]

ConfigValue: TypeAlias = Scalar | list[Scalar] | dict[str, Scalar]

DEFAULT_SET = "default"


class ConfigurationError(ValueError):
    """A refused configuration operation; names the parameter, value and constraint."""

    def __init__(
        self,
        message: str,
        *,
        parameter: str | None = None,
        value: object = None,
        constraint: str | None = None,
    ) -> None:
        super().__init__(message)
        self.parameter = parameter
        self.value = value
        self.constraint = constraint


# --- types -------------------------------------------------------------------------


class ScalarKind(Enum):
    """The element kind of a parameter type."""

    INTEGER = "integer"
    FLOAT = "float"
    STRING = "string"
    BOOLEAN = "boolean"
    CHAR = "char"


class Container(Enum):
    """Scalar, comma-separated sequence (``vector<T>``) or ``key:value`` map."""

    SCALAR = "scalar"
    SEQUENCE = "sequence"
    MAP = "map"


# name -> (kind, bits, signed); names are matched lower-cased without "std::".
_SCALARS: dict[str, tuple[ScalarKind, int, bool]] = {
    "short": (ScalarKind.INTEGER, 16, True),
    "unsigned short": (ScalarKind.INTEGER, 16, False),
    "int": (ScalarKind.INTEGER, 32, True),
    "unsigned int": (ScalarKind.INTEGER, 32, False),
    "long": (ScalarKind.INTEGER, 32, True),  # IDL long is 32-bit
    "unsigned long": (ScalarKind.INTEGER, 32, False),
    "long long": (ScalarKind.INTEGER, 64, True),
    "unsigned long long": (ScalarKind.INTEGER, 64, False),
    "octet": (ScalarKind.INTEGER, 8, False),
    "float": (ScalarKind.FLOAT, 32, True),
    "double": (ScalarKind.FLOAT, 64, True),
    "string": (ScalarKind.STRING, 0, False),
    "boolean": (ScalarKind.BOOLEAN, 0, False),
    "bool": (ScalarKind.BOOLEAN, 0, False),
    "char": (ScalarKind.CHAR, 0, False),
}
_SEQUENCE = re.compile(r"(?:vector|sequence)\s*<\s*(.+?)\s*>")
_MAP = re.compile(r"map\s*<\s*string\s*,\s*(.+?)\s*>")
_INT = re.compile(r"[+-]?\d+")


def _clip(value: object) -> str:
    """repr of a value for a one-line message (long text clipped)."""
    text = repr(value)
    return text if len(text) <= 80 else text[:80] + "..."


_FLOAT_WORDS = frozenset({"inf", "+inf", "-inf", "infinity", "+infinity", "-infinity", "nan"})
_FLOAT32_MAX = 3.4028234663852886e38


@dataclass(frozen=True)
class ParamType:
    """A parsed parameter type such as ``double``, ``vector<long>`` or ``std::string``."""

    name: str
    kind: ScalarKind
    container: Container = Container.SCALAR
    bits: int = 0
    signed: bool = True

    @classmethod
    def parse(cls, name: str) -> ParamType:
        """Parse a type name; raises ValueError for unsupported types."""
        norm = " ".join(name.replace("std::", "").lower().split())
        container = Container.SCALAR
        inner = norm
        if m := _SEQUENCE.fullmatch(norm):
            container, inner = Container.SEQUENCE, m.group(1)
        elif m := _MAP.fullmatch(norm):
            container, inner = Container.MAP, m.group(1)
        spec = _SCALARS.get(inner)
        if spec is None:
            raise ValueError(f"unsupported parameter type {name!r}")
        kind, bits, signed = spec
        return cls(name, kind, container, bits, signed)

    def parse_scalar(self, text: str) -> Scalar:
        """One element from its text; raises ValueError naming what was expected."""
        kind = self.kind
        if kind is ScalarKind.STRING:
            return text
        if kind is ScalarKind.CHAR:
            if len(text) != 1:
                raise ValueError("expected a single character")
            return text
        if kind is ScalarKind.BOOLEAN:
            flag = parse_bool(text)
            if flag is None:
                raise ValueError("expected true/false, 1/0, yes/no or on/off")
            return flag
        s = text.strip()
        if kind is ScalarKind.INTEGER:
            if not _INT.fullmatch(s):
                raise ValueError("expected an integer")
            integer = parse_int(s)
            if integer is None:  # more digits than any integer type holds
                raise ValueError(f"out of range for a {self.bits}-bit integer")
            return self._in_range(integer)
        if parse_number(s) is None and s.lower() not in _FLOAT_WORDS:
            raise ValueError("expected a number")
        number = float(s)
        if self.bits == 32 and math.isfinite(number) and abs(number) > _FLOAT32_MAX:
            raise ValueError("out of range for a 32-bit float")
        return number

    def _in_range(self, number: int) -> int:
        low, high = (
            (-(2 ** (self.bits - 1)), 2 ** (self.bits - 1) - 1)
            if self.signed
            else (0, 2**self.bits - 1)
        )
        if not low <= number <= high:
            raise ValueError(f"out of range {low}..{high}")
        return number

    def scalar_to_text(self, value: object) -> str:
        """Text of a Python value of this element type; raises ValueError otherwise."""
        kind = self.kind
        ok = {
            ScalarKind.INTEGER: isinstance(value, int) and not isinstance(value, bool),
            ScalarKind.FLOAT: isinstance(value, int | float) and not isinstance(value, bool),
            ScalarKind.BOOLEAN: isinstance(value, bool),
            ScalarKind.STRING: isinstance(value, str),
            ScalarKind.CHAR: isinstance(value, str),
        }[kind]
        if not ok:
            raise ValueError(f"expected a {kind.value} value, got {type(value).__name__}")
        assert isinstance(value, bool | int | float | str)
        text = scalar_text(value)
        if self.container is not Container.SCALAR and ("," in text or text != text.strip()):
            raise ValueError(f"element {text!r} cannot be written in the comma-separated form")
        return text

    def to_text(self, value: object) -> str:
        """Text form of a Python value (text is returned unchanged)."""
        if isinstance(value, str):
            return value
        if self.container is Container.SCALAR:
            return self.scalar_to_text(value)
        if self.container is Container.SEQUENCE and isinstance(value, Sequence):
            return ",".join(self.scalar_to_text(v) for v in value)
        if self.container is Container.MAP and isinstance(value, Mapping):
            return ",".join(f"{k}:{self.scalar_to_text(v)}" for k, v in value.items())
        raise ValueError(f"expected a {self.container.value} value, got {type(value).__name__}")

    def parse_text(self, text: str) -> tuple[ConfigValue, Value]:
        """(Python value, constraint operand) of a text value."""
        if self.container is Container.SCALAR:
            scalar = self.parse_scalar(text)
            return scalar, TypedValue(scalar, self._operand_text(text))
        parts = [] if not text.strip() else [p.strip() for p in text.split(",")]
        if self.container is Container.SEQUENCE:
            values = [self.parse_scalar(p) for p in parts]
            return values, [TypedValue(v, p) for v, p in zip(values, parts, strict=True)]
        pairs: dict[str, Scalar] = {}
        operands: dict[str, Value] = {}
        for part in parts:
            key, sep, item = part.partition(":")
            key, item = key.strip(), item.strip()
            if not sep or not key:
                raise ValueError(f"expected key:value, got {part!r}")
            if key in pairs:
                raise ValueError(f"duplicate key {key!r}")
            pairs[key] = self.parse_scalar(item)
            operands[key] = TypedValue(pairs[key], item)
        return pairs, operands

    def _operand_text(self, text: str) -> str:
        # Enumerations compare text exactly; surrounding blanks of a number are not text.
        return text if self.kind in (ScalarKind.STRING, ScalarKind.CHAR) else text.strip()


# --- parameters --------------------------------------------------------------------


@dataclass(frozen=True)
class ParsedValue:
    """A validated value: its text, the Python value and the constraint operand."""

    text: str
    value: ConfigValue
    operand: Value = field(compare=False)


@dataclass(frozen=True)
class ParameterSpec:
    """One configuration parameter: name, type, default text, constraint and unit."""

    name: str
    type: str
    default: str
    constraint: Constraint | None = None
    unit: str | None = None
    param_type: ParamType = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        try:
            ptype = ParamType.parse(self.type)
        except ValueError as e:
            raise ConfigurationError(f"parameter {self.name!r}: {e}", parameter=self.name) from None
        object.__setattr__(self, "param_type", ptype)
        c = self.constraint
        problem = None
        if isinstance(c, ListConstraint) and ptype.container is not Container.SEQUENCE:
            problem = "a per-element list constraint needs a sequence type"
        elif isinstance(c, HashConstraint) and ptype.container is not Container.MAP:
            problem = "a hash constraint needs a map type"
        elif (
            c is not None and not isinstance(c, HashConstraint) and ptype.container is Container.MAP
        ):
            problem = "a map type needs a hash constraint"
        if problem:
            raise ConfigurationError(
                f"parameter {self.name!r}: {problem} (type {self.type!r})",
                parameter=self.name,
                constraint=self.constraint_text,
            )

    @classmethod
    def from_text(
        cls, name: str, type: str, default: str, constraint: str = "", unit: str | None = None
    ) -> ParameterSpec:
        """A parameter whose constraint is given in OpenRTM's text form ("" for none)."""
        tree = parse_constraint(constraint) if constraint.strip() else None
        return cls(name, type, default, tree, unit)

    @classmethod
    def from_profile(cls, profile: ConfigurationProfile) -> ParameterSpec:
        """The parameter described by a profile's ``configuration`` element."""
        return cls(
            profile.name, profile.type, profile.default_value, profile.constraint, profile.unit
        )

    @property
    def constraint_text(self) -> str | None:
        """The constraint as text (the exact text form when it has one)."""
        return None if self.constraint is None else describe(self.constraint)

    def parse(self, value: object, *, check_constraint: bool = True) -> ParsedValue:
        """Convert a text or Python value; raises ConfigurationError when it is not of
        the type or (unless told not to check) violates the constraint."""
        try:
            text = self.param_type.to_text(value)
            parsed, operand = self.param_type.parse_text(text)
        except ValueError as e:
            raise ConfigurationError(
                f"parameter {self.name!r}: value {_clip(value)} is not a valid {self.type}: {e}",
                parameter=self.name,
                value=value,
                constraint=self.constraint_text,
            ) from None
        if check_constraint and self.constraint is not None and not self.constraint.check(operand):
            raise ConfigurationError(
                f"parameter {self.name!r}: value {_clip(value)} violates constraint "
                f"{_clip(self.constraint_text)}",
                parameter=self.name,
                value=value,
                constraint=self.constraint_text,
            )
        return ParsedValue(text, parsed, operand)

    def check(self, value: object) -> bool:
        """True when the value is of the type and satisfies the constraint."""
        try:
            self.parse(value)
        except ConfigurationError:
            return False
        return True


def _in_context(context: str, error: ConfigurationError) -> ConfigurationError:
    return ConfigurationError(
        f"{context}: {error}",
        parameter=error.parameter,
        value=error.value,
        constraint=error.constraint,
    )


def _copy(value: ConfigValue) -> ConfigValue:
    if isinstance(value, list):
        return list(value)
    if isinstance(value, dict):
        return dict(value)
    return value


class Configuration:
    """Named sets of parameter values with one active set.

    The ``default`` set holds the parameters' defaults; other sets start as a copy of
    a base set.  Changes are validated before they are applied, so a refused change
    leaves every set as it was.
    """

    def __init__(self, parameters: Iterable[ParameterSpec], *, check_defaults: bool = True):
        self._params: dict[str, ParameterSpec] = {}
        for spec in parameters:
            if spec.name in self._params:
                raise ConfigurationError(f"duplicate parameter {spec.name!r}", parameter=spec.name)
            self._params[spec.name] = spec
        # Type errors in defaults always fail; constraint checks can be relaxed for
        # profiles whose defaults break their own constraints (the spec's §9 sample).
        defaults: dict[str, ParsedValue] = {}
        for name, spec in self._params.items():
            try:
                defaults[name] = spec.parse(spec.default, check_constraint=check_defaults)
            except ConfigurationError as e:
                raise _in_context("default value", e) from None
        self._sets: dict[str, dict[str, ParsedValue]] = {DEFAULT_SET: defaults}
        self._active = DEFAULT_SET

    @classmethod
    def from_profile(
        cls,
        profile: RtcProfile | ConfigurationSetProfile | None,
        *,
        check_defaults: bool = True,
    ) -> Configuration:
        """The configuration described by a profile (no parameters without a set)."""
        if isinstance(profile, RtcProfile):
            configs = profile.configurations
        else:
            configs = profile.configurations if profile is not None else ()
        specs = [ParameterSpec.from_profile(c) for c in configs]
        return cls(specs, check_defaults=check_defaults)

    @property
    def parameters(self) -> Mapping[str, ParameterSpec]:
        """The parameters by name."""
        return MappingProxyType(self._params)

    @property
    def set_names(self) -> tuple[str, ...]:
        """Names of the configuration sets, ``default`` first."""
        return tuple(self._sets)

    @property
    def active_set(self) -> str:
        """Name of the active set."""
        return self._active

    def _set(self, name: str) -> dict[str, ParsedValue]:
        values = self._sets.get(name)
        if values is None:
            raise ConfigurationError(f"unknown configuration set {name!r}")
        return values

    def _spec(self, param: str) -> ParameterSpec:
        spec = self._params.get(param)
        if spec is None:
            raise ConfigurationError(f"unknown parameter {param!r}", parameter=param)
        return spec

    def add_set(
        self, name: str, values: Mapping[str, object] | None = None, *, base: str = DEFAULT_SET
    ) -> None:
        """Create a set as a copy of ``base`` with some values replaced."""
        if not name:
            raise ConfigurationError("a configuration set needs a name")
        if name in self._sets:
            raise ConfigurationError(f"configuration set {name!r} already exists")
        new = dict(self._set(base))
        for param, value in (values or {}).items():
            try:
                new[param] = self._spec(param).parse(value)
            except ConfigurationError as e:
                raise _in_context(f"set {name!r}", e) from None
        self._sets[name] = new

    def remove_set(self, name: str) -> None:
        """Remove a set other than ``default`` and the active one."""
        self._set(name)
        if name == DEFAULT_SET or name == self._active:
            raise ConfigurationError(f"cannot remove the {name!r} set (default or active)")
        del self._sets[name]

    def activate_set(self, name: str) -> None:
        """Make ``name`` the active set."""
        self._set(name)
        self._active = name

    def set_value(self, set_name: str, param: str, value: object) -> None:
        """Set one value (text or Python value); refused values change nothing."""
        values = self._set(set_name)
        try:
            entry = self._spec(param).parse(value)
        except ConfigurationError as e:
            raise _in_context(f"set {set_name!r}", e) from None
        values[param] = entry

    def get(self, param: str, set_name: str | None = None) -> ConfigValue:
        """The typed value of a parameter in the active (or given) set."""
        self._spec(param)
        return _copy(self._set(set_name or self._active)[param].value)

    def get_text(self, param: str, set_name: str | None = None) -> str:
        """The text form of a parameter's value."""
        self._spec(param)
        return self._set(set_name or self._active)[param].text

    def values(self, set_name: str | None = None) -> dict[str, ConfigValue]:
        """All typed values of the active (or given) set."""
        return {k: _copy(e.value) for k, e in self._set(set_name or self._active).items()}

    def texts(self, set_name: str | None = None) -> dict[str, str]:
        """All values of the active (or given) set as text."""
        return {k: e.text for k, e in self._set(set_name or self._active).items()}
