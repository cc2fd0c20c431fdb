"""Real profiles as RTCBuilder/OpenRTP and OpenRTM-aist write them (tests/rtc/data/real,
origins in its README): they validate, show and convert both ways; and the forms of
those tools that used to be refused (issue 13) or crash (issue 10, point 17)."""

from __future__ import annotations

import argparse
import copy
import subprocess
import sys
import xml.etree.ElementTree as ET
from datetime import datetime, timedelta, timezone
from pathlib import Path
from typing import Any

import pytest
import yaml

from openel_async.cli import profile_cmd
from openel_async.rtc.configuration import Configuration, ConfigurationError, ParameterSpec
from openel_async.rtc.constraints import (
    And,
    Between,
    ConstraintSyntaxError,
    GreaterThan,
    GreaterThanOrEqualTo,
    HashConstraint,
    LessThan,
    LessThanOrEqualTo,
    ListConstraint,
    constraint_from_xml,
    constraint_from_yaml,
    format_constraint,
    parse_constraint,
)
from openel_async.rtc.profile import (
    Parameter,
    PortType,
    ProfileError,
    RtcProfile,
    dumps_xml,
    dumps_yaml,
    load_profile,
    loads_xml,
    loads_yaml,
    xml_io,
    yaml_io,
)

REAL = Path(__file__).parent / "data" / "real"
PROFILES = sorted(p for p in REAL.iterdir() if p.suffix in (".xml", ".yaml"))
# The profile whose config2 default 'Sample' breaks its own enumeration (README).
BAD_DEFAULT = {"RtcSampleVer02.xml"}


def cli(argv: list[str]) -> int:
    parser = argparse.ArgumentParser()
    profile_cmd.add_parser(parser.add_subparsers(dest="command"))
    return profile_cmd.run(parser.parse_args(argv))


def test_the_real_set_is_there() -> None:
    assert len(PROFILES) >= 6
    assert (REAL / "README.md").read_text().count("|") > 40


@pytest.mark.parametrize("path", PROFILES, ids=lambda p: p.name)
def test_real_profiles_load_and_round_trip(path: Path) -> None:
    profile = load_profile(path)
    assert loads_yaml(dumps_yaml(profile)) == profile
    assert loads_xml(dumps_xml(profile)) == profile
    assert loads_xml(dumps_xml(loads_yaml(dumps_yaml(profile)))) == profile


@pytest.mark.parametrize("path", PROFILES, ids=lambda p: p.name)
def test_real_profiles_validate_show_and_convert_with_the_cli(
    path: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = cli(["profile", "validate", str(path)])
    out, err = capsys.readouterr()
    if path.name in BAD_DEFAULT:
        assert code == 1
        assert len(err.strip().splitlines()) == 1
        assert "config2" in err and "'Sample'" in err
    else:
        assert code == 0, err
        assert out.startswith(f"OK: {path}")
    assert cli(["profile", "show", str(path)]) == 0
    shown = capsys.readouterr().out
    assert load_profile(path).basic_info.name in shown
    other = ".yaml" if path.suffix == ".xml" else ".xml"
    converted = tmp_path / f"RTC{other}"
    back = tmp_path / f"back{path.suffix}"
    assert cli(["profile", "convert", str(path), str(converted)]) == 0
    assert cli(["profile", "convert", str(converted), str(back)]) == 0
    assert load_profile(converted) == load_profile(back) == load_profile(path)


@pytest.mark.parametrize("name", ["ConsoleOut.RTC.xml", "TestComp.RTC.xml"])
def test_ext_trig_profiles_show_with_the_console_script(name: str) -> None:
    # Was: "invalid: ... unsupported execution type 'ExtTrigExecutionContext'", exit 1
    # (issue 21, point 17).
    done = subprocess.run(
        [sys.executable, "-m", "openel_async.cli", "profile", "show", str(REAL / name)],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert done.stderr == ""
    lines = done.stdout.splitlines()
    assert lines[0] == f"id              {load_profile(REAL / name).id}"
    assert (
        "execution       ExtTrigExecutionContext (one cycle per tick, nominal rate 1000 Hz)"
        in lines
    )


def test_show_summarises_a_profile_whose_context_cannot_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # show is a summary: any profile that loads is shown; validate still refuses it.
    text = (REAL / "Motor.RTC.xml").read_text()
    path = tmp_path / "RTC.xml"
    path.write_text(text.replace("PeriodicExecutionContext", "OpenHRPExecutionContext"))
    assert cli(["profile", "show", str(path)]) == 0
    out = capsys.readouterr().out
    assert (
        "execution       OpenHRPExecutionContext at 1000 Hz (openel-async cannot run it: "
        "rtcProfile.basicInfo.executionType: unsupported execution type "
        "'OpenHRPExecutionContext'" in out
    )
    assert "motor_id" in out
    assert cli(["profile", "validate", str(path)]) == 1
    assert "unsupported execution type 'OpenHRPExecutionContext'" in capsys.readouterr().err


def test_language_ext_without_targets_loads() -> None:
    # Every OpenRTM-aist example ends with this line; spec 0.2 wanted a target.
    p = load_profile(REAL / "ConsoleIn.RTC.xml")
    assert p.language is not None and p.language.kind == "C++"
    assert p.language.ext is None  # nothing in it: the same as no ext
    assert p.basic_info.creation_date == datetime(
        2021, 3, 26, 10, 54, 5, tzinfo=timezone(timedelta(hours=9))
    )


def test_rtcbuilder_yaml_export_loads() -> None:
    p = load_profile(REAL / "YAMLSample_RTC_Ver03Ex.yaml")
    jst = timezone(timedelta(minutes=540))
    assert p.basic_info.creation_date == datetime(2008, 4, 18, 14, 0, 0, tzinfo=jst)
    # the plural rtcExt::properties is read as the properties, not left in extra
    assert [q.name for q in p.basic_info.ext.properties] == ["BasicPropKey1", "BasicPropKey2"]
    assert "rtcExt::properties" not in p.basic_info.extra
    assert [q.name for q in p.configurations[0].ext.properties] == [
        "Conf1PropKey1",
        "Conf1PropKey2",
    ]
    # dates go back out in RTCBuilder's mapping form
    data = yaml.safe_load(dumps_yaml(p))
    assert data["rtcProfile"]["basicInfo"]["creationDate"] == {
        "year": 2008,
        "month": 4,
        "day": 18,
        "hour": 14,
        "minute": 0,
        "second": 0,
        "timezone": 540,
    }


def _minimal_yaml(**basic: Any) -> dict[str, Any]:
    date = {"year": 2024, "month": 5, "day": 1, "hour": 12, "minute": 30, "second": 0}
    info = {
        "name": "Comp",
        "componentType": "STATIC",
        "activityType": "PERIODIC",
        "componentKind": "DataFlowComponent",
        "category": "Cat",
        "executionType": "PeriodicExecutionContext",
        "vendor": "Vendor",
        "version": "1.0.0",
        "creationDate": date,
        "updateDate": copy.deepcopy(date),
    }
    info.update(basic)
    return {
        "rtcProfile": {
            "id": "RTC:Vendor:Cat:Comp:1.0.0",
            "version": "0.3",
            "basicInfo": info,
            "actions": {"onExecute": {"implemented": True}},
        }
    }


@pytest.mark.parametrize(
    ("extra", "expected"),
    [
        ({"millisecond": "250"}, datetime(2024, 5, 1, 12, 30, 0, 250_000)),
        ({"fractionalSecond": "0.125"}, datetime(2024, 5, 1, 12, 30, 0, 125_000)),
        (
            {"timezone": "-300", "millisecond": "0", "fractionalSecond": "0.000"},
            datetime(2024, 5, 1, 12, 30, tzinfo=timezone(timedelta(hours=-5))),
        ),
        ({"timezone": "-2147483648"}, datetime(2024, 5, 1, 12, 30)),  # Java's "undefined"
    ],
)
def test_rtcbuilder_date_fields(extra: dict[str, str], expected: datetime) -> None:
    doc = _minimal_yaml()
    doc["rtcProfile"]["basicInfo"]["creationDate"].update(extra)
    p = loads_yaml(yaml.safe_dump(doc))
    assert p.basic_info.creation_date == expected
    assert loads_yaml(dumps_yaml(p)) == p


@pytest.mark.parametrize(
    ("extra", "where"),
    [
        ({"millisecond": "250", "fractionalSecond": "0.5"}, "creationDate.millisecond"),
        ({"timezone": "9999"}, "creationDate.timezone"),
        ({"fractionalSecond": "1.5"}, "creationDate.fractionalSecond"),
        ({"week": "3"}, "creationDate.week"),
    ],
)
def test_bad_date_fields_name_the_field(extra: dict[str, str], where: str) -> None:
    doc = _minimal_yaml()
    doc["rtcProfile"]["basicInfo"]["creationDate"].update(extra)
    with pytest.raises(ProfileError) as info:
        loads_yaml(yaml.safe_dump(doc))
    assert info.value.path == f"rtcProfile.basicInfo.{where}"


def test_event_ports_load() -> None:
    # Finite-state-machine components' event ports (RtcProfile_basic.xsd allows them).
    text = (REAL / "ConsoleIn.RTC.xml").read_text().replace("DataOutPort", "EventPort")
    p = loads_xml(text)
    assert p.data_ports[0].port_type is PortType.EVENT_PORT
    assert loads_yaml(dumps_yaml(p)) == p
    assert 'rtc:portType="EventPort"' in dumps_xml(p)


@pytest.mark.parametrize("encoding", ["Shift_JIS", "EUC-JP", "UTF-16"])
def test_xml_in_its_declared_encoding(encoding: str, tmp_path: Path) -> None:
    text = (
        (REAL / "ConsoleIn.RTC.xml")
        .read_text()
        .replace('encoding="UTF-8"', f'encoding="{encoding}"')
        .replace("Console input component", "コンソール入力コンポーネント")
    )
    path = tmp_path / "RTC.xml"
    path.write_bytes(text.encode(encoding))
    p = load_profile(path)
    assert p.basic_info.description == "コンソール入力コンポーネント"
    assert p == loads_xml(text.replace(f'encoding="{encoding}"', 'encoding="UTF-8"').encode())


def test_xml_encoding_errors_are_profile_errors() -> None:
    with pytest.raises(ProfileError, match="unknown encoding 'x-nope'"):
        loads_xml(b'<?xml version="1.0" encoding="x-nope"?><a/>')
    with pytest.raises(ProfileError, match="not valid Shift_JIS"):
        loads_xml(b'<?xml version="1.0" encoding="Shift_JIS"?><a>\x81</a>')


# -- constraints as OpenRTP writes and reads them -----------------------------------------

# (file, OpenRTP's text of it (its tests), our tree of that text)
FRAGMENTS = [
    (
        "Hash2.yaml",
        "{el1:100<=x,el2:150}",
        HashConstraint((("el1", GreaterThanOrEqualTo("100")), ("el2", parse_constraint("150")))),
    ),
    (
        "Array2.yaml",
        "100<=x,x<150,200",
        ListConstraint((GreaterThanOrEqualTo("100"), LessThan("150"), parse_constraint("200"))),
    ),
    ("GreaterLessEqual2.yaml", "150=>x>100", And((LessThanOrEqualTo("150"), GreaterThan("100")))),
    ("Enum.yaml", "(100,150)", parse_constraint("(100,150)")),
]


@pytest.mark.parametrize(("name", "text", "tree"), FRAGMENTS, ids=[f[0] for f in FRAGMENTS])
def test_rtcbuilder_yaml_constraint_form(name: str, text: str, tree: object) -> None:
    data = yaml.safe_load((REAL / "constraints" / name).read_text())
    value = data["rtcProfile"]["configurationSet"]["configuration"][0]["constraint"]
    assert constraint_from_yaml(value) == tree == parse_constraint(text)


def test_openrtp_xml_hash_constraint() -> None:
    root = ET.parse(REAL / "constraints" / "Hash2.xml").getroot()
    elem = root.find(".//{http://www.openrtp.org/namespaces/rtc}Constraint")
    assert elem is not None
    tree = constraint_from_xml(elem)
    assert isinstance(tree, HashConstraint)
    for value, ok in (({"el1": 100, "el2": 150}, True), ({"el1": 99, "el2": 150}, False)):
        assert tree.check(value) is ok
        assert parse_constraint("{el1:100<=x,el2:150}").check(value) is ok


@pytest.mark.parametrize(
    ("text", "tree", "canonical"),
    [
        ("100<x", GreaterThan("100"), "x>100"),
        ("100<=x", GreaterThanOrEqualTo("100"), "x>=100"),
        ("100>x", LessThan("100"), "x<100"),
        ("100>=x", LessThanOrEqualTo("100"), "x<=100"),
        ("100=>x", LessThanOrEqualTo("100"), "x<=100"),
        ("100>x>0", And((LessThan("100"), GreaterThan("0"))), "100>x>0"),
        ("100>=x>0", And((LessThanOrEqualTo("100"), GreaterThan("0"))), "100>=x>0"),
        ("100=>x=>0", Between("0", "100"), "0<=x<=100"),
        (
            "100<=x,x<150,200",
            ListConstraint((GreaterThanOrEqualTo("100"), LessThan("150"), parse_constraint("200"))),
            "x>=100, x<150, 200",
        ),
        (
            "{el1:100<=x,el2:150}",
            HashConstraint(
                (("el1", GreaterThanOrEqualTo("100")), ("el2", parse_constraint("150")))
            ),
            "{el1: x>=100, el2: 150}",
        ),
    ],
)
def test_openrtp_constraint_texts(text: str, tree: object, canonical: str) -> None:
    assert parse_constraint(text) == tree
    assert format_constraint(parse_constraint(text)) == canonical
    assert parse_constraint(canonical) == tree


# -- long numbers (issue 10, point 17) -------------------------------------------------------

LONG = "9" * 5000


@pytest.mark.parametrize(
    ("basic", "path"),
    [
        ({"maxInstances": LONG}, "rtcProfile.basicInfo.maxInstances"),
        ({"executionRate": LONG}, "rtcProfile.basicInfo.executionRate"),
        ({"executionRate": "1" + "0" * 400}, "rtcProfile.basicInfo.executionRate"),
    ],
)
def test_long_numbers_are_profile_errors(basic: dict[str, str], path: str) -> None:
    with pytest.raises(ProfileError) as info:
        loads_yaml(yaml.safe_dump(_minimal_yaml(**basic)))
    assert info.value.path == path
    assert len(str(info.value)) < 300


def test_long_date_year_is_a_profile_error() -> None:
    doc = _minimal_yaml()
    doc["rtcProfile"]["basicInfo"]["creationDate"]["year"] = LONG
    with pytest.raises(ProfileError) as info:
        loads_yaml(yaml.safe_dump(doc))
    assert info.value.path == "rtcProfile.basicInfo.creationDate.year"


def test_long_constraint_bounds() -> None:
    with pytest.raises(ConstraintSyntaxError, match="greater than upper bound") as info:
        parse_constraint(LONG + "<=x<=1")
    assert len(str(info.value)) < 400
    # a long literal that loads keeps every later check working
    c = parse_constraint("x<" + LONG)
    assert c.check(5) and c.check(1e308) and not c.check(float("inf"))
    assert not parse_constraint("x>" + LONG).check(10**100)
    spec = ParameterSpec.from_text("n", "long", "5", "x<" + LONG)
    assert spec.check("7")
    config = Configuration([spec])
    with pytest.raises(ConfigurationError, match=r"out of range|expected an integer"):
        config.set_value("default", "n", LONG)
    assert config.get("n") == 5


def test_long_numbers_give_one_line_from_the_cli(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "RTC.yaml"
    path.write_text(yaml.safe_dump(_minimal_yaml(maxInstances=LONG)))
    assert cli(["profile", "validate", str(path)]) == 1
    assert cli(["profile", "show", str(path)]) == 1
    err = capsys.readouterr().err
    assert err.count("rtcProfile.basicInfo.maxInstances: expected an integer") == 2
    assert "Traceback" not in err and len(err.splitlines()) == 2


def test_long_constraint_bounds_in_a_profile_give_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # Was: a traceback from profile show/validate (int() of a 5000-digit bound).
    doc = _minimal_yaml()
    doc["rtcProfile"]["configurationSet"] = {
        "configuration": [
            {
                "name": "gain",
                "type": "int",
                "defaultValue": "5",
                "constraint": {
                    "constraintUnit": {
                        "propertyIsBetween": {"lowerBoundary": LONG, "upperBoundary": "1"}
                    }
                },
            }
        ]
    }
    path = tmp_path / "RTC.yaml"
    path.write_text(yaml.safe_dump(doc))
    assert cli(["profile", "show", str(path)]) == 0
    assert "gain" in capsys.readouterr().out
    assert cli(["profile", "validate", str(path)]) == 1
    err = capsys.readouterr().err
    assert "parameter 'gain': value '5' violates constraint" in err
    assert len(err.splitlines()) == 1 and len(err) < 500


# -- unknown YAML keys written as XML (issue 10, point 17) -----------------------------------


@pytest.mark.parametrize(
    "key", ['my:a"><evil/><b x="', "my:two words", "rtcExt::a:b", "my::1st", "rtcExt::9"]
)
def test_keys_that_are_no_xml_names_are_refused(
    key: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    doc = _minimal_yaml(**{key: "value"})
    p = loads_yaml(yaml.safe_dump(doc))
    assert p.basic_info.extra[key] == "value"
    with pytest.raises(ProfileError, match="cannot be written as an XML name") as info:
        dumps_xml(p)
    assert info.value.path.startswith("rtcProfile.basicInfo.")
    source = tmp_path / "RTC.yaml"
    source.write_text(yaml.safe_dump(doc))
    out = tmp_path / "RTC.xml"
    assert cli(["profile", "convert", str(source), str(out)]) == 1
    assert not out.exists()
    assert "cannot be written as an XML name" in capsys.readouterr().err


def test_unknown_keys_that_are_xml_names_convert_and_validate(tmp_path: Path) -> None:
    doc = _minimal_yaml(**{"rtcExt::myTool": "x", "rtcExt::colour": "blue"})
    doc["rtcProfile"]["basicInfo"]["rtcExt::nested"] = {"inner": {"deep": "1"}}
    p = loads_yaml(yaml.safe_dump(doc))
    assert loads_xml(dumps_xml(p)).basic_info.extra["rtcExt::colour"] == "blue"


# -- one size limit for both forms ----------------------------------------------------------


def _many_parameters(count: int) -> RtcProfile:
    base = loads_yaml(yaml.safe_dump(_minimal_yaml()))
    params = tuple(Parameter(name=f"p{i}", default_value=str(i)) for i in range(count))
    return RtcProfile(
        id=base.id,
        version=base.version,
        basic_info=base.basic_info,
        actions=base.actions,
        parameters=params,
    )


def test_a_large_xml_converts_to_a_yaml_that_loads(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Was: 20 000 parameters converted to a YAML file refused for its node count. Scaled down
    # for speed (4 000 parameters, a 40 000-node limit): both forms count against one limit.
    monkeypatch.setattr(yaml_io, "MAX_NODES", 40_000)
    monkeypatch.setattr(xml_io, "MAX_NODES", 40_000)
    xml_path = tmp_path / "RTC.xml"
    xml_path.write_text(dumps_xml(_many_parameters(4_000)))
    yaml_path = tmp_path / "RTC.yaml"
    assert cli(["profile", "convert", str(xml_path), str(yaml_path)]) == 0
    assert load_profile(yaml_path) == load_profile(xml_path)


def test_writers_refuse_what_the_loaders_would(monkeypatch: pytest.MonkeyPatch) -> None:
    profile = _many_parameters(200)
    monkeypatch.setattr(yaml_io, "MAX_NODES", 500)
    monkeypatch.setattr(xml_io, "MAX_NODES", 500)
    for dump in (dumps_yaml, dumps_xml):
        with pytest.raises(ProfileError, match="more than 500 nodes"):
            dump(profile)
    small = _many_parameters(10)
    assert loads_yaml(dumps_yaml(small)) == small
    assert loads_xml(dumps_xml(small)) == small
