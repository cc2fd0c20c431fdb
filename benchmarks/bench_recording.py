"""The flight recorder and the live view on the arm2 lockstep control loop.

The loop: the MuJoCo arm2 model in lockstep (1 ms physics step), its two joints as Actuators
in an ActuatorBank and the ``tip_pos`` sensor as a Sensor, on a 2 ms EventTimer whose plain
observer streams both joints' setpoints (a sine) and reads the tip at every tick -- the
per-tick work of the arm2 demo. Three variants run in the same process, interleaved round by
round: without any tap (the baseline), with a ``Recorder`` writing MCAP, and with a
``LiveView`` that one Foxglove WebSocket client subscribes to on every channel before the
loop starts (a process of its own on 127.0.0.1, reading the socket raw and counting the
messages after the loop, niced as the writer is: a viewer runs elsewhere, a browser, not on
the control loop's cores). Figures: medians over the rounds of the real time per control
tick, of the CPU time of the loop's thread, of the app process (the loop and the recorder's
feeding thread) and of the writer process (reported by it); ratio = variant / baseline. In
lockstep the loop runs as fast as it can (about 200x real time), so this is the recorder at
saturation: 3.4 messages per 10 us tick. Neither queue may drop anything.

Interference, separated: two more variants run the loop without any tap while another process
feeds the stream that a Recorder's loop sent to its writer (captured once, before the rounds)
to a writer process of its own at nice 19, paced over the no-tap loop's duration: an MCAP
writer, and a live server with the same kind of client subscribed. Their ratios are what the
writer process (and the live client) cost the loop through the shared cores and caches, with
nothing done in the loop; the rest of a tap's ratio is the app process's own work.

Where the cost is (docs/recording.md, "Cost"): main-thread instructions per tick under
callgrind, no tap about 106 600, the Recorder about 117 000-120 000 (+10-12 %); per call,
timed in place: the sensor reading's listener call and record about 0.3 us every tick, the
bank batch's about 0.28 us every tick, the joint-state sample about 1 us every 5 ticks, the
tap's clock callback 0.35 us every 5 ticks, and encoding a batch of 1 024 records every 300
ticks or so. The loop thread's CPU time shows about twice the instruction count's share:
the records (a few hundred bytes per tick, alive until their batch is encoded), the garbage
collector's passes over them and the feeding thread's interpreter-lock hand-overs. The
interference rows show what the writer process costs the loop from outside: the MCAP writer
next to nothing, the live server with its client some wall time (the loop waiting for a
core), not the loop thread's CPU. The writer process runs on one CPU (its threads and the
Foxglove server's), the last one. It costs
about 1.9 us CPU per message (msgpack decode, the JSON message, the SDK's Rust MCAP writer or
WebSocket server and the call into it). It runs at the lowest priority (nice 19): on a busy
machine the loop keeps the CPU and the writer catches up afterwards (bounded by the queue's
capacity, 100 000 records).
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import tempfile
import time
from collections.abc import Awaitable, Callable
from pathlib import Path
from statistics import median
from typing import Any

import anyio

from .harness import BenchResult, Row, ratio_of

PERIOD_MS = 2
LOOP_TIMEOUT_S = 300.0
"""Real seconds a loop of ticks may take before the benchmark fails (a stalled loop)."""
CHANNELS = 6
"""The live view's channels in this loop: /log, /hal/<3 components>, /joint_states and the
timer's."""
LOOP_CPU: list[tuple[float, float]] = []
"""Per tick of each _loop call: (CPU time of the loop's thread, CPU time of the whole process:
the loop and the recorder's feeding thread); the last call's is LOOP_CPU[-1]."""


class _Control:
    def __init__(self, bank: Any, tip: Any, ticks: int, done: anyio.Event) -> None:
        self.bank, self.tip, self.ticks, self.done, self.k = bank, tip, ticks, done, 0

    def notify_timer(self, timer: Any) -> None:
        self.k += 1
        phase = self.k * 0.002
        self.bank.set_values_nowait([0.4 * math.sin(phase), -0.8 + 0.3 * math.cos(phase)])
        self.tip.get_value_nowait()
        if self.k >= self.ticks:
            timer.stop_timer()
            self.done.set()


async def _loop(
    ticks: int, tap: Any | None, ready: Callable[[], Awaitable[None]] | None = None
) -> float:
    """Real seconds per tick of ``ticks`` control ticks (``tap``: observing everything;
    ``ready``: awaited once everything is observed, before the timer starts)."""
    from openel_async import Actuator, ActuatorBank, EventTimer, Sensor
    from openel_mujoco import MujocoSim

    sim = MujocoSim("arm2", pacing="lockstep")
    async with sim:
        axes = [Actuator(sim.actuator(j), clock=sim.clock) for j in ("shoulder", "elbow")]
        tip = Sensor(sim.sensor("tip_pos"), clock=sim.clock)
        timer = EventTimer(PERIOD_MS, clock=sim.clock, name="arm2-sync")
        if tap is not None:
            for component in (*axes, tip):
                tap.observe(component)
            tap.observe_timer(timer)
        async with axes[0], axes[1], tip, timer:
            if ready is not None:
                await ready()
            done = anyio.Event()
            timer.add_observer(_Control(ActuatorBank(axes), tip, ticks, done))
            started, cpu, process = time.perf_counter(), time.thread_time(), time.process_time()
            timer.start_timer()
            with anyio.fail_after(LOOP_TIMEOUT_S):  # real seconds: the loop must end
                await done.wait()
            LOOP_CPU.append(
                ((time.thread_time() - cpu) / ticks, (time.process_time() - process) / ticks)
            )
            return (time.perf_counter() - started) / ticks


async def _baseline(ticks: int) -> float:
    return await _loop(ticks, None)


async def _recorded(ticks: int, path: Path) -> tuple[float, int, float, float]:
    """(seconds per tick, records dropped, writer-process CPU seconds per tick, messages
    written per tick)."""
    from openel_async.recording import Recorder

    recorder = Recorder(path)
    async with recorder:
        per_tick = await _loop(ticks, recorder)
    assert recorder.final_stats is not None
    writer_cpu = recorder.pipeline.writer_cpu_s or 0.0
    stats = recorder.final_stats
    return per_tick, stats.dropped, writer_cpu / ticks, stats.written / ticks


CLIENT = r"""
# A Foxglove WebSocket client on a raw socket: it subscribes to every channel advertised
# (printing "subscribed N"), then, once it has CHANNELS of them, only reads the socket into
# memory (one recv per 256 KiB at most, so that it keeps up and the server drops nothing for
# it) until it has been idle for IDLE s; then it counts the message-data frames and prints the
# count. A Python WebSocket library's per-frame work would take a core at the loop's rate.
import base64, json, os, socket, struct, sys, urllib.parse
url, idle, channels = urllib.parse.urlparse(sys.argv[1]), float(sys.argv[2]), int(sys.argv[3])
sock = socket.create_connection((url.hostname, url.port))
key = base64.b64encode(os.urandom(16)).decode()
sock.sendall((f"GET / HTTP/1.1\r\nHost: {url.hostname}:{url.port}\r\nUpgrade: websocket\r\n"
              f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
              "Sec-WebSocket-Version: 13\r\nSec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n"
              ).encode())
buf = b""
while b"\r\n\r\n" not in buf:
    buf += sock.recv(65536)
head, _, buf = buf.partition(b"\r\n\r\n")
assert head.split()[1] == b"101", head
print("ready", flush=True)

def send_text(text):
    data, mask = text.encode(), os.urandom(4)
    n = len(data)
    header = bytes([0x81]) + (bytes([0x80 | n]) if n < 126 else
                              bytes([0x80 | 126]) + struct.pack(">H", n) if n < 65536 else
                              bytes([0x80 | 127]) + struct.pack(">Q", n))
    sock.sendall(header + mask + bytes(b ^ mask[i & 3] for i, b in enumerate(data)))

def frames(data, start):
    # (opcode, payload) of each complete frame from start; and where the rest begins
    out, i, end = [], start, len(data)
    while i + 2 <= end:
        opcode, n, j = data[i] & 0x0F, data[i + 1] & 0x7F, i + 2
        if n == 126:
            if j + 2 > end: break
            (n,), j = struct.unpack_from(">H", data, j), j + 2
        elif n == 127:
            if j + 8 > end: break
            (n,), j = struct.unpack_from(">Q", data, j), j + 8
        if j + n > end: break
        out.append((opcode, data[j:j + 1] if opcode == 2 else data[j:j + n]))
        i = j + n
    return out, i

count, next_id, subscribed = 0, 1, 0
while subscribed < channels:
    found, used = frames(buf, 0)  # what came with the handshake's reply first
    if not found:
        buf += sock.recv(262144)
        continue
    buf = buf[used:]
    for opcode, payload in found:
        if opcode == 1:
            message = json.loads(payload)
            if message.get("op") == "advertise":
                subs = [{"id": next_id + i, "channelId": c["id"]}
                        for i, c in enumerate(message["channels"])]
                next_id += len(subs)
                subscribed += len(subs)
                send_text(json.dumps({"op": "subscribe", "subscriptions": subs}))
                print("subscribed", subscribed, flush=True)
        elif opcode == 2 and payload[:1] == b"\x01":
            count += 1
chunks = [buf]
sock.settimeout(idle)
try:
    while True:
        chunk = sock.recv(262144)
        if not chunk:
            break
        chunks.append(chunk)
except OSError:  # idle (timeout)
    pass
found, _ = frames(b"".join(chunks), 0)
count += sum(1 for opcode, payload in found if opcode == 2 and payload[:1] == b"\x01")
print(count, flush=True)
"""


async def _live(ticks: int) -> tuple[float, int, float, int, int]:
    """The loop with a LiveView and one Foxglove client (a process of its own, subscribed
    to every channel); returns (seconds per tick, messages the client received, writer-process
    CPU seconds per tick, messages published, records dropped)."""
    from openel_async.recording import LiveView

    live = LiveView(port=0, joint_period_ms=10.0)
    async with live:
        client = subprocess.Popen(  # noqa: ASYNC220 (started once, before the loop)
            # niced like the writer: a viewer usually runs elsewhere (a browser), not on
            # the control loop's two cores
            ["nice", "-n", "19", sys.executable, "-c", CLIENT, live.url, "1.0", str(CHANNELS)],
            stdout=subprocess.PIPE,
            text=True,
        )
        assert client.stdout is not None
        try:
            with anyio.fail_after(20):
                line = await anyio.to_thread.run_sync(client.stdout.readline)
            assert line.strip() == "ready", line
            stdout = client.stdout

            async def subscribed() -> None:
                # every channel (/log, three components, /joint_states, the timer's)
                # advertised and subscribed to before the loop starts
                with anyio.fail_after(20):
                    count = 0
                    while count < CHANNELS:
                        line = await anyio.to_thread.run_sync(stdout.readline)
                        assert line.startswith("subscribed"), line
                        count = int(line.split()[1])
                    await anyio.sleep(0.05)  # the server has the subscriptions

            per_tick = await _loop(ticks, live, subscribed)
            # (untimed) the server's last batch reaches the client before the server stops
            await anyio.sleep(0.5)
        except BaseException:
            client.kill()
            raise
    out, _ = await anyio.to_thread.run_sync(lambda: client.communicate(timeout=30))
    writer_cpu = live.pipeline.writer_cpu_s or 0.0
    assert live.final_stats is not None
    stats = live.final_stats
    return per_tick, int(out.split()[-1]), writer_cpu / ticks, stats.written, stats.dropped


FEEDER = r"""
# Feeds a captured writer stream (the frames one Recorder loop sent to its writer process) to
# a writer process of its own, started with the command given (a Pipeline's: nice 19, its
# CPU): the entries up to the last one that makes a channel at once (setup), then,
# after a "go" line on stdin, the rest paced evenly by bytes over DURATION s (the no-tap
# loop's duration); prints the writer's ready line, then its final line.
import subprocess, sys, time
import msgspec
path, duration, command = sys.argv[1], float(sys.argv[2]), sys.argv[3:]
data, frames, i = open(path, "rb").read(), [], 0
while i < len(data):
    n = int.from_bytes(data[i:i + 4], "little")
    frames.append(data[i:i + 4 + n])
    i += 4 + n
decode, encode = msgspec.msgpack.Decoder().decode, msgspec.msgpack.Encoder().encode
batches = [decode(f[4:]) for f in frames]
last = max((k, j) for k, b in enumerate(batches) for j, e in enumerate(b) if e[0] == -1)
batches = [*batches[:last[0]], batches[last[0]][:last[1] + 1], batches[last[0]][last[1] + 1:],
           *batches[last[0] + 1:]]
frames = [len(p).to_bytes(4, "little") + p for p in map(encode, batches) if p != b"\x90"]
setup = last[0] + 1
child = subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.PIPE)
print(child.stdout.readline().decode().strip(), flush=True)
child.stdin.write(b"".join(frames[:setup]))
child.stdin.flush()
sys.stdin.readline()
rest = frames[setup:]
total, sent, start = sum(map(len, rest)) or 1, 0, time.perf_counter()
for frame in rest:
    sent += len(frame)
    delay = start + duration * sent / total - time.perf_counter()
    if delay > 0:
        time.sleep(delay)
    child.stdin.write(frame)
    child.stdin.flush()
child.stdin.close()
print(child.stdout.read().decode().strip().splitlines()[-1], flush=True)
child.wait()
"""


async def _capture(ticks: int, path: Path, stream: Path) -> None:
    """One Recorder loop (untimed) whose writer process's input is also copied to
    ``stream``."""
    from openel_async.recording import Recorder

    recorder = Recorder(path)
    command = recorder.pipeline.writer_command()
    tee = ["sh", "-c", f'tee "{stream}" | exec "$@"', "sh", *command]
    recorder.pipeline.writer_command = lambda: tee  # type: ignore[method-assign]
    async with recorder:
        await _loop(ticks, recorder)


async def _interfered(
    ticks: int, stream: Path, duration: float, command: list[str], live: bool
) -> tuple[float, float]:
    """The no-tap loop while another process feeds ``stream`` to a writer process of its own
    (``command``: a Pipeline's writer command) over ``duration`` s, with a live client subscribed when
    ``live``: the interference of the writer (and the client) without any work in the loop.
    Returns (seconds per tick, writer-process CPU seconds per tick)."""
    feeder = subprocess.Popen(  # noqa: ASYNC220 (started once, before the loop)
        [sys.executable, "-c", FEEDER, str(stream), repr(duration), *command],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    assert feeder.stdin is not None and feeder.stdout is not None
    stdin, stdout = feeder.stdin, feeder.stdout
    client: subprocess.Popen[str] | None = None
    try:
        with anyio.fail_after(30):
            info = json.loads(await anyio.to_thread.run_sync(stdout.readline))
        if live:
            url = f"ws://127.0.0.1:{info['port']}"
            client = subprocess.Popen(  # noqa: ASYNC220
                ["nice", "-n", "19", sys.executable, "-c", CLIENT, url, "1.0", str(CHANNELS)],
                stdout=subprocess.PIPE,
                text=True,
            )
            assert client.stdout is not None
            client_out = client.stdout
            with anyio.fail_after(20):
                count = 0
                while count < CHANNELS:
                    line = await anyio.to_thread.run_sync(client_out.readline)
                    if line.startswith("subscribed"):
                        count = int(line.split()[1])
                    else:
                        assert line.strip() == "ready", line
                await anyio.sleep(0.05)

        async def go() -> None:
            stdin.write("go\n")
            stdin.flush()

        per_tick = await _loop(ticks, None, go)
        with anyio.fail_after(60):
            done = json.loads(await anyio.to_thread.run_sync(stdout.readline))
        await anyio.to_thread.run_sync(lambda: feeder.wait(30))
        if client is not None:
            await anyio.to_thread.run_sync(lambda: client.communicate(timeout=30))
    except BaseException:
        feeder.kill()
        if client is not None:
            client.kill()
        raise
    return per_tick, float(done["cpu_s"]) / ticks


def _cpu_row(name: str, value: float, base: float, label: str) -> Row:
    return Row(
        name,
        value * 1e6,
        "us",
        baseline=base * 1e6,
        baseline_label="no tap",
        ratio=ratio_of(value, base),
        ratio_label=label,
        digits=1,
    )


def run(quick: bool) -> BenchResult:
    ticks = 2_000 if quick else 20_000
    rounds = 3 if quick else 9
    names = ("base", "rec", "live", "rec_io", "live_io")
    wall: dict[str, list[float]] = {k: [] for k in names}
    thread: dict[str, list[float]] = {k: [] for k in names}
    process: dict[str, list[float]] = {k: [] for k in names}
    writer: dict[str, list[float]] = {"rec": [], "live": [], "rec_io": [], "live_io": []}
    dropped = received = published = live_dropped = 0
    messages: list[float] = []
    from openel_async.recording.pipeline import Pipeline

    with tempfile.TemporaryDirectory() as tmp:
        anyio.run(_baseline, 500, backend="asyncio")  # warm-up: imports, model load
        stream = Path(tmp) / "stream.bin"  # a Recorder loop's writer input, for interference
        anyio.run(_capture, ticks, Path(tmp) / "capture.mcap", stream, backend="asyncio")
        sinks = {  # the writer processes a Recorder and a LiveView start
            "rec_io": Pipeline(mcap=Path(tmp) / "fed.mcap").writer_command(),
            "live_io": Pipeline(foxglove=("127.0.0.1", 0)).writer_command(),
        }
        for r in range(rounds):
            wall["base"].append(anyio.run(_baseline, ticks, backend="asyncio"))
            thread["base"].append(LOOP_CPU[-1][0])
            process["base"].append(LOOP_CPU[-1][1])
            duration = wall["base"][-1] * ticks
            for key, sink in sinks.items():
                per_tick, cpu = anyio.run(
                    _interfered, ticks, stream, duration, sink, key == "live_io", backend="asyncio"
                )
                wall[key].append(per_tick)
                thread[key].append(LOOP_CPU[-1][0])
                process[key].append(LOOP_CPU[-1][1])
                writer[key].append(cpu)
            per_tick, lost, cpu, written = anyio.run(
                _recorded, ticks, Path(tmp) / f"r{r}.mcap", backend="asyncio"
            )
            wall["rec"].append(per_tick)
            thread["rec"].append(LOOP_CPU[-1][0])
            process["rec"].append(LOOP_CPU[-1][1])
            writer["rec"].append(cpu)
            messages.append(written)
            dropped += lost
            per_tick, got, cpu, sent, lost = anyio.run(_live, ticks, backend="asyncio")
            wall["live"].append(per_tick)
            thread["live"].append(LOOP_CPU[-1][0])
            process["live"].append(LOOP_CPU[-1][1])
            writer["live"].append(cpu)
            received += got
            published += sent
            live_dropped += lost
    w = {k: median(v) for k, v in wall.items()}
    t = {k: median(v) for k, v in thread.items()}
    p = {k: median(v) for k, v in process.items()}
    wr = {k: median(v) for k, v in writer.items()}
    b, rc, lv = w["base"] * 1e6, w["rec"] * 1e6, w["live"] * 1e6
    rec_ratio, live_ratio = ratio_of(rc, b), ratio_of(lv, b)
    rows = (
        Row("arm2 lockstep tick, no tap (baseline)", b, "us", digits=1),
        Row(
            "arm2 lockstep tick, Recorder (MCAP)",
            rc,
            "us",
            baseline=b,
            baseline_label="no tap",
            ratio=rec_ratio,
            ratio_label="recorder/baseline",
            target="<= 1.1x",
            passed=rec_ratio <= 1.1,
            digits=1,
        ),
        Row(
            "arm2 lockstep tick, LiveView + 1 client",
            lv,
            "us",
            baseline=b,
            baseline_label="no tap",
            ratio=live_ratio,
            ratio_label="live/baseline",
            target="<= 1.2x",
            passed=live_ratio <= 1.2,
            digits=1,
        ),
        _cpu_row(
            "no tap, a Recorder's writer fed its stream beside the loop (interference)",
            w["rec_io"],
            w["base"],
            "interfered/baseline",
        ),
        _cpu_row(
            "no tap, a LiveView's writer + client fed the stream beside (interference)",
            w["live_io"],
            w["base"],
            "interfered/baseline",
        ),
        _cpu_row(
            "loop thread CPU per tick, no tap, Recorder's writer beside",
            t["rec_io"],
            t["base"],
            "interfered/baseline",
        ),
        _cpu_row(
            "loop thread CPU per tick, no tap, LiveView's writer + client beside",
            t["live_io"],
            t["base"],
            "interfered/baseline",
        ),
        _cpu_row("loop thread CPU per tick, Recorder", t["rec"], t["base"], "recorder/baseline"),
        _cpu_row("loop thread CPU per tick, LiveView", t["live"], t["base"], "live/baseline"),
        _cpu_row(
            "app process CPU per tick (loop + feeding thread), Recorder",
            p["rec"],
            p["base"],
            "recorder/baseline",
        ),
        _cpu_row(
            "app process CPU per tick (loop + feeding thread), LiveView",
            p["live"],
            p["base"],
            "live/baseline",
        ),
        _cpu_row(
            "all CPU per tick (app + writer process), Recorder",
            p["rec"] + wr["rec"],
            p["base"],
            "recorder/baseline",
        ),
        _cpu_row(
            "all CPU per tick (app + writer process), LiveView",
            p["live"] + wr["live"],
            p["base"],
            "live/baseline",
        ),
        Row(
            "recorder messages dropped",
            float(dropped),
            "",
            target="0",
            passed=dropped == 0,
            digits=0,
        ),
        Row(
            "live view messages dropped",
            float(live_dropped),
            "",
            target="0",
            passed=live_dropped == 0,
            digits=0,
        ),
        Row("live messages published by the server", float(published), "", digits=0),
        Row("live messages received by the client", float(received), "", digits=0),
    )
    per_tick = median(messages)
    loop_extra = (t["rec"] - t["base"]) * 1e6
    notes = (
        f"Recorder: {per_tick:.1f} messages per tick. Loop thread: +{loop_extra:.2f} us per "
        f"tick ({loop_extra / per_tick * 1000:.0f} ns per message, dispatch and the joint-state "
        "sample included); writer process: "
        f"{wr['rec'] * 1e6:.2f} us CPU per tick ({wr['rec'] * 1e6 / per_tick:.2f} us per "
        "message: msgpack decode, the JSON message, the Rust MCAP writer).",
        f"At the loop's full speed the writer process needs {wr['rec'] / w['rec']:.0%} of a "
        f"core (LiveView: {wr['live'] / w['live']:.0%}), at nice 19. What the wall-time "
        "ratios show beyond the loop-thread CPU ratios is the loop waiting for a core or for "
        "the interpreter lock (the writer process, the thread writing to it, the live "
        "client and other work on the two shared cores).",
        f"Interference alone (no tap; the captured stream fed to a writer process of its own "
        f"beside the loop): MCAP writer {w['rec_io'] / w['base']:.2f}x wall, "
        f"{t['rec_io'] / t['base']:.2f}x loop-thread CPU (writer "
        f"{wr['rec_io'] * 1e6:.2f} us CPU per tick); live server + client "
        f"{w['live_io'] / w['base']:.2f}x, {t['live_io'] / t['base']:.2f}x (writer "
        f"{wr['live_io'] * 1e6:.2f} us per tick). The rest of each tap's ratio is the app "
        "process's own work: the listener calls and records, the samples, the batch encoding, "
        "the garbage collector and the feeding thread.",
    )
    return BenchResult(
        name="recording",
        notes=notes,
        title="Flight recorder (MCAP) and live view (Foxglove) on the arm2 lockstep loop",
        rows=rows,
        description=__doc__ or "",
        params={
            "ticks per round": str(ticks),
            "rounds": str(rounds),
            "period": f"{PERIOD_MS} ms",
            "joint-state period": "10 ms",
        },
    )
