"""Constraint tree of the RTC Profile spec and OpenRTM's text form of constraints.

The tree follows §2.3.17-2.3.41 of the spec (not/and/or, the ``propertyIs*``
comparisons, like, null, constraint lists and hashes).  Two nodes are ours:
``Enumeration`` (the spec writes an enumeration as ``or`` of ``propertyIsEqualTo``,
§8, but OpenRTM compares enumeration items as exact strings, which ``EqualTo`` on a
number does not) and the exclusive ranges of the text form, which are ``And`` of two
comparisons because the spec's ``propertyIsBetween`` is inclusive on both ends.

Values given to ``check`` are typed (bool, int, float, str, sequences, mappings,
``None`` for null).  A ``TypedValue`` carries a typed scalar together with the text it
was parsed from, so that numeric comparisons use the number while enumerations and
``like`` patterns use the text exactly as written.
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import ClassVar, TypeAlias, Union

__all__ = [
    "COMPARISONS",
    "MAX_DEPTH",
    "MAX_INT_DIGITS",
    "RTC_NS",
    "And",
    "Between",
    "Constraint",
    "ConstraintError",
    "ConstraintFormatError",
    "ConstraintSyntaxError",
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
    "constraint_from_xml",
    "constraint_from_yaml",
    "constraint_to_xml",
    "constraint_to_yaml",
    "describe",
    "format_constraint",
    "is_unit",
    "parse_bool",
    "parse_constraint",
    "parse_int",
    "parse_number",
    "scalar_text",
]

RTC_NS = "http://www.openrtp.org/namespaces/rtc"

Scalar: TypeAlias = bool | int | float | str
Value: TypeAlias = Union[Scalar, "TypedValue", Sequence["Value"], Mapping[str, "Value"], None]

# Deeper trees than this are refused by the YAML/XML readers (no legitimate profile
# nests that far; it keeps hostile input from exhausting the stack).
MAX_DEPTH = 64


class ConstraintError(ValueError):
    """An invalid constraint; ``path`` names where it is (empty when not applicable)."""

    def __init__(self, message: str, path: str = "") -> None:
        super().__init__(f"{path}: {message}" if path else message)
        self.path = path
        self.message = message


_SHOWN = 80  # characters of a bad constraint text quoted in its error message


class ConstraintSyntaxError(ConstraintError):
    """The text form could not be parsed; ``position`` is a 0-based index into ``text``."""

    def __init__(self, text: str, position: int, expected: str, problem: str | None = None) -> None:
        found = repr(text[position]) if position < len(text) else "end of input"
        detail = problem if problem is not None else f"expected {expected}, got {found}"
        shown = text if len(text) <= _SHOWN else text[:_SHOWN] + "..."
        super().__init__(f"invalid constraint {shown!r}: position {position}: {detail}")
        self.text = text
        self.position = position
        self.expected = expected


class ConstraintFormatError(ConstraintError):
    """The tree has no exact text form (e.g. ``like``, ``not``, case-insensitive compare)."""


@dataclass(frozen=True)
class TypedValue:
    """A scalar plus the exact text it came from (enumerations compare the text)."""

    value: Scalar
    text: str


# --- value helpers -----------------------------------------------------------------

_NUMBER = re.compile(r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?")
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
    if _NUMBER.fullmatch(s):
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
class _Comparison(Constraint):
    """binary_comparison_op_type: a literal and the matchCase flag."""

    literal: str
    match_case: bool = True

    op: ClassVar[str] = ""
    yaml_name: ClassVar[str] = ""

    def _accepts(self, order: int | None) -> bool:
        raise NotImplementedError

    def check(self, value: Value) -> bool:
        return _each(value, lambda v: self._accepts(_order(v, self.literal, self.match_case)))


@dataclass(frozen=True)
class EqualTo(_Comparison):
    """property_is_equal_to; numbers compare numerically ("100.0" equals 100)."""

    op: ClassVar[str] = "=="
    yaml_name: ClassVar[str] = "propertyIsEqualTo"

    def _accepts(self, order: int | None) -> bool:
        return order == 0


@dataclass(frozen=True)
class NotEqualTo(_Comparison):
    """property_is_not_equal_to: the negation of EqualTo (incomparable is not equal)."""

    op: ClassVar[str] = "!="
    yaml_name: ClassVar[str] = "propertyIsNotEqualTo"

    def _accepts(self, order: int | None) -> bool:
        return order != 0


@dataclass(frozen=True)
class LessThan(_Comparison):
    """property_is_less_than (exclusive)."""

    op: ClassVar[str] = "<"
    yaml_name: ClassVar[str] = "propertyIsLessThan"

    def _accepts(self, order: int | None) -> bool:
        return order is not None and order < 0


@dataclass(frozen=True)
class GreaterThan(_Comparison):
    """property_is_greater_than (exclusive)."""

    op: ClassVar[str] = ">"
    yaml_name: ClassVar[str] = "propertyIsGreaterThan"

    def _accepts(self, order: int | None) -> bool:
        return order is not None and order > 0


@dataclass(frozen=True)
class LessThanOrEqualTo(_Comparison):
    """property_is_less_than_or_equal_to (inclusive)."""

    op: ClassVar[str] = "<="
    yaml_name: ClassVar[str] = "propertyIsLessThanOrEqualTo"

    def _accepts(self, order: int | None) -> bool:
        return order is not None and order <= 0


@dataclass(frozen=True)
class GreaterThanOrEqualTo(_Comparison):
    """property_is_greater_than_or_equal_to (inclusive)."""

    op: ClassVar[str] = ">="
    yaml_name: ClassVar[str] = "propertyIsGreaterThanOrEqualTo"

    def _accepts(self, order: int | None) -> bool:
        return order is not None and order >= 0


COMPARISONS: tuple[type[_Comparison], ...] = (
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


# --- text form ---------------------------------------------------------------------

_LITERAL_STOP = frozenset(",(){}<>=:")
_ITEM_STOP = frozenset(",(){}")
_UPPER_OPS = {"<": LessThan, "<=": LessThanOrEqualTo}
_LOWER_OPS = {"<": GreaterThan, "<=": GreaterThanOrEqualTo}
_ASCENDING = ("<", "<=")
_DESCENDING = (">", ">=", "=>")
# A descending operator as the ascending one with the sides swapped.
_FLIP = {">": "<", ">=": "<=", "=>": "<="}
_X_OPS: dict[str, type[_Comparison]] = {
    "<": LessThan,
    "<=": LessThanOrEqualTo,
    ">": GreaterThan,
    ">=": GreaterThanOrEqualTo,
}


def _clip(text: str) -> str:
    return text if len(text) <= _SHOWN else text[:_SHOWN] + "..."


class _Parser:
    def __init__(self, text: str) -> None:
        self.text = text
        self.pos = 0

    def error(self, expected: str, problem: str | None = None) -> ConstraintSyntaxError:
        return ConstraintSyntaxError(self.text, self.pos, expected, problem)

    def peek(self) -> str:
        return self.text[self.pos : self.pos + 1]

    def ws_end(self, pos: int) -> int:
        while pos < len(self.text) and self.text[pos].isspace():
            pos += 1
        return pos

    def skip_ws(self) -> None:
        self.pos = self.ws_end(self.pos)

    def read_until(self, stops: frozenset[str]) -> str:
        start = self.pos
        while self.pos < len(self.text) and self.text[self.pos] not in stops:
            self.pos += 1
        return self.text[start : self.pos].strip()

    def read_op(self, allowed: Sequence[str]) -> str:
        two = self.text[self.pos : self.pos + 2]
        op = two if two in ("<=", ">=", "=>") else self.peek()
        if op not in allowed:
            raise self.error(" or ".join(repr(a) for a in allowed))
        self.pos += len(op)
        return op

    def read_number(self) -> str:
        m = _NUMBER.match(self.text, self.pos)
        if m is None:
            raise self.error("a number")
        self.pos = m.end()
        return m.group()

    def parse(self) -> Constraint:
        self.skip_ws()
        result: Constraint
        if self.peek() == "{":
            result = self.parse_hash()
            expected = "end of input"
        else:
            units = [self.parse_unit()]
            self.skip_ws()
            while self.peek() == ",":
                self.pos += 1
                units.append(self.parse_unit())
                self.skip_ws()
            result = units[0] if len(units) == 1 else ListConstraint(tuple(units))
            expected = "',' or end of input"
        self.skip_ws()
        if self.pos < len(self.text):
            raise self.error(expected)
        return result

    def parse_unit(self) -> Constraint:
        self.skip_ws()
        if self.peek() == "(":
            return self.parse_enumeration()
        if self.peek() == "x" and self.text[self.ws_end(self.pos + 1) :][:1] in ("<", ">"):
            return self.parse_comparison()
        number = _NUMBER.match(self.text, self.pos)
        if number is not None:
            after = self.text[self.ws_end(number.end()) :][:2]
            if after[:1] in ("<", ">") or after == "=>":
                return self.parse_range(number.group())
        literal = self.read_until(_LITERAL_STOP)
        if not literal:
            raise self.error("a constraint (a value, 'x<op>number', 'a<x<b' or '(a,b,...)')")
        if literal == "x":
            self.skip_ws()
            raise self.error("'<', '<=', '>' or '>=' after 'x'")
        return EqualTo(literal)

    def parse_comparison(self) -> Constraint:
        self.pos += 1
        self.skip_ws()
        op = self.read_op(list(_X_OPS))
        self.skip_ws()
        return _X_OPS[op](self.read_number())

    def parse_range(self, first: str) -> Constraint:
        """``a<x``, ``a<=x``, ``a<x<b`` ... (ascending) or ``a>x``, ``a>=x``, ``a=>x``,
        ``a>x>b`` ... (descending, as OpenRTP reads them)."""
        start = self.pos
        self.pos += len(first)
        self.skip_ws()
        op1 = self.read_op(["<", "<=", ">", ">=", "=>"])
        ascending = op1 in _ASCENDING
        self.skip_ws()
        if self.peek() != "x":
            raise self.error("'x'")
        self.pos += 1
        self.skip_ws()
        follow = _ASCENDING if ascending else _DESCENDING
        two = self.text[self.pos : self.pos + 2]
        if self.peek() not in follow and two not in follow:
            # One bound only: "a<x" is x > a, "a>x" is x < a.
            if ascending:
                return _LOWER_OPS[op1](first)
            return _UPPER_OPS[_FLIP[op1]](first)
        op2 = self.read_op(list(follow))
        self.skip_ws()
        second = self.read_number()
        if ascending:
            lower, low_op, upper, high_op = first, op1, second, op2
        else:
            lower, low_op, upper, high_op = second, _FLIP[op2], first, _FLIP[op1]
        lo, hi = parse_number(lower), parse_number(upper)
        if lo is not None and hi is not None and lo > hi:
            self.pos = start
            raise self.error(
                "a range",
                f"lower bound {_clip(lower)} is greater than upper bound {_clip(upper)}",
            )
        if low_op == "<=" and high_op == "<=":
            return Between(lower, upper)
        if ascending:
            return And((_LOWER_OPS[low_op](lower), _UPPER_OPS[high_op](upper)))
        # OpenRTP keeps the written order: "100>x>0" is x<100 and x>0.
        return And((_UPPER_OPS[high_op](upper), _LOWER_OPS[low_op](lower)))

    def parse_enumeration(self) -> Constraint:
        self.pos += 1
        items: list[str] = []
        while True:
            item = self.read_until(_ITEM_STOP)
            if not item:
                raise self.error("an enumeration item")
            items.append(item)
            if self.peek() == ",":
                self.pos += 1
            elif self.peek() == ")":
                self.pos += 1
                return Enumeration(tuple(items))
            else:
                raise self.error("',' or ')'")

    def parse_hash(self) -> Constraint:
        self.pos += 1
        entries: list[tuple[str, Constraint]] = []
        while True:
            self.skip_ws()
            key_pos = self.pos
            key = self.read_until(_LITERAL_STOP)
            if not key:
                raise self.error("a hash key")
            if any(key == k for k, _ in entries):
                self.pos = key_pos
                raise self.error("a new key", f"duplicate hash key {key!r}")
            if self.peek() != ":":
                raise self.error("':' after the hash key")
            self.pos += 1
            entries.append((key, self.parse_unit()))
            self.skip_ws()
            if self.peek() == ",":
                self.pos += 1
            elif self.peek() == "}":
                self.pos += 1
                return HashConstraint(tuple(entries))
            else:
                raise self.error("',' or '}'")


def parse_constraint(text: str) -> Constraint:
    """Parse OpenRTM's text form (``100``, ``x>=100``, ``100<=x<=200``, ``(a,b)``,
    ``c0, c1``, ``{k0: c0, k1: c1}``); raises ConstraintSyntaxError."""
    return _Parser(text).parse()


def _format_unit(c: Constraint) -> str:
    if isinstance(c, EqualTo) and c.match_case:
        return c.literal
    if isinstance(c, LessThan | LessThanOrEqualTo | GreaterThan | GreaterThanOrEqualTo):
        return f"x{c.op}{c.literal}"
    if isinstance(c, Between):
        return f"{c.lower}<=x<={c.upper}"
    if isinstance(c, Enumeration) and c.match_case:
        return "(" + ",".join(c.values) + ")"
    if isinstance(c, And) and len(c.children) == 2:
        low, high = c.children
        if isinstance(low, GreaterThan | GreaterThanOrEqualTo) and isinstance(
            high, LessThan | LessThanOrEqualTo
        ):
            low_op = "<" if isinstance(low, GreaterThan) else "<="
            return f"{low.literal}{low_op}x{high.op}{high.literal}"
        high, low = c.children
        if isinstance(high, LessThan | LessThanOrEqualTo) and isinstance(
            low, GreaterThan | GreaterThanOrEqualTo
        ):
            high_op = ">" if isinstance(high, LessThan) else ">="
            return f"{high.literal}{high_op}x{low.op}{low.literal}"
    raise ConstraintFormatError(f"{_describe(c)} has no text form")


def format_constraint(c: Constraint) -> str:
    """The text form of a tree; raises ConstraintFormatError unless parsing the text
    gives back exactly this tree (so the text form never silently changes meaning)."""
    if isinstance(c, HashConstraint):
        text = "{" + ", ".join(f"{k}: {_format_unit(v)}" for k, v in c.entries) + "}"
    elif isinstance(c, ListConstraint):
        text = ", ".join(_format_unit(item) for item in c.items)
    else:
        text = _format_unit(c)
    try:
        back = parse_constraint(text)
    except ConstraintSyntaxError:
        back = None
    if back != c:
        raise ConstraintFormatError(f"{_describe(c)} has no exact text form")
    return text


def _describe(c: Constraint) -> str:
    fold = "" if getattr(c, "match_case", True) else " (ignoring case)"
    if isinstance(c, _Comparison):
        # Case cannot matter against a number: keep the message readable.
        return f"x{c.op}{c.literal}" + ("" if parse_number(c.literal) is not None else fold)
    if isinstance(c, Between):
        return f"{c.lower}<=x<={c.upper}"
    if isinstance(c, Enumeration):
        return "(" + ",".join(c.values) + ")" + fold
    if isinstance(c, Like):
        return f"x like {c.pattern!r}"
    if isinstance(c, IsNull):
        return "x is null"
    if isinstance(c, Not):
        return f"not ({_describe(c.child)})"
    if isinstance(c, And | Or):
        joiner = " and " if isinstance(c, And) else " or "
        return joiner.join(f"({_describe(ch)})" for ch in c.children)
    if isinstance(c, ListConstraint):
        return ", ".join(_describe(i) for i in c.items)
    if isinstance(c, HashConstraint):
        return "{" + ", ".join(f"{k}: {_describe(v)}" for k, v in c.entries) + "}"
    return type(c).__name__


def describe(c: Constraint) -> str:
    """Human-readable text: the exact text form when there is one, else a readable
    rendering (``not (x is null)``, ``x like 'a*'``) for messages."""
    try:
        return format_constraint(c)
    except ConstraintFormatError:
        return _describe(c)


# --- YAML form (§7, §8.2) ----------------------------------------------------------

_UNIT_KEYS = ("constraintUnit", "constraintUnitType")
_LIST_KEYS = ("constraintList", "constraintListType")
_HASH_KEYS = ("constraintHash", "constraintHashType")
_ROOT_KEYS = frozenset(_UNIT_KEYS + _LIST_KEYS + _HASH_KEYS)
_BY_NAME: dict[str, type[_Comparison]] = {c.yaml_name: c for c in COMPARISONS}
_WILD_NAMES = ("wildCard", "wildChar", "wildcard")


def _enumeration_or(children: list[Constraint], path: str) -> Constraint:
    """``or`` of equalities is how the spec writes an enumeration (§8); read it back so."""
    if children and all(isinstance(c, EqualTo) for c in children):
        cases = {c.match_case for c in children if isinstance(c, EqualTo)}
        if len(cases) == 1:
            literals = tuple(c.literal for c in children if isinstance(c, EqualTo))
            return Enumeration(literals, match_case=cases.pop())
    if len(children) < 2:
        raise ConstraintError("'or' needs at least 2 constraints", path)
    return Or(tuple(children))


def _yaml_scalar(data: object, path: str) -> str:
    if data is None:
        raise ConstraintError("required field missing", path)
    if isinstance(data, bool):
        return "true" if data else "false"
    if isinstance(data, str | int | float):
        return str(data)
    raise ConstraintError(f"expected a scalar, got {type(data).__name__}", path)


def _yaml_bool(data: object, path: str) -> bool:
    if data is None:
        return True  # §8.1 omits matchCase for the case-sensitive sample
    if isinstance(data, bool):
        return data
    parsed = parse_bool(data) if isinstance(data, str) else None
    if parsed is None:
        raise ConstraintError(f"expected a boolean, got {data!r}", path)
    return parsed


def _yaml_map(data: object, path: str, allowed: Sequence[str] | None = None) -> dict[str, object]:
    if data is None:
        return {}
    if not isinstance(data, Mapping):
        raise ConstraintError(f"expected a mapping, got {type(data).__name__}", path)
    out: dict[str, object] = {}
    for key, value in data.items():
        if not isinstance(key, str):
            raise ConstraintError(f"keys must be strings, got {key!r}", path)
        if allowed is not None and key not in allowed:
            expected = ", ".join(allowed)
            raise ConstraintError(f"unknown field (expected {expected})", f"{path}.{key}")
        out[key] = value
    return out


def _yaml_seq(data: object, path: str) -> list[object]:
    """The children of and/or/constraintList/constraintHash: a sequence, or RTCBuilder's
    wrapping mapping ``{constraint: [...]}`` (the XML's Constraint children)."""
    if isinstance(data, Mapping) and len(data) == 1 and "constraint" in data:
        data = data["constraint"]
        if isinstance(data, Mapping):
            data = [data]  # one child written as the child itself
    if isinstance(data, Sequence) and not isinstance(data, str):
        return list(data)
    raise ConstraintError(f"expected a sequence, got {type(data).__name__}", path)


class _YamlReader:
    def root(self, data: object, path: str, depth: int) -> Constraint:
        if depth > MAX_DEPTH:
            raise ConstraintError(f"nested deeper than {MAX_DEPTH} levels", path)
        m = _yaml_map(data, path)
        keys = [k for k in m if k in _ROOT_KEYS]
        if len(keys) != 1 or len(m) != 1:
            raise ConstraintError(
                "expected exactly one of constraintUnit, constraintList, constraintHash", path
            )
        key = keys[0]
        sub = f"{path}.{key}"
        if key in _UNIT_KEYS:
            return self.unit(m[key], sub, depth, keyed=False)[1]
        items = _yaml_seq(m[key], sub)
        if not items:
            raise ConstraintError("needs at least one constraint", sub)
        if key in _LIST_KEYS:
            return ListConstraint(
                tuple(self.root(item, f"{sub}[{i}]", depth + 1) for i, item in enumerate(items))
            )
        entries: list[tuple[str, Constraint]] = []
        for i, item in enumerate(items):
            item_path = f"{sub}[{i}]"
            entry = _yaml_map(item, item_path)
            unit_keys = [k for k in entry if k in _UNIT_KEYS]
            if len(unit_keys) != 1 or len(entry) != 1:
                raise ConstraintError("a hash entry must be a constraintUnit with a key", item_path)
            k = unit_keys[0]
            hkey, c = self.unit(entry[k], f"{item_path}.{k}", depth + 1, keyed=True)
            if any(hkey == seen for seen, _ in entries):
                raise ConstraintError(f"duplicate key {hkey!r}", item_path)
            entries.append((hkey or "", c))
        return HashConstraint(tuple(entries))

    def root_or_unit(self, data: object, path: str, depth: int) -> Constraint:
        if isinstance(data, Mapping) and any(k in _ROOT_KEYS for k in data):
            return self.root(data, path, depth)
        return self.unit(data, path, depth, keyed=False)[1]

    def unit(
        self, data: object, path: str, depth: int, *, keyed: bool
    ) -> tuple[str | None, Constraint]:
        if depth > MAX_DEPTH:
            raise ConstraintError(f"nested deeper than {MAX_DEPTH} levels", path)
        m = _yaml_map(data, path)
        key = _yaml_scalar(m["key"], f"{path}.key") if m.get("key") is not None else None
        if keyed and not key:
            raise ConstraintError("required field missing", f"{path}.key")
        if not keyed and key:
            raise ConstraintError("only allowed in constraintHash entries", f"{path}.key")
        ops = [k for k in m if k != "key"]
        if len(ops) != 1:
            raise ConstraintError(
                "expected exactly one operator (not, and, or, propertyIs...)"
                + (f", got {', '.join(ops)}" if ops else ""),
                path,
            )
        op = ops[0]
        try:
            return key, self.operator(op, m[op], f"{path}.{op}", depth)
        except ConstraintError as e:
            if e.path:
                raise
            raise ConstraintError(e.message, f"{path}.{op}") from e

    def operator(self, op: str, data: object, path: str, depth: int) -> Constraint:
        if op == "not":
            inner = data
            if isinstance(data, Mapping) and "constraint" in data:
                inner = _yaml_map(data, path, ("constraint",))["constraint"]
                path = f"{path}.constraint"
            return Not(self.root_or_unit(inner, path, depth + 1))
        if op in ("and", "or"):
            items = _yaml_seq(data, path)
            children = [
                self.root_or_unit(item, f"{path}[{i}]", depth + 1) for i, item in enumerate(items)
            ]
            if op == "or":
                return _enumeration_or(children, path)
            if len(children) < 2:
                raise ConstraintError("'and' needs at least 2 constraints", path)
            return And(tuple(children))
        if op in _BY_NAME:
            m = _yaml_map(data, path, ("literal", "matchCase"))
            literal = _yaml_scalar(m.get("literal"), f"{path}.literal")
            return _BY_NAME[op](literal, _yaml_bool(m.get("matchCase"), f"{path}.matchCase"))
        if op == "propertyIsBetween":
            m = _yaml_map(data, path, ("lowerBoundary", "upperBoundary"))
            return Between(
                _yaml_scalar(m.get("lowerBoundary"), f"{path}.lowerBoundary"),
                _yaml_scalar(m.get("upperBoundary"), f"{path}.upperBoundary"),
            )
        if op == "propertyIsLike":
            m = _yaml_map(data, path, ("literal", "singleChar", "escapeChar", *_WILD_NAMES))
            wild_key = next((k for k in _WILD_NAMES if k in m), "wildCard")
            return Like(
                _yaml_scalar(m.get("literal"), f"{path}.literal"),
                _yaml_scalar(m.get(wild_key), f"{path}.{wild_key}"),
                _yaml_scalar(m.get("singleChar"), f"{path}.singleChar"),
                _yaml_scalar(m.get("escapeChar"), f"{path}.escapeChar"),
            )
        if op in ("propertyIsNull", "propertyIsNullType"):
            if data not in (None, "") and not (isinstance(data, Mapping) and not data):
                raise ConstraintError("takes no value", path)
            return IsNull()
        raise ConstraintError("unknown constraint operator", path)


def constraint_from_yaml(data: object, path: str = "constraint") -> Constraint:
    """Read the YAML form (the value under a ``constraint:`` key); raises ConstraintError
    whose ``path`` starts with ``path``."""
    return _YamlReader().root(data, path, 0)


def _unit_to_yaml(c: Constraint) -> dict[str, object]:
    if isinstance(c, Not):
        return {"not": {"constraint": constraint_to_yaml(c.child)}}
    if isinstance(c, And | Or):
        items = [_unit_to_yaml(ch) if is_unit(ch) else constraint_to_yaml(ch) for ch in c.children]
        return {"and" if isinstance(c, And) else "or": items}
    if isinstance(c, Enumeration):
        return {"or": [_unit_to_yaml(EqualTo(v, c.match_case)) for v in c.values]}
    if isinstance(c, _Comparison):
        return {c.yaml_name: {"matchCase": c.match_case, "literal": c.literal}}
    if isinstance(c, Between):
        return {"propertyIsBetween": {"lowerBoundary": c.lower, "upperBoundary": c.upper}}
    if isinstance(c, Like):
        return {
            "propertyIsLike": {
                "wildCard": c.wild_char,
                "singleChar": c.single_char,
                "escapeChar": c.escape_char,
                "literal": c.pattern,
            }
        }
    if isinstance(c, IsNull):
        return {"propertyIsNull": None}
    raise ConstraintError(f"{type(c).__name__} is not a unit constraint")


def constraint_to_yaml(c: Constraint) -> dict[str, object]:
    """The YAML form of a tree (the value to put under a ``constraint:`` key)."""
    if isinstance(c, ListConstraint):
        return {"constraintList": [constraint_to_yaml(i) for i in c.items]}
    if isinstance(c, HashConstraint):
        return {
            "constraintHash": [
                {"constraintUnit": {"key": k, **_unit_to_yaml(v)}} for k, v in c.entries
            ]
        }
    return {"constraintUnit": _unit_to_yaml(c)}


# --- XML form (§6.1, §8.1) ---------------------------------------------------------


def _local(tag: str) -> str:
    """Local name with the first letter lowered: the spec spells elements both ways."""
    name = tag.rpartition("}")[2]
    return name[:1].lower() + name[1:]


def _xml_attr(elem: ET.Element, *names: str) -> str | None:
    for key, value in elem.attrib.items():
        if key.rpartition("}")[2] in names:
            return value
    return None


def _xml_children(elem: ET.Element, path: str) -> list[ET.Element]:
    if elem.text is not None and elem.text.strip():
        raise ConstraintError("unexpected text", path)
    for child in elem:
        if child.tail is not None and child.tail.strip():
            raise ConstraintError("unexpected text", path)
    return list(elem)


def _xml_only_child(elem: ET.Element, path: str, names: Sequence[str]) -> ET.Element:
    children = _xml_children(elem, path)
    if len(children) != 1 or _local(children[0].tag) not in names:
        raise ConstraintError(f"expected exactly one {' or '.join(names)} element", path)
    return children[0]


class _XmlReader:
    def root(self, elem: ET.Element, path: str, depth: int) -> Constraint:
        if depth > MAX_DEPTH:
            raise ConstraintError(f"nested deeper than {MAX_DEPTH} levels", path)
        names = ("constraintUnitType", "constraintListType", "constraintHashType")
        child = _xml_only_child(elem, path, names)
        kind = _local(child.tag)
        sub = f"{path}.{child.tag.rpartition('}')[2]}"
        if kind == "constraintUnitType":
            return self.unit(child, sub, depth, keyed=False)[1]
        items = [(f"{sub}.Constraint[{i}]", c) for i, c in enumerate(self.constraints(child, sub))]
        if not items:
            raise ConstraintError("needs at least one Constraint", sub)
        if kind == "constraintListType":
            return ListConstraint(tuple(self.root(c, p, depth + 1) for p, c in items))
        entries: list[tuple[str, Constraint]] = []
        for p, c in items:
            unit = _xml_only_child(c, p, ("constraintUnitType",))
            key, constraint = self.unit(unit, f"{p}.ConstraintUnitType", depth + 1, keyed=True)
            if any(key == seen for seen, _ in entries):
                raise ConstraintError(f"duplicate key {key!r}", p)
            entries.append((key or "", constraint))
        return HashConstraint(tuple(entries))

    def constraints(self, elem: ET.Element, path: str) -> list[ET.Element]:
        children = _xml_children(elem, path)
        for child in children:
            if _local(child.tag) not in ("constraint", "constraintType"):
                raise ConstraintError(f"unexpected element {child.tag!r}", path)
        return children

    def unit(
        self, elem: ET.Element, path: str, depth: int, *, keyed: bool
    ) -> tuple[str | None, Constraint]:
        key = _xml_attr(elem, "key")
        if keyed and not key:
            raise ConstraintError("required field missing", f"{path}.key")
        if not keyed and key:
            raise ConstraintError("only allowed in ConstraintHashType entries", f"{path}.key")
        children = _xml_children(elem, path)
        if len(children) != 1:
            raise ConstraintError("expected exactly one operator element", path)
        op_elem = children[0]
        op = _local(op_elem.tag)
        sub = f"{path}.{op_elem.tag.rpartition('}')[2]}"
        try:
            return key, self.operator(op, op_elem, sub, depth)
        except ConstraintError as e:
            if e.path:
                raise
            raise ConstraintError(e.message, sub) from e

    def literal(self, elem: ET.Element, path: str, name: str) -> str:
        found = [c for c in _xml_children(elem, path) if _local(c.tag) == name]
        if len(found) != 1:
            raise ConstraintError("required field missing", f"{path}.{name}")
        if len(found[0]):
            raise ConstraintError("must contain only text", f"{path}.{name}")
        return found[0].text or ""

    def operator(self, op: str, elem: ET.Element, path: str, depth: int) -> Constraint:
        if op == "not":
            inner = self.constraints(elem, path)
            if len(inner) != 1:
                raise ConstraintError("expected exactly one Constraint", path)
            return Not(self.root(inner[0], f"{path}.Constraint", depth + 1))
        if op in ("and", "or"):
            children = [
                self.root(c, f"{path}.Constraint[{i}]", depth + 1)
                for i, c in enumerate(self.constraints(elem, path))
            ]
            if op == "or":
                return _enumeration_or(children, path)
            if len(children) < 2:
                raise ConstraintError("'and' needs at least 2 constraints", path)
            return And(tuple(children))
        if op in _BY_NAME:
            match_case = _xml_attr(elem, "matchCase")
            case = True if match_case is None else parse_bool(match_case)
            if case is None:
                raise ConstraintError(
                    f"expected a boolean, got {match_case!r}", f"{path}.matchCase"
                )
            return _BY_NAME[op](self.literal(elem, path, "literal"), case)
        if op == "propertyIsBetween":
            return Between(
                self.literal(elem, path, "lowerBoundary"), self.literal(elem, path, "upperBoundary")
            )
        if op == "propertyIsLike":
            wild = _xml_attr(elem, *_WILD_NAMES)
            single = _xml_attr(elem, "singleChar")
            escape = _xml_attr(elem, "escapeChar")
            for name, v in (("wildCard", wild), ("singleChar", single), ("escapeChar", escape)):
                if v is None:
                    raise ConstraintError("required field missing", f"{path}.{name}")
            assert wild is not None and single is not None and escape is not None
            return Like(self.literal(elem, path, "literal"), wild, single, escape)
        if op in ("propertyIsNull", "propertyIsNullType"):
            return IsNull()
        raise ConstraintError("unknown constraint operator", path)


def constraint_from_xml(elem: ET.Element, path: str = "Constraint") -> Constraint:
    """Read a ``Constraint`` element (any namespace, or none as in §8.1)."""
    if _local(elem.tag) not in ("constraint", "constraintType"):
        raise ConstraintError(f"expected a Constraint element, got {elem.tag!r}", path)
    return _XmlReader().root(elem, path, 0)


def _q(ns: str, name: str) -> str:
    return f"{{{ns}}}{name}"


def _unit_to_xml(parent: ET.Element, c: Constraint, ns: str) -> None:
    if isinstance(c, Not):
        ET.SubElement(parent, _q(ns, "Not")).append(constraint_to_xml(c.child, ns))
    elif isinstance(c, And | Or | Enumeration):
        op = ET.SubElement(parent, _q(ns, "And" if isinstance(c, And) else "Or"))
        children: Sequence[Constraint] = (
            [EqualTo(v, c.match_case) for v in c.values]
            if isinstance(c, Enumeration)
            else c.children
        )
        for child in children:
            op.append(constraint_to_xml(child, ns))
    elif isinstance(c, _Comparison):
        op = ET.SubElement(
            parent, _q(ns, c.yaml_name), {_q(ns, "matchCase"): "true" if c.match_case else "false"}
        )
        ET.SubElement(op, _q(ns, "Literal")).text = c.literal
    elif isinstance(c, Between):
        op = ET.SubElement(parent, _q(ns, "propertyIsBetween"))
        ET.SubElement(op, _q(ns, "LowerBoundary")).text = c.lower
        ET.SubElement(op, _q(ns, "UpperBoundary")).text = c.upper
    elif isinstance(c, Like):
        attrs = {
            _q(ns, "wildCard"): c.wild_char,
            _q(ns, "singleChar"): c.single_char,
            _q(ns, "escapeChar"): c.escape_char,
        }
        op = ET.SubElement(parent, _q(ns, "propertyIsLike"), attrs)
        ET.SubElement(op, _q(ns, "Literal")).text = c.pattern
    elif isinstance(c, IsNull):
        ET.SubElement(parent, _q(ns, "propertyIsNull"))
    else:
        raise ConstraintError(f"{type(c).__name__} is not a unit constraint")


def constraint_to_xml(c: Constraint, ns: str = RTC_NS) -> ET.Element:
    """A ``{ns}Constraint`` element in the form of the spec's XML schema (§6.1)."""
    root = ET.Element(_q(ns, "Constraint"))
    if isinstance(c, ListConstraint):
        holder = ET.SubElement(root, _q(ns, "ConstraintListType"))
        for item in c.items:
            holder.append(constraint_to_xml(item, ns))
    elif isinstance(c, HashConstraint):
        holder = ET.SubElement(root, _q(ns, "ConstraintHashType"))
        for key, value in c.entries:
            entry = ET.SubElement(holder, _q(ns, "Constraint"))
            unit = ET.SubElement(entry, _q(ns, "ConstraintUnitType"), {_q(ns, "key"): key})
            _unit_to_xml(unit, value, ns)
    else:
        _unit_to_xml(ET.SubElement(root, _q(ns, "ConstraintUnitType")), c, ns)
    return root
