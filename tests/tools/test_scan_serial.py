"""``openel-async scan serial`` (issue 25 point 1): Dynamixel and Feetech servos found by PING
through the driver's own ports, and an NMEA receiver by its sentences, on simulated devices
behind a pty that hear (or send) only at their own baud rate; the table, JSON and rig file;
the option refusals (exit 2)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from openel_async.cli import main
from openel_async.rig import load_rig, resolve_rig
from openel_serial.peers import PeerThread, SimDynamixelBus, SimGps, SimServo
from openel_serial.scan import parse_ids, scan, scan_nmea

ROOT = Path(__file__).resolve().parents[2]
SO101 = ROOT / "apps" / "openel_apps" / "rigs" / "so101.yaml"

DXL_RIG = """\
buses:
  arm: {type: serial, protocol: dynamixel, device: /dev/ttyUSB0, baudrate: 1000000}
  gps: {type: serial, protocol: nmea, device: /dev/ttyACM0, baudrate: 9600}
components:
  - {name: J1, driver: serial, device: dynamixel_xm430_w350, bus: arm, params: {dxl_id: 3}}
  - {name: J2, driver: serial, device: dynamixel_xl430_w250, bus: arm, params: {dxl_id: 7}}
  - {name: G, driver: serial, device: nmea_gps, bus: gps}
"""


async def test_dynamixel_servos_answer_only_at_their_baud_rate() -> None:
    servos = [
        SimServo(3, model_number=1020, baud_rate=3),
        SimServo(7, model_number=1060, baud_rate=3),
    ]
    peer = SimDynamixelBus(servos, check_baudrate=True)  # Baud Rate (8) 3: 1 Mbit/s
    async with PeerThread(peer):
        result = await scan(
            peer.path, "dynamixel", (57_600, 1_000_000), range(0, 12), timeout_margin=0.05
        )
    assert [(s.servo_id, s.baudrate) for s in result.servos] == [(3, 1_000_000), (7, 1_000_000)]
    assert [s.model for s in result.servos] == ["XM430-W350", "XL430-W250"]
    assert [s.device for s in result.servos] == ["dynamixel_xm430_w350", "dynamixel_xl430_w250"]
    assert all(s.firmware is not None and s.error == 0 for s in result.servos)
    assert peer.baud_mismatches == 2  # the PINGs of 3 and 7 at 57600 were not heard
    assert result.to_dict()["servos"][0]["servo_id"] == 3


async def test_an_nmea_receiver_is_found_at_its_rate_only() -> None:
    receiver = SimGps(rate_hz=10.0, baudrate=9600)
    async with PeerThread(receiver):
        found = await scan_nmea(receiver.path, (4800, 9600), listen=0.35)
    [at] = found
    assert at.baudrate == 9600 and at.sentences >= 4 and at.checksum_errors == 0
    assert at.kinds == ("GPGGA", "GPRMC")


def test_ids_parse_and_refuse() -> None:
    assert parse_ids("1-3,7,2", 252) == (1, 2, 3, 7)
    for bad in ("300", "5-2", "x", "1-"):
        with pytest.raises(ValueError):
            parse_ids(bad, 252)


def test_feetech_servos_of_the_so101_rig_table_and_rig_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "scanned.yaml"
    code = main(["scan", "serial", "--rig", str(SO101), "--sim", "--ids", "0-8", "--timeout", "0.05", "--rig-out", str(out)])  # fmt: skip
    printed = capsys.readouterr().out
    assert code == 0, printed
    assert "Feetech servos" in printed and "STS3215 (777)" in printed
    assert f"wrote {out}" in printed
    resolved = resolve_rig(load_rig(out))
    assert [c.name for c in resolved.spec.components] == [f"SERVO_{i}" for i in range(1, 7)]
    assert {c.params["servo_id"] for c in resolved.spec.components} == set(range(1, 7))


def test_json_and_nothing_found(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rig = tmp_path / "dxl.yaml"
    rig.write_text(DXL_RIG)
    assert main(["scan", "serial", "--rig", str(rig), "--bus", "arm", "--sim", "--ids", "1-8", "--timeout", "0.05", "--json"]) == 0  # fmt: skip
    found = json.loads(capsys.readouterr().out)
    assert [s["servo_id"] for s in found["servos"]] == [3, 7]
    assert found["protocol"] == "dynamixel" and found["baudrates"] == [1_000_000]
    assert main(["scan", "serial", "--rig", str(rig), "--bus", "arm", "--sim", "--ids", "20-22"]) == 1  # fmt: skip
    assert "nothing found" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--port", "/dev/null"], "give --port DEVICE and --protocol"),
        (
            ["--port", "/dev/null", "--protocol", "dynamixel", "--baud", "1234"],
            "not a dynamixel rate",
        ),
        (["--port", "/dev/null", "--protocol", "feetech", "--ids", "300"], "--ids 300"),
        (["--port", "/dev/null", "--protocol", "nmea", "--ids", "1"], "an NMEA port has no ids"),
        (["--port", "/dev/null", "--protocol", "nmea", "--sim"], "--sim and --bus go with --rig"),
        (["--rig", str(SO101), "--port", "/dev/null"], "--rig takes the port"),
        (["--rig", str(SO101), "--bus", "nope"], "has no serial bus of that name"),
        (["--rig", "missing.yaml"], "no such file"),
        (["--port", "/dev/null", "--protocol", "feetech", "--timeout", "5"], "--timeout 5"),
    ],
)
def test_usage_errors_exit_2_before_anything_is_opened(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["scan", "serial", *argv]) == 2
    assert message in capsys.readouterr().err


def test_the_command_line_in_a_process() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "openel_async.cli", "scan", "serial", "--rig", str(SO101), "--sim",
         "--ids", "1-6", "--timeout", "0.05", "--json"],
        capture_output=True, text=True, timeout=60, env=dict(os.environ, NO_COLOR="1"),
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert [s["servo_id"] for s in json.loads(done.stdout)["servos"]] == [1, 2, 3, 4, 5, 6]
