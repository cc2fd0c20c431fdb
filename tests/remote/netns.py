"""Network namespaces joined by veth pairs, for the fault tests (tests/remote/test_faults.py)
and their measuring script (benchmarks/bench_remote_faults.py).

``async with netns() as ns`` creates a network namespace and a veth pair: one end stays in
the caller's namespace (``ns.host_ip``), the other goes into the new one (``ns.ip``, with
its loopback up). ``ns.run(argv)`` is the argument list that runs a command inside it
(``ip netns exec``); ``await ns.link(False)`` takes the caller's end down -- a partition:
packets are dropped, nothing tells TCP, which retransmits until the link is back -- and
``await ns.link(True)`` heals it. Both are removed on exit, also on failure.

``netns_unavailable()`` says why this machine cannot do it (not root, no ``ip``, no
permission to create a namespace or a veth pair), None when it can; ``require_netns()``
skips a test with that reason (and warns once, so that the run's summary shows it).
"""

from __future__ import annotations

import contextlib
import itertools
import os
import shutil
import subprocess
import sys
import time
import warnings
from collections.abc import AsyncIterator, Callable, Sequence
from contextlib import asynccontextmanager
from dataclasses import dataclass

import anyio
import anyio.abc
import pytest

_counter = itertools.count(1)
IP_TIMEOUT_S = 10.0
"""Longest wait for one ``ip`` command."""


def _ip(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        ["ip", *args], capture_output=True, text=True, timeout=IP_TIMEOUT_S, check=False
    )


_probe: list[str | None] = []


def netns_unavailable() -> str | None:
    """Why network namespaces and veth pairs cannot be used here (None: they can).

    Checked once per process by creating and removing a namespace and a veth pair."""
    if _probe:
        return _probe[0]
    reason: str | None = None
    if shutil.which("ip") is None:
        reason = "the 'ip' command (iproute2) is not installed"
    elif os.geteuid() != 0:
        reason = "creating network namespaces needs root (CAP_NET_ADMIN, CAP_SYS_ADMIN)"
    else:
        name = f"oeprobe{os.getpid() % 100000}"
        made = _ip("netns", "add", name)
        if made.returncode != 0:
            reason = f"'ip netns add' is not permitted here: {made.stderr.strip()}"
        else:
            veth = _ip("link", "add", f"{name}a", "type", "veth", "peer", "name", f"{name}b")
            if veth.returncode != 0:
                reason = f"veth pairs cannot be created here: {veth.stderr.strip()}"
            else:
                _ip("link", "del", f"{name}a")
            _ip("netns", "del", name)
    _probe.append(reason)
    return reason


def require_netns() -> None:
    """Skip the calling test where network namespaces are unavailable, saying why: in the
    skip reason (``pytest -rs``) and, once per run, as a warning, which pytest prints in its
    summary by default."""
    reason = netns_unavailable()
    if reason is None:
        return
    message = f"network namespaces unavailable on this machine, fault tests skipped: {reason}"
    if not _warned:
        _warned.append(True)
        warnings.warn(message, UserWarning, stacklevel=2)
    pytest.skip(message)


_warned: list[bool] = []


@dataclass(frozen=True)
class Netns:
    name: str
    host_dev: str
    """The veth end in the caller's namespace."""
    host_ip: str
    ip: str
    """The address of the other end, inside the namespace."""

    def run(self, argv: Sequence[str]) -> list[str]:
        """``argv`` run inside the namespace."""
        return ["ip", "netns", "exec", self.name, *argv]

    async def link(self, up: bool) -> None:
        """Take the caller's end of the veth pair down (a partition) or up (healed)."""
        await _ip_async("link", "set", self.host_dev, "up" if up else "down")


async def _ip_async(*args: str) -> None:
    with anyio.fail_after(IP_TIMEOUT_S):
        done = await anyio.run_process(["ip", *args], check=False)
    if done.returncode != 0:
        raise OSError(f"ip {' '.join(args)}: {done.stderr.decode(errors='replace').strip()}")


@asynccontextmanager
async def netns() -> AsyncIterator[Netns]:
    """A new network namespace joined to the caller's by a veth pair (/30, 10.213.n.0)."""
    n = next(_counter)
    tag = f"{os.getpid() % 100000}x{n}"
    name, host_dev, ns_dev = f"oe{tag}", f"oe{tag}h", f"oe{tag}n"
    subnet = (os.getpid() * 7 + n) % 250 + 1
    host_ip, ip = f"10.213.{subnet}.1", f"10.213.{subnet}.2"
    await _ip_async("netns", "add", name)
    try:
        await _ip_async("link", "add", host_dev, "type", "veth", "peer", "name", ns_dev)
        await _ip_async("link", "set", ns_dev, "netns", name)
        await _ip_async("addr", "add", f"{host_ip}/30", "dev", host_dev)
        await _ip_async("link", "set", host_dev, "up")
        for args in (
            ("addr", "add", f"{ip}/30", "dev", ns_dev),
            ("link", "set", ns_dev, "up"),
            ("link", "set", "lo", "up"),
        ):
            with anyio.fail_after(IP_TIMEOUT_S):
                await anyio.run_process(["ip", "netns", "exec", name, "ip", *args], check=True)
        yield Netns(name, host_dev, host_ip, ip)
    finally:
        with anyio.CancelScope(shield=True):
            with contextlib.suppress(OSError, subprocess.CalledProcessError):
                await _ip_async("link", "del", host_dev)
            with contextlib.suppress(OSError, subprocess.CalledProcessError):
                await _ip_async("netns", "del", name)


SERVE_READY_S = 30.0
"""Longest wait for ``openel-async serve`` to print its ``serving`` line (imports first)."""


@asynccontextmanager
async def serve_in(
    ns: Netns, rig: str, listen: Sequence[str], *extra: str
) -> AsyncIterator[anyio.abc.Process]:
    """``openel-async serve RIG --listen ...`` inside ``ns`` (``--stop-on-eof``); waits,
    bounded, for its ``serving`` line; stops it on exit (end of input, SIGTERM, SIGKILL)."""
    async with serve_many([(ns, rig, listen, extra)]) as processes:
        yield processes[0]


@asynccontextmanager
async def serve_many(
    servers: Sequence[tuple[Netns, str, Sequence[str], Sequence[str]]],
) -> AsyncIterator[list[anyio.abc.Process]]:
    """Several ``serve_in`` at once: (namespace, rig, listen, extra arguments) each, started
    together and waited for together."""
    processes: list[anyio.abc.Process] = []
    try:
        for ns, rig, listen, extra in servers:
            argv = [sys.executable, "-m", "openel_async.cli", "--log-level", "warning"]
            argv += ["serve", rig, *(a for each in listen for a in ("--listen", each))]
            processes.append(
                await anyio.open_process(
                    ns.run([*argv, "--stop-on-eof", *extra]),
                    stdin=subprocess.PIPE,
                    stdout=subprocess.PIPE,
                    stderr=subprocess.STDOUT,
                    env={**os.environ, "PYTHONUNBUFFERED": "1"},
                )
            )
        with anyio.fail_after(SERVE_READY_S):
            async with anyio.create_task_group() as tg:
                for process in processes:
                    tg.start_soon(_serving, process)
        async with anyio.create_task_group() as tg:
            for process in processes:
                assert process.stdout is not None
                tg.start_soon(_drain, process.stdout)
            yield processes
            tg.cancel_scope.cancel()
    finally:
        with anyio.CancelScope(shield=True):
            for process in processes:
                await _stop(process)


async def _serving(process: anyio.abc.Process) -> None:
    assert process.stdout is not None
    seen = b""
    while b"serving" not in seen:
        try:
            seen += await process.stdout.receive()
        except anyio.EndOfStream:
            raise OSError(f"serve ended before serving: {seen.decode()!r}") from None


async def _stop(process: anyio.abc.Process) -> None:
    if process.stdin is not None:
        with contextlib.suppress(OSError, anyio.BrokenResourceError):
            await process.stdin.aclose()
    with anyio.move_on_after(5):
        await process.wait()
    if process.returncode is None:
        process.kill()
        with anyio.move_on_after(5):
            await process.wait()
    await process.aclose()


async def _drain(stream: anyio.abc.ByteReceiveStream) -> None:
    """Keep reading a child's output (a full pipe would block it)."""
    with contextlib.suppress(anyio.EndOfStream, anyio.ClosedResourceError):
        while True:
            await stream.receive()


async def until(predicate: Callable[[], bool], timeout: float) -> float:  # noqa: ASYNC109
    """Poll ``predicate`` every 5 ms until true (TimeoutError after ``timeout`` s); the
    seconds it took. (States of remote components and presence have no event to wait on.)"""
    started = time.monotonic()
    with anyio.fail_after(timeout):
        while not predicate():  # noqa: ASYNC110 - no event to wait on
            await anyio.sleep(0.005)
    return time.monotonic() - started
