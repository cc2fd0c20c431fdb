"""The figures of docs/remote.md ("Faults"), measured by hand (root, network namespaces):

    uv run python -m tests.remote.faults_run [--commands N]

``openel-async serve`` runs in a network namespace of its own joined to this one by a veth
pair (tests/remote/netns.py); the client is this process. Latency, jitter and loss come from
the fault-injecting relay (tests/remote/relay.py), partitions from the veth link taken down.
Prints one markdown table row per fault. For each: commands sent, commands lost (no reply and
no ``completed``, or an accepted command without exactly one ``completed``), commands
duplicated (executed twice: the server numbers every executed command, c1, c2, ..., so an
extra execution leaves a gap in the ids this only client sees), notices missed, and for
partitions the time from the link going down to the components in Error (detect) and from the
link coming back to the server seen again and ``re_init`` done (recover), and whether the
command sent into the partition was executed after it (it must not be).
"""

from __future__ import annotations

import argparse
import contextlib
import math
import statistics
import sys
import tempfile
import time
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass, field
from pathlib import Path

import anyio

from openel_async import Actuator, ComponentState, Request, ReturnCode
from openel_async.cli.logs import configure_logging
from openel_async.surface import CommandMessage, Device
from openel_zenoh import RemoteActuator, RemoteSurface, close_session, open_session
from openel_zenoh.config import LEASE_S, client_config

from .netns import Netns, netns, netns_unavailable, serve_in, until
from .relay import Faults, Relay

RIG = """\
namespace: faults
components:
  - {name: MOTOR_1, driver: sim, device: motor, params: {max_velocity: 0.5, max_acceleration: 20.0}}
  - {name: MOTOR_2, driver: sim, device: motor, params: {max_velocity: 4.0, max_acceleration: 40.0}}
"""
PORT = 7447
TIMEOUT_S = 2.0


@dataclass
class Row:
    fault: str
    commands: int = 0
    lost: int = 0
    duplicated: int = 0
    missed: int = 0
    detect: str = "-"
    recover: str = "-"
    notes: list[str] = field(default_factory=list)

    def markdown(self) -> str:
        return (
            f"| {self.fault} | {self.detect} | {self.recover} | {self.commands} | {self.lost} "
            f"| {self.duplicated} | {self.missed} | {'; '.join(self.notes)} |"
        )


class Completions:
    def __init__(self) -> None:
        self.seen: dict[str, list[int]] = {}
        self.missed = 0

    def completed(self, command_id: str, status: ReturnCode) -> None:
        self.seen.setdefault(command_id, []).append(int(status))

    def report_missed(self, count: int) -> None:
        self.missed += count


def command(function: str, logical_id: int, **arguments: float) -> Device:
    return Device("Motor", (CommandMessage.call(function, "", logical_id=logical_id, **arguments),))


def ms(seconds: float) -> str:
    return f"{seconds * 1000:.0f} ms" if seconds < 10 else f"{seconds:.1f} s"


@asynccontextmanager
async def client(endpoints: list[str]) -> AsyncIterator[RemoteSurface]:
    zs = await open_session(client_config(endpoints))
    try:
        async with RemoteSurface(zs, "faults", timeout=TIMEOUT_S) as remote:
            await remote.wait_server(15)
            yield remote
    finally:
        await close_session(zs)


def gaps(ids: list[str]) -> int:
    """Command ids the server assigned that this client never saw (executed unseen)."""
    numbers = sorted(int(i.removeprefix("c")) for i in ids)
    return numbers[-1] - numbers[0] + 1 - len(set(numbers)) if numbers else 0


async def traffic(ns: Netns, rig: str, faults: Faults, n: int) -> Row:
    """``n`` SetPosition + GetPosition pairs through the relay with ``faults``."""
    if faults.latency:
        label = f"latency {faults.latency * 1000:g} ms, jitter {faults.jitter * 1000:g} ms"
    elif faults.loss:
        label = f"loss {faults.loss * 100:g} %"
    else:
        label = "none (through the relay)"
    row = Row(label)
    async with (
        serve_in(ns, rig, [f"tcp/{ns.ip}:{PORT}"]),
        Relay(ns.ip, PORT, faults) as relay,
        client([relay.endpoint]) as remote,
    ):
        app = Completions()
        ids: list[str] = []
        accepted: list[str] = []
        reads: list[float] = []
        completions: list[float] = []
        for i in range(n):
            row.commands += 1
            started = time.monotonic()
            try:
                reply = await remote.execute(
                    command("SetPosition", 1, position=0.01 * (i % 2)), app
                )
            except (TimeoutError, OSError) as exc:
                row.lost += 1
                row.notes.append(f"no reply: {exc}")
                continue
            cid = reply.commands[0].command_id
            ids.append(cid)
            accepted.append(cid)
            with contextlib.suppress(TimeoutError):  # counted as lost below
                await until(lambda: cid in app.seen, 10)  # noqa: B023 - awaited here
            completions.append(time.monotonic() - started)
            started = time.monotonic()
            read = await remote.execute(command("GetPosition", 1))
            reads.append(time.monotonic() - started)
            ids.append(read.commands[0].command_id)
        await anyio.sleep(0.5)  # a late duplicate would arrive by now
        row.lost += sum(1 for c in accepted if len(app.seen.get(c, [])) == 0)
        row.duplicated = gaps(ids) + sum(1 for c in accepted if len(app.seen.get(c, [])) > 1)
        row.missed = app.missed + remote.missed_total
        row.notes.append(
            f"read p50 {ms(statistics.median(reads))}, max {ms(max(reads))}; "
            f"set→completed p50 {ms(statistics.median(completions))}"
        )
        if faults.loss:
            row.notes.append(f"{relay.lost} of {relay.chunks} chunks delayed as lost")
    return row


async def partition(ns: Netns, rig: str, seconds: float) -> Row:
    """A pending motion, the link down, a command sent into the partition, the link up."""
    row = Row(f"partition {seconds:g} s (link down)")
    async with (
        serve_in(ns, rig, [f"tcp/{ns.ip}:{PORT}"]),
        client([f"tcp/{ns.ip}:{PORT}"]) as remote,
        Actuator(RemoteActuator(remote, 0)) as slow,
        Actuator(RemoteActuator(remote, 1)) as other,
    ):
        app = Completions()
        pending = await remote.execute(command("SetPosition", 0, position=2.0), app)
        pending_id = pending.commands[0].command_id
        row.commands = 2
        outcome: list[str] = []

        async def into_the_partition() -> None:
            try:
                await other.set_value(1.0, Request.POSITION)
                outcome.append("accepted")
            except Exception as exc:
                outcome.append(f"{type(exc).__name__} {getattr(exc, 'code', '')!s}")

        healed = math.inf

        async def heal() -> None:
            nonlocal healed
            await anyio.sleep(seconds)
            await ns.link(True)
            healed = time.monotonic()

        await ns.link(False)
        async with anyio.create_task_group() as tg:
            tg.start_soon(into_the_partition)
            tg.start_soon(heal)
            try:
                detected = await until(
                    lambda: slow.state is not ComponentState.ACTIVE, seconds + LEASE_S + 3
                )
                row.detect = ms(detected) + (" (after the heal)" if detected > seconds else "")
            except TimeoutError:
                row.detect = "not detected"
        if slow.state is ComponentState.ERROR or other.state is ComponentState.ERROR:
            await until(lambda: remote.server_alive, 30)
            back = time.monotonic() - healed
            with anyio.fail_after(10):
                await slow.re_init()
                await other.re_init()
            row.recover = f"{ms(back)} (+ re_init {ms(time.monotonic() - healed - back)})"
        await anyio.sleep(1.0)  # a stale command would have been retransmitted by now
        position = await other.get_value(Request.POSITION_ACTUAL)
        statuses = app.seen.get(pending_id, [])
        if len(statuses) != 1:
            row.lost += len(statuses) == 0
            row.duplicated += len(statuses) > 1
        row.notes.append(f"pending motion completed {statuses}")
        row.notes.append(f"command sent into it: {outcome[0] if outcome else '?'}")
        executed = position != 0.0
        row.notes.append(f"executed after the heal: {'yes' if executed else 'no'}")
        if executed and outcome != ["accepted"]:
            row.notes.append("SAFETY: a command the client gave up on was executed")
        row.missed = app.missed + remote.missed_total
    return row


async def restart_elsewhere(first: Netns, second: Netns, rig: str) -> Row:
    row = Row("server killed, restarted on another address")
    endpoints = [f"tcp/{first.ip}:{PORT}", f"tcp/{second.ip}:{PORT}"]
    async with (
        serve_in(first, rig, endpoints[:1]) as process,
        client(endpoints) as remote,
        Actuator(RemoteActuator(remote, 1)) as axis,
    ):
        with anyio.fail_after(10):
            await (await axis.set_value(0.1, Request.POSITION))
        row.commands = 2
        process.kill()
        row.detect = ms(await until(lambda: axis.state is not ComponentState.ACTIVE, 10))
        started = time.monotonic()
        async with serve_in(second, rig, endpoints[1:]):
            serving = time.monotonic() - started
            back = await until(lambda: remote.server_alive, 30)
            with anyio.fail_after(10):
                await axis.re_init()
                await (await axis.set_value(0.2, Request.POSITION))
            row.recover = f"{ms(back)} after it served"
        row.notes.append(f"the new server took {ms(serving)} to start")
    return row


async def main(n: int, rig: str) -> None:
    reason = netns_unavailable()
    if reason is not None:
        print(f"network namespaces unavailable: {reason}", file=sys.stderr)
        raise SystemExit(2)
    rows: list[Row] = []
    async with netns() as ns, netns() as other:
        rows.append(await traffic(ns, rig, Faults(), n))
        for latency in (0.001, 0.01, 0.05):
            rows.append(await traffic(ns, rig, Faults(latency, latency / 2), n))
        for loss in (0.01, 0.1):
            rows.append(await traffic(ns, rig, Faults(loss=loss), n))
        for seconds in (0.5, 2.0, 20.0):
            rows.append(await partition(ns, rig, seconds))
        rows.append(await restart_elsewhere(ns, other, rig))
    print("| fault | detect | recover | commands | lost | duplicated | notices missed | notes |")
    print("|---|---|---|---|---|---|---|---|")
    for row in rows:
        print(row.markdown())


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--commands", type=int, default=50, help="commands per latency/loss")
    args = parser.parse_args()
    configure_logging(level="error")
    with tempfile.TemporaryDirectory() as folder:
        rig_file = Path(folder) / "rig.yaml"
        rig_file.write_text(RIG, encoding="utf-8")
        anyio.run(main, args.commands, str(rig_file))
