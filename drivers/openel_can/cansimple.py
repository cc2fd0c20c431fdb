"""ODrive CANSimple codec (firmware 0.6.x), pure and byte-exact.

Frame layout (ODrive docs "CAN Protocol", odrive-cansimple-0.6.x DBC):

* 11-bit arbitration id = ``node_id << 5 | cmd_id`` (node 0..0x3F, cmd 0..0x1F);
* little-endian payloads; every data message is 8 bytes long except Reboot
  and Clear_Errors (1 byte) and Estop / Enter_DFU (no data), as the DBC says;
* ``Get_*`` messages and the Heartbeat are requested by the host with a remote
  (RTR) frame on the same id; those requests are modelled by :class:`Request`.

The same command id carries different payloads per direction, so
:func:`decode` needs ``from_host``. Malformed frames raise
:class:`~openel_can.errors.CanSimpleDecodeError` and nothing else; encoders
raise :class:`ValueError` for values that do not fit the wire format.

Enumerated fields (axis state, control and input mode, reboot action, SDO opcode) hold
the enum member when this codec knows the value and the plain ``int`` otherwise: newer
firmware adds values (0.6.11 reports axis states 15 and 16), and a frame carrying one is
a valid frame, not a malformed one. :func:`value_name` names either.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, fields
from enum import IntEnum
from typing import Any, ClassVar, Final, Self, TypeVar

from openel_can.errors import CanSimpleDecodeError

__all__ = [
    "BROADCAST_NODE_ID",
    "FF_SCALE",
    "MAX_NODE_ID",
    "Address",
    "AxisState",
    "BusVoltageCurrent",
    "CanSimpleDecodeError",
    "CanSimpleMessage",
    "ClearErrors",
    "CmdId",
    "ControlMode",
    "EncoderEstimates",
    "EnterDfu",
    "ErrorStatus",
    "Estop",
    "Heartbeat",
    "InputMode",
    "Iq",
    "Powers",
    "ProcedureResult",
    "Reboot",
    "RebootAction",
    "Request",
    "RxSdo",
    "SdoOpcode",
    "SetAbsolutePosition",
    "SetAxisState",
    "SetControllerMode",
    "SetInputPos",
    "SetInputTorque",
    "SetInputVel",
    "SetLimits",
    "SetPosGain",
    "SetTrajAccelLimits",
    "SetTrajInertia",
    "SetTrajVelLimit",
    "SetVelGains",
    "Temperature",
    "Torques",
    "TxSdo",
    "Version",
    "arbitration_id",
    "decode",
    "encode",
    "split_arbitration_id",
    "value_name",
]

MAX_NODE_ID: Final = 0x3F
#: Unaddressed / broadcast node id (used for Address discovery).
BROADCAST_NODE_ID: Final = 0x3F
_MAX_ARB_ID: Final = 0x7FF
_MAX_DLC: Final = 8
#: Set_Input_Pos feed-forward terms travel as int16 with this factor.
FF_SCALE: Final = 0.001


class CmdId(IntEnum):
    GET_VERSION = 0x00
    HEARTBEAT = 0x01
    ESTOP = 0x02
    GET_ERROR = 0x03
    RX_SDO = 0x04
    TX_SDO = 0x05
    ADDRESS = 0x06
    SET_AXIS_STATE = 0x07
    GET_ENCODER_ESTIMATES = 0x09
    SET_CONTROLLER_MODE = 0x0B
    SET_INPUT_POS = 0x0C
    SET_INPUT_VEL = 0x0D
    SET_INPUT_TORQUE = 0x0E
    SET_LIMITS = 0x0F
    SET_TRAJ_VEL_LIMIT = 0x11
    SET_TRAJ_ACCEL_LIMITS = 0x12
    SET_TRAJ_INERTIA = 0x13
    GET_IQ = 0x14
    GET_TEMPERATURE = 0x15
    REBOOT = 0x16
    GET_BUS_VOLTAGE_CURRENT = 0x17
    CLEAR_ERRORS = 0x18
    SET_ABSOLUTE_POSITION = 0x19
    SET_POS_GAIN = 0x1A
    SET_VEL_GAINS = 0x1B
    GET_TORQUES = 0x1C
    GET_POWERS = 0x1D
    ENTER_DFU = 0x1F


class AxisState(IntEnum):
    UNDEFINED = 0
    IDLE = 1
    STARTUP_SEQUENCE = 2
    FULL_CALIBRATION_SEQUENCE = 3
    MOTOR_CALIBRATION = 4
    SENSORLESS_CONTROL = 5  # firmware 0.5 only; still listed in the 0.6 DBC
    ENCODER_INDEX_SEARCH = 6
    ENCODER_OFFSET_CALIBRATION = 7
    CLOSED_LOOP_CONTROL = 8
    LOCKIN_SPIN = 9
    ENCODER_DIR_FIND = 10
    HOMING = 11
    ENCODER_HALL_POLARITY_CALIBRATION = 12
    ENCODER_HALL_PHASE_CALIBRATION = 13
    ANTICOGGING_CALIBRATION = 14


class ControlMode(IntEnum):
    VOLTAGE = 0
    TORQUE = 1
    VELOCITY = 2
    POSITION = 3


class InputMode(IntEnum):
    INACTIVE = 0
    PASSTHROUGH = 1
    VEL_RAMP = 2
    POS_FILTER = 3
    MIX_CHANNELS = 4
    TRAP_TRAJ = 5
    TORQUE_RAMP = 6
    MIRROR = 7
    TUNING = 8


class ProcedureResult(IntEnum):
    """Heartbeat ``procedure_result`` values (kept as a plain int in the message)."""

    SUCCESS = 0
    BUSY = 1
    CANCELLED = 2
    DISARMED = 3
    NO_RESPONSE = 4
    POLE_PAIR_CPR_MISMATCH = 5
    PHASE_RESISTANCE_OUT_OF_RANGE = 6
    PHASE_INDUCTANCE_OUT_OF_RANGE = 7
    UNBALANCED_PHASES = 8
    INVALID_MOTOR_TYPE = 9
    ILLEGAL_HALL_STATE = 10
    TIMEOUT = 11
    HOMING_WITHOUT_ENDSTOP = 12
    INVALID_STATE = 13
    NOT_CALIBRATED = 14
    NOT_CONVERGING = 15


class RebootAction(IntEnum):
    REBOOT = 0
    SAVE_CONFIGURATION = 1
    ERASE_CONFIGURATION = 2
    ENTER_DFU = 3


class SdoOpcode(IntEnum):
    READ = 0
    WRITE = 1


_E = TypeVar("_E", bound=IntEnum)


def _enum_or_int(enum_type: type[_E], value: int) -> _E | int:
    """The enum member for ``value``, or the plain int when the enum does not know it."""
    if not isinstance(value, int):
        raise ValueError(f"{enum_type.__name__} value must be an int, got {value!r}")
    try:
        return enum_type(value)
    except ValueError:
        return int(value)


def value_name(value: int) -> str:
    """``name`` of an enum member, ``"unknown (n)"`` for a value kept as a plain int."""
    return value.name if isinstance(value, IntEnum) else f"unknown ({int(value)})"


def arbitration_id(node_id: int, cmd: CmdId) -> int:
    """``node_id << 5 | cmd``; raises :class:`ValueError` for a node id outside 0..0x3F."""
    if not 0 <= node_id <= MAX_NODE_ID:
        raise ValueError(f"node_id {node_id} outside 0..{MAX_NODE_ID}")
    return node_id << 5 | int(cmd)


_CMD_BY_VALUE: Final = {int(cmd): cmd for cmd in CmdId}


def split_arbitration_id(arb_id: int) -> tuple[int, CmdId]:
    """Inverse of :func:`arbitration_id`; unknown command ids are a decode error."""
    if not 0 <= arb_id <= _MAX_ARB_ID:
        raise CanSimpleDecodeError(f"arbitration id {arb_id:#x} is not an 11-bit id")
    cmd = _CMD_BY_VALUE.get(arb_id & 0x1F)
    if cmd is None:
        raise CanSimpleDecodeError(f"unknown CANSimple command {arb_id & 0x1F:#04x}")
    return arb_id >> 5, cmd


def _pack(fmt: str, *values: Any) -> bytes:
    # struct reports out-of-range values as struct.error/OverflowError; callers
    # only need to know the value does not fit the wire format.
    try:
        return struct.pack(fmt, *values)
    except (struct.error, OverflowError) as exc:
        raise ValueError(f"value does not fit CANSimple field ({fmt}): {exc}") from exc


def _check_sdo_value(value: bytes) -> None:
    # struct's "4s" would silently pad or truncate; the value field is exactly 4 bytes.
    if len(value) != 4:
        raise ValueError(f"SDO value must be exactly 4 bytes, got {len(value)}")


@dataclass(frozen=True)
class CanSimpleMessage:
    """Base of every CANSimple message; ``node_id`` is the arbitration node id."""

    node_id: int

    _CMD: ClassVar[CmdId]
    _FMT: ClassVar[str] = "<"
    _DLC: ClassVar[int] = _MAX_DLC
    #: Enum types the raw unpacked integers are coerced to, by field name (values the
    #: enum does not know stay plain ints).
    _ENUMS: ClassVar[tuple[tuple[str, type[IntEnum]], ...]] = ()

    def __post_init__(self) -> None:
        if not 0 <= self.node_id <= MAX_NODE_ID:
            raise ValueError(f"node_id {self.node_id} outside 0..{MAX_NODE_ID}")
        for name, enum_type in self._ENUMS:
            object.__setattr__(self, name, _enum_or_int(enum_type, getattr(self, name)))

    @property
    def cmd(self) -> CmdId:
        return self._CMD

    def payload(self) -> bytes:
        values = [getattr(self, f.name) for f in fields(self)[1:]]
        return _pack(self._FMT, *values).ljust(self._DLC, b"\x00")

    @classmethod
    def from_payload(cls, node_id: int, data: bytes) -> Self:
        need = struct.calcsize(cls._FMT)
        if len(data) < need:
            raise CanSimpleDecodeError(f"{cls.__name__} needs {need} bytes, got {len(data)}")
        return cls(node_id, *struct.unpack_from(cls._FMT, data))


@dataclass(frozen=True)
class Request(CanSimpleMessage):
    """Host request for a ``Get_*``/Heartbeat/Address message: send as a remote frame."""

    cmd_id: CmdId

    _DLC: ClassVar[int] = 0

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "cmd_id", CmdId(self.cmd_id))
        if self.cmd_id not in _REQUESTABLE:
            raise ValueError(f"{self.cmd_id.name} cannot be requested")

    @property
    def cmd(self) -> CmdId:
        return self.cmd_id

    def payload(self) -> bytes:
        return b""


# --- ODrive -> host -----------------------------------------------------------------------


@dataclass(frozen=True)
class Version(CanSimpleMessage):
    protocol_version: int
    hw_version_major: int
    hw_version_minor: int
    hw_version_variant: int
    fw_version_major: int
    fw_version_minor: int
    fw_version_revision: int
    fw_version_unreleased: int

    _CMD = CmdId.GET_VERSION
    _FMT = "<8B"


@dataclass(frozen=True)
class Heartbeat(CanSimpleMessage):
    axis_error: int
    axis_state: AxisState | int
    procedure_result: int
    trajectory_done: bool = False

    _CMD = CmdId.HEARTBEAT
    _FMT = "<IBBB"
    _ENUMS = (("axis_state", AxisState),)

    def payload(self) -> bytes:
        raw = _pack(
            self._FMT,
            self.axis_error,
            self.axis_state,
            self.procedure_result,
            int(self.trajectory_done),
        )
        return raw.ljust(self._DLC, b"\x00")

    @classmethod
    def from_payload(cls, node_id: int, data: bytes) -> Self:
        if len(data) < 7:
            raise CanSimpleDecodeError(f"Heartbeat needs 7 bytes, got {len(data)}")
        error, state, result, flags = struct.unpack_from(cls._FMT, data)
        # Only bit 0 of byte 6 is defined (Trajectory_Done_Flag); ignore the rest.
        return cls(node_id, error, state, result, bool(flags & 0x01))


@dataclass(frozen=True)
class ErrorStatus(CanSimpleMessage):
    """Reply to Get_Error."""

    active_errors: int
    disarm_reason: int

    _CMD = CmdId.GET_ERROR
    _FMT = "<II"


@dataclass(frozen=True)
class TxSdo(CanSimpleMessage):
    """Endpoint read reply; ``value`` is the raw 4-byte little-endian value field."""

    endpoint_id: int
    value: bytes = bytes(4)

    _CMD = CmdId.TX_SDO
    _FMT = "<xHx4s"

    def __post_init__(self) -> None:
        super().__post_init__()
        _check_sdo_value(self.value)


@dataclass(frozen=True)
class Address(CanSimpleMessage):
    """Address reply (ODrive -> host) or node id assignment (host -> ODrive).

    ``payload_node_id`` is the Node_ID signal carried in the data (the arbitration
    node of an assignment is usually :data:`BROADCAST_NODE_ID`).
    """

    payload_node_id: int
    serial_number: int

    _CMD = CmdId.ADDRESS
    _FMT = "<B6s"

    def payload(self) -> bytes:
        if not isinstance(self.serial_number, int):
            raise TypeError(f"serial_number must be an int, got {self.serial_number!r}")
        if not 0 <= self.serial_number < 1 << 48:
            raise ValueError("serial_number must fit 48 bits")
        return _pack(
            self._FMT, self.payload_node_id, self.serial_number.to_bytes(6, "little")
        ).ljust(self._DLC, b"\x00")

    @classmethod
    def from_payload(cls, node_id: int, data: bytes) -> Self:
        if len(data) < 7:
            raise CanSimpleDecodeError(f"Address needs 7 bytes, got {len(data)}")
        return cls(node_id, data[0], int.from_bytes(data[1:7], "little"))


@dataclass(frozen=True)
class EncoderEstimates(CanSimpleMessage):
    pos: float  # rev
    vel: float  # rev/s

    _CMD = CmdId.GET_ENCODER_ESTIMATES
    _FMT = "<ff"


@dataclass(frozen=True)
class Iq(CanSimpleMessage):
    setpoint: float  # A
    measured: float  # A

    _CMD = CmdId.GET_IQ
    _FMT = "<ff"


@dataclass(frozen=True)
class Temperature(CanSimpleMessage):
    fet: float  # degC
    motor: float  # degC

    _CMD = CmdId.GET_TEMPERATURE
    _FMT = "<ff"


@dataclass(frozen=True)
class BusVoltageCurrent(CanSimpleMessage):
    voltage: float  # V
    current: float  # A

    _CMD = CmdId.GET_BUS_VOLTAGE_CURRENT
    _FMT = "<ff"


@dataclass(frozen=True)
class Torques(CanSimpleMessage):
    target: float  # Nm
    estimate: float  # Nm

    _CMD = CmdId.GET_TORQUES
    _FMT = "<ff"


@dataclass(frozen=True)
class Powers(CanSimpleMessage):
    electrical: float  # W
    mechanical: float  # W

    _CMD = CmdId.GET_POWERS
    _FMT = "<ff"


# --- host -> ODrive -----------------------------------------------------------------------


@dataclass(frozen=True)
class Estop(CanSimpleMessage):
    _CMD = CmdId.ESTOP
    _DLC = 0

    @classmethod
    def from_payload(cls, node_id: int, data: bytes) -> Self:
        return cls(node_id)  # the ODrive ignores any data


@dataclass(frozen=True)
class EnterDfu(CanSimpleMessage):
    _CMD = CmdId.ENTER_DFU
    _DLC = 0

    @classmethod
    def from_payload(cls, node_id: int, data: bytes) -> Self:
        return cls(node_id)


@dataclass(frozen=True)
class RxSdo(CanSimpleMessage):
    """Endpoint access; ``value`` is the raw 4-byte little-endian value field."""

    opcode: SdoOpcode | int
    endpoint_id: int
    value: bytes = bytes(4)

    _CMD = CmdId.RX_SDO
    _FMT = "<BHx4s"
    _ENUMS = (("opcode", SdoOpcode),)

    def __post_init__(self) -> None:
        super().__post_init__()
        _check_sdo_value(self.value)


@dataclass(frozen=True)
class SetAxisState(CanSimpleMessage):
    state: AxisState | int

    _CMD = CmdId.SET_AXIS_STATE
    _FMT = "<I"
    _ENUMS = (("state", AxisState),)


@dataclass(frozen=True)
class SetControllerMode(CanSimpleMessage):
    control_mode: ControlMode | int
    input_mode: InputMode | int

    _CMD = CmdId.SET_CONTROLLER_MODE
    _FMT = "<II"
    _ENUMS = (("control_mode", ControlMode), ("input_mode", InputMode))


@dataclass(frozen=True)
class SetInputPos(CanSimpleMessage):
    """Position setpoint; the feed-forwards are quantised to 0.001 rev/s and 0.001 Nm."""

    pos: float  # rev
    vel_ff: float = 0.0  # rev/s
    torque_ff: float = 0.0  # Nm

    _CMD = CmdId.SET_INPUT_POS
    _FMT = "<fhh"

    def payload(self) -> bytes:
        try:
            vel = round(self.vel_ff / FF_SCALE)
            torque = round(self.torque_ff / FF_SCALE)
        except (OverflowError, ValueError) as exc:  # inf / nan
            raise ValueError(f"feed-forward not representable: {exc}") from exc
        return _pack(self._FMT, self.pos, vel, torque)

    @classmethod
    def from_payload(cls, node_id: int, data: bytes) -> Self:
        if len(data) < 8:
            raise CanSimpleDecodeError(f"Set_Input_Pos needs 8 bytes, got {len(data)}")
        pos, vel, torque = struct.unpack_from(cls._FMT, data)
        return cls(node_id, pos, vel * FF_SCALE, torque * FF_SCALE)


@dataclass(frozen=True)
class SetInputVel(CanSimpleMessage):
    vel: float  # rev/s
    torque_ff: float = 0.0  # Nm

    _CMD = CmdId.SET_INPUT_VEL
    _FMT = "<ff"


@dataclass(frozen=True)
class SetInputTorque(CanSimpleMessage):
    torque: float  # Nm

    _CMD = CmdId.SET_INPUT_TORQUE
    _FMT = "<f"


@dataclass(frozen=True)
class SetLimits(CanSimpleMessage):
    velocity_limit: float  # rev/s
    current_limit: float  # A

    _CMD = CmdId.SET_LIMITS
    _FMT = "<ff"


@dataclass(frozen=True)
class SetTrajVelLimit(CanSimpleMessage):
    vel_limit: float  # rev/s

    _CMD = CmdId.SET_TRAJ_VEL_LIMIT
    _FMT = "<f"


@dataclass(frozen=True)
class SetTrajAccelLimits(CanSimpleMessage):
    accel_limit: float  # rev/s^2
    decel_limit: float  # rev/s^2

    _CMD = CmdId.SET_TRAJ_ACCEL_LIMITS
    _FMT = "<ff"


@dataclass(frozen=True)
class SetTrajInertia(CanSimpleMessage):
    inertia: float  # Nm/(rev/s^2)

    _CMD = CmdId.SET_TRAJ_INERTIA
    _FMT = "<f"


@dataclass(frozen=True)
class Reboot(CanSimpleMessage):
    action: RebootAction | int = RebootAction.REBOOT

    _CMD = CmdId.REBOOT
    _FMT = "<B"
    _DLC = 1
    _ENUMS = (("action", RebootAction),)

    @classmethod
    def from_payload(cls, node_id: int, data: bytes) -> Self:
        # Pre-0.6.9 hosts send Reboot without data, which means a plain reboot.
        return cls(node_id) if not data else super().from_payload(node_id, data)


@dataclass(frozen=True)
class ClearErrors(CanSimpleMessage):
    identify: bool = False

    _CMD = CmdId.CLEAR_ERRORS
    _FMT = "<?"
    _DLC = 1

    @classmethod
    def from_payload(cls, node_id: int, data: bytes) -> Self:
        return cls(node_id, bool(data[0])) if data else cls(node_id)


@dataclass(frozen=True)
class SetAbsolutePosition(CanSimpleMessage):
    position: float  # rev

    _CMD = CmdId.SET_ABSOLUTE_POSITION
    _FMT = "<f"


@dataclass(frozen=True)
class SetPosGain(CanSimpleMessage):
    pos_gain: float  # (rev/s)/rev

    _CMD = CmdId.SET_POS_GAIN
    _FMT = "<f"


@dataclass(frozen=True)
class SetVelGains(CanSimpleMessage):
    vel_gain: float  # Nm/(rev/s)
    vel_integrator_gain: float  # Nm/rev

    _CMD = CmdId.SET_VEL_GAINS
    _FMT = "<ff"


_AXIS_TO_HOST: Final[dict[CmdId, type[CanSimpleMessage]]] = {
    cls._CMD: cls
    for cls in (
        Version,
        Heartbeat,
        ErrorStatus,
        TxSdo,
        Address,
        EncoderEstimates,
        Iq,
        Temperature,
        BusVoltageCurrent,
        Torques,
        Powers,
    )
}
_HOST_TO_AXIS: Final[dict[CmdId, type[CanSimpleMessage]]] = {
    cls._CMD: cls
    for cls in (
        Estop,
        RxSdo,
        Address,
        SetAxisState,
        SetControllerMode,
        SetInputPos,
        SetInputVel,
        SetInputTorque,
        SetLimits,
        SetTrajVelLimit,
        SetTrajAccelLimits,
        SetTrajInertia,
        Reboot,
        ClearErrors,
        SetAbsolutePosition,
        SetPosGain,
        SetVelGains,
        EnterDfu,
    )
}
# Everything the ODrive transmits except TxSdo (an answer to RxSdo) can be polled by RTR.
_REQUESTABLE: Final = frozenset(_AXIS_TO_HOST) - {CmdId.TX_SDO}


def encode(msg: CanSimpleMessage) -> tuple[int, bytes]:
    """Return ``(arbitration_id, data)``; a :class:`Request` gives empty data (send as RTR)."""
    return arbitration_id(msg.node_id, msg.cmd), msg.payload()


def decode(
    arb_id: int, data: bytes | bytearray, *, from_host: bool, remote: bool = False
) -> CanSimpleMessage:
    """Decode one frame.

    ``from_host`` selects the payload direction (True: host -> ODrive).
    A remote frame from the host, or an empty frame from the host on an id the
    host never sends data on, decodes to :class:`Request`. Trailing padding up
    to 8 bytes is ignored. Raises only :class:`CanSimpleDecodeError`.
    """
    if len(data) > _MAX_DLC:
        raise CanSimpleDecodeError(f"classic CAN frame carries at most 8 bytes, got {len(data)}")
    node_id, cmd = split_arbitration_id(arb_id)
    if from_host:
        if cmd in _REQUESTABLE and (remote or (cmd not in _HOST_TO_AXIS and not data)):
            return Request(node_id, cmd)
        cls = _HOST_TO_AXIS.get(cmd)
    else:
        cls = None if remote else _AXIS_TO_HOST.get(cmd)
    if cls is None or remote:
        sender = "host" if from_host else "ODrive"
        kind = "remote frame" if remote else "data frame"
        raise CanSimpleDecodeError(f"{cmd.name} is not a {kind} sent by the {sender}")
    try:
        return cls.from_payload(node_id, bytes(data))
    except CanSimpleDecodeError:
        raise
    except ValueError as exc:  # enum coercion of an unknown state/mode value
        raise CanSimpleDecodeError(f"{cmd.name}: {exc}") from exc
