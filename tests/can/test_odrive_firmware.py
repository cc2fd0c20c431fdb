"""ODrive endpoint ids belong to one firmware build: the driver and ``openel-async param`` write
an endpoint only when the axis's Get_Version is the endpoint table's ``fw_version``
(``flat_endpoints.json``), against the simulated ODrive on python-can's virtual bus."""

from __future__ import annotations

import json
import struct
from pathlib import Path
from typing import Any

import anyio
import pytest

from openel_async import Actuator
from openel_async.device import VelocityRamp
from openel_async.errors import BadParameterError, HALError
from openel_can import CanBus, ODriveAxis
from openel_can import cansimple as cs
from openel_can.odrive_endpoints import ENDPOINTS
from openel_can.odrive_firmware import (
    BUILTIN_TABLE,
    SIMULATED_FIRMWARE,
    EndpointTable,
    FirmwareVersion,
    load_endpoints,
)
from openel_can.params_odrive import ODriveParameters
from openel_can.sim.odrive import SimODrive

from .conftest import Peers, wait_until

NODE = 4
HB = 0.02
SHIFT = 1000  # the file's ids: the built-in ones + SHIFT, so the wire shows which table
PRO_0_6_11 = FirmwareVersion((0, 6, 11), (4, 4, 58))
_TYPES = {"uint32": "uint32", "int32": "int32", "float": "float", "bool": "bool"}


def _flat(fw: str = "0.6.11", hw: str = "4.4.58") -> dict[str, Any]:
    endpoints: dict[str, Any] = {
        e.name: {"id": e.id + SHIFT, "type": _TYPES[e.type], "access": "rw" if e.writable else "r"}
        for e in ENDPOINTS
    }
    endpoints["save_configuration"] = {"id": 9000, "type": "function", "inputs": [], "outputs": []}
    endpoints["serial_number"]["type"] = "uint64"
    return {"fw_version": fw, "hw_version": hw, "endpoints": endpoints}


@pytest.fixture
def flat_file(tmp_path: Path) -> Path:
    path = tmp_path / "flat_endpoints.json"
    path.write_text(json.dumps(_flat()))
    return path


def _writes(sim: SimODrive) -> list[cs.RxSdo]:
    return [c for c in sim.commands if isinstance(c, cs.RxSdo) and c.opcode is cs.SdoOpcode.WRITE]


def test_the_builtin_table_matches_no_firmware_but_the_simulation() -> None:
    assert BUILTIN_TABLE.fw_version is None and "exact revision unknown" in BUILTIN_TABLE.firmware
    assert BUILTIN_TABLE.matches(SIMULATED_FIRMWARE)
    for fw in ((0, 6, 10), (0, 6, 11), (0, 6, 9)):
        assert not BUILTIN_TABLE.matches(FirmwareVersion(fw, (4, 4, 58)))
        assert not BUILTIN_TABLE.matches(FirmwareVersion(fw, (4, 4, 58), unreleased=1))


def test_a_flat_endpoints_file_is_loaded(flat_file: Path) -> None:
    table = load_endpoints(flat_file)
    assert (table.fw_version, table.hw_version, table.source) == (
        "0.6.11",
        "4.4.58",
        str(flat_file),
    )
    watchdog = table.get("axis0.config.watchdog_timeout")
    assert watchdog is not None and watchdog.id == 200 + SHIFT and watchdog.writable
    assert table.get("vbus_voltage") is not None and not table.get("vbus_voltage").writable  # type: ignore[union-attr]
    assert set(table.skipped) == {"save_configuration", "serial_number"}  # no 4-byte value
    assert table.matches(PRO_0_6_11)
    assert table.matches(FirmwareVersion((0, 6, 11), (4, 4, 58), unreleased=1))
    assert not table.matches(FirmwareVersion((0, 6, 10), (4, 4, 58)))
    assert not table.matches(FirmwareVersion((0, 6, 11), (5, 2, 0)))  # another board
    assert not table.matches(SIMULATED_FIRMWARE)
    refusal = table.refusal(NODE, FirmwareVersion((0, 6, 10), (4, 4, 58)), "x")
    assert refusal is not None and "0.6.10" in refusal and "0.6.11" in refusal


@pytest.mark.parametrize(
    ("content", "problem"),
    [
        ('{"fw_version": "0.6.11",\n "endpoints": {', "not JSON: line 2"),
        ("[1, 2]", "top level is not an object"),
        (json.dumps({"hw_version": "4.4.58", "endpoints": {}}), "fw_version None"),
        (json.dumps({**_flat(), "fw_version": "latest"}), "fw_version 'latest'"),
        (json.dumps({**_flat(), "hw_version": 4}), "hw_version 4"),
        (json.dumps({"fw_version": "0.6.11", "hw_version": "4.4.58"}), "no 'endpoints'"),
        (json.dumps({**_flat(), "endpoints": {"a": {"id": 70000, "type": "float"}}}), "65535"),
        (json.dumps({**_flat(), "endpoints": {"a": {"id": "3", "type": "float"}}}), "id '3'"),
        (json.dumps({**_flat(), "endpoints": {"a": {"id": 3}}}), "type None"),
        (json.dumps({**_flat(), "endpoints": {"a": 3}}), "not an object"),
        (
            json.dumps({**_flat(), "endpoints": {"a": {"id": 3, "type": "bool", "access": "x"}}}),
            "access 'x'",
        ),
        (
            json.dumps(
                {
                    **_flat(),
                    "endpoints": {"a": {"id": 3, "type": "uint8"}, "b": {"id": 3, "type": "bool"}},
                }
            ),
            "both",
        ),
    ],
)
def test_a_bad_file_is_refused_naming_it_and_the_problem(
    tmp_path: Path, content: str, problem: str
) -> None:
    path = tmp_path / "bad.json"
    path.write_text(content)
    with pytest.raises(BadParameterError, match="endpoints") as caught:
        load_endpoints(path)
    assert str(path) in str(caught.value) and problem in str(caught.value)


def test_a_missing_file_and_a_table_without_the_watchdog_are_refused(tmp_path: Path) -> None:
    with pytest.raises(BadParameterError, match="cannot be read"):
        load_endpoints(tmp_path / "none.json")
    path = tmp_path / "small.json"
    path.write_text(json.dumps({**_flat(), "endpoints": {"a": {"id": 3, "type": "float"}}}))
    with pytest.raises(BadParameterError, match=r"axis0\.config\.watchdog_timeout \(float\)"):
        ODriveAxis(CanBus.__new__(CanBus), NODE, endpoints=path)


async def test_matching_firmware_writes_the_files_ids(
    peers: Peers, host_bus: CanBus, flat_file: Path
) -> None:
    table = load_endpoints(flat_file)
    sim = await peers.start(SimODrive(NODE, heartbeat_period=HB, endpoints=table))
    assert sim.firmware == PRO_0_6_11  # the file's version
    device = ODriveAxis(
        host_bus, NODE, heartbeat_period=HB, endpoints=flat_file.name, files_dir=flat_file.parent
    )
    async with Actuator(device):
        with anyio.fail_after(5):
            await device.arm_watchdog(0.3)
        assert device.firmware_version == PRO_0_6_11
        assert sim.enable_watchdog and sim.watchdog_timeout == pytest.approx(0.3)
        assert {w.endpoint_id for w in _writes(sim)} == {200 + SHIFT, 201 + SHIFT}
        await device.disarm_watchdog()


@pytest.mark.parametrize("firmware", [FirmwareVersion((0, 6, 10), (4, 4, 58)), None])
async def test_mismatching_firmware_refuses_the_watchdog_writes_and_idles_the_axis(
    peers: Peers, host_bus: CanBus, flat_file: Path, firmware: FirmwareVersion | None
) -> None:
    # None: the host's built-in table against an axis reporting a real release.
    table = load_endpoints(flat_file)
    reported = firmware or FirmwareVersion((0, 6, 10), (4, 4, 58))
    sim = await peers.start(
        SimODrive(NODE, heartbeat_period=HB, endpoints=table, firmware=reported)
    )
    endpoints = flat_file if firmware is not None else None
    device = ODriveAxis(host_bus, NODE, heartbeat_period=HB, endpoints=endpoints)
    async with Actuator(device) as axis:
        assert sim.axis_state is cs.AxisState.CLOSED_LOOP_CONTROL
        with anyio.fail_after(5), pytest.raises(HALError) as caught:
            await device.arm_watchdog(0.3)
        message = str(caught.value)
        assert "reports firmware 0.6.10" in message
        assert ("0.6.11" if firmware is not None else "exact revision unknown") in message
        assert "flat_endpoints.json" in message and "watchdog_timeout: null" in message
        assert _writes(sim) == [] and not sim.enable_watchdog
        await wait_until(lambda: sim.axis_state is cs.AxisState.IDLE)
        # A tm_acc ramp (vel_ramp_rate by RxSdo) is refused too, before anything is sent.
        sent = sim.commands.total
        with anyio.fail_after(5), pytest.raises(HALError, match="vel_ramp_rate"):
            await device.command_velocity_ramp(VelocityRamp(0.0, 1.0, 0.5))
        assert sim.commands.total == sent and _writes(sim) == []
        assert axis.state.value == "Error"  # faulted: no command re-engages it


async def test_a_rig_init_fails_on_a_mismatch(tmp_path: Path) -> None:
    from openel_async.rig import load_rig, open_rig

    path = tmp_path / "rig.yaml"
    (tmp_path / "fw").mkdir()
    (tmp_path / "fw" / "flat.json").write_text(json.dumps(_flat()))
    path.write_text(
        "buses:\n  can0: {type: can, interface: socketcan, channel: can0}\n"
        "components:\n  - {name: AXIS, driver: can, device: odrive_axis, bus: can0, "
        "params: {node_id: 1, heartbeat_period: 0.02, endpoints: fw/flat.json}}\n"
        "safety: {watchdog_timeout: 0.3, on_exit: torque_off}\n"
    )
    async with open_rig(load_rig(path), sim=True, init=False) as rig:
        peer: Any = rig.peers["AXIS"]
        assert peer.firmware == PRO_0_6_11  # --sim: the node has the file's ids and version
        axis = rig.actuators[0]
        # the axis runs another firmware than the file's (reflashed): init fails, axis IDLE
        peer.firmware = FirmwareVersion((0, 6, 9), (4, 4, 58))
        with anyio.fail_after(5), pytest.raises(HALError, match=r"reports firmware 0\.6\.9"):
            await axis.init()
        assert _writes(peer) == [] and not peer.enable_watchdog
        assert axis.state.value == "Error"
        await wait_until(lambda: peer.axis_state is cs.AxisState.IDLE)
        # the firmware the file is for: re_init asks the version again and arms the watchdog
        peer.firmware = PRO_0_6_11
        with anyio.fail_after(5):
            await axis.re_init()
        assert peer.enable_watchdog and peer.watchdog_timeout == pytest.approx(0.3)
        assert {w.endpoint_id for w in _writes(peer)} == {200 + SHIFT, 201 + SHIFT}
        assert peer.axis_state is cs.AxisState.CLOSED_LOOP_CONTROL


@pytest.mark.parametrize(
    ("content", "problem"),
    [
        ("{}", "fw_version"),
        (
            json.dumps({**_flat(), "endpoints": {"a": {"id": 3, "type": "float"}}}),
            "axis0.config.enable_watchdog (bool)",
        ),
    ],
)
def test_rig_check_refuses_a_bad_endpoints_file(tmp_path: Path, content: str, problem: str) -> None:
    from openel_async.rig import load_rig, resolve_rig

    path = tmp_path / "rig.yaml"
    (tmp_path / "flat.json").write_text(content)
    path.write_text(
        "buses:\n  can0: {type: can, interface: socketcan, channel: can0}\n"
        "components:\n  - {name: AXIS, driver: can, device: odrive_axis, bus: can0, "
        "params: {node_id: 1, endpoints: flat.json}}\n"
    )
    with pytest.raises(BadParameterError, match=r"AXIS\.params\.endpoints") as caught:
        resolve_rig(load_rig(path))
    assert "flat.json" in str(caught.value) and problem in str(caught.value)


async def test_param_set_refuses_on_a_mismatch_and_get_warns(
    peers: Peers, host_bus: CanBus, flat_file: Path
) -> None:
    table = load_endpoints(flat_file)
    sim = await peers.start(
        SimODrive(NODE, endpoints=table, firmware=FirmwareVersion((0, 6, 10), (4, 4, 58)))
    )
    access = ODriveParameters(host_bus, NODE, endpoints=table)
    limit = access.parameter("axis0.controller.config.vel_limit")
    assert limit.address == f"endpoint {388 + SHIFT}"
    with anyio.fail_after(5):
        assert await access.read(limit) == pytest.approx(sim.vel_limit)  # reads proceed
        assert access.mismatch is not None and "WARNING" in access.source
        assert "0.6.10" in access.source and "0.6.11" in access.source
        with pytest.raises(HALError, match="refused"):
            await access.write(limit, 1.5)
    assert _writes(sim) == [] and sim.endpoint_values == {}


async def test_param_set_writes_on_a_match(peers: Peers, host_bus: CanBus, flat_file: Path) -> None:
    table = load_endpoints(flat_file)
    sim = await peers.start(SimODrive(NODE, endpoints=table))
    access = ODriveParameters(host_bus, NODE, endpoints=table)
    gain = access.parameter("axis0.controller.config.vel_gain")
    with anyio.fail_after(5):
        await access.write(gain, 0.25)
        assert await access.read(gain) == 0.25
    assert access.mismatch is None and "WARNING" not in access.source
    assert [w.endpoint_id for w in _writes(sim)] == [gain_id := int(gain.address.split()[1])]
    assert struct.unpack("<f", sim.endpoint_values[gain_id])[0] == 0.25


def test_the_table_type() -> None:
    assert isinstance(BUILTIN_TABLE, EndpointTable) and len(BUILTIN_TABLE.endpoints) == len(
        ENDPOINTS
    )
