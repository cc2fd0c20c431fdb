"""openel_zenoh: remote devices and the HAL4RT surface layer over Zenoh (the ``zenoh`` driver).

``SurfaceServer`` serves a Surface; ``RemoteSurface`` uses one; ``RemoteActuator`` and
``RemoteSensor`` make a served component a local device. Key expressions: ``keys``;
safe session configurations: ``config``; the e-stop of a served rig (``openel-async
estop``): ``estop``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from openel_async.lazy import lazy_exports

if TYPE_CHECKING:
    from openel_async.registry import DriverInfo

    from .client import RemoteSurface, close_session, open_session
    from .config import client_config, file_config, safe_config, server_config
    from .device import RemoteActuator, RemoteSensor
    from .keys import Keys
    from .server import SurfaceServer

# The names below load their module (and zenoh) on first use: a command contributed by this
# package (openel-async serve, estop ...) is listed by 'openel-async --help' without them.
_LAZY = {
    "RemoteSurface": "client",
    "close_session": "client",
    "open_session": "client",
    "client_config": "config",
    "file_config": "config",
    "safe_config": "config",
    "server_config": "config",
    "RemoteActuator": "device",
    "RemoteSensor": "device",
    "Keys": "keys",
    "SurfaceServer": "server",
}


def _driver() -> DriverInfo:
    from openel_async.registry import DriverInfo, lazy_classes

    return DriverInfo(
        name="zenoh",
        description="Remote devices: components served by 'openel-async serve' over Zenoh",
        devices=lazy_classes(
            {
                "actuator": "openel_zenoh.device:RemoteActuator",
                "sensor": "openel_zenoh.device:RemoteSensor",
            }
        ),
    )


__getattr__, __dir__ = lazy_exports(__name__, _LAZY, {"DRIVER": _driver})


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
