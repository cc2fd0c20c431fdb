"""The bus monitor's PDO and SDO decoding (:mod:`openel_can.monitor_canopen`) against
canopen-py: PDO frames that canopen-py's maps build from the same EDS decode field by field
to the values canopen-py was given, on the wire too; a segmented SDO transfer of canopen-py's
client with our simulated drive is followed to its value and size."""

from __future__ import annotations

import random
from pathlib import Path
from typing import Any

import anyio
import can
import canopen
import pytest

from openel_async.rig import SimulatedDevice
from openel_can import cyclic402, node402
from openel_can.bus import CanBus
from openel_can.monitor import Decoded, Decoder, monitor
from openel_can.monitor_canopen import (
    CanopenKnowledge,
    PdoLayout,
    fixed_layouts,
    rig_knowledge,
)
from openel_can.od import SHIPPED_EDS
from openel_can.sim.cia402 import OPERATING_TIME, SimCia402Drive

from .conftest import Peers, canopen_network, in_thread

NODE = 2


def _device(**params: object) -> SimulatedDevice:
    return SimulatedDevice("AXIS", "can", "cia402_drive", {"node_id": NODE, **params}, None)


def _canopen_map(node: canopen.RemoteNode, layout: PdoLayout) -> Any:
    maps = node.tpdo if layout.name.startswith("TPDO") else node.rpdo
    pdo_map = maps[int(layout.name[4:])]
    pdo_map.clear()
    for entry in layout.entries:
        pdo_map.add_variable(entry.index, entry.subindex)
    return pdo_map


def _msg(cob_id: int, data: bytes) -> can.Message:
    return can.Message(arbitration_id=cob_id, data=data, is_extended_id=False)


def _random_values(pdo_map: Any, rng: random.Random) -> dict[str, int]:
    values = {}
    for var in pdo_map.map:
        bits = var.length
        signed = var.od.data_type in (
            canopen.objectdictionary.INTEGER8,
            canopen.objectdictionary.INTEGER16,
            canopen.objectdictionary.INTEGER32,
        )
        low, high = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)
        var.raw = values[var.name] = rng.randint(low, high)
    return values


def test_the_fixed_maps_are_the_drivers() -> None:
    maps = fixed_layouts(NODE, "pp")
    objects = {layout.name: tuple(e.index for e in layout.entries) for layout in maps.values()}
    assert [objects[f"RPDO{n}"] for n in (1, 2, 3)] == [
        tuple(o.index for o in m) for m in node402.RPDO_MAPS
    ]
    assert [objects["TPDO1"], objects["TPDO2"]] == [
        tuple(o.index for o in m) for m in node402.TPDO_MAPS
    ]
    cyclic = {layout.name: layout for layout in fixed_layouts(NODE, "csp").values()}
    assert tuple(e.index for e in cyclic["TPDO2"].entries) == tuple(
        o.index for o in cyclic402.STATUS_TPDO_MAP
    )
    assert set(maps) == {0x202, 0x302, 0x402, 0x182, 0x282}


@pytest.mark.parametrize(
    "params",
    [
        {},  # the fixed maps
        {"mode": "csv"},
        {"mode": "csp", "eds": "openel_servo402.eds"},  # the defaults of the mode, by the EDS
        {
            "eds": "openel_servo402.eds",
            "pdos": [
                {"pdo": "rpdo1", "objects": ["Controlword", "0x6060", "Target position"]},
                {"pdo": "tpdo3", "objects": ["0x6041", "0x6061", "0x606C"], "cob_id": 0x3A2},
            ],
        },
    ],
)
def test_frames_canopen_builds_decode_to_its_values(params: dict[str, object]) -> None:
    known = rig_knowledge([_device(**params)])
    assert known.pdos and NODE in known.ods
    remote = canopen.RemoteNode(NODE, str(SHIPPED_EDS))
    rng = random.Random(25)
    for cob_id, layout in known.pdos.items():
        pdo_map = _canopen_map(remote, layout)
        for _ in range(5):
            values = _random_values(pdo_map, rng)
            frame = _msg(cob_id, bytes(pdo_map.data))
            decoded = Decoder(known=known).decode(frame)
            assert not decoded.malformed, decoded.text
            assert {f["name"]: f["value"] for f in decoded.fields} == values
            assert decoded.text.startswith(f"node {NODE} {layout.name} ")
        # a frame one byte short or long is flagged
        for data in (bytes(pdo_map.data)[:-1], bytes(pdo_map.data) + b"\x00"):
            bad = Decoder(known=known).decode(_msg(cob_id, data))
            assert bad.malformed and "malformed" in bad.text and not bad.fields


def test_a_pdo_line_names_fields_and_types() -> None:
    known = CanopenKnowledge()
    known.add_fixed(NODE)
    decoder = Decoder(known=known)
    rpdo = decoder.decode(_msg(0x202, bytes.fromhex("0f003930 0000")))
    assert rpdo.text == "node 2 RPDO1 Controlword=0x000f Target position=12345"
    tpdo = decoder.decode(_msg(0x182, bytes.fromhex("3702 d2040000 f6ff")))
    assert tpdo.text == (
        "node 2 TPDO1 Statusword=0x0237 OPERATION_ENABLED Position actual value=1234 "
        "Torque actual value=-10"
    )
    assert [f["type"] for f in tpdo.to_dict()["fields"]] == ["UNSIGNED16", "INTEGER32", "INTEGER16"]
    # a PDO of a node nobody described stays raw
    assert Decoder().decode(_msg(0x183, b"\x01")).text == ("node 3 TPDO1 01")


async def test_canopen_pdos_and_a_segmented_sdo_on_the_wire(peers: Peers, channel: str) -> None:
    """canopen-py sends an RPDO and a TPDO on the bus and reads a 64-bit object of our
    simulated drive by segmented upload, while the monitor watches."""
    await peers.start(SimCia402Drive(NODE))
    known = rig_knowledge([_device(eds="openel_servo402.eds", mode="csp")])
    seen: list[Decoded] = []
    with canopen_network(interface="virtual", channel=channel, receive_own_messages=False) as net:
        remote = canopen.RemoteNode(NODE, str(SHIPPED_EDS))
        net.add_node(remote)
        rpdo = _canopen_map(remote, known.pdos[0x202])
        tpdo = _canopen_map(remote, known.pdos[0x182])
        rpdo.cob_id, tpdo.cob_id = 0x202, 0x182
        rpdo["Controlword"].raw, rpdo["Target position"].raw = 0x0F, -98765
        tpdo["Statusword"].raw, tpdo["Position actual value"].raw = 0x0237, 4321
        tpdo["Torque actual value"].raw = -7

        def talk() -> int:
            rpdo.transmit()
            tpdo.transmit()
            value: int = remote.sdo[OPERATING_TIME.index].raw
            return value

        async with (
            CanBus(interface="virtual", channel=channel) as bus,
            anyio.create_task_group() as tg,
        ):

            async def watch() -> None:
                await monitor(bus, Decoder(known=known), duration=0.5, on_frame=seen.append)

            tg.start_soon(watch)
            await anyio.sleep(0.05)
            uptime = await in_thread(talk)
    texts = [d.text for d in seen]
    assert "node 2 RPDO1 Controlword=0x000f Target position=-98765" in texts
    assert (
        "node 2 TPDO1 Statusword=0x0237 OPERATION_ENABLED Position actual value=4321 "
        "Torque actual value=-7" in texts
    )
    start = next(t for t in texts if "SegmentedUploadResponse" in t)
    assert start.startswith("node 2 SDO SegmentedUploadResponse 2030:00 ") and "size=8" in start
    done = next(t for t in texts if ": upload 2030:00" in t)
    assert done.endswith(f"= {uptime} ({uptime.to_bytes(8, 'little').hex(' ')}), 8 bytes")
    assert not any(d.malformed for d in seen)


def test_a_rig_drive_s_files_are_checked(tmp_path: Path) -> None:
    with pytest.raises(Exception, match="eds"):
        rig_knowledge([_device(eds=str(tmp_path / "missing.eds"))])
