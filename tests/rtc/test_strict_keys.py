"""Strict profiles (issue 21, point 1): an unknown key is refused with the file, line
and column and a "did you mean" for near misses, in YAML and XML; keys that mark
themselves as extensions (``prefix::name``, a foreign XML namespace) stay accepted and
round-trip."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from openel_async.positioned import DocumentError, load_yaml
from openel_async.rtc.profile import (
    ProfileError,
    dumps_xml,
    dumps_yaml,
    load_profile,
    loads_xml,
    loads_yaml,
)

DATA = Path(__file__).parent / "data"
REAL = DATA / "real"

YAML = """\
rtcProfile:
  id: "RTC:Vendor:Cat:Comp:1.0.0"
  version: "0.3"
  basicInfo:
    name: Comp
    componentType: STATIC
    activityType: PERIODIC
    componentKind: DataFlowComponent
    category: Cat
    executionType: PeriodicExecutionContext
    executionRate: 100.0
    vendor: Vendor
    version: 1.0.0
    creationDate: {year: 2024, month: 5, day: 1, hour: 12, minute: 30, second: 0}
    updateDate: {year: 2024, month: 5, day: 1, hour: 12, minute: 30, second: 0}
  actions:
    onExecute: {implemented: true}
"""

XML = """\
<?xml version="1.0" encoding="UTF-8"?>
<rtc:RtcProfile xmlns:rtc="http://www.openrtp.org/namespaces/rtc"
    xmlns:vendor="urn:example:vendor"
    rtc:id="RTC:Vendor:Cat:Comp:1.0.0" rtc:version="0.2">
  <rtc:BasicInfo rtc:name="Comp" rtc:componentType="STATIC" rtc:activityType="PERIODIC"
      rtc:componentKind="DataFlowComponent" rtc:category="Cat"
      rtc:executionType="PeriodicExecutionContext" rtc:executionRate="100.0"
      rtc:vendor="Vendor" rtc:version="1.0.0"
      rtc:creationDate="2024-05-01T12:30:00" rtc:updateDate="2024-05-02T08:00:00"/>
  <rtc:Actions><rtc:OnExecute rtc:implemented="true"/></rtc:Actions>
</rtc:RtcProfile>
"""


def test_the_base_documents_load() -> None:
    assert loads_yaml(YAML).basic_info.execution_rate == 100.0
    assert loads_xml(XML).basic_info.execution_rate == 100.0


def test_a_misspelt_yaml_key_is_refused_with_line_column_and_did_you_mean(
    tmp_path: Path,
) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text(YAML.replace("executionRate:", "executionRat:"))
    with pytest.raises(ProfileError) as info:
        load_profile(bad)
    e = info.value
    assert (e.source, e.line, e.column) == (str(bad), 11, 5)
    assert e.path == "rtcProfile.basicInfo"
    assert str(e).startswith(f"{bad}:11:5: rtcProfile.basicInfo: unknown key 'executionRat'")
    assert "did you mean 'executionRate'?" in str(e)


def test_a_misspelt_xml_attribute_is_refused_with_line_column_and_did_you_mean(
    tmp_path: Path,
) -> None:
    bad = tmp_path / "bad.xml"
    bad.write_text(XML.replace("rtc:executionRate=", "rtc:executionRat="))
    with pytest.raises(ProfileError) as info:
        load_profile(bad)
    e = info.value
    # the attribute itself: line 7, after six spaces and the executionType attribute
    line = XML.splitlines()[6]
    assert (e.source, e.line, e.column) == (str(bad), 7, line.index("rtc:executionRate") + 1)
    assert "unknown attribute 'rtc:executionRat'" in str(e)
    assert "did you mean 'rtc:executionRate'?" in str(e)


def test_an_unknown_xml_element_and_text_are_refused() -> None:
    text = XML.replace(
        "<rtc:Actions>", '<rtc:DataPort rtc:name="x"/>\n  <rtc:Actions>'
    )  # DataPorts misspelt
    with pytest.raises(
        ProfileError,
        match=r"^<string>:10:3: rtcProfile: unknown element "
        r"'rtc:DataPort' \(did you mean 'rtc:DataPorts'\?",
    ) as info:
        loads_xml(text)
    assert info.value.line == 10
    with pytest.raises(ProfileError, match="unexpected text 'hello'"):
        loads_xml(XML.replace("<rtc:Actions>", "<rtc:Actions>hello"))


@pytest.mark.parametrize(
    ("wrong", "right", "hint"),
    [
        ("vendr", "vendor", "required field missing (did you mean it by 'vendr'?)"),
        ("action", "actions", "required field missing (did you mean it by 'action'?)"),
        ("implemnted", "implemented", "did you mean it by 'implemnted'?"),
        ("onExecut", "onExecute", "unknown key 'onExecut' (did you mean 'onExecute'?"),
        ("abstrct", "abstract", "unknown key 'abstrct' (did you mean 'abstract'?"),
        ("secnd", "second", "unknown date field 'secnd' (did you mean 'second'?"),
    ],
)
def test_every_level_is_strict_and_points_at_the_misspelt_key(
    wrong: str, right: str, hint: str
) -> None:
    text = YAML.replace("    vendor: Vendor\n", "    vendor: Vendor\n    abstract: A\n")
    text = text.replace(f"{right}:", f"{wrong}:", 1)
    assert wrong in text
    with pytest.raises(ProfileError) as info:
        loads_yaml(text, "p.yaml")
    e = info.value
    assert hint in str(e)
    assert e.source == "p.yaml" and e.line is not None and e.column is not None
    assert text.splitlines()[e.line - 1][e.column - 1 :].startswith(f"{wrong}:")


def test_a_yaml_syntax_error_names_the_file(tmp_path: Path) -> None:
    bad = tmp_path / "broken.yaml"
    bad.write_text(YAML.replace("  actions:", "  actions: [", 1))
    with pytest.raises(ProfileError) as info:
        load_profile(bad)
    assert str(info.value).startswith(f"{bad}:")
    assert "<unicode string>" not in str(info.value)
    assert info.value.line is not None


@pytest.mark.parametrize(
    "key", ["rtcExt::vendorUrl", "rtcDoc::tutorial", "acme::tuning", "acme:colour"]
)
def test_namespaced_yaml_keys_are_extensions_and_round_trip(key: str) -> None:
    text = YAML.replace("    vendor: Vendor\n", f"    vendor: Vendor\n    {key}: blue\n")
    p = loads_yaml(text)
    assert p.basic_info.extra == {key: "blue"}
    assert loads_yaml(dumps_yaml(p)) == p


def test_the_rtc_prefix_is_no_extension() -> None:
    with pytest.raises(ProfileError, match="unknown key 'rtc::executionRat'"):
        loads_yaml(YAML.replace("executionRate:", "rtc::executionRat:"))


def test_foreign_xml_names_are_extensions_and_round_trip() -> None:
    text = XML.replace(
        'rtc:updateDate="2024-05-02T08:00:00"/>',
        'rtc:updateDate="2024-05-02T08:00:00" vendor:tuning="fast">'
        '<vendor:Note vendor:by="me">text</vendor:Note></rtc:BasicInfo>',
    )
    p = loads_xml(text)
    assert p.basic_info.extra == {
        "{urn:example:vendor}tuning": "fast",
        "{urn:example:vendor}Note": {"by": "me", "#text": "text"},
    }
    assert loads_xml(dumps_xml(p)) == p
    assert loads_yaml(dumps_yaml(p)) == p


def test_rtcbuilders_occerrence_is_known() -> None:
    # OpenRTP's RtcProfile_doc.xsd spells the data port's occurrence "occerrence".
    for name in ("YAMLSample_RTC_Ver03Ex.yaml", "RtcSampleVer02.xml"):
        p = load_profile(REAL / name)
        assert p.data_ports[0].doc.occurrence == "In1Occerrence"
        assert p.data_ports[0].doc.extra == {}


def test_the_cli_names_file_line_column_and_suggestion(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text(YAML.replace("executionRate:", "executionRat:"))
    run = subprocess.run(
        [sys.executable, "-m", "openel_async.cli", "profile", "validate", str(bad)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert run.returncode != 0
    assert "bad.yaml:11:5" in run.stderr
    assert "did you mean 'executionRate'?" in run.stderr
    assert "OK" not in run.stdout


# -- positions ------------------------------------------------------------------------------

_KEYS = st.from_regex(r"[a-z][a-zA-Z0-9_]{0,8}", fullmatch=True)
_TREES = st.recursive(
    st.integers(0, 9) | st.just("x"),
    lambda inner: st.dictionaries(_KEYS, inner, min_size=1, max_size=3),
    max_leaves=12,
)


@given(st.dictionaries(_KEYS, _TREES, min_size=1, max_size=3), st.integers(0, 4))
def test_every_key_position_points_at_the_key(tree: dict[str, object], indent: int) -> None:
    import yaml

    text = yaml.safe_dump(tree, indent=indent + 2, default_flow_style=False)
    doc = load_yaml(text, "t.yaml")
    lines = text.splitlines()
    stack: list[object] = [doc.data]
    while stack:
        node = stack.pop()
        if isinstance(node, dict):
            for key, value in node.items():
                where = doc.key(node, key)
                assert where.line is not None and where.column is not None
                at = lines[where.line - 1][where.column - 1 :]
                assert at.startswith((f"{key}:", f"'{key}':"))  # YAML quotes "no", "on"
                stack.append(value)


def test_duplicate_keys_are_refused_with_both_positions() -> None:
    with pytest.raises(
        DocumentError,
        match=r"^d.yaml:3:1: invalid YAML: duplicate key 'a' "
        r"\(first at line 1, column 1\)",
    ):
        load_yaml("a: 1\nb: 2\na: 3\n", "d.yaml")


_ATTRS = [
    'rtc:name="Comp"',
    'rtc:componentType="STATIC"',
    'rtc:activityType="PERIODIC"',
    'rtc:componentKind="DataFlowComponent"',
    'rtc:category="Cat"',
    'rtc:executionType="PeriodicExecutionContext"',
    'rtc:executionRate="100.0"',
    'rtc:vendor="Vendor"',
    'rtc:version="1.0.0"',
    'rtc:creationDate="2024-05-01T12:30:00"',
    'rtc:updateDate="2024-05-02T08:00:00"',
]


@given(
    st.permutations(_ATTRS),
    st.lists(st.sampled_from([" ", "  ", "\n    ", "\n\t"]), min_size=11, max_size=11),
    st.sampled_from(["ü", "x"]),
)
def test_an_xml_attribute_position_points_at_the_attribute(
    attrs: list[str], gaps: list[str], letter: str
) -> None:
    attrs = [a.replace("executionRate=", "executionRat=") for a in attrs]
    attrs[0] = attrs[0].replace('"Comp"', f'"C{letter}mp"')  # non-ASCII before it, maybe
    head = "".join(gap + attr for gap, attr in zip(gaps, attrs, strict=True))
    text = (
        XML[: XML.index("<rtc:BasicInfo")]
        + "<rtc:BasicInfo"
        + head
        + "/>\n"
        + (XML[XML.index("  <rtc:Actions>") :])
    )
    with pytest.raises(ProfileError, match="unknown attribute 'rtc:executionRat'") as info:
        loads_xml(text.encode())
    e = info.value
    assert e.line is not None and e.column is not None
    line = text.splitlines()[e.line - 1]
    assert line[e.column - 1 :].startswith("rtc:executionRat="), (line, e.column)
