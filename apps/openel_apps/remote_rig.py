"""The two-axis demo's rig served by another process: ``openel-async demo --remote``
(``openel-async run twoaxis --bus remote``).

The sim rig's devices (two motors, an encoder on the first, a thermometer on the second)
are hosted by ``openel-async serve`` in a child process on a free loopback port
(:func:`openel_zenoh.spawn.served`); the demo drives them through ``RemoteActuator`` and
``RemoteSensor`` over Zenoh. The server process is stopped when the rig closes, also on
Ctrl-C. Faults cannot be injected from here (the devices are in the server process):
the demo refuses ``--inject-fault`` with ``--bus remote``.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import AsyncExitStack, asynccontextmanager

from openel_apps.twoaxis import Rig
from openel_async import Actuator, Clock, Sensor
from openel_zenoh import RemoteActuator, RemoteSensor
from openel_zenoh.spawn import served

__all__ = ["RIG_YAML", "remote_rig"]

NAMESPACE = "twoaxis"
RIG_YAML = f"""\
namespace: {NAMESPACE}
components:
  - {{name: MOTOR_1, driver: sim, device: motor, params: {{max_velocity: 3.0, max_acceleration: 40.0}}}}
  - {{name: MOTOR_2, driver: sim, device: motor, params: {{max_velocity: 3.0, max_acceleration: 40.0}}}}
  - {{name: ENCODER_1, driver: sim, device: encoder, params: {{motor: {{ref: MOTOR_1}}}}}}
  - {{name: TEMP_2, driver: sim, device: temperature, params: {{motor: {{ref: MOTOR_2}}, noise: 0.05, seed: 7}}}}
"""


@asynccontextmanager
async def remote_rig(clock: Clock) -> AsyncIterator[Rig]:
    """The sim rig served by a child process, the remote devices entered (not initialized)."""
    async with served(RIG_YAML, NAMESPACE) as server, AsyncExitStack() as stack:
        remote = server.remote
        axes = (
            Actuator(RemoteActuator(remote, 0), device_name="MOTOR_1", clock=clock, auto_init=False),
            Actuator(RemoteActuator(remote, 1), device_name="MOTOR_2", clock=clock, auto_init=False),
        )  # fmt: skip
        sensors = (
            Sensor(RemoteSensor(remote, 0, device_kind="Encoder"), device_name="ENCODER_1", clock=clock, auto_init=False),
            Sensor(RemoteSensor(remote, 0, device_kind="TemperatureSensor"), device_name="TEMP_2", clock=clock, auto_init=False),
        )  # fmt: skip
        for component in (*axes, *sensors):
            await stack.enter_async_context(component)

        def trip() -> None:
            raise NotImplementedError("no fault injection into a served rig")

        yield Rig(
            f"simulated devices served by 'openel-async serve' (pid {server.pid}) over "
            f"Zenoh, tcp/127.0.0.1:{server.port}",
            axes,
            sensors,
            trip,
        )
