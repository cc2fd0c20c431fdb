"""FeetechPort: one half-duplex Feetech SCS/STS bus, many servos (the STS3215 of an SO-101).

A :class:`~openel_serial.busport.PolledBusPort`, as :class:`~openel_serial.port.DynamixelPort`
is (the lifecycle, transactions, reception, e-stop and poller are the base's; this module
supplies the STS codec, the poll window, the alarms and the host watchdog): every
transaction (an instruction packet and the status packets it asks for) runs under the bus's
FIFO lock; the wait for the statuses is bounded by

    (instruction bytes + expected status bytes) x 10 bits / baud rate
    + number of statuses x return delay + timeout margin

and the missing ones are asked again up to ``retries`` times (a SYNC READ asks only the servos
that did not answer), then :class:`~openel_serial.errors.FeetechTimeoutError` is raised. A
status's error byte holds the servo's alarms (:class:`~openel_serial.feetech.StatusError`),
not a refusal: requests return normally and the poller reports the alarms to the servo.

Polling (the bank): while servos are attached, one task reads Present Position .. Present
Current (addresses 56..70) of all of them with ONE SYNC READ per cycle and hands each servo its
:class:`FeetechPresentState`.

Host watchdog: the STS/SCS have no bus watchdog of their own (nothing in the control table stops
a servo when the host goes silent; their protections -- 19 unloading condition, 34..36
protective/overload torque and time, 13..15 temperature and voltage limits -- are for faults,
not for communication). :meth:`FeetechPort.arm_host_watchdog` starts what the protocol allows
instead: a thread of the port that, when the poller (a task of the event loop) has not completed
a cycle for ``timeout_s``, writes a broadcast WRITE of Torque Enable (40) = 0 straight to the
port's file descriptor, so the servos go limp while the loop is stalled; the servos' components
are told (``ErrorId.WATCHDOG``) when the loop runs again. It cannot help when the host process
dies (kill -9, a crash: the servos hold their last goal with the torque on), when the USB
adapter or the cable is gone, or when the stalled code holds the GIL in C for longer than the
timeout.

E-stop: :meth:`FeetechPort.estop` writes Torque Enable (40) = 0 to every servo at once (a
broadcast WRITE to 0xFE; given ids: a SYNC WRITE), ahead of every queued transaction.

Faults: a vanished port is reported to every attached servo (``ErrorId.DISCONNECTED``);
:meth:`FeetechPort.reconnect` reopens it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from contextlib import AsyncExitStack
from dataclasses import dataclass
from typing import Any, ClassVar, Final, Protocol, Self

from openel_async.clock import Clock
from openel_async.errors import BadParameterError, HALError
from openel_async.logs import get_logger
from openel_serial import feetech as ft
from openel_serial.busport import BusClient, BusStats, PolledBusPort
from openel_serial.errors import FeetechTimeoutError
from openel_serial.feetech_watchdog import TORQUE_OFF_BROADCAST, HostWatchdog

__all__ = [
    "DEFAULT_RETURN_DELAY",
    "POLL_ADDRESS",
    "POLL_LENGTH",
    "SYNC_READ_OVERHEAD",
    "TORQUE_OFF_BROADCAST",
    "FeetechClient",
    "FeetechPingInfo",
    "FeetechPort",
    "FeetechPortStats",
    "FeetechPresentState",
    "HostWatchdog",
]

log = get_logger(__name__)

S = ft.STS
POLL_ADDRESS: Final = S.PRESENT_POSITION.address  # 56
POLL_LENGTH: Final = S.PRESENT_CURRENT.address + S.PRESENT_CURRENT.size - POLL_ADDRESS  # 15
DEFAULT_RETURN_DELAY: Final = 500e-6
"""The STS3215's factory Return Delay (7): 250 x 2 us (LeRobot sets 0)."""
SYNC_READ_OVERHEAD: Final = 8
"""Bytes of a SYNC READ besides its id list: header 2, id, length, instruction, address,
length, checksum."""


@dataclass(frozen=True, slots=True)
class FeetechPingInfo:
    model_number: int
    error: int
    """The PING status's error byte (the servo's alarms)."""


@dataclass(frozen=True, slots=True)
class FeetechPresentState:
    """One poll of one servo: addresses 56..70, decoded (sign-magnitude applied)."""

    transaction: int
    """The port's transaction number of the SYNC READ (later reads have larger ones)."""
    time_ns: int
    position: int
    """Present Position (56), steps."""
    speed: int
    """Present Speed (58), steps/s."""
    load: int
    """Present Load (60), 0.1 % of the stall torque."""
    voltage: int
    """Present Voltage (62), 0.1 V."""
    temperature: int
    """Present Temperature (63), deg C."""
    status: int
    """Servo status (65): the alarm bits in force."""
    moving: bool
    current: int
    """Present Current (69), 6.5 mA."""
    error: int = 0
    """The status packet's error byte."""

    @classmethod
    def decode(cls, params: bytes, transaction: int, time_ns: int, error: int = 0) -> Self:
        def at(item: ft.ControlItem) -> int:
            return item.of(params, POLL_ADDRESS)

        return cls(
            transaction,
            time_ns,
            at(S.PRESENT_POSITION),
            at(S.PRESENT_SPEED),
            at(S.PRESENT_LOAD),
            at(S.PRESENT_VOLTAGE),
            at(S.PRESENT_TEMPERATURE),
            at(S.SERVO_STATUS),
            bool(at(S.MOVING)),
            at(S.PRESENT_CURRENT),
            error,
        )


@dataclass(slots=True)
class FeetechPortStats(BusStats):
    alarms: int = 0
    """Polled statuses with alarm bits set."""
    watchdog_trips: int = 0


class FeetechClient(BusClient, Protocol):
    """What a servo attached to the port implements (see :class:`FeetechServo`)."""

    @property
    def servo_id(self) -> int: ...

    def _poll_update(self, state: FeetechPresentState) -> None: ...


class FeetechPort(PolledBusPort[ft.Status, FeetechClient]):
    """A serial port carrying Feetech SCS/STS servos; ``async with`` opens it.

    ``url``: a device path or pyserial URL (``/dev/ttyACM0`` for the SO-101's Waveshare
    board). ``return_delay`` (s): the servos' Return Delay (7) (factory 500 us). ``poll_period``
    (s) paces the shared poller; 0 polls back to back.
    """

    name: ClassVar[str] = "FeetechPort"
    log_prefix: ClassVar[str] = "feetech"
    id_param: ClassVar[str] = "servo_id"
    max_id: ClassVar[int] = ft.MAX_ID
    status_overhead: ClassVar[int] = ft.STATUS_OVERHEAD
    sync_read_overhead: ClassVar[int] = SYNC_READ_OVERHEAD
    poll_address: ClassVar[int] = POLL_ADDRESS
    poll_length: ClassVar[int] = POLL_LENGTH
    status_type: ClassVar[type[Any]] = ft.Status
    timeout_error = FeetechTimeoutError
    reset_parser_per_request: ClassVar[bool] = True
    estop_broadcasts: ClassVar[bool] = True

    stats: FeetechPortStats
    parser: ft.PacketParser

    def __init__(
        self,
        url: str,
        *,
        baudrate: int = 1_000_000,
        return_delay: float = DEFAULT_RETURN_DELAY,
        timeout_margin: float = 0.02,
        retries: int = 2,
        poll_period: float = 0.01,
        clock: Clock | None = None,
        serial_options: Mapping[str, Any] | None = None,
    ) -> None:
        self.stats = FeetechPortStats()
        self.parser = ft.PacketParser(status=True)
        super().__init__(
            url,
            baudrate=baudrate,
            return_delay=return_delay,
            timeout_margin=timeout_margin,
            retries=retries,
            poll_period=poll_period,
            clock=clock,
            serial_options=serial_options,
        )
        self.watchdog = HostWatchdog(self._link, url)
        self._watchdog_ids: dict[int, float] = {}

    # -- protocol ------------------------------------------------------------------
    def client_id(self, client: FeetechClient) -> int:
        return client.servo_id

    def encode_sync_read(self, address: int, length: int, ids: tuple[int, ...]) -> bytes:
        return ft.encode(ft.SyncRead(address, length, ids))

    def encode_sync_write(self, address: int, length: int, data: Mapping[int, bytes]) -> bytes:
        return ft.encode_sync_write(address, length, data)

    def estop_packet(self, every: bool, listed: Sequence[int]) -> bytes:
        if every:
            return TORQUE_OFF_BROADCAST
        item = S.TORQUE_ENABLE
        return self.encode_sync_write(item.address, item.size, dict.fromkeys(listed, b"\x00"))

    def enter_extras(self, stack: AsyncExitStack) -> None:
        stack.push_async_callback(self.watchdog.stop)

    def detach(self, client: FeetechClient) -> None:
        super().detach(client)
        self.disarm_host_watchdog(client.servo_id)

    # -- host watchdog -------------------------------------------------------------
    def arm_host_watchdog(self, servo_id: int, timeout_s: float) -> None:
        """Count servo ``servo_id`` in the host watchdog with ``timeout_s`` (the shortest of
        the armed servos' applies to the port); refused (:class:`BadParameterError` naming
        ``timeout_s``) unless ``poll_period`` is below half of it."""
        if not (math.isfinite(timeout_s) and self.poll_period < timeout_s / 2):
            raise BadParameterError(
                "timeout_s",
                timeout_s,
                f"a finite number of seconds above twice the poll_period of {self.url} "
                f"({self.poll_period} s): the poller feeds the host watchdog",
            )
        self._watchdog_ids[servo_id] = float(timeout_s)
        self.watchdog.arm(min(self._watchdog_ids.values()))
        self.wake_poller()

    def disarm_host_watchdog(self, servo_id: int) -> None:
        self._watchdog_ids.pop(servo_id, None)
        if self._watchdog_ids:
            self.watchdog.arm(min(self._watchdog_ids.values()))
        else:
            self.watchdog.disarm()

    @property
    def host_watchdogs(self) -> Mapping[int, float]:
        return dict(self._watchdog_ids)

    def poll_loop_tick(self) -> None:
        """Report a trip of the host watchdog; feed it (the event loop runs)."""
        silent = self.watchdog.take_trip()
        if silent is not None:
            self.stats.watchdog_trips += 1
            reason = (
                f"{self.url}: host watchdog: no poll for {silent:.3f} s (> "
                f"{self.watchdog.timeout} s): every servo's torque was turned off"
            )
            self._log.warning("feetech_host_watchdog_tripped", silent_s=silent)
            for servo_id in list(self._watchdog_ids):
                client = self._clients.get(servo_id)
                if client is not None:
                    client._watchdog_tripped(reason)
        if self._link.is_open:
            self.watchdog.feed()

    def idle_timeout(self) -> float | None:
        """Idle but armed: wake up to feed the host watchdog (the loop is alive)."""
        timeout = self.watchdog.timeout
        return None if timeout is None else timeout / 4

    def poll_done(self) -> None:
        self.watchdog.feed()

    # -- requests ------------------------------------------------------------------
    async def ping(self, servo_id: int) -> FeetechPingInfo:
        """PING, then Model Number (3) as the vendor's SDK does."""
        status = await self._unicast(ft.encode(ft.Ping(servo_id)), servo_id, "PING", 0)
        model = await self.read_item(servo_id, S.MODEL_NUMBER)
        return FeetechPingInfo(model, status.error)

    async def read(self, servo_id: int, address: int, length: int) -> bytes:
        packet = ft.encode(ft.Read(servo_id, address, length))
        status = await self._unicast(packet, servo_id, f"READ {address}+{length}", length)
        return status.params

    async def read_item(self, servo_id: int, item: ft.ControlItem) -> int:
        return item.decode(await self.read(servo_id, item.address, item.size))

    async def write(self, servo_id: int, address: int, data: bytes, *, ack: bool = True) -> int:
        """WRITE ``data`` at ``address``; returns the status's error byte (0 without ``ack``:
        Response Status Level 0, or broadcast)."""
        packet = ft.encode(ft.Write(servo_id, address, bytes(data)))
        if not ack or servo_id == ft.BROADCAST_ID:
            await self.send_only(packet)
            return 0
        status = await self._unicast(packet, servo_id, f"WRITE {address}+{len(data)}", 0)
        return status.error

    async def write_item(
        self, servo_id: int, item: ft.ControlItem, value: int, *, ack: bool = True
    ) -> int:
        return await self.write(servo_id, item.address, item.encode(value), ack=ack)

    async def write_eeprom(
        self, servo_id: int, writes: Sequence[tuple[ft.ControlItem, int]], *, ack: bool = True
    ) -> None:
        """EEPROM writes kept at power-off: Lock (55) = 0, the writes, Lock = 1, then each
        read back (HALError naming the register if the servo kept another value). The torque
        should be off (the vendor's tools do so)."""
        await self.write_item(servo_id, S.LOCK, 0, ack=ack)
        try:
            for item, value in writes:
                await self.write_item(servo_id, item, value, ack=ack)
        finally:
            await self.write_item(servo_id, S.LOCK, 1, ack=ack)
        for item, value in writes:
            got = await self.read_item(servo_id, item)
            if got != value:
                raise HALError(
                    f"servo {servo_id}: register {item.address} reads {got} after writing {value}"
                )

    async def sync_read(self, ids: Sequence[int], address: int, length: int) -> dict[int, bytes]:
        """SYNC READ: ``{id: data}`` for every id, or :class:`FeetechTimeoutError`."""
        ids, statuses = await self.sync_read_all(ids, address, length)
        return {i: statuses[i].params for i in ids}

    async def _unicast(
        self, packet: bytes, servo_id: int, what: str, param_length: int
    ) -> ft.Status:
        if not 0 <= servo_id <= ft.MAX_ID:
            raise BadParameterError("servo_id", servo_id, f"a servo id in 0..{ft.MAX_ID}")
        return await self.unicast(packet, servo_id, what, param_length)

    # -- poller (the bank) -----------------------------------------------------------
    def deliver(
        self,
        client: FeetechClient,
        status: ft.Status,
        transaction: int,
        now_ns: int,
        later: list[Any],
    ) -> None:
        if status.error:
            self.stats.alarms += 1
        client._poll_update(
            FeetechPresentState.decode(status.params, transaction, now_ns, status.error)
        )
