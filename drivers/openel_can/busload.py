"""CAN bus load, computed: how long each frame holds the bus in the worst case, and what share
of the bus a set of periodic frames takes.

A classical (CAN 2.0) data frame of ``n`` data bytes with an 11-bit identifier is
``44 + 8n`` bits from start of frame to end of frame: SOF 1, identifier 11, RTR 1, IDE 1,
r0 1, DLC 4, data ``8n``, CRC 15, CRC delimiter 1, ACK slot and delimiter 2, EOF 7 (a 29-bit
identifier adds 20: SRR, IDE and 18 more identifier bits). The ``34 + 8n`` bits from SOF to
the end of the CRC (``54 + 8n`` extended) are bit-stuffed: after five equal bits the
transmitter inserts one of the other value, and since a stuff bit counts towards the next
run, the worst case is one stuff bit every four bits after the first:
``floor((34 + 8n - 1) / 4)``. The 3-bit intermission follows every frame. So an 8-byte
frame takes at most 135 bit times, a SYNC without counter 55 (Davis, Burns, Bril and
Lukkien, *Controller Area Network (CAN) schedulability analysis: refuted, revisited and
revised*, Real-Time Systems 35, 2007, eq. 1).

A CAN FD frame (ISO 11898-1:2015) is counted with its arbitration phase at the nominal bit
rate (SOF, identifier, RRS, IDE, FDF, res, BRS: 17 bits, stuffed at most every 4 bits, then
CRC delimiter, ACK, EOF and intermission: 13 bits) and its data phase at the data bit rate
(ESI, DLC, the data, the 4-bit stuff count with its parity, the CRC -- 17 bits up to 16 data
bytes, 21 above -- and the fixed stuff bits, one every four bits of the stuff count and CRC;
ESI to the data stuffed at most every 4 bits). Data lengths above 8 round up to the next
FD length (12, 16, 20, 24, 32, 48, 64).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

from openel_async.errors import BadParameterError

__all__ = [
    "FD_LENGTHS",
    "Traffic",
    "bus_load",
    "frame_bits",
    "frame_time",
]

FD_LENGTHS = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)
"""The data lengths a CAN FD frame can carry."""


def _fd_length(payload: int) -> int:
    for length in FD_LENGTHS:
        if length >= payload:
            return length
    raise BadParameterError("payload", payload, "0..64 bytes (CAN FD)")


def frame_bits(payload: int, *, extended: bool = False) -> int:
    """Bit times a classical CAN data frame of ``payload`` bytes holds the bus, worst-case
    stuffing and the intermission included (135 for 8 bytes, 11-bit identifier)."""
    if isinstance(payload, bool) or not isinstance(payload, int) or not 0 <= payload <= 8:
        raise BadParameterError("payload", payload, "0..8 bytes (classical CAN)")
    fixed = (64 if extended else 44) + 8 * payload
    stuffable = (54 if extended else 34) + 8 * payload
    return fixed + (stuffable - 1) // 4 + 3


def frame_time(
    payload: int,
    bitrate: float,
    *,
    extended: bool = False,
    fd: bool = False,
    data_bitrate: float | None = None,
) -> float:
    """Seconds a data frame of ``payload`` bytes holds a bus at ``bitrate`` (worst case).
    With ``fd``, the data phase runs at ``data_bitrate`` (the nominal rate when None: no bit
    rate switch)."""
    if not (math.isfinite(bitrate) and bitrate > 0):
        raise BadParameterError("bitrate", bitrate, "bits per second > 0")
    if not fd:
        return frame_bits(payload, extended=extended) / bitrate
    rate = bitrate if data_bitrate is None else data_bitrate
    if not (math.isfinite(rate) and rate > 0):
        raise BadParameterError("data_bitrate", data_bitrate, "bits per second > 0")
    length = _fd_length(payload)
    arbitration = 17 + (18 if extended else 0)
    nominal = arbitration + (arbitration - 1) // 4 + 13
    crc = 17 if length <= 16 else 21
    dynamic = 1 + 4 + 8 * length  # ESI, DLC, data: dynamically stuffed
    fixed = 4 + crc  # stuff count and parity, CRC: a fixed stuff bit every 4 bits
    data = dynamic + dynamic // 4 + fixed + math.ceil(fixed / 4)
    return nominal / bitrate + data / rate


@dataclass(frozen=True)
class Traffic:
    """Frames of one kind on a bus: ``count`` frames of ``payload`` bytes every
    ``period`` seconds, described by ``what`` (``RPDO1 of node 2``)."""

    what: str
    payload: int
    period: float
    count: int = 1
    extended: bool = False


def bus_load(
    traffic: Iterable[Traffic],
    bitrate: float,
    *,
    fd: bool = False,
    data_bitrate: float | None = None,
) -> float:
    """The share of the bus's time ``traffic`` takes in the worst case (1.0: the bus is
    full; above it, frames queue up without bound)."""
    total = 0.0
    for t in traffic:
        if not (math.isfinite(t.period) and t.period > 0):
            raise BadParameterError(f"{t.what}.period", t.period, "seconds > 0")
        duration = frame_time(
            t.payload, bitrate, extended=t.extended, fd=fd, data_bitrate=data_bitrate
        )
        total += t.count * duration / t.period
    return total
