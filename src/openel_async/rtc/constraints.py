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

This module is the public face of three that implement it, and re-exports their names:

* :mod:`openel_async.rtc.constraint_tree`: the tree's nodes, ``ConstraintError``,
  ``TypedValue`` and the guarded literal parsers (``parse_int``, ``parse_number``,
  ``parse_bool``, ``scalar_text``);
* :mod:`openel_async.rtc.constraint_text`: OpenRTM's text form (``parse_constraint``,
  ``format_constraint``, ``describe``, ``ConstraintSyntaxError``, ``ConstraintFormatError``);
* :mod:`openel_async.rtc.constraint_yaml_xml`: the YAML and XML forms
  (``constraint_from_yaml`` ... ``constraint_to_xml``, ``RTC_NS``, ``MAX_DEPTH``).
"""

from __future__ import annotations

from .constraint_text import (
    ConstraintFormatError,
    ConstraintSyntaxError,
    describe,
    format_constraint,
    parse_constraint,
)
from .constraint_tree import (
    COMPARISONS,
    MAX_INT_DIGITS,
    And,
    Between,
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
    NotEqualTo,
    Or,
    Scalar,
    TypedValue,
    Value,
    is_unit,
    parse_bool,
    parse_int,
    parse_number,
    scalar_text,
)
from .constraint_yaml_xml import (
    MAX_DEPTH,
    RTC_NS,
    constraint_from_xml,
    constraint_from_yaml,
    constraint_to_xml,
    constraint_to_yaml,
)

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
