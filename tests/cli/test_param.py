"""``openel-async param``: every form against the shipped rigs with --sim (in process: the
CAN rig's ODrive and CiA 402 drive, the Dynamixel rig, the SO-101's Feetech servos), the
refusals (exit 2) before anything is written, and one run as its own process."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from openel_async.cli import main
from openel_async.cli.logs import reset_logging
from openel_async.errors import BadParameterError
from openel_async.params import ParameterInfo, close_matches, format_value, parse_value

RIGS = Path(__file__).resolve().parents[2] / "apps" / "openel_apps" / "rigs"
CAN = str(RIGS / "twoaxis-can.yaml")
DXL = str(RIGS / "dynamixel-pair.yaml")
SO101 = str(RIGS / "so101.yaml")


@pytest.fixture(autouse=True)
def _reset_logging() -> Iterator[None]:
    yield
    reset_logging()


def _json(capsys: pytest.CaptureFixture[str], argv: list[str]) -> dict[str, object]:
    assert main(argv) == 0, capsys.readouterr().err
    document = json.loads(capsys.readouterr().out)
    assert isinstance(document, dict)
    return document


def test_get_a_cia402_object_by_index_and_name(capsys: pytest.CaptureFixture[str]) -> None:
    got = _json(capsys, ["param", "get", CAN, "MOTOR_2", "0x6081:00", "--sim", "--json"])
    assert got["value"] == 10000
    assert got["parameter"] == {
        "name": "Profile velocity",
        "address": "0x6081:00",
        "type": "UNSIGNED32",
        "access": "rw",
        "unit": "inc/s",
        "scale": 1.0,
        "storage": "ram",
        "description": "",
    }
    assert main(["param", "get", CAN, "MOTOR_2", "Profile velocity", "--sim"]) == 0
    assert "MOTOR_2 Profile velocity = 10000 inc/s" in capsys.readouterr().out


def test_set_and_dump_an_odrive(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["param", "set", CAN, "MOTOR_1", "axis0.controller.config.vel_limit", "2.5", "--sim"]
    got = _json(capsys, [*argv, "--json"])
    assert (got["before"], got["written"], got["after"]) == (2.0, 2.5, 2.5)
    dump = _json(capsys, ["param", "dump", CAN, "MOTOR_1", "--sim", "--json"])
    values = {p["name"]: p.get("value") for p in dump["parameters"]}  # type: ignore[union-attr]
    assert values["axis0.config.can.node_id"] == 1
    assert values["vbus_voltage"] == 24.0
    assert not [p for p in dump["parameters"] if "error" in p]  # type: ignore[union-attr]


def test_dump_and_set_a_dynamixel(capsys: pytest.CaptureFixture[str]) -> None:
    dump = _json(capsys, ["param", "dump", DXL, "TILT", "--sim", "--json"])
    values = {p["name"]: p["value"] for p in dump["parameters"]}  # type: ignore[union-attr]
    assert values["Model Number"] == 1060  # the XL430-W250
    assert "Current Limit" not in values
    got = _json(
        capsys, ["param", "set", DXL, "PAN", "Velocity Limit", "300", "--sim", "--yes", "--json"]
    )
    assert got["after"] == 300 and got["torque_turned_off"] is False


def test_list_and_set_a_feetech_servo(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["param", "list", SO101, "gripper", "--sim"]) == 0
    out = capsys.readouterr().out
    assert "Torque Limit" in out and "eeprom" in out
    got = _json(
        capsys,
        [
            "param",
            "set",
            SO101,
            "gripper",
            "Max Temperature Limit",
            "60",
            "--sim",
            "--yes",
            "--json",
        ],
    )
    assert got["after"] == 60


@pytest.mark.parametrize(
    ("argv", "said"),
    [
        (["get", CAN, "MOTOR_2", "Profile velocty"], "did you mean 'Profile velocity'"),
        (["get", CAN, "MOTOR_3", "6081"], "component"),
        (["get", CAN, "MOTOR_2", "6081", "--timeout", "0"], "--timeout"),
        (["set", CAN, "MOTOR_2", "Controlword", "15"], "is a command"),
        (["set", CAN, "MOTOR_2", "Statusword", "1"], "cannot be written"),
        (["set", CAN, "MOTOR_2", "Profile velocity", "-1"], "0..4294967295"),
        (["set", DXL, "PAN", "ID", "3"], "give --yes"),
        (["get", str(RIGS / "pantilt-sim.yaml"), "pan", "x"], "on no bus"),
    ],
)
def test_refusals_exit_2_saying_why(
    argv: list[str], said: str, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(sys, "stdin", open("/dev/null"))  # noqa: SIM115 - no terminal to ask on
    assert main(["param", *argv, "--sim"] if "--timeout" not in argv else ["param", *argv]) == 2
    assert said in capsys.readouterr().err


def test_values_parsed_and_shown_with_units() -> None:
    info = ParameterInfo(
        "Profile Velocity", "112", "uint32", "rw", "rpm", scale=0.229, low=0, high=2**32 - 1
    )
    assert parse_value(info, "0x10") == 16
    assert format_value(info, 100) == "100 (22.9 rpm)"
    with pytest.raises(BadParameterError, match=r"0\.\.4294967295"):
        parse_value(info, "-1")
    flag = ParameterInfo("enable_watchdog", "endpoint 201", "bool", "rw", kind="bool")
    assert parse_value(flag, "on") is True and format_value(flag, False) == "false"
    rate = ParameterInfo("vel_ramp_rate", "endpoint 390", "float", "rw", "turns/s²", kind="float")
    assert parse_value(rate, "2.5") == 2.5 and format_value(rate, 2.5) == "2.5 turns/s²"
    with pytest.raises(BadParameterError, match="finite"):
        parse_value(rate, "nan")
    names = ["axis0.controller.config.vel_limit", "axis0.config.watchdog_timeout"]
    assert close_matches("vel_limt", names) == ["axis0.controller.config.vel_limit"]


def test_param_as_its_own_process() -> None:
    """The one subprocess run: the command line end to end, the ODrive's watchdog timeout
    read from the simulated axis as JSON."""
    result = subprocess.run(
        [sys.executable, "-m", "openel_async.cli", "param", "get", CAN, "MOTOR_1",
         "axis0.config.watchdog_timeout", "--sim", "--json"],
        capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    document = json.loads(result.stdout)
    assert document["parameter"]["address"] == "endpoint 200"
    assert document["value"] == 0.0 and document["shown"] == "0 s"


def test_json_values_are_valid_json_for_every_float() -> None:
    from openel_async.cli.param_cmd import value_json

    document = [value_json(v) for v in (float("nan"), float("inf"), -float("inf"), 1.5, b"\x01")]
    assert document == ["nan", "inf", "-inf", 1.5, "01"]
    assert json.loads(json.dumps(document, allow_nan=False)) == document
