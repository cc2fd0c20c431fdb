"""Emergency error codes in words: the CiA 301 classes (the code's high byte, then its high
nibble) and the codes CiA 301 and CiA 402 (IEC 61800-7-201) define one by one.

>>> describe_emcy(0x8611)
'0x8611 following error (monitoring: control)'
>>> describe_emcy(0x2345)
'0x2345 current, device output side'
"""

from __future__ import annotations

from typing import Final

__all__ = ["EMCY_CLASSES", "EMCY_CODES", "describe_emcy", "emcy_class"]

EMCY_CLASSES: Final[dict[int, str]] = {
    0x00: "no error",
    0x10: "generic error",
    0x20: "current",
    0x21: "current, device input side",
    0x22: "current inside the device",
    0x23: "current, device output side",
    0x30: "voltage",
    0x31: "mains voltage",
    0x32: "voltage inside the device",
    0x33: "output voltage",
    0x40: "temperature",
    0x41: "ambient temperature",
    0x42: "device temperature",
    0x43: "drive temperature",
    0x50: "device hardware",
    0x54: "device hardware: power section",
    0x55: "device hardware: data storage",
    0x60: "device software",
    0x61: "internal software",
    0x62: "user software",
    0x63: "data set",
    0x70: "additional modules",
    0x71: "additional modules: power",
    0x73: "additional modules: sensor",
    0x75: "additional modules: communication",
    0x80: "monitoring",
    0x81: "monitoring: communication",
    0x82: "monitoring: protocol error",
    0x84: "monitoring: velocity controller",
    0x85: "monitoring: position controller",
    0x86: "monitoring: control",
    0x90: "external error",
    0xF0: "additional functions",
    0xFF: "device specific",
}
"""CiA 301 Table 21 by the code's high byte (``0x81`` communication, ``0x82`` protocol
error ...); a byte not listed falls back to its high nibble (``0x2F`` -> ``0x20`` current).
The ``0x43``, ``0x54``-``0x55``, ``0x71``-``0x75`` and ``0x84``-``0x86`` rows are CiA 402's."""

EMCY_CODES: Final[dict[int, str]] = {
    0x0000: "error reset or no error",
    0x1000: "generic error",
    0x2310: "continuous over current",
    0x2320: "short circuit or earth leakage",
    0x3110: "mains over-voltage",
    0x3120: "mains under-voltage",
    0x3210: "DC link over-voltage",
    0x3220: "DC link under-voltage",
    0x4210: "excess temperature device",
    0x4310: "excess temperature drive",
    0x5000: "device hardware",
    0x5441: "power section: safety function",
    0x5530: "data storage: flash",
    0x6100: "internal software",
    0x6320: "parameter error",
    0x7121: "motor blocked",
    0x7300: "sensor",
    0x7305: "incremental sensor 1 fault",
    0x8110: "CAN overrun (objects lost)",
    0x8120: "CAN in error passive mode",
    0x8130: "life guard or heartbeat error",
    0x8140: "recovered from bus off",
    0x8150: "CAN-ID collision",
    0x8210: "PDO not processed due to length error",
    0x8220: "PDO length exceeded",
    0x8230: "DAM MPDO not processed, destination object not available",
    0x8240: "unexpected SYNC data length",
    0x8250: "RPDO timeout",
    0x8400: "velocity speed controller",
    0x8500: "position controller",
    0x8611: "following error",
    0x8612: "reference limit",
    0x9000: "external error",
    0xF000: "additional functions",
    0xFF00: "device specific",
}
"""The codes CiA 301 (Table 21) and CiA 402 (Annex: error codes) name one by one."""


def emcy_class(code: int) -> str:
    """The class of an emergency error code (``0x8611`` -> ``monitoring: control``)."""
    high = (code >> 8) & 0xFF
    found = EMCY_CLASSES.get(high)
    if found is not None:
        return found
    return EMCY_CLASSES.get(high & 0xF0, "reserved")


def describe_emcy(code: int) -> str:
    """``0x8611 following error (monitoring: control)``; a code without a name of its own
    is described by its class (``0x2345 current, device output side``)."""
    cls = emcy_class(code)
    name = EMCY_CODES.get(code)
    if name is None:
        return f"{code:#06x} {cls}"
    if name == cls:
        return f"{code:#06x} {name}"
    return f"{code:#06x} {name} ({cls})"
