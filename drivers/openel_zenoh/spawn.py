"""A rig served by ``openel-async serve`` in a child process, used through Zenoh.

``async with served(rig_yaml, "demo") as served_rig`` writes the rig file to a temporary
folder, starts ``openel-async serve`` on a free port of 127.0.0.1 (``--stop-on-eof``, in a
session of its own so that the terminal's Ctrl-C reaches only this process), waits (bounded)
for its ``serving`` line and for its liveliness token, and yields the connected
:class:`RemoteSurface`. On exit, also on cancellation (Ctrl-C), the server is stopped:
its stdin is closed (it stops at the end of its input, so it also stops if this process
dies), then SIGTERM, then SIGKILL, each wait bounded.
"""

from __future__ import annotations

import contextlib
import os
import socket
import subprocess
import sys
import tempfile
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass
from pathlib import Path

import anyio
import anyio.abc

from openel_async.logs import get_logger

from .client import RemoteSurface, close_session, open_session
from .config import client_config, endpoint
from .keys import check_chunk

log = get_logger(__name__)

READY_TIMEOUT_S = 30.0
"""Longest wait for the server process to serve (it imports its drivers first)."""
STOP_TIMEOUT_S = 5.0
"""Longest wait at each step of stopping it (end of input, SIGTERM, SIGKILL)."""


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port nobody listens on right now."""
    with socket.socket() as s:
        s.bind((host, 0))
        port: int = s.getsockname()[1]
        return port


@dataclass(frozen=True)
class ServedRig:
    remote: RemoteSurface
    port: int
    pid: int
    ready_line: str
    """The server's ``serving ...`` line."""


class ServeFailed(RuntimeError):
    """The server process ended or stayed silent before serving."""


@asynccontextmanager
async def served(
    rig_yaml: str,
    namespace: str,
    *,
    timeout: float = 2.0,  # noqa: ASYNC109  (the RemoteSurface's query timeout)
    ready_timeout: float = READY_TIMEOUT_S,
) -> AsyncIterator[ServedRig]:
    """``rig_yaml`` (a rig file's text) served by a child process; see the module."""
    check_chunk("namespace", namespace)
    port = free_port()
    with tempfile.TemporaryDirectory(prefix="openel-serve-") as folder:
        rig = Path(folder) / "rig.yaml"
        rig.write_text(rig_yaml, encoding="utf-8")
        process = await anyio.open_process(
            [sys.executable, "-m", "openel_async.cli", "--log-level", "warning", "serve",
             str(rig), "--listen", endpoint(port), "--namespace", namespace, "--stop-on-eof"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
            env={**os.environ, "PYTHONUNBUFFERED": "1"}, start_new_session=True,
        )  # fmt: skip
        log.info("serve_process_started", pid=process.pid, port=port, namespace=namespace)
        try:
            async with anyio.create_task_group() as tg:
                ready: list[str] = []
                seen = anyio.Event()
                tg.start_soon(_read_output, process, ready, seen)
                with anyio.move_on_after(ready_timeout):
                    await seen.wait()
                if not ready or not ready[-1].startswith("serving"):
                    raise ServeFailed(
                        f"openel-async serve did not start within {ready_timeout} s "
                        f"(exit status {process.returncode}): {' | '.join(ready[-5:])}"
                    )
                session = await open_session(client_config([endpoint(port)]))
                try:
                    async with RemoteSurface(session, namespace, timeout=timeout) as remote:
                        await remote.wait_server(ready_timeout)
                        yield ServedRig(remote, port, process.pid, ready[-1])
                finally:
                    with anyio.CancelScope(shield=True):
                        await close_session(session)
                tg.cancel_scope.cancel()
        finally:
            with anyio.CancelScope(shield=True):
                await _stop(process)


async def _read_output(process: anyio.abc.Process, lines: list[str], seen: anyio.Event) -> None:
    """Keep the server's output flowing (a full pipe would block it); its lines are logged.
    ``seen`` is set at its ``serving`` line or at its end."""
    assert process.stdout is not None
    buffer = b""
    try:
        async for chunk in process.stdout:
            buffer += chunk
            while b"\n" in buffer:
                raw, buffer = buffer.split(b"\n", 1)
                line = raw.decode("utf-8", "replace").rstrip()
                lines.append(line)
                del lines[:-20]
                if line.startswith("serving"):
                    seen.set()
                else:
                    log.info("serve_process_output", line=line)
    except (anyio.ClosedResourceError, anyio.BrokenResourceError):
        pass
    seen.set()


async def _stop(process: anyio.abc.Process) -> None:
    if process.stdin is not None:
        with contextlib.suppress(anyio.BrokenResourceError, OSError):
            await process.stdin.aclose()  # --stop-on-eof
    for step in ("eof", "terminate", "kill"):
        if step == "terminate" and process.returncode is None:
            process.terminate()
        elif step == "kill" and process.returncode is None:
            process.kill()
        with anyio.move_on_after(STOP_TIMEOUT_S):
            await process.wait()
        if process.returncode is not None:
            break
    log.info("serve_process_stopped", pid=process.pid, returncode=process.returncode)
    await process.aclose()
