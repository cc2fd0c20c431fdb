"""SimServoBus: what the simulated servo buses on a pty share (every protocol's).

A simulated bus (:class:`~openel_serial.peers.SimDynamixelBus`,
:class:`~openel_serial.feetech_peers.SimFeetechBus`) reads the driver's instruction packets
from its pty (:class:`~openel_serial.ptypeer.PtyPeer`), keeps what it received
(``received``, ``instructions`` while ``keep_log``), and sends the servos' statuses to one
instruction together after their return delays (:meth:`SimServoBus.send_replies`), with the
faults a test may ask for: replies dropped (``drop_replies``) or sent with a damaged last byte
(``corrupt_replies``), servos deaf to a tty set to another bit rate (``check_baudrate``).

A protocol subclass supplies its parser (:meth:`SimServoBus.new_parser`), what it does with
one decoded packet (:meth:`SimServoBus.receive`), how a status is encoded and a servo's return
delay.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, ClassVar, Generic, Protocol, TypeVar

import anyio

from openel_async.clock import Clock
from openel_serial.ptypeer import PtyPeer

__all__ = ["SimBusServo", "SimServoBus"]


class SimBusServo(Protocol):
    """What the bus asks of a simulated servo."""

    @property
    def baudrate(self) -> int: ...

    @property
    def table(self) -> bytearray: ...


class _Parser(Protocol):
    def feed_all(self, data: bytes) -> Sequence[Any]: ...


ServoT = TypeVar("ServoT", bound=SimBusServo)
MsgT = TypeVar("MsgT")


class SimServoBus(PtyPeer, Generic[ServoT, MsgT]):
    """A servo bus behind a pty (see the module docstring)."""

    return_delay_address: ClassVar[int] = 0
    """The control-table address of a servo's return delay setting."""
    return_delay_unit_s: ClassVar[float] = 2e-6

    def __init__(
        self, *, path: str | Path | None, clock: Clock | None, check_baudrate: bool
    ) -> None:
        super().__init__(path, clock)
        self.check_baudrate = check_baudrate
        self.baud_mismatches = 0
        """Packets a servo did not hear: the driver's tty was at another bit rate."""
        self._tty_rate: int | None = None
        self.parser: Any = self.new_parser()
        self.received = bytearray()
        self.instructions: list[MsgT] = []
        self.keep_log = True
        self.drop_replies = 0
        """Instructions whose replies are dropped (lost on the wire)."""
        self.corrupt_replies = 0
        """Replies sent with a damaged last byte (CRC or checksum)."""
        self.corrupt_instructions = 0
        """Packets from the driver that failed their CRC or checksum."""
        self.replies = 0

    # -- protocol (subclasses) -----------------------------------------------------
    def new_parser(self) -> Any:
        """A parser of the driver's instruction packets (``feed_all``)."""
        raise NotImplementedError

    async def receive(self, msg: Any) -> None:
        """Handle one decoded packet (or corrupt packet) from the driver."""
        raise NotImplementedError

    def encode_status(self, status: Any) -> bytes:
        raise NotImplementedError

    # -- serving -------------------------------------------------------------------
    def inject_garbage(self, data: bytes) -> None:
        """Send noise to the driver now (a glitch on the line)."""
        self.pty.write_nowait(data)

    def log_instruction(self, msg: MsgT) -> None:
        if self.keep_log:
            self.instructions.append(msg)

    async def _serve(self) -> None:
        parser = self.new_parser()
        self.parser = parser
        while True:
            data = await self.pty.read()
            if self.keep_log:
                self.received += data
            if self.check_baudrate:
                self._tty_rate = self.pty.baudrate()
            for msg in parser.feed_all(data):
                await self.receive(msg)

    async def send_replies(
        self, order: Sequence[ServoT], handle: Callable[[ServoT], object | None]
    ) -> None:
        """Let each servo of ``order`` (that hears the driver) handle the packet; send the
        statuses together after the sum of their return delays."""
        if self.check_baudrate:
            heard = [s for s in order if s.baudrate == self._tty_rate]
            self.baud_mismatches += len(order) - len(heard)
            order = heard
        replies: list[bytes] = []
        delay_units = 0
        for servo in order:
            status = handle(servo)
            if status is not None:
                replies.append(self.encode_status(status))
                delay_units += servo.table[self.return_delay_address]
        if not replies:
            return
        if self.drop_replies:
            self.drop_replies -= 1
            return
        if self.corrupt_replies:
            self.corrupt_replies -= 1
            last = bytearray(replies[-1])
            last[-1] ^= 0xFF
            replies[-1] = bytes(last)
        if delay_units:
            await anyio.sleep(delay_units * self.return_delay_unit_s)
        self.replies += len(replies)
        await self.pty.write(b"".join(replies))
