"""The simulated Feetech bus of the feetech benchmark, served from its own process.

``python -m benchmarks.feetech_bus N`` starts :class:`openel_serial.feetech_peers.SimFeetechBus`
with STS3215s 1..N (Return Delay (7) 0, as LeRobot sets it; no packet log), prints the tty path
the clients open on one line of stdout, and serves until its stdin is closed (EOF): its CPU
time stays out of the benchmark process, whichever client (ours or scservo_sdk) is measured.
"""

from __future__ import annotations

import subprocess
import sys
from types import TracebackType

import anyio

from openel_serial.feetech_peers import SimFeetechBus, SimStsServo

START_TIMEOUT_S = 20.0


async def serve(servos: int) -> None:
    bus = SimFeetechBus([SimStsServo(i, return_delay=0) for i in range(1, servos + 1)])
    bus.keep_log = False
    async with bus:
        print(bus.path, flush=True)
        await anyio.wait_readable(sys.stdin.fileno())  # EOF (or any byte): the run is done


class FeetechBusProcess:
    """``with FeetechBusProcess(n) as path:`` a simulated bus of ``n`` STS3215s in a child."""

    def __init__(self, servos: int) -> None:
        self.servos = servos
        self._proc: subprocess.Popen[str] | None = None

    def __enter__(self) -> str:
        proc = subprocess.Popen(
            [sys.executable, "-m", "benchmarks.feetech_bus", str(self.servos)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        self._proc = proc
        assert proc.stdout is not None
        line = proc.stdout.readline().strip()  # printed once it serves
        if not line:
            self.__exit__(None, None, None)
            raise RuntimeError(f"simulated Feetech bus process exited with {proc.poll()}")
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


if __name__ == "__main__":
    anyio.run(serve, int(sys.argv[1]), backend="asyncio")
