"""Errors of the serial drivers: codec decode errors and device/link errors.

Every ``decode...`` function in :mod:`openel_serial` raises only its module's
subclass of :class:`DecodeError` on malformed input; the streaming parsers
never raise on garbage and count it instead.

The drivers raise HAL errors the framework understands:

* :class:`DynamixelStatusError` (a ``HALError``): a servo answered with a non-zero
  error number; the instruction was not executed. :class:`DynamixelHardwareAlert`
  (its subclass): the status alert bit is set, the servo has a hardware error and
  has disabled its torque until it is rebooted.
* :class:`DynamixelTimeoutError` (a ``TimeoutError``, a link fault): no status
  packet within the response timeout, after every retry.
* :class:`PortDisconnectedError` (a ``NotConnectedError``, a link fault): the
  serial port could not be opened or vanished (unplugged adapter, closed pty).
* :class:`NoFixError` (a ``HALError``): the GPS has not delivered a position yet.
"""

from __future__ import annotations

from collections.abc import Sequence

from openel_async.errors import HALError, NotConnectedError

__all__ = [
    "DecodeError",
    "DynamixelCrcError",
    "DynamixelDecodeError",
    "DynamixelHardwareAlert",
    "DynamixelStatusError",
    "DynamixelTimeoutError",
    "FeetechChecksumError",
    "FeetechDecodeError",
    "FeetechStatusError",
    "FeetechTimeoutError",
    "NmeaChecksumError",
    "NmeaDecodeError",
    "NoFixError",
    "PortDisconnectedError",
    "ServoTimeoutError",
]


class DecodeError(ValueError):
    """Bytes received from a serial link do not form a valid message."""


class DynamixelDecodeError(DecodeError):
    """Invalid Dynamixel Protocol 2.0 packet (:mod:`openel_serial.dynamixel`)."""


class DynamixelCrcError(DynamixelDecodeError):
    """Dynamixel packet whose CRC-16 does not match its contents."""


class FeetechDecodeError(DecodeError):
    """Invalid Feetech SCS/STS packet (:mod:`openel_serial.feetech`)."""


class FeetechChecksumError(FeetechDecodeError):
    """Feetech packet whose checksum does not match its contents."""


class NmeaDecodeError(DecodeError):
    """Invalid NMEA 0183 sentence (:mod:`openel_serial.nmea`)."""


class NmeaChecksumError(NmeaDecodeError):
    """NMEA sentence whose ``*hh`` checksum does not match its contents."""


_ERROR_NAMES = {
    1: "RESULT_FAIL",
    2: "INSTRUCTION_ERROR",
    3: "CRC_ERROR",
    4: "DATA_RANGE_ERROR",
    5: "DATA_LENGTH_ERROR",
    6: "DATA_LIMIT_ERROR",
    7: "ACCESS_ERROR",
}


class DynamixelStatusError(HALError):
    """A servo's status packet reports an error (error byte bits 0..6 or the alert bit)."""

    def __init__(self, dxl_id: int, error: int, request: str, detail: str = "") -> None:
        number = error & 0x7F
        name = _ERROR_NAMES.get(number, f"error {number}") if number else "no error number"
        alert = ", hardware alert" if error & 0x80 else ""
        text = f"servo {dxl_id}: {request}: {name} (error byte {error:#04x}{alert})"
        super().__init__(text + (f"; {detail}" if detail else ""))
        self.dxl_id = dxl_id
        self.error = error
        self.request = request

    @property
    def error_number(self) -> int:
        """Bits 0..6 (compare with :class:`openel_serial.dynamixel.ErrorNumber`)."""
        return self.error & 0x7F

    @property
    def alert(self) -> bool:
        return bool(self.error & 0x80)


class DynamixelHardwareAlert(DynamixelStatusError):
    """The alert bit: the servo has a hardware error (overload, overheating, ...).

    ``hardware_error`` is Hardware Error Status (address 70) when it could be read.
    The servo keeps the error, with its torque off, until it is rebooted.
    """

    def __init__(self, dxl_id: int, error: int, request: str, hardware_error: int | None) -> None:
        from openel_serial.dynamixel import HardwareError

        if hardware_error is None:
            detail = "hardware error status unreadable; reboot the servo to clear it"
        else:
            bits = HardwareError(hardware_error).describe()
            detail = f"hardware error status {hardware_error:#04x} ({bits}); reboot to clear"
        super().__init__(dxl_id, error, request, detail)
        self.hardware_error = hardware_error


class ServoTimeoutError(TimeoutError):
    """No (valid) status packet from ``ids`` within the timeout, after every attempt (any
    servo protocol; ``servo`` names its servos in the message)."""

    servo: str = "servo"

    def __init__(self, port: str, ids: Sequence[int], request: str, timeout: float, attempts: int):
        id_text = ", ".join(str(i) for i in ids)
        super().__init__(
            f"{port}: no status from {self.servo} {id_text} to {request} "
            f"({attempts} attempt(s), {timeout * 1e3:.1f} ms each)"
        )
        self.port = port
        self.ids = tuple(ids)
        self.request = request
        self.timeout = timeout
        self.attempts = attempts


class DynamixelTimeoutError(ServoTimeoutError):
    """No (valid) status packet from ``ids`` within the timeout, after every attempt."""


class FeetechStatusError(HALError):
    """A Feetech servo reports alarms in its status (voltage, angle sensor, overheat,
    overcurrent, overload: :class:`openel_serial.feetech.StatusError`); unlike Dynamixel 2.0
    the instruction was executed, and the unloading condition (19) bits among them have turned
    its torque off."""

    def __init__(self, servo_id: int, error: int, request: str, detail: str = "") -> None:
        from openel_serial.feetech import StatusError

        text = f"servo {servo_id}: {request}: {StatusError(error).describe()} (error byte {error:#04x})"
        super().__init__(text + (f"; {detail}" if detail else ""))
        self.servo_id = servo_id
        self.error = error
        self.request = request


class FeetechTimeoutError(ServoTimeoutError):
    """No (valid) status from ``ids`` within the timeout, after every attempt."""

    servo = "Feetech servo"


class PortDisconnectedError(NotConnectedError):
    """The serial port cannot be opened, was closed or vanished (HAL_NO_CONNECTED)."""

    def __init__(self, port: str, reason: str) -> None:
        super().__init__(f"serial port {port}: {reason}")
        self.port = port
        self.reason = reason


class NoFixError(HALError):
    """The GPS has not received a position yet (HAL_ERROR; the component stays Active)."""
