"""Finding what is on a serial port before writing a rig (``openel-async scan serial``).

- Dynamixel Protocol 2.0 and Feetech STS servos: at each baud rate asked for, a PING of every
  id asked for (each bounded by the port's status timeout, no retry; on a Dynamixel bus one
  broadcast PING when that is quicker, every servo answering in turn), through the driver's own
  ports (:class:`~openel_serial.port.DynamixelPort`, :class:`~openel_serial.feetech_port.FeetechPort`),
  so the bytes on the wire are the driver's. A servo answers only at its own baud rate; the
  model number comes with the PING's status (Dynamixel) or from Model Number (3) (Feetech,
  as the vendor's SDK reads it).
- NMEA 0183 receivers: at each baud rate, the port is listened to for ``listen`` seconds and
  the checksummed sentences counted (:class:`~openel_serial.nmea.NmeaParser`); a receiver is
  found at the rate where whole sentences come.
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any, Final, Literal

import anyio

from . import feetech as ft
from .errors import PortDisconnectedError, ServoTimeoutError
from .link import SerialLink
from .nmea import NmeaParser, Sentence
from .rigbus import FEETECH_MODELS, SERVO_MODELS

__all__ = [
    "DEFAULT_BAUDRATES",
    "FoundReceiver",
    "FoundServo",
    "Protocol",
    "SerialScan",
    "parse_ids",
    "scan_nmea",
    "scan_servos",
]

Protocol = Literal["dynamixel", "feetech", "nmea"]

DEFAULT_BAUDRATES: Final[Mapping[str, tuple[int, ...]]] = {
    "dynamixel": (57_600, 1_000_000),  # the X series' factory rate, and the usual fast one
    "feetech": (1_000_000,),  # the STS3215's factory rate (and the SO-101's)
    "nmea": (9600, 4800, 38_400, 115_200),
}
"""The rates tried when none are given (``--baud all``: every rate of the protocol)."""

MODEL_NAMES: Final[Mapping[tuple[str, int], str]] = {
    ("dynamixel", 1020): "XM430-W350",
    ("dynamixel", 1060): "XL430-W250",
    ("feetech", ft.STS3215_MODEL): "STS3215",
}
"""The models the driver has classes for (another model is shown by its number)."""


@dataclass(frozen=True, slots=True)
class FoundServo:
    protocol: Literal["dynamixel", "feetech"]
    baudrate: int
    servo_id: int
    model_number: int
    model: str | None
    """The model's name where the number is known."""
    device: str | None
    """The driver's device class for it (``rig-out`` names it), where one fits."""
    firmware: int | None
    """Dynamixel's firmware version (the PING status); None for Feetech."""
    error: int
    """The status error byte (Dynamixel bit 7: a hardware alert; Feetech: its alarm bits)."""


@dataclass(frozen=True, slots=True)
class FoundReceiver:
    baudrate: int
    sentences: int
    """Checksummed sentences decoded in the listening time."""
    kinds: tuple[str, ...]
    """Their addresses, first seen first (``GPGGA``, ``GNRMC``...)."""
    checksum_errors: int


@dataclass
class SerialScan:
    """What a scan of one port found."""

    port: str
    protocol: Protocol
    baudrates: tuple[int, ...]
    servos: list[FoundServo] = field(default_factory=list)
    receivers: list[FoundReceiver] = field(default_factory=list)
    seconds: float = 0.0

    @property
    def found(self) -> bool:
        return bool(self.servos or self.receivers)

    def to_dict(self) -> dict[str, Any]:
        return {
            "port": self.port,
            "protocol": self.protocol,
            "baudrates": list(self.baudrates),
            "servos": [asdict(s) for s in self.servos],
            "receivers": [asdict(r) | {"kinds": list(r.kinds)} for r in self.receivers],
            "seconds": round(self.seconds, 3),
        }


def parse_ids(text: str, max_id: int) -> tuple[int, ...]:
    """``"1-6,10"`` -> (1, 2, 3, 4, 5, 6, 10); ValueError naming what is wrong."""
    ids: set[int] = set()
    for part in text.split(","):
        low, dash, high = part.strip().partition("-")
        try:
            first = int(low)
            last = int(high) if dash else first
        except ValueError:
            raise ValueError(f"{part.strip()!r} is not an id or a range of ids (1-6)") from None
        if not 0 <= first <= last <= max_id:
            raise ValueError(f"{part.strip()!r}: ids are 0..{max_id}, low-high")
        ids.update(range(first, last + 1))
    return tuple(sorted(ids))


def _device_for(protocol: str, model_number: int) -> str | None:
    models = SERVO_MODELS if protocol == "dynamixel" else FEETECH_MODELS
    # the most specific class of that model (the generic one names no model)
    named = [name for name, number in models.items() if number == model_number and "_" in name]
    return named[0] if named else None


async def scan_servos(
    url: str,
    protocol: Literal["dynamixel", "feetech"],
    baudrates: Sequence[int],
    ids: Iterable[int],
    *,
    timeout_margin: float = 0.005,
    serial_options: Mapping[str, Any] | None = None,
) -> list[FoundServo]:
    """PING ``ids`` at each of ``baudrates``: the servos that answer. Each PING waits the
    status's own time plus ``timeout_margin`` s, once (a scan must not retry 253 times)."""
    from .feetech_port import FeetechPort
    from .port import DynamixelPort

    port_class = DynamixelPort if protocol == "dynamixel" else FeetechPort
    wanted = tuple(ids)
    found: list[FoundServo] = []
    for baudrate in baudrates:
        async with port_class(
            url,
            baudrate=baudrate,
            timeout_margin=timeout_margin,
            retries=0,
            serial_options=serial_options,
        ) as port:
            for servo_id, info in (await _ping_each(port, wanted)).items():
                model = info.model_number
                found.append(
                    FoundServo(
                        protocol,
                        baudrate,
                        servo_id,
                        model,
                        MODEL_NAMES.get((protocol, model)),
                        _device_for(protocol, model),
                        getattr(info, "firmware_version", None),  # Dynamixel's PING has it
                        info.error,
                    )
                )
    return found


async def _ping_each(port: Any, wanted: Sequence[int]) -> dict[int, Any]:
    """What each id of ``wanted`` answers to a PING: by one broadcast PING on a Dynamixel
    bus when that takes less time than PINGs one id at a time (a long id list: the
    broadcast waits for every id's turn, ~0.77 s), else id by id."""
    from .port import PING_PACKET, DynamixelPort

    if isinstance(port, DynamixelPort):
        one_by_one = len(wanted) * port.response_timeout(PING_PACKET, 1, 3)
        if port.broadcast_ping_window() < one_by_one:
            found = await port.broadcast_ping()
            return {i: found[i] for i in wanted if i in found}
    answers = {}
    for servo_id in wanted:
        try:
            answers[servo_id] = await port.ping(servo_id)
        except ServoTimeoutError:
            continue
    return answers


async def scan_nmea(
    url: str,
    baudrates: Sequence[int],
    *,
    listen: float = 1.5,
    serial_options: Mapping[str, Any] | None = None,
) -> list[FoundReceiver]:
    """Listen ``listen`` s at each of ``baudrates``: the rates at which whole, checksummed
    NMEA sentences come (at a wrong rate only garbage does)."""
    found: list[FoundReceiver] = []
    for baudrate in baudrates:
        parser = NmeaParser()
        kinds: dict[str, None] = {}
        count = 0

        def on_data(
            data: bytes, parser: NmeaParser = parser, kinds: dict[str, None] = kinds
        ) -> None:
            nonlocal count
            for sentence in parser.feed(data):
                count += 1
                kinds.setdefault(_address(sentence), None)

        lost: list[str] = []
        link = SerialLink(
            url,
            baudrate=baudrate,
            on_data=on_data,
            on_lost=lost.append,
            serial_options=serial_options,
        )
        await link.open()
        try:
            await anyio.sleep(listen)
        finally:
            await link.close()
        if lost:
            raise PortDisconnectedError(url, lost[0])
        if count:
            found.append(FoundReceiver(baudrate, count, tuple(kinds), parser.checksum_errors))
    return found


def _address(sentence: Sentence) -> str:
    """``GPGGA``, ``GNRMC``, ``PUBX``...: the talker and the sentence type."""
    kind = getattr(sentence, "sentence_type", None) or type(sentence).__name__
    return f"{sentence.talker}{kind}"


async def scan(
    url: str,
    protocol: Protocol,
    baudrates: Sequence[int],
    ids: Iterable[int] = (),
    *,
    timeout_margin: float = 0.005,
    listen: float = 1.5,
    serial_options: Mapping[str, Any] | None = None,
) -> SerialScan:
    """Scan one port for one protocol."""
    started = time.monotonic()
    result = SerialScan(url, protocol, tuple(baudrates))
    if protocol == "nmea":
        result.receivers = await scan_nmea(
            url, baudrates, listen=listen, serial_options=serial_options
        )
    else:
        result.servos = await scan_servos(
            url,
            protocol,
            baudrates,
            ids,
            timeout_margin=timeout_margin,
            serial_options=serial_options,
        )
    result.seconds = time.monotonic() - started
    return result
