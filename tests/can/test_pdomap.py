"""PDO maps (openel_can.pdomap): specs from a rig file, checks against the EDS, the CiA 301
configure sequence on the simulated drive, read-back verification, DCF PDOs."""

from __future__ import annotations

import configparser
import re
from pathlib import Path

import anyio
import msgspec
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from openel_async.errors import BadParameterError
from openel_can import CanBus, SdoClient
from openel_can import canopen as co
from openel_can.od import SHIPPED_EDS, ObjectDictionary, ObjectKey, OdEntry, OdValue, load_od
from openel_can.pdomap import (
    PdoConfigError,
    PdoMapError,
    PdoSpec,
    PdoVerifyError,
    configure_pdos,
    default_pdos,
    dump_pdos,
    maps_from_od,
    parse_pdos,
    resolve_pdos,
)
from openel_can.sim.cia402 import SimCia402Drive

from .conftest import Peers

NODE = 5
OD = load_od(SHIPPED_EDS, node_id=NODE)


@pytest.mark.parametrize(
    ("mode", "target", "ttype"),
    [
        ("pp", 0x607A, 0xFF),
        ("pv", 0x60FF, 0xFF),
        ("tq", 0x6071, 0xFF),
        ("csp", 0x607A, 1),
        ("csv", 0x60FF, 1),
        ("cst", 0x6071, 1),
        (8, 0x607A, 1),
    ],
)
def test_default_maps_per_mode(mode: str | int, target: int, ttype: int) -> None:
    rpdo1, tpdo1, tpdo2 = resolve_pdos(default_pdos(mode), OD)
    assert [e.index for e in rpdo1.entries] == [0x6040, target]
    assert [e.index for e in tpdo1.entries] == [0x6041, 0x6064, 0x6077]
    cyclic = ttype != 0xFF
    assert [e.index for e in tpdo2.entries] == ([0x6041, 0x6061] if cyclic else [0x606C, 0x6061])
    assert tpdo2.transmission_type == 0xFF and tpdo2.event_ms == (0 if cyclic else 10)
    assert (rpdo1.cob_id, tpdo1.cob_id, tpdo2.cob_id) == (0x205, 0x185, 0x285)
    assert rpdo1.transmission_type == tpdo1.transmission_type == ttype
    assert tpdo1.event_ms == (10 if ttype == 0xFF else 0) and tpdo1.bits == 64
    with pytest.raises(BadParameterError, match="csp, csv, cst"):
        default_pdos("homing")


def _refusal(spec: PdoSpec, od: ObjectDictionary = OD) -> str:
    with pytest.raises(PdoMapError) as err:
        resolve_pdos([PdoSpec(pdo="tpdo3", objects=("Statusword",)), spec], od)
    assert isinstance(err.value, BadParameterError)
    return str(err.value)


@pytest.mark.parametrize(
    ("spec", "says"),
    [
        (
            PdoSpec(pdo="rpdo1", objects=("Controlword", "Max torque")),
            r"pdos\[1\]\.objects\[1\]='Max torque'.*Max torque \(0x6072:0\) is not \(PDOMapping=0",
        ),
        (
            PdoSpec(pdo="rpdo2", objects=("Statusword",)),
            r"written by the master \(wo, rw, rww\): Statusword \(0x6041:0\) is ro",
        ),
        (
            PdoSpec(pdo="tpdo1", objects=("Controlword",)),
            r"readable by the node .*Controlword \(0x6040:0\) is rww",
        ),
        (
            PdoSpec(
                pdo="tpdo1", objects=("Position actual value", "Velocity actual value", "0x6041")
            ),
            r"objects\[2\]='0x6041'.*at most 64 bits in TPDO1: Statusword \(0x6041:0\) \(16 bits\) makes 80",
        ),
        (PdoSpec(pdo="tpdo1", objects=("Statusward",)), r"closest: 'Statusword'"),
        (
            PdoSpec(pdo="rpdo5", objects=()),
            r"rpdo5.*RPDOs 1\.\.4: 0x1404/0x1604 are not in the file",
        ),
        (PdoSpec(pdo="tpdo1", trigger="sync", event_ms=10), r"event_ms=10.*no timers"),
        (PdoSpec(pdo="rpdo1", inhibit_us=500), r"0x1400 has no sub-index 3"),
        (PdoSpec(pdo="tpdo1", every=2), r"every=2.*applies to trigger sync"),
        (PdoSpec(pdo="tpdo1", cob_id=0x385), r"TPDO3 uses it"),
        (PdoSpec(pdo="tpdo3"), r"each PDO once"),
        (
            PdoSpec(pdo="tpdo1", objects=("0x6041", "Statusword")),
            r"Statusword \(0x6041:0\) is mapped twice",
        ),
        (PdoSpec(pdo="xpdo1"), r"rpdo1\.\.rpdo512"),
    ],
)
def test_maps_a_node_would_refuse_are_named(spec: PdoSpec, says: str) -> None:
    assert re.search(says, _refusal(spec)), _refusal(spec)


def test_a_dictionary_without_node_id_needs_cob_ids() -> None:
    od = load_od(SHIPPED_EDS)
    with pytest.raises(PdoMapError, match="node id"):
        resolve_pdos([PdoSpec(pdo="tpdo1", objects=("Statusword",))], od)
    (pdo,) = resolve_pdos([PdoSpec(pdo="tpdo1", objects=("Statusword",), cob_id=0x190)], od)
    assert pdo.cob_id == 0x190


RIG_YAML = b"""
- {pdo: rpdo1, objects: [Controlword, Target position], trigger: sync}
- {pdo: tpdo1, objects: [Statusword, "0x6064"], trigger: sync, every: 2}
- {pdo: TPDO2, objects: [Velocity actual value], inhibit_us: 500, event_ms: 10}
- {pdo: tpdo4, enabled: false}
"""


def test_rig_form_parses_and_dumps() -> None:
    specs = parse_pdos(msgspec.yaml.decode(RIG_YAML))
    assert specs[1] == PdoSpec(
        pdo="tpdo1", objects=("Statusword", "0x6064"), trigger="sync", every=2
    )
    assert dump_pdos(specs)[2] == {
        "pdo": "TPDO2",
        "objects": ["Velocity actual value"],
        "inhibit_us": 500,
        "event_ms": 10,
    }
    assert parse_pdos(dump_pdos(specs)) == specs
    resolved = resolve_pdos(specs, OD)
    assert resolved[2].inhibit == 5 and resolved[1].transmission_type == 2
    for raw, says in [
        ([{"pdo": "tpdo1", "every": 241}], r"<= 240 - at `\$\[0\]\.every`"),
        ([{"pdo": "tpdo1", "inhibit_us": 150}], r"multiple of 100 - at `\$\[0\]\.inhibit_us`"),
        ([{"pdo": "tpdo1", "objectz": []}], r"unknown field `objectz`"),
        ([{"pdo": "tpdo1", "trigger": "cyclic"}], r"`\$\[0\]\.trigger`"),
    ]:
        with pytest.raises(BadParameterError, match=says):
            parse_pdos(raw, where="rig.devices.axis1.params.pdos")


_MAPPABLE = [e for e in OD if e.tpdo_mappable and e.is_integer]


@settings(max_examples=60, deadline=None)
@given(st.lists(st.sampled_from(_MAPPABLE), min_size=1, max_size=6, unique=True), st.data())
def test_any_tpdo_map_resolves_within_64_bits_and_round_trips(
    entries: list[OdEntry], data: st.DataObject
) -> None:
    spec = PdoSpec(pdo="tpdo1", objects=tuple(e.name for e in entries))
    bits = sum(e.bit_length or 0 for e in entries)
    if bits > 64:
        with pytest.raises(PdoMapError, match="at most 64 bits"):
            resolve_pdos([spec], OD)
        return
    (pdo,) = resolve_pdos([spec], OD)
    values = []
    for e in pdo.entries:
        width = e.bit_length or 0
        low, high = (
            (-(1 << (width - 1)), (1 << (width - 1)) - 1) if e.signed else (0, (1 << width) - 1)
        )
        values.append(data.draw(st.integers(low, high)))
    frame = pdo.pack(values)
    assert len(frame) == (bits + 7) // 8
    assert list(pdo.codec.unpack(frame)) == values
    by_name = pdo.unpack(frame)
    assert all(by_name[e.name] == v for e, v in zip(pdo.entries, values, strict=False))


# -- over the bus, against the simulated drive ----------------------------------------------
async def _pre_operational(sdo: SdoClient) -> None:
    # The sim boots into PRE-OPERATIONAL; any SDO answer shows it is up.
    with anyio.fail_after(2):
        await sdo.read("Statusword")


async def test_configure_writes_the_cia301_sequence_and_verifies(
    peers: Peers, host_bus: CanBus
) -> None:
    sim = await peers.start(SimCia402Drive(NODE))
    sdo = SdoClient(host_bus, NODE, timeout=0.5, od=OD)
    await _pre_operational(sdo)
    with anyio.fail_after(5):
        resolved = await configure_pdos(sdo, default_pdos("csp"))
    od = sim.od
    assert [od[(0x1600, s)].value for s in range(3)] == [2, 0x6040_0010, 0x607A_0020]
    assert [od[(0x1A00, s)].value for s in range(4)] == [3, 0x6041_0010, 0x6064_0020, 0x6077_0010]
    assert [od[(0x1A01, s)].value for s in range(3)] == [2, 0x6041_0010, 0x6061_0008]
    assert od[(0x1400, 1)].value == 0x205 and od[(0x1800, 1)].value == 0x185
    assert od[(0x1801, 1)].value == 0x285 and od[(0x1800, 2)].value == od[(0x1400, 2)].value == 1
    assert od[(0x1801, 2)].value == 0xFF  # TPDO2 (statusword, mode display) on change
    for comm in (0x1401, 0x1402, 0x1403, 0x1802, 0x1803):
        assert od[(comm, 1)].value & co.PDO_COB_ID_INVALID, hex(comm)  # unused: disabled
    # Started, the drive sends TPDO2 (event) and answers a SYNC with TPDO1; our codecs read them.
    tpdo1, tpdo2 = resolved[1], resolved[2]
    port = host_bus.attach([tpdo1.cob_id, tpdo2.cob_id], name="test-tpdos")
    try:
        await port.send(*co.encode(co.NmtControl(co.NmtCommand.START, NODE)))
        with anyio.fail_after(2):
            while sim.nmt_state is not co.NmtState.OPERATIONAL:  # noqa: ASYNC110
                await anyio.sleep(0.001)
            await port.send(*co.encode(co.Sync()))
            got: dict[int, dict[str, int]] = {}
            while len(got) < 2:
                for frame in await port.receive():
                    pdo = tpdo1 if frame.arbitration_id == tpdo1.cob_id else tpdo2
                    got[frame.arbitration_id] = pdo.unpack(frame.data)
    finally:
        port.close()
    assert got[0x185]["Statusword"] == sim.statusword()
    assert got[0x285]["Modes of operation display"] == 1


async def test_a_refusal_names_the_pdo_and_the_object(
    peers: Peers, host_bus: CanBus, tmp_path: Path
) -> None:
    """The master's EDS says Max torque is mappable; the drive (shipped EDS) refuses it."""
    parser = configparser.RawConfigParser()
    parser.optionxform = str  # type: ignore[assignment,method-assign]
    parser.read(SHIPPED_EDS)
    parser.set("6072", "PDOMapping", "1")
    eds = tmp_path / "optimistic.eds"
    with eds.open("w") as f:
        parser.write(f)
    await peers.start(SimCia402Drive(NODE))
    sdo = SdoClient(host_bus, NODE, timeout=0.5, od=load_od(eds, node_id=NODE))
    with anyio.fail_after(5), pytest.raises(PdoConfigError) as err:
        await configure_pdos(sdo, [PdoSpec(pdo="tpdo2", objects=("Max torque",))])
    message = str(err.value)
    assert "TPDO2 of node 5" in message and "count of Max torque (0x6072:0)" in message
    assert "CANNOT_BE_MAPPED" in message


class _ForgetfulClient(SdoClient):
    """An in-memory node that stores every write but reads the event timer back as 0."""

    store: dict[tuple[int, int], OdValue]

    async def write(self, entry: ObjectKey, value: object, *, timeout: float | None = None) -> None:  # noqa: ASYNC109
        assert isinstance(value, int)
        self.store[self.entry(entry).key] = value

    async def read(self, entry: ObjectKey, *, timeout: float | None = None) -> OdValue:  # type: ignore[override]  # noqa: ASYNC109
        od_entry = self.entry(entry)
        if od_entry.key == (0x1801, 5):
            return 0
        value = self.store.get(od_entry.key, od_entry.value)
        assert value is not None
        return value


async def test_read_back_mismatch_names_the_entry(host_bus: CanBus) -> None:
    sdo = _ForgetfulClient(host_bus, NODE, od=OD)
    sdo.store = {}
    with pytest.raises(
        PdoVerifyError,
        match=r"TPDO2 of node 5: TPDO communication parameter 2\.Event timer \(0x1801:5\) reads back 0x0, written 0x19",
    ):
        await configure_pdos(sdo, [PdoSpec(pdo="tpdo2", objects=("0x606C",), event_ms=25)])


async def test_dcf_pdos_are_configured(peers: Peers, host_bus: CanBus, tmp_path: Path) -> None:
    parser = configparser.RawConfigParser()
    parser.optionxform = str  # type: ignore[assignment,method-assign]
    parser.read(SHIPPED_EDS)
    values = {
        "1802sub1": "$NODEID+0x380",
        "1802sub2": "0xFE",
        "1802sub3": "20",
        "1802sub5": "50",
        "1A02sub0": "2",
        "1A02sub1": "0x20220010",
        "1A02sub2": "0x60770010",
        "1401sub1": "$NODEID+0x80000300",
    }
    for key, value in values.items():
        parser.set(key[:4] if "sub" not in key else key, "ParameterValue", value)
    parser.add_section("DeviceComissioning")
    parser.set("DeviceComissioning", "NodeID", str(NODE))
    path = tmp_path / "axis.dcf"
    with path.open("w") as f:
        parser.write(f)
    dcf = load_od(path)
    specs = maps_from_od(dcf)
    assert specs == (
        PdoSpec(pdo="rpdo2", objects=(), cob_id=0x305, enabled=False),
        PdoSpec(
            pdo="tpdo3",
            objects=("0x2022:0", "0x6077:0"),
            inhibit_us=2000,
            event_ms=50,
            cob_id=0x385,
        ),
    )
    sim = await peers.start(SimCia402Drive(NODE))
    sdo = SdoClient(host_bus, NODE, timeout=0.5, od=dcf)
    await _pre_operational(sdo)
    with anyio.fail_after(5):
        (_, tpdo3) = await configure_pdos(sdo, specs, disable_unused=False)
    assert [e.name for e in tpdo3.entries] == ["Drive temperature", "Torque actual value"]
    assert sim.od[(0x1802, 1)].value == 0x385 and sim.od[(0x1802, 3)].value == 20
    assert (
        sim.od[(0x1A02, 1)].value == 0x2022_0010
        and sim.od[(0x1401, 1)].value & co.PDO_COB_ID_INVALID
    )
    assert sim.od[(0x1800, 1)].value == 0x185  # left alone
