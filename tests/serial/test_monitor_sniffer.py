"""The serial bus monitor's decoders (:mod:`openel_serial.sniffer`): instruction packets built
by the vendors' SDKs (dynamixel-sdk, scservo_sdk) interleaved with the servos' statuses, as a
second adapter on the line hears them, decoded by instruction and control-table item;
garbage and damaged packets skipped and counted; the stream splitters round-trip any
sequence of packets however it is cut (hypothesis); a capture file read back."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import anyio
import dynamixel_sdk as dsdk
import scservo_sdk as ssdk
from hypothesis import given, settings
from hypothesis import strategies as st

from openel_serial import dynamixel as dx
from openel_serial import feetech as ft
from openel_serial.monitor import monitor_stream, read_capture
from openel_serial.sniffer import (
    DynamixelSniffer,
    DynamixelSplitter,
    FeetechSniffer,
    FeetechSplitter,
    Frame,
)

from .conftest import RecordingPort

X, S = dx.XSeries, ft.STS


def _texts(frames: list[Frame]) -> list[str]:
    return [f.text for f in frames]


def _feed_bytewise(sniffer: Any, stream: bytes) -> list[Frame]:
    out: list[Frame] = []
    for i in range(0, len(stream), 3):  # cut anywhere
        out += sniffer.feed(stream[i : i + 3], 0.0)
    return out


def test_dynamixel_sdk_packets_and_statuses() -> None:
    port: Any = RecordingPort()
    ph = dsdk.PacketHandler(2.0)
    ph.ping(port, 1)
    ph.write4ByteTxRx(port, 1, X.GOAL_POSITION.address, 2048)
    ph.read4ByteTxRx(port, 2, X.PRESENT_POSITION.address)
    writer = dsdk.GroupSyncWrite(port, ph, X.GOAL_POSITION.address, 4)
    writer.addParam(1, list((1000).to_bytes(4, "little")))
    writer.addParam(2, list((3000).to_bytes(4, "little")))
    writer.txPacket()
    reader = dsdk.GroupSyncRead(port, ph, X.PRESENT_CURRENT.address, 10)
    reader.addParam(1)
    reader.addParam(2)
    reader.txPacket()
    ping, write, read, sync_write, sync_read = port.written
    block = (
        (-5).to_bytes(2, "little", signed=True)
        + (7).to_bytes(4, "little")
        + (2047).to_bytes(4, "little")
    )
    stream = b"".join(
        [
            b"\x00\xff\x13",  # garbage first
            ping, dx.encode(dx.Status(1, 0, b"\x4c\x04\x2f")),
            write, dx.encode(dx.Status(1, 0)),
            read, dx.encode(dx.Status(2, dx.ALERT_BIT, (-12).to_bytes(4, "little", signed=True))),
            sync_write,
            sync_read, dx.encode(dx.Status(1, 0, block)), dx.encode(dx.Status(2, 0, block)),
            write[:-1] + bytes([write[-1] ^ 0xFF]),  # a damaged packet
            dx.encode(dx.Status(1, dx.ErrorNumber.DATA_LIMIT_ERROR)),
        ]
    )  # fmt: skip
    sniffer = DynamixelSniffer()
    frames = _feed_bytewise(sniffer, stream)
    assert _texts(frames) == [
        "Dynamixel 1 PING",
        "Dynamixel 1 STATUS model=1100 firmware=47",
        "Dynamixel 1 WRITE Goal Position=2048",
        "Dynamixel 1 STATUS",
        "Dynamixel 2 READ Present Position",
        "Dynamixel 2 STATUS Present Position=-12 ALERT (hardware error status)",
        "Dynamixel SYNC WRITE 1,2 Goal Position 1=1000 2=3000",
        "Dynamixel SYNC READ 1,2 126+10 (Present Current, Present Velocity, Present Position)",
        "Dynamixel 1 STATUS Present Current=-5 Present Velocity=7 Present Position=2047",
        "Dynamixel 2 STATUS Present Current=-5 Present Velocity=7 Present Position=2047",
        "Dynamixel 1: CRC error (instruction 0x03)",
        "Dynamixel 1 STATUS error=DATA_LIMIT_ERROR",
    ]
    assert [f.kind for f in frames][:3] == ["PING", "STATUS", "WRITE"]
    c = sniffer.counters
    assert c.checksum_errors == 1 and c.dropped_bytes >= 3 and sniffer.malformed == 0


def test_feetech_sdk_packets_and_statuses_direction_inferred() -> None:
    port: Any = RecordingPort()
    ph = ssdk.PacketHandler(0)
    ph.ping(port, 1)
    ph.read2ByteTxRx(port, 3, S.PRESENT_POSITION.address)
    ph.write2ByteTxRx(port, 5, S.GOAL_POSITION.address, 3000)
    writer = ssdk.GroupSyncWrite(port, ph, S.GOAL_POSITION.address, 2)
    for i in range(1, 7):
        writer.addParam(i, [0x00, 0x08])
    writer.txPacket()
    reader = ssdk.GroupSyncRead(port, ph, S.PRESENT_POSITION.address, 2)
    for i in (1, 2):
        reader.addParam(i)
    reader.txPacket()
    port.is_using = False  # the SDK waits for the replies before its next packet
    ph.action(port, ft.BROADCAST_ID)
    ping, read, write, sync_write, sync_read, action = port.written
    stream = b"".join(
        [
            ping, ft.encode(ft.Status(1, 0)),
            read, ft.encode(ft.Status(3, 0, (0x8000 | 10).to_bytes(2, "little"))),  # -10
            write, ft.encode(ft.Status(5, int(ft.StatusError.OVERHEAT))),
            b"\xff\xff\xff\x01",  # noise
            sync_write,
            sync_read, ft.encode(ft.Status(1, 0, b"\x00\x08")), ft.encode(ft.Status(2, 0, b"\x01\x08")),
            action,
        ]
    )  # fmt: skip
    sniffer = FeetechSniffer()
    frames = _feed_bytewise(sniffer, stream)
    assert _texts(frames) == [
        "Feetech 1 PING",
        "Feetech 1 STATUS",
        "Feetech 3 READ Present Position",
        "Feetech 3 STATUS Present Position=-10",
        "Feetech 5 WRITE Goal Position=3000",
        "Feetech 5 STATUS alarms=OVERHEAT",
        "Feetech SYNC WRITE 1..6 Goal Position 1=2048 2=2048 3=2048 4=2048 5=2048 6=2048",
        "Feetech SYNC READ 1,2 Present Position",
        "Feetech 1 STATUS Present Position=2048",
        "Feetech 2 STATUS Present Position=2049",
        "Feetech 254 ACTION",
    ]
    assert sniffer.counters.dropped_bytes == 4 and sniffer.counters.checksum_errors == 0


def _dynamixel_packets() -> st.SearchStrategy[bytes]:
    ids = st.integers(0, dx.MAX_ID)
    return st.one_of(
        st.builds(lambda i: dx.encode(dx.Ping(i)), ids),
        st.builds(lambda i, a, n: dx.encode(dx.Read(i, a, n)), ids, st.integers(0, 300), st.integers(1, 64)),
        st.builds(lambda i, a, d: dx.encode(dx.Write(i, a, d)), ids, st.integers(0, 300), st.binary(min_size=1, max_size=40)),
        st.builds(lambda i, e, p: dx.encode(dx.Status(i, e, p)), ids, st.integers(0, 0x87), st.binary(max_size=40)),
    )  # fmt: skip


def _feetech_packets() -> st.SearchStrategy[bytes]:
    ids = st.integers(0, ft.MAX_ID)
    return st.one_of(
        st.builds(lambda i: ft.encode(ft.Ping(i)), ids),
        st.builds(lambda i, a, n: ft.encode(ft.Read(i, a, n)), ids, st.integers(0, 85), st.integers(1, 40)),
        st.builds(lambda i, a, d: ft.encode(ft.Write(i, a, d)), ids, st.integers(0, 85), st.binary(min_size=1, max_size=40)),
        st.builds(lambda i, e, p: ft.encode(ft.Status(i, e, p)), ids, st.integers(0, 0x2F), st.binary(max_size=40)),
    )  # fmt: skip


_NO_FF = st.binary(max_size=6).map(lambda b: b.replace(b"\xff", b"\x00"))


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(_NO_FF, _dynamixel_packets()), max_size=8), st.integers(1, 17))
def test_dynamixel_splitter_round_trip(parts: list[tuple[bytes, bytes]], cut: int) -> None:
    stream = b"".join(g + p for g, p in parts)
    splitter = DynamixelSplitter()
    got: list[Any] = []
    for i in range(0, len(stream), cut):
        got += splitter.feed(stream[i : i + cut])
    assert got == [p for _, p in parts]
    assert splitter.counters.dropped_bytes == sum(len(g) for g, _ in parts)
    assert splitter.buffered == 0


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(_NO_FF, _feetech_packets()), max_size=8), st.integers(1, 17))
def test_feetech_splitter_round_trip(parts: list[tuple[bytes, bytes]], cut: int) -> None:
    stream = b"".join(g + p for g, p in parts)
    splitter = FeetechSplitter()
    got: list[Any] = []
    for i in range(0, len(stream), cut):
        got += splitter.feed(stream[i : i + cut])
    assert got == [p for _, p in parts]
    assert splitter.counters.dropped_bytes == sum(len(g) for g, _ in parts)


async def test_capture_file_reads_back(tmp_path: Path) -> None:
    log = tmp_path / "bus.hex"
    send, receive = anyio.create_memory_object_stream[tuple[float, bytes]](16)
    packets = [ft.encode(ft.Ping(1)), ft.encode(ft.Status(1, 0))]
    for p in packets:
        send.send_nowait((anyio.current_time(), p))
    send.close()
    seen: list[Frame] = []
    stats = await monitor_stream(
        receive, FeetechSniffer(), duration=5, on_frame=seen.append, log=str(log), description="t"
    )
    assert _texts(seen) == ["Feetech 1 PING", "Feetech 1 STATUS"] and stats.packets == 2
    assert log.read_text().startswith("# openel-async bus monitor capture: t\n")
    assert [data for _, data in read_capture(log)] == packets
    again = FeetechSniffer()
    assert _texts([f for _, d in read_capture(log) for f in again.feed(d, 0.0)]) == _texts(seen)
