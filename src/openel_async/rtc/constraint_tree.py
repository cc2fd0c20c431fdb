"""The constraint tree of the RTC Profile spec and the typed values it checks.

The tree follows §2.3.17-2.3.41 of the spec (not/and/or, the ``propertyIs*``
comparisons, like, null, constraint lists and hashes).  Two nodes are ours:
``Enumeration`` (the spec writes an enumeration as ``or`` of ``propertyIsEqualTo``,
§8, but OpenRTM compares enumeration items as exact strings, which ``EqualTo`` on a
number does not) and the exclusive ranges of the text form, which are ``And`` of two
comparisons because the spec's ``propertyIsBetween`` is inclusive on both ends.

Values given to ``check`` are typed (bool, int, float, str, sequences, mappings,
``None`` for null).  A ``TypedValue`` carries a typed scalar together with the text it
was parsed from, so that numeric comparisons use the number while enumerations and
``like`` patterns use the text exactly as written.  The guarded parsers of literals
(``parse_int``, ``parse_number``, ``parse_bool``) live here too.

Re-exported by :mod:`openel_async.rtc.constraints`.
"""

from __future__ import annotations

import math
import re
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import ClassVar, TypeAlias, Union

__all__ = [
    "COMPARISONS",
    "MAX_INT_DIGITS",
    "NUMBER_LITERAL",
    "And",
    "Between",
    "Comparison",
    "Constraint",
    "ConstraintError",
    "Enumeration",
    "EqualTo",
    "GreaterThan",
    "GreaterThanOrEqualTo",
    "HashConstraint",
    "IsNull",
    "LessThan",
    "LessThanOrEqualTo",
    "Like",
    "ListConstraint",
    "Not",
    "NotEqualTo",
    "Or",
    "Scalar",
    "TypedValue",
    "Value",
    "is_unit",
    "parse_bool",
    "parse_int",
    "parse_number",
    "scalar_text",
]

Scalar: TypeAlias = bool | int | float | str
Value: TypeAlias = Union[Scalar, "TypedValue", Sequence["Value"], Mapping[str, "Value"], None]


class ConstraintError(ValueError):
    """An invalid constraint; ``path`` names where it is (empty when not applicable)."""

    def __init__(self, message: str, path: str = "") -> None:
        super().__init__(f"{path}: {message}" if path else message)
        self.path = path
        self.message = message


@dataclass(frozen=True)
class TypedValue:
    """A scalar plus the exact text it came from (enumerations compare the text)."""

    value: Scalar
    text: str


# --- value helpers -----------------------------------------------------------------

NUMBER_LITERAL = re.compile(r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?")
"""A decimal number literal (the text form's numbers, ``parse_number``'s syntax)."""
_INTEGER = re.compile(r"[+-]?\d+")
_TRUE_WORDS = frozenset({"true", "1", "yes", "on"})
_FALSE_WORDS = frozenset({"false", "0", "no", "off"})


# Python refuses to convert decimal strings of more than 4300 digits to int
# (sys.int_info.default_max_str_digits); stay below that everywhere.
MAX_INT_DIGITS = 4000


def parse_int(text: str) -> int | None:
    """The integer a decimal literal denotes, or None (also for more than
    ``MAX_INT_DIGITS`` significant digits: such text is refused, never a crash)."""
    s = text.strip()
    if not _INTEGER.fullmatch(s):
        return None
    if len(s.lstrip("+-").lstrip("0")) > MAX_INT_DIGITS:
        return None
    return int(s)


def parse_number(text: str) -> int | float | None:
    """The number a literal denotes (decimal notation only), or None.

    The one guarded number parser of profiles, constraints and configuration: an
    integer literal too long for ``int`` (more than ``MAX_INT_DIGITS`` digits) is read
    as a float (``inf`` for such magnitudes), so comparisons stay correct and nothing
    raises.
    """
    s = text.strip()
    if _INTEGER.fullmatch(s):
        value = parse_int(s)
        return value if value is not None else float(s)
    if NUMBER_LITERAL.fullmatch(s):
        return float(s)
    return None


def parse_bool(text: str) -> bool | None:
    """true/false, 1/0, yes/no, on/off in any case; None for anything else."""
    s = text.strip().lower()
    if s in _TRUE_WORDS:
        return True
    if s in _FALSE_WORDS:
        return False
    return None


def scalar_text(value: Scalar) -> str:
    """Canonical text of a typed scalar (bools as ``true``/``false``)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    return str(value)


def _scalar(value: Value) -> Scalar | None:
    if isinstance(value, TypedValue):
        return value.value
    if isinstance(value, bool | int | float | str):
        return value
    return None


def _text(value: Value) -> str | None:
    if isinstance(value, TypedValue):
        return value.text
    if isinstance(value, bool | int | float | str):
        return scalar_text(value)
    return None


def _each(value: Value, predicate: Callable[[Value], bool]) -> bool:
    """Apply a scalar predicate; on a sequence every element must satisfy it."""
    if isinstance(value, Mapping):
        return False
    if isinstance(value, Sequence) and not isinstance(value, str):
        return all(_each(item, predicate) for item in value)
    return predicate(value)


def _order(value: Value, literal: str, match_case: bool) -> int | None:
    """-1, 0 or 1 comparing value to literal; None when they are not comparable."""
    v = _scalar(value)
    if v is None:
        return None
    if isinstance(v, bool):
        b = parse_bool(literal)
        return None if b is None else (v > b) - (v < b)
    if isinstance(v, int | float):
        n = parse_number(literal)
        if n is None or math.isnan(v):
            return None
        return (v > n) - (v < n)
    a, b2 = (v, literal) if match_case else (v.casefold(), literal.casefold())
    return (a > b2) - (a < b2)


# --- the tree ----------------------------------------------------------------------


class Constraint(ABC):
    """Root of the constraint tree (constraint_type)."""

    __slots__ = ()

    @abstractmethod
    def check(self, value: Value) -> bool:
        """True when the value satisfies the constraint."""


@dataclass(frozen=True)
class Comparison(Constraint):
    """binary_comparison_op_type: a literal and the matchCase flag (the base of the six
    ``COMPARISONS``; ``op`` is its text-form operator, ``yaml_name`` its element name)."""

    literal: str
    match_case: bool = True

    op: ClassVar[str] = ""
    yaml_name: ClassVar[str] = ""

    def _accepts(self, order: int | None) -> bool:
        raise NotImplementedError

    def check(self, value: Value) -> bool:
        return _each(value, lambda v: self._accepts(_order(v, self.literal, self.match_case)))


@dataclass(frozen=True)
class EqualTo(Comparison):
    """property_is_equal_to; numbers compare numerically ("100.0" equals 100)."""

    op: ClassVar[str] = "=="
    yaml_name: ClassVar[str] = "propertyIsEqualTo"

    def _accepts(self, order: int | None) -> bool:
        return order == 0


@dataclass(frozen=True)
class NotEqualTo(Comparison):
    """property_is_not_equal_to: the negation of EqualTo (incomparable is not equal)."""

    op: ClassVar[str] = "!="
    yaml_name: ClassVar[str] = "propertyIsNotEqualTo"

    def _accepts(self, order: int | None) -> bool:
        return order != 0


@dataclass(frozen=True)
class LessThan(Comparison):
    """property_is_less_than (exclusive)."""

    op: ClassVar[str] = "<"
    yaml_name: ClassVar[str] = "propertyIsLessThan"

    def _accepts(self, order: int | None) -> bool:
        return order is not None and order < 0


@dataclass(frozen=True)
class GreaterThan(Comparison):
    """property_is_greater_than (exclusive)."""

    op: ClassVar[str] = ">"
    yaml_name: ClassVar[str] = "propertyIsGreaterThan"

    def _accepts(self, order: int | None) -> bool:
        return order is not None and order > 0


@dataclass(frozen=True)
class LessThanOrEqualTo(Comparison):
    """property_is_less_than_or_equal_to (inclusive)."""

    op: ClassVar[str] = "<="
    yaml_name: ClassVar[str] = "propertyIsLessThanOrEqualTo"

    def _accepts(self, order: int | None) -> bool:
        return order is not None and order <= 0


@dataclass(frozen=True)
class GreaterThanOrEqualTo(Comparison):
    """property_is_greater_than_or_equal_to (inclusive)."""

    op: ClassVar[str] = ">="
    yaml_name: ClassVar[str] = "propertyIsGreaterThanOrEqualTo"

    def _accepts(self, order: int | None) -> bool:
        return order is not None and order >= 0


COMPARISONS: tuple[type[Comparison], ...] = (
    EqualTo,
    NotEqualTo,
    LessThan,
    GreaterThan,
    LessThanOrEqualTo,
    GreaterThanOrEqualTo,
)


@dataclass(frozen=True)
class Between(Constraint):
    """property_is_between: lower <= value <= upper, both bounds included (§2.3.40)."""

    lower: str
    upper: str

    def check(self, value: Value) -> bool:
        def inside(v: Value) -> bool:
            lo = _order(v, self.lower, True)
            hi = _order(v, self.upper, True)
            return lo is not None and hi is not None and lo >= 0 and hi <= 0

        return _each(value, inside)


# Tokens of a like pattern: a literal character, or one of these markers.
_ANY = 0
_ONE = 1


def _glob(tokens: tuple[str | int, ...], text: str) -> bool:
    """Whole-string wildcard match in O(len(text) * len(tokens)), without the
    exponential backtracking a regex can hit on patterns like ``*a*a*a*b``."""
    t = s = 0
    star, mark = -1, 0
    while s < len(text):
        if t < len(tokens) and tokens[t] != _ANY and tokens[t] in (_ONE, text[s]):
            t, s = t + 1, s + 1
        elif t < len(tokens) and tokens[t] == _ANY:
            star, mark, t = t, s, t + 1
        elif star >= 0:
            mark += 1
            t, s = star + 1, mark
        else:
            return False
    while t < len(tokens) and tokens[t] == _ANY:
        t += 1
    return t == len(tokens)


@dataclass(frozen=True)
class Like(Constraint):
    """property_is_like: a whole-string pattern with wild, single and escape characters."""

    pattern: str
    wild_char: str = "*"
    single_char: str = "?"
    escape_char: str = "\\"
    _tokens: tuple[str | int, ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        chars = (self.wild_char, self.single_char, self.escape_char)
        if any(len(c) != 1 for c in chars):
            raise ConstraintError("wildCard, singleChar and escapeChar must be single characters")
        if len(set(chars)) != 3:
            raise ConstraintError("wildCard, singleChar and escapeChar must differ")
        object.__setattr__(self, "_tokens", self._tokenize())

    def _tokenize(self) -> tuple[str | int, ...]:
        tokens: list[str | int] = []
        chars = iter(self.pattern)
        for ch in chars:
            if ch == self.escape_char:
                escaped = next(chars, None)
                if escaped is None:
                    raise ConstraintError(
                        f"pattern {self.pattern!r} ends with the escape character"
                    )
                tokens.append(escaped)
            elif ch == self.wild_char:
                if not tokens or tokens[-1] != _ANY:  # "**" matches what "*" does
                    tokens.append(_ANY)
            elif ch == self.single_char:
                tokens.append(_ONE)
            else:
                tokens.append(ch)
        return tuple(tokens)

    def check(self, value: Value) -> bool:
        def match(v: Value) -> bool:
            text = _text(v)
            return text is not None and _glob(self._tokens, text)

        return _each(value, match)


@dataclass(frozen=True)
class IsNull(Constraint):
    """property_is_null: the value is absent (None), empty text, or an empty container."""

    def check(self, value: Value) -> bool:
        if value is None:
            return True
        if isinstance(value, Mapping):
            return not value
        if isinstance(value, Sequence) and not isinstance(value, str):
            return len(value) == 0
        return _text(value) == ""


def _children(node: Constraint, children: Sequence[Constraint], minimum: int) -> None:
    object.__setattr__(node, "children", tuple(children))
    if len(children) < minimum:
        raise ConstraintError(f"{type(node).__name__} needs at least {minimum} children")


@dataclass(frozen=True)
class Not(Constraint):
    """not: inverts its child."""

    child: Constraint

    def check(self, value: Value) -> bool:
        return not self.child.check(value)


@dataclass(frozen=True)
class And(Constraint):
    """and: every child holds (two or more children)."""

    children: tuple[Constraint, ...]

    def __post_init__(self) -> None:
        _children(self, self.children, 2)

    def check(self, value: Value) -> bool:
        return all(c.check(value) for c in self.children)


@dataclass(frozen=True)
class Or(Constraint):
    """or: some child holds (two or more children)."""

    children: tuple[Constraint, ...]

    def __post_init__(self) -> None:
        _children(self, self.children, 2)

    def check(self, value: Value) -> bool:
        return any(c.check(value) for c in self.children)


@dataclass(frozen=True)
class Enumeration(Constraint):
    """The value's text is one of ``values`` (exact strings; casefolded without match_case)."""

    values: tuple[str, ...]
    match_case: bool = True

    def __post_init__(self) -> None:
        object.__setattr__(self, "values", tuple(self.values))
        if not self.values:
            raise ConstraintError("an enumeration needs at least one value")

    def check(self, value: Value) -> bool:
        def member(v: Value) -> bool:
            text = _text(v)
            if text is None:
                return False
            if self.match_case:
                return text in self.values
            folded = text.casefold()
            return any(folded == item.casefold() for item in self.values)

        return _each(value, member)


@dataclass(frozen=True)
class ListConstraint(Constraint):
    """constraint_list_type: element i of a sequence value satisfies ``items[i]``.

    The value must have exactly ``len(items)`` elements (the spec orders the children
    one per value and says nothing about other lengths).
    """

    items: tuple[Constraint, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "items", tuple(self.items))
        if not self.items:
            raise ConstraintError("a constraint list needs at least one item")

    def check(self, value: Value) -> bool:
        if not isinstance(value, Sequence) or isinstance(value, str):
            return False
        if len(value) != len(self.items):
            return False
        return all(c.check(v) for c, v in zip(self.items, value, strict=True))


@dataclass(frozen=True)
class HashConstraint(Constraint):
    """constraint_hash_type: per-key constraints on a mapping value.

    A key missing from the value is checked as ``None`` (so only ``IsNull`` or ``Not``
    forms accept it); keys without a constraint are not checked.  Entry constraints
    must be unit constraints because the spec keeps the key on constraint_unit_type.
    """

    entries: tuple[tuple[str, Constraint], ...]

    def __post_init__(self) -> None:
        entries = tuple((k, c) for k, c in self.entries)
        object.__setattr__(self, "entries", entries)
        if not entries:
            raise ConstraintError("a constraint hash needs at least one entry")
        keys = [k for k, _ in entries]
        if len(set(keys)) != len(keys):
            raise ConstraintError("constraint hash keys must be unique")
        for key, c in entries:
            if isinstance(c, ListConstraint | HashConstraint):
                raise ConstraintError(f"hash entry {key!r} must be a unit constraint")

    def get(self, key: str) -> Constraint | None:
        """The constraint of a key, or None."""
        return dict(self.entries).get(key)

    def check(self, value: Value) -> bool:
        if not isinstance(value, Mapping):
            return False
        return all(c.check(value.get(k)) for k, c in self.entries)


def is_unit(c: Constraint) -> bool:
    """True for constraint_unit_type nodes (everything but lists and hashes)."""
    return not isinstance(c, ListConstraint | HashConstraint)
