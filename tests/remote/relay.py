"""A fault-injecting TCP relay, for the fault tests (tests/remote/test_faults.py) and their
measuring script (benchmarks/bench_remote_faults.py), where the kernel has no netem qdisc.

``async with Relay(host, port) as relay`` listens on a free port of 127.0.0.1 and forwards
every connection made to it to ``host:port``, byte for byte, in both directions. What it
does to the traffic (``relay.faults``, changeable at any time, applied to each chunk read
from a socket, in both directions):

- ``latency`` (s): each chunk is delivered that much later (one way: a round trip gets
  twice); ``jitter`` (s): plus a uniform random delay in [0, jitter]. Order is kept, as
  TCP keeps it: a chunk never overtakes the one before it.
- ``loss`` (a probability): Zenoh runs over TCP, where a lost segment is not lost but
  retransmitted after the retransmission timeout (Linux: at least 200 ms) while the
  segments behind it wait (head-of-line blocking). So a "lost" chunk is delivered ``rto``
  (0.2 s) late, and everything behind it waits for it. Nothing is ever dropped, duplicated
  or reordered: that is what loss looks like to a TCP application.
- ``hold()`` / ``release()``: a partition inside the relay -- nothing is forwarded until
  released, then everything held is delivered (TCP retransmitting after a short
  partition). ``cut()`` closes every connection (a partition long enough for TCP or
  Zenoh's lease to give up; Zenoh reconnects through the relay).

Counters: ``chunks``, ``lost`` (chunks delayed as lost), ``bytes``, ``connections``.
"""

from __future__ import annotations

import contextlib
import math
import random
from dataclasses import dataclass
from types import TracebackType
from typing import Self

import anyio
import anyio.abc
from anyio.streams.memory import MemoryObjectReceiveStream, MemoryObjectSendStream

CHUNK = 65536
BUFFERED_CHUNKS = 4096
"""Chunks one direction may have in flight in the relay before its reader waits."""


@dataclass
class Faults:
    latency: float = 0.0
    jitter: float = 0.0
    loss: float = 0.0
    rto: float = 0.2


class Relay:
    """See the module doc."""

    def __init__(
        self, host: str, port: int, faults: Faults | None = None, *, seed: int = 26
    ) -> None:
        self.host = host
        self.upstream_port = port
        self.faults = faults or Faults()
        self.random = random.Random(seed)
        self.port = 0
        self.chunks = 0
        self.lost = 0
        self.bytes = 0
        self.connections = 0
        self._held = False
        self._released = anyio.Event()
        self._scopes: set[anyio.CancelScope] = set()
        self._tg: anyio.abc.TaskGroup | None = None

    @property
    def endpoint(self) -> str:
        return f"tcp/127.0.0.1:{self.port}"

    async def __aenter__(self) -> Self:
        listener = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=0)
        self.port = listener.extra(anyio.abc.SocketAttribute.local_port)
        tg = anyio.create_task_group()
        await tg.__aenter__()
        self._tg = tg
        tg.start_soon(listener.serve, self._connection)
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        assert self._tg is not None
        self._tg.cancel_scope.cancel()
        await self._tg.__aexit__(None, None, None)
        self._tg = None

    def hold(self) -> None:
        """Forward nothing until ``release()`` (what arrives meanwhile is kept)."""
        self._held = True

    def release(self) -> None:
        self._held = False
        self._released.set()
        self._released = anyio.Event()

    def cut(self) -> None:
        """Close every connection now (new ones are still accepted)."""
        for scope in tuple(self._scopes):
            scope.cancel()

    async def _connection(self, downstream: anyio.abc.SocketStream) -> None:
        self.connections += 1
        async with downstream:
            try:
                upstream = await anyio.connect_tcp(self.host, self.upstream_port)
            except OSError:
                return
            async with upstream, anyio.create_task_group() as tg:
                self._scopes.add(tg.cancel_scope)
                try:
                    for source, sink in ((downstream, upstream), (upstream, downstream)):
                        send, receive = anyio.create_memory_object_stream[tuple[float, bytes]](
                            BUFFERED_CHUNKS
                        )
                        tg.start_soon(self._read, source, send, tg.cancel_scope)
                        tg.start_soon(self._write, receive, sink, tg.cancel_scope)
                    await anyio.sleep(math.inf)
                finally:
                    self._scopes.discard(tg.cancel_scope)

    async def _read(
        self,
        source: anyio.abc.SocketStream,
        out: MemoryObjectSendStream[tuple[float, bytes]],
        scope: anyio.CancelScope,
    ) -> None:
        last = 0.0
        async with out:
            try:
                while True:
                    data = await source.receive(CHUNK)
                    f = self.faults
                    delay = f.latency + (self.random.uniform(0.0, f.jitter) if f.jitter else 0.0)
                    if f.loss and self.random.random() < f.loss:
                        self.lost += 1
                        delay += f.rto
                    last = max(last, anyio.current_time() + delay)
                    self.chunks += 1
                    self.bytes += len(data)
                    await out.send((last, data))
            except (anyio.EndOfStream, anyio.BrokenResourceError, OSError):
                pass
        # the other direction's queue may still hold data: the writer ends the connection

    async def _write(
        self,
        queue: MemoryObjectReceiveStream[tuple[float, bytes]],
        sink: anyio.abc.SocketStream,
        scope: anyio.CancelScope,
    ) -> None:
        async with queue:
            with contextlib.suppress(anyio.BrokenResourceError, anyio.ClosedResourceError, OSError):
                async for at, data in queue:
                    await anyio.sleep_until(at)
                    while self._held:
                        await self._released.wait()
                    await sink.send(data)
        scope.cancel()  # one direction ended: so does the connection
