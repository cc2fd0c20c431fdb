"""The ``serial`` bus kind of rig files: a serial port carrying Dynamixel Protocol 2.0 servos
(one :class:`~openel_serial.port.DynamixelPort` shared by the servos that name it) or an NMEA
GPS receiver, and its simulation for ``--sim``.

```yaml
buses:
  arm: {type: serial, protocol: dynamixel, device: /dev/ttyUSB0, baudrate: 1000000}
  gps: {type: serial, protocol: nmea, device: /dev/ttyACM0, baudrate: 9600}
```

With ``--sim`` the port is a pseudo-terminal with simulated servos
(:class:`~openel_serial.peers.SimDynamixelBus`, the model of each device class, at the rig's
ids) or a simulated receiver (:class:`~openel_serial.peers.SimGps`), served on a thread of its
own (:class:`~openel_serial.peers.PeerThread`: it keeps running -- the servos' Bus Watchdog
too -- while the host's event loop is blocked); the driver opens the pty at the rig's baud
rate with the port's real termios settings.
"""

from __future__ import annotations

from collections.abc import AsyncIterator, Mapping, Sequence
from contextlib import AbstractAsyncContextManager, asynccontextmanager
from typing import Any, Literal

import msgspec

from openel_async.errors import BadParameterError
from openel_async.rig import BusKind, SimulatedBus, SimulatedDevice

from .port import DynamixelPort

__all__ = ["SerialBusKind", "SerialBusOptions"]

SERVO_MODELS: Mapping[str, int] = {
    "dynamixel": 1020,
    "dynamixel_xm430_w350": 1020,
    "dynamixel_xl430_w250": 1060,
}
"""The Dynamixel device classes and the model number a simulated servo of each reports."""
GPS_DEVICES = frozenset({"nmea_gps"})
DYNAMIXEL_BAUDRATES = (9600, 57_600, 115_200, 1_000_000, 2_000_000, 3_000_000, 4_000_000, 4_500_000)
"""The X series' Baud Rate (8) settings, bit/s."""


class SerialBusOptions(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """A serial port."""

    device: str
    """The port: /dev/ttyUSB0, /dev/serial/by-id/... (stable across replugs), or a pyserial
    URL."""
    baudrate: int
    """Bits per second: the servos' Baud Rate setting (Dynamixel X: 9600 .. 4500000) or the
    receiver's (NMEA: usually 9600)."""
    protocol: Literal["dynamixel", "nmea"]
    """What the port carries: Dynamixel Protocol 2.0 servos, or an NMEA 0183 GPS receiver."""
    poll_period: float = 0.01
    """Dynamixel: seconds between the SYNC READs of every servo's present state (below half
    the watchdog timeout)."""
    return_delay: float = 500e-6
    """Dynamixel: the servos' Return Delay Time, seconds."""
    timeout_margin: float = 0.02
    """Dynamixel: seconds added to a reply's transfer time before it counts as lost."""
    retries: int = 2
    """Dynamixel: resends of a lost exchange."""


def _servo_ids(devices: Sequence[SimulatedDevice]) -> dict[int, SimulatedDevice]:
    ids: dict[int, SimulatedDevice] = {}
    for d in devices:
        dxl_id = d.params.get("dxl_id")
        if not isinstance(dxl_id, int) or isinstance(dxl_id, bool) or not 0 <= dxl_id <= 252:
            raise BadParameterError(f"{d.name}.params.dxl_id", dxl_id, "a servo id in 0..252")
        if dxl_id in ids:
            raise BadParameterError(
                f"{d.name}.params.dxl_id", dxl_id, f"an id of its own ({ids[dxl_id].name} has it)"
            )
        ids[dxl_id] = d
    return ids


class SerialBusKind(BusKind):
    """``type: serial`` (see the module docstring)."""

    options_type = SerialBusOptions

    def check(self, options: Any, devices: Sequence[SimulatedDevice]) -> None:
        assert isinstance(options, SerialBusOptions)
        if options.baudrate <= 0:
            raise BadParameterError("baudrate", options.baudrate, "bits per second > 0")
        wanted = SERVO_MODELS if options.protocol == "dynamixel" else GPS_DEVICES
        for d in devices:
            if d.device not in wanted:
                raise BadParameterError(
                    f"{d.name}.device",
                    d.device,
                    f"a {options.protocol} device ({', '.join(sorted(wanted))})",
                )
        if options.protocol == "dynamixel":
            if options.baudrate not in DYNAMIXEL_BAUDRATES:
                raise BadParameterError(
                    "baudrate", options.baudrate,
                    f"a Dynamixel X baud rate: {', '.join(map(str, DYNAMIXEL_BAUDRATES))}",
                )  # fmt: skip
            _servo_ids(devices)
        elif len(devices) > 1:
            names = ", ".join(d.name for d in devices)
            raise BadParameterError("devices", names, "one GPS receiver per NMEA port")

    def describe(self, options: Any) -> str:
        assert isinstance(options, SerialBusOptions)
        what = "Dynamixel 2.0" if options.protocol == "dynamixel" else "NMEA 0183"
        return f"serial {options.device} at {options.baudrate} baud, {what}"

    def open(self, name: str, options: Any) -> AbstractAsyncContextManager[object]:
        assert isinstance(options, SerialBusOptions)
        if options.protocol == "dynamixel":
            return DynamixelPort(
                options.device,
                baudrate=options.baudrate,
                return_delay=options.return_delay,
                timeout_margin=options.timeout_margin,
                retries=options.retries,
                poll_period=options.poll_period,
            )
        return _nothing(options)  # the GPS device opens its port itself

    def device_arguments(
        self, bus: object, options: Any, device: SimulatedDevice
    ) -> Mapping[str, Any]:
        assert isinstance(options, SerialBusOptions)
        if options.protocol == "dynamixel":
            return {"port": bus}
        return {"url": options.device, "baudrate": options.baudrate}

    def simulate(
        self, name: str, options: Any, devices: Sequence[SimulatedDevice]
    ) -> AbstractAsyncContextManager[SimulatedBus]:
        assert isinstance(options, SerialBusOptions)
        return _simulated(options, devices)


@asynccontextmanager
async def _nothing(options: SerialBusOptions) -> AsyncIterator[object]:
    yield options


@asynccontextmanager
async def _simulated(
    options: SerialBusOptions, devices: Sequence[SimulatedDevice]
) -> AsyncIterator[SimulatedBus]:
    from .peers import PeerThread, SimDynamixelBus, SimGps, SimServo

    if options.protocol == "dynamixel":
        ids = _servo_ids(devices)
        servos = {i: SimServo(i, model_number=SERVO_MODELS[d.device]) for i, d in ids.items()}
        peer: SimDynamixelBus | SimGps = SimDynamixelBus(servos.values())
        by_name: dict[str, object] = {d.name: servos[i] for i, d in ids.items()}
        what = f"simulated Dynamixel servos {', '.join(map(str, sorted(ids)))}"
    else:
        peer = SimGps()
        by_name = {d.name: peer for d in devices}
        what = "a simulated NMEA receiver"
    async with PeerThread(peer):
        yield SimulatedBus(
            msgspec.structs.replace(options, device=peer.path),
            f"pty {peer.path} at {options.baudrate} baud with {what}",
            by_name,
        )
