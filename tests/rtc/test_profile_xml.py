"""Loading, validating and writing RTC Profiles in the XML form."""

from __future__ import annotations

import dataclasses
import xml.etree.ElementTree as ET
from datetime import datetime
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from openel_async.rtc.constraints import Between, Enumeration, LessThan
from openel_async.rtc.profile import (
    BasicInfo,
    InterfaceDirection,
    Position,
    ProfileError,
    RtcProfile,
    dumps_xml,
    dumps_yaml,
    load_profile,
    loads_xml,
    loads_yaml,
    save_profile,
)
from openel_async.rtc.profile.xml_io import XSI_NS

from .strategies import SETTINGS, profiles

DATA = Path(__file__).parent / "data"
NS = (
    'xmlns:rtc="http://www.openrtp.org/namespaces/rtc" '
    'xmlns:rtcDoc="http://www.openrtp.org/namespaces/rtc_doc" '
    'xmlns:rtcExt="http://www.openrtp.org/namespaces/rtc_ext" '
    'xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"'
)
BASIC = (
    'rtc:name="Comp" rtc:componentType="STATIC" rtc:activityType="PERIODIC" '
    'rtc:componentKind="DataFlowComponent" rtc:category="Cat" '
    'rtc:executionType="PeriodicExecutionContext" rtc:vendor="Vendor" rtc:version="1.0.0" '
    'rtc:creationDate="2024-05-01T12:30:00" rtc:updateDate="2024-05-02T08:00:00"'
)
MINIMAL = f"""<?xml version="1.0" encoding="UTF-8"?>
<rtc:RtcProfile {NS} rtc:id="RTC:Vendor:Cat:Comp:1.0.0" rtc:version="0.2">
  <rtc:BasicInfo {BASIC}/>
  <rtc:Actions><rtc:OnExecute rtc:implemented="true"/></rtc:Actions>
  <rtc:ConfigurationSet>
    <rtc:Configuration rtc:name="gain" rtc:type="double" rtc:defaultValue="1.5"/>
    <rtc:Configuration rtc:name="mode" rtc:type="string" rtc:defaultValue=""/>
  </rtc:ConfigurationSet>
  <rtc:DataPorts rtc:portType="DataInPort" rtc:name="in" rtc:type="RTC::TimedDouble"/>
</rtc:RtcProfile>
"""


def test_minimal_profile() -> None:
    p = loads_xml(MINIMAL)
    assert p.basic_info.update_date == datetime(2024, 5, 2, 8, 0)
    assert [(c.name, c.default_value) for c in p.configurations] == [("gain", "1.5"), ("mode", "")]
    assert p.data_ports[0].ext is None
    assert loads_xml(dumps_xml(p)) == p


def test_spec_sample() -> None:
    p = load_profile(DATA / "rtc_sample.xml")
    b = p.basic_info
    assert (b.rtc_type, b.hardware_profile, b.max_instances) == ("Normal", "SampleProfile", 1)
    assert b.instance_limit == 1
    assert b.update_date == datetime(2008, 4, 18, 14, 0)
    assert b.doc.reference == "SampleReference"
    assert b.ext.version_up_logs == ("2008/04/18 14:00:00:Ver1.0", "2008/04/18 17:00:00:Ver1.1")
    assert len(list(p.actions.items())) == 12
    assert p.actions.on_aborting is not None and p.actions.on_aborting.implemented
    assert p.actions.on_aborting.doc.description == "on_aborting description"
    config1, config2 = p.configurations
    assert (config1.type, config1.unit, config1.variable_name) == ("int", "config_unit1", "var1")
    assert config1.ext.comment == "Sample"
    assert config1.constraint == LessThan("100", match_case=False)
    assert config1.doc.dataname == "dataname1"
    assert config2.constraint == Enumeration(("up", "down", "left", "right"), match_case=False)
    assert [p.name for p in p.data_ports] == ["inport1", "inport2", "outport1", "outport2"]
    positions = [port.ext.position if port.ext else None for port in p.data_ports]
    assert positions == [Position.LEFT, Position.LEFT, Position.RIGHT, Position.RIGHT]
    assert p.data_ports[0].constraint == Between("100", "200")
    assert p.data_ports[0].idl_file == "DataPort1.idl"
    assert p.data_ports[1].variable_name == "In2Var"
    srv1 = p.service_ports[0]
    assert srv1.ext is not None and srv1.ext.position is Position.LEFT
    assert srv1.interfaces[0].doc.doc_exception == "if1 Exception"
    assert srv1.interfaces[1].direction is InterfaceDirection.REQUIRED
    assert [t.kind for sp in p.service_ports for t in sp.trans_methods] == ["CORBA", "TCP"]
    assert p.language is not None and p.language.ext is not None
    assert p.language.ext.targets[0].lang_version == "JDK6"


def test_xml_and_yaml_samples_agree_where_the_spec_does() -> None:
    x = load_profile(DATA / "rtc_sample.xml")
    y = load_profile(DATA / "rtc_sample.yaml")
    assert x.id == y.id and x.version == y.version
    assert x.actions == y.actions
    assert x.language == y.language
    assert x.parameters == y.parameters
    assert [c.name for c in x.configurations] == [c.name for c in y.configurations]


@pytest.mark.parametrize("name", ["rtc_sample.xml", "rtc_sample.yaml"])
def test_round_trips_within_and_across_formats(name: str, tmp_path: Path) -> None:
    p = load_profile(DATA / name)
    assert loads_xml(dumps_xml(p)) == p
    assert loads_yaml(dumps_yaml(p)) == p
    assert loads_xml(dumps_xml(loads_yaml(dumps_yaml(p)))) == p
    save_profile(p, tmp_path / "copy.xml")
    assert load_profile(tmp_path / "copy.xml") == p


def test_dump_uses_the_schema_spelling() -> None:
    text = dumps_xml(load_profile(DATA / "rtc_sample.xml"))
    for fragment in (
        '<rtc:BasicInfo xsi:type="rtcExt:basic_info_ext"',
        "<rtcExt:VersionUpLogs>2008/04/18 14:00:00:Ver1.0</rtcExt:VersionUpLogs>",
        '<rtc:OnInitialize xsi:type="rtcDoc:action_status_doc" rtc:implemented="true">',
        '<rtc:propertyIsLessThan rtc:matchCase="false">',
        '<rtc:TransMethods rtc:kind="CORBA"/>',
        'rtcExt:position="LEFT"',
        '<rtc:Configuration xsi:type="rtcExt:configuration_ext"',
        'rtc:creationDate="2008-04-18T14:00:00"',
    ):
        assert fragment in text


def _without(text: str, fragment: str) -> str:
    assert fragment in text
    return text.replace(fragment, "", 1)


@pytest.mark.parametrize(
    ("text", "path", "message"),
    [
        (
            _without(MINIMAL, 'rtc:name="Comp" '),
            "rtcProfile.basicInfo.name",
            "required field missing",
        ),
        (
            _without(MINIMAL, 'rtc:id="RTC:Vendor:Cat:Comp:1.0.0"'),
            "rtcProfile.id",
            "required field missing",
        ),
        (
            _without(MINIMAL, ' rtc:defaultValue=""'),
            "rtcProfile.configurationSet.configuration[1].defaultValue",
            "required field missing",
        ),
        (
            _without(MINIMAL, 'rtc:implemented="true"'),
            "rtcProfile.actions.onExecute.implemented",
            "required field missing",
        ),
        (
            _without(MINIMAL, f"<rtc:BasicInfo {BASIC}/>"),
            "rtcProfile.basicInfo",
            "required field missing",
        ),
        (
            MINIMAL.replace('implemented="true"', 'implemented="sure"'),
            "rtcProfile.actions.onExecute.implemented",
            "expected a boolean",
        ),
        (
            MINIMAL.replace('"STATIC"', '"static"'),
            "rtcProfile.basicInfo.componentType",
            "expected one of STATIC, UNIQUE, COMMUTATIVE",
        ),
        (
            MINIMAL.replace("2024-05-01T12:30:00", "May 1st"),
            "rtcProfile.basicInfo.creationDate",
            "ISO 8601",
        ),
        (
            MINIMAL.replace('rtc:category="Cat"', 'rtc:category="Cat" rtc:maxInstances="1.5"'),
            "rtcProfile.basicInfo.maxInstances",
            "expected an integer",
        ),
        (
            MINIMAL.replace("<rtc:Actions>", f"<rtc:BasicInfo {BASIC}/><rtc:Actions>"),
            "rtcProfile.basicInfo",
            "expected one element",
        ),
        (
            MINIMAL.replace('rtc:name="in"', 'rtc:name="in" rtcExt:comment="c"'),
            "rtcProfile.dataPorts[0].rtcExt::position",
            "required field missing",
        ),
        (
            MINIMAL.replace('rtc:name="in"', 'rtc:name="in" rtcExt:position="middle"'),
            "rtcProfile.dataPorts[0].rtcExt::position",
            "expected one of left, right, top, bottom",
        ),
        (
            MINIMAL.replace(
                'rtc:defaultValue="1.5"/>',
                'rtc:defaultValue="1.5"><rtc:Constraint><rtc:ConstraintUnitType>'
                "<rtc:propertyIsLessThan/></rtc:ConstraintUnitType></rtc:Constraint>"
                "</rtc:Configuration>",
            ),
            "rtcProfile.configurationSet.configuration[0].constraint.ConstraintUnitType"
            ".propertyIsLessThan.literal",
            "required field missing",
        ),
    ],
)
def test_bad_fields_name_the_path(text: str, path: str, message: str) -> None:
    with pytest.raises(ProfileError) as info:
        loads_xml(text)
    assert info.value.path == path
    assert message in info.value.message


BILLION_LAUGHS = """<?xml version="1.0"?>
<!DOCTYPE lolz [
 <!ENTITY lol "lol">
 <!ENTITY lol1 "&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;">
 <!ENTITY lol2 "&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;">
 <!ENTITY lol3 "&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;">
 <!ENTITY lol9 "&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;">
]>
<rtc:RtcProfile xmlns:rtc="http://www.openrtp.org/namespaces/rtc" rtc:id="&lol9;"/>
"""
EXTERNAL_ENTITY = """<?xml version="1.0"?>
<!DOCTYPE r [<!ENTITY xxe SYSTEM "file:///etc/passwd">]>
<rtc:RtcProfile xmlns:rtc="http://www.openrtp.org/namespaces/rtc" rtc:id="&xxe;"/>
"""
PARAMETER_ENTITY = """<?xml version="1.0"?>
<!DOCTYPE r [<!ENTITY % ext SYSTEM "http://127.0.0.1:9/evil.dtd"> %ext;]>
<r/>
"""
EXTERNAL_DTD = '<?xml version="1.0"?><!DOCTYPE r SYSTEM "file:///etc/passwd"><r/>'


@pytest.mark.parametrize("text", [BILLION_LAUGHS, EXTERNAL_ENTITY, PARAMETER_ENTITY, EXTERNAL_DTD])
def test_unsafe_xml_is_refused(text: str) -> None:
    with pytest.raises(ProfileError, match="unsafe XML refused") as info:
        loads_xml(text)
    assert info.value.path == "<document>"
    assert "entit" in info.value.message  # says why a DTD is refused


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "invalid XML"),
        ("<rtc:RtcProfile", r"^<string>:1:\d+: <document>: invalid XML: unclosed token"),
        ("<a><b></a>", "invalid XML: mismatched tag"),
        ("<x:RtcProfile/>", "invalid XML: unbound prefix"),
        ("<RtcProfile xmlns='urn:other'/>", "expected an rtc:RtcProfile root element"),
        ("<Profile/>", "expected an rtc:RtcProfile root element"),
        (b'<?xml version="1.0" encoding="no-such-codec"?><a/>', "unknown encoding"),
        (b"<a>\xff</a>", "invalid XML"),
    ],
)
def test_malformed_documents(text: str | bytes, message: str) -> None:
    with pytest.raises(ProfileError, match=message):
        loads_xml(text)


def test_unqualified_attributes_and_spec_spellings_are_accepted() -> None:
    text = f"""<rtc:RtcProfile {NS} id="i" version="1">
      <rtc:BasicInfo {BASIC.replace("rtc:", "")}>
        <rtcExt:VersionUpLog>one</rtcExt:VersionUpLog>
        <rtcExt:VersionUpLogs>two</rtcExt:VersionUpLogs>
      </rtc:BasicInfo>
      <rtc:Actions/>
      <rtc:ServicePorts name="sp"><rtc:TransMethod kind="CORBA"/></rtc:ServicePorts>
    </rtc:RtcProfile>"""
    p = loads_xml(text)
    assert p.basic_info.name == "Comp"
    assert p.basic_info.ext.version_up_logs == ("one", "two")
    assert p.service_ports[0].trans_methods[0].kind == "CORBA"


def test_unknown_attributes_and_elements_survive() -> None:
    text = MINIMAL.replace(
        f"<rtc:BasicInfo {BASIC}/>",
        f'<rtc:BasicInfo {BASIC} rtcExt:vendorUrl="https://example.org" xsi:future="1">'
        '<rtcExt:Custom a="1"><rtcExt:Inner>text</rtcExt:Inner><rtcExt:Inner/></rtcExt:Custom>'
        "</rtc:BasicInfo>",
    ).replace(
        "<rtc:RtcProfile ",
        '<rtc:RtcProfile xsi:schemaLocation="http://www.openrtp.org/namespaces/rtc x.xsd" ',
    )
    p = loads_xml(text)
    assert p.basic_info.extra == {
        "rtcExt::vendorUrl": "https://example.org",
        f"{{{XSI_NS}}}future": "1",
        "rtcExt::Custom": {"a": "1", "Inner": ["text", {}]},
    }
    assert p.extra == {
        "{http://www.w3.org/2001/XMLSchema-instance}schemaLocation": (
            "http://www.openrtp.org/namespaces/rtc x.xsd"
        )
    }
    again = loads_xml(dumps_xml(p))
    assert again == p
    assert 'xsi:schemaLocation="http://www.openrtp.org/namespaces/rtc x.xsd"' in dumps_xml(p)
    assert loads_yaml(dumps_yaml(p)) == p


def test_awkward_text_survives() -> None:
    p = loads_xml(MINIMAL)
    tricky = "a \"quoted\" <tag> & 'apos'\n\tline\r\n  end "
    basic = p.basic_info
    changed = RtcProfile(
        id=p.id,
        version=p.version,
        basic_info=BasicInfo(
            name=basic.name,
            component_type=basic.component_type,
            activity_type=basic.activity_type,
            component_kind=basic.component_kind,
            category=basic.category,
            execution_type=basic.execution_type,
            vendor=basic.vendor,
            version=basic.version,
            creation_date=basic.creation_date,
            update_date=basic.update_date,
            description=tricky,
        ),
    )
    assert loads_xml(dumps_xml(changed)).basic_info.description == tricky
    bad = RtcProfile(
        id=p.id,
        version=p.version,
        basic_info=BasicInfo(**{**basic.__dict__, "description": "bell\x07"}),
    )
    with pytest.raises(ProfileError, match="cannot be written in XML"):
        dumps_xml(bad)


@SETTINGS
@given(profiles(nested_extras=False))
def test_parse_dump_parse(profile: RtcProfile) -> None:
    text = dumps_xml(profile)
    again = loads_xml(text)
    assert again == profile
    assert dumps_xml(again) == text


def assert_loads_or_profile_error(text: str | bytes) -> None:
    """The documented contract: a profile, or a ProfileError that names a path."""
    try:
        result = loads_xml(text)
    except ProfileError as e:
        assert e.path and e.message
    else:
        assert isinstance(result, RtcProfile)


@SETTINGS
@given(st.text(max_size=200) | st.binary(max_size=200))
def test_garbage_only_raises_profile_errors(text: str | bytes) -> None:
    assert_loads_or_profile_error(text)


@SETTINGS
@given(st.data())
def test_damaged_sample_only_raises_profile_errors(data: st.DataObject) -> None:
    """Delete or alter random attributes and elements of the spec's sample."""
    root = ET.fromstring((DATA / "rtc_sample.xml").read_bytes())  # trusted test data
    elements = list(root.iter())
    for _ in range(data.draw(st.integers(1, 4))):
        elem = data.draw(st.sampled_from(elements))
        action = data.draw(st.sampled_from(["drop attribute", "garble attribute", "drop child"]))
        if action != "drop child" and elem.attrib:
            key = data.draw(st.sampled_from(sorted(elem.attrib)))
            if action == "drop attribute":
                del elem.attrib[key]
            else:
                elem.attrib[key] = data.draw(st.sampled_from(["", " ", "x y", "-1", "true:"]))
        elif len(elem):
            elem.remove(data.draw(st.sampled_from(list(elem))))
    assert_loads_or_profile_error(ET.tostring(root))


def test_extras_lists_of_plain_values_round_trip_through_xml() -> None:
    """A YAML extra holding a list that mixes plain values and mappings used to come back
    from XML as [{'#text': ...}, ...] (found by the profile fuzzer)."""
    p = loads_xml(MINIMAL)
    extra = {"rtcExt::Transports": ["CORBA", {"kind": "zenoh"}, "shm"]}
    p = dataclasses.replace(p, basic_info=dataclasses.replace(p.basic_info, extra=extra))
    assert loads_xml(dumps_xml(p)).basic_info.extra == extra
    assert loads_yaml(dumps_yaml(p)) == p


@pytest.mark.parametrize(
    "value",
    [["one"], [{"a": "1"}], [{"#text": "t"}, "u"], ["a", ["b", "c"]], ["a", "  "]],
)
def test_extras_that_xml_cannot_tell_apart_are_refused_naming_the_field(value: object) -> None:
    p = loads_xml(MINIMAL)
    extra = {"rtcExt::Odd": value}
    p = dataclasses.replace(p, basic_info=dataclasses.replace(p.basic_info, extra=extra))
    with pytest.raises(ProfileError, match="Odd"):
        dumps_xml(p)
