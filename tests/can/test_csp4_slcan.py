"""The csp4 app through python-can's ``slcan`` interface on a pty: its rig file with the bus
changed to the simulated slcan adapter (four simulated CiA 402 drives behind it), SYNC from
the rig on the group's timer, every frame through the Lawicel ASCII protocol."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from openel_apps.csp4 import RIG
from openel_async.app import find_app, run_app
from openel_can.sim.cia402 import SimCia402Drive
from openel_can.sim.slcan import SlcanAdapter


def test_csp4_runs_through_slcan_on_a_pty(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sims = [SimCia402Drive(node) for node in (1, 2, 3, 4)]
    with SlcanAdapter(bitrate=1_000_000, peers=sims) as adapter:
        text = RIG.read_text()
        bus = "interface: socketcan\n    channel: can0\n"
        assert bus in text
        # A 10 ms cycle and 0.5 s SDO timeouts: python-can's slcan reader and the adapter,
        # threads on a loaded 2-core machine, must not decide the test (the 1.5 ms cycle runs
        # in test_csp4 on virtual).
        text = text.replace(bus, f"interface: slcan\n    channel: {adapter.port}\n")
        text = text.replace("heartbeat_ms: 200,", "heartbeat_ms: 200, sdo_timeout: 0.5,")
        text = text.replace("cycle: {period_ms: 1.5}", "cycle: {period_ms: 10.0}")
        rig = tmp_path / "csp4-slcan.yaml"  # eds: a bare name, the shipped file
        rig.write_text(
            text.replace("bitrate: 1000000\n", "bitrate: 1000000\n    sleep_after_open: 0\n", 1)
        )
        status = run_app(find_app("csp4"), ["--moves", "1"], prog="csp4", rig=rig)
        out = capsys.readouterr().out
        assert status == 0, out
        assert f"SYNC every 10 ms on CAN slcan {adapter.port} at 1 Mbit/s" in out
        match = re.search(r"move 1: .* max error ([\d.]+) rad, SYNC cycles (\d+)", out)
        assert match is not None, out
        assert float(match[1]) <= 2e-3 and int(match[2]) > 10
        assert all(sim.syncs > 10 for sim in sims)
        assert all(sim.mode == 8 for sim in sims)  # on_exit hold: left in CSP, halted
    assert adapter.stats.errors == 0
