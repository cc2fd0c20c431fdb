"""CANopen (CiA 301 subset) codec: golden frames, round trips, PDO packing, fuzzing.

Golden SDO frames are also checked against canopen-py's own constants and structs
(an independent implementation) in ``tests/can/test_interop_canopen.py``.
"""

from __future__ import annotations

import contextlib

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from openel_can import canopen as co
from openel_can.errors import CanOpenDecodeError

nodes = st.integers(1, co.MAX_NODE_ID)
u16 = st.integers(0, 0xFFFF)
u8 = st.integers(0, 0xFF)
expedited = st.binary(min_size=1, max_size=4)
u32 = st.integers(0, 0xFFFF_FFFF)
segment = st.binary(max_size=7)
FUZZ = settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])

MESSAGES: st.SearchStrategy[co.CanOpenMessage] = st.one_of(
    st.builds(co.NmtControl, st.sampled_from(co.NmtCommand), st.integers(0, co.MAX_NODE_ID)),
    st.builds(co.Sync, st.none() | st.integers(1, 240)),
    st.builds(co.Emergency, nodes, u16, u8, st.binary(min_size=5, max_size=5)),
    st.builds(co.Heartbeat, nodes, st.sampled_from(co.NmtState), st.booleans()),
    st.builds(co.SdoUploadRequest, nodes, u16, u8),
    st.builds(co.SdoUploadResponse, nodes, u16, u8, expedited),
    st.builds(co.SdoDownloadRequest, nodes, u16, u8, expedited),
    st.builds(
        co.SdoDownloadRequest, nodes, u16, u8, st.binary(min_size=4, max_size=4), st.just(False)
    ),
    st.builds(co.SdoDownloadResponse, nodes, u16, u8),
    st.builds(co.SdoSegmentedUploadResponse, nodes, u16, u8, st.none() | u32),
    st.builds(co.SdoSegmentedDownloadRequest, nodes, u16, u8, st.none() | u32),
    st.builds(co.SdoUploadSegmentRequest, nodes, st.booleans()),
    st.builds(co.SdoUploadSegment, nodes, st.booleans(), segment, st.booleans()),
    st.builds(co.SdoDownloadSegment, nodes, st.booleans(), segment, st.booleans()),
    st.builds(co.SdoDownloadSegmentResponse, nodes, st.booleans()),
    st.builds(
        co.SdoUnsupportedRequest,
        nodes,
        u16,
        u8,
        st.integers(0xA0, 0xFF),
        st.binary(min_size=4, max_size=4),
    ),
    st.builds(co.SdoAbort, nodes, u16, u8, st.integers(0, 0xFFFF_FFFF), st.booleans()),
    st.builds(co.Pdo, nodes, st.integers(1, 4), st.booleans(), st.binary(max_size=8)),
)


@pytest.mark.parametrize(
    ("msg", "cob_id", "hexdata"),
    [
        (co.NmtControl(co.NmtCommand.START), 0x000, "01 00"),
        (co.NmtControl(co.NmtCommand.RESET_NODE, 5), 0x000, "81 05"),
        (co.NmtControl(co.NmtCommand.ENTER_PRE_OPERATIONAL, 2), 0x000, "80 02"),
        (co.Sync(), 0x080, ""),
        (co.Heartbeat(5, co.NmtState.OPERATIONAL), 0x705, "05"),
        (co.Heartbeat(5, co.NmtState.BOOT_UP), 0x705, "00"),
        (co.Heartbeat(5, co.NmtState.PRE_OPERATIONAL), 0x705, "7f"),
        (co.Emergency(3, 0x2310, 0x03), 0x083, "10 23 03 00 00 00 00 00"),
        # Read statusword 0x6041:00 from node 1 and its 2-byte reply 0x0237.
        (co.SdoUploadRequest(1, 0x6041, 0), 0x601, "40 41 60 00 00 00 00 00"),
        (co.SdoUploadResponse(1, 0x6041, 0, b"\x37\x02"), 0x581, "4b 41 60 00 37 02 00 00"),
        # Writes of 2, 4 and 1 bytes, and the confirmation.
        (co.SdoDownloadRequest(1, 0x6040, 0, b"\x0f\x00"), 0x601, "2b 40 60 00 0f 00 00 00"),
        (
            co.SdoDownloadRequest(1, 0x6081, 0, (1000).to_bytes(4, "little")),
            0x601,
            "23 81 60 00 e8 03 00 00",
        ),
        (co.SdoDownloadRequest(1, 0x6060, 0, b"\x08"), 0x601, "2f 60 60 00 08 00 00 00"),
        (co.SdoUploadResponse(2, 0x1018, 1, b"\x01\x02\x03"), 0x582, "47 18 10 01 01 02 03 00"),
        (co.SdoDownloadResponse(1, 0x6040, 0), 0x581, "60 40 60 00 00 00 00 00"),
        (
            co.SdoAbort(1, 0x2000, 0, co.SdoAbortCode.OBJECT_DOES_NOT_EXIST),
            0x581,
            "80 00 20 00 00 00 02 06",
        ),
        (
            co.SdoAbort(1, 0x6041, 5, co.SdoAbortCode.SUBINDEX_DOES_NOT_EXIST, from_client=True),
            0x601,
            "80 41 60 05 11 00 09 06",
        ),
        # Segmented upload of a 64-bit object 0x2030:00 (8 bytes: 7 + 1).
        (co.SdoSegmentedUploadResponse(1, 0x2030, 0, 8), 0x581, "41 30 20 00 08 00 00 00"),
        (co.SdoSegmentedUploadResponse(1, 0x2030, 0, None), 0x581, "40 30 20 00 00 00 00 00"),
        (co.SdoUploadSegmentRequest(1, False), 0x601, "60 00 00 00 00 00 00 00"),
        (co.SdoUploadSegmentRequest(1, True), 0x601, "70 00 00 00 00 00 00 00"),
        (
            co.SdoUploadSegment(1, False, bytes(range(1, 8)), False),
            0x581,
            "00 01 02 03 04 05 06 07",
        ),
        (co.SdoUploadSegment(1, True, b"\x08", True), 0x581, "1d 08 00 00 00 00 00 00"),
        # Segmented download of 9 bytes.
        (co.SdoSegmentedDownloadRequest(1, 0x2031, 0, 9), 0x601, "21 31 20 00 09 00 00 00"),
        (co.SdoDownloadSegment(1, False, b"abcdefg", False), 0x601, "00 61 62 63 64 65 66 67"),
        (co.SdoDownloadSegment(1, True, b"hi", True), 0x601, "1b 68 69 00 00 00 00 00"),
        (co.SdoDownloadSegment(1, False, b"", True), 0x601, "0f 00 00 00 00 00 00 00"),
        (co.SdoDownloadSegmentResponse(1, False), 0x581, "20 00 00 00 00 00 00 00"),
        (co.SdoDownloadSegmentResponse(1, True), 0x581, "30 00 00 00 00 00 00 00"),
        # Expedited download without size (0x22): four bytes, the server's object decides.
        (
            co.SdoDownloadRequest(1, 0x6040, 0, b"\x0f\x00\x00\x00", size_indicated=False),
            0x601,
            "22 40 60 00 0f 00 00 00",
        ),
        # Block download / upload initiate: decoded so a server can abort them.
        (
            co.SdoUnsupportedRequest(1, 0x2031, 0, 0xC6, b"\x08\x00\x00\x00"),
            0x601,
            "c6 31 20 00 08 00 00 00",
        ),
        (
            co.SdoUnsupportedRequest(1, 0x2030, 0, 0xA4, b"\x7f\x00\x00\x00"),
            0x601,
            "a4 30 20 00 7f 00 00 00",
        ),
        (co.Heartbeat(5, 0x42), 0x705, "42"),  # unknown NMT state: kept as an int
        (co.NmtControl(0x03, 0), 0x000, "03 00"),  # unknown NMT command: kept as an int
        (co.Pdo(1, 1, True, b"\x37\x02"), 0x181, "37 02"),
        (co.Pdo(1, 4, False, b""), 0x501, ""),
    ],
)
def test_golden_frames(msg: co.CanOpenMessage, cob_id: int, hexdata: str) -> None:
    assert co.encode(msg) == (cob_id, bytes.fromhex(hexdata))
    assert co.decode(cob_id, bytes.fromhex(hexdata)) == msg


def test_abort_codes() -> None:
    assert co.SdoAbortCode.READ_ONLY.value == 0x0601_0002
    assert co.SdoAbortCode.GENERAL_ERROR.value == 0x0800_0000


def test_upload_response_without_size_gives_four_bytes() -> None:
    msg = co.decode(0x581, bytes.fromhex("42 64 60 00 01 02 03 04"))
    assert msg == co.SdoUploadResponse(1, 0x6064, 0, b"\x01\x02\x03\x04")


@pytest.mark.parametrize(
    ("cob_id", "hexdata"),
    [
        (0x581, "c4 00 10 00 10 00 00 00"),  # block upload response: not implemented
        (0x581, "a0 00 10 00 10 00 00 00"),  # block download response
        (0x581, "e0 00 10 00 10 00 00 00"),  # invalid server command specifier 7
        (0x581, "40 41 60 00 00 00 00"),  # SDO frames are 8 bytes
        (0x100, "00 00 00 00 00 00"),  # TIME
        (0x7E5, "00"),  # LSS
        (0x700, "05"),  # node id 0
        (0x000, "01 80"),  # node id 128
        (0x080, "00"),  # SYNC counter 0
        (0x083, "10 23 03"),  # short EMCY
        (0x181, "00" * 9),
        (0x800, ""),
    ],
)
def test_invalid_frames(cob_id: int, hexdata: str) -> None:
    with pytest.raises(CanOpenDecodeError):
        co.decode(cob_id, bytes.fromhex(hexdata))


def test_cob_id_helpers() -> None:
    assert [co.tpdo_cob_id(n, 1) for n in range(1, 5)] == [0x181, 0x281, 0x381, 0x481]
    assert [co.rpdo_cob_id(n, 1) for n in range(1, 5)] == [0x201, 0x301, 0x401, 0x501]
    with pytest.raises(ValueError):
        co.tpdo_cob_id(5, 1)
    with pytest.raises(ValueError):
        co.rpdo_cob_id(1, 0)


def test_pdo_mapping_entries() -> None:
    statusword = co.PdoMapEntry.from_u32(0x6041_0010)
    assert (statusword.index, statusword.subindex, statusword.bit_length) == (0x6041, 0, 16)
    assert co.PdoMapEntry(0x6064, 0, 32, signed=True).to_u32() == 0x6064_0020
    assert co.ObjectEntry(0x6060, 0, co.DataType.INTEGER8).map_entry().to_u32() == 0x6060_0008
    with pytest.raises(CanOpenDecodeError):
        co.PdoMapEntry.from_u32(0x6041_0000)  # zero length


def test_pack_pdo_controlword_and_target_position() -> None:
    mapping = [
        co.PdoMapEntry(0x6040, 0, 16),
        co.PdoMapEntry(0x607A, 0, 32, signed=True),
    ]
    data = co.pack_pdo(mapping, [0x000F, -1])
    assert data == bytes.fromhex("0f 00 ff ff ff ff")
    assert co.unpack_pdo(mapping, data) == [0x000F, -1]
    assert co.unpack_pdo(mapping, data + b"\x00\x00") == [0x000F, -1]  # extra bytes ignored
    with pytest.raises(CanOpenDecodeError):
        co.unpack_pdo(mapping, data[:-1])
    with pytest.raises(ValueError):
        co.pack_pdo(mapping, [0x1_0000, 0])


def test_pack_pdo_bits_lsb_first() -> None:
    mapping = [co.PdoMapEntry(0x2000, n, 1) for n in range(1, 4)] + [co.PdoMapEntry(0x2001, 0, 5)]
    assert co.pack_pdo(mapping, [1, 0, 1, 0b10101]) == bytes((0b10101_101,))
    with pytest.raises(ValueError):
        co.pack_pdo([co.PdoMapEntry(0x2000, 0, 64), co.PdoMapEntry(0x2001, 0, 1)], [0, 0])


@st.composite
def mapping_and_values(draw: st.DrawFn) -> tuple[list[co.PdoMapEntry], list[int]]:
    lengths = draw(st.lists(st.integers(1, 32), min_size=1, max_size=8))
    budget: list[int] = []
    for length in lengths:
        if sum(budget) + length <= 64:
            budget.append(length)
    mapping = [
        co.PdoMapEntry(draw(u16), draw(u8), length, draw(st.booleans())) for length in budget
    ]
    values = [
        draw(st.integers(-(1 << (e.bit_length - 1)), (1 << (e.bit_length - 1)) - 1))
        if e.signed
        else draw(st.integers(0, (1 << e.bit_length) - 1))
        for e in mapping
    ]
    return mapping, values


def test_unknown_nmt_values_are_plain_ints() -> None:
    heartbeat = co.decode(0x705, b"\x42")
    assert isinstance(heartbeat, co.Heartbeat)
    assert type(heartbeat.state) is int and heartbeat.state == 0x42
    assert co.decode(0x705, b"\x05") == co.Heartbeat(5, co.NmtState.OPERATIONAL)
    with pytest.raises(ValueError):
        co.Heartbeat(5, 0x80)  # 7 bits
    with pytest.raises(ValueError):
        co.NmtControl(0x100)


def test_segment_and_size_bounds() -> None:
    with pytest.raises(ValueError):
        co.SdoUploadSegment(1, False, bytes(8), True)
    with pytest.raises(ValueError):
        co.SdoSegmentedDownloadRequest(1, 0x2000, 0, 2**32)
    with pytest.raises(ValueError):
        co.SdoDownloadRequest(1, 0x2000, 0, b"\x01", size_indicated=False)
    with pytest.raises(ValueError):
        co.SdoUnsupportedRequest(1, 0x2000, 0, 0x40)  # an upload initiate is supported


@FUZZ
@given(mapping_and_values())
def test_pdo_pack_round_trip(case: tuple[list[co.PdoMapEntry], list[int]]) -> None:
    mapping, values = case
    data = co.pack_pdo(mapping, values)
    assert len(data) == (sum(e.bit_length for e in mapping) + 7) // 8
    assert co.unpack_pdo(mapping, data) == values
    for entry in mapping:
        assert co.PdoMapEntry.from_u32(entry.to_u32(), signed=entry.signed) == entry


@FUZZ
@given(st.sampled_from(co.DataType), st.data())
def test_object_entry_round_trip(data_type: co.DataType, data: st.DataObject) -> None:
    bits = data_type.size * 8
    low, high = (
        (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if data_type.signed else (0, (1 << bits) - 1)
    )
    value = data.draw(st.integers(low, high))
    entry = co.ObjectEntry(0x2000, 1, data_type)
    raw = entry.encode(value)
    assert len(raw) == data_type.size
    assert entry.decode(raw) == value
    with pytest.raises(ValueError):
        entry.encode(high + 1)


@FUZZ
@given(MESSAGES)
def test_round_trip(msg: co.CanOpenMessage) -> None:
    cob_id, data = co.encode(msg)
    assert 0 <= cob_id <= 0x7FF and len(data) <= 8
    assert co.decode(cob_id, data) == msg


@FUZZ
@given(st.integers(-1, 0x800), st.binary(max_size=9))
def test_random_frames_raise_only_decode_error(cob_id: int, data: bytes) -> None:
    try:
        msg = co.decode(cob_id, data)
    except CanOpenDecodeError:
        return
    assert co.encode(msg)[0] == cob_id


@FUZZ
@given(nodes, st.binary(min_size=8, max_size=8), st.booleans())
def test_random_sdo_payloads(node_id: int, data: bytes, to_server: bool) -> None:
    cob_id = (0x600 if to_server else 0x580) + node_id
    with contextlib.suppress(CanOpenDecodeError):
        co.decode(cob_id, data)


@FUZZ
@given(nodes, st.binary(min_size=8, max_size=8))
def test_every_client_sdo_frame_decodes(node_id: int, data: bytes) -> None:
    """A server must be able to answer anything a client sends: no client SDO frame of
    8 bytes is undecodable (block and invalid requests decode to SdoUnsupportedRequest)."""
    msg = co.decode(0x600 + node_id, data)
    assert isinstance(msg, (*co.SDO_CLIENT_MESSAGES, co.SdoAbort))


@FUZZ
@given(
    st.sampled_from(
        [
            co.NmtControl,
            co.Emergency,
            co.Heartbeat,
            co.SdoUploadResponse,
            co.SdoSegmentedUploadResponse,
            co.SdoUploadSegment,
            co.SdoAbort,
            co.Pdo,
            co.Sync,
        ]
    ),
    st.lists(st.integers(-(2**33), 2**33) | st.binary(max_size=10) | st.booleans(), max_size=6),
)
def test_constructors_raise_only_value_or_type_error(kind: type, args: list[object]) -> None:
    """Building a message from arbitrary values: a frame our decoder reads back to the
    same bytes, or ValueError (a value that does not fit) / TypeError (wrong arity or
    type)."""
    try:
        msg = kind(*args)
        cob_id, data = co.encode(msg)
    except (ValueError, TypeError):
        return
    assert co.encode(co.decode(cob_id, data)) == (cob_id, data)
