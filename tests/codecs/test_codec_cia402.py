"""CiA 402 power state machine: statusword decoding, transitions, path finding."""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from openel_can import cia402 as ds
from openel_can.errors import Cia402DecodeError

S = ds.PowerState
FUZZ = settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@pytest.mark.parametrize(
    ("statusword", "state"),
    [
        (0x0000, S.NOT_READY_TO_SWITCH_ON),
        (0x0250, S.SWITCH_ON_DISABLED),
        (0x0270, S.SWITCH_ON_DISABLED),  # quick-stop bit is "don't care" here
        (0x0231, S.READY_TO_SWITCH_ON),
        (0x0233, S.SWITCHED_ON),
        (0x0237, S.OPERATION_ENABLED),
        (0x1637, S.OPERATION_ENABLED),
        (0x0217, S.QUICK_STOP_ACTIVE),
        (0x021F, S.FAULT_REACTION_ACTIVE),
        (0x0218, S.FAULT),
        (0x0238, S.FAULT),
    ],
)
def test_statusword_states(statusword: int, state: ds.PowerState) -> None:
    assert ds.state_from_statusword(statusword) is state
    assert ds.Statusword.decode(statusword).state is state


@pytest.mark.parametrize("statusword", [0x0001, 0x0003, 0x0011, 0x0061, 0x0041, 0x10000, -1])
def test_invalid_statuswords(statusword: int) -> None:
    with pytest.raises(Cia402DecodeError):
        ds.state_from_statusword(statusword)


def test_state_patterns_are_disjoint() -> None:
    # Every u16 matches at most one (mask, value) pattern of the CiA 402 table.
    patterns = [(0x4F, s) for s in (S.NOT_READY_TO_SWITCH_ON, S.SWITCH_ON_DISABLED)]
    patterns += [(0x4F, s) for s in (S.FAULT_REACTION_ACTIVE, S.FAULT)]
    patterns += [
        (0x6F, s)
        for s in (S.READY_TO_SWITCH_ON, S.SWITCHED_ON, S.OPERATION_ENABLED, S.QUICK_STOP_ACTIVE)
    ]
    for word in range(0x80):
        matches = [s for mask, s in patterns if word & mask == s.value]
        assert len(matches) <= 1
        if matches:
            assert ds.state_from_statusword(word) is matches[0]
        else:
            with pytest.raises(Cia402DecodeError):
                ds.state_from_statusword(word)


@FUZZ
@given(
    st.sampled_from(S),
    st.booleans(),
    st.booleans(),
    st.booleans(),
    st.booleans(),
    st.booleans(),
    st.booleans(),
    st.booleans(),
)
def test_statusword_build_round_trip(
    state: ds.PowerState,
    voltage: bool,
    warning: bool,
    remote: bool,
    reached: bool,
    limit: bool,
    ack: bool,
    following: bool,
) -> None:
    word = ds.Statusword.build(
        state,
        voltage_enabled=voltage,
        warning=warning,
        remote=remote,
        target_reached=reached,
        internal_limit_active=limit,
        setpoint_acknowledge=ack,
        following_error=following,
    )
    decoded = ds.Statusword.decode(word.raw)
    assert decoded == word
    assert decoded.state is state
    assert (decoded.voltage_enabled, decoded.warning, decoded.remote) == (voltage, warning, remote)
    assert (decoded.target_reached, decoded.internal_limit_active) == (reached, limit)
    assert (decoded.setpoint_acknowledge, decoded.following_error) == (ack, following)


def test_status_bits() -> None:
    assert ds.StatusBit.WARNING == 1 << 7
    assert ds.StatusBit.REMOTE == 1 << 9
    assert ds.StatusBit.TARGET_REACHED == 1 << 10
    assert ds.StatusBit.INTERNAL_LIMIT_ACTIVE == 1 << 11
    assert ds.StatusBit.SETPOINT_ACKNOWLEDGE == 1 << 12


def test_controlword_commands() -> None:
    assert ds.Command.SHUTDOWN.value == 0x06
    assert ds.Command.SWITCH_ON.value == ds.Command.DISABLE_OPERATION.value == 0x07
    assert ds.Command.ENABLE_OPERATION.value == 0x0F
    assert ds.Command.DISABLE_VOLTAGE.value == 0x00
    assert ds.Command.QUICK_STOP.value == 0x02
    assert ds.Command.FAULT_RESET.value == 0x80
    assert ds.controlword(ds.Command.ENABLE_OPERATION, new_setpoint=True) == 0x1F
    assert ds.controlword(ds.Command.ENABLE_OPERATION, change_set_immediately=True) == 0x2F
    assert ds.controlword(ds.Command.ENABLE_OPERATION, halt=True) == 0x10F


@pytest.mark.parametrize(
    ("word", "command"),
    [
        (0x00, ds.Command.DISABLE_VOLTAGE),
        (0x0D, ds.Command.DISABLE_VOLTAGE),  # 0xxx xx0x
        (0x02, ds.Command.QUICK_STOP),
        (0x0B, ds.Command.QUICK_STOP),  # 0xxx x01x
        (0x06, ds.Command.SHUTDOWN),
        (0x0E, ds.Command.SHUTDOWN),  # 0xxx x110
        (0x07, ds.Command.SWITCH_ON),
        (0x0F, ds.Command.ENABLE_OPERATION),
        (0x1F, ds.Command.ENABLE_OPERATION),
    ],
)
def test_decode_command(word: int, command: ds.Command) -> None:
    assert ds.decode_command(word) is command


@pytest.mark.parametrize(
    ("state", "word", "after"),
    [
        (S.SWITCH_ON_DISABLED, 0x06, S.READY_TO_SWITCH_ON),  # 2
        (S.READY_TO_SWITCH_ON, 0x07, S.SWITCHED_ON),  # 3
        (S.READY_TO_SWITCH_ON, 0x0F, S.OPERATION_ENABLED),  # 3 + 4
        (S.SWITCHED_ON, 0x0F, S.OPERATION_ENABLED),  # 4
        (S.OPERATION_ENABLED, 0x07, S.SWITCHED_ON),  # 5
        (S.SWITCHED_ON, 0x06, S.READY_TO_SWITCH_ON),  # 6
        (S.READY_TO_SWITCH_ON, 0x00, S.SWITCH_ON_DISABLED),  # 7
        (S.READY_TO_SWITCH_ON, 0x02, S.SWITCH_ON_DISABLED),  # 7
        (S.OPERATION_ENABLED, 0x06, S.READY_TO_SWITCH_ON),  # 8
        (S.OPERATION_ENABLED, 0x00, S.SWITCH_ON_DISABLED),  # 9
        (S.SWITCHED_ON, 0x02, S.SWITCH_ON_DISABLED),  # 10
        (S.OPERATION_ENABLED, 0x02, S.QUICK_STOP_ACTIVE),  # 11
        (S.QUICK_STOP_ACTIVE, 0x00, S.SWITCH_ON_DISABLED),  # 12
        (S.QUICK_STOP_ACTIVE, 0x0F, S.OPERATION_ENABLED),  # 16
        (S.FAULT, 0x80, S.SWITCH_ON_DISABLED),  # 15
        (S.SWITCH_ON_DISABLED, 0x0F, S.SWITCH_ON_DISABLED),  # no transition
        (S.FAULT, 0x0F, S.FAULT),
        (S.FAULT_REACTION_ACTIVE, 0x80, S.FAULT_REACTION_ACTIVE),
        (S.NOT_READY_TO_SWITCH_ON, 0x06, S.NOT_READY_TO_SWITCH_ON),
        (S.OPERATION_ENABLED, 0x8F, S.OPERATION_ENABLED),  # bit 7 ignored outside Fault
    ],
)
def test_apply_controlword(state: ds.PowerState, word: int, after: ds.PowerState) -> None:
    assert ds.apply_controlword(state, word) is after


def test_fault_reset_needs_rising_edge() -> None:
    assert ds.apply_controlword(S.FAULT, 0x80, previous_controlword=0x80) is S.FAULT
    assert ds.apply_controlword(S.FAULT, 0x80, previous_controlword=0x00) is S.SWITCH_ON_DISABLED
    assert ds.next_controlword(S.FAULT, previous_controlword=0x80) == 0x00
    assert ds.next_controlword(S.FAULT, previous_controlword=0x00) == 0x80


def test_standard_enable_sequence() -> None:
    assert ds.next_controlword(S.SWITCH_ON_DISABLED) == 0x06
    assert ds.next_controlword(S.READY_TO_SWITCH_ON) == 0x07
    assert ds.next_controlword(S.SWITCHED_ON) == 0x0F
    assert ds.next_controlword(S.OPERATION_ENABLED) == 0x0F
    assert ds.next_controlword(S.QUICK_STOP_ACTIVE) == 0x00
    assert ds.next_controlword(S.FAULT) == 0x80
    assert ds.next_controlword(S.NOT_READY_TO_SWITCH_ON) is None
    assert ds.next_controlword(S.FAULT_REACTION_ACTIVE) is None
    assert ds.next_controlword(S.OPERATION_ENABLED, S.SWITCH_ON_DISABLED) == 0x00
    assert ds.next_controlword(S.OPERATION_ENABLED, S.SWITCHED_ON) == 0x07
    with pytest.raises(ValueError):
        ds.next_controlword(S.SWITCHED_ON, S.FAULT)


COMMANDABLE = [
    S.SWITCH_ON_DISABLED,
    S.READY_TO_SWITCH_ON,
    S.SWITCHED_ON,
    S.OPERATION_ENABLED,
    S.QUICK_STOP_ACTIVE,
]


@FUZZ
@given(st.sampled_from([*COMMANDABLE, S.FAULT]), st.sampled_from(COMMANDABLE), st.integers(0, 0xFF))
def test_host_and_device_converge(
    start: ds.PowerState, target: ds.PowerState, previous: int
) -> None:
    """Driving the device model with next_controlword reaches any commandable target."""
    state = start
    for _ in range(8):
        word = ds.next_controlword(state, target, previous_controlword=previous)
        assert word is not None
        state = ds.apply_controlword(state, word, previous_controlword=previous)
        previous = word
        if state is target:
            break
    assert state is target
    assert ds.apply_controlword(state, ds.next_controlword(state, target) or 0) is target


def test_object_dictionary() -> None:
    assert ds.CONTROLWORD.map_entry().to_u32() == 0x6040_0010
    assert ds.STATUSWORD.map_entry().to_u32() == 0x6041_0010
    assert ds.TARGET_POSITION.map_entry().to_u32() == 0x607A_0020
    assert ds.MODES_OF_OPERATION.map_entry().to_u32() == 0x6060_0008
    assert ds.TARGET_VELOCITY.index == 0x60FF
    assert ds.VELOCITY_ACTUAL_VALUE.index == 0x606C
    assert ds.TARGET_TORQUE.index == 0x6071
    assert ds.TORQUE_ACTUAL_VALUE.index == 0x6077
    assert (ds.SOFTWARE_POSITION_LIMIT_MIN.index, ds.SOFTWARE_POSITION_LIMIT_MIN.subindex) == (
        0x607D,
        1,
    )
    assert ds.POSITION_ENCODER_INCREMENTS.index == 0x608F
    assert ds.MODES_OF_OPERATION.encode(ds.ModeOfOperation.CYCLIC_SYNC_POSITION) == b"\x08"
    assert ds.TARGET_POSITION.decode(b"\xff\xff\xff\xff") == -1


def test_modes_of_operation() -> None:
    mode = ds.ModeOfOperation
    assert (mode.PROFILE_POSITION, mode.PROFILE_VELOCITY, mode.PROFILE_TORQUE) == (1, 3, 4)
    assert (mode.HOMING, mode.CYCLIC_SYNC_POSITION) == (6, 8)
    assert (mode.CYCLIC_SYNC_VELOCITY, mode.CYCLIC_SYNC_TORQUE) == (9, 10)


@FUZZ
@given(st.integers(-(2**20), 2**20))
def test_statusword_parsers_raise_only_the_decode_error(raw: int) -> None:
    """Any int: a state (and a Statusword whose accessors agree) or Cia402DecodeError."""
    try:
        state = ds.state_from_statusword(raw)
    except Cia402DecodeError:
        with pytest.raises(Cia402DecodeError):
            ds.Statusword.decode(raw)
        return
    word = ds.Statusword.decode(raw)
    assert word.state is state and 0 <= raw <= 0xFFFF
    assert word.setpoint_acknowledge == bool(raw & ds.StatusBit.SETPOINT_ACKNOWLEDGE)


@FUZZ
@given(st.sampled_from(S), st.integers(0, 0xFFFF), st.integers(0, 0xFFFF))
def test_any_controlword_gives_a_state(state: ds.PowerState, word: int, previous: int) -> None:
    """Every u16 controlword maps to one command and every state/word pair to a state."""
    assert isinstance(ds.decode_command(word), ds.Command)
    after = ds.apply_controlword(state, word, previous_controlword=previous)
    assert isinstance(after, ds.PowerState)
    if state in (S.NOT_READY_TO_SWITCH_ON, S.FAULT_REACTION_ACTIVE):
        assert after is state  # only automatic transitions leave these
