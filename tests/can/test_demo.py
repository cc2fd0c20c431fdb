"""The CAN demo rig end to end, and the driver's registration."""

from __future__ import annotations

import pytest

from openel_apps.can_rig import can_rig
from openel_apps.twoaxis import run_demo
from openel_async.cli import main
from openel_async.device import ErrorId
from openel_async.registry import discover_drivers
from openel_can import DRIVER, Cia402Drive, ODriveAxis


async def test_demo_on_can_recovers_from_the_injected_fault() -> None:
    summary = await run_demo(duration_s=1.0, period_ms=10.0, inject_fault=True, rig=can_rig)
    assert summary.rig.startswith("CAN:")
    assert summary.recoveries == 1
    # One injected fault, one error (not the EMCY and the fault: issue 21 point 7), with the
    # id the sim rig reports for the same trip.
    assert [(e.device, e.error_id) for e in summary.errors] == [("MOTOR_2", ErrorId.DEVICE_ERROR)]
    line = summary.error_line()
    assert line.startswith("errors             1: MOTOR_2 error 1 (device error: CiA 402 node 2")
    assert "EMCY DEVICE_OVER_TEMPERATURE" in line
    assert summary.last_readings["TEMP_2"].endswith(" K")
    assert summary.setpoints > 150 and summary.sensor_reads >= 18
    assert summary.final_positions == pytest.approx((0.0, 0.0), abs=2e-3)


def test_driver_is_registered() -> None:
    entries = {e.name: e for e in discover_drivers()}
    assert entries["can"].info is DRIVER
    assert DRIVER.devices["odrive_axis"] is ODriveAxis
    assert DRIVER.devices["cia402_drive"] is Cia402Drive


def test_devices_command_lists_the_can_driver(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["devices"]) == 0
    out = capsys.readouterr().out
    assert "openel_can.odrive.ODriveAxis" in out and "openel_can.drive402.Cia402Drive" in out
