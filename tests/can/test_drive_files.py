"""A CiA 402 drive configured from its files: ``eds``/``dcf``/``pdos`` of Cia402Drive and of
a rig's drive entry (paths relative to the rig file), the maps written in PRE-OPERATIONAL
and verified, the DCF's parameter values, and the strict refusals naming the parameter."""

from __future__ import annotations

import configparser
import math
import shutil
from contextlib import AsyncExitStack
from pathlib import Path
from typing import Any

import anyio
import pytest

from openel_async import Actuator, BadParameterError, EventTimer, Request
from openel_async.rig import load_rig, open_rig, resolve_rig
from openel_can import CanBus, CanSync, Cia402CyclicDrive, Cia402Drive
from openel_can import cia402 as ds
from openel_can.layout402 import drive_pdos
from openel_can.od import SHIPPED_EDS
from openel_can.pdomap import PdoSpec
from openel_can.sim.cia402 import SimCia402Drive

from .conftest import Peers, wait_until

CPR = 10_000
Mode = ds.ModeOfOperation

CUSTOM = [
    {"pdo": "rpdo2", "objects": ["Controlword", "Target position"], "trigger": "sync"},
    {"pdo": "tpdo1", "objects": ["Position actual value"], "trigger": "sync"},
    {"pdo": "tpdo3", "objects": ["Statusword", "0x6061", "0x1001"], "trigger": "event"},
]
"""Other PDOs than the defaults, objects by name and index, an unfollowed one (0x1001)."""


async def _csp_move(axis: Actuator, bus: CanBus, sim: SimCia402Drive, target: float) -> None:
    async with EventTimer(2.0, name="cycle") as timer:
        sync = CanSync.of(bus)
        await sync.start(timer)
        try:
            timer.start_timer()
            await axis.set_value(target)
            counts = round(target * CPR / math.tau)
            await wait_until(lambda: abs(sim.position - counts) < 0.5)  # there, not on the way
            drive = axis.device
            assert isinstance(drive, Cia402CyclicDrive)
            await wait_until(lambda: drive.feedback_cycle >= sync.cycle - 1)
            await wait_until(lambda: abs(drive._position - sim.position) < 1)
            position = await axis.get_value(Request.POSITION_ACTUAL)
            assert position == pytest.approx(target, abs=1e-3)
        finally:
            sync.stop()


async def test_rpdo4_carries_a_csp_set_point_to_the_simulated_drive(
    peers: Peers, host_bus: CanBus
) -> None:
    """RPDO4 (invalid and empty by default in the shipped EDS: no mode of ours maps it
    unless told) is served by the simulated drive like RPDO1-3."""
    sim = await peers.start(SimCia402Drive(9))
    pdos = [
        {"pdo": "rpdo4", "objects": ["Controlword", "Target position"], "trigger": "sync"},
        {"pdo": "tpdo1", "objects": ["Statusword", "Position actual value"], "trigger": "sync"},
        {"pdo": "tpdo2", "objects": ["Statusword", "Modes of operation display"]},
    ]
    drive = Cia402Drive(host_bus, 9, mode="csp", eds=SHIPPED_EDS, pdos=pdos, heartbeat_ms=100)
    assert drive.rpdo_cob_id == 0x509  # type: ignore[attr-defined]
    async with Actuator(drive) as axis:
        assert [sim.od[(0x1603, s)].value for s in range(3)] == [2, 0x6040_0010, 0x607A_0020]
        await _csp_move(axis, host_bus, sim, -0.25)


async def test_a_csp_drive_runs_with_the_pdos_its_entry_names(
    peers: Peers, host_bus: CanBus
) -> None:
    sim = await peers.start(SimCia402Drive(7))
    drive = Cia402Drive(host_bus, 7, mode="csp", eds=SHIPPED_EDS, pdos=CUSTOM, heartbeat_ms=100)
    assert drive.layout is not None and drive.rpdo_cob_id == 0x307  # type: ignore[attr-defined]
    async with Actuator(drive) as axis:
        od = sim.od
        # written in PRE-OPERATIONAL with the CiA 301 sequence, read back; others disabled
        assert [od[(0x1601, s)].value for s in range(3)] == [2, 0x6040_0010, 0x607A_0020]
        assert od[(0x1401, 2)].value == 1 and not od[(0x1401, 1)].value & 0x8000_0000
        assert [od[(0x1A00, s)].value for s in range(2)] == [1, 0x6064_0020]
        assert [od[(0x1A02, s)].value for s in range(4)] == [
            3,
            0x6041_0010,
            0x6061_0008,
            0x1001_0008,
        ]
        assert od[(0x1400, 1)].value & 0x8000_0000 and od[(0x1801, 1)].value & 0x8000_0000
        assert sim.mode == Mode.CYCLIC_SYNC_POSITION
        assert sim.power_state is ds.PowerState.OPERATION_ENABLED
        assert drive.pdo_values == {"Error register": 0}
        await _csp_move(axis, host_bus, sim, 0.4)


async def test_statusword_only_on_sync_the_driver_reads_it_by_sdo(
    peers: Peers, host_bus: CanBus
) -> None:
    """No event-driven statusword and a synchronous RPDO before any SYNC: the state machine
    runs by SDO (controlword written, statusword read) until the timer's SYNC runs."""
    sim = await peers.start(SimCia402Drive(8))
    pdos = [
        PdoSpec(pdo="rpdo1", objects=("0x6040", "0x607A"), trigger="sync"),
        PdoSpec(pdo="tpdo1", objects=("0x6041", "0x6064"), trigger="sync"),
    ]
    drive = Cia402Drive(host_bus, 8, mode="csp", eds=SHIPPED_EDS, pdos=pdos, heartbeat_ms=100)
    assert drive.layout is not None and not drive.layout.status_on_event
    async with Actuator(drive) as axis:
        assert sim.power_state is ds.PowerState.OPERATION_ENABLED
        await _csp_move(axis, host_bus, sim, -0.3)


async def test_dcf_parameter_values_are_written_at_init_and_pp_offers_the_mapped_modes(
    peers: Peers, host_bus: CanBus, tmp_path: Path
) -> None:
    dcf = _dcf(tmp_path, {"6083": "12345", "6081": "5000"})
    sim = await peers.start(SimCia402Drive(9))
    sim.od[(0x6083, 0)].value = 1
    pdos = [
        {"pdo": "rpdo1", "objects": ["Controlword", "Target position"]},
        {"pdo": "tpdo1", "objects": ["Statusword", "Position actual value"], "event_ms": 10},
    ]
    drive = Cia402Drive(host_bus, 9, dcf=dcf, pdos=pdos, heartbeat_ms=100)
    assert drive.supported_requests == frozenset({Request.POSITION, Request.NO_EXCITE})
    async with Actuator(drive) as axis:
        assert sim.od[(0x6083, 0)].value == 12345 and sim.od[(0x6081, 0)].value == 5000
        with anyio.fail_after(5):
            await (await axis.set_value(0.2))
        assert sim.position == pytest.approx(0.2 * CPR / math.tau, abs=2)
    assert drive_pdos("pp")[1].pdo == "rpdo2"  # the default pp maps carry all three targets


def _dcf(tmp_path: Path, values: dict[str, str]) -> Path:
    parser = configparser.RawConfigParser()
    parser.optionxform = str  # type: ignore[assignment,method-assign]
    parser.read(SHIPPED_EDS)
    for section, value in values.items():
        parser.set(section, "ParameterValue", value)
    path = tmp_path / "drive.dcf"
    with path.open("w") as f:
        parser.write(f)
    return path


def _rig(tmp_path: Path, params: dict[str, Any]) -> Path:
    import yaml

    rig = {
        "namespace": "files",
        "buses": {"can0": {"type": "can", "interface": "virtual", "bitrate": 1_000_000}},
        "components": [
            {
                "name": "AXIS_1",
                "driver": "can",
                "device": "cia402_drive",
                "bus": "can0",
                "params": {"node_id": 1, "mode": "csp", "heartbeat_ms": 100, **params},
            }
        ],
        "timers": {"cycle": {"period_ms": 2.0}},
        "safety": {"watchdog_timeout": None, "on_exit": "hold"},
    }
    path = tmp_path / "rig.yaml"
    path.write_text(yaml.safe_dump(rig, sort_keys=False))
    return path


async def test_a_rig_names_the_eds_relative_to_its_file_and_the_sim_loads_it(
    tmp_path: Path,
) -> None:
    (tmp_path / "drives").mkdir()
    shutil.copy(SHIPPED_EDS, tmp_path / "drives" / "servo.eds")
    path = _rig(tmp_path, {"eds": "drives/servo.eds", "pdos": CUSTOM})
    resolved = resolve_rig(load_rig(path))
    load = resolved.buses["can0"].load
    assert load is not None and "1 axes" not in load.detail  # no group: not streamed
    async with AsyncExitStack() as stack:
        rig = await stack.enter_async_context(open_rig(resolved, sim=True))
        drive = rig.actuator("AXIS_1").device
        assert isinstance(drive, Cia402CyclicDrive) and drive.files is not None
        assert drive.files.od.source == "servo.eds" and drive.files.origin == "pdos"
        sim = rig.peers["AXIS_1"]
        assert isinstance(sim, SimCia402Drive)
        assert sim.object_dictionary.source == "servo.eds"
        assert sim.od[(0x1A02, 0)].value == 3


@pytest.mark.parametrize(
    ("params", "parameter", "words"),
    [
        ({"eds": "missing.eds"}, "AXIS_1.params.eds", "openel_servo402.eds"),
        ({"eds": "openel_servo402.eds", "dcf": "x.eds"}, "AXIS_1.params.dcf", "DCF file"),
        ({"pdos": CUSTOM}, "AXIS_1.params.pdos", "give 'eds' or 'dcf' too"),
        (
            {"eds": "openel_servo402.eds", "pdos": [{"pdo": "tpdo1", "objects": ["Statuswrd"]}]},
            "AXIS_1.params.pdos[0].objects[0]",
            "closest: 'Statusword'",
        ),
        (
            {"eds": "openel_servo402.eds", "pdos": [{"pdo": "tpdo1", "object": ["Statusword"]}]},
            "AXIS_1.params.pdos",
            "object",
        ),
        (
            {
                "eds": "openel_servo402.eds",
                "pdos": [
                    {"pdo": "rpdo1", "objects": ["Controlword", "0x6081"]},
                    {"pdo": "tpdo1", "objects": ["Statusword"]},
                ],
            },
            "AXIS_1.params.pdos[0].objects[1]",
            "an object the driver writes",
        ),
        (
            {
                "eds": "openel_servo402.eds",
                "pdos": [{"pdo": "rpdo1", "objects": ["Controlword", "Target position"]}],
            },
            "AXIS_1.params.pdos",
            "statusword 0x6041",
        ),
        (
            {
                "eds": "openel_servo402.eds",
                "pdos": [
                    {"pdo": "rpdo1", "objects": ["Controlword", "Target velocity"]},
                    {"pdo": "tpdo1", "objects": ["Statusword"]},
                ],
            },
            "AXIS_1.params.pdos",
            "Target position (0x607a:0) (mode csp)",
        ),
        ({"eds": "openel_servo402.eds", "edf": "x"}, "AXIS_1.params", "edf"),
    ],
)
def test_rig_check_refuses_bad_files_and_maps_naming_the_parameter(
    tmp_path: Path, params: dict[str, Any], parameter: str, words: str
) -> None:
    path = _rig(tmp_path, params)
    with pytest.raises(BadParameterError) as err:
        resolve_rig(load_rig(path))
    assert parameter in str(err.value) and words in str(err.value), str(err.value)
