"""Loading, validating and writing RTC Profiles in the YAML form."""

from __future__ import annotations

import copy
from datetime import datetime
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import given
from hypothesis import strategies as st

from openel_async.rtc.constraints import Between, Enumeration, LessThan
from openel_async.rtc.profile import (
    ComponentType,
    InterfaceDirection,
    Position,
    ProfileError,
    RtcProfile,
    dumps_yaml,
    load_profile,
    loads_yaml,
    save_profile,
)

from .strategies import SETTINGS, profiles

DATA = Path(__file__).parent / "data"
DATE = {"year": 2024, "month": 5, "day": 1, "hour": 12, "minute": 30, "second": 0}
MINIMAL: dict[str, Any] = {
    "rtcProfile": {
        "id": "RTC:Vendor:Cat:Comp:1.0.0",
        "version": "0.2",
        "basicInfo": {
            "name": "Comp",
            "componentType": "STATIC",
            "activityType": "PERIODIC",
            "componentKind": "DataFlowComponent",
            "category": "Cat",
            "executionType": "PeriodicExecutionContext",
            "vendor": "Vendor",
            "version": "1.0.0",
            "creationDate": DATE,
            "updateDate": DATE,
        },
        "actions": {"onExecute": {"implemented": True}},
        "configurationSet": {
            "configuration": [
                {"name": "gain", "type": "double", "defaultValue": "1.5"},
                {"name": "mode", "type": "string", "defaultValue": ""},
                {"name": "limit", "type": "int", "defaultValue": "3"},
            ]
        },
        "dataPorts": [
            {"portType": "DataInPort", "name": "in", "type": "RTC::TimedDouble"},
        ],
    }
}


def assert_loads_or_profile_error(text: str) -> None:
    """The documented contract: a profile, or a ProfileError that names a path."""
    try:
        result = loads_yaml(text)
    except ProfileError as e:
        assert e.path and e.message
    else:
        assert isinstance(result, RtcProfile)


def load_modified(change: Any) -> RtcProfile:
    """Load MINIMAL after ``change(doc)`` edited a deep copy of it."""
    doc = copy.deepcopy(MINIMAL)
    change(doc["rtcProfile"])
    return loads_yaml(yaml.safe_dump(doc))


def test_minimal_profile() -> None:
    p = load_modified(lambda d: None)
    assert p.basic_info.creation_date == datetime(2024, 5, 1, 12, 30)
    assert [c.name for c in p.configurations] == ["gain", "mode", "limit"]
    assert p.configurations[1].default_value == ""
    assert p.actions.on_execute is not None and p.actions.on_execute.implemented
    assert p.data_ports[0].ext is None
    assert p.language is None


def test_spec_sample() -> None:
    p = load_profile(DATA / "rtc_sample.yaml")
    b = p.basic_info
    assert p.id == "RTC:SampleVendor:SampleCategory:SampleComponent:1.0.0"
    assert p.version == "0.2"
    assert (b.name, b.component_type, b.max_instances) == (
        "SampleComponent",
        ComponentType.STATIC,
        1,
    )
    assert b.execution_rate == 1000.0
    assert b.creation_date == datetime(2008, 4, 18, 14, 0, 0)
    assert b.update_date == datetime(2008, 4, 17, 14, 0, 0)
    assert b.doc.algorithm == "SampleAlgorithm"
    assert b.ext.save_project == "SampleSaveProject"
    assert b.ext.version_up_logs == ("2008/04/18 14:00:00:Ver1.0", "2008/04/18 17:00:00:Ver1.1")
    assert [(x.name, x.value) for x in b.ext.properties] == [("SampleName", "SampleValue")]
    assert len(list(p.actions.items())) == 12
    assert p.actions.on_state_update is not None
    assert p.actions.on_state_update.doc.pre_condition == "on_state_update Pre_condition"
    config1, config2 = p.configurations
    assert config1.constraint == LessThan("100", match_case=True)
    assert config1.variable_name == "var1"
    assert config1.ext.properties[0].name == "SampleName"  # single mapping accepted
    assert config1.doc.range == "config_range1"
    assert config2.constraint == Enumeration(("up", "down", "left", "right"))
    assert config2.variable_name == "config2"
    in1, in2, out1, out2 = p.data_ports
    assert in1.constraint == Between("100", "200")
    assert in1.ext is not None and in1.ext.position is Position.LEFT
    assert in2.ext is not None and in2.ext.position is Position.LEFT  # alias *58
    assert out2.ext is not None and out2.ext.position is Position.RIGHT  # alias *62
    assert in2.variable_name == "inport2"
    assert out1.doc.semantics == "Out1Semantics"
    srv1, srv2 = p.service_ports
    assert [t.kind for t in srv1.trans_methods] == ["CORBA"]
    assert [i.direction for i in srv1.interfaces] == [
        InterfaceDirection.PROVIDED,
        InterfaceDirection.REQUIRED,
    ]
    assert srv1.interfaces[0].varname == "IF1VarName"
    assert srv2.doc.ifdescription == "ServicePort2 I/F description"
    assert [(x.name, x.default_value) for x in p.parameters] == [
        ("param1", "param_def1"),
        ("param2", "param_def2"),
    ]
    assert p.language is not None and p.language.ext is not None
    (target,) = p.language.ext.targets
    assert target.os_versions == ("2.4", "2.6")
    assert target.cpus == ("i386", "ARM")
    assert [(lib.name, lib.version) for lib in target.libraries] == [
        ("SampleLib", "1.0"),
        ("SampleLib2", "1.5"),
    ]


def test_sample_round_trip(tmp_path: Path) -> None:
    p = load_profile(DATA / "rtc_sample.yaml")
    assert loads_yaml(dumps_yaml(p)) == p
    for name in ("copy.yaml", "copy.YML"):
        save_profile(p, tmp_path / name)
        assert load_profile(tmp_path / name) == p


def test_dump_uses_the_spec_forms() -> None:
    text = dumps_yaml(load_profile(DATA / "rtc_sample.yaml"))
    doc = yaml.safe_load(text)["rtcProfile"]
    assert doc["basicInfo"]["creationDate"] == {
        "year": 2008,
        "month": 4,
        "day": 18,
        "hour": 14,
        "minute": 0,
        "second": 0,
    }
    assert doc["dataPorts"][0]["rtcExt::position"] == "LEFT"
    assert doc["actions"]["onAborting"]["implemented"] is True
    assert doc["dataPorts"][0]["constraint"] == {
        "constraintUnit": {"propertyIsBetween": {"lowerBoundary": "100", "upperBoundary": "200"}}
    }


def test_plain_scalars_keep_their_text() -> None:
    text = yaml.safe_dump(MINIMAL)
    text = text.replace("version: 1.0.0", "version: 1.10")
    text = text.replace("defaultValue: '1.5'", "defaultValue: 010")
    p = loads_yaml(text)
    assert p.basic_info.version == "1.10"
    assert p.configurations[0].default_value == "010"


@pytest.mark.parametrize(
    ("remove", "path"),
    [
        (("basicInfo", "name"), "rtcProfile.basicInfo.name"),
        (("basicInfo", "vendor"), "rtcProfile.basicInfo.vendor"),
        (("basicInfo", "creationDate"), "rtcProfile.basicInfo.creationDate"),
        (("basicInfo", "creationDate", "month"), "rtcProfile.basicInfo.creationDate.month"),
        (("basicInfo",), "rtcProfile.basicInfo"),
        (("actions",), "rtcProfile.actions"),
        (("id",), "rtcProfile.id"),
        (("actions", "onExecute", "implemented"), "rtcProfile.actions.onExecute.implemented"),
        (
            ("configurationSet", "configuration", 2, "defaultValue"),
            "rtcProfile.configurationSet.configuration[2].defaultValue",
        ),
        (
            ("configurationSet", "configuration", 0, "type"),
            "rtcProfile.configurationSet.configuration[0].type",
        ),
        (("dataPorts", 0, "portType"), "rtcProfile.dataPorts[0].portType"),
    ],
)
def test_missing_required_field_names_the_path(remove: tuple[Any, ...], path: str) -> None:
    def change(d: Any) -> None:
        for part in remove[:-1]:
            d = d[part]
        del d[remove[-1]]

    with pytest.raises(ProfileError) as info:
        load_modified(change)
    assert info.value.path == path
    assert info.value.location is not None and info.value.location.source == "<string>"
    assert info.value.line is not None and info.value.column is not None
    assert str(info.value) == f"{info.value.location}: {path}: required field missing"


def _set(path: tuple[Any, ...], value: Any) -> Any:
    def change(d: Any) -> None:
        for part in path[:-1]:
            d = d[part]
        d[path[-1]] = value

    return change


@pytest.mark.parametrize(
    ("path", "value", "where", "message"),
    [
        (("basicInfo", "name"), ["a"], "rtcProfile.basicInfo.name", "expected a string"),
        (("basicInfo", "name"), "", "rtcProfile.basicInfo.name", "must not be empty"),
        (
            ("basicInfo", "componentType"),
            "FLOATING",
            "rtcProfile.basicInfo.componentType",
            "expected one of STATIC, UNIQUE, COMMUTATIVE",
        ),
        (
            ("basicInfo", "maxInstances"),
            "many",
            "rtcProfile.basicInfo.maxInstances",
            "expected an integer",
        ),
        (
            ("basicInfo", "executionRate"),
            "fast",
            "rtcProfile.basicInfo.executionRate",
            "expected a number",
        ),
        (
            ("basicInfo", "executionRate"),
            ".inf",
            "rtcProfile.basicInfo.executionRate",
            "expected a number",
        ),
        (
            ("basicInfo", "creationDate", "month"),
            13,
            "rtcProfile.basicInfo.creationDate",
            "invalid date",
        ),
        (
            ("basicInfo", "creationDate"),
            "yesterday",
            "rtcProfile.basicInfo.creationDate",
            "ISO 8601",
        ),
        (("basicInfo", "vendor"), "my vendor", "rtcProfile.basicInfo.vendor", "whitespace"),
        (("basicInfo", "version"), "1:0", "rtcProfile.basicInfo.version", "':'"),
        (
            ("actions", "onExecute", "implemented"),
            "perhaps",
            "rtcProfile.actions.onExecute.implemented",
            "expected a boolean",
        ),
        (("actions", "onExecute"), "yes", "rtcProfile.actions.onExecute", "expected a mapping"),
        (("dataPorts",), 5, "rtcProfile.dataPorts", "expected a sequence"),
        (
            ("dataPorts", 0, "portType"),
            "DataPort",
            "rtcProfile.dataPorts[0].portType",
            "DataInPort, DataOutPort",
        ),
        (("dataPorts", 0, "name"), "in port", "rtcProfile.dataPorts[0].name", "whitespace"),
        (
            ("configurationSet", "configuration", 1, "name"),
            "gain",
            "rtcProfile.configurationSet.configuration[1].name",
            "duplicate configuration name",
        ),
        (
            ("configurationSet", "configuration", 0, "constraint"),
            {"constraintUnit": {"propertyIsLessThan": {"matchCase": True}}},
            "rtcProfile.configurationSet.configuration[0].constraint.constraintUnit"
            ".propertyIsLessThan.literal",
            "required field missing",
        ),
        (
            ("dataPorts", 0, "rtcExt::comment"),
            "has ext",
            "rtcProfile.dataPorts[0].rtcExt::position",
            "required field missing",
        ),
    ],
)
def test_bad_fields_name_the_path(
    path: tuple[Any, ...], value: Any, where: str, message: str
) -> None:
    with pytest.raises(ProfileError) as info:
        load_modified(_set(path, value))
    assert info.value.path == where
    assert message in info.value.message


def test_duplicate_port_names_across_kinds() -> None:
    def change(d: dict[str, Any]) -> None:
        d["servicePorts"] = [{"name": "in"}]

    with pytest.raises(ProfileError, match="duplicate port name 'in'") as info:
        load_modified(change)
    assert info.value.path == "rtcProfile.servicePorts[0].name"


@pytest.mark.parametrize(
    "text",
    [
        "rtcProfile: !!python/object/apply:os.system ['echo unsafe']",
        "rtcProfile: !!python/name:os.system",
        "rtcProfile: !!python/object:builtins.object {}",
        "rtcProfile: !!python/tuple [1, 2]",
        "rtcProfile: !custom {a: 1}",
    ],
)
def test_unsafe_yaml_tags_are_refused(text: str) -> None:
    with pytest.raises(ProfileError, match="could not determine a constructor") as info:
        loads_yaml(text)
    assert info.value.path == "<document>"


def test_yaml_alias_bomb_is_refused() -> None:
    lines = ["a0: &a0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]"]
    lines += [f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 9)}]" for i in range(1, 10)]
    text = "\n".join(lines) + "\nrtcProfile: *a9\n"
    with pytest.raises(ProfileError, match="alias expansion"):
        loads_yaml(text)


def test_recursive_alias_is_refused() -> None:
    with pytest.raises(ProfileError, match="nested deeper"):
        loads_yaml("rtcProfile: &r {basicInfo: *r}")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            "rtcProfile: [unclosed",
            r"^<string>:2:1: <document>: invalid YAML: did not find expected ',' or '\]' "
            r"\(while parsing a flow sequence started at line 1, column 13\)",
        ),
        ("a: b\n  c: d", r"^<string>:2:4: <document>: invalid YAML: mapping values"),
        ("[" * 5000, "invalid YAML"),
        ("rtcProfile: !!int abc", "invalid YAML value"),
        ("- just\n- a list", "expected a mapping with the key 'rtcProfile'"),
        ("other: 1", "expected a mapping with the key 'rtcProfile'"),
        ("", "expected a mapping with the key 'rtcProfile'"),
        ("rtcProfile: {}\nextra: 1", "unknown top-level key"),
        ("a: 1\n---\nb: 2", "invalid YAML"),
        ("rtcProfile:\n  !!int 1: x", "keys must be strings"),
    ],
)
def test_malformed_documents(text: str, message: str) -> None:
    with pytest.raises(ProfileError, match=message):
        loads_yaml(text)


def test_unknown_keys_survive_a_round_trip() -> None:
    def change(d: dict[str, Any]) -> None:
        d["basicInfo"]["rtcExt::vendorUrl"] = "https://example.org"
        d["basicInfo"]["rtcDoc::doc"] = {"description": "x", "my:tutorial": {"steps": ["a", "b"]}}
        d["dataPorts"][0]["vendor::custom"] = None
        d["future:topLevel"] = [{"k": "v"}]

    p = load_modified(change)
    assert p.basic_info.extra == {"rtcExt::vendorUrl": "https://example.org"}
    assert p.basic_info.doc.extra == {"my:tutorial": {"steps": ["a", "b"]}}
    assert p.data_ports[0].extra == {"vendor::custom": None}
    assert p.extra == {"future:topLevel": [{"k": "v"}]}
    assert loads_yaml(dumps_yaml(p)) == p


def test_dumping_validates() -> None:
    p = load_modified(lambda d: None)
    bad = RtcProfile(
        id=p.id,
        version=p.version,
        basic_info=p.basic_info,
        data_ports=(p.data_ports[0], p.data_ports[0]),
    )
    with pytest.raises(ProfileError, match="duplicate port name"):
        dumps_yaml(bad)


def test_unknown_suffix(tmp_path: Path) -> None:
    with pytest.raises(ProfileError, match="unknown profile format"):
        load_profile(tmp_path / "profile.json")
    with pytest.raises(ProfileError, match="unknown profile format"):
        save_profile(load_modified(lambda d: None), tmp_path / "profile.txt")


@SETTINGS
@given(profiles(nested_extras=True))
def test_parse_dump_parse(profile: RtcProfile) -> None:
    text = dumps_yaml(profile)
    again = loads_yaml(text)
    assert again == profile
    assert dumps_yaml(again) == text


@SETTINGS
@given(st.text(max_size=200))
def test_garbage_text_only_raises_profile_errors(text: str) -> None:
    assert_loads_or_profile_error(text)


_KEYS = [
    "name",
    "basicInfo",
    "actions",
    "dataPorts",
    "rtcExt::position",
    "constraint",
    "constraintUnit",
    "creationDate",
    "year",
    "implemented",
    "onExecute",
    "portType",
]
JSONISH = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=4),
    lambda inner: (
        st.lists(inner, max_size=3) | st.dictionaries(st.sampled_from(_KEYS), inner, max_size=4)
    ),
    max_leaves=20,
)


@SETTINGS
@given(JSONISH)
def test_garbage_structures_only_raise_profile_errors(data: object) -> None:
    assert_loads_or_profile_error(yaml.safe_dump({"rtcProfile": data}))


@SETTINGS
@given(st.data())
def test_random_field_damage_only_raises_profile_errors(data: st.DataObject) -> None:
    doc = copy.deepcopy(MINIMAL)
    body = doc["rtcProfile"]
    section = data.draw(st.sampled_from(["basicInfo", "actions", "configurationSet", "dataPorts"]))
    body[section] = data.draw(JSONISH)
    assert_loads_or_profile_error(yaml.safe_dump(doc))


def test_rtcbuilder_plural_trans_methods_key() -> None:
    """RTCBuilder writes ``transMethods``; it is read as the spec's ``transMethod``."""
    text = (DATA / "rtc_sample.yaml").read_text(encoding="utf-8")
    assert "transMethod:" in text
    profile = loads_yaml(text.replace("transMethod:", "transMethods:"))
    port = profile.service_ports[0]
    assert [t.kind for t in port.trans_methods] == ["CORBA"]
    assert "transMethods" not in port.extra


def test_singular_and_plural_trans_methods_round_trip() -> None:
    """Both spellings in one port: every entry is read, and the profile written back
    (singular key) reads the same (the fuzzer found an empty singular key beside a
    plural one that came back different)."""
    text = (DATA / "rtc_sample.yaml").read_text(encoding="utf-8")
    block = "      transMethod:\n        kind: CORBA\n"
    assert block in text
    both = text.replace(block, block + "      transMethods:\n        - kind: TCP\n", 1)
    profile = loads_yaml(both)
    assert [t.kind for t in profile.service_ports[0].trans_methods] == ["CORBA", "TCP"]
    assert loads_yaml(dumps_yaml(profile)) == profile
    empty_singular = text.replace(
        block, "      transMethod:\n      transMethods:\n" + block[19:], 1
    )
    profile = loads_yaml(empty_singular)
    assert loads_yaml(dumps_yaml(profile)) == profile
