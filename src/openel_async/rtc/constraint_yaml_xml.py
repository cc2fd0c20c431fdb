"""The constraint tree in the RTC Profile's document forms: the YAML form (§7, §8.2) and
the XML form (§6.1, §8.1), read and written.

Re-exported by :mod:`openel_async.rtc.constraints`.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence

from .constraint_tree import (
    COMPARISONS,
    And,
    Between,
    Comparison,
    Constraint,
    ConstraintError,
    Enumeration,
    EqualTo,
    HashConstraint,
    IsNull,
    Like,
    ListConstraint,
    Not,
    Or,
    is_unit,
    parse_bool,
)

__all__ = [
    "MAX_DEPTH",
    "RTC_NS",
    "constraint_from_xml",
    "constraint_from_yaml",
    "constraint_to_xml",
    "constraint_to_yaml",
]

RTC_NS = "http://www.openrtp.org/namespaces/rtc"

# Deeper trees than this are refused by the YAML/XML readers (no legitimate profile
# nests that far; it keeps hostile input from exhausting the stack).
MAX_DEPTH = 64


# --- YAML form (§7, §8.2) ----------------------------------------------------------

_UNIT_KEYS = ("constraintUnit", "constraintUnitType")
_LIST_KEYS = ("constraintList", "constraintListType")
_HASH_KEYS = ("constraintHash", "constraintHashType")
_ROOT_KEYS = frozenset(_UNIT_KEYS + _LIST_KEYS + _HASH_KEYS)
_BY_NAME: dict[str, type[Comparison]] = {c.yaml_name: c for c in COMPARISONS}
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
    if isinstance(c, Comparison):
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
    elif isinstance(c, Comparison):
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
