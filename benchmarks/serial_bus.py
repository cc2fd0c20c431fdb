"""The simulated Dynamixel bus of the serial benchmark, served from its own process.

``python -m benchmarks.serial_bus N`` starts :class:`openel_serial.peers.SimDynamixelBus`
with servos 1..N (Return Delay Time 0, no packet log), prints the tty path the clients
open on one line of stdout, and serves until its stdin is closed (EOF). Running the peer
in another process keeps its CPU time out of the benchmark process, so the
``time.process_time`` of the benchmark process is the client's alone, whichever client
(ours or dynamixel-sdk) is measured.

:func:`serve_bus` and :class:`BusProcess` are the scaffold every simulated-bus child process
shares (:mod:`benchmarks.feetech_bus` too).
"""

from __future__ import annotations

import subprocess
import sys
from types import TracebackType
from typing import Any, ClassVar

import anyio

from openel_serial.buspeer import SimServoBus
from openel_serial.peers import SimDynamixelBus, SimServo

START_TIMEOUT_S = 20.0


async def serve_bus(bus: SimServoBus[Any, Any]) -> None:
    """Serve ``bus`` (no packet log), print its tty path, return at EOF on stdin."""
    bus.keep_log = False
    async with bus:
        print(bus.path, flush=True)
        stdin = sys.stdin.fileno()
        await anyio.wait_readable(stdin)  # EOF (or any byte): the benchmark is done


async def serve(servos: int) -> None:
    await serve_bus(
        SimDynamixelBus([SimServo(i, return_delay_time=0) for i in range(1, servos + 1)])
    )


class BusProcess:
    """``with BusProcess(n) as path:`` a simulated bus of ``n`` servos in a child process
    (``python -m`` :attr:`module` ``n``)."""

    module: ClassVar[str] = "benchmarks.serial_bus"

    def __init__(self, servos: int) -> None:
        self.servos = servos
        self._proc: subprocess.Popen[str] | None = None

    def __enter__(self) -> str:
        proc = subprocess.Popen(
            [sys.executable, "-m", self.module, str(self.servos)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        self._proc = proc
        assert proc.stdout is not None
        line = proc.stdout.readline().strip()  # the child prints its path once it serves
        if not line:
            self.__exit__(None, None, None)
            raise RuntimeError(f"simulated bus process {self.module} exited with {proc.poll()}")
        return line

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        proc, self._proc = self._proc, None
        if proc is None:
            return
        if proc.stdin is not None:
            proc.stdin.close()
        try:
            proc.wait(timeout=START_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        if proc.stdout is not None:
            proc.stdout.close()

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.servos})"


if __name__ == "__main__":
    anyio.run(serve, int(sys.argv[1]), backend="asyncio")
