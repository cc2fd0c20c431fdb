"""openel_can: OpenEL devices on CAN buses through python-can (the ``can`` driver).

- :class:`CanBus`: one python-can bus (socketcan, pcan, kvaser, virtual ...) with one
  reader, one sender and bus-failure recovery, shared by every node on it;
- ODrive axes over CANSimple: :class:`ODriveAxis`, :class:`ODriveEncoder`,
  :class:`ODriveTemperature`, :class:`ODriveBusMonitor`;
- CiA 402 drives over CANopen: :class:`Cia402Drive`, :class:`Cia402Temperature`; in the
  cyclic synchronous modes :class:`Cia402CyclicDrive` on the SYNC of :class:`CanSync`, an
  EventTimer's observer;
- the pure codecs :mod:`openel_can.cansimple`, :mod:`openel_can.canopen`,
  :mod:`openel_can.cia402`, and simulated peers in :mod:`openel_can.sim`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from openel_async.lazy import lazy_exports

if TYPE_CHECKING:
    from openel_async.registry import DriverInfo

    from .bus import BusState, BusStats, CanBus, NodePort, TxMessage
    from .cyclic402 import Cia402CyclicDrive
    from .drive402 import Cia402Drive, Cia402Temperature
    from .odrive import ODriveAxis, ODriveBusMonitor, ODriveEncoder, ODriveError, ODriveTemperature
    from .rigbus import CanBusKind, CanBusOptions
    from .sdo import SdoAbortError, SdoClient, SdoTimeoutError
    from .sync import CanSync, SyncStats

# The names below load their module on first use: a command this package contributes
# (openel-async scan can ...) is listed by 'openel-async --help' without loading its dependencies.
_LAZY = {
    "BusState": "bus",
    "BusStats": "bus",
    "CanBus": "bus",
    "NodePort": "bus",
    "TxMessage": "bus",
    "Cia402CyclicDrive": "cyclic402",
    "Cia402Drive": "drive402",
    "Cia402Temperature": "drive402",
    "ODriveAxis": "odrive",
    "ODriveBusMonitor": "odrive",
    "ODriveEncoder": "odrive",
    "ODriveError": "odrive",
    "ODriveTemperature": "odrive",
    "CanBusKind": "rigbus",
    "CanBusOptions": "rigbus",
    "SdoAbortError": "sdo",
    "SdoClient": "sdo",
    "SdoTimeoutError": "sdo",
    "CanSync": "sync",
    "SyncStats": "sync",
}


def _driver() -> DriverInfo:
    from openel_async.registry import DriverInfo, lazy_bus_kinds, lazy_classes

    return DriverInfo(
        name="can",
        description="CAN buses via python-can: ODrive (CANSimple) and CiA 402 (CANopen) drives",
        devices=lazy_classes(
            {
                "odrive_axis": "openel_can.odrive:ODriveAxis",
                "odrive_encoder": "openel_can.odrive:ODriveEncoder",
                "odrive_temperature": "openel_can.odrive:ODriveTemperature",
                "odrive_bus_monitor": "openel_can.odrive:ODriveBusMonitor",
                "cia402_drive": "openel_can.drive402:Cia402Drive",
                "cia402_temperature": "openel_can.drive402:Cia402Temperature",
            }
        ),
        buses=lazy_bus_kinds({"can": "openel_can.rigbus:CanBusKind"}),
    )


__getattr__, __dir__ = lazy_exports(__name__, _LAZY, {"DRIVER": _driver})

__all__ = [
    "DRIVER",
    "BusState",
    "BusStats",
    "CanBus",
    "CanBusKind",
    "CanBusOptions",
    "CanSync",
    "Cia402CyclicDrive",
    "Cia402Drive",
    "Cia402Temperature",
    "NodePort",
    "ODriveAxis",
    "ODriveBusMonitor",
    "ODriveEncoder",
    "ODriveError",
    "ODriveTemperature",
    "SdoAbortError",
    "SdoClient",
    "SdoTimeoutError",
    "SyncStats",
    "TxMessage",
]
