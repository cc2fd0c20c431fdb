"""The simulated Feetech bus of the feetech benchmark, served from its own process.

``python -m benchmarks.feetech_bus N`` starts :class:`openel_serial.feetech_peers.SimFeetechBus`
with STS3215s 1..N (Return Delay (7) 0, as LeRobot sets it; no packet log), prints the tty path
the clients open on one line of stdout, and serves until its stdin is closed (EOF): its CPU
time stays out of the benchmark process, whichever client (ours or scservo_sdk) is measured.
The child-process scaffold is :mod:`benchmarks.serial_bus`'s.
"""

from __future__ import annotations

import sys
from typing import ClassVar

import anyio

from openel_serial.feetech_peers import SimFeetechBus, SimStsServo

from .serial_bus import BusProcess, serve_bus


async def serve(servos: int) -> None:
    await serve_bus(SimFeetechBus([SimStsServo(i, return_delay=0) for i in range(1, servos + 1)]))


class FeetechBusProcess(BusProcess):
    """``with FeetechBusProcess(n) as path:`` a simulated bus of ``n`` STS3215s in a child."""

    module: ClassVar[str] = "benchmarks.feetech_bus"


if __name__ == "__main__":
    anyio.run(serve, int(sys.argv[1]), backend="asyncio")
