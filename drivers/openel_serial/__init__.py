"""openel_serial: serial-port devices on pyserial-asyncio-fast (the ``serial`` driver).

* :class:`DynamixelPort` + :class:`DynamixelServo`: Dynamixel Protocol 2.0 X-series
  servos sharing one half-duplex port, polled with one SYNC READ per cycle; the model
  classes :class:`DynamixelXM430W350`, :class:`DynamixelXL430W250` (product id = model
  number) are in the Device Kind ID registry.
* :class:`FeetechPort` + :class:`FeetechServo`: Feetech STS servos (the SO-101's STS3215,
  :class:`FeetechSTS3215`) sharing one port, polled with one SYNC READ per cycle.
* :class:`NmeaGps`: an NMEA 0183 GPS receiver (GGA, RMC).
* :mod:`openel_serial.peers`, :mod:`openel_serial.feetech_peers`: simulated devices on
  pseudo-terminals for tests and demos.

Codecs: :mod:`openel_serial.dynamixel`, :mod:`openel_serial.feetech`, :mod:`openel_serial.nmea`.
See docs/serial.md.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from openel_async.lazy import lazy_exports

if TYPE_CHECKING:
    from openel_async.registry import DriverInfo

    from .errors import (
        DynamixelHardwareAlert,
        DynamixelStatusError,
        DynamixelTimeoutError,
        FeetechStatusError,
        FeetechTimeoutError,
        NoFixError,
        PortDisconnectedError,
    )
    from .feetech_port import FeetechPort, FeetechPresentState
    from .feetech_servo import FeetechServo, FeetechSTS3215
    from .gps import GpsFix, NmeaGps
    from .port import DynamixelPort, PingInfo, PortStats, PresentState
    from .rigbus import SerialBusKind, SerialBusOptions
    from .servo import DynamixelServo, DynamixelXL430W250, DynamixelXM430W350

# The names below load their module on first use: a command this package contributes
# (openel-async calibrate) is listed by 'openel-async --help' without loading its dependencies.
_LAZY = {
    "DynamixelHardwareAlert": "errors",
    "DynamixelStatusError": "errors",
    "DynamixelTimeoutError": "errors",
    "FeetechStatusError": "errors",
    "FeetechTimeoutError": "errors",
    "NoFixError": "errors",
    "PortDisconnectedError": "errors",
    "FeetechPort": "feetech_port",
    "FeetechPresentState": "feetech_port",
    "FeetechServo": "feetech_servo",
    "FeetechSTS3215": "feetech_servo",
    "GpsFix": "gps",
    "NmeaGps": "gps",
    "DynamixelPort": "port",
    "PingInfo": "port",
    "PortStats": "port",
    "PresentState": "port",
    "SerialBusKind": "rigbus",
    "SerialBusOptions": "rigbus",
    "DynamixelServo": "servo",
    "DynamixelXL430W250": "servo",
    "DynamixelXM430W350": "servo",
}


def _driver() -> DriverInfo:
    from openel_async.registry import DriverInfo, lazy_bus_kinds, lazy_classes

    return DriverInfo(
        name="serial",
        description=(
            "Serial devices on pyserial-asyncio-fast: Dynamixel 2.0 servos, Feetech STS servos, "
            "NMEA GPS"
        ),
        devices=lazy_classes(
            {
                "dynamixel": "openel_serial.servo:DynamixelServo",
                "dynamixel_xm430_w350": "openel_serial.servo:DynamixelXM430W350",
                "dynamixel_xl430_w250": "openel_serial.servo:DynamixelXL430W250",
                "feetech": "openel_serial.feetech_servo:FeetechServo",
                "feetech_sts3215": "openel_serial.feetech_servo:FeetechSTS3215",
                "nmea_gps": "openel_serial.gps:NmeaGps",
            }
        ),
        buses=lazy_bus_kinds({"serial": "openel_serial.rigbus:SerialBusKind"}),
    )


__getattr__, __dir__ = lazy_exports(__name__, _LAZY, {"DRIVER": _driver})

__all__ = [
    "DRIVER",
    "DynamixelHardwareAlert",
    "DynamixelPort",
    "DynamixelServo",
    "DynamixelStatusError",
    "DynamixelTimeoutError",
    "DynamixelXL430W250",
    "DynamixelXM430W350",
    "FeetechPort",
    "FeetechPresentState",
    "FeetechSTS3215",
    "FeetechServo",
    "FeetechStatusError",
    "FeetechTimeoutError",
    "GpsFix",
    "NmeaGps",
    "NoFixError",
    "PingInfo",
    "PortDisconnectedError",
    "PortStats",
    "PresentState",
    "SerialBusKind",
    "SerialBusOptions",
]
