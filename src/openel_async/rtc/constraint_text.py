"""OpenRTM's text form of constraints (``100``, ``x>=100``, ``100<=x<=200``, ``(a,b)``,
``c0, c1``, ``{k0: c0, k1: c1}``): :func:`parse_constraint`, :func:`format_constraint`,
:func:`describe`, and their errors.

Re-exported by :mod:`openel_async.rtc.constraints`.
"""

from __future__ import annotations

from collections.abc import Sequence

from .constraint_tree import (
    NUMBER_LITERAL,
    And,
    Between,
    Comparison,
    Constraint,
    ConstraintError,
    Enumeration,
    EqualTo,
    GreaterThan,
    GreaterThanOrEqualTo,
    HashConstraint,
    IsNull,
    LessThan,
    LessThanOrEqualTo,
    Like,
    ListConstraint,
    Not,
    Or,
    parse_number,
)

__all__ = [
    "ConstraintFormatError",
    "ConstraintSyntaxError",
    "describe",
    "format_constraint",
    "parse_constraint",
]

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


_LITERAL_STOP = frozenset(",(){}<>=:")
_ITEM_STOP = frozenset(",(){}")
_UPPER_OPS = {"<": LessThan, "<=": LessThanOrEqualTo}
_LOWER_OPS = {"<": GreaterThan, "<=": GreaterThanOrEqualTo}
_ASCENDING = ("<", "<=")
_DESCENDING = (">", ">=", "=>")
# A descending operator as the ascending one with the sides swapped.
_FLIP = {">": "<", ">=": "<=", "=>": "<="}
_X_OPS: dict[str, type[Comparison]] = {
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
        m = NUMBER_LITERAL.match(self.text, self.pos)
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
        number = NUMBER_LITERAL.match(self.text, self.pos)
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
    if isinstance(c, Comparison):
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
