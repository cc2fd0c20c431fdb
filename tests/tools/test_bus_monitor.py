"""``openel-async bus monitor`` (issue 25 point 5): frames from simulated peers and from the test
decoded (ODrive CANSimple, CANopen NMT/SYNC/heartbeat/EMCY/SDO/PDO), per-id rates and error
counters, and the log file read back with python-can's own reader."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import uuid
from pathlib import Path

import anyio
import can
import pytest

from openel_async.cli import main
from openel_can import canopen as co
from openel_can.bus import CanBus
from openel_can.monitor import Decoded, Decoder, monitor
from openel_can.sim.cia402 import SimCia402Drive
from openel_can.sim.faults import peers_on_thread
from openel_can.sim.odrive import SimODrive

ROOT = Path(__file__).resolve().parents[2]
CAN_RIG = ROOT / "apps" / "openel_apps" / "rigs" / "twoaxis-can.yaml"
SO101 = ROOT / "apps" / "openel_apps" / "rigs" / "so101.yaml"


def _frame(msg: co.CanOpenMessage) -> can.Message:
    cob_id, data = co.encode(msg)
    return can.Message(arbitration_id=cob_id, data=data, is_extended_id=False)


@pytest.mark.parametrize("suffix", [".blf", ".trc"])
async def test_frames_decoded_counted_and_logged(tmp_path: Path, suffix: str) -> None:
    # (a name ending in a number over 65535: python-can's BLF writer took it for the channel
    # number, which BLF stores in 16 bits -- a random name failed now and then)
    channel = f"monitor-{uuid.uuid4().hex[:8]}-1234567"
    log = tmp_path / f"bus{suffix}"
    seen: list[Decoded] = []
    peers = [SimODrive(1, heartbeat_period=0.05), SimCia402Drive(2, heartbeat_ms=50)]
    with peers_on_thread(peers, channel):
        async with CanBus(interface="virtual", channel=channel) as bus:

            async def produce() -> None:
                with can.Bus(interface="virtual", channel=channel) as other:
                    await anyio.sleep(0.05)
                    for msg in (
                        co.NmtControl(co.NmtCommand.ENTER_PRE_OPERATIONAL, 0),
                        co.Sync(),
                        co.SdoUploadRequest(2, 0x1018, 4),  # the drive answers
                        co.Emergency(9, 0x4210, 0x09),
                    ):
                        other.send(_frame(msg))
                    other.send(
                        can.Message(arbitration_id=0x702, data=b"\x7f\x00", is_extended_id=False)
                    )

            async with anyio.create_task_group() as tg:
                tg.start_soon(produce)
                stats = await monitor(
                    bus, Decoder(frozenset({1})), duration=0.3, on_frame=seen.append, log=str(log)
                )
    texts = [d.text for d in seen]
    assert any(t.startswith("ODrive 1 -> Heartbeat axis_error=0 axis_state=IDLE") for t in texts)
    assert any(t.startswith("ODrive 1 -> EncoderEstimates pos=") for t in texts)
    assert "node 2 heartbeat PRE_OPERATIONAL" in texts
    assert "NMT ENTER_PRE_OPERATIONAL all nodes" in texts and "SYNC" in texts
    assert "node 2 SDO UploadRequest 1018:04" in texts
    assert f"node 2 SDO UploadResponse 1018:04 = {0x1234_0002} (02 00 34 12)" in texts
    assert (
        "node 9 EMCY 0x4210 excess temperature device (device temperature) register=0x09" in texts
    )
    assert stats.malformed == 1  # the two-byte heartbeat
    assert stats.frames == len(seen) and stats.per_id[0x021] >= 4
    assert stats.rates()[0x021] == pytest.approx(20, rel=0.5)  # 50 ms heartbeats
    logged = list(can.LogReader(str(log)))
    assert len(logged) == stats.frames
    assert [m.arbitration_id for m in logged] == [d.arbitration_id for d in seen]
    assert bytes(logged[-1].data) == seen[-1].data


def test_the_command_on_a_rigs_simulated_bus(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = tmp_path / "sim.asc"
    argv = ["bus", "monitor", str(CAN_RIG), "can0", "--sim", "--duration", "0.25", "--json"]
    assert main([*argv, "--summary", "0.1", "--log", str(log)]) == 0
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    frames = [line for line in lines if "summary" not in line]
    summaries = [line["summary"] for line in lines if "summary" in line]
    assert any(f["text"].startswith("ODrive 1 -> Heartbeat") for f in frames)  # node 1 from the rig
    assert len(summaries) >= 2 and summaries[-1]["frames"] == len(frames)
    assert summaries[-1]["malformed"] == 0 and "021" in summaries[-1]["rates"]
    assert len(list(can.LogReader(str(log)))) == len(frames)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        ([], "give --interface (and --channel, --bitrate) or --rig RIG.yaml"),
        ([str(CAN_RIG), "can0", "--rig", str(CAN_RIG)], "as RIG.yaml BUS or --rig/--bus, not both"),
        (["--interface", "virtual", "--log", "x.txt"], "--log x.txt: a file ending in .asc"),
        (["--interface", "virtual", "--duration", "0"], "--duration 0: a number of seconds"),
        (["--interface", "virtual", "--odrive", "1,x"], "--odrive 1,x: node ids 0..62"),
        (["--interface", "virtual", "--cia402", "2:xx"], "--cia402 2:xx: node ids 1..127"),
        (["--interface", "virtual", "--port", "/dev/null"], "--port goes with a serial bus"),
        ([str(SO101), "arm"], "give --port DEVICE (a second adapter listening"),
        ([str(SO101), "arm", "--sim", "--odrive", "1"], "--odrive: CAN options (arm is a serial"),
        ([str(CAN_RIG), "bus9"], "has no CAN bus of that name"),
    ],
)
def test_options_are_checked_before_anything_opens(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["bus", "monitor", *argv]) == 2
    assert message in capsys.readouterr().err


def test_a_serial_bus_with_sim_in_a_subprocess(tmp_path: Path) -> None:
    """The rig's simulated Feetech servos read by its driver through the tap: both
    directions decoded, no error, and the capture file read back."""
    from openel_serial.monitor import read_capture

    log = tmp_path / "arm.hex"
    done = subprocess.run(
        [sys.executable, "-m", "openel_async.cli", "bus", "monitor", str(SO101), "arm", "--sim",
         "--duration", "0.4", "--summary", "5", "--json", "--log", str(log)],
        capture_output=True, text=True, timeout=60, env=dict(os.environ, NO_COLOR="1"),
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    lines = [json.loads(line) for line in done.stdout.splitlines()]
    frames = [line for line in lines if "summary" not in line]
    texts = [f["text"] for f in frames]
    assert "Feetech 1 PING" in texts and "Feetech 1 STATUS Model Number=777" in texts
    assert any(t.startswith("Feetech SYNC READ 1..6 56+8 (Present Position") for t in texts)
    assert any(t.startswith("Feetech 6 STATUS Present Position=") for t in texts)
    assert not any(f["kind"] in ("WRITE", "SYNC WRITE", "REG_WRITE") for f in frames)
    summary = lines[-1]["summary"]
    assert summary["packets"] == len(frames) and summary["malformed"] == 0
    assert summary["checksum_errors"] == 0 and summary["dropped_bytes"] == 0
    assert set(summary["rates"]) == {"1", "2", "3", "4", "5", "6"}
    assert sum(len(data) for _, data in read_capture(log)) == summary["bytes"]
