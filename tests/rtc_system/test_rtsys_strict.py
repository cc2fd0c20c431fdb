"""Strict rtsys files and located build errors (issue 21, point 1): an element or
attribute OpenRTP's RtsProfile schema does not declare is refused with the file, line and
column and a "did you mean"; names in other namespaces are extensions; real files still
load; a connector naming a port or component that does not exist is refused at the
place it is written, with a suggestion."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from openel_async import VirtualClock
from openel_async.rtc.system import SystemFileError, load_system, prepare_system
from openel_async.rtc.system.rtsys_schema import check_rtsys, parse_rtsys

from .test_system import RTSYS, copy_app, edit

DATA = Path(__file__).parent / "data"


def position(text: str, needle: str, occurrence: int = 0) -> tuple[int, int]:
    """1-based line and column of ``needle`` in ``text``."""
    index = -1
    for _ in range(occurrence + 1):
        index = text.index(needle, index + 1)
    before = text[:index]
    return before.count("\n") + 1, index - (before.rfind("\n") + 1) + 1


def rtsys(tmp_path: Path, text: str) -> Path:
    """``text`` as an rtsys file next to the shipped system's profiles."""
    path = copy_app(tmp_path).parent / "PanTiltSystem.xml"
    path.write_text(text)
    return path


def refused(path: Path) -> SystemFileError:
    with pytest.raises(SystemFileError) as info:
        prepare_system(load_system(path), clock=VirtualClock())
    return info.value


def test_the_base_rtsys_loads(tmp_path: Path) -> None:
    spec = load_system(rtsys(tmp_path, RTSYS))
    assert [c.name for c in spec.components] == ["target0", "tracker0", "head0"]


def test_misspelt_element_refused_with_position_and_suggestion(tmp_path: Path) -> None:
    text = RTSYS.replace(
        '<rts:ConfigurationSets rts:id="fast">', '<rts:ConfigurationSet rts:id="fast">'
    ).replace(
        '<rts:ConfigurationData rts:data="1.0" rts:name="frequency"/>\n    </rts:ConfigurationSets>',
        '<rts:ConfigurationData rts:data="1.0" rts:name="frequency"/>\n    </rts:ConfigurationSet>',
    )
    path = rtsys(tmp_path, text)
    line, column = position(text, "<rts:ConfigurationSet ")
    error = refused(path)
    assert str(error).startswith(
        f"{path}:{line}:{column}: rts:Components[0]: unknown element 'rts:ConfigurationSet' "
        "(did you mean 'rts:ConfigurationSets'?"
    )
    assert (error.line, error.column) == (line, column)


def test_misspelt_attribute_refused_with_position_and_suggestion(tmp_path: Path) -> None:
    text = RTSYS.replace(
        'rts:instanceName="tracker0" rts:id=', 'rts:instanceNme="tracker0" rts:id='
    )
    path = rtsys(tmp_path, text)
    line, column = position(text, "rts:instanceNme")
    assert str(refused(path)).startswith(
        f"{path}:{line}:{column}: rts:Components[1]: unknown attribute 'rts:instanceNme' "
        "(did you mean 'rts:instanceName'?"
    )


SVC_TARGET = '<rts:targetServicePort rts:portName="head0.head" rts:instanceName="head0"/>'


@pytest.mark.parametrize(
    ("edits", "needle", "message"),
    [
        # an attribute without its namespace is not the schema's (all are qualified)
        (
            [('rts:pushInterval="100.0"', 'pushInterval="100.0"')],
            "pushInterval=",
            "rts:DataPortConnectors[2]: unknown attribute 'pushInterval' "
            "(did you mean 'rts:pushInterval'?",
        ),
        # an rtsExt name where the element's type has none
        (
            [
                (
                    '<rts:ExecutionContexts rts:rate="100.0"',
                    '<rts:ExecutionContexts rtsExt:visible="true" rts:rate="100.0"',
                )
            ],
            "rtsExt:visible",
            "rts:Components[1].rts:ExecutionContexts[0]: unknown attribute 'rtsExt:visible'",
        ),
        # an xsi:type that is not a type of that element
        (
            [
                (
                    'xsi:type="rtsExt:component_ext" rts:instanceName="head0"',
                    'xsi:type="rtsExt:componnet_ext" rts:instanceName="head0"',
                )
            ],
            'xsi:type="rtsExt:componnet_ext"',
            "rts:Components[2]: xsi:type 'rtsExt:componnet_ext' is not a type this element "
            "can have (did you mean 'rtsExt:component_ext'?",
        ),
        # rtsExt:Properties under an xsi:type that does not have it (the base type)
        (
            [
                (
                    '<rts:ServicePortConnectors rts:name="svc"',
                    '<rts:ServicePortConnectors xsi:type="rts:serviceport_connector" '
                    'rts:name="svc"',
                ),
                (SVC_TARGET, SVC_TARGET + '\n    <rtsExt:Properties rtsExt:name="a"/>'),
            ],
            '<rtsExt:Properties rtsExt:name="a"',
            "rts:ServicePortConnectors[0]: unknown element 'rtsExt:Properties' "
            "(allowed: rts:sourceServicePort, rts:targetServicePort;",
        ),
    ],
)
def test_other_unknown_names_refused(
    tmp_path: Path, edits: list[tuple[str, str]], needle: str, message: str
) -> None:
    text = RTSYS
    for old, new in edits:
        assert old in text
        text = text.replace(old, new)
    path = rtsys(tmp_path, text)
    line, column = position(text, needle)
    assert str(refused(path)).startswith(f"{path}:{line}:{column}: {message}")


def test_foreign_namespace_extensions_accepted(tmp_path: Path) -> None:
    text = (
        RTSYS.replace(
            'xmlns:rts="http://www.openrtp.org/namespaces/rts"',
            'xmlns:rts="http://www.openrtp.org/namespaces/rts" xmlns:acme="urn:acme:rts-tools"',
        )
        .replace(
            'rts:instanceName="tracker0" rts:id=',
            'acme:colour="red" rts:instanceName="tracker0" rts:id=',
        )
        .replace(
            "<rts:ServicePortConnectors ",
            '<acme:Layout acme:grid="8"><acme:anything rts:whatever="1"/></acme:Layout>\n'
            "  <rts:ServicePortConnectors ",
        )
    )
    spec = load_system(rtsys(tmp_path, text))
    assert [c.name for c in spec.components] == ["target0", "tracker0", "head0"]
    assert len(spec.services) == 1


def test_openrtp_sample_passes_the_schema_check() -> None:
    # OpenRTP's own sample: rtsExt members on rts:RtsProfile without xsi:type
    path = DATA / "openrtp_test.xml"
    check_rtsys(parse_rtsys(path.read_bytes(), str(path)))
    with pytest.raises(SystemFileError, match="no RTC Profile with id 'RTC:SampleVendor") as info:
        load_system(path)  # its component's profile is not there: refused at rts:id
    text = path.read_text()
    line, _ = position(text, 'rts:id="RTC:SampleVendor')
    assert info.value.line == line


# The traits of files written by Choreonoid's OpenRTM plugin (rtsExt:Properties before
# rts:DataPorts, no rts:creationDate/updateDate) and of rtshell's rtsprofile test system
# (rtsExt:comment on the root, lower-case rtsExt:direction, rts:TargetComponent before
# rts:WaitTime): the schema's order, required attributes and enumerations are not
# enforced, its names are.
WRITTEN_BY_TOOLS = """<?xml version="1.0"?>
<rts:RtsProfile rts:version="0.2" rts:id="RTSystem:AIST:RTSystem:1.0.0" rtsExt:comment="tools"
\txmlns:rts="http://www.openrtp.org/namespaces/rts"
\txmlns:rtsExt="http://www.openrtp.org/namespaces/rts_ext"
\txmlns:xsi="http://www.w3.org/2001/XMLSchema-instance">
\t<rts:Components xsi:type="rtsExt:component_ext" rts:isRequired="false" rts:compositeType="None" rts:activeConfigurationSet="default" rts:instanceName="Target0" rts:pathUri="localhost/Target0.rtc" rts:id="RTC:Tools:Demo:Target:1.0.0">
\t\t<rtsExt:Properties rtsExt:value="false" rtsExt:name="OpenRTM_NS" />
\t\t<rts:DataPorts xsi:type="rtsExt:dataport_ext" rts:name="Target0.target">
\t\t\t<rtsExt:Properties rtsExt:value="DataOutPort" rtsExt:name="port.port_type" />
\t\t</rts:DataPorts>
\t\t<rts:ConfigurationSets rts:id="default" />
\t\t<rts:ExecutionContexts xsi:type="rtsExt:execution_context_ext" rts:id="0" rts:rate="50" rts:kind="PERIODIC" />
\t\t<rtsExt:Location rtsExt:direction="right" rtsExt:width="-1" rtsExt:height="-1" rtsExt:x="393" rtsExt:y="222" />
\t</rts:Components>
\t<rts:Components xsi:type="rtsExt:component_ext" rts:isRequired="false" rts:compositeType="None" rts:instanceName="Tracker0" rts:pathUri="localhost/Tracker0.rtc" rts:id="RTC:OpenEL:Demo:Tracker:1.0.0">
\t\t<rts:ExecutionContexts xsi:type="rtsExt:execution_context_ext" rts:id="0" rts:rate="100" rts:kind="PERIODIC" />
\t\t<rtsExt:Location rtsExt:direction="RIGHT" rtsExt:width="-1" rtsExt:height="-1" rtsExt:x="182" rtsExt:y="0" />
\t</rts:Components>
\t<rts:DataPortConnectors xsi:type="rtsExt:dataport_connector_ext" rts:connectorId="NoConnection_1" rts:name="Target0.target_Tracker0.target" rts:dataType="IDL:RTC/TimedDoubleSeq:1.0" rts:interfaceType="corba_cdr" rts:dataflowType="push" rts:subscriptionType="flush">
\t\t<rts:sourceDataPort xsi:type="rtsExt:target_port_ext" rts:portName="Target0.target" rts:instanceName="Target0" rts:componentId="RTC:Tools:Demo:Target:1.0.0">
\t\t\t<rtsExt:Properties rtsExt:value="localhost/Target0.rtc" rtsExt:name="COMPONENT_PATH_ID" />
\t\t</rts:sourceDataPort>
\t\t<rts:targetDataPort xsi:type="rtsExt:target_port_ext" rts:portName="Tracker0.target" rts:instanceName="Tracker0" rts:componentId="RTC:OpenEL:Demo:Tracker:1.0.0">
\t\t\t<rtsExt:Properties rtsExt:value="localhost/Tracker0.rtc" rtsExt:name="COMPONENT_PATH_ID" />
\t\t</rts:targetDataPort>
\t\t<rtsExt:Properties rtsExt:value="little,big" rtsExt:name="dataport.serializer.cdr.endian" />
\t\t<rtsExt:Properties rtsExt:value="{1:(306,19),2:(311,19)}" rtsExt:name="POSITION" />
\t</rts:DataPortConnectors>
\t<rts:StartUp>
\t\t<rts:targets xsi:type="rtsExt:condition_ext" rts:sequence="1">
\t\t\t<rts:TargetComponent rts:id="0" rts:instanceName="Target0" rts:componentId="RTC:Tools:Demo:Target:1.0.0"/>
\t\t\t<rts:WaitTime rts:waitTime="1000"/>
\t\t</rts:targets>
\t</rts:StartUp>
</rts:RtsProfile>
"""


def test_files_written_by_tools_load(tmp_path: Path) -> None:
    path = rtsys(tmp_path, WRITTEN_BY_TOOLS)
    edit(
        path.parent / "target_sensor.yaml",
        '"RTC:OpenEL:Demo:TargetSensor:1.0.0"',
        '"RTC:Tools:Demo:Target:1.0.0"',
    )
    spec = load_system(path)
    assert [(c.name, c.profile.name) for c in spec.components] == [
        ("Target0", "target_sensor.yaml"),
        ("Tracker0", "tracker.yaml"),
    ]
    (conn,) = spec.connections
    assert (str(conn.source), str(conn.target)) == ("Target0.target", "Tracker0.target")
    assert conn.properties["dataport.subscription_type"] == "flush"


def test_misspelt_port_in_rtsys_connector_located(tmp_path: Path) -> None:
    text = RTSYS.replace('rts:portName="tracker0.target"', 'rts:portName="tracker0.targte"')
    path = rtsys(tmp_path, text)
    line, column = position(text, 'rts:portName="tracker0.targte"')
    error = refused(path)
    assert str(error).startswith(
        f"{path}:{line}:{column}: rts:DataPortConnectors[0].targetDataPort: component "
        "'tracker0' has no port 'targte' (did you mean 'target'?"
    )


def test_misspelt_port_and_component_in_yaml_located(tmp_path: Path) -> None:
    path = copy_app(tmp_path)
    text = path.read_text()
    edit(path, "to: tracker.target", "to: tracker.targte")
    line, column = position(text, "tracker.target")
    error = refused(path)
    assert str(error).startswith(
        f"{path}:{line}:{column}: system.connections[0].to: component 'tracker' has no port "
        "'targte' (did you mean 'target'?"
    )
    edit(path, "[tracker.head, head.head]", "[tracker.head, haed.head]")
    edit(path, "to: tracker.targte", "to: tracker.target")
    line, column = position(path.read_text(), "haed.head")
    assert str(refused(path)).startswith(
        f"{path}:{line}:{column}: system.services[0][1]: no component 'haed' in the system "
        "(did you mean 'head'?"
    )


def test_cli_names_the_position(tmp_path: Path) -> None:
    path = copy_app(tmp_path)
    line, column = position(path.read_text(), "tracker.target")
    edit(path, "to: tracker.target", "to: tracker.targte")
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "openel_async.cli",
            "run",
            str(path),
            "--virtual",
            "--duration",
            "0.1",
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2
    assert done.stderr.startswith(
        f"openel-async run: {path}:{line}:{column}: system.connections[0].to: component "
        "'tracker' has no port 'targte' (did you mean 'target'?"
    ), done.stderr


def test_near_miss_of_the_rts_ext_namespace_refused(tmp_path: Path) -> None:
    # a typo in xmlns:rtsExt would make every rtsExt name an "extension", silently
    text = RTSYS.replace(
        'xmlns:rtsExt="http://www.openrtp.org/namespaces/rts_ext"',
        'xmlns:rtsExt="http://www.openrtp.org/namespaces/rts_ex"',
    )
    path = rtsys(tmp_path, text)
    line, column = position(text, 'xsi:type="rtsExt:component_ext"')
    assert str(refused(path)).startswith(
        f"{path}:{line}:{column}: rts:Components[0]: namespace "
        "'http://www.openrtp.org/namespaces/rts_ex' is not OpenRTP's (did you mean "
        "'http://www.openrtp.org/namespaces/rts_ext'?)"
    )
    # without xsi:type, at the first rtsExt name
    text = text.replace('xsi:type="rtsExt:component_ext" ', "")
    text = text.replace('xsi:type="rtsExt:dataport_ext" ', "")
    text = text.replace('xsi:type="rtsExt:execution_context_ext" ', "")
    path.write_text(text)
    line, column = position(text, '<rtsExt:Properties rtsExt:value="head.yaml"')
    assert str(refused(path)).startswith(f"{path}:{line}:{column}: rts:Components[2]: namespace ")


def test_text_in_an_element_only_element_refused(tmp_path: Path) -> None:
    text = RTSYS.replace("<rts:ServicePortConnectors ", "oops\n  <rts:ServicePortConnectors ")
    path = rtsys(tmp_path, text)
    line, column = position(text, "<rts:RtsProfile ")
    assert str(refused(path)).startswith(
        f"{path}:{line}:{column}: rts:RtsProfile: unexpected text 'oops'"
    )
