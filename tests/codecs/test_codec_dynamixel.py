"""Dynamixel Protocol 2.0 codec: e-manual packets, stuffing, round trips, stream parsing."""

from __future__ import annotations

import math
import random
import time

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from openel_serial import dynamixel as dx
from openel_serial.errors import DynamixelCrcError, DynamixelDecodeError

X = dx.XSeries


def test_golden_sync_write_goal_position() -> None:
    msg = dx.SyncWrite(
        X.GOAL_POSITION.address,
        X.GOAL_POSITION.size,
        (
            dx.SyncWriteItem(1, X.GOAL_POSITION.encode(2048)),
            dx.SyncWriteItem(2, X.GOAL_POSITION.encode(1024)),
        ),
    )
    packet = bytes.fromhex(
        "ff ff fd 00 fe 11 00 83 74 00 04 00 01 00 08 00 00 02 00 04 00 00 98 4c"
    )
    assert dx.encode(msg) == packet
    assert dx.decode(packet) == msg


# Packets from the ROBOTIS Protocol 2.0 e-manual examples.
EMANUAL = [
    (dx.Ping(1), "FF FF FD 00 01 03 00 01 19 4E"),
    (dx.Ping(dx.BROADCAST_ID), "FF FF FD 00 FE 03 00 01 31 42"),
    (dx.Status(1, 0, bytes.fromhex("06 04 26")), "FF FF FD 00 01 07 00 55 00 06 04 26 65 5D"),
    (dx.Read(1, 132, 4), "FF FF FD 00 01 07 00 02 84 00 04 00 1D 15"),
    (dx.Status(1, 0, bytes.fromhex("A6 00 00 00")), "FF FF FD 00 01 08 00 55 00 A6 00 00 00 8C C0"),
    (
        dx.Write(1, 116, bytes.fromhex("00 02 00 00")),
        "FF FF FD 00 01 09 00 03 74 00 00 02 00 00 CA 89",
    ),
    (dx.Status(1, 0, b""), "FF FF FD 00 01 04 00 55 00 A1 0C"),
    (dx.Action(1), "FF FF FD 00 01 03 00 05 02 CE"),
    (dx.FactoryReset(1, dx.FactoryResetMode.EXCEPT_ID), "FF FF FD 00 01 04 00 06 01 A1 E6"),
    (dx.Reboot(1), "FF FF FD 00 01 03 00 08 2F 4E"),
    (dx.Clear(1, 0x01), "FF FF FD 00 01 08 00 10 01 44 58 4C 22 B1 DC"),
    (dx.SyncRead(132, 4, (1, 2)), "FF FF FD 00 FE 09 00 82 84 00 04 00 01 02 CE FA"),
    (
        dx.SyncWrite(
            116,
            4,
            (
                dx.SyncWriteItem(1, (150).to_bytes(4, "little")),
                dx.SyncWriteItem(2, (170).to_bytes(4, "little")),
            ),
        ),
        "FF FF FD 00 FE 11 00 83 74 00 04 00 01 96 00 00 00 02 AA 00 00 00 82 87",
    ),
]


@pytest.mark.parametrize(("msg", "hexpacket"), EMANUAL)
def test_emanual_packets(msg: dx.DynamixelMessage, hexpacket: str) -> None:
    packet = bytes.fromhex(hexpacket)
    assert dx.encode(msg) == packet
    assert dx.decode(packet) == msg


def test_ping_reply_and_status_error() -> None:
    status = dx.decode(bytes.fromhex("FF FF FD 00 01 07 00 55 00 06 04 26 65 5D"))
    assert isinstance(status, dx.Status)
    assert status.ping_info() == (1030, 38)
    alarm = dx.Status(1, 0x80 | dx.ErrorNumber.DATA_RANGE_ERROR)
    assert alarm.alert and alarm.error_number == dx.ErrorNumber.DATA_RANGE_ERROR


def test_crc16_check_value() -> None:
    # CRC-16/UMTS (poly 0x8005, init 0, no reflection) check value.
    assert dx.crc16(b"123456789") == 0xFEE8


def test_stuffing_examples() -> None:
    assert dx.stuff(b"\xff\xff\xfd") == b"\xff\xff\xfd\xfd"
    assert dx.stuff(b"\xff\xff\xff\xfd\x00") == b"\xff\xff\xff\xfd\xfd\x00"
    assert dx.stuff(b"\xff\xff\xfd\xfd") == b"\xff\xff\xfd\xfd\xfd"
    assert dx.unstuff(b"\xff\xff\xfd\xfd\xfd") == b"\xff\xff\xfd\xfd"
    for bad in (b"\xff\xff\xfd", b"\xff\xff\xfd\x00"):
        with pytest.raises(DynamixelDecodeError):
            dx.unstuff(bad)


def test_stuffed_packet_length_counts_stuffed_bytes() -> None:
    msg = dx.Write(1, 0x0200, b"\xff\xff\xfd")
    packet = dx.encode(msg)
    # instruction + address(2) + 3 data + 1 stuffing byte + CRC(2)
    assert packet[5:7] == (1 + 2 + 4 + 2).to_bytes(2, "little")
    assert packet[7:-2] == b"\x03\x00\x02\xff\xff\xfd\xfd"
    assert dx.decode(packet) == msg


runs = st.lists(
    st.sampled_from([b"\xff", b"\xfd", b"\x00", b"\xff\xff\xfd", b"\xff\xff\xfd\xfd"]), max_size=40
).map(b"".join)


@given(runs | st.binary(max_size=64))
def test_stuffing_round_trip(data: bytes) -> None:
    stuffed = dx.stuff(data)
    assert dx.unstuff(stuffed) == data
    assert len(stuffed) == len(data) + data.count(b"\xff\xff\xfd")
    # The header can never appear inside a stuffed body.
    assert dx.HEADER not in stuffed


ids = st.integers(0, dx.MAX_ID)
any_id = ids | st.just(dx.BROADCAST_ID)
u16 = st.integers(0, 0xFFFF)
payload = runs | st.binary(max_size=16)


@st.composite
def sync_writes(draw: st.DrawFn) -> dx.SyncWrite:
    length = draw(st.integers(0, 6))
    items = draw(
        st.lists(
            st.builds(dx.SyncWriteItem, ids, st.binary(min_size=length, max_size=length)),
            max_size=5,
        )
    )
    return dx.SyncWrite(draw(u16), length, tuple(items))


MESSAGES: st.SearchStrategy[dx.DynamixelMessage] = st.one_of(
    st.builds(dx.Ping, any_id),
    st.builds(dx.Read, any_id, u16, u16),
    st.builds(dx.Write, any_id, u16, payload),
    st.builds(dx.RegWrite, any_id, u16, payload),
    st.builds(dx.Action, any_id),
    st.builds(dx.FactoryReset, any_id, st.sampled_from(dx.FactoryResetMode)),
    st.builds(dx.Reboot, any_id),
    st.builds(dx.Clear, any_id, st.integers(0, 0xFF)),
    st.builds(dx.SyncRead, u16, u16, st.lists(ids, max_size=8).map(tuple)),
    st.builds(dx.FastSyncRead, u16, u16, st.lists(ids, max_size=8).map(tuple)),
    sync_writes(),
    st.builds(dx.BulkRead, st.lists(st.builds(dx.BulkReadItem, ids, u16, u16)).map(tuple)),
    st.builds(
        dx.BulkWrite,
        st.lists(st.builds(dx.BulkWriteItem, ids, u16, payload), max_size=4).map(tuple),
    ),
    st.builds(dx.Status, any_id, st.integers(0, 0xFF), payload),
)


@given(MESSAGES)
def test_round_trip(msg: dx.DynamixelMessage) -> None:
    packet = dx.encode(msg)
    assert packet.startswith(dx.HEADER)
    assert dx.HEADER not in packet[4:-2]
    assert dx.decode(packet) == msg


@given(st.binary(max_size=40))
def test_random_bytes_raise_only_decode_error(data: bytes) -> None:
    with pytest.raises(DynamixelDecodeError):
        dx.decode(data)


def _frame(dxl_id: int, body: bytes) -> bytes:
    head = dx.HEADER + bytes((dxl_id,)) + (len(body) + 2).to_bytes(2, "little") + body
    return head + dx.crc16(head).to_bytes(2, "little")


@given(
    st.integers(0, 0xFF),
    st.sampled_from(list(dx.Instruction)) | st.integers(0, 0xFF),
    st.binary(max_size=24),
)
def test_random_bodies_with_valid_crc(dxl_id: int, instruction: int, params: bytes) -> None:
    try:
        msg = dx.decode(_frame(dxl_id, bytes((instruction,)) + params))
    except DynamixelDecodeError as exc:
        assert not isinstance(exc, DynamixelCrcError)
        return
    assert dx.decode(dx.encode(msg)) == msg


def test_crc_error_detected() -> None:
    packet = bytearray(dx.encode(dx.Read(1, 132, 4)))
    packet[8] ^= 0x01
    with pytest.raises(DynamixelCrcError):
        dx.decode(bytes(packet))


# --- streaming parser ----------------------------------------------------------------------

no_fd = st.binary(max_size=12).map(lambda b: b.replace(b"\xfd", b"\x00"))


@given(st.lists(st.tuples(no_fd, MESSAGES), max_size=6), no_fd, st.data())
def test_parser_recovers_packets_from_noisy_stream(
    parts: list[tuple[bytes, dx.DynamixelMessage]], tail: bytes, data: st.DataObject
) -> None:
    stream = b"".join(noise + dx.encode(msg) for noise, msg in parts) + tail
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=6)))
    parser = dx.PacketParser(max_length=4096)
    got: list[dx.DynamixelMessage] = []
    for start, end in zip([0, *cuts], [*cuts, len(stream)], strict=True):
        got += parser.feed(stream[start:end])
    assert got == [msg for _, msg in parts]
    assert parser.packets == len(parts)
    assert parser.crc_errors == parser.malformed == 0


@given(st.lists(st.binary(max_size=64), max_size=20))
def test_parser_never_raises_and_stays_bounded(chunks: list[bytes]) -> None:
    parser = dx.PacketParser(max_length=64)
    for chunk in chunks:
        parser.feed(dx.HEADER[:2] + chunk)
        parser.feed(dx.HEADER + chunk)
        assert parser.buffered <= 7 + 64


def test_parser_counts_and_resyncs_after_corruption() -> None:
    good = dx.encode(dx.Read(1, 132, 4))
    corrupt = bytearray(dx.encode(dx.Ping(2)))
    corrupt[-1] ^= 0xFF
    bad_length = dx.HEADER + b"\x01\xff\xff"  # length 65535 > max_length
    parser = dx.PacketParser()
    got = parser.feed(b"\x00\x01" + bytes(corrupt) + bad_length + good)
    assert got == [dx.Read(1, 132, 4)]
    assert parser.crc_errors == 1
    assert parser.length_errors == 1
    valid_crc_bad_body = _frame(1, b"\x02\x84\x00")  # READ with 2 params
    assert parser.feed(valid_crc_bad_body + good) == [dx.Read(1, 132, 4)]
    assert parser.malformed == 1


# --- control table and units ---------------------------------------------------------------


def test_control_table_addresses() -> None:
    assert (X.TORQUE_ENABLE.address, X.LED.address, X.STATUS_RETURN_LEVEL.address) == (64, 65, 68)
    assert X.HARDWARE_ERROR_STATUS.address == 70
    assert (X.GOAL_PWM.address, X.GOAL_CURRENT.address, X.GOAL_VELOCITY.address) == (100, 102, 104)
    assert (X.PROFILE_ACCELERATION.address, X.PROFILE_VELOCITY.address) == (108, 112)
    assert (X.GOAL_POSITION.address, X.GOAL_POSITION.size) == (116, 4)
    assert (X.MOVING.address, X.MOVING_STATUS.address, X.PRESENT_PWM.address) == (122, 123, 124)
    assert (X.PRESENT_CURRENT.address, X.PRESENT_VELOCITY.address) == (126, 128)
    assert (X.PRESENT_POSITION.address, X.PRESENT_INPUT_VOLTAGE.address) == (132, 144)
    assert (X.PRESENT_TEMPERATURE.address, X.OPERATING_MODE.address) == (146, 11)
    assert (dx.OperatingMode.EXTENDED_POSITION.value, dx.OperatingMode.PWM.value) == (4, 16)
    assert X.PRESENT_POSITION.read(1) == dx.Read(1, 132, 4)
    assert X.GOAL_VELOCITY.write(1, -1) == dx.Write(1, 104, b"\xff\xff\xff\xff")
    assert X.PRESENT_CURRENT.decode(b"\xff\xff") == -1
    with pytest.raises(ValueError):
        X.TORQUE_ENABLE.encode(256)


def test_unit_conversions() -> None:
    assert dx.ticks_to_rad(2048) == 0.0
    assert dx.ticks_to_rad(3072) == pytest.approx(math.pi / 2)
    assert dx.rad_to_ticks(-math.pi) == 0
    assert dx.velocity_to_rad_s(1) == pytest.approx(0.229 * 2 * math.pi / 60)
    assert dx.current_to_amps(1000) == pytest.approx(2.69)
    assert dx.amps_to_current(-2.69) == -1000


@given(st.integers(-(1 << 20), 1 << 20))
def test_unit_round_trips(units: int) -> None:
    assert dx.rad_to_ticks(dx.ticks_to_rad(units)) == units
    assert dx.rad_s_to_velocity(dx.velocity_to_rad_s(units)) == units
    assert dx.amps_to_current(dx.current_to_amps(units)) == units
    assert dx.rad_s2_to_acceleration(dx.acceleration_to_rad_s2(units)) == units


def test_acceleration_unit_and_status_flags() -> None:
    assert dx.acceleration_to_rad_s2(1) == pytest.approx(214.577 * 2 * math.pi / 3600)
    assert (X.MOVING_THRESHOLD.address, X.MOVING_THRESHOLD.size) == (24, 4)
    error = dx.HardwareError.OVERHEATING | dx.HardwareError.OVERLOAD
    assert error.describe() == "OVERHEATING|OVERLOAD"
    assert dx.HardwareError(0x42).describe() == "0x42"
    assert dx.HardwareError(0).describe() == "none"
    status = dx.MovingStatus(0x33)
    assert dx.MovingStatus.IN_POSITION in status and dx.MovingStatus.PROFILE_ONGOING in status
    assert status & dx.MovingStatus.PROFILE_TYPE_MASK == 0x30


@given(st.floats(-100.0, 100.0))
def test_position_quantisation(rad: float) -> None:
    assert abs(dx.ticks_to_rad(dx.rad_to_ticks(rad)) - rad) <= math.pi / 4096 + 1e-12


# --- parser robustness: resynchronisation cost, chunking, accounting -------------------------

LINE_RATE = 100_000  # bytes/s of a 1 Mbaud line (8N1)
MIN_RATE = 2 * LINE_RATE


def _filler(size: int, seed: int) -> bytes:
    """Deterministic noise without a header in it."""
    data = random.Random(seed).randbytes(size)
    return data.replace(b"\xff\xff\xfd", b"\xff\x00\xfd")


def _fake(dxl_id: int, length: int, rest: bytes = b"") -> bytes:
    return dx.HEADER + bytes((dxl_id,)) + length.to_bytes(2, "little") + rest


def _adversarial_streams() -> dict[str, bytes]:
    size = 200_000
    max_len = 1024
    rng = random.Random(7)
    sprinkled = bytearray()
    while len(sprinkled) < size:
        sprinkled += _fake(rng.randrange(256), rng.randrange(3, max_len + 1))
        sprinkled += rng.randbytes(rng.randrange(0, 64))
    # Each candidate needs a CRC: the next header starts in its last 4 bytes (allowed).
    chained = _fake(1, max_len, b"\x55\x00" + _filler(max_len - 6, 3))
    return {
        # The case: a status header claiming 1 kB, again and again.
        "dense_status_headers": _fake(1, max_len, b"\x55\x00") * (size // 11),
        "headers_every_7_bytes": _fake(1, max_len) * (size // 7),
        "full_length_bad_crc": _fake(1, max_len - 7, b"\x55\x00" + _filler(max_len, 1))
        * (size // (max_len + 7)),
        "chained_at_last_4_bytes": chained * (size // len(chained)),
        "sprinkled_random": bytes(sprinkled),
        "random_bytes": random.Random(11).randbytes(size),
    }


@pytest.mark.parametrize("name", list(_adversarial_streams()))
def test_parser_keeps_up_with_a_1_mbaud_line_on_adversarial_noise(name: str) -> None:
    noise = _adversarial_streams()[name]
    good = dx.encode(dx.Status(1, 0, bytes(range(14))))
    stream = noise + good
    for chunk in (len(stream), 64):  # one read, then reads as a USB adapter delivers them
        parser = dx.PacketParser(max_length=1024)
        got: list[dx.DynamixelMessage] = []
        start = time.perf_counter()
        for i in range(0, len(stream), chunk):
            got += parser.feed(stream[i : i + chunk])
        rate = len(stream) / (time.perf_counter() - start)
        assert rate >= MIN_RATE, f"{name}: {rate / 1e3:.0f} kB/s in {chunk}-byte reads"
        assert got[-1] == dx.Status(1, 0, bytes(range(14)))  # the reply after the noise
        assert parser.buffered == 0


def test_false_header_does_not_hold_back_the_reply_behind_it() -> None:
    # A header claiming 1 kB, then the genuine reply: delivered at once, not after 1 kB more.
    parser = dx.PacketParser()
    reply = dx.Status(1, 0, b"\x01\x02")
    assert parser.feed(_fake(1, 1000, b"\x55\x00\x12") + dx.encode(reply)) == [reply]
    assert parser.interrupted == 1 and parser.crc_errors == 0
    assert parser.buffered == 0


def test_packet_ending_in_a_header_pattern_is_kept() -> None:
    # Body ending FF FF and CRC FD 00 form a header in the packet's last 4 bytes.
    for address in range(0x10000):
        packet = dx.encode(dx.Write(1, address, b"\xff\xff"))
        if packet.endswith(b"\xfd\x00"):
            break
    else:
        pytest.fail("no WRITE with CRC 0x00FD found")
    parser = dx.PacketParser()
    follower = dx.encode(dx.Ping(2))
    assert parser.feed(packet + follower) == [dx.decode(packet), dx.Ping(2)]
    assert parser.interrupted == parser.crc_errors == 0


def test_feed_all_reports_crc_failures_with_their_id() -> None:
    corrupt = bytearray(dx.encode(dx.Write(3, 116, b"\x00\x08\x00\x00")))
    corrupt[10] ^= 0x40
    parser = dx.PacketParser()
    got = parser.feed_all(bytes(corrupt) + dx.encode(dx.Ping(3)))
    assert got == [dx.CorruptPacket(3, dx.Instruction.WRITE, 9), dx.Ping(3)]
    assert parser.crc_errors == 1
    corrupt2 = bytearray(dx.encode(dx.Ping(4)))
    corrupt2[-2] ^= 1
    assert parser.feed(bytes(corrupt2)) == []  # feed() leaves them out
    assert parser.crc_errors == 2


def _damaged(packet: bytes, rng_seed: int) -> bytes:
    rng = random.Random(rng_seed)
    data = bytearray(packet)
    data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
    return bytes(data)


segments = st.one_of(
    MESSAGES.map(dx.encode),  # valid packets
    st.tuples(MESSAGES.map(dx.encode), st.integers(0, 2**32)).map(lambda t: _damaged(*t)),
    st.tuples(MESSAGES.map(dx.encode), st.integers(1, 12)).map(lambda t: t[0][: -t[1]]),
    st.builds(_fake, st.integers(0, 255), st.integers(0, 0xFFFF), st.binary(max_size=4)),
    st.binary(max_size=24),
    st.sampled_from([dx.HEADER, dx.HEADER[:3], b"\xff\xff\xfd\xfd", b"\xff"]),
)


def _parse_in_pieces(
    stream: bytes, cuts: list[int], max_length: int
) -> tuple[list[dx.DynamixelMessage | dx.CorruptPacket], tuple[int, ...]]:
    parser = dx.PacketParser(max_length=max_length)
    got: list[dx.DynamixelMessage | dx.CorruptPacket] = []
    for start, end in zip([0, *cuts], [*cuts, len(stream)], strict=True):
        got += parser.feed_all(stream[start:end])
    counters = (
        parser.packets,
        parser.crc_errors,
        parser.length_errors,
        parser.interrupted,
        parser.malformed,
        parser.dropped_bytes,
        parser.buffered,
    )
    return got, counters


@settings(max_examples=100, deadline=None)
@given(st.lists(segments, max_size=12).map(b"".join), st.data(), st.sampled_from([16, 64, 1024]))
def test_fuzz_parser_split_anywhere_parses_as_whole(
    stream: bytes, data: st.DataObject, max_length: int
) -> None:
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=8)))
    whole, whole_counters = _parse_in_pieces(stream, [], max_length)
    split, split_counters = _parse_in_pieces(stream, cuts, max_length)
    bytewise, bytewise_counters = _parse_in_pieces(stream, list(range(1, len(stream))), max_length)
    assert split == whole == bytewise
    assert split_counters == whole_counters == bytewise_counters
    # Nothing lost untold: every byte is in a packet, counted as dropped, or buffered.
    packets = [m for m in whole if not isinstance(m, dx.CorruptPacket)]
    delivered = sum(len(dx.encode(m)) for m in packets)
    assert delivered + whole_counters[5] + whole_counters[6] == len(stream)
    assert whole_counters[6] <= 7 + max_length


@settings(max_examples=100, deadline=None)
@given(st.binary(max_size=64) | st.lists(segments, max_size=3).map(b"".join))
def test_fuzz_decode_raises_only_decode_errors(data: bytes) -> None:
    try:
        msg = dx.decode(data)
    except DynamixelDecodeError:
        return
    assert dx.encode(msg) == data  # what decodes is exactly what encodes
