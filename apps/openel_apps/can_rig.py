"""The two-axis demo's rig on CAN: ``openel-async demo --bus can`` (``openel-async run twoaxis
--bus can``).

Axis 1 is an ODrive (node 1, CANSimple) and axis 2 a CiA 402 drive (node 2, CANopen),
both simulated peers (:mod:`openel_can.sim`) on a fresh python-can ``virtual`` channel
that exists only for the duration of the rig; the drivers talk to them through one
:class:`~openel_can.bus.CanBus` exactly as they would on ``socketcan``. The sensors are
the ODrive's encoder estimates (``ENCODER_1``) and the CiA 402 drive's temperature read
by SDO (``TEMP_2``). ``trip_axis2`` makes the CiA 402 peer trip on over-temperature:
EMCY 0x4210 and Fault, so the driver posts the error and faults; the demo recovers it
with ``re_init`` (fault reset and enable). ``Rig.peers`` holds the two simulated peers
(``"odrive"``, ``"cia402"``) for fault injection (e.g. ``sdo_silent``, ``set_silent``).
"""

from __future__ import annotations

import uuid
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import anyio

from openel_apps.twoaxis import Rig
from openel_async import Actuator, Clock, HALId, Sensor
from openel_async.ids import DeviceKind
from openel_can import canopen as co
from openel_can.bus import CanBus
from openel_can.drive402 import CIA402_VENDOR_ID, Cia402Drive, Cia402Temperature
from openel_can.odrive import ODRIVE_VENDOR_ID, ODriveAxis, ODriveEncoder
from openel_can.sim.cia402 import SimCia402Drive
from openel_can.sim.odrive import SimODrive

__all__ = ["can_rig"]

ODRIVE_NODE = 1
CIA402_NODE = 2


@asynccontextmanager
async def can_rig(clock: Clock) -> AsyncIterator[Rig]:
    """Two simulated drives on a fresh virtual channel, the devices not yet entered."""
    channel = f"openel-demo-{uuid.uuid4().hex[:8]}"
    odrive = SimODrive(ODRIVE_NODE, traj_vel_limit=2.0, traj_accel_limit=20.0)
    drive = SimCia402Drive(CIA402_NODE)
    async with anyio.create_task_group() as peers:
        await peers.start(odrive.serve, channel)
        await peers.start(drive.serve, channel)
        async with CanBus(interface="virtual", channel=channel, name="demo") as bus:
            axes = (
                Actuator(ODriveAxis(bus, ODRIVE_NODE), hal_id=HALId(DeviceKind.MOTOR, ODRIVE_VENDOR_ID, 0x0006, 1), device_name="MOTOR_1", clock=clock, auto_init=False),
                Actuator(Cia402Drive(bus, CIA402_NODE, heartbeat_ms=200, profile_velocity=6.0, profile_acceleration=60.0), hal_id=HALId(DeviceKind.MOTOR, CIA402_VENDOR_ID, 0x0192, 2), device_name="MOTOR_2", clock=clock, auto_init=False),
            )  # fmt: skip
            sensors = (
                Sensor(ODriveEncoder(bus, ODRIVE_NODE), hal_id=HALId(DeviceKind.ROTARY_ANGLE, ODRIVE_VENDOR_ID, 0x0106, 1), device_name="ENCODER_1", clock=clock, auto_init=False),
                Sensor(Cia402Temperature(bus, CIA402_NODE), hal_id=HALId(DeviceKind.TEMPERATURE, CIA402_VENDOR_ID, 0x0408, 2), device_name="TEMP_2", clock=clock, auto_init=False),
            )  # fmt: skip

            def trip() -> None:
                drive.trip(co.EmcyCode.DEVICE_OVER_TEMPERATURE, co.ErrorRegister.TEMPERATURE)

            yield Rig(
                f"CAN: ODrive node {ODRIVE_NODE} (CANSimple) + CiA 402 node {CIA402_NODE} "
                f"(CANopen), simulated on python-can virtual channel {channel}",
                axes,
                sensors,
                trip,
                peers={"odrive": odrive, "cia402": drive},
            )
        peers.cancel_scope.cancel()
