"""Configuration sets: typed parameters, constraints and the active set."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from openel_async.rtc.configuration import (
    DEFAULT_SET,
    Configuration,
    ConfigurationError,
    ConfigValue,
    Container,
    ParameterSpec,
    ParamType,
    ScalarKind,
)
from openel_async.rtc.constraints import ConstraintSyntaxError, LessThan
from openel_async.rtc.profile import load_profile

from .strategies import SETTINGS

DATA = Path(__file__).parent / "data"


@pytest.mark.parametrize(
    ("name", "kind", "container"),
    [
        ("short", ScalarKind.INTEGER, Container.SCALAR),
        ("unsigned long", ScalarKind.INTEGER, Container.SCALAR),
        ("int", ScalarKind.INTEGER, Container.SCALAR),
        ("double", ScalarKind.FLOAT, Container.SCALAR),
        ("String", ScalarKind.STRING, Container.SCALAR),
        ("std::string", ScalarKind.STRING, Container.SCALAR),
        ("boolean", ScalarKind.BOOLEAN, Container.SCALAR),
        ("char", ScalarKind.CHAR, Container.SCALAR),
        ("vector<double>", ScalarKind.FLOAT, Container.SEQUENCE),
        ("std::vector< std::string >", ScalarKind.STRING, Container.SEQUENCE),
        ("sequence<long>", ScalarKind.INTEGER, Container.SEQUENCE),
        ("map<string, double>", ScalarKind.FLOAT, Container.MAP),
    ],
)
def test_type_names(name: str, kind: ScalarKind, container: Container) -> None:
    t = ParamType.parse(name)
    assert (t.kind, t.container) == (kind, container)


@pytest.mark.parametrize("name", ["RTC::TimedLong", "vector<vector<int>>", "map<int,int>", ""])
def test_unsupported_types(name: str) -> None:
    with pytest.raises(ValueError, match="unsupported parameter type"):
        ParamType.parse(name)
    with pytest.raises(ConfigurationError, match="unsupported parameter type"):
        ParameterSpec("p", name, "0")


@pytest.mark.parametrize(
    ("type_name", "text", "value"),
    [
        ("short", "-32768", -32768),
        ("short", " 32767 ", 32767),
        ("unsigned short", "65535", 65535),
        ("long", "-2147483648", -2147483648),
        ("long long", "9223372036854775807", 9223372036854775807),
        ("octet", "255", 255),
        ("double", "1e3", 1000.0),
        ("double", "-0.5", -0.5),
        ("double", "inf", float("inf")),
        ("float", "3.5", 3.5),
        ("boolean", "TRUE", True),
        ("boolean", "0", False),
        ("boolean", "off", False),
        ("char", "a", "a"),
        ("char", " ", " "),
        ("string", " keep spaces ", " keep spaces "),
        ("vector<double>", "1, 2.5 ,3", [1.0, 2.5, 3.0]),
        ("vector<long>", "", []),
        ("vector<string>", "a,b", ["a", "b"]),
        ("map<string,long>", "a:1, b : 2", {"a": 1, "b": 2}),
    ],
)
def test_values_parse_from_text(type_name: str, text: str, value: ConfigValue) -> None:
    spec = ParameterSpec("p", type_name, text)
    assert spec.parse(text).value == value


@pytest.mark.parametrize(
    ("type_name", "text", "reason"),
    [
        ("short", "32768", "out of range -32768..32767"),
        ("unsigned short", "-1", "out of range 0..65535"),
        ("long", "1.5", "expected an integer"),
        ("long", "1_000", "expected an integer"),
        ("octet", "256", "out of range 0..255"),
        ("double", "abc", "expected a number"),
        ("double", "1_0", "expected a number"),
        ("float", "1e39", "out of range for a 32-bit float"),
        ("boolean", "maybe", "expected true/false"),
        ("char", "ab", "single character"),
        ("char", "", "single character"),
        ("vector<long>", "1,x", "expected an integer"),
        ("map<string,long>", "a=1", "expected key:value"),
        ("map<string,long>", "a:1,a:2", "duplicate key 'a'"),
    ],
)
def test_bad_text_is_refused(type_name: str, text: str, reason: str) -> None:
    spec = ParameterSpec("p", type_name, "0" if "map" not in type_name else "")
    with pytest.raises(ConfigurationError) as info:
        spec.parse(text)
    assert reason in str(info.value)
    assert f"parameter 'p': value {text!r} is not a valid {type_name}" in str(info.value)
    assert info.value.parameter == "p" and info.value.value == text


@pytest.mark.parametrize(
    ("type_name", "value", "ok"),
    [
        ("double", 5, True),
        ("double", 2.5, True),
        ("double", True, False),
        ("long", 5, True),
        ("long", 5.0, False),
        ("long", False, False),
        ("boolean", True, True),
        ("boolean", 1, False),
        ("char", "x", True),
        ("vector<double>", [1, 2.5], True),
        ("vector<double>", (1.0,), True),
        ("vector<double>", [1, "a"], False),
        ("vector<string>", ["a,b"], False),  # cannot be written comma-separated
        ("vector<double>", 1.0, False),
        ("map<string,double>", {"k": 1}, True),
        ("map<string,double>", [1], False),
    ],
)
def test_python_values(type_name: str, value: object, ok: bool) -> None:
    spec = ParameterSpec("p", type_name, "" if "<" in type_name else "0")
    assert spec.check(value) is ok


def test_constraint_violation_names_parameter_value_and_constraint() -> None:
    config = Configuration([ParameterSpec.from_text("gain", "double", "150", "100<=x<=200")])
    with pytest.raises(ConfigurationError) as info:
        config.set_value(DEFAULT_SET, "gain", "250")
    e = info.value
    assert str(e) == (
        "set 'default': parameter 'gain': value '250' violates constraint '100<=x<=200'"
    )
    assert (e.parameter, e.value, e.constraint) == ("gain", "250", "100<=x<=200")
    assert config.get("gain") == 150.0  # the previous value is kept
    assert config.get_text("gain") == "150"


@pytest.mark.parametrize(
    ("constraint", "type_name", "value", "ok"),
    [
        ("100<=x<=200", "double", "100", True),
        ("100<=x<=200", "double", "200.0", True),
        ("100<=x<=200", "double", "99.99", False),
        ("100<x<200", "long", "100", False),
        ("100<x<200", "long", "101", True),
        ("x>=0", "short", "0", True),
        ("x>=0", "short", "-1", False),
        ("x<100", "double", 99.5, True),
        ("100", "double", "100.0", True),  # equality is numeric
        ("(100,200)", "double", "100", True),  # enumeration compares text exactly
        ("(100,200)", "double", "100.0", False),
        ("(100,200)", "double", 100.0, False),  # written as "100.0"
        ("(100,200)", "long", 100, True),
        ("(100,200)", "long", " 100 ", True),  # blanks around a number are not text
        ("(red,green)", "string", "red", True),
        ("(red,green)", "string", "Red", False),
        ("(red,green)", "string", " red", False),
        ("(true,false)", "boolean", True, True),
        ("(true,false)", "boolean", "1", False),
        ("x<1.5, x<3", "vector<double>", "1,2", True),
        ("x<1.5, x<3", "vector<double>", "2,2", False),
        ("x<1.5, x<3", "vector<double>", "1,2,2", False),
        ("0<=x<=1", "vector<double>", [0.5, 1, 0], True),
        ("0<=x<=1", "vector<double>", [0.5, 2], False),
        ("{k0: 100<x<200, k1: x>=100}", "map<string,double>", "k0:150,k1:100", True),
        ("{k0: 100<x<200, k1: x>=100}", "map<string,double>", "k0:150", False),
        ("{k0: 100<x<200, k1: x>=100}", "map<string,double>", {"k0": 200, "k1": 100}, False),
    ],
)
def test_constraints_on_typed_values(
    constraint: str, type_name: str, value: object, ok: bool
) -> None:
    default = {"vector<double>": "", "map<string,double>": "k0:150,k1:100"}.get(type_name, "0")
    spec = ParameterSpec.from_text("p", type_name, default, constraint)
    assert spec.check(value) is ok


@pytest.mark.parametrize(
    ("type_name", "constraint", "problem"),
    [
        ("double", "x<1, x<2", "a per-element list constraint needs a sequence type"),
        ("vector<double>", "{a: 1}", "a hash constraint needs a map type"),
        ("map<string,double>", "x<1", "a map type needs a hash constraint"),
    ],
)
def test_constraint_shape_must_fit_the_type(type_name: str, constraint: str, problem: str) -> None:
    with pytest.raises(ConfigurationError, match=problem):
        ParameterSpec.from_text("p", type_name, "", constraint)


def test_constraint_text_errors_are_syntax_errors() -> None:
    with pytest.raises(ConstraintSyntaxError):
        ParameterSpec.from_text("p", "double", "0", "x<<1")


def test_sets_and_activation() -> None:
    config = Configuration(
        [
            ParameterSpec.from_text("speed", "double", "1.0", "0<=x<=10", unit="m/s"),
            ParameterSpec.from_text("mode", "string", "auto", "(auto,manual)"),
        ]
    )
    assert list(config.set_names) == [DEFAULT_SET]
    assert config.active_set == DEFAULT_SET
    assert config.values() == {"speed": 1.0, "mode": "auto"}
    assert config.parameters["speed"].unit == "m/s"

    config.add_set("fast", {"speed": "8.5"})
    assert list(config.set_names) == [DEFAULT_SET, "fast"]
    assert config.get("speed") == 1.0  # adding does not activate
    config.activate_set("fast")
    assert config.active_set == "fast"
    assert config.get("speed") == 8.5
    assert config.get("mode") == "auto"  # copied from the base set
    assert config.get("speed", DEFAULT_SET) == 1.0

    config.set_value("fast", "mode", "manual")
    assert config.texts() == {"speed": "8.5", "mode": "manual"}
    assert config.texts(DEFAULT_SET) == {"speed": "1.0", "mode": "auto"}

    config.add_set("slow", {"speed": 0.5}, base="fast")
    assert config.values("slow") == {"speed": 0.5, "mode": "manual"}
    config.activate_set(DEFAULT_SET)
    config.remove_set("slow")
    assert list(config.set_names) == [DEFAULT_SET, "fast"]


def test_refused_operations_change_nothing() -> None:
    config = Configuration([ParameterSpec.from_text("speed", "double", "1.0", "0<=x<=10")])
    config.add_set("fast", {"speed": 5})
    config.activate_set("fast")
    refused: list[tuple[Callable[[], object], str]] = [
        (lambda: config.set_value("fast", "speed", 11), "violates constraint '0<=x<=10'"),
        (lambda: config.set_value("fast", "speed", "quick"), "is not a valid double"),
        (lambda: config.set_value("nope", "speed", 1), "unknown configuration set 'nope'"),
        (lambda: config.set_value("fast", "torque", 1), "unknown parameter 'torque'"),
        (lambda: config.activate_set("nope"), "unknown configuration set"),
        (lambda: config.add_set("fast"), "already exists"),
        (lambda: config.add_set("other", {"speed": 99}), "set 'other': parameter 'speed'"),
        (lambda: config.add_set("other", base="nope"), "unknown configuration set"),
        (lambda: config.remove_set(DEFAULT_SET), "cannot remove"),
        (lambda: config.remove_set("fast"), "cannot remove"),
        (lambda: config.get("torque"), "unknown parameter"),
    ]
    for action, message in refused:
        with pytest.raises(ConfigurationError, match=message):
            action()
    assert list(config.set_names) == [DEFAULT_SET, "fast"]
    assert config.active_set == "fast"
    assert config.values() == {"speed": 5.0}


def test_returned_containers_are_copies() -> None:
    config = Configuration([ParameterSpec("v", "vector<long>", "1,2")])
    value = config.get("v")
    assert isinstance(value, list)
    value.append(3)
    assert config.get("v") == [1, 2]


def test_defaults_are_checked() -> None:
    spec = ParameterSpec.from_text("gain", "double", "500", "x<100")
    with pytest.raises(ConfigurationError, match="default value: parameter 'gain'"):
        Configuration([spec])
    assert Configuration([spec], check_defaults=False).get("gain") == 500.0
    with pytest.raises(ConfigurationError, match="not a valid double"):
        Configuration([ParameterSpec("gain", "double", "fast")], check_defaults=False)
    with pytest.raises(ConfigurationError, match="duplicate parameter"):
        Configuration([spec, spec], check_defaults=False)


def test_configuration_from_the_spec_sample() -> None:
    profile = load_profile(DATA / "rtc_sample.xml")
    # The sample's own default for config2 ("Sample") is not one of its enumerated values.
    with pytest.raises(ConfigurationError) as info:
        Configuration.from_profile(profile)
    assert info.value.parameter == "config2"
    assert info.value.constraint == "(up,down,left,right) (ignoring case)"

    config = Configuration.from_profile(profile, check_defaults=False)
    assert config.values() == {"config1": 10, "config2": "Sample"}
    assert config.parameters["config1"].constraint == LessThan("100", match_case=False)
    config.set_value(DEFAULT_SET, "config1", "99")
    with pytest.raises(ConfigurationError, match="violates constraint 'x<100'"):
        config.set_value(DEFAULT_SET, "config1", "100")
    config.set_value(DEFAULT_SET, "config2", "LEFT")  # matchCase="false"
    assert config.get("config2") == "LEFT"
    assert config.get("config1") == 99


def test_configuration_from_profiles_without_a_set() -> None:
    profile = load_profile(DATA / "rtc_sample.yaml")
    assert Configuration.from_profile(profile.configuration_set, check_defaults=False).values()
    assert Configuration.from_profile(None).values() == {}


@SETTINGS
@given(low=st.integers(-1000, 1000), span=st.integers(0, 1000), value=st.integers(-3000, 3000))
def test_range_acceptance_matches_the_bounds(low: int, span: int, value: int) -> None:
    high = low + span
    spec = ParameterSpec.from_text("p", "long", str(low), f"{low}<=x<={high}")
    config = Configuration([spec])
    inside = low <= value <= high
    try:
        config.set_value(DEFAULT_SET, "p", value)
    except ConfigurationError:
        assert not inside
        assert config.get("p") == low
    else:
        assert inside
        assert config.get("p") == value


@SETTINGS
@given(
    st.text(max_size=12), st.sampled_from(["short", "double", "boolean", "char", "vector<long>"])
)
def test_text_values_are_parsed_or_refused(text: str, type_name: str) -> None:
    spec = ParameterSpec("p", type_name, "" if "<" in type_name else "0")
    try:
        parsed = spec.parse(text)
    except ConfigurationError as e:
        assert e.parameter == "p" and e.value == text
    else:
        assert parsed.text == text
        again = spec.parse(parsed.value).value  # the Python value writes back
        assert again == parsed.value or again != again  # (NaN is not equal to itself)
