"""Systems: the shipped three-RTC system runs on the virtual clock; bad system files
are refused before anything starts; RTSystemEditor's rtsys XML is read."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from openel_async import VirtualClock
from openel_async.rtc import LifeCycleState, ObjectState
from openel_async.rtc.runner import run_profile_cli
from openel_async.rtc.system import (
    SystemFileError,
    blocking_cycle,
    load_system,
    prepare_system,
    run_system,
    run_system_file,
)

APP = Path(__file__).resolve().parents[2] / "apps" / "pan_tilt_system"
SYSTEM = APP / "system.yaml"


async def test_shipped_system_runs(virtual_clock: VirtualClock) -> None:
    lines: list[str] = []
    prepared = prepare_system(load_system(SYSTEM), clock=virtual_clock)
    summary = await run_system(
        prepared,
        clock=virtual_clock,
        duration_s=3.0,
        handle_signals=False,
        live_interval_s=1.0,
        on_live=lines.append,
    )
    assert len(lines) == 3 and lines[0].startswith("t=    1.00 s | target ACTIVE 49")
    by_name = {c.name: c for c in summary.components}
    assert by_name["target"].cycles == 150 and by_name["tracker"].cycles == 300
    assert {c.state for c in summary.components} == {LifeCycleState.ACTIVE}
    # the sporadic head ran once per command that arrived
    head = prepared.component("head")
    assert by_name["head"].cycles == head.runs == by_name["tracker"].report["commands"]  # type: ignore[attr-defined]
    assert all(c.lost == 0 for c in summary.connectors)
    assert {c.kind for c in summary.connectors} == {"push/new", "push/flush", "pull"}
    error = float(str(by_name["tracker"].report["tracking error"]).split()[1])
    assert error < 0.1  # the head follows the target
    assert {c.rtc.state for c in prepared.components} == {ObjectState.FINALIZED}
    for connector in prepared.connectors:
        assert not connector.connected


def test_cli_runs_the_system(capsys: pytest.CaptureFixture[str]) -> None:
    assert run_profile_cli(SYSTEM, ["--virtual", "--duration", "1", "--live", "0.5"]) == 0
    out = capsys.readouterr().out
    assert "t=    0.50 s" in out and "summary" in out
    assert "tracker.command -> head.command [push/flush]" in out


def copy_app(tmp_path: Path) -> Path:
    target = tmp_path / "app"
    shutil.copytree(APP, target)
    return target / "system.yaml"


def edit(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new))


@pytest.mark.parametrize(
    ("old", "new", "match"),
    [
        ("profile: head.yaml", "profile: nohead.yaml", r"components\.head\.profile: no such file"),
        ("to: tracker.target", "to: tracker.targte", r"has no port 'targte'"),
        ("to: tracker.target", "to: trakker.target", r"no component 'trakker'"),
        ("from: target.target", "from: tracker.target", r"not an OutPort"),
        ("dataport.buffer.length: 4", "dataport.buffer.length: 0", r"dataport.buffer.length"),
        ("dataport.buffer.length: 4", "dataport.bufer.length: 4", r"connector property"),
        ("[tracker.head, head.head]", "[tracker.head, head.command]", r"not a service port"),
        ('amplitude: "0.6"', 'amplitude: "9"', r"amplitude.*violates constraint"),
        ("rate: 100", "rate: 0", r"rate"),
        ("type: periodic", "type: cyclic", r"periodic, event_driven or sporadic"),
    ],
)
def test_bad_system_refused_before_start(tmp_path: Path, old: str, new: str, match: str) -> None:
    path = copy_app(tmp_path)
    edit(path, old, new)
    with pytest.raises(SystemFileError, match=match):
        prepare_system(load_system(path), clock=VirtualClock())


def test_bad_system_cli_exit_status(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = copy_app(tmp_path)
    edit(path, "to: tracker.target", "to: tracker.nothere")
    assert run_profile_cli(path, ["--virtual", "--duration", "1"]) == 2
    err = capsys.readouterr().err
    assert "system.connections[0].to" in err and "nothere" in err


def test_profile_port_declared_with_another_type(tmp_path: Path) -> None:
    path = copy_app(tmp_path)
    edit(
        path.parent / "tracker.yaml",
        'name: command\n      portType: DataOutPort\n      type: "RTC::TimedDoubleSeq"',
        'name: command\n      portType: DataOutPort\n      type: "RTC::TimedLong"',
    )
    with pytest.raises(SystemFileError, match=r"dataPorts\[2\].*RTC::TimedLong"):
        prepare_system(load_system(path), clock=VirtualClock())


def test_cycle_of_blocking_connectors_refused(tmp_path: Path) -> None:
    path = copy_app(tmp_path)
    text = path.read_text()
    text = text.replace(
        "dataport.buffer.length: 4",
        "dataport.buffer.length: 4\n        dataport.buffer.write.full_policy: block",
    )
    text = text.replace(
        "dataport.dataflow_type: pull",
        "dataport.dataflow_type: pull\n        dataport.buffer.read.empty_policy: block",
    )
    path.write_text(text)
    with pytest.raises(
        SystemFileError,
        match=r"cycle of blocking connectors.*(tracker -> head -> tracker|head -> tracker -> head)",
    ) as info:
        prepare_system(load_system(path), clock=VirtualClock())
    # located at a connection of the cycle
    assert str(info.value).startswith(f"{path}:") and "system.connections[" in str(info.value)


def test_blocking_cycle_graph() -> None:
    assert blocking_cycle({"a": {"b"}, "b": {"c"}}) is None
    assert blocking_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert blocking_cycle({"a": {"a"}}) == ["a", "a"]


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("system: {}", "system.components"),
        ("systems: {}", r"s\.yaml:1:1: unknown key 'systems' \(did you mean 'system'\?"),
        ("system: {components: {a: {profile: x.yaml, colour: red}}}", "colour"),
        ("system: {components: {a.b: {profile: x.yaml}}}", "without '.'"),
        (
            "system: {components: {a: {profile: x.yaml}}, connections: [{from: a, to: b.c}]}",
            "component.port",
        ),
        ("system: [", r"s\.yaml:2:1: invalid YAML: did not find expected node content"),
    ],
)
def test_bad_yaml(tmp_path: Path, text: str, match: str) -> None:
    path = tmp_path / "s.yaml"
    path.write_text(text)
    with pytest.raises(SystemFileError, match=match):
        load_system(path)


RTSYS = """<?xml version="1.0" encoding="UTF-8"?>
<rts:RtsProfile rts:updateDate="2026-11-24T12:00:00.000+09:00" rts:creationDate="2026-11-24T12:00:00.000+09:00"
    rts:version="0.2" rts:id="RTSystem:OpenEL:PanTiltSystem:1.0"
    xmlns:rtsExt="http://www.openrtp.org/namespaces/rts_ext"
    xmlns:rts="http://www.openrtp.org/namespaces/rts"
    xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance">
  <rts:Components xsi:type="rtsExt:component_ext" rts:isRequired="true" rts:compositeType="None"
      rts:activeConfigurationSet="fast" rts:instanceName="target0" rts:pathUri="localhost/target0.rtc"
      rts:id="RTC:OpenEL:Demo:TargetSensor:1.0.0">
    <rts:DataPorts xsi:type="rtsExt:dataport_ext" rts:name="target0.target"/>
    <rts:ConfigurationSets rts:id="default">
      <rts:ConfigurationData rts:data="0.5" rts:name="amplitude"/>
    </rts:ConfigurationSets>
    <rts:ConfigurationSets rts:id="fast">
      <rts:ConfigurationData rts:data="0.3" rts:name="amplitude"/>
      <rts:ConfigurationData rts:data="1.0" rts:name="frequency"/>
    </rts:ConfigurationSets>
    <rts:ConfigurationSets rts:id="__widget__"/>
    <rts:ExecutionContexts xsi:type="rtsExt:execution_context_ext" rts:rate="25.0" rts:kind="PERIODIC" rts:id="0"/>
  </rts:Components>
  <rts:Components xsi:type="rtsExt:component_ext" rts:instanceName="tracker0" rts:id="RTC:OpenEL:Demo:Tracker:1.0.0">
    <rts:ExecutionContexts rts:rate="100.0" rts:kind="PERIODIC" rts:id="0"/>
  </rts:Components>
  <rts:Components xsi:type="rtsExt:component_ext" rts:instanceName="head0" rts:id="RTC:OpenEL:Demo:Head:1.0.0">
    <rtsExt:Properties rtsExt:value="head.yaml" rtsExt:name="openel.profile"/>
  </rts:Components>
  <rts:DataPortConnectors xsi:type="rtsExt:dataport_connector_ext" rts:subscriptionType="new"
      rts:dataflowType="push" rts:interfaceType="corba_cdr" rts:dataType="IDL:RTC/TimedDoubleSeq:1.0"
      rts:name="target0.target_tracker0.target" rts:connectorId="c1">
    <rts:sourceDataPort xsi:type="rtsExt:target_port_ext" rts:portName="target0.target" rts:instanceName="target0" rts:componentId="RTC:OpenEL:Demo:TargetSensor:1.0.0"/>
    <rts:targetDataPort xsi:type="rtsExt:target_port_ext" rts:portName="tracker0.target" rts:instanceName="tracker0" rts:componentId="RTC:OpenEL:Demo:Tracker:1.0.0"/>
    <rtsExt:Properties rtsExt:value="little,big" rtsExt:name="dataport.serializer.cdr.endian"/>
    <rtsExt:Properties rtsExt:value="2" rtsExt:name="dataport.buffer.length"/>
    <rtsExt:Properties rtsExt:value="{1:(100,50)}" rtsExt:name="POSITION"/>
  </rts:DataPortConnectors>
  <rts:DataPortConnectors rts:subscriptionType="flush" rts:dataflowType="push" rts:interfaceType="corba_cdr"
      rts:dataType="IDL:RTC/TimedDoubleSeq:1.0" rts:name="c2" rts:connectorId="c2">
    <rts:sourceDataPort rts:portName="tracker0.command" rts:instanceName="tracker0"/>
    <rts:targetDataPort rts:portName="head0.command" rts:instanceName="head0"/>
  </rts:DataPortConnectors>
  <rts:DataPortConnectors rts:subscriptionType="periodic" rts:pushInterval="100.0" rts:dataflowType="push"
      rts:interfaceType="corba_cdr" rts:dataType="IDL:RTC/TimedDoubleSeq:1.0" rts:name="c3" rts:connectorId="c3">
    <rts:sourceDataPort rts:portName="head0.measured" rts:instanceName="head0"/>
    <rts:targetDataPort rts:portName="tracker0.measured" rts:instanceName="tracker0"/>
  </rts:DataPortConnectors>
  <rts:ServicePortConnectors rts:name="svc" rts:connectorId="s1">
    <rts:sourceServicePort rts:portName="tracker0.head" rts:instanceName="tracker0"/>
    <rts:targetServicePort rts:portName="head0.head" rts:instanceName="head0"/>
  </rts:ServicePortConnectors>
</rts:RtsProfile>
"""


async def test_rtsys_xml_runs(tmp_path: Path, virtual_clock: VirtualClock) -> None:
    path = copy_app(tmp_path).parent / "PanTiltSystem.xml"
    path.write_text(RTSYS)
    spec = load_system(path)
    assert spec.name == "PanTiltSystem"
    target = spec.components[0]
    assert target.profile.name == "target_sensor.yaml"  # found by its id
    assert target.active_set == "fast" and "__widget__" not in target.configuration_sets
    assert target.context.rate_hz == 25.0
    conn = spec.connections[0]
    assert (str(conn.source), str(conn.target)) == ("target0.target", "tracker0.target")
    assert "dataport.serializer.cdr.endian" not in conn.properties
    assert spec.connections[2].properties["dataport.publisher.push_rate"] == "100.0"
    summary = await run_system_file(path, clock=virtual_clock, duration_s=1.0, handle_signals=False)
    by_name = {c.name: c for c in summary.components}
    assert by_name["target0"].cycles == 25 and by_name["tracker0"].cycles == 100
    assert [c.kind for c in summary.connectors] == ["push/new", "push/flush", "push/periodic"]


def test_rtsys_missing_profile(tmp_path: Path) -> None:
    path = tmp_path / "s.xml"
    path.write_text(RTSYS)
    with pytest.raises(
        SystemFileError, match="no RTC Profile with id 'RTC:OpenEL:Demo:TargetSensor"
    ):
        load_system(path)
