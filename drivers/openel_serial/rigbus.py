"""The ``serial`` bus kind of rig files: a serial port carrying Dynamixel Protocol 2.0 servos
(one :class:`~openel_serial.port.DynamixelPort` shared by the servos that name it), Feetech
STS servos (one :class:`~openel_serial.feetech_port.FeetechPort`) or an NMEA GPS receiver, and
its simulation for ``--sim``.

```yaml
buses:
  arm: {type: serial, protocol: dynamixel, device: /dev/ttyUSB0, baudrate: 1000000}
  so101: {type: serial, protocol: feetech, device: /dev/ttyACM0, baudrate: 1000000}
  gps: {type: serial, protocol: nmea, device: /dev/ttyACM0, baudrate: 9600}
```

Feetech servos are addressed by ``params.servo_id`` (0..253), Dynamixel ones by
``params.dxl_id``; the Feetech baud rates are the STS's Baud Rate (6) table (1000000, 500000,
250000, 128000, 115200, 76800, 57600, 38400); the port tuning options apply to both servo
protocols. With ``--sim`` a Feetech port is a :class:`~openel_serial.feetech_peers.SimFeetechBus`
of :class:`~openel_serial.feetech_peers.SimStsServo` s at the rig's ids, with the rig's baud
rate as their Baud Rate (6) and its ``return_delay`` as their Return Delay (7).

A Feetech port's ``calibration: FILE`` (a file ``openel-async calibrate`` writes; a relative
path is taken relative to the rig file's directory by :meth:`SerialBusKind.resolve_paths`,
which the rig loader applies) gives each servo its entry
(:class:`~openel_serial.feetech_calibration.JointCalibration`, by component name):
``rig check`` refuses a file it cannot read as a calibration file (with its ``FILE:LINE:COL``),
a servo without an entry or with another id; a missing file passes ``rig check`` (calibrate
writes it) but opening the real port refuses it. With ``--sim`` the simulated servos are the
calibrated arm (the file's homing offsets and angle limits in their EEPROM, each at the
middle of its range) when the file exists, else factory-fresh servos at step 2048 (the bus
then opens without the calibration).

``rig check`` (:meth:`SerialBusKind.check`) refuses a device of the other protocol on a
port, a baud rate the protocol does not have (the X series' Baud Rate (8) table; the
standard tty rates for NMEA), a servo id outside 0..252 or given twice, a second receiver
on an NMEA port, and the Dynamixel tuning options on an NMEA port.

With ``--sim`` the port is a pseudo-terminal with simulated servos
(:class:`~openel_serial.peers.SimDynamixelBus`: a :class:`~openel_serial.peers.SimServo` of
each device class's model at the rig's ids, with the rig's baud rate as their Baud Rate (8)
and its ``return_delay`` as their Return Delay Time (9)) or a simulated receiver
(:class:`~openel_serial.peers.SimGps`), served on a thread of its own
(:class:`~openel_serial.peers.PeerThread`: it keeps running -- the servos' Bus Watchdog
too -- while the host's event loop is blocked, and stops at exit). The driver opens the pty
at the rig's baud rate with the port's real termios settings, and the simulated servos hear
it only at their own rate, as on a real bus.
"""

from __future__ import annotations

import math
from collections.abc import AsyncIterator, Mapping, Sequence
from contextlib import AbstractAsyncContextManager, asynccontextmanager
from pathlib import Path
from typing import Annotated, Any, Final, Literal

import msgspec

from openel_async.errors import BadParameterError
from openel_async.params import ParameterAccess
from openel_async.positioned import DocumentError, relocate
from openel_async.rig import BusKind, SimulatedBus, SimulatedDevice
from openel_serial import dynamixel as dx
from openel_serial import feetech as ft

from .feetech_calibration import CalibrationFile, JointCalibration, load_calibration
from .feetech_port import DEFAULT_RETURN_DELAY as FEETECH_RETURN_DELAY
from .feetech_port import FeetechPort
from .port import DEFAULT_RETURN_DELAY, DynamixelPort

__all__ = [
    "DYNAMIXEL_BAUDRATES",
    "FEETECH_BAUDRATES",
    "FEETECH_MODELS",
    "GPS_DEVICES",
    "NMEA_BAUDRATES",
    "SERVO_MODELS",
    "SerialBusKind",
    "SerialBusOptions",
]

SERVO_MODELS: Final[Mapping[str, int]] = {
    "dynamixel": 1020,
    "dynamixel_xm430_w350": 1020,
    "dynamixel_xl430_w250": 1060,
}
"""The Dynamixel device classes and the model number a simulated servo of each reports (the
generic ``dynamixel`` class: an XM430-W350)."""
FEETECH_MODELS: Final[Mapping[str, int]] = {
    "feetech": ft.STS3215_MODEL,
    "feetech_sts3215": ft.STS3215_MODEL,
}
"""The Feetech device classes and the model number a simulated servo of each reports."""
FEETECH_BAUDRATES: Final = ft.BAUD_RATES
"""The STS's Baud Rate (6) settings, bit/s."""
GPS_DEVICES: Final = frozenset({"nmea_gps"})
DYNAMIXEL_BAUDRATES: Final = dx.BAUD_RATES
"""The X series' Baud Rate (8) settings, bit/s."""
NMEA_BAUDRATES: Final = (4800, 9600, 19_200, 38_400, 57_600, 115_200, 230_400, 460_800, 921_600)
"""The tty rates GPS receivers use (NMEA 0183 itself says 4800; most send at 9600)."""
DYNAMIXEL_ONLY: Final = ("poll_period", "return_delay", "timeout_margin", "retries")
"""The options of a servo port, Dynamixel or Feetech (None: the port class's default)."""
_ADDRESS_KEY: Final = {"dynamixel": "dxl_id", "feetech": "servo_id"}
_MAX_ID: Final = {"dynamixel": dx.MAX_ID, "feetech": ft.MAX_ID}

Seconds = Annotated[float, msgspec.Meta(ge=0)]


class SerialBusOptions(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """A serial port: its device, baud rate and protocol; for Dynamixel, the port's tuning."""

    device: Annotated[str, msgspec.Meta(min_length=1)]
    """The port: ``/dev/ttyUSB0``, ``/dev/serial/by-id/...`` (stable across replugs), or a
    pyserial URL."""
    baudrate: Annotated[int, msgspec.Meta(gt=0)]
    """Bits per second: the servos' Baud Rate (8) (Dynamixel X: 9600, 57600, 115200, 1000000,
    2000000, 3000000, 4000000 or 4500000) or the receiver's (NMEA: 4800 .. 921600, usually
    9600)."""
    protocol: Literal["dynamixel", "feetech", "nmea"]
    """What the port carries: Dynamixel Protocol 2.0 servos or Feetech STS servos (they share
    one port object and its poller), or one NMEA 0183 GPS receiver (the ``nmea_gps`` device
    opens the port)."""
    poll_period: Seconds | None = None
    """Servo ports only: seconds between the SYNC READs of every servo's present state, which
    also feed their Bus Watchdogs (Feetech: the port's host watchdog) -- below half of
    ``safety.watchdog_timeout``; 0 polls back to back. Default 0.01."""
    return_delay: Annotated[float, msgspec.Meta(ge=0, le=508e-6)] | None = None
    """Servo ports only: the servos' Return Delay Time (Dynamixel 9, Feetech 7), in seconds
    (0 .. 508e-6, 2 us units; factory setting 500e-6 on both; LeRobot sets its STS3215s to
    0). Default 500e-6."""
    timeout_margin: Annotated[float, msgspec.Meta(gt=0)] | None = None
    """Dynamixel only: seconds added to a reply's transfer time and the return delays before
    it counts as lost (USB adapter latency: with an FTDI adapter at its 16 ms latency timer,
    more than 0.016). Default 0.02."""
    retries: Annotated[int, msgspec.Meta(ge=0)] | None = None
    """Dynamixel only: how many times a request whose replies were lost is sent again before
    the request fails. Default 2."""
    calibration: Annotated[str, msgspec.Meta(min_length=1)] | None = None
    """Feetech only: the calibration file ``openel-async calibrate`` writes (a relative path:
    relative to the rig file's directory, see :meth:`SerialBusKind.resolve_paths`): each
    servo's homing offset, range and drive mode, by component name."""


def read_calibration(path: str) -> CalibrationFile:
    """The calibration file at ``path``; BadParameterError (located in the file) when refused."""
    try:
        return load_calibration(path)
    except DocumentError as exc:
        raise relocate(BadParameterError("calibration", path, exc.message), exc) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise BadParameterError(
            "calibration", path, f"a readable calibration file ({exc})"
        ) from None


def _calibration_of(
    calibration: CalibrationFile, path: str, device: SimulatedDevice
) -> JointCalibration:
    entry = calibration.joints.get(device.name)
    if entry is None:
        raise BadParameterError(
            "calibration",
            path,
            f"a calibration file with an entry for {device.name} (run openel-async calibrate)",
        )
    servo_id = device.params.get("servo_id")
    if entry.id != servo_id:
        raise BadParameterError(
            "calibration",
            path,
            f"the calibration of {device.name}'s servo {servo_id} (the file's is of servo "
            f"{entry.id}: run openel-async calibrate)",
        )
    return entry


def _servo_ids(
    devices: Sequence[SimulatedDevice], protocol: str = "dynamixel"
) -> dict[int, SimulatedDevice]:
    """The servos by id; BadParameterError on an id out of range or given twice."""
    key, max_id = _ADDRESS_KEY[protocol], _MAX_ID[protocol]
    ids: dict[int, SimulatedDevice] = {}
    for d in devices:
        servo_id = d.params.get(key)
        if (
            not isinstance(servo_id, int)
            or isinstance(servo_id, bool)
            or not 0 <= servo_id <= max_id
        ):
            raise BadParameterError(
                f"{d.name}.params.{key}", servo_id, f"a servo id in 0..{max_id}"
            )
        if servo_id in ids:
            raise BadParameterError(
                f"{d.name}.params.{key}",
                servo_id,
                f"an id of its own ({ids[servo_id].name} has it)",
            )
        ids[servo_id] = d
    return ids


def _port_arguments(options: SerialBusOptions) -> dict[str, Any]:
    """The :class:`DynamixelPort` tuning the options give (the others keep its defaults)."""
    return {k: v for k in DYNAMIXEL_ONLY if (v := getattr(options, k)) is not None}


class SerialBusKind(BusKind):
    """``type: serial`` (see the module docstring)."""

    options_type = SerialBusOptions

    def resolve_paths(self, options: Any, base: Path) -> SerialBusOptions:
        """``options`` with a relative ``calibration:`` path made relative to ``base`` (the
        directory of the rig file the options come from), so that the file is found from
        any current directory."""
        assert isinstance(options, SerialBusOptions)
        path = options.calibration
        if path is None or Path(path).is_absolute():
            return options
        return msgspec.structs.replace(options, calibration=str(base / path))

    def check(self, options: Any, devices: Sequence[SimulatedDevice]) -> None:
        assert isinstance(options, SerialBusOptions)
        protocol = options.protocol
        servos = protocol != "nmea"
        wanted = {"dynamixel": SERVO_MODELS, "feetech": FEETECH_MODELS}.get(protocol, GPS_DEVICES)
        for d in devices:
            if d.device not in wanted:
                raise BadParameterError(
                    f"{d.name}.device",
                    d.device,
                    f"a {options.protocol} device ({', '.join(sorted(wanted))}): the bus "
                    f"carries {options.protocol}",
                )
        rates = {"dynamixel": DYNAMIXEL_BAUDRATES, "feetech": FEETECH_BAUDRATES}.get(
            protocol, NMEA_BAUDRATES
        )
        if options.baudrate not in rates:
            what = {
                "dynamixel": "a Dynamixel X baud rate",
                "feetech": "a Feetech STS baud rate",
            }.get(protocol, "a GPS receiver's baud rate")
            raise BadParameterError(
                "baudrate", options.baudrate, f"{what}: {', '.join(map(str, rates))}"
            )
        for key in ("poll_period", "timeout_margin"):
            value = getattr(options, key)
            if value is not None and not math.isfinite(value):
                raise BadParameterError(key, value, "a finite number of seconds")
        if options.calibration is not None:
            if protocol != "feetech":
                raise BadParameterError(
                    "calibration", options.calibration, "only with protocol: feetech"
                )
            if Path(options.calibration).exists():
                calibration = read_calibration(options.calibration)
                for d in devices:
                    _calibration_of(calibration, options.calibration, d)
        if servos:
            _servo_ids(devices, protocol)
            return
        for key in DYNAMIXEL_ONLY:
            value = getattr(options, key)
            if value is not None:
                raise BadParameterError(key, value, "only with protocol: dynamixel or feetech")
        if len(devices) > 1:
            names = ", ".join(d.name for d in devices)
            raise BadParameterError(
                f"{devices[1].name}.bus", names, "one GPS receiver per NMEA port"
            )

    def describe(self, options: Any) -> str:
        assert isinstance(options, SerialBusOptions)
        what = {"dynamixel": "Dynamixel 2.0", "feetech": "Feetech STS"}.get(
            options.protocol, "NMEA 0183"
        )
        return f"serial {options.device} at {options.baudrate} baud, {what}"

    def open(self, name: str, options: Any) -> AbstractAsyncContextManager[object]:
        assert isinstance(options, SerialBusOptions)
        if options.protocol == "dynamixel":
            return DynamixelPort(
                options.device, baudrate=options.baudrate, **_port_arguments(options)
            )
        if options.protocol == "feetech":
            if options.calibration is not None and not Path(options.calibration).exists():
                raise BadParameterError(
                    "calibration",
                    options.calibration,
                    "a calibration file: run 'openel-async calibrate RIG.yaml' first",
                )
            return FeetechPort(
                options.device, baudrate=options.baudrate, **_port_arguments(options)
            )
        return _nothing(options)  # the GPS device opens its port itself

    def device_arguments(
        self, bus: object, options: Any, device: SimulatedDevice
    ) -> Mapping[str, Any]:
        assert isinstance(options, SerialBusOptions)
        if options.protocol == "feetech" and options.calibration is not None:
            # rig check asks with a placeholder bus (the file may not be written yet)
            path = options.calibration
            entry = (
                _calibration_of(read_calibration(path), path, device)
                if Path(path).exists()
                else None
            )
            return {"port": bus, "calibration": entry}
        if options.protocol != "nmea":
            return {"port": bus}
        return {"url": options.device, "baudrate": options.baudrate}

    def monitor(self, args: Any, name: str, bus: Any) -> int:
        """``openel-async bus monitor`` on this bus (the command's parsed ``args``; ``bus``:
        the rig's resolved entry): :func:`openel_serial.monitor_cmd.run`, the exit status."""
        from .monitor_cmd import run

        return run(args, name, bus)

    def parameter_access(
        self, bus: object, options: Any, device: SimulatedDevice
    ) -> ParameterAccess | None:
        """A Dynamixel's or a Feetech servo's control table (:mod:`openel_serial.params_servo`)."""
        from .params_servo import ServoParameters

        if isinstance(bus, DynamixelPort):
            xl430 = device.device == "dynamixel_xl430_w250"
            return ServoParameters.dynamixel(bus, int(device.params["dxl_id"]), current=not xl430)
        if isinstance(bus, FeetechPort):
            return ServoParameters.sts(bus, int(device.params["servo_id"]))
        return None

    def simulate(
        self, name: str, options: Any, devices: Sequence[SimulatedDevice]
    ) -> AbstractAsyncContextManager[SimulatedBus]:
        assert isinstance(options, SerialBusOptions)
        self.check(options, devices)
        entries: dict[int, JointCalibration] = {}
        note = ""
        path = options.calibration
        if path is not None and Path(path).exists():
            calibration = read_calibration(path)
            for d in devices:
                entries[d.params["servo_id"]] = _calibration_of(calibration, path, d)
            note = f", calibrated as {path}"
        elif path is not None:
            options = msgspec.structs.replace(options, calibration=None)
            note = f" ({path} absent: uncalibrated)"
        return _simulated(options, devices, entries, note)


@asynccontextmanager
async def _nothing(options: SerialBusOptions) -> AsyncIterator[object]:
    yield options


@asynccontextmanager
async def _simulated(
    options: SerialBusOptions,
    devices: Sequence[SimulatedDevice],
    entries: Mapping[int, JointCalibration],
    note: str,
) -> AsyncIterator[SimulatedBus]:
    from .feetech_peers import SimFeetechBus, SimStsServo
    from .peers import PeerThread, SimDynamixelBus, SimGps, SimServo

    peer: SimDynamixelBus | SimFeetechBus | SimGps
    if options.protocol == "dynamixel":
        ids = _servo_ids(devices)
        return_delay = _port_arguments(options).get("return_delay", DEFAULT_RETURN_DELAY)
        servos = {
            i: SimServo(
                i,
                model_number=SERVO_MODELS[d.device],
                baud_rate=DYNAMIXEL_BAUDRATES.index(options.baudrate),
                return_delay_time=round(return_delay / dx.RETURN_DELAY_UNIT_S),
            )
            for i, d in ids.items()
        }
        peer = SimDynamixelBus(servos.values(), check_baudrate=True)
        by_name: dict[str, object] = {d.name: servos[i] for i, d in ids.items()}
        what = f"simulated Dynamixel servos {', '.join(map(str, sorted(ids)))}"
    elif options.protocol == "feetech":
        ids = _servo_ids(devices, "feetech")
        return_delay = _port_arguments(options).get("return_delay", FEETECH_RETURN_DELAY)
        sts = {
            i: SimStsServo(
                i,
                model_number=FEETECH_MODELS[d.device],
                baud_rate=FEETECH_BAUDRATES.index(options.baudrate),
                return_delay=round(return_delay / ft.RETURN_DELAY_UNIT_S),
                **_sim_calibration(entries.get(i)),
            )
            for i, d in ids.items()
        }
        peer = SimFeetechBus(sts.values(), check_baudrate=True)
        by_name = {d.name: sts[i] for i, d in ids.items()}
        what = f"simulated Feetech STS3215 servos {', '.join(map(str, sorted(ids)))}"
        what += note
    else:
        peer = SimGps(baudrate=options.baudrate)
        by_name = {d.name: peer for d in devices}
        what = "a simulated NMEA receiver"
    async with PeerThread(peer):
        yield SimulatedBus(
            msgspec.structs.replace(options, device=peer.path),
            f"pty {peer.path} at {options.baudrate} baud with {what}",
            by_name,
        )


def _sim_calibration(entry: JointCalibration | None) -> dict[str, Any]:
    """A simulated servo calibrated as ``entry``: its EEPROM, its rotor in the middle."""
    if entry is None:
        return {}
    middle = (entry.range_min + entry.range_max) // 2
    return {
        "homing_offset": entry.homing_offset,
        "min_angle": entry.range_min,
        "max_angle": entry.range_max,
        "position": middle + entry.homing_offset,
    }
