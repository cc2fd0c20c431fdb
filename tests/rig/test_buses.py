"""The bus kinds the bundled drivers register: strict options, what ``rig check`` refuses,
``rig show``'s lines, and a rig with a Dynamixel bus and a GPS port run with ``--sim``."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import anyio
import pytest

from openel_async import BadParameterError, MonotonicClock, Request
from openel_async.rig import load_rig, open_rig, resolve_rig


def _check(tmp_path: Path, text: str) -> None:
    path = tmp_path / "rig.yaml"
    path.write_text(text)
    resolve_rig(load_rig(path))


CAN = """\
buses:
  can0: {type: can, interface: INTERFACE, channel: can0, bitrate: 1000000EXTRA}
components:
  - {name: A, driver: can, device: odrive_axis, bus: can0, params: {node_id: NODE}}
  - {name: B, driver: can, device: cia402_drive, bus: can0, params: {node_id: 2}}
"""


def _can(interface: str = "socketcan", node: int = 1, extra: str = "") -> str:
    return CAN.replace("INTERFACE", interface).replace("NODE", str(node)).replace("EXTRA", extra)


def test_a_can_rig_is_checked_without_opening_anything(tmp_path: Path) -> None:
    _check(tmp_path, _can())
    with pytest.raises(
        BadParameterError,
        match=r"rig.yaml:2:76: unknown key 'bitrat' in buses.can0 .did you mean 'bitrate'",
    ):
        _check(tmp_path, _can(extra=", bitrat: 5"))
    with pytest.raises(BadParameterError, match="a python-can interface"):
        _check(tmp_path, _can(interface="sockcan"))
    # ODrive node 4 takes 0x80..0x9f: SYNC (0x080) and CANopen node 2's EMCY (0x082)
    with pytest.raises(BadParameterError, match=r"A.params.node_id.*0x8"):
        _check(tmp_path, _can(node=4))
    with pytest.raises(BadParameterError, match="only with fd"):
        _check(tmp_path, _can(extra=", data_bitrate: 5000000"))


def test_a_device_on_a_bus_of_another_driver_is_refused(tmp_path: Path) -> None:
    text = (
        _can()
        + "  - {name: S, driver: serial, device: dynamixel, bus: can0, params: {dxl_id: 1}}\n"
    )
    with pytest.raises(BadParameterError, match="a bus of driver serial"):
        _check(tmp_path, text)


SERIAL = """\
buses:
  arm: {type: serial, protocol: dynamixel, device: /dev/ttyUSB0, baudrate: BAUD}
  gps: {type: serial, protocol: nmea, device: /dev/ttyACM0, baudrate: 9600}
components:
  - {name: J1, driver: serial, device: dynamixel_xm430_w350, bus: arm, params: {dxl_id: 1}}
  - {name: J2, driver: serial, device: dynamixel_xl430_w250, bus: arm, params: {dxl_id: ID2}}
  - {name: GPS, driver: serial, device: nmea_gps, bus: gps}
safety: {watchdog_timeout: 0.5, on_exit: hold}
"""


def _serial(baud: int = 1_000_000, id2: int = 2) -> str:
    return SERIAL.replace("BAUD", str(baud)).replace("ID2", str(id2))


def test_a_serial_rig_is_checked(tmp_path: Path) -> None:
    _check(tmp_path, _serial())
    with pytest.raises(BadParameterError, match="a Dynamixel X baud rate"):
        _check(tmp_path, _serial(baud=1_234))
    with pytest.raises(BadParameterError, match="an id of its own"):
        _check(tmp_path, _serial(id2=1))


def test_rig_show_names_each_bus_as_its_driver_describes_it(tmp_path: Path) -> None:
    path = tmp_path / "rig.yaml"
    path.write_text(_can(interface="slcan").replace("channel: can0", "channel: /dev/ttyACM0"))
    result = subprocess.run(
        [sys.executable, "-m", "openel_async.cli", "rig", "show", str(path)],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "  can0: CAN slcan /dev/ttyACM0 at 1 Mbit/s" in result.stdout
    assert "  A: can.odrive_axis (ODriveAxis) on can0 node_id=1" in result.stdout


async def test_a_serial_rig_runs_with_sim(tmp_path: Path) -> None:
    path = tmp_path / "rig.yaml"
    path.write_text(_serial())
    async with open_rig(load_rig(path), MonotonicClock(), sim=True) as rig:
        assert rig.bus_descriptions["arm"].endswith("simulated Dynamixel servos 1, 2")
        with anyio.fail_after(10):
            motions = [await rig.actuator(n).set_value(0.3, Request.POSITION) for n in ("J1", "J2")]
            for motion in motions:
                await motion
        assert await rig.actuator("J2").get_value(Request.POSITION_ACTUAL) == pytest.approx(
            0.3, abs=0.01
        )
        with anyio.fail_after(5):
            while True:
                try:
                    fix = await rig.sensor("GPS").get_value()
                    break
                except Exception:  # no fix yet: the receiver sends one a second
                    await anyio.sleep(0.1)
        assert len(fix) >= 2
    assert [r.ok for r in rig.exit_report] == [True, True]
