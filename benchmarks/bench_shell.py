"""``openel-async set --wait`` against ``openel-async hal4rt exec``, measured in the same run.

The two-axis rig is served by ``openel-async serve`` in a child process on loopback
(``openel_zenoh.spawn.served``); this process is the client. Every round runs the cases
one after the other (interleaved, so load changes on the machine hit both alike); each
figure is the median over the rounds of each round's median.

- ``set --wait`` round trip: what the command does once it found its component, in this
  process: one SetPosition (compact encoding) and the wait for its ``completed`` notice
  (``RigShell.command(..., wait=...)``). The target is the axis's position, so the motion
  ends when it is accepted and the figure is the messages' time, not the motion's.
- ``hal4rt exec`` round trip: what ``hal4rt exec`` does once connected: the same
  SetPosition as an XML ``<Device>`` message and its reply (``RemoteSurface(encoding="xml")``).
  Target: ``set --wait`` <= 1.5x this.
- Unless ``--quick``: both commands as processes (``openel-async set MOTOR_1 0 --wait`` and
  ``openel-async hal4rt exec FILE.xml``), wall time from start to exit: the interpreter's
  start and imports, the session, the discovery of the namespace (set) and the message.
"""

from __future__ import annotations

import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import anyio

from .harness import REPO_ROOT, BenchResult, Row, quiet_logging, ratio_of

RIG = REPO_ROOT / "apps" / "openel_apps" / "rigs" / "twoaxis-sim.yaml"
NAMESPACE = "twoaxis"
XML = """<?xml version="1.0" encoding="utf-8"?>
<Device><device_kind>Motor</device_kind><CommandMessage><function_name>SetPosition</function_name>
<command_id></command_id><arguments>
<parameters><data_type_id>1</data_type_id><name>logical_id</name><value>0</value></parameters>
<parameters><data_type_id>2</data_type_id><name>position</name><value>0.0</value></parameters>
</arguments></CommandMessage></Device>
"""


async def _measure(rounds: int, calls: int, processes: int) -> dict[str, list[float]]:
    from openel_async.surface import xml_psm
    from openel_zenoh import RemoteSurface
    from openel_zenoh.config import client_config, endpoint
    from openel_zenoh.shell import RigShell
    from openel_zenoh.spawn import served

    device = xml_psm.device_from_xml(XML.encode())
    out: dict[str, list[float]] = {"set": [], "exec": [], "set_process": [], "exec_process": []}
    async with served(RIG.read_text(encoding="utf-8"), NAMESPACE, timeout=5.0) as rig:
        config = client_config([endpoint(rig.port)])
        async with (
            RigShell(config, namespace=NAMESPACE, timeout=5.0) as shell,
            RemoteSurface(rig.remote.session, NAMESPACE, timeout=5.0, encoding="xml") as xml,
        ):
            target = await shell.target("MOTOR_1")
            await xml.wait_server(5.0)

            async def set_wait() -> None:
                _, status = await shell.command(target, "SetPosition", {"position": 0.0}, wait=5.0)
                assert status == 0, status

            async def hal4rt_exec() -> None:
                reply = await xml.execute(device)
                results = reply.commands[0].results
                assert results is not None and results.value("return_code") == 0

            cases = {"set": set_wait, "exec": hal4rt_exec}
            for case in cases.values():  # warm-up
                for _ in range(3):
                    await case()
            for _ in range(rounds):
                for name, case in cases.items():
                    times = []
                    for _ in range(calls):
                        start = time.perf_counter()
                        await case()
                        times.append(time.perf_counter() - start)
                    out[name].append(statistics.median(times))
        if processes:
            await _processes(rig.port, processes, out)
    return out


async def _processes(port: int, rounds: int, out: dict[str, list[float]]) -> None:
    from openel_zenoh.config import endpoint

    cli = [sys.executable, "-m", "openel_async.cli", "--log-level", "warning"]
    where = ["--connect", endpoint(port), "--namespace", NAMESPACE, "--timeout", "10"]
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    with tempfile.TemporaryDirectory(prefix="bench-shell-") as folder:
        message = Path(folder) / "set_position.xml"
        message.write_text(XML, encoding="utf-8")
        commands = {
            "set_process": [*cli, "set", "MOTOR_1", "0", "--wait", *where],
            "exec_process": [*cli, "hal4rt", "exec", str(message), *where],
        }
        for _ in range(rounds):
            for name, argv in commands.items():
                start = time.perf_counter()
                with anyio.fail_after(60):
                    done = await anyio.run_process(argv, check=False, env=env)
                out[name].append(time.perf_counter() - start)
                if done.returncode != 0:
                    raise RuntimeError(f"{' '.join(argv)}: exit {done.returncode}: {done.stderr!r}")


def run(quick: bool) -> BenchResult:
    quiet_logging()
    rounds, calls, processes = (5, 10, 0) if quick else (7, 30, 5)
    figures = anyio.run(_measure, rounds, calls, processes)
    us = 1e6
    shell_rtt = statistics.median(figures["set"])
    exec_rtt = statistics.median(figures["exec"])
    ratio = ratio_of(shell_rtt, exec_rtt)
    rows = [
        Row(
            "set --wait round trip (SetPosition + completed), median",
            shell_rtt * us,
            "us",
            exec_rtt * us,
            "hal4rt exec message round trip (XML)",
            ratio,
            "set/exec",
            "<= 1.5",
            ratio <= 1.5,
        )
    ]
    if figures["set_process"]:
        set_process = statistics.median(figures["set_process"])
        exec_process = statistics.median(figures["exec_process"])
        rows.append(
            Row(
                "openel-async set --wait, whole process, median",
                set_process * 1e3,
                "ms",
                exec_process * 1e3,
                "openel-async hal4rt exec, whole process",
                ratio_of(set_process, exec_process),
                "set/exec",
            )
        )
    return BenchResult(
        name="shell",
        title="openel-async set --wait vs hal4rt exec",
        rows=tuple(rows),
        description=(__doc__ or "").split("\n\n", 1)[1].strip(),
        params={
            "rounds": str(rounds),
            "calls per round": str(calls),
            "process rounds": str(processes),
        },
        quick=quick,
    )
