"""Constraint tree semantics, the text form, and the spec's YAML/XML forms."""

from __future__ import annotations

import re

import pytest
import yaml
from hypothesis import given
from hypothesis import strategies as st

from openel_async.rtc.constraints import (
    And,
    Between,
    Constraint,
    ConstraintError,
    ConstraintFormatError,
    ConstraintSyntaxError,
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
    TypedValue,
    Value,
    constraint_from_yaml,
    constraint_to_yaml,
    describe,
    format_constraint,
    parse_constraint,
)
from openel_async.rtc.profile import ProfileError, dumps_constraint_xml, loads_constraint_xml

from .strategies import ANY_CONSTRAINT, SETTINGS, TEXT_CONSTRAINT


def tv(text: str) -> TypedValue:
    """A double parsed from text, as Configuration hands it to constraints."""
    return TypedValue(float(text), text)


# --- semantics -----------------------------------------------------------------------

CHECKS: list[tuple[str, Value, bool]] = [
    # equality is numeric on numbers
    ("100", 100, True),
    ("100", 100.0, True),
    ("100", tv("100.0"), True),
    ("100", 101, False),
    ("100", "100", True),
    ("100", "100.0", False),  # a str value compares as a string
    # one-sided bounds
    ("x>=100", 100, True),
    ("x>=100", 99.999, False),
    ("x>100", 100, False),
    ("x>100", 100.0001, True),
    ("x<100", 100, False),
    ("x<100", 99, True),
    ("x<=100", 100, True),
    ("x<=100", 100.5, False),
    ("x>=-1.5", -1.5, True),
    ("x<1e3", 999.9, True),
    ("x<1e3", 1000, False),
    # ranges: inclusive and exclusive ends
    ("100<=x<=200", 100, True),
    ("100<=x<=200", 200, True),
    ("100<=x<=200", 99, False),
    ("100<=x<=200", 201, False),
    ("100<x<200", 100, False),
    ("100<x<200", 200, False),
    ("100<x<200", 150, True),
    ("100<x<=200", 100, False),
    ("100<x<=200", 200, True),
    ("100<=x<200", 100, True),
    ("100<=x<200", 200, False),
    # enumerations compare the text exactly
    ("(100,200)", tv("100"), True),
    ("(100,200)", tv("100.0"), False),
    ("(100,200)", "100", True),
    ("(100,200)", 100, True),
    ("(100,200)", 100.0, False),
    ("(red, green, blue)", "green", True),
    ("(red,green,blue)", "Red", False),
    ("(red,green,blue)", None, False),
    # per-element constraints of a sequence: one per element, lengths must match
    ("x<1, x<10", [0.5, 5], True),
    ("x<1, x<10", [1, 5], False),
    ("x<1, x<10", [0.5], False),
    ("x<1, x<10", [0.5, 5, 5], False),
    ("x<1, x<10", 0.5, False),
    # a scalar constraint on a sequence holds for every element
    ("0<=x<=10", [1, 2, 3], True),
    ("0<=x<=10", [1, 11], False),
    ("(a,b)", ["a", "b", "a"], True),
    # hashes: per-key constraints, a missing key is null
    ("{k0: 100<x<200, k1: x>=100}", {"k0": 150, "k1": 100}, True),
    ("{k0: 100<x<200, k1: x>=100}", {"k0": 100, "k1": 100}, False),
    ("{k0: 100<x<200, k1: x>=100}", {"k0": 150}, False),
    ("{k0: 100<x<200, k1: x>=100}", {"k0": 150, "k1": 100, "other": -1}, True),
    ("{k0: 100<x<200}", [150], False),
    # non-numeric values never satisfy numeric bounds
    ("x<100", None, False),
    ("x<100", tv("nan"), False),
]


@pytest.mark.parametrize(("text", "value", "expected"), CHECKS)
def test_text_constraint_checks(text: str, value: Value, expected: bool) -> None:
    assert parse_constraint(text).check(value) is expected


@pytest.mark.parametrize(
    ("constraint", "value", "expected"),
    [
        (EqualTo("test"), "test", True),
        (EqualTo("test"), "TEST", False),
        (EqualTo("test", match_case=False), "TEST", True),
        (EqualTo("test", match_case=False), "tests", False),
        (NotEqualTo("test"), "TEST", True),
        (NotEqualTo("test", match_case=False), "TEST", False),
        (NotEqualTo("5"), None, True),
        (Enumeration(("Up", "down"), match_case=False), "UP", True),
        (Enumeration(("Up", "down"), match_case=True), "up", False),
        (LessThan("b"), "a", True),  # strings order as strings
        (LessThan("b", match_case=False), "A", True),
        (LessThan("b"), "A", True),
        (LessThan("B"), "a", False),
        (EqualTo("true"), True, True),
        (EqualTo("1"), True, True),
        (EqualTo("false"), True, False),
        (IsNull(), None, True),
        (IsNull(), "", True),
        (IsNull(), TypedValue("", ""), True),
        (IsNull(), "x", False),
        (IsNull(), [], True),
        (IsNull(), {}, True),
        (Not(IsNull()), "x", True),
        (Or((LessThanOrEqualTo("100"), GreaterThanOrEqualTo("200"))), 100, True),
        (Or((LessThanOrEqualTo("100"), GreaterThanOrEqualTo("200"))), 150, False),
        (Or((LessThanOrEqualTo("100"), GreaterThanOrEqualTo("200"))), 200, True),
        (And((GreaterThan("0"), NotEqualTo("5"))), 5, False),
        (Between("a", "c"), "b", True),
        (HashConstraint((("k", IsNull()),)), {}, True),
        (HashConstraint((("k", Not(IsNull())),)), {}, False),
    ],
)
def test_tree_checks(constraint: Constraint, value: Value, expected: bool) -> None:
    assert constraint.check(value) is expected


@pytest.mark.parametrize(
    ("pattern", "value", "expected"),
    [
        ("....:...:*", "abcd:efg:anything at all", True),  # the §8 sample
        ("....:...:*", "abcd:efg:", True),
        ("....:...:*", "abc:efg:x", False),
        ("a*", "a", True),
        ("a*", "ba", False),
        ("a.c", "abc", True),
        ("a.c", "ac", False),
        ("a\\.c", "a.c", True),  # escaped single char is literal
        ("a\\.c", "abc", False),
        ("a\\*", "a*", True),
        ("a\\*", "ab", False),
        ("a\\\\b", "a\\b", True),  # escaped escape
        ("a+b", "a+b", True),  # regex metacharacters are literal
        ("a+b", "aab", False),
        ("*\n*", "x\ny", True),
    ],
)
def test_like(pattern: str, value: str, expected: bool) -> None:
    assert Like(pattern, "*", ".", "\\").check(value) is expected


def test_like_has_no_catastrophic_backtracking() -> None:
    # A backtracking regex needs O(n**8) steps here; the matcher is O(n * pattern).
    like = Like("*a*a*a*a*a*a*a*a*b")
    assert not like.check("a" * 5000)
    assert like.check("a" * 5000 + "b")


def _reference_like(pattern: str, text: str) -> bool:
    parts: list[str] = []
    chars = iter(pattern)
    for ch in chars:
        if ch == "\\":
            parts.append(re.escape(next(chars)))
        else:
            parts.append({"*": ".*", "?": "."}.get(ch, re.escape(ch)))
    return re.fullmatch("".join(parts), text, re.DOTALL) is not None


@SETTINGS
@given(
    st.text("ab*?\\", max_size=8).filter(lambda p: not p.replace("\\\\", "").endswith("\\")),
    st.text("ab?*\\", max_size=8),
)
def test_like_agrees_with_a_regex_reference(pattern: str, text: str) -> None:
    assert Like(pattern).check(text) is _reference_like(pattern, text)


def test_like_uses_the_text_of_typed_values() -> None:
    like = Like("1?0", "*", "?", "\\")
    assert like.check(tv("100"))
    assert not like.check(tv("1e2"))
    assert like.check(100)


@pytest.mark.parametrize(
    "build",
    [
        lambda: And((IsNull(),)),
        lambda: Or(()),
        lambda: Enumeration(()),
        lambda: ListConstraint(()),
        lambda: HashConstraint(()),
        lambda: HashConstraint((("a", IsNull()), ("a", IsNull()))),
        lambda: HashConstraint((("a", ListConstraint((IsNull(),))),)),
        lambda: Like("a", "**", "?", "\\"),
        lambda: Like("a", "*", "*", "\\"),
        lambda: Like("ab\\", "*", "?", "\\"),
    ],
)
def test_invalid_trees_are_refused(build: object) -> None:
    with pytest.raises(ConstraintError):
        build()  # type: ignore[operator]


# --- text form -----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "tree", "canonical"),
    [
        ("100", EqualTo("100"), "100"),
        (" red ", EqualTo("red"), "red"),
        ("x>=100", GreaterThanOrEqualTo("100"), "x>=100"),
        ("x > -2.5", GreaterThan("-2.5"), "x>-2.5"),
        ("x<100", LessThan("100"), "x<100"),
        ("x <= 1e3", LessThanOrEqualTo("1e3"), "x<=1e3"),
        ("100<=x<=200", Between("100", "200"), "100<=x<=200"),
        ("100<x<200", And((GreaterThan("100"), LessThan("200"))), "100<x<200"),
        ("100 <= x < 200", And((GreaterThanOrEqualTo("100"), LessThan("200"))), "100<=x<200"),
        ("(a, b ,c)", Enumeration(("a", "b", "c")), "(a,b,c)"),
        ("(100,200)", Enumeration(("100", "200")), "(100,200)"),
        ("x<1,x<10", ListConstraint((LessThan("1"), LessThan("10"))), "x<1, x<10"),
        (
            "{k0: 100<x<200, k1: x>=100}",
            HashConstraint(
                (
                    ("k0", And((GreaterThan("100"), LessThan("200")))),
                    ("k1", GreaterThanOrEqualTo("100")),
                )
            ),
            "{k0: 100<x<200, k1: x>=100}",
        ),
        ("{a:(x,y)}", HashConstraint((("a", Enumeration(("x", "y"))),)), "{a: (x,y)}"),
    ],
)
def test_parse_and_format(text: str, tree: Constraint, canonical: str) -> None:
    assert parse_constraint(text) == tree
    assert format_constraint(tree) == canonical
    assert parse_constraint(canonical) == tree


@pytest.mark.parametrize(
    ("text", "position", "expected"),
    [
        ("", 0, "expected a constraint"),
        ("x", 1, "expected '<', '<=', '>' or '>=' after 'x'"),
        ("x=5", 1, "after 'x', got '='"),
        ("x<abc", 2, "expected a number, got 'a'"),
        ("100<x>5", 5, "expected ',' or end of input, got '>'"),
        ("100>x<5", 5, "expected ',' or end of input, got '<'"),
        ("100<x<", 6, "expected a number, got end of input"),
        ("0>x>100", 0, "lower bound 100 is greater than upper bound 0"),
        ("9" * 5000 + "<=x<=1", 0, "lower bound 9999"),
        ("100<y<200", 4, "expected 'x', got 'y'"),
        ("200<x<100", 0, "lower bound 200 is greater than upper bound 100"),
        ("(a,,b)", 3, "expected an enumeration item"),
        ("(a,b", 4, "expected ',' or ')', got end of input"),
        ("()", 1, "expected an enumeration item"),
        ("{}", 1, "expected a hash key"),
        ("{a 1}", 4, "expected ':' after the hash key"),
        ("{a: 1, a: 2}", 7, "duplicate hash key 'a'"),
        ("{a: 1", 5, "expected ',' or '}'"),
        ("{a: 1} b", 7, "expected end of input, got 'b'"),
        ("x<1,", 4, "expected a constraint"),
        ("a:b", 1, "expected ',' or end of input, got ':'"),
        ("{a: x<1, x<2}", 10, "expected ':' after the hash key"),
    ],
)
def test_syntax_errors_name_position_and_expectation(
    text: str, position: int, expected: str
) -> None:
    with pytest.raises(ConstraintSyntaxError) as info:
        parse_constraint(text)
    assert info.value.position == position
    assert expected in str(info.value)
    assert f"position {position}" in str(info.value)
    assert isinstance(info.value, ValueError)


@pytest.mark.parametrize(
    "tree",
    [
        Like("a*", "*", "?", "\\"),
        Not(IsNull()),
        IsNull(),
        NotEqualTo("1"),
        EqualTo("test", match_case=False),
        Enumeration(("a",), match_case=False),
        EqualTo(" padded "),
        EqualTo("x"),
        EqualTo("a,b"),
        Enumeration(("a)",)),
        Or((LessThan("1"), GreaterThan("5"))),
        And((LessThan("1"), GreaterThan("5"))),
        GreaterThan("abc"),
        Between("a", "b"),
    ],
)
def test_trees_without_an_exact_text_form(tree: Constraint) -> None:
    with pytest.raises(ConstraintFormatError):
        format_constraint(tree)
    assert describe(tree)  # messages still get a readable rendering


def test_describe() -> None:
    assert describe(parse_constraint("100<x<200")) == "100<x<200"
    assert describe(Not(IsNull())) == "not (x is null)"
    assert describe(LessThan("100", match_case=False)) == "x<100"
    assert describe(Enumeration(("a", "b"), False)) == "(a,b) (ignoring case)"
    assert describe(Like("a*")) == "x like 'a*'"


@SETTINGS
@given(TEXT_CONSTRAINT)
def test_text_round_trip(tree: Constraint) -> None:
    text = format_constraint(tree)
    assert parse_constraint(text) == tree
    assert format_constraint(parse_constraint(text)) == text


@SETTINGS
@given(st.text(max_size=30))
def test_parser_only_raises_syntax_errors(text: str) -> None:
    try:
        tree = parse_constraint(text)
    except ConstraintSyntaxError as e:
        assert 0 <= e.position <= len(text)
        return
    # Whatever parses has a canonical text that parses back to the same tree.
    assert parse_constraint(format_constraint(tree)) == tree


@SETTINGS
@given(st.text(alphabet="x<>=(),{}: 01.-ab", max_size=20))
def test_parser_on_operator_soup(text: str) -> None:
    test_parser_only_raises_syntax_errors.hypothesis.inner_test(text)  # type: ignore[attr-defined]


# --- YAML and XML forms (§8) ---------------------------------------------------------

YAML_SAMPLES = {
    "equal": (
        "constraint:\n  constraintUnit:\n    propertyIsEqualTo:\n"
        "      matchCase: false\n      literal: 100\n",
        EqualTo("100", match_case=False),
    ),
    "less": (
        "constraint:\n  constraintUnit:\n    propertyIsLessThan:\n"
        "      matchCase: false\n      literal: 100\n",
        LessThan("100", match_case=False),
    ),
    "between": (
        "constraint:\n  constraintUnit:\n    propertyIsBetween:\n"
        "      lowerBoundary: 100\n      upperBoundary: 200\n",
        Between("100", "200"),
    ),
    "like": (
        'constraint:\n  constraintUnit:\n    propertyIsLike:\n      wildcard: "*"\n'
        '      singleChar: "."\n      escapeChar: "\\\\"\n      literal: ....:...:*\n',
        Like("....:...:*", "*", ".", "\\"),
    ),
    "not null": (
        "constraint:\n  constraintUnit:\n    not:\n      constraint:\n"
        "        constraintUnitType:\n          propertyIsNull:\n",
        Not(IsNull()),
    ),
    "or": (
        "constraint:\n  constraintUnit:\n    or:\n      -\n"
        "        propertyIsLessThanOrEqualTo:\n          matchCase: false\n          literal: 100\n"
        "      -\n        propertyIsGreaterThanOrEqualTo:\n          matchCase: false\n"
        "          literal: 200\n",
        Or(
            (
                LessThanOrEqualTo("100", match_case=False),
                GreaterThanOrEqualTo("200", match_case=False),
            )
        ),
    ),
    "string enumeration": (
        "constraint:\n  constraintUnit:\n    or:\n"
        + "".join(
            f"      -\n        propertyIsEqualTo:\n          matchCase: false\n"
            f"          literal: {v}\n"
            for v in ("red", "blue", "green")
        ),
        Enumeration(("red", "blue", "green"), match_case=False),
    ),
}


@pytest.mark.parametrize("name", list(YAML_SAMPLES))
def test_spec_yaml_samples(name: str) -> None:
    text, expected = YAML_SAMPLES[name]
    data = yaml.safe_load(text)["constraint"]
    assert constraint_from_yaml(data) == expected
    assert constraint_from_yaml(constraint_to_yaml(expected)) == expected


def _xml_unit(body: str) -> str:
    return f"<Constraint><ConstraintUnitType>{body}</ConstraintUnitType></Constraint>"


XML_SAMPLES = {
    "equal (case-sensitive by default)": (
        _xml_unit("<PropertyIsEqualTo><Literal>test</Literal></PropertyIsEqualTo>"),
        EqualTo("test", match_case=True),
    ),
    "equal ignoring case": (
        _xml_unit(
            '<PropertyIsEqualTo matchCase="false"><Literal>test</Literal></PropertyIsEqualTo>'
        ),
        EqualTo("test", match_case=False),
    ),
    "not equal": (
        _xml_unit("<PropertyIsNotEqualTo><Literal>100</Literal></PropertyIsNotEqualTo>"),
        NotEqualTo("100"),
    ),
    "greater": (
        _xml_unit("<PropertyIsGreaterThan><Literal>100</Literal></PropertyIsGreaterThan>"),
        GreaterThan("100"),
    ),
    "between": (
        _xml_unit(
            "<PropertyIsBetween><LowerBoundary>100</LowerBoundary>"
            "<UpperBoundary>200</UpperBoundary></PropertyIsBetween>"
        ),
        Between("100", "200"),
    ),
    "like": (
        _xml_unit(
            '<PropertyIsLike wildCard="*" singleChar="." escapeChar="\\">'
            "<Literal>....:...:*</Literal></PropertyIsLike>"
        ),
        Like("....:...:*", "*", ".", "\\"),
    ),
    "not null": (
        _xml_unit(f"<Not>{_xml_unit('<PropertyIsNull />')}</Not>"),
        Not(IsNull()),
    ),
    "numeric enumeration": (
        _xml_unit(
            "<Or>"
            + "".join(
                _xml_unit(f"<PropertyIsEqualTo><Literal>{v}</Literal></PropertyIsEqualTo>")
                for v in (5, 10, 15, 20)
            )
            + "</Or>"
        ),
        Enumeration(("5", "10", "15", "20")),
    ),
}


@pytest.mark.parametrize("name", list(XML_SAMPLES))
def test_spec_xml_samples(name: str) -> None:
    text, expected = XML_SAMPLES[name]
    assert loads_constraint_xml(text) == expected
    assert loads_constraint_xml(dumps_constraint_xml(expected)) == expected


def test_xml_lists_and_hashes() -> None:
    tree = parse_constraint("{k0: 100<x<200, k1: (a,b)}")
    xml = dumps_constraint_xml(tree)
    assert 'rtc:key="k0"' in xml and "rtc:ConstraintHashType" in xml
    assert loads_constraint_xml(xml) == tree
    listed = parse_constraint("x<1, 0<=x<=5")
    assert loads_constraint_xml(dumps_constraint_xml(listed)) == listed


@pytest.mark.parametrize(
    ("text", "path"),
    [
        ("<Other/>", "Constraint"),
        ("<Constraint/>", "Constraint"),
        (_xml_unit("<PropertyIsEqualTo/>"), "PropertyIsEqualTo.literal"),
        (
            _xml_unit(
                '<PropertyIsEqualTo matchCase="maybe"><Literal>1</Literal></PropertyIsEqualTo>'
            ),
            "matchCase",
        ),
        (_xml_unit("<PropertyIsWeird/>"), "PropertyIsWeird"),
        (_xml_unit("<And>" + _xml_unit("<PropertyIsNull/>") + "</And>"), "And"),
        (
            _xml_unit('<PropertyIsLike singleChar="." escapeChar="\\"><Literal/></PropertyIsLike>'),
            "wildCard",
        ),
        (
            "<Constraint><ConstraintHashType>"
            + _xml_unit("<PropertyIsNull/>")
            + "</ConstraintHashType></Constraint>",
            "key",
        ),
        (_xml_unit("<PropertyIsNull/><PropertyIsNull/>"), "ConstraintUnitType"),
    ],
)
def test_bad_xml_constraints(text: str, path: str) -> None:
    with pytest.raises(ProfileError) as info:
        loads_constraint_xml(text)
    assert path in info.value.path


@pytest.mark.parametrize(
    ("data", "path"),
    [
        ({}, "constraint"),
        ({"constraintUnit": {}}, "constraint.constraintUnit"),
        ({"constraintUnit": {"propertyIsLessThan": {}}}, "propertyIsLessThan.literal"),
        ({"constraintUnit": {"propertyIsLessThan": {"literal": 1, "bogus": 2}}}, "bogus"),
        (
            {"constraintUnit": {"propertyIsLessThan": {"literal": 1, "matchCase": "perhaps"}}},
            "matchCase",
        ),
        ({"constraintUnit": {"or": [{"propertyIsNull": None}]}}, "or"),
        ({"constraintUnit": {"and": {"propertyIsNull": None}}}, "and"),
        ({"constraintUnit": {"key": "k", "propertyIsNull": None}}, "constraintUnit.key"),
        ({"constraintHash": [{"constraintUnit": {"propertyIsNull": None}}]}, "key"),
        ({"constraintList": []}, "constraintList"),
        ({"constraintUnit": {"propertyIsLike": {"literal": "a", "wildCard": "*"}}}, "singleChar"),
        ({"constraintUnit": {"propertyIsNull": None, "not": {}}}, "constraintUnit"),
        ([1, 2], "constraint"),
    ],
)
def test_bad_yaml_constraints(data: object, path: str) -> None:
    with pytest.raises(ConstraintError) as info:
        constraint_from_yaml(data)
    assert path in info.value.path


def test_deep_nesting_is_refused() -> None:
    data: object = {"constraintUnit": {"propertyIsNull": None}}
    for _ in range(200):
        data = {"constraintUnit": {"not": {"constraint": data}}}
    with pytest.raises(ConstraintError, match="nested deeper"):
        constraint_from_yaml(data)


@SETTINGS
@given(TEXT_CONSTRAINT)
def test_text_to_yaml_and_xml_round_trip(tree: Constraint) -> None:
    text = format_constraint(tree)
    via_yaml = constraint_from_yaml(yaml.safe_load(yaml.safe_dump(constraint_to_yaml(tree))))
    via_xml = loads_constraint_xml(dumps_constraint_xml(tree))
    assert via_yaml == tree == via_xml
    assert format_constraint(via_yaml) == text == format_constraint(via_xml)


@SETTINGS
@given(ANY_CONSTRAINT)
def test_any_tree_round_trips_through_yaml_and_xml(tree: Constraint) -> None:
    assert constraint_from_yaml(yaml.safe_load(yaml.safe_dump(constraint_to_yaml(tree)))) == tree
    assert loads_constraint_xml(dumps_constraint_xml(tree)) == tree


def test_or_of_equalities_reads_back_as_enumeration() -> None:
    tree = Or((EqualTo("a"), EqualTo("b")))
    assert constraint_from_yaml(constraint_to_yaml(tree)) == Enumeration(("a", "b"))
    mixed = Or((EqualTo("a"), EqualTo("b", match_case=False)))
    assert constraint_from_yaml(constraint_to_yaml(mixed)) == mixed


JSONISH = st.recursive(
    st.none() | st.booleans() | st.integers() | st.text(max_size=5),
    lambda inner: (
        st.lists(inner, max_size=3)
        | st.dictionaries(
            st.sampled_from(
                [
                    "constraintUnit",
                    "constraintList",
                    "constraintHash",
                    "not",
                    "and",
                    "or",
                    "key",
                    "literal",
                    "matchCase",
                    "propertyIsEqualTo",
                    "propertyIsBetween",
                    "propertyIsLike",
                    "propertyIsNull",
                    "lowerBoundary",
                    "constraint",
                    "wildCard",
                ]
            ),
            inner,
            max_size=3,
        )
    ),
    max_leaves=12,
)


@SETTINGS
@given(JSONISH)
def test_yaml_reader_only_raises_constraint_errors(data: object) -> None:
    try:
        tree = constraint_from_yaml(data)
    except ConstraintError as e:
        assert e.path.startswith("constraint")
    else:
        assert constraint_from_yaml(constraint_to_yaml(tree)) == tree
