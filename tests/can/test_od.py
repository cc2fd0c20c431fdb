"""Object dictionaries from EDS/DCF files: openel_can.od, the SDO client by name, the
simulated drive built from the shipped EDS, a DCF's parameter values written at init."""

from __future__ import annotations

import configparser
import struct
from pathlib import Path

import anyio
import pytest
from canopen import objectdictionary as cod
from hypothesis import given
from hypothesis import strategies as st

from openel_async.errors import BadParameterError
from openel_can import CanBus, SdoAbortError, SdoClient
from openel_can import canopen as co
from openel_can.od import (
    SHIPPED_EDS,
    Access,
    ObjectNotFoundError,
    OdEntry,
    load_od,
    parse_key,
    write_parameter_values,
)
from openel_can.sim.cia402 import SimCia402Drive
from openel_can.sim.objects import REQUIRED_OBJECTS

from .conftest import Peers

NODE = 5
OD = load_od(SHIPPED_EDS, node_id=NODE)

# The CiA 402 objects the drive uses, with their data types in the shipped file.
CIA402 = {
    0x6040: co.DataType.UNSIGNED16,
    0x6041: co.DataType.UNSIGNED16,
    0x6060: co.DataType.INTEGER8,
    0x6061: co.DataType.INTEGER8,
    0x6064: co.DataType.INTEGER32,
    0x606C: co.DataType.INTEGER32,
    0x6077: co.DataType.INTEGER16,
    0x607A: co.DataType.INTEGER32,
    0x60FF: co.DataType.INTEGER32,
    0x6071: co.DataType.INTEGER16,
    0x6076: co.DataType.UNSIGNED32,
    0x605A: co.DataType.INTEGER16,
    0x6007: co.DataType.INTEGER16,
    0x603F: co.DataType.UNSIGNED16,
    0x1017: co.DataType.UNSIGNED16,
    0x1005: co.DataType.UNSIGNED32,
    0x1006: co.DataType.UNSIGNED32,
    0x2022: co.DataType.INTEGER16,
}


def test_shipped_eds_has_the_cia402_objects_the_drive_uses() -> None:
    for index, data_type in CIA402.items():
        assert OD[index].object_entry == co.ObjectEntry(index, 0, data_type), hex(index)
    for key in [(0x608F, 1), (0x608F, 2), (0x60C2, 1), (0x60C2, 2), (0x1016, 1)]:
        assert key in OD
    for base in (0x1400, 0x1600, 0x1800, 0x1A00):
        for n in range(4):
            assert OD.has_index(base + n), hex(base + n)
    assert OD.supported_modes() == {1, 3, 4, 8, 9, 10}  # pp pv tq csp csv cst
    assert OD.device["nr_of_RXPDO"] == OD.device["nr_of_TXPDO"] == 4
    assert all(key in OD for key in REQUIRED_OBJECTS)


def test_entries_carry_type_access_mapping_defaults_and_limits() -> None:
    cw = OD["Controlword"]
    assert (cw.index, cw.subindex, cw.access, cw.pdo_mappable) == (0x6040, 0, Access.RWW, True)
    assert cw.rpdo_mappable and not cw.tpdo_mappable and cw.type_name == "UNSIGNED16"
    sw = OD["Statusword"]
    assert sw.tpdo_mappable and not sw.rpdo_mappable and not sw.writable
    assert OD["Modes of operation"].signed and OD["Modes of operation"].bit_length == 8
    assert OD["0x1400:1"].default == 0x200 + NODE  # $NODEID resolved
    assert OD["0x1401:1"].default == 0x8000_0300 + NODE  # RPDO2 invalid by default
    assert OD["Identity object.Vendor-ID"] is OD[(0x1018, 1)] is OD["0x1018sub1"]
    assert OD["Manufacturer device name"].default == "OpenEL servo 402"
    assert OD["Manufacturer device name"].size is None  # variable length
    assert (OD["Abort connection option code"].low, OD["Abort connection option code"].high) == (
        0,
        3,
    )
    assert OD["Software position limit.Min position limit"].default == -(2**31)
    assert OD["statusword"] is sw  # a name ignoring case, when unique
    assert not OD.find("0x6040:1") and OD.is_record(0x1018) and not OD.is_record(0x6040)


@pytest.mark.parametrize(
    ("key", "says"),
    [
        ("Controlwort", "closest: 'Controlword'"),
        (0x1018, "0x1018 is a record/array: name a sub-index"),
        ("0x1018:9", "0x1018 has sub-indices 0x1018:0"),
        ((0x5FFF, 0), "object='0x5fff:0'"),
        ("no such thing", "openel_servo402.eds by name"),
    ],
)
def test_unknown_objects_are_named_with_what_is_allowed(key: object, says: str) -> None:
    with pytest.raises(ObjectNotFoundError) as err:
        OD[key]  # type: ignore[index]
    assert isinstance(err.value, BadParameterError) and says in str(err.value)


@pytest.mark.parametrize(
    ("text", "key"),
    [
        ("0x6040", (0x6040, None)),
        ("0x1018:1", (0x1018, 1)),
        ("0x1600:a", (0x1600, 10)),
        ("1018sub1", (0x1018, 1)),
        ("0x1A00sub0A", (0x1A00, 10)),
        ("6040h", (0x6040, None)),
        ("Controlword", None),
        ("Target position", None),
    ],
)
def test_parse_key(text: str, key: tuple[int, int | None] | None) -> None:
    assert parse_key(text) == key


@given(index=st.integers(0, 0xFFFF), sub=st.integers(0, 0xFF), sep=st.sampled_from([":", "sub"]))
def test_parse_key_round_trips_any_index_text(index: int, sub: int, sep: str) -> None:
    assert parse_key(f"0x{index:04X}{sep}{sub:X}") == (index, sub)
    assert parse_key(f"{index:#x}") == (index, None)


_INT_TYPES = [(code, bits, signed) for code, (bits, signed) in
              {cod.INTEGER8: (8, True), cod.INTEGER16: (16, True), cod.INTEGER24: (24, True),
               cod.INTEGER32: (32, True), cod.INTEGER64: (64, True), cod.UNSIGNED8: (8, False),
               cod.UNSIGNED16: (16, False), cod.UNSIGNED40: (40, False),
               cod.UNSIGNED32: (32, False), cod.UNSIGNED64: (64, False)}.items()]  # fmt: skip


def _entry(data_type: int, **kw: object) -> OdEntry:
    return OdEntry(0x2100, 0, "Test object", data_type, Access.RW, True, **kw)  # type: ignore[arg-type]


@given(data=st.data(), spec=st.sampled_from(_INT_TYPES))
def test_integer_encoding_agrees_with_canopen(
    data: st.DataObject, spec: tuple[int, int, bool]
) -> None:
    code, bits, signed = spec
    low, high = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)
    value = data.draw(st.integers(low, high))
    ours = _entry(code)
    theirs = cod.ODVariable("x", 0x2100, 0)
    theirs.data_type = code
    assert ours.encode(value) == theirs.encode_raw(value)
    assert ours.decode(ours.encode(value)) == value == theirs.decode_raw(ours.encode(value))
    with pytest.raises(BadParameterError, match=r"Test object \(0x2100:0\)"):
        ours.encode(data.draw(st.one_of(st.integers(high + 1), st.integers(max_value=low - 1))))


@given(st.floats(allow_nan=False, width=32))
def test_real32_round_trips(value: float) -> None:
    assert _entry(cod.REAL32).decode(_entry(cod.REAL32).encode(value)) == value


def test_values_are_checked_against_type_and_limits() -> None:
    option = OD["Abort connection option code"]
    assert option.encode(3) == b"\x03\x00"
    with pytest.raises(BadParameterError, match=r"0x6007:0.*LowLimit\.\.HighLimit"):
        option.encode(4)
    with pytest.raises(BadParameterError, match="INTEGER16"):
        option.encode(1.5)
    with pytest.raises(BadParameterError, match="printable text"):
        OD["Manufacturer device name"].encode("caf\u00e9")
    assert (
        _entry(cod.BOOLEAN).encode(True) == b"\x01" and _entry(cod.BOOLEAN).decode(b"\x00") is False
    )
    assert _entry(cod.OCTET_STRING).encode(b"\x01\x02") == b"\x01\x02"
    assert _entry(cod.UNICODE_STRING).decode("hi".encode("utf-16-le")) == "hi"
    with pytest.raises(BadParameterError, match="supports"):
        _entry(cod.TIME_OF_DAY).encode(0)
    with pytest.raises(BadParameterError, match=r"canopen\.DataType"):
        _ = OD["Manufacturer device name"].object_entry


def test_load_refuses_missing_or_malformed_files(tmp_path: Path) -> None:
    with pytest.raises(BadParameterError, match="an existing EDS or DCF file"):
        load_od(tmp_path / "nope.eds")
    with pytest.raises(BadParameterError, match=r"\(\.eds\) or DCF"):
        load_od(tmp_path / "drive.xdd")
    bad = tmp_path / "bad.eds"
    bad.write_text("[6040]\nParameterName=Controlword\nDataType=0x0006\nAccessType=sometimes\n")
    with pytest.raises(BadParameterError, match="AccessType 'sometimes'"):
        load_od(bad)
    (tmp_path / "broken.eds").write_text("[6040\nnot ini")
    with pytest.raises(BadParameterError, match="CiA 306"):
        load_od(tmp_path / "broken.eds")


def _dcf(tmp_path: Path, values: dict[str, str], node_id: int = NODE) -> Path:
    """A DCF from the shipped EDS: ParameterValue entries and the commissioned node id."""
    parser = configparser.RawConfigParser()
    parser.optionxform = str  # type: ignore[assignment,method-assign]
    parser.read(SHIPPED_EDS)
    for section, value in values.items():
        parser.set(section, "ParameterValue", value)
    parser.add_section("DeviceComissioning")
    parser.set("DeviceComissioning", "NodeID", str(node_id))
    parser.set("DeviceComissioning", "Baudrate", "1000")
    path = tmp_path / "drive.dcf"
    with path.open("w") as f:
        parser.write(f)
    return path


DCF_VALUES = {
    "6081": "5000",  # profile velocity
    "605A": "6",  # quick stop option code
    "1017": "200",  # producer heartbeat
    "1008": "renamed",  # const: not written
    "1018sub1": "0x1234",  # ro: not written
    "1600sub1": "0x60410010",  # PDO mapping: left to pdomap.configure_pdos
    "2031": "-7",  # energy limit (64-bit: segmented)
}


def test_dcf_has_its_node_id_and_parameter_values(tmp_path: Path) -> None:
    dcf = load_od(_dcf(tmp_path, DCF_VALUES, node_id=9))
    assert dcf.node_id == 9 and dcf["0x1800:1"].default == 0x189
    assert dcf["Profile velocity"].parameter_value == 5000 == dcf["Profile velocity"].value
    assert dcf["Profile deceleration"].value == dcf["Profile deceleration"].default
    assert [e.index for e in dcf.parameter_values()] == [
        0x1008,
        0x1017,
        0x1018,
        0x1600,
        0x2031,
        0x605A,
        0x6081,
    ]


# -- over the bus: our SDO client by name, the simulated drive from the EDS ------------------
async def test_sdo_client_reads_and_writes_by_name(peers: Peers, host_bus: CanBus) -> None:
    sim = await peers.start(SimCia402Drive(NODE))
    sdo = SdoClient(host_bus, NODE, timeout=0.5, od=OD)
    with anyio.fail_after(5):
        assert await sdo.read("Manufacturer device name") == "OpenEL servo 402"  # segmented
        assert await sdo.read("Identity object.Serial number") == 0x1234_0000 + NODE
        assert await sdo.read((0x1400, 1)) == 0x200 + NODE
        await sdo.write("Target position", -1234)
        await sdo.write(OD["Energy limit"], -(2**40))
        assert await sdo.read("0x2031") == -(2**40)
        assert await sdo.read(co.ObjectEntry(0x607A, 0, co.DataType.INTEGER32)) == -1234
        with pytest.raises(BadParameterError, match=r"Statusword \(0x6041:0\).*access is ro"):
            await sdo.write("Statusword", 1)
        with pytest.raises(BadParameterError, match="INTEGER8"):
            await sdo.write("Modes of operation", 300)
        with pytest.raises(ObjectNotFoundError, match="closest: 'Target position'"):
            await sdo.read("Target positon")
        assert await sdo.read("Supported drive modes") == 0b11_1000_1101  # pp pv tq csp csv cst
    assert sim.od[(0x607A, 0)].value == -1234
    assert sdo.transfers == 8  # refusals send nothing
    with pytest.raises(BadParameterError, match="no object dictionary"):
        await SdoClient(host_bus, NODE).read("Statusword")


async def test_sim_access_rights_and_mapping_rules_come_from_the_file(
    peers: Peers, host_bus: CanBus
) -> None:
    await peers.start(SimCia402Drive(NODE))
    sdo = SdoClient(host_bus, NODE, timeout=0.5)
    u8, u32 = co.DataType.UNSIGNED8, co.DataType.UNSIGNED32
    with anyio.fail_after(5):
        with pytest.raises(SdoAbortError) as const:
            await sdo.download(0x1008, 0, b"x")  # const string
        assert const.value.abort_code == co.SdoAbortCode.READ_ONLY
        await sdo.write(co.ObjectEntry(0x1A01, 1, u32), 0x6040_0010)  # TPDO2 is invalid
        with pytest.raises(SdoAbortError) as rww:  # Controlword is rww: RPDO only
            await sdo.write(co.ObjectEntry(0x1A01, 0, u8), 1)
        assert rww.value.abort_code == co.SdoAbortCode.CANNOT_BE_MAPPED
        await sdo.write(co.ObjectEntry(0x1601, 1, u32), 0x6041_0010)
        with pytest.raises(SdoAbortError) as ro:  # Statusword is ro: TPDO only
            await sdo.write(co.ObjectEntry(0x1601, 0, u8), 1)
        assert ro.value.abort_code == co.SdoAbortCode.CANNOT_BE_MAPPED
        await sdo.write(co.ObjectEntry(0x1601, 1, u32), 0x6081_0020)  # rw + mappable
        await sdo.write(co.ObjectEntry(0x1601, 0, u8), 1)


def _edited_eds(tmp_path: Path, edit: dict[str, dict[str, str] | None]) -> Path:
    parser = configparser.RawConfigParser()
    parser.optionxform = str  # type: ignore[assignment,method-assign]
    parser.read(SHIPPED_EDS)
    for section, options in edit.items():
        if options is None:
            parser.remove_section(section)
        else:
            for key, value in options.items():
                parser.set(section, key, value)
    path = tmp_path / "vendor.eds"
    with path.open("w") as f:
        parser.write(f)
    return path


async def test_sim_loads_another_eds(peers: Peers, host_bus: CanBus, tmp_path: Path) -> None:
    eds = _edited_eds(tmp_path, {"6072": {"DefaultValue": "1500"}, "6081": {"PDOMapping": "0"}})
    sim = await peers.start(SimCia402Drive(NODE, eds=eds))
    assert sim.od[(0x6072, 0)].value == 1500 and not sim.od[(0x6081, 0)].mappable
    sdo = SdoClient(host_bus, NODE, timeout=0.5)
    with anyio.fail_after(5):
        assert await sdo.read(co.ObjectEntry(0x6072, 0, co.DataType.UNSIGNED16)) == 1500
        await sdo.write(co.ObjectEntry(0x1601, 1, co.DataType.UNSIGNED32), 0x6081_0020)
        with pytest.raises(SdoAbortError) as refused:
            await sdo.write(co.ObjectEntry(0x1601, 0, co.DataType.UNSIGNED8), 1)
    assert refused.value.abort_code == co.SdoAbortCode.CANNOT_BE_MAPPED


def test_sim_refuses_an_eds_without_the_objects_it_needs(tmp_path: Path) -> None:
    eds = _edited_eds(tmp_path, {"6087": None})
    with pytest.raises(ValueError, match=r"lacks objects .*0x6087:0"):
        SimCia402Drive(NODE, eds=eds)


async def test_dcf_parameter_values_are_written_to_the_drive(
    peers: Peers, host_bus: CanBus, tmp_path: Path
) -> None:
    sim = await peers.start(SimCia402Drive(NODE))
    dcf = load_od(_dcf(tmp_path, DCF_VALUES))
    sdo = SdoClient(host_bus, NODE, timeout=0.5, od=dcf)
    with anyio.fail_after(5):
        written = await write_parameter_values(sdo, dcf)
    assert [e.label for e in written] == [
        "Producer heartbeat time (0x1017:0)",
        "Energy limit (0x2031:0)",
        "Quick stop option code (0x605a:0)",
        "Profile velocity (0x6081:0)",
    ]
    assert sim.od[(0x6081, 0)].value == 5000 and sim.od[(0x605A, 0)].value == 6
    assert sim.od[(0x1017, 0)].value == 200 and sim.od[(0x2031, 0)].value == -7
    assert sim.od[(0x1600, 1)].value == 0x6040_0010  # PDO mapping untouched
    assert struct.pack("<H", 200) == dcf["0x1017"].encode(200)


def test_shipped_eds_is_package_data() -> None:
    from importlib.resources import files

    assert SHIPPED_EDS.is_file()
    assert files("openel_can").joinpath("eds/openel_servo402.eds").is_file()
    assert files("openel_can").joinpath("eds/README.md").is_file()
