"""``openel-async scan can`` (issue 25 point 1): CANopen nodes and ODrive axes found on python-can's
virtual bus and through the simulated slcan adapter; the table, JSON and rig file; the option
refusals (exit 2) and Ctrl-C (130)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import uuid
from pathlib import Path

import pytest

from openel_async.cli import main
from openel_can.bus import CanBus
from openel_can.scan import scan_can
from openel_can.sim.cia402 import SimCia402Drive
from openel_can.sim.faults import peers_on_thread
from openel_can.sim.odrive import SimODrive
from openel_can.sim.slcan import SlcanAdapter

ROOT = Path(__file__).resolve().parents[2]
CAN_RIG = ROOT / "apps" / "openel_apps" / "rigs" / "twoaxis-can.yaml"


async def test_canopen_nodes_and_odrive_axes_on_the_virtual_bus() -> None:
    channel = f"scan-{uuid.uuid4().hex[:8]}"
    odrive = SimODrive(3, heartbeat_period=0.05)
    peers = [odrive, SimCia402Drive(5, heartbeat_ms=100), SimCia402Drive(17, heartbeat_ms=100)]
    with peers_on_thread(peers, channel):
        async with CanBus(interface="virtual", channel=channel) as bus:
            result = await scan_can(bus, listen=0.25, node_timeout=0.05)
    assert [n.node_id for n in result.canopen] == [5, 17]
    drive = result.canopen[1]
    assert drive.state == "PRE_OPERATIONAL"
    assert drive.profile == 402 and drive.device_type == 0x0002_0192
    assert (drive.vendor_id, drive.product_code, drive.revision) == (0xE1A, 0x402, 0x1_0000)
    assert drive.serial_number == 0x1234_0000 + 17
    [axis] = result.odrives
    assert (axis.node_id, axis.axis_state, axis.axis_error) == (3, "IDLE", 0)
    assert (axis.firmware, axis.hardware) == ("0.6.10", "4.4-58")
    assert axis.serial_number == odrive.serial_number
    assert result.skipped == [] and result.seconds < 1.5
    assert odrive.commands.total == 0  # the scan asked, it commanded nothing


async def test_an_odrive_at_node_48_is_not_sent_sdo_requests_it_would_take_as_commands() -> None:
    channel = f"scan-{uuid.uuid4().hex[:8]}"
    odrive = SimODrive(48, heartbeat_period=0.05)
    with peers_on_thread([odrive, SimCia402Drive(40, heartbeat_ms=100)], channel):
        async with CanBus(interface="virtual", channel=channel) as bus:
            result = await scan_can(bus, listen=0.15, node_timeout=0.03, concurrency=127)
    assert result.skipped == list(range(1, 32))  # 0x601..0x61F: ODrive 48's command ids
    assert [o.node_id for o in result.odrives] == [48]
    assert [n.node_id for n in result.canopen] == [40]
    assert odrive.commands.total == 0 and odrive.malformed == 0


def test_through_the_slcan_adapter_from_a_rig_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with SlcanAdapter(peers=[SimODrive(1), SimCia402Drive(2)]) as adapter:
        rig = tmp_path / "slcan.yaml"
        rig.write_text(
            CAN_RIG.read_text().replace(
                "    interface: socketcan\n    channel: can0\n",
                f"    interface: slcan\n    channel: {adapter.port}\n    sleep_after_open: 0\n",
            )
        )
        code = main(["scan", "can", "--rig", str(rig), "--listen", "0.2", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0
    assert out["bus"].startswith(f"CAN slcan {adapter.port} at 1 Mbit/s")
    assert [o["node_id"] for o in out["odrive"]] == [1]
    assert [(n["node_id"], n["profile"]) for n in out["canopen"]] == [(2, 402)]
    assert adapter.stats.errors == 0


def test_the_table_and_a_rig_file_that_rig_check_accepts(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out_rig = tmp_path / "found.yaml"
    args = ["scan", "can", "--rig", str(CAN_RIG), "--sim", "--listen", "0.15"]
    assert main([*args, "--rig-out", str(out_rig)]) == 0
    text = capsys.readouterr().out
    assert "ODrive axes (CANSimple)" in text and "CANopen nodes" in text
    assert "0.6.10" in text and "CiA 402" in text and "0x00000E1A" in text
    written = out_rig.read_text()
    assert "device: odrive_axis" in written and "params: {node_id: 1}" in written
    assert "device: cia402_drive" in written and "params: {node_id: 2}" in written
    assert 'interface: "socketcan"' in written  # the rig's bus, not the simulation's
    assert main(["rig", "check", str(out_rig)]) == 0
    assert "ok (1 bus, 2 components" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        ([], "give --interface (and --channel, --bitrate) or --rig RIG.yaml"),
        (["--interface", "virtual", "--sim"], "--sim and --bus go with --rig"),
        (["--rig", "nowhere.yaml"], "nowhere.yaml: no such file"),
        (
            ["--rig", str(CAN_RIG), "--bus", "can9"],
            "has no CAN bus of that name (its CAN buses: can0)",
        ),
        (["--rig", str(CAN_RIG), "--channel", "can1"], "--rig takes the bus from the rig file"),
        (["--interface", "virtual", "--listen", "-1"], "--listen -1: a number of seconds in 0..60"),
        (["--interface", "virtual", "--concurrency", "0"], "--concurrency 0: an int in 1..127"),
        (["--interface", "virtual", "--rig-out", "/no/such/dir/x.yaml"], "no such folder"),
    ],
)
def test_options_are_checked_before_anything_opens(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["scan", "can", *argv]) == 2
    assert message in capsys.readouterr().err


def test_nothing_found_exits_1_and_ctrl_c_exits_130(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    channel = f"scan-{uuid.uuid4().hex[:8]}"
    base = ["scan", "can", "--interface", "virtual", "--channel", channel]
    assert main([*base, "--listen", "0", "--timeout", "0.01"]) == 1
    assert "nothing found" in capsys.readouterr().out

    async def interrupted(*args: object, **kwargs: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr("openel_can.scan.scan_can", interrupted)
    assert main(base) == 130
    err = capsys.readouterr().err
    assert "interrupted by SIGINT" in err and "Traceback" not in err


def test_the_command_line_in_a_process() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "openel_async.cli", "scan", "can", "--rig", str(CAN_RIG), "--sim",
         "--listen", "0.15", "--json"],
        capture_output=True, text=True, timeout=60, env=dict(os.environ, NO_COLOR="1"),
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    found = json.loads(result.stdout)
    assert [o["node_id"] for o in found["odrive"]] == [1]
    assert [n["node_id"] for n in found["canopen"]] == [2]
