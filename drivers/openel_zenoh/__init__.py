"""openel_zenoh: remote devices and the HAL4RT surface layer over Zenoh (the ``zenoh`` driver).

``SurfaceServer`` serves a Surface; ``RemoteSurface`` uses one; ``RemoteActuator`` and
``RemoteSensor`` make a served component a local device. Key expressions: ``keys``;
safe session configurations: ``config``; the e-stop of a served rig (``openel-async
estop``): ``estop``.
"""

from openel_async.registry import DriverInfo

from .client import RemoteSurface, close_session, open_session
from .config import client_config, file_config, safe_config, server_config
from .device import RemoteActuator, RemoteSensor
from .keys import Keys
from .server import SurfaceServer

DRIVER = DriverInfo(
    name="zenoh",
    description="Remote devices: components served by 'openel-async serve' over Zenoh",
    devices={"actuator": RemoteActuator, "sensor": RemoteSensor},
)

__all__ = [
    "DRIVER",
    "Keys",
    "RemoteActuator",
    "RemoteSensor",
    "RemoteSurface",
    "SurfaceServer",
    "client_config",
    "close_session",
    "file_config",
    "open_session",
    "safe_config",
    "server_config",
]
