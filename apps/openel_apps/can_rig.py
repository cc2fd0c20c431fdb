"""The two-axis demo's rig on CAN, simulated: ``openel-async demo --bus can``
(``openel-async run twoaxis --bus can``, the same as ``--rig rigs/twoaxis-can.yaml --sim``).

Axis 1 is an ODrive (node 1, CANSimple) and axis 2 a CiA 402 drive (node 2, CANopen) on
``can0`` in ``rigs/twoaxis-can.yaml``; with ``--sim`` the bus is a fresh python-can
``virtual`` channel with simulated peers (:mod:`openel_can.sim`) at the same node ids, and
the drivers talk to them through one :class:`~openel_can.bus.CanBus` exactly as they would on
``socketcan``. The sensors are the ODrive's encoder estimates (``ENCODER_1``) and the CiA 402
drive's temperature read by SDO (``TEMP_2``). ``trip_axis2`` makes the CiA 402 peer trip on
over-temperature: EMCY 0x4210 and Fault, so the driver posts the error and faults; the demo
recovers it with ``re_init`` (fault reset and enable). ``Rig.peers`` holds the simulated
peers by component name (``"MOTOR_2"`` is the CiA 402 drive) for fault injection (e.g.
``sdo_silent``, ``set_silent``).
"""

from __future__ import annotations

from openel_apps.twoaxis import CAN_RIG, file_rig

__all__ = ["can_rig"]

can_rig = file_rig(CAN_RIG, sim=True)
"""The simulated CAN rig's factory (a :data:`~openel_apps.twoaxis.RigFactory`)."""
