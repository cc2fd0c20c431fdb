"""The Dynamixel X series' control table and units (re-exported by :mod:`openel_serial.dynamixel`).

:class:`ControlItem` (an item: size, address, signedness), :class:`XSeries` (the XM430 / XL430
table), the bits of Hardware Error Status and Moving Status, the Operating Mode values, and
the unit conversions of the e-manual (velocity 0.229 rpm, Profile Acceleration 214.577
rev/min^2, current 2.69 mA, Bus Watchdog 20 ms, Return Delay Time 2 us).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum, IntFlag
from typing import TYPE_CHECKING, Final

from openel_serial.errors import DynamixelDecodeError
from openel_serial.servocodec import DescribedFlag

if TYPE_CHECKING:
    from openel_serial.dynamixel import Read, Write

__all__ = [
    "ACCELERATION_UNIT_RPM2",
    "BAUD_RATES",
    "BUS_WATCHDOG_ERROR",
    "BUS_WATCHDOG_FIRMWARE",
    "BUS_WATCHDOG_MAX",
    "BUS_WATCHDOG_UNIT_S",
    "CURRENT_UNIT_A",
    "PWM_FULL_SCALE",
    "RETURN_DELAY_MAX",
    "RETURN_DELAY_UNIT_S",
    "VELOCITY_UNIT_RPM",
    "VOLTAGE_UNIT_V",
    "ControlItem",
    "HardwareError",
    "MovingStatus",
    "OperatingMode",
    "XSeries",
    "acceleration_to_rad_s2",
    "amps_to_current",
    "bus_watchdog_units",
    "current_to_amps",
    "rad_s2_to_acceleration",
    "rad_s_to_velocity",
    "velocity_to_rad_s",
]


@dataclass(frozen=True)
class ControlItem:
    """A control-table item: ``size`` bytes, little-endian, at ``address``."""

    address: int
    size: int
    signed: bool = False

    def encode(self, value: int) -> bytes:
        try:
            return value.to_bytes(self.size, "little", signed=self.signed)
        except OverflowError as exc:
            raise ValueError(f"{value} does not fit {self}") from exc

    def decode(self, data: bytes) -> int:
        if len(data) != self.size:
            raise DynamixelDecodeError(f"item at {self.address} is {self.size} bytes")
        return int.from_bytes(data, "little", signed=self.signed)

    def read(self, dxl_id: int) -> Read:
        from openel_serial.dynamixel import Read  # the codec imports this module

        return Read(dxl_id, self.address, self.size)

    def write(self, dxl_id: int, value: int) -> Write:
        from openel_serial.dynamixel import Write

        return Write(dxl_id, self.address, self.encode(value))


class XSeries:
    """Protocol 2.0 control table of the X series (XM430 / XL430; XL430 has no current items)."""

    MODEL_NUMBER: Final = ControlItem(0, 2)
    FIRMWARE_VERSION: Final = ControlItem(6, 1)
    ID: Final = ControlItem(7, 1)
    BAUD_RATE: Final = ControlItem(8, 1)
    RETURN_DELAY_TIME: Final = ControlItem(9, 1)
    DRIVE_MODE: Final = ControlItem(10, 1)
    OPERATING_MODE: Final = ControlItem(11, 1)
    HOMING_OFFSET: Final = ControlItem(20, 4, signed=True)
    MOVING_THRESHOLD: Final = ControlItem(24, 4)
    TEMPERATURE_LIMIT: Final = ControlItem(31, 1)
    PWM_LIMIT: Final = ControlItem(36, 2)
    CURRENT_LIMIT: Final = ControlItem(38, 2)
    VELOCITY_LIMIT: Final = ControlItem(44, 4)
    MAX_POSITION_LIMIT: Final = ControlItem(48, 4)
    MIN_POSITION_LIMIT: Final = ControlItem(52, 4)
    SHUTDOWN: Final = ControlItem(63, 1)
    TORQUE_ENABLE: Final = ControlItem(64, 1)
    LED: Final = ControlItem(65, 1)
    STATUS_RETURN_LEVEL: Final = ControlItem(68, 1)
    REGISTERED_INSTRUCTION: Final = ControlItem(69, 1)
    HARDWARE_ERROR_STATUS: Final = ControlItem(70, 1)
    VELOCITY_I_GAIN: Final = ControlItem(76, 2)
    VELOCITY_P_GAIN: Final = ControlItem(78, 2)
    POSITION_D_GAIN: Final = ControlItem(80, 2)
    POSITION_I_GAIN: Final = ControlItem(82, 2)
    POSITION_P_GAIN: Final = ControlItem(84, 2)
    FEEDFORWARD_2ND_GAIN: Final = ControlItem(88, 2)
    FEEDFORWARD_1ST_GAIN: Final = ControlItem(90, 2)
    BUS_WATCHDOG: Final = ControlItem(98, 1, signed=True)
    """-1 (0xFF on the wire): Bus Watchdog Error; 0: off; 1..127: armed, 20 ms units."""
    GOAL_PWM: Final = ControlItem(100, 2, signed=True)
    GOAL_CURRENT: Final = ControlItem(102, 2, signed=True)
    GOAL_VELOCITY: Final = ControlItem(104, 4, signed=True)
    PROFILE_ACCELERATION: Final = ControlItem(108, 4)
    PROFILE_VELOCITY: Final = ControlItem(112, 4)
    GOAL_POSITION: Final = ControlItem(116, 4, signed=True)
    REALTIME_TICK: Final = ControlItem(120, 2)
    MOVING: Final = ControlItem(122, 1)
    MOVING_STATUS: Final = ControlItem(123, 1)
    PRESENT_PWM: Final = ControlItem(124, 2, signed=True)
    PRESENT_CURRENT: Final = ControlItem(126, 2, signed=True)
    PRESENT_VELOCITY: Final = ControlItem(128, 4, signed=True)
    PRESENT_POSITION: Final = ControlItem(132, 4, signed=True)
    VELOCITY_TRAJECTORY: Final = ControlItem(136, 4, signed=True)
    POSITION_TRAJECTORY: Final = ControlItem(140, 4, signed=True)
    PRESENT_INPUT_VOLTAGE: Final = ControlItem(144, 2)
    PRESENT_TEMPERATURE: Final = ControlItem(146, 1)


class HardwareError(DescribedFlag):
    """Bits of Hardware Error Status (address 70); any of them sets the status alert bit.

    The servo disables its torque (Shutdown, address 63 selects which bits do) and keeps
    the bits until it is rebooted.
    """

    INPUT_VOLTAGE = 0x01
    OVERHEATING = 0x04
    MOTOR_ENCODER = 0x08
    ELECTRICAL_SHOCK = 0x10
    OVERLOAD = 0x20


class MovingStatus(IntFlag):
    """Bits of Moving Status (address 123)."""

    IN_POSITION = 0x01
    PROFILE_ONGOING = 0x02
    FOLLOWING_ERROR = 0x08
    PROFILE_TYPE_MASK = 0x30
    """Bits 4-5: 3 trapezoidal, 2 triangular, 1 rectangular, 0 step (no profile)."""


class OperatingMode(IntEnum):
    """Values of Operating Mode (address 11)."""

    CURRENT = 0
    VELOCITY = 1
    POSITION = 3
    EXTENDED_POSITION = 4
    CURRENT_BASED_POSITION = 5
    PWM = 16


VELOCITY_UNIT_RPM: Final = 0.229
#: Profile Acceleration (108) unit, rev/min^2.
ACCELERATION_UNIT_RPM2: Final = 214.577
CURRENT_UNIT_A: Final = 0.00269  # XM430 series; 2.69 mA per unit
VOLTAGE_UNIT_V: Final = 0.1
PWM_FULL_SCALE: Final = 885  # 100 % duty
#: Bus Watchdog (98): unit, largest setting, the value it reads after expiring (0xFF), and
#: the first firmware version that has it (e-manual, "Bus Watchdog (98)").
BUS_WATCHDOG_UNIT_S: Final = 0.020
BUS_WATCHDOG_MAX: Final = 127
BUS_WATCHDOG_ERROR: Final = -1
BUS_WATCHDOG_FIRMWARE: Final = 38
BAUD_RATES: Final = (9600, 57_600, 115_200, 1_000_000, 2_000_000, 3_000_000, 4_000_000, 4_500_000)
"""Baud Rate (8) setting -> bit/s: the X series' rates, in the order of the item's values 0..7
(e-manual, "Baud Rate (8)")."""
RETURN_DELAY_UNIT_S: Final = 2e-6
"""Return Delay Time (9) unit; the largest setting is :data:`RETURN_DELAY_MAX`."""
RETURN_DELAY_MAX: Final = 254
_RAD_S_PER_UNIT: Final = VELOCITY_UNIT_RPM * 2 * math.pi / 60
_RAD_S2_PER_UNIT: Final = ACCELERATION_UNIT_RPM2 * 2 * math.pi / 3600


def velocity_to_rad_s(units: int) -> float:
    return units * _RAD_S_PER_UNIT


def rad_s_to_velocity(rad_s: float) -> int:
    return round(rad_s / _RAD_S_PER_UNIT)


def acceleration_to_rad_s2(units: int) -> float:
    """Profile Acceleration units (214.577 rev/min^2 each) to rad/s^2."""
    return units * _RAD_S2_PER_UNIT


def rad_s2_to_acceleration(rad_s2: float) -> int:
    return round(rad_s2 / _RAD_S2_PER_UNIT)


def current_to_amps(units: int) -> float:
    return units * CURRENT_UNIT_A


def amps_to_current(amps: float) -> int:
    return round(amps / CURRENT_UNIT_A)


def bus_watchdog_units(timeout_s: float) -> int:
    """Bus Watchdog (98) setting for ``timeout_s``: a whole number of 20 ms units in
    1..127 (0.02..2.54 s); anything else raises :class:`ValueError`."""
    if isinstance(timeout_s, bool) or not isinstance(timeout_s, int | float):
        raise ValueError(f"bus watchdog timeout {timeout_s!r} is not a number")
    units = timeout_s / BUS_WATCHDOG_UNIT_S if math.isfinite(timeout_s) else -1.0
    whole = round(units)
    if not (1 <= whole <= BUS_WATCHDOG_MAX and abs(units - whole) <= 1e-6):
        raise ValueError(
            f"bus watchdog timeout {timeout_s!r} s is not a multiple of "
            f"{BUS_WATCHDOG_UNIT_S} s in {BUS_WATCHDOG_UNIT_S}..{BUS_WATCHDOG_MAX * BUS_WATCHDOG_UNIT_S:g} s"
        )
    return whole
