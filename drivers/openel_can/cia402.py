"""CiA 402 (IEC 61800-7-201) drive power state machine as pure logic.

Host side: :class:`Statusword` decoding and :func:`next_controlword`, which
walks the standard transition path toward a target state. Device side (the
simulated drive): :func:`apply_controlword`. Also the modes of operation and
the object dictionary entries a CiA 402 master uses.

Statuswords whose state bits match no state raise
:class:`~openel_can.errors.Cia402DecodeError`.
"""

from __future__ import annotations

import functools
import operator
from collections import deque
from dataclasses import dataclass
from enum import IntEnum, IntFlag
from typing import Final

from openel_can.canopen import DataType, ObjectEntry
from openel_can.errors import Cia402DecodeError

__all__ = [
    "CONTROLWORD",
    "ERROR_CODE",
    "HOME_OFFSET",
    "HOMING_METHOD",
    "MAX_MOTOR_SPEED",
    "MAX_TORQUE",
    "MODES_OF_OPERATION",
    "MODES_OF_OPERATION_DISPLAY",
    "MOTOR_RATED_TORQUE",
    "POSITION_ACTUAL_VALUE",
    "POSITION_ENCODER_INCREMENTS",
    "POSITION_ENCODER_MOTOR_REVOLUTIONS",
    "PROFILE_ACCELERATION",
    "PROFILE_DECELERATION",
    "PROFILE_VELOCITY",
    "QUICK_STOP_DECELERATION",
    "QUICK_STOP_OPTION_CODE",
    "SOFTWARE_POSITION_LIMIT_MAX",
    "SOFTWARE_POSITION_LIMIT_MIN",
    "STATUSWORD",
    "SUPPORTED_DRIVE_MODES",
    "TARGET_POSITION",
    "TARGET_TORQUE",
    "TARGET_VELOCITY",
    "TORQUE_ACTUAL_VALUE",
    "VELOCITY_ACTUAL_VALUE",
    "Cia402DecodeError",
    "Command",
    "ControlBit",
    "ModeOfOperation",
    "PowerState",
    "StatusBit",
    "Statusword",
    "apply_controlword",
    "controlword",
    "decode_command",
    "next_controlword",
    "state_from_statusword",
]


class StatusBit(IntFlag):
    """Statusword (0x6041) bits."""

    READY_TO_SWITCH_ON = 1 << 0
    SWITCHED_ON = 1 << 1
    OPERATION_ENABLED = 1 << 2
    FAULT = 1 << 3
    VOLTAGE_ENABLED = 1 << 4
    QUICK_STOP = 1 << 5  # active low: 0 means a quick stop is in progress
    SWITCH_ON_DISABLED = 1 << 6
    WARNING = 1 << 7
    REMOTE = 1 << 9
    TARGET_REACHED = 1 << 10
    INTERNAL_LIMIT_ACTIVE = 1 << 11
    SETPOINT_ACKNOWLEDGE = 1 << 12  # mode specific: pp set-point ack, homing attained, ...
    FOLLOWING_ERROR = 1 << 13  # mode specific: pp/csp following error


class ControlBit(IntFlag):
    """Controlword (0x6040) bits."""

    SWITCH_ON = 1 << 0
    ENABLE_VOLTAGE = 1 << 1
    QUICK_STOP = 1 << 2  # active low: 0 requests a quick stop
    ENABLE_OPERATION = 1 << 3
    NEW_SETPOINT = 1 << 4  # profile position: rising edge latches the target
    CHANGE_SET_IMMEDIATELY = 1 << 5  # profile position
    RELATIVE = 1 << 6  # profile position: target is relative
    FAULT_RESET = 1 << 7  # rising edge
    HALT = 1 << 8


class Command(IntEnum):
    """Device-control commands (bits 0..3, plus bit 7 for fault reset)."""

    DISABLE_VOLTAGE = 0x00
    QUICK_STOP = 0x02
    SHUTDOWN = 0x06
    SWITCH_ON = 0x07
    DISABLE_OPERATION = 0x07  # same bits as SWITCH_ON, used from Operation enabled
    ENABLE_OPERATION = 0x0F
    FAULT_RESET = 0x80


class PowerState(IntEnum):
    """Power states; the value is the state's statusword bit pattern."""

    NOT_READY_TO_SWITCH_ON = 0x00
    SWITCH_ON_DISABLED = 0x40
    READY_TO_SWITCH_ON = 0x21
    SWITCHED_ON = 0x23
    OPERATION_ENABLED = 0x27
    QUICK_STOP_ACTIVE = 0x07
    FAULT_REACTION_ACTIVE = 0x0F
    FAULT = 0x08


# (mask, value) per state, CiA 402 statusword table. States whose quick-stop bit
# is "don't care" use 0x4F, the others 0x6F.
_STATE_PATTERNS: Final = (
    (0x4F, PowerState.NOT_READY_TO_SWITCH_ON),
    (0x4F, PowerState.SWITCH_ON_DISABLED),
    (0x6F, PowerState.READY_TO_SWITCH_ON),
    (0x6F, PowerState.SWITCHED_ON),
    (0x6F, PowerState.OPERATION_ENABLED),
    (0x6F, PowerState.QUICK_STOP_ACTIVE),
    (0x4F, PowerState.FAULT_REACTION_ACTIVE),
    (0x4F, PowerState.FAULT),
)


_STATE_MATCH: Final = tuple((mask, int(state.value), state) for mask, state in _STATE_PATTERNS)
"""(mask, value as a plain int, state): the table above without enum lookups per call."""


def _first_match(bits: int) -> PowerState | None:
    for mask, value, state in _STATE_MATCH:
        if bits & mask == value:
            return state
    return None


_STATE_BITS: Final = functools.reduce(operator.or_, (mask for mask, _, _ in _STATE_MATCH))
"""The union of the table's masks (0x6F): the state depends on these statusword bits only."""
_STATE_OF_BITS: Final = tuple(_first_match(bits) for bits in range(_STATE_BITS + 1))
"""The state of ``statusword & 0x6F`` (None: no state), the table's first match."""


def state_from_statusword(statusword: int) -> PowerState:
    """Map a statusword to its power state; raises :class:`Cia402DecodeError` if none matches."""
    if not 0 <= statusword <= 0xFFFF:
        raise Cia402DecodeError(f"statusword {statusword} is not a u16")
    state = _STATE_OF_BITS[statusword & _STATE_BITS]
    if state is None:
        raise Cia402DecodeError(f"statusword {statusword:#06x} matches no CiA 402 state")
    return state


@dataclass(frozen=True)
class Statusword:
    """A statusword value with named accessors; build one for a state with :meth:`build`."""

    raw: int

    def __post_init__(self) -> None:
        if not 0 <= self.raw <= 0xFFFF:
            raise ValueError(f"statusword {self.raw} is not a u16")

    @classmethod
    def decode(cls, raw: int) -> Statusword:
        """Validate that ``raw`` encodes a state (raises :class:`Cia402DecodeError`)."""
        state_from_statusword(raw)
        return cls(raw)

    @classmethod
    def build(
        cls,
        state: PowerState,
        *,
        voltage_enabled: bool = True,
        warning: bool = False,
        remote: bool = True,
        target_reached: bool = False,
        internal_limit_active: bool = False,
        setpoint_acknowledge: bool = False,
        following_error: bool = False,
    ) -> Statusword:
        flags = (
            (StatusBit.VOLTAGE_ENABLED, voltage_enabled),
            (StatusBit.WARNING, warning),
            (StatusBit.REMOTE, remote),
            (StatusBit.TARGET_REACHED, target_reached),
            (StatusBit.INTERNAL_LIMIT_ACTIVE, internal_limit_active),
            (StatusBit.SETPOINT_ACKNOWLEDGE, setpoint_acknowledge),
            (StatusBit.FOLLOWING_ERROR, following_error),
        )
        raw = int(state)
        for bit, on in flags:
            if on:
                raw |= bit
        return cls(raw)

    def _bit(self, bit: StatusBit) -> bool:
        return bool(self.raw & bit)

    @property
    def state(self) -> PowerState:
        return state_from_statusword(self.raw)

    @property
    def voltage_enabled(self) -> bool:
        return self._bit(StatusBit.VOLTAGE_ENABLED)

    @property
    def warning(self) -> bool:
        return self._bit(StatusBit.WARNING)

    @property
    def remote(self) -> bool:
        return self._bit(StatusBit.REMOTE)

    @property
    def target_reached(self) -> bool:
        return self._bit(StatusBit.TARGET_REACHED)

    @property
    def internal_limit_active(self) -> bool:
        return self._bit(StatusBit.INTERNAL_LIMIT_ACTIVE)

    @property
    def setpoint_acknowledge(self) -> bool:
        return self._bit(StatusBit.SETPOINT_ACKNOWLEDGE)

    @property
    def following_error(self) -> bool:
        return self._bit(StatusBit.FOLLOWING_ERROR)


def controlword(
    command: Command,
    *,
    new_setpoint: bool = False,
    change_set_immediately: bool = False,
    relative: bool = False,
    halt: bool = False,
) -> int:
    """Compose a controlword from a device-control command and the mode-specific bits."""
    word = int(command)
    for bit, on in (
        (ControlBit.NEW_SETPOINT, new_setpoint),
        (ControlBit.CHANGE_SET_IMMEDIATELY, change_set_immediately),
        (ControlBit.RELATIVE, relative),
        (ControlBit.HALT, halt),
    ):
        if on:
            word |= bit
    return word


def decode_command(controlword: int) -> Command:
    """The state-machine command in bits 0..3 (fault reset is handled separately).

    Every bit combination maps to exactly one command, following the "x" (don't
    care) columns of the CiA 402 command table.
    """
    if not controlword & ControlBit.ENABLE_VOLTAGE:
        return Command.DISABLE_VOLTAGE
    if not controlword & ControlBit.QUICK_STOP:
        return Command.QUICK_STOP
    if not controlword & ControlBit.SWITCH_ON:
        return Command.SHUTDOWN
    if not controlword & ControlBit.ENABLE_OPERATION:
        return Command.SWITCH_ON
    return Command.ENABLE_OPERATION


_S = PowerState
_C = Command
# Device transitions triggered by a command, numbered as in CiA 402.
_TRANSITIONS: Final[dict[tuple[PowerState, Command], PowerState]] = {
    (_S.SWITCH_ON_DISABLED, _C.SHUTDOWN): _S.READY_TO_SWITCH_ON,  # 2
    (_S.READY_TO_SWITCH_ON, _C.SWITCH_ON): _S.SWITCHED_ON,  # 3
    # "Switch on + enable operation": 3 then the automatic 4.
    (_S.READY_TO_SWITCH_ON, _C.ENABLE_OPERATION): _S.OPERATION_ENABLED,
    (_S.SWITCHED_ON, _C.ENABLE_OPERATION): _S.OPERATION_ENABLED,  # 4
    (_S.OPERATION_ENABLED, _C.DISABLE_OPERATION): _S.SWITCHED_ON,  # 5
    (_S.SWITCHED_ON, _C.SHUTDOWN): _S.READY_TO_SWITCH_ON,  # 6
    (_S.READY_TO_SWITCH_ON, _C.DISABLE_VOLTAGE): _S.SWITCH_ON_DISABLED,  # 7
    (_S.READY_TO_SWITCH_ON, _C.QUICK_STOP): _S.SWITCH_ON_DISABLED,  # 7
    (_S.OPERATION_ENABLED, _C.SHUTDOWN): _S.READY_TO_SWITCH_ON,  # 8
    (_S.OPERATION_ENABLED, _C.DISABLE_VOLTAGE): _S.SWITCH_ON_DISABLED,  # 9
    (_S.SWITCHED_ON, _C.DISABLE_VOLTAGE): _S.SWITCH_ON_DISABLED,  # 10
    (_S.SWITCHED_ON, _C.QUICK_STOP): _S.SWITCH_ON_DISABLED,  # 10
    (_S.OPERATION_ENABLED, _C.QUICK_STOP): _S.QUICK_STOP_ACTIVE,  # 11
    (_S.QUICK_STOP_ACTIVE, _C.DISABLE_VOLTAGE): _S.SWITCH_ON_DISABLED,  # 12
    # 16 is only legal with quick stop option codes 5..8; the simulated drive allows it.
    (_S.QUICK_STOP_ACTIVE, _C.ENABLE_OPERATION): _S.OPERATION_ENABLED,  # 16
}


def apply_controlword(
    state: PowerState, controlword: int, *, previous_controlword: int = 0
) -> PowerState:
    """Device side: the state after the drive receives ``controlword`` in ``state``.

    Fault reset (15) needs a 0 -> 1 edge of bit 7 relative to
    ``previous_controlword``; outside Fault bit 7 is ignored. Automatic
    transitions (0, 1, 13, 14, and 12 at the end of a quick stop) are the
    caller's job: here Not ready to switch on and Fault reaction active ignore
    all commands.
    """
    if state is PowerState.FAULT:
        rising = controlword & ControlBit.FAULT_RESET and not (
            previous_controlword & ControlBit.FAULT_RESET
        )
        return PowerState.SWITCH_ON_DISABLED if rising else state
    return _TRANSITIONS.get((state, decode_command(controlword)), state)


# Host-side path graph: single standard transitions only, so the master goes
# through Switched on (3 then 4) and leaves Quick stop active via Switch on
# disabled (12), which every drive supports whatever its option codes.
_PATH_COMMANDS: Final = (
    Command.SHUTDOWN,
    Command.SWITCH_ON,
    Command.ENABLE_OPERATION,
    Command.DISABLE_VOLTAGE,
    Command.QUICK_STOP,
)
_HOLD: Final[dict[PowerState, Command]] = {
    PowerState.SWITCH_ON_DISABLED: Command.DISABLE_VOLTAGE,
    PowerState.READY_TO_SWITCH_ON: Command.SHUTDOWN,
    PowerState.SWITCHED_ON: Command.SWITCH_ON,
    PowerState.OPERATION_ENABLED: Command.ENABLE_OPERATION,
    PowerState.QUICK_STOP_ACTIVE: Command.QUICK_STOP,
}


def _step(state: PowerState, command: Command) -> PowerState | None:
    if (state, command) in (
        (PowerState.READY_TO_SWITCH_ON, Command.ENABLE_OPERATION),
        (PowerState.QUICK_STOP_ACTIVE, Command.ENABLE_OPERATION),
    ):
        return None
    return _TRANSITIONS.get((state, command))


def next_controlword(
    current: PowerState,
    target: PowerState = PowerState.OPERATION_ENABLED,
    *,
    previous_controlword: int | None = None,
) -> int | None:
    """Host side: the controlword to send now to move from ``current`` toward ``target``.

    Returns the holding command when ``current == target`` (useful for cyclic
    RPDOs) and ``None`` while the drive moves on its own (Not ready to switch
    on, Fault reaction active). From Fault it returns 0x80, or 0x00 first when
    ``previous_controlword`` already had bit 7 set, so the reset sees an edge.
    Raises :class:`ValueError` for a target the host cannot command
    (Not ready to switch on, Fault reaction active, Fault).
    """
    if target not in _HOLD:
        raise ValueError(f"{target.name} cannot be reached by a controlword")
    if current in (PowerState.NOT_READY_TO_SWITCH_ON, PowerState.FAULT_REACTION_ACTIVE):
        return None
    if current is PowerState.FAULT:
        if previous_controlword is not None and previous_controlword & ControlBit.FAULT_RESET:
            return int(Command.DISABLE_VOLTAGE)
        return int(Command.FAULT_RESET)
    if current is target:
        return int(_HOLD[current])
    # Breadth-first search over the standard transitions; the graph has five nodes.
    first_move: dict[PowerState, Command] = {}
    queue: deque[PowerState] = deque([current])
    while queue:
        state = queue.popleft()
        for command in _PATH_COMMANDS:
            nxt = _step(state, command)
            if nxt is None or nxt is current or nxt in first_move:
                continue
            first_move[nxt] = first_move.get(state, command)
            if nxt is target:
                return int(first_move[nxt])
            queue.append(nxt)
    raise AssertionError(f"no path {current.name} -> {target.name}")  # graph is connected


# --- Modes of operation and object dictionary ----------------------------------------------


class ModeOfOperation(IntEnum):
    """Values of 0x6060 / 0x6061."""

    NO_MODE = 0
    PROFILE_POSITION = 1
    VELOCITY = 2
    PROFILE_VELOCITY = 3
    PROFILE_TORQUE = 4
    HOMING = 6
    INTERPOLATED_POSITION = 7
    CYCLIC_SYNC_POSITION = 8
    CYCLIC_SYNC_VELOCITY = 9
    CYCLIC_SYNC_TORQUE = 10


ERROR_CODE: Final = ObjectEntry(0x603F, 0, DataType.UNSIGNED16)
CONTROLWORD: Final = ObjectEntry(0x6040, 0, DataType.UNSIGNED16)
STATUSWORD: Final = ObjectEntry(0x6041, 0, DataType.UNSIGNED16)
QUICK_STOP_OPTION_CODE: Final = ObjectEntry(0x605A, 0, DataType.INTEGER16)
ABORT_CONNECTION_OPTION_CODE: Final = ObjectEntry(0x6007, 0, DataType.INTEGER16)
"""What the drive does in Operation enabled when its connection is lost (e.g. a heartbeat
consumer timeout): 0 no action, 1 fault signal, 2 disable voltage, 3 quick stop (negative
values: manufacturer-specific)."""
MODES_OF_OPERATION: Final = ObjectEntry(0x6060, 0, DataType.INTEGER8)
MODES_OF_OPERATION_DISPLAY: Final = ObjectEntry(0x6061, 0, DataType.INTEGER8)
POSITION_ACTUAL_VALUE: Final = ObjectEntry(0x6064, 0, DataType.INTEGER32)
VELOCITY_ACTUAL_VALUE: Final = ObjectEntry(0x606C, 0, DataType.INTEGER32)
TARGET_TORQUE: Final = ObjectEntry(0x6071, 0, DataType.INTEGER16)  # per mille of rated torque
MAX_TORQUE: Final = ObjectEntry(0x6072, 0, DataType.UNSIGNED16)  # per mille of rated torque
MOTOR_RATED_TORQUE: Final = ObjectEntry(0x6076, 0, DataType.UNSIGNED32)  # mNm
TORQUE_ACTUAL_VALUE: Final = ObjectEntry(0x6077, 0, DataType.INTEGER16)  # per mille
TARGET_POSITION: Final = ObjectEntry(0x607A, 0, DataType.INTEGER32)
HOME_OFFSET: Final = ObjectEntry(0x607C, 0, DataType.INTEGER32)
SOFTWARE_POSITION_LIMIT_MIN: Final = ObjectEntry(0x607D, 1, DataType.INTEGER32)
SOFTWARE_POSITION_LIMIT_MAX: Final = ObjectEntry(0x607D, 2, DataType.INTEGER32)
MAX_MOTOR_SPEED: Final = ObjectEntry(0x6080, 0, DataType.UNSIGNED32)
PROFILE_VELOCITY: Final = ObjectEntry(0x6081, 0, DataType.UNSIGNED32)
PROFILE_ACCELERATION: Final = ObjectEntry(0x6083, 0, DataType.UNSIGNED32)
PROFILE_DECELERATION: Final = ObjectEntry(0x6084, 0, DataType.UNSIGNED32)
QUICK_STOP_DECELERATION: Final = ObjectEntry(0x6085, 0, DataType.UNSIGNED32)
POSITION_ENCODER_INCREMENTS: Final = ObjectEntry(0x608F, 1, DataType.UNSIGNED32)
POSITION_ENCODER_MOTOR_REVOLUTIONS: Final = ObjectEntry(0x608F, 2, DataType.UNSIGNED32)
HOMING_METHOD: Final = ObjectEntry(0x6098, 0, DataType.INTEGER8)
TARGET_VELOCITY: Final = ObjectEntry(0x60FF, 0, DataType.INTEGER32)
SUPPORTED_DRIVE_MODES: Final = ObjectEntry(0x6502, 0, DataType.UNSIGNED32)
