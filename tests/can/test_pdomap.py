"""Issue 23 points 2 and 6: PDO maps checked against the EDS, written by SDO in CiA 301's order,
read back and verified -- against our simulated drive, and both ways against canopen-py: its
``LocalNode`` loaded from the same EDS is mapped and started by our master, and its
``RemoteNode`` with its own ``pdo`` and ``sync`` tooling masters our simulated drive."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TypeVar

import anyio
import canopen
import pytest

from openel_async import BadParameterError
from openel_can import CanBus, SdoClient
from openel_can import canopen as co
from openel_can.od import SHIPPED_EDS, load_od
from openel_can.pdomap import (
    PdoMap,
    PdoMappingError,
    PdoSpec,
    cia402_maps,
    configure_pdos,
    read_pdo,
    resolve_maps,
)
from openel_can.sim.cia402 import SimCia402Drive

from .conftest import Peers

T = TypeVar("T")
NODE = 6
OD = load_od(SHIPPED_EDS, node_id=NODE)


async def _in_thread(fn: Callable[[], T]) -> T:
    with anyio.fail_after(10):
        return await anyio.to_thread.run_sync(fn)


# -- checked before anything is sent -----------------------------------------------------------
@pytest.mark.parametrize(
    ("pdo", "says"),
    [
        (
            PdoMap("rpdo", 1, ("Controlword", "Statusword")),
            r"an object an RPDO writes \(Statusword \(0x6041:0\) is access ro",
        ),
        (
            PdoMap("tpdo", 1, ("Producer heartbeat time",)),
            r"Producer heartbeat time \(0x1017:0\) is not PDO-mappable",
        ),
        (
            PdoMap(
                "tpdo",
                1,
                ("Position actual value", "Velocity actual value", "Statusword"),
            ),
            r"at most 64 bits in one PDO \(80 given\)",
        ),
        (PdoMap("tpdo", 1, ("Statusword",), transmission=241), r"transmission=241"),
        (PdoMap("rpdo", 1, ("Controlword",), event_timer=10), r"a TPDO's parameter"),
        (PdoMap("rpdo", 5, ("Controlword",)), r"PDOs above 4 have no default"),
        (PdoMap("tpdo", 1, ("Statusword", "Statusword"), cob_id=0x800), r"0x001..0x7FF"),
        (PdoMap("tpdo", 1, ("Statuswort",)), r"closest: 'Statusword'"),
    ],
)
def test_maps_are_refused_naming_the_object(pdo: PdoMap, says: str) -> None:
    with pytest.raises(BadParameterError, match=says):
        resolve_maps([pdo], OD, NODE)


def test_the_cia402_maps_of_every_mode_fit_the_shipped_eds() -> None:
    for mode in ("pp", "pv", "tq", "csp", "csv", "cst"):
        rpdo, tpdo1, tpdo2 = resolve_maps(cia402_maps(mode), OD, NODE)  # type: ignore[arg-type]
        assert rpdo.cob_id == 0x200 + NODE and tpdo1.cob_id == 0x180 + NODE
        assert tpdo1.bits == 64 and tpdo2.bits == 40
        assert rpdo.map.transmission == (1 if mode.startswith("cs") else 255)
    with pytest.raises(BadParameterError, match="one of pp, csp, pv"):
        cia402_maps("ip")  # type: ignore[arg-type]


def test_a_rig_files_pdo_entry_is_strict() -> None:
    import msgspec

    spec = msgspec.convert(
        {"pdo": "tpdo3", "objects": ["Statusword", "0x6064"], "transmission": 2},
        PdoSpec,
    )
    (resolved,) = resolve_maps([spec.to_map()], OD, NODE)
    assert resolved.communication == 0x1802 and resolved.mapping == 0x1A02
    assert resolved.cob_id == 0x380 + NODE
    with pytest.raises(msgspec.ValidationError, match="unknown field `mode`"):
        msgspec.convert({"pdo": "tpdo1", "objects": [], "mode": 1}, PdoSpec)
    with pytest.raises(BadParameterError, match="rpdoN or tpdoN"):
        PdoSpec(pdo="xpdo1", objects=["Statusword"]).to_map()


# -- our master, our simulated drive -----------------------------------------------------------
async def test_configure_writes_in_cia_301_order_and_verifies(
    peers: Peers, host_bus: CanBus, channel: str
) -> None:
    sim = await peers.start(SimCia402Drive(NODE))
    sdo = SdoClient(host_bus, NODE, timeout=0.5, od=OD)
    pdos = resolve_maps(cia402_maps("csp"), OD, NODE)
    with anyio.fail_after(10):
        await configure_pdos(sdo, pdos)
        held = await read_pdo(sdo, "tpdo", 1)
    assert held == (0x180 + NODE, 1, (0x6041_0010, 0x6064_0020, 0x6077_0010))
    assert sim.od[(0x1600, 0)].value == 2 and sim.od[(0x1600, 2)].value == 0x607A_0020
    assert sim.od[(0x1400, 2)].value == 1  # applied every SYNC


async def test_a_mapping_the_drive_refuses_names_the_object(
    peers: Peers, host_bus: CanBus, tmp_path: Path
) -> None:
    """Our copy of the EDS says the heartbeat time is mappable, the drive's does not: the
    drive aborts the mapping entry and the error names the PDO, the object and the abort."""
    text = SHIPPED_EDS.read_text()
    section = text.index("[1017]")
    end = text.index("\n[", section + 1)
    patched = (
        text[:section] + text[section:end].replace("PDOMapping=0", "PDOMapping=1") + text[end:]
    )
    eds = tmp_path / "optimistic.eds"
    eds.write_text(patched)
    optimistic = load_od(eds, node_id=NODE)
    await peers.start(SimCia402Drive(NODE))
    sdo = SdoClient(host_bus, NODE, timeout=0.5, od=optimistic)
    pdos = resolve_maps([PdoMap("tpdo", 3, ("Producer heartbeat time",))], optimistic, NODE)
    with anyio.fail_after(10), pytest.raises(PdoMappingError) as info:
        await configure_pdos(sdo, pdos)
    assert "TPDO3: the node refused to map Producer heartbeat time (0x1017:0)" in str(info.value)
    assert "0x06040041" in str(info.value)


async def test_a_node_holding_another_mapping_is_refused(
    peers: Peers, host_bus: CanBus, monkeypatch: pytest.MonkeyPatch
) -> None:
    sim = await peers.start(SimCia402Drive(NODE))
    sdo = SdoClient(host_bus, NODE, timeout=0.5, od=OD)
    pdos = resolve_maps([PdoMap("tpdo", 2, ("Velocity actual value",))], OD, NODE)
    real_write = sdo.write

    async def lossy_write(entry: object, value: object, **kwargs: object) -> None:
        if getattr(entry, "index", None) == 0x1801 and getattr(entry, "subindex", None) == 2:
            value = 2  # the write "went wrong": the node takes another (valid) type
        await real_write(entry, value, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(sdo, "write", lossy_write)
    with (
        anyio.fail_after(10),
        pytest.raises(PdoMappingError, match="TPDO2: holds COB-ID 0x286, transmission 2"),
    ):
        await configure_pdos(sdo, pdos)
    assert sim.od[(0x1801, 1)].value & co.PDO_COB_ID_INVALID == 0  # enabled, mapped wrong


# -- canopen-py's LocalNode, mastered by us ----------------------------------------------------
@pytest.fixture
def network(channel: str) -> Iterator[canopen.Network]:
    net = canopen.Network()
    net.connect(interface="virtual", channel=channel, receive_own_messages=False)
    try:
        yield net
    finally:
        net.disconnect()


async def test_our_master_maps_and_starts_a_canopen_py_local_node(
    network: canopen.Network, host_bus: CanBus
) -> None:
    local = canopen.LocalNode(NODE, str(SHIPPED_EDS))
    network.add_node(local)
    sdo = SdoClient(host_bus, NODE, timeout=0.5, od=OD)
    pdos = resolve_maps(cia402_maps("csp"), OD, NODE)
    with anyio.fail_after(10):
        await configure_pdos(sdo, pdos)
    # the mapping is in canopen-py's own object dictionary store
    assert local.sdo[0x1600][1].raw == 0x6040_0010
    assert local.sdo[0x1600][2].raw == 0x607A_0020
    assert local.sdo[0x1A00][0].raw == 3 and local.sdo[0x1800][2].raw == 1
    # canopen-py reads the mapping from its dictionary and decodes OUR RPDO by it
    await _in_thread(lambda: local.rpdo.read(from_od=False))  # from its data store
    rpdo = local.rpdo[1]
    assert [v.name for v in rpdo.map] == ["Controlword", "Target position"]
    frame = pdos[0].codec().pack([0x000F, -123456])
    sender = host_bus.attach([], name="master")
    try:
        with anyio.fail_after(5):
            await sender.send(*co.encode(co.NmtControl(co.NmtCommand.START, NODE)))
            while local.nmt.state != "OPERATIONAL":  # noqa: ASYNC110 - canopen-py's thread sets it
                await anyio.sleep(0.01)
            await sender.send(pdos[0].cob_id, frame)
            await _in_thread(lambda: rpdo.wait_for_reception(timeout=5))
    finally:
        sender.close()
    assert rpdo["Target position"].raw == -123456 and rpdo["Controlword"].raw == 0x000F
    # and its TPDO, sent from its dictionary, is decoded by our codec of the same map
    await _in_thread(lambda: local.tpdo.read(from_od=False))
    assert [v.name for v in local.tpdo[1].map] == [
        "Statusword",
        "Position actual value",
        "Torque actual value",
    ]
    local.tpdo[1]["Position actual value"].raw = 98765
    local.tpdo[1]["Statusword"].raw = 0x0237
    port = host_bus.attach([pdos[1].cob_id], name="test")
    try:
        local.tpdo[1].transmit()
        with anyio.fail_after(5):
            frames = await port.__anext__()
        statusword, position, _torque = pdos[1].codec().unpack(frames[-1].data)
    finally:
        port.close()
    assert (statusword, position) == (0x0237, 98765)


# -- our simulated drive, mastered by canopen-py ----------------------------------------------
async def test_canopen_py_masters_our_simulated_drive_with_its_pdo_and_sync_tooling(
    peers: Peers, network: canopen.Network
) -> None:
    sim = await peers.start(SimCia402Drive(NODE))
    node = canopen.RemoteNode(NODE, str(SHIPPED_EDS))
    network.add_node(node)

    def configure() -> None:
        node.nmt.state = "PRE-OPERATIONAL"
        node.tpdo.read()  # the drive's mapping, by SDO
        node.rpdo.read()
        node.tpdo[1].clear()
        node.tpdo[1].add_variable("Statusword")
        node.tpdo[1].add_variable("Position actual value")
        node.tpdo[1].trans_type = 1
        node.tpdo[1].enabled = True
        node.rpdo[1].clear()
        node.rpdo[1].add_variable("Controlword")
        node.rpdo[1].trans_type = 255
        node.rpdo[1].enabled = True
        node.tpdo.save()  # CiA 301's sequence, by canopen-py, against our SDO server
        node.rpdo.save()
        node.nmt.state = "OPERATIONAL"

    await _in_thread(configure)
    assert sim.od[(0x1A00, 0)].value == 2 and sim.od[(0x1A00, 2)].value == 0x6064_0020

    def drive() -> list[int]:
        network.sync.start(0.005)
        try:
            words = []
            for control in (0x0006, 0x0007, 0x000F):  # shutdown, switch on, enable operation
                node.rpdo[1]["Controlword"].raw = control
                node.rpdo[1].transmit()
                node.tpdo[1].wait_for_reception(timeout=2)
                node.tpdo[1].wait_for_reception(timeout=2)  # the SYNC after the command
                words.append(node.tpdo[1]["Statusword"].raw & 0x6F)
            return words
        finally:
            network.sync.stop()

    words = await _in_thread(drive)
    # ready to switch on, switched on, operation enabled (bits 0-3, 5, 6 of the statusword)
    assert words == [0x21, 0x23, 0x27]
    assert math.isclose(sim.position, 0.0, abs_tol=1e-9)
