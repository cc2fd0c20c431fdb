"""Issue 22, watchdogs on the device, through a rig file with ``--sim``: at init the rig arms
every device's own watchdog with ``safety.watchdog_timeout`` and the control loop feeds it.
Blocking the event loop for 3x the timeout (a GC pause, a blocking call) leaves the host
silent: every simulated drive and servo stops by itself, and when the loop resumes each
component reports the trip as an error with ``ErrorId.WATCHDOG``."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import anyio

from openel_async import MonotonicClock, Request
from openel_async.device import ErrorId
from openel_async.rig import load_rig, open_rig

TIMEOUT_S = 0.2

RIG = f"""\
description: a CAN bus and a Dynamixel bus, simulated
buses:
  can0: {{type: can, interface: socketcan, channel: can0, bitrate: 1000000}}
  servos: {{type: serial, protocol: dynamixel, device: /dev/ttyUSB0, baudrate: 1000000}}
components:
  - {{name: ODRIVE, driver: can, device: odrive_axis, bus: can0, params: {{node_id: 1}}}}
  - {{name: CIA402, driver: can, device: cia402_drive, bus: can0, params: {{node_id: 2}}}}
  - {{name: SERVO_1, driver: serial, device: dynamixel_xm430_w350, bus: servos, params: {{dxl_id: 1}}}}
  - {{name: SERVO_2, driver: serial, device: dynamixel_xm430_w350, bus: servos, params: {{dxl_id: 2}}}}
safety: {{watchdog_timeout: {TIMEOUT_S}, on_exit: torque_off}}
"""


class Errors:
    def __init__(self) -> None:
        self.seen: dict[str, list[int]] = {}
        self.changed = anyio.Event()

    def notify_event(self, source: object, event_id: int) -> None:
        pass

    def notify_error(self, source: object, error_id: int) -> None:
        self.seen.setdefault(getattr(source, "device_name", "?"), []).append(int(error_id))
        self.changed.set()
        self.changed = anyio.Event()


async def test_a_stalled_loop_lets_every_device_watchdog_stop_its_drive(tmp_path: Path) -> None:
    path = tmp_path / "rig.yaml"
    path.write_text(RIG)
    errors = Errors()
    async with open_rig(load_rig(path), MonotonicClock(), sim=True) as rig:
        for actuator in rig.actuators:
            actuator.add_observer(errors)
        with anyio.fail_after(10):
            motions = [await a.set_value(0.2, Request.POSITION) for a in rig.actuators]
            for motion in motions:
                await motion
        time.sleep(3 * TIMEOUT_S)  # noqa: ASYNC251  (the stall under test: nothing feeds)
        with anyio.fail_after(5):
            while set(errors.seen) != set(rig.components):
                await errors.changed.wait()
        assert {
            name: ErrorId.WATCHDOG in ids for name, ids in errors.seen.items()
        } == dict.fromkeys(rig.components, True)
        assert {c.state.value for c in rig.components.values()} == {"Error"}
        peers: dict[str, Any] = dict(rig.peers)
        assert peers["ODRIVE"].axis_state.name == "IDLE"
        assert peers["CIA402"].power_state.name != "OPERATION_ENABLED"
        assert peers["SERVO_1"].watchdog_tripped and peers["SERVO_2"].watchdog_tripped
