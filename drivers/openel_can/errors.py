"""Decode errors raised by the pure CAN protocol codecs.

Every ``decode...`` function in :mod:`openel_can` raises only its module's
subclass of :class:`DecodeError` on malformed input, so callers can catch one
exception type per bus and count bad frames without masking programming bugs.
"""

from __future__ import annotations

__all__ = [
    "CanOpenDecodeError",
    "CanSimpleDecodeError",
    "Cia402DecodeError",
    "DecodeError",
]


class DecodeError(ValueError):
    """Bytes received from a CAN bus do not form a valid message."""


class CanSimpleDecodeError(DecodeError):
    """Invalid ODrive CANSimple frame (:mod:`openel_can.cansimple`)."""


class CanOpenDecodeError(DecodeError):
    """Invalid or unsupported CANopen frame (:mod:`openel_can.canopen`)."""


class Cia402DecodeError(DecodeError):
    """Statusword bit pattern that matches no CiA 402 state (:mod:`openel_can.cia402`)."""
