"""``openel-async rig check|show|schema``: exit codes and what they print."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from openel_async.cli import main as cli_main

ROOT = Path(__file__).resolve().parents[2]
RIGS = ROOT / "apps" / "openel_apps" / "rigs"


@pytest.mark.parametrize(
    "name",
    [
        "twoaxis-sim.yaml",
        "twoaxis-can.yaml",
        "arm2.yaml",
        "arm6.yaml",
        "pantilt-sim.yaml",
        "so101-mujoco.yaml",
        "csp4.yaml",
    ],
)
def test_every_shipped_rig_checks(name: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli_main(["rig", "check", str(RIGS / name)]) == 0
    assert f"{name}: ok (" in capsys.readouterr().out


def test_check_names_the_mistake_and_exits_1(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rig = tmp_path / "bad.yaml"
    rig.write_text(
        (RIGS / "twoaxis-can.yaml")
        .read_text()
        .replace("params: {node_id: 1}", "params: {node: 1}", 1)
    )
    assert cli_main(["rig", "check", str(rig)]) == 1
    err = capsys.readouterr().err
    assert "bad.yaml:" in err and "unknown key 'node'" in err and "did you mean 'node_id'" in err
    assert cli_main(["rig", "check", str(tmp_path / "missing.yaml")]) == 2


def test_check_warns_when_watchdogs_are_not_armed(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rig = tmp_path / "unguarded.yaml"
    rig.write_text(
        (RIGS / "twoaxis-can.yaml")
        .read_text()
        .replace("watchdog_timeout: 0.5", "watchdog_timeout: null")
    )
    assert cli_main(["rig", "check", str(rig)]) == 0
    assert "the watchdogs of MOTOR_1, MOTOR_2 are not armed" in capsys.readouterr().out


def test_schema_documents_every_field_and_every_bus_type(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert cli_main(["rig", "schema"]) == 0
    schema = json.loads(capsys.readouterr().out)
    defs = schema["$defs"]
    assert defs["SafetyDoc"]["properties"]["on_exit"]["enum"] == ["hold", "stop", "torque_off"]
    assert "watchdog" in defs["SafetyDoc"]["properties"]["watchdog_timeout"]["description"]
    variants = defs["RigDoc"]["properties"]["buses"]["anyOf"][0]["additionalProperties"]["anyOf"]
    types = {defs[v["$ref"].rsplit("/", 1)[1]]["properties"]["type"]["const"] for v in variants}
    assert {"can", "serial", "mujoco"} <= types
    assert defs["CanBusOptions"]["properties"]["interface"]["description"].startswith(
        "A python-can"
    )
