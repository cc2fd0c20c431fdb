"""The Feetech SCS/STS codec: golden packets of the vendor's documentation, round trips,
sign-magnitude, checksum corruption, the stream parser."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from openel_serial import feetech as ft

S = ft.STS

# PING, READ and WRITE are the Feetech protocol manual's examples (SCS/STS communication
# protocol: ping servo 1, read its present position, write position 2048 at speed 1000); the
# others follow its definitions, and test_feetech_sdk checks that the vendor's SDK sends the
# same bytes.
GOLDEN = [
    # PING servo 1, and its status (no alarm).
    (ft.Ping(1), "ff ff 01 02 01 fb"),
    (ft.Status(1, 0, b""), "ff ff 01 02 00 fc"),
    # READ servo 1, Present Position (56 = 0x38), 2 bytes; a status with 0x0800 = 2048.
    (ft.Read(1, 0x38, 2), "ff ff 01 04 02 38 02 be"),
    (ft.Status(1, 0, b"\x00\x08"), "ff ff 01 04 00 00 08 f2"),
    # WRITE servo 1 at 42: Goal Position 2048, Goal Time 0, Goal Speed 1000 (little-endian).
    (ft.Write(1, 0x2A, bytes.fromhex("0008 0000 e803")), "ff ff 01 09 03 2a 00 08 00 00 e8 03 d5"),
    # REG WRITE + ACTION (broadcast).
    (ft.RegWrite(1, 0x2A, bytes.fromhex("0008")), "ff ff 01 05 04 2a 00 08 c3"),
    (ft.Action(), "ff ff fe 02 05 fa"),
    # SYNC WRITE Goal Position to servos 1 and 2; SYNC READ 56+2 of servos 1 and 2.
    (
        ft.SyncWrite(0x2A, 2, (ft.SyncWriteItem(1, b"\x00\x08"), ft.SyncWriteItem(2, b"\xff\x0f"))),
        "ff ff fe 0a 83 2a 02 01 00 08 02 ff 0f 2f",
    ),
    (ft.SyncRead(0x38, 2, (1, 2)), "ff ff fe 06 82 38 02 01 02 3c"),
    # Broadcast torque off (the e-stop packet).
    (ft.Write(ft.BROADCAST_ID, 40, b"\x00"), "ff ff fe 04 03 28 00 d2"),
]


@pytest.mark.parametrize(("msg", "wire"), GOLDEN)
def test_golden_packets(msg: ft.FeetechMessage, wire: str) -> None:
    packet = bytes.fromhex(wire)
    assert ft.encode(msg) == packet
    assert ft.decode(packet, status=isinstance(msg, ft.Status)) == msg


def test_checksum_is_the_inverted_byte_sum() -> None:
    assert ft.checksum(bytes.fromhex("01 02 01")) == 0xFB
    assert ft.checksum(b"") == 0xFF


ids = st.integers(0, ft.MAX_ID)
addresses = st.integers(0, 255)
payload = st.binary(min_size=1, max_size=60)
instructions = st.one_of(
    st.builds(ft.Ping, ids),
    st.builds(ft.Read, ids, addresses, st.integers(0, 255)),
    st.builds(ft.Write, ids, addresses, payload),
    st.builds(ft.RegWrite, ids, addresses, payload),
    st.builds(ft.Action, ids),
    st.builds(ft.Reset, ids),
    st.builds(
        ft.SyncRead,
        addresses,
        st.integers(1, 255),
        st.lists(ids, min_size=1, max_size=20, unique=True).map(tuple),
    ),
    st.integers(1, 8).flatmap(
        lambda n: st.builds(
            ft.SyncWrite,
            addresses,
            st.just(n),
            st.lists(
                st.builds(ft.SyncWriteItem, ids, st.binary(min_size=n, max_size=n)),
                min_size=1,
                max_size=10,
            ).map(tuple),
        )
    ),
)
statuses = st.builds(ft.Status, ids, st.integers(0, 255), st.binary(max_size=80))


@settings(max_examples=100, deadline=None)
@given(instructions)
def test_instruction_round_trip(msg: ft.FeetechMessage) -> None:
    packet = ft.encode(msg)
    assert ft.decode(packet, status=False) == msg
    assert ft.PacketParser(status=False).feed(packet) == [msg]


@settings(max_examples=100, deadline=None)
@given(statuses)
def test_status_round_trip(msg: ft.Status) -> None:
    assert ft.decode(ft.encode(msg), status=True) == msg


@settings(max_examples=100, deadline=None)
@given(st.one_of(instructions, statuses), st.data())
def test_a_corrupted_byte_is_detected(msg: ft.FeetechMessage, data: st.DataObject) -> None:
    packet = bytearray(ft.encode(msg))
    # Any byte the checksum covers (id .. params) or the checksum itself, changed.
    index = data.draw(st.integers(2, len(packet) - 1))
    if index == 3:
        return  # the length byte: a framing error, tested below
    packet[index] ^= data.draw(st.integers(1, 255))
    with pytest.raises(ft.FeetechDecodeError):
        ft.decode(bytes(packet), status=isinstance(msg, ft.Status))
    parser = ft.PacketParser(status=isinstance(msg, ft.Status))
    assert parser.feed(bytes(packet)) == [] or parser.checksum_errors == 0
    assert msg not in parser.feed(b"")


def test_a_wrong_length_byte_is_a_decode_error() -> None:
    packet = bytearray(ft.encode(ft.Read(1, 56, 2)))
    packet[3] += 1
    with pytest.raises(ft.FeetechDecodeError):
        ft.decode(bytes(packet), status=False)


@settings(max_examples=100, deadline=None)
@given(st.integers(0, 15), st.data())
def test_sign_magnitude_round_trip(bit: int, data: st.DataObject) -> None:
    value = data.draw(st.integers(-(2**bit) + 1, 2**bit - 1))
    raw = ft.to_sign_magnitude(value, bit)
    assert 0 <= raw < 2 ** (bit + 1)
    assert ft.from_sign_magnitude(raw, bit) == value
    assert (raw >> bit) & 1 == (value < 0)


def test_sign_magnitude_of_the_sts_registers() -> None:
    # bit 15: -100 steps/s is 0x8064; bit 11 (homing offset): -5 is 0x0805; bit 10 (load).
    assert S.GOAL_SPEED.encode(-100) == b"\x64\x80"
    assert S.PRESENT_SPEED.decode(b"\x64\x80") == -100
    assert S.HOMING_OFFSET.encode(-5) == b"\x05\x08"
    assert S.HOMING_OFFSET.decode(b"\x05\x08") == -5
    assert S.PRESENT_LOAD.decode((1024 + 300).to_bytes(2, "little")) == -300
    with pytest.raises(ValueError):
        S.HOMING_OFFSET.encode(2048)  # the magnitude has 11 bits
    # SCS: big-endian, speed signed in bit 10.
    assert ft.SCS.GOAL_POSITION.encode(0x0123) == b"\x01\x23"
    assert ft.SCS.GOAL_SPEED.encode(-1) == b"\x04\x01"


@settings(max_examples=100, deadline=None)
@given(
    st.lists(st.one_of(instructions, st.binary(max_size=8)), max_size=12),
    st.lists(st.integers(1, 40), max_size=6),
)
def test_parser_finds_every_packet_among_garbage_in_any_chunks(
    items: list[ft.FeetechMessage | bytes], cuts: list[int]
) -> None:
    """Garbage between packets never hides a packet that follows it, however the stream is cut,
    as long as the garbage has no FF FF of its own (which could open a false frame)."""
    stream = bytearray()
    sent = []
    for item in items:
        if isinstance(item, bytes):
            stream += item.replace(b"\xff", b"\x00")
        else:
            stream += ft.encode(item)
            sent.append(item)
    parser = ft.PacketParser(status=False)
    got: list[ft.FeetechMessage] = []
    position = 0
    for cut in cuts:
        got += parser.feed(bytes(stream[position : position + cut]))
        position += cut
    got += parser.feed(bytes(stream[position:]))
    assert got == sent


def test_parser_resynchronises_after_a_damaged_packet() -> None:
    good = ft.encode(ft.Status(2, 0, b"\x00\x08"))
    damaged = bytearray(ft.encode(ft.Status(1, 0, b"\x01\x02")))
    damaged[-1] ^= 0x10
    parser = ft.PacketParser(status=True)
    out = parser.feed_all(b"\xff" + bytes(damaged) + good)
    assert out == [ft.CorruptPacket(1, 0, 4), ft.Status(2, 0, b"\x00\x08")]
    assert parser.checksum_errors == 1


def test_status_error_bits_describe() -> None:
    error = ft.StatusError(0x24)
    assert error.describe() == "OVERHEAT|OVERLOAD"
    assert ft.StatusError(0).describe() == "none"
    assert ft.StatusError(0x41).describe() == "VOLTAGE|0x40"


@settings(max_examples=100, deadline=None)
@given(
    addresses,
    st.integers(1, 8).flatmap(
        lambda n: st.tuples(
            st.just(n),
            st.dictionaries(ids, st.binary(min_size=n, max_size=n), min_size=1, max_size=10),
        )
    ),
)
def test_the_direct_sync_write_encoder_is_encode_of_a_sync_write(
    address: int, case: tuple[int, dict[int, bytes]]
) -> None:
    length, data = case
    items = tuple(ft.SyncWriteItem(i, d) for i, d in data.items())
    assert ft.encode_sync_write(address, length, data) == ft.encode(
        ft.SyncWrite(address, length, items)
    )


@pytest.mark.parametrize(
    ("address", "length", "data"),
    [(256, 1, {1: b"x"}), (0, 256, {1: b"x"}), (0, 2, {1: b"x"}), (0, 1, {254: b"x"})],
)
def test_the_direct_sync_write_encoder_refuses_what_a_sync_write_refuses(
    address: int, length: int, data: dict[int, bytes]
) -> None:
    with pytest.raises(ValueError):
        ft.encode_sync_write(address, length, data)
    with pytest.raises(ValueError):
        ft.SyncWrite(address, length, tuple(ft.SyncWriteItem(i, d) for i, d in data.items()))


def test_a_parsed_status_is_a_status_like_a_built_one() -> None:
    built = ft.Status(7, 0x24, b"\x01\x02")
    (parsed,) = ft.PacketParser(status=True).feed(ft.encode(built))
    assert type(parsed) is ft.Status and parsed == built and hash(parsed) == hash(built)
    assert repr(parsed) == repr(built)
    with pytest.raises(AttributeError):
        parsed.id = 3  # type: ignore[misc]
