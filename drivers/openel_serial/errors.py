"""Decode errors raised by the pure serial protocol codecs.

Every ``decode...`` function in :mod:`openel_serial` raises only its module's
subclass of :class:`DecodeError` on malformed input; the streaming parsers
never raise on garbage and count it instead.
"""

from __future__ import annotations

__all__ = [
    "DecodeError",
    "DynamixelCrcError",
    "DynamixelDecodeError",
    "NmeaChecksumError",
    "NmeaDecodeError",
]


class DecodeError(ValueError):
    """Bytes received from a serial link do not form a valid message."""


class DynamixelDecodeError(DecodeError):
    """Invalid Dynamixel Protocol 2.0 packet (:mod:`openel_serial.dynamixel`)."""


class DynamixelCrcError(DynamixelDecodeError):
    """Dynamixel packet whose CRC-16 does not match its contents."""


class NmeaDecodeError(DecodeError):
    """Invalid NMEA 0183 sentence (:mod:`openel_serial.nmea`)."""


class NmeaChecksumError(NmeaDecodeError):
    """NMEA sentence whose ``*hh`` checksum does not match its contents."""
