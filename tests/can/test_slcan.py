"""The simulated slcan adapter (openel_can.sim.slcan) against python-can's own ``slcan``
interface and the ODrive / CiA 402 drivers, in-thread and as a separate process.

Real time is unavoidable (a pty, python-can's serial reader): every wait is bounded.
"""

from __future__ import annotations

import math
import os
import re
import select
import signal
import subprocess
import sys
import termios
import time
import tty
from collections.abc import AsyncIterator, Iterator
from contextlib import asynccontextmanager, contextmanager

import anyio
import can
import pytest
from hypothesis import given
from hypothesis import strategies as st

from openel_async import Actuator, EventId, Request
from openel_async.clock import VirtualClock, default_clock
from openel_async.errors import BadParameterError
from openel_async.testing import EventRecorder
from openel_can import CanBus, ODriveAxis
from openel_can import cansimple as cs
from openel_can.drive402 import Cia402Drive
from openel_can.sim.cia402 import SimCia402Drive
from openel_can.sim.odrive import SimODrive
from openel_can.sim.slcan import (
    SlcanAdapter,
    SlcanAdapterProcess,
    SlcanError,
    StatusFlag,
    btr_bitrate,
    decode_frame,
    encode_frame,
)

ODRIVE = 3
CIA402 = 5
HB = 0.02
COMPLETED = EventId.COMPLETED


# -- helpers ------------------------------------------------------------------------------------
@contextmanager
def raw_port(path: str) -> Iterator[int]:
    """The adapter's pty opened raw, as a serial port would be (no python-can in between)."""
    fd = os.open(path, os.O_RDWR | os.O_NOCTTY)
    try:
        tty.setraw(fd)
        termios.tcflush(fd, termios.TCIFLUSH)
        yield fd
    finally:
        os.close(fd)


def read_reply(fd: int, count: int = 1, timeout: float = 5.0) -> bytes:
    """Bytes up to the ``count``-th CR or BEL (bounded wait: generous, the adapter is a
    process of its own that a loaded machine may schedule late)."""
    out = b""
    deadline = time.monotonic() + timeout
    while sum(out.count(end) for end in (b"\r", b"\a")) < count:
        left = deadline - time.monotonic()
        if left <= 0 or not select.select([fd], [], [], left)[0]:
            raise TimeoutError(f"no reply from the adapter (got {out!r})")
        out += os.read(fd, 256)
    return out


def talk(fd: int, command: bytes, count: int = 1) -> bytes:
    os.write(fd, command + b"\r")
    return read_reply(fd, count)


def slcan_bus(port: str) -> can.BusABC:
    # sleep_after_open: python-can waits 2 s for a USB adapter to boot; a pty needs none.
    return can.Bus(interface="slcan", channel=port, bitrate=1_000_000, sleep_after_open=0)


def host_bus(port: str) -> CanBus:
    return CanBus(
        interface="slcan",
        channel=port,
        bitrate=1_000_000,
        sleep_after_open=0,
        poll_interval=0.01,
        name="host-slcan",
    )


def recv_matching(bus: can.BusABC, arb_id: int, timeout: float = 1.0) -> can.Message:
    deadline = time.monotonic() + timeout
    while (left := deadline - time.monotonic()) > 0:
        msg = bus.recv(left)
        if msg is not None and msg.arbitration_id == arb_id:
            return msg
    raise TimeoutError(f"no frame {arb_id:#x}")


@pytest.fixture
def adapter() -> Iterator[SlcanAdapter]:
    with SlcanAdapter() as sim:
        yield sim


@pytest.fixture
def bus_side(adapter: SlcanAdapter) -> Iterator[can.BusABC]:
    """A plain python-can bus on the adapter's CAN side (the "other nodes")."""
    bus = can.Bus(interface="virtual", channel=adapter.channel)
    try:
        yield bus
    finally:
        bus.shutdown()


# -- codec --------------------------------------------------------------------------------------
frames = st.builds(
    lambda ext, remote, arb, data, dlc: can.Message(
        arbitration_id=arb & (0x1FFF_FFFF if ext else 0x7FF),
        is_extended_id=ext,
        is_remote_frame=remote,
        data=b"" if remote else data,
        dlc=dlc if remote else len(data),
    ),
    st.booleans(),
    st.booleans(),
    st.integers(0, 0x1FFF_FFFF),
    st.binary(max_size=8),
    st.integers(0, 8),
)


def _same(a: can.Message, b: can.Message) -> bool:
    return (a.arbitration_id, a.is_extended_id, a.is_remote_frame, a.dlc, bytes(a.data)) == (
        b.arbitration_id,
        b.is_extended_id,
        b.is_remote_frame,
        b.dlc,
        bytes(b.data),
    )


@pytest.fixture(scope="module")
def loopback() -> Iterator[can.BusABC]:
    """python-can's slcan interface on pyserial's ``loop://``: what it writes it reads back."""
    bus = can.Bus(interface="slcan", channel="loop://", sleep_after_open=0)
    try:
        yield bus
    finally:
        bus.shutdown()


@given(msg=frames)
def test_codec_is_byte_exact_with_python_can(loopback: can.BusABC, msg: can.Message) -> None:
    port = loopback.serialPortOrig  # type: ignore[attr-defined]
    port.reset_input_buffer()
    loopback.send(msg)
    expected = encode_frame(msg)
    wire = b""
    deadline = time.monotonic() + 2.0
    while len(wire) < len(expected) and time.monotonic() < deadline:
        wire += port.read(len(expected) - len(wire))  # (1 ms timeout a read: bounded)
    assert wire == expected  # the adapter writes what python-can writes
    assert _same(decode_frame(wire[:-1]), msg)  # and reads it back
    port.write(encode_frame(msg))
    got = loopback.recv(0.5)  # python-can parses what the adapter sends the host
    assert got is not None and _same(got, msg)


@given(msg=frames, stamp=st.integers(0, 59_999))
def test_timestamped_lines_parse_in_python_can(
    loopback: can.BusABC, msg: can.Message, stamp: int
) -> None:
    port = loopback.serialPortOrig  # type: ignore[attr-defined]
    port.reset_input_buffer()
    line = encode_frame(msg, stamp)
    assert line.endswith(f"{stamp:04X}\r".encode())
    port.write(line)
    got = loopback.recv(0.5)
    assert got is not None and _same(got, msg)


@pytest.mark.parametrize(
    "line",
    [
        b"t12",
        b"t1239",
        b"t8000",
        b"tG230",
        b"t12321",
        b"t1231AAB",
        b"T2000000000",
        b"r1231AA",
        b"x1230",
        b"t123 1AA",
    ],
)
def test_decode_refuses_malformed_frames(line: bytes) -> None:
    with pytest.raises(SlcanError):
        decode_frame(line)


def test_btr_bitrate_of_common_register_values() -> None:
    # The SJA1000 (8 MHz) values Lawicel lists for 1 Mbit/s, 500 and 125 kbit/s.
    assert btr_bitrate(0x00, 0x14) == 1_000_000
    assert btr_bitrate(0x00, 0x1C) == 500_000
    assert btr_bitrate(0x03, 0x1C) == 125_000


# -- the wire -----------------------------------------------------------------------------------
def test_wire_bytes_both_ways(adapter: SlcanAdapter, bus_side: can.BusABC) -> None:
    with raw_port(adapter.port) as fd:
        assert talk(fd, b"V") == b"V1013\r"
        assert talk(fd, b"v") == b"v1300\r"
        assert talk(fd, b"N") == b"NSIM1\r"
        assert talk(fd, b"S8") == b"\r"
        assert talk(fd, b"O") == b"\r"
        assert talk(fd, b"t1232AABB") == b"z\r"
        assert talk(fd, b"T1FFFFFFF0") == b"Z\r"
        assert talk(fd, b"r7FF8") == b"z\r"
        assert talk(fd, b"R000000013") == b"Z\r"
        sent = [bus_side.recv(5.0) for _ in range(4)]
        assert [
            (m.arbitration_id, m.is_extended_id, m.is_remote_frame, m.dlc, bytes(m.data))
            for m in sent
            if m
        ] == [
            (0x123, False, False, 2, b"\xaa\xbb"),
            (0x1FFFFFFF, True, False, 0, b""),
            (0x7FF, False, True, 8, b""),
            (0x1, True, True, 3, b""),
        ]
        bus_side.send(can.Message(arbitration_id=0x0A5, is_extended_id=False, data=b"\x01\xfe"))
        bus_side.send(can.Message(arbitration_id=0x18FF0102, data=b"\x00" * 8))
        bus_side.send(can.Message(arbitration_id=0x701, is_extended_id=False, is_remote_frame=True, dlc=1))  # fmt: skip
        assert read_reply(fd, 3) == b"t0A5201FE\rT18FF01028" + b"00" * 8 + b"\rr7011\r"
        assert talk(fd, b"F") == b"F00\r"
        assert talk(fd, b"C") == b"\r"
        bus_side.send(can.Message(arbitration_id=0x0A5, is_extended_id=False))
        assert talk(fd, b"Z1") == b"\r"  # nothing of the frame received while closed
        assert talk(fd, b"O") == b"\r"
        bus_side.send(can.Message(arbitration_id=0x0A5, is_extended_id=False, data=b"\x07"))
        line = read_reply(fd)
        assert line.startswith(b"t0A5107") and len(line) == len(b"t0A5107") + 4 + 1  # ms stamp
    assert adapter.stats.errors == 0
    assert adapter.stats.to_bus == 4 and adapter.stats.to_host == 4


@pytest.mark.parametrize(
    ("commands", "kind"),
    [
        ([b"S8", b"t1230"], "refused"),  # a frame before O
        ([b"S8", b"L", b"t1230"], "refused"),  # listen-only
        ([b"S8", b"O", b"C", b"t1230"], "refused"),  # after C
        ([b"O"], "malformed"),  # no bit rate set yet
        ([b"S9"], "malformed"),  # 83.3 kbit/s: not in this (CANable) table
        ([b"S8", b"O", b"S6"], "malformed"),  # bit rate while open
        ([b"S8", b"O", b"L"], "malformed"),  # listen-only while open
        ([b"F"], "malformed"),  # status while closed
        ([b"X"], "malformed"),  # unknown command
        ([b"S8", b"O", b"t12"], "malformed"),
        ([b"S8", b"O", b"t1239"], "malformed"),  # dlc 9
        ([b"S8", b"O", b"t8000"], "malformed"),  # id beyond 0x7FF
        ([b"S8", b"O", b"t1231XY"], "malformed"),  # non-hex data
        ([b"S8", b"O", b"d1231AA"], "malformed"),  # CAN FD: a CAN 2.0 adapter
        ([b"S8", b"O", b"t1238" + b"0" * 60], "malformed"),  # longer than MAX_LINE
        ([b"S6", b"O", b"t1230"], "bitrate_errors"),  # 500 kbit/s on a 1 Mbit/s bus
    ],
)
def test_malformed_or_refused_commands_get_bel(
    adapter: SlcanAdapter, bus_side: can.BusABC, commands: list[bytes], kind: str
) -> None:
    with raw_port(adapter.port) as fd:
        *setup, bad = commands
        for command in setup:
            assert talk(fd, command) == b"\r"
        assert talk(fd, bad) == b"\a"
        assert talk(fd, b"V") == b"V1013\r"  # the adapter still answers
    assert adapter.stats.errors == 1
    assert getattr(adapter.stats, kind) == 1
    assert bus_side.recv(0.0) is None  # nothing reached the bus


def test_bitrate_mismatch_flags_and_no_frames(adapter: SlcanAdapter, bus_side: can.BusABC) -> None:
    with raw_port(adapter.port) as fd:
        assert talk(fd, b"S6") == b"\r"
        assert talk(fd, b"O") == b"\r"  # a real adapter cannot know the bus's rate either
        bus_side.send(can.Message(arbitration_id=0x123, is_extended_id=False))
        deadline = time.monotonic() + 1.0  # the bus side sees the frame a moment later
        while (status := talk(fd, b"F")) == b"F00\r" and time.monotonic() < deadline:
            time.sleep(0.001)
        assert status == f"F{StatusFlag.BUS_ERROR | StatusFlag.ERROR_PASSIVE:02X}\r".encode()
        assert read_reply(fd, 0) == b""  # the frame never reached the host
        assert talk(fd, b"F") == b"F00\r"  # cleared by reading
        assert talk(fd, b"C") == b"\r"
        assert talk(fd, b"s0014") == b"\r"  # BTR0/BTR1 for 1 Mbit/s at 8 MHz
        assert talk(fd, b"O") == b"\r"
        assert talk(fd, b"t1230") == b"z\r"
    assert bus_side.recv(1.0) is not None


def test_a_host_that_does_not_read_loses_frames_not_the_adapter(
    adapter: SlcanAdapter, bus_side: can.BusABC
) -> None:
    with raw_port(adapter.port) as fd:
        assert talk(fd, b"S8") == b"\r"
        assert talk(fd, b"O") == b"\r"
        frame = can.Message(arbitration_id=0x123, is_extended_id=False, data=bytes(8))
        for _ in range(5000):  # 105 kB: more than the pty and the adapter's buffer hold
            bus_side.send(frame)
        deadline = time.monotonic() + 10.0  # (the adapter's thread on a loaded machine)
        while adapter.stats.to_host + adapter.stats.dropped < 5000:
            assert time.monotonic() < deadline, adapter.stats
            time.sleep(0.005)
        assert adapter.stats.dropped > 0
        os.write(fd, b"F\r")
        backlog = b""
        while not re.search(rb"F[0-9A-F]{2}\r$", backlog):  # whole lines, then the status
            try:  # (15 s: the adapter's two threads on a loaded machine, in a full run)
                backlog += read_reply(fd, 1, timeout=15.0)
            except TimeoutError as exc:
                raise TimeoutError(f"{exc}; {len(backlog)} B read; {adapter.stats}") from None
        lines = backlog.split(b"\r")
        assert set(lines[:-2]) == {b"t1238" + b"00" * 8}
        overrun = StatusFlag.RX_FIFO_FULL | StatusFlag.DATA_OVERRUN
        assert lines[-2] == f"F{overrun:02X}".encode()
    assert adapter.stats.errors == 0


# -- python-can's slcan interface -----------------------------------------------------------------
def test_python_can_slcan_sends_and_receives(adapter: SlcanAdapter, bus_side: can.BusABC) -> None:
    host = slcan_bus(adapter.port)
    try:
        assert host.get_version(1.0) == (10, 13)  # type: ignore[attr-defined]
        assert host.get_serial_number(1.0) == "SIM1"  # type: ignore[attr-defined]
        out = [
            can.Message(arbitration_id=0x123, is_extended_id=False, data=b"\x11\x22\x33"),
            can.Message(arbitration_id=0x1ABCDEF0, is_extended_id=True, data=bytes(range(8))),
            can.Message(arbitration_id=0x7FF, is_extended_id=False, is_remote_frame=True, dlc=4),
            can.Message(arbitration_id=0x42, is_extended_id=True, is_remote_frame=True, dlc=0),
        ]
        for msg in out:
            host.send(msg)
        for msg in out:
            got = bus_side.recv(1.0)
            assert got is not None and _same(got, msg)
        for msg in out:
            bus_side.send(msg)
        for msg in out:
            got = host.recv(1.0)
            assert got is not None and _same(got, msg)
    finally:
        host.shutdown()
    # python-can's open: C, S8, an empty line (no FD data rate), O, O; shutdown: C.
    assert list(adapter.lines)[:4] == [b"C", b"S8", b"O", b"O"]
    assert b"t1233112233" in adapter.lines and b"T1ABCDEF080001020304050607" in adapter.lines
    assert b"r7FF4" in adapter.lines and b"R000000420" in adapter.lines
    assert adapter.stats.errors == 0


def test_hosted_peers_must_run_on_the_real_clock() -> None:
    with pytest.raises(BadParameterError, match="peers"):
        SlcanAdapter(peers=[SimODrive(0, clock=VirtualClock())])
    with pytest.raises(BadParameterError, match="bitrate"):
        SlcanAdapter(bitrate=83_300)


# -- the drivers through python-can's slcan interface ------------------------------------------------
@asynccontextmanager
async def axes(port: str, recorder: EventRecorder) -> AsyncIterator[tuple[Actuator, Actuator]]:
    async with host_bus(port) as bus:
        odrive = Actuator(ODriveAxis(bus, ODRIVE, heartbeat_period=HB), clock=default_clock())
        cia402 = Actuator(Cia402Drive(bus, CIA402, heartbeat_ms=50), clock=default_clock())
        async with odrive, cia402:
            odrive.add_observer(recorder)
            cia402.add_observer(recorder)
            yield odrive, cia402


async def _move_both(odrive: Actuator, cia402: Actuator, recorder: EventRecorder) -> None:
    with anyio.fail_after(2.5):
        moves = [await odrive.set_value(1.0, Request.POSITION), await cia402.set_value(2.0)]
        for motion in moves:
            await motion
    assert await odrive.get_value(Request.POSITION_ACTUAL) == pytest.approx(1.0, abs=1e-4)
    assert await cia402.get_value(Request.POSITION_ACTUAL) == pytest.approx(2.0, abs=1e-3)
    assert recorder.count("event", COMPLETED, source=odrive) == 1
    assert recorder.count("event", COMPLETED, source=cia402) == 1


async def test_drivers_complete_a_move_through_the_in_thread_adapter() -> None:
    recorder = EventRecorder(default_clock())
    odrive_sim = SimODrive(ODRIVE, heartbeat_period=HB)
    cia402_sim = SimCia402Drive(CIA402)
    with SlcanAdapter(peers=[odrive_sim, cia402_sim]) as adapter:
        async with axes(adapter.port, recorder) as (odrive, cia402):
            await _move_both(odrive, cia402, recorder)
        assert odrive_sim.position == pytest.approx(1.0 / math.tau, abs=1e-6)
    assert adapter.stats.errors == 0 and adapter.stats.dropped == 0


async def test_in_thread_peers_keep_running_while_the_host_loop_blocks() -> None:
    odrive_sim = SimODrive(ODRIVE, heartbeat_period=HB)
    with SlcanAdapter(peers=[odrive_sim]) as adapter:
        host = slcan_bus(adapter.port)
        try:
            recv_matching(host, (ODRIVE << 5) | 0x01)  # a heartbeat
            before = adapter.stats.to_host
            time.sleep(0.2)  # noqa: ASYNC251 - blocks the host's event loop on purpose
            assert adapter.stats.to_host >= before + 3  # heartbeats every 20 ms meanwhile
        finally:
            host.shutdown()


def test_faults_are_injected_in_the_peers_thread() -> None:
    odrive_sim = SimODrive(ODRIVE, heartbeat_period=HB)
    with SlcanAdapter(peers=[odrive_sim]) as adapter:
        host = slcan_bus(adapter.port)
        try:
            adapter.call(odrive_sim.inject_error)
            deadline = time.monotonic() + 1.0
            while True:
                beat = recv_matching(host, (ODRIVE << 5) | 1)
                msg = cs.decode(beat.arbitration_id, beat.data, from_host=False)
                assert isinstance(msg, cs.Heartbeat)
                if msg.axis_error:
                    break
                assert time.monotonic() < deadline, "no heartbeat with the error"
        finally:
            host.shutdown()
    with SlcanAdapter() as bare, pytest.raises(RuntimeError, match="no peers"):
        bare.call(print)


async def test_drivers_complete_a_move_through_the_adapter_process() -> None:
    args = ("--odrive", str(ODRIVE), "--cia402", str(CIA402), "--odrive-heartbeat", str(HB))
    with SlcanAdapterProcess(*args, "--bitrate", "1000000") as sim:
        port = sim.port
        recorder = EventRecorder(default_clock())
        async with axes(port, recorder) as (odrive, cia402):
            await _move_both(odrive, cia402, recorder)
        # The host has gone; the drives keep running in the adapter process.
        host = await anyio.to_thread.run_sync(slcan_bus, port)
        try:
            beat = await anyio.to_thread.run_sync(recv_matching, host, (ODRIVE << 5) | 1)
            msg = cs.decode(beat.arbitration_id, beat.data, from_host=False)
            assert isinstance(msg, cs.Heartbeat) and msg.axis_error == 0
        finally:
            host.shutdown()
        assert sim.process is not None
        sim.process.send_signal(signal.SIGTERM)
        assert sim.process.wait(5.0) == 0


def test_the_adapter_process_outlives_a_killed_host() -> None:
    with SlcanAdapterProcess("--odrive", str(ODRIVE), "--odrive-heartbeat", str(HB)) as sim:
        script = (
            "import can, sys, time\n"
            "bus = can.Bus(interface='slcan', channel=sys.argv[1], bitrate=1000000, sleep_after_open=0)\n"
            "bus.send(can.Message(arbitration_id=0x7E5, is_extended_id=False, data=b'\\x01'))\n"
            "print('open', flush=True)\n"
            "time.sleep(30)\n"
        )
        host = subprocess.Popen([sys.executable, "-c", script, sim.port], stdout=subprocess.PIPE)
        try:
            assert host.stdout is not None
            assert select.select([host.stdout], [], [], 10.0)[0]
            assert host.stdout.readline() == b"open\n"
        finally:
            host.kill()  # SIGKILL: no C, no close
            host.wait()
            if host.stdout is not None:
                host.stdout.close()
        # The adapter is still open at 1 Mbit/s with its drive running: a new host just opens.
        again = slcan_bus(sim.port)
        try:
            assert again.get_version(1.0) == (10, 13)  # type: ignore[attr-defined]
            recv_matching(again, (ODRIVE << 5) | 1)  # heartbeats keep coming
        finally:
            again.shutdown()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("--bitrate", "123"), b"bitrate=123 is not allowed"),
        (("--odrive", "99"), b"--odrive: node_id 99 outside 0..62"),
        (("--cia402", "0"), b"--cia402: node_id 0 outside 1..127"),
    ],
)
def test_the_adapter_process_refuses_bad_arguments(args: tuple[str, ...], message: bytes) -> None:
    result = subprocess.run(
        [sys.executable, "-m", "openel_can.sim.slcan", *args],
        capture_output=True,
        timeout=20,
        check=False,
    )
    assert result.returncode == 2 and result.stdout == b""
    assert message in result.stderr
