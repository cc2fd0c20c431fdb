"""ODrive CANSimple codec: golden frames, round trips, fuzzing."""

from __future__ import annotations

import struct

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from openel_can import cansimple as cs
from openel_can.errors import CanSimpleDecodeError, DecodeError

nodes = st.integers(0, cs.MAX_NODE_ID)
f32 = st.floats(width=32, allow_nan=False)
u8 = st.integers(0, 0xFF)
u32 = st.integers(0, 0xFFFF_FFFF)
ff = st.integers(-32768, 32767).map(lambda k: k * cs.FF_SCALE)
FUZZ = settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])


REQUESTABLE = [
    cs.CmdId.GET_VERSION,
    cs.CmdId.HEARTBEAT,
    cs.CmdId.GET_ERROR,
    cs.CmdId.ADDRESS,
    cs.CmdId.GET_ENCODER_ESTIMATES,
    cs.CmdId.GET_IQ,
    cs.CmdId.GET_TEMPERATURE,
    cs.CmdId.GET_BUS_VOLTAGE_CURRENT,
    cs.CmdId.GET_TORQUES,
    cs.CmdId.GET_POWERS,
]


def _f32s(cls: type[cs.CanSimpleMessage], count: int) -> st.SearchStrategy[cs.CanSimpleMessage]:
    return st.builds(lambda n, *v: cls(n, *v), nodes, *([f32] * count))


AXIS_MESSAGES: st.SearchStrategy[cs.CanSimpleMessage] = st.one_of(
    st.builds(cs.Version, nodes, u8, u8, u8, u8, u8, u8, u8, u8),
    st.builds(cs.Heartbeat, nodes, u32, st.sampled_from(cs.AxisState) | u8, u8, st.booleans()),
    st.builds(cs.ErrorStatus, nodes, u32, u32),
    st.builds(cs.TxSdo, nodes, st.integers(0, 0xFFFF), st.binary(min_size=4, max_size=4)),
    st.builds(cs.Address, nodes, u8, st.integers(0, (1 << 48) - 1)),
    *(_f32s(cls, 2) for cls in (cs.EncoderEstimates, cs.Iq, cs.Temperature, cs.BusVoltageCurrent)),
    _f32s(cs.Torques, 2),
    _f32s(cs.Powers, 2),
)

HOST_MESSAGES: st.SearchStrategy[cs.CanSimpleMessage] = st.one_of(
    st.builds(cs.Estop, nodes),
    st.builds(cs.EnterDfu, nodes),
    st.builds(
        cs.RxSdo,
        nodes,
        st.sampled_from(cs.SdoOpcode) | u8,
        st.integers(0, 0xFFFF),
        st.binary(min_size=4, max_size=4),
    ),
    st.builds(cs.Address, nodes, u8, st.integers(0, (1 << 48) - 1)),
    st.builds(cs.SetAxisState, nodes, st.sampled_from(cs.AxisState) | u32),
    st.builds(
        cs.SetControllerMode,
        nodes,
        st.sampled_from(cs.ControlMode) | u32,
        st.sampled_from(cs.InputMode) | u32,
    ),
    st.builds(cs.SetInputPos, nodes, f32, ff, ff),
    _f32s(cs.SetInputVel, 2),
    _f32s(cs.SetInputTorque, 1),
    _f32s(cs.SetLimits, 2),
    _f32s(cs.SetTrajVelLimit, 1),
    _f32s(cs.SetTrajAccelLimits, 2),
    _f32s(cs.SetTrajInertia, 1),
    st.builds(cs.Reboot, nodes, st.sampled_from(cs.RebootAction) | u8),
    st.builds(cs.ClearErrors, nodes, st.booleans()),
    _f32s(cs.SetAbsolutePosition, 1),
    _f32s(cs.SetPosGain, 1),
    _f32s(cs.SetVelGains, 2),
    st.builds(cs.Request, nodes, st.sampled_from(REQUESTABLE)),
)


def test_golden_set_input_pos() -> None:
    arb_id, data = cs.encode(cs.SetInputPos(3, 1.5, vel_ff=0.5, torque_ff=0.1))
    assert arb_id == 0x06C
    assert data == bytes.fromhex("00 00 c0 3f f4 01 64 00")
    assert cs.decode(arb_id, data, from_host=True) == cs.SetInputPos(3, 1.5, 0.5, 0.1)


@pytest.mark.parametrize(
    ("msg", "arb_id", "hexdata"),
    [
        (
            cs.Heartbeat(1, 0, cs.AxisState.CLOSED_LOOP_CONTROL, 0, True),
            0x021,
            "00 00 00 00 08 00 01 00",
        ),
        (cs.EncoderEstimates(0, 1.0, -2.0), 0x009, "00 00 80 3f 00 00 00 c0"),
        (cs.SetAxisState(0, cs.AxisState.CLOSED_LOOP_CONTROL), 0x007, "08 00 00 00 00 00 00 00"),
        (
            cs.SetControllerMode(1, cs.ControlMode.POSITION, cs.InputMode.TRAP_TRAJ),
            0x02B,
            "03 00 00 00 05 00 00 00",
        ),
        (cs.SetInputVel(2, 1.0, 0.0), 0x04D, "00 00 80 3f 00 00 00 00"),
        (cs.ErrorStatus(0, 0x0000_0100, 0x0000_0200), 0x003, "00 01 00 00 00 02 00 00"),
        (
            cs.RxSdo(1, cs.SdoOpcode.WRITE, 0x0123, b"\x01\x02\x03\x04"),
            0x024,
            "01 23 01 00 01 02 03 04",
        ),
        (cs.Address(5, 5, 0x0123456789AB), 0x0A6, "05 ab 89 67 45 23 01 00"),
        (cs.Estop(1), 0x022, ""),
        (cs.Reboot(1, cs.RebootAction.SAVE_CONFIGURATION), 0x036, "01"),
        (cs.ClearErrors(0x3F), 0x7F8, "00"),
        (cs.Request(1, cs.CmdId.GET_ENCODER_ESTIMATES), 0x029, ""),
    ],
)
def test_golden_frames(msg: cs.CanSimpleMessage, arb_id: int, hexdata: str) -> None:
    assert cs.encode(msg) == (arb_id, bytes.fromhex(hexdata))


def test_remote_requests() -> None:
    assert cs.decode(0x029, b"", from_host=True, remote=True) == cs.Request(
        1, cs.CmdId.GET_ENCODER_ESTIMATES
    )
    # An empty data frame on a Get_* id is also a request ...
    assert cs.decode(0x023, b"", from_host=True) == cs.Request(1, cs.CmdId.GET_ERROR)
    # ... but not on an id the host sends data on.
    with pytest.raises(CanSimpleDecodeError):
        cs.decode(0x026, b"", from_host=True)
    assert cs.decode(0x7E6, b"", from_host=True, remote=True) == cs.Request(0x3F, cs.CmdId.ADDRESS)
    with pytest.raises(CanSimpleDecodeError):
        cs.decode(0x02C, b"", from_host=True, remote=True)  # Set_Input_Pos is not requestable
    with pytest.raises(ValueError):
        cs.Request(1, cs.CmdId.SET_INPUT_POS)


def test_direction_matters() -> None:
    _, hb = cs.encode(cs.Heartbeat(1, 0, cs.AxisState.IDLE, 0))
    with pytest.raises(CanSimpleDecodeError):
        cs.decode(0x021, hb, from_host=True)
    _, pos = cs.encode(cs.SetInputPos(1, 0.0))
    with pytest.raises(CanSimpleDecodeError):
        cs.decode(0x02C, pos, from_host=False)


def test_legacy_empty_reboot_and_clear() -> None:
    assert cs.decode(0x036, b"", from_host=True) == cs.Reboot(1)
    assert cs.decode(0x038, b"", from_host=True) == cs.ClearErrors(1)


@pytest.mark.parametrize(
    ("arb_id", "data"),
    [
        (0x028, bytes(8)),  # cmd 0x08 unused in 0.6
        (0x800, bytes(8)),  # not 11-bit
        (-1, bytes(8)),
        (0x021, bytes(6)),  # heartbeat too short
        (0x021, bytes(9)),  # more than classic CAN
    ],
)
def test_invalid_frames(arb_id: int, data: bytes) -> None:
    with pytest.raises(CanSimpleDecodeError):
        cs.decode(arb_id, data, from_host=False)


@pytest.mark.parametrize("state", [15, 16, 99, 255])
def test_unknown_enum_values_are_kept_as_ints(state: int) -> None:
    """Firmware 0.6.11 reports axis states 15 and 16: a valid heartbeat, not a bad frame."""
    data = bytes((0, 0, 0, 0, state, 0, 1, 0))
    hb = cs.decode(0x021, data, from_host=False)
    assert isinstance(hb, cs.Heartbeat)
    assert type(hb.axis_state) is int and hb.axis_state == state
    assert cs.value_name(hb.axis_state) == f"unknown ({state})"
    assert cs.encode(hb) == (0x021, data)
    assert cs.value_name(cs.AxisState.IDLE) == "IDLE"
    mode = cs.decode(0x02B, bytes((3, 0, 0, 0, 9, 0, 0, 0)), from_host=True)
    assert mode == cs.SetControllerMode(1, cs.ControlMode.POSITION, 9)
    assert isinstance(mode, cs.SetControllerMode) and mode.control_mode is cs.ControlMode.POSITION
    assert cs.decode(0x036, b"\x07", from_host=True) == cs.Reboot(1, 7)


def test_encoder_range_errors() -> None:
    with pytest.raises(ValueError):
        cs.encode(cs.SetInputPos(1, 0.0, vel_ff=40.0))  # > int16 * 0.001
    with pytest.raises(ValueError):
        cs.encode(cs.SetInputTorque(1, 1e39))  # not an f32
    with pytest.raises(ValueError):
        cs.SetInputTorque(64, 0.0)
    with pytest.raises(ValueError):
        cs.TxSdo(1, 2, b"\x00")


@FUZZ
@given(AXIS_MESSAGES)
def test_round_trip_from_axis(msg: cs.CanSimpleMessage) -> None:
    arb_id, data = cs.encode(msg)
    assert arb_id == msg.node_id << 5 | msg.cmd
    assert len(data) <= 8
    assert cs.decode(arb_id, data, from_host=False) == msg


@FUZZ
@given(HOST_MESSAGES)
def test_round_trip_from_host(msg: cs.CanSimpleMessage) -> None:
    arb_id, data = cs.encode(msg)
    remote = isinstance(msg, cs.Request)
    assert cs.decode(arb_id, data, from_host=True, remote=remote) == msg


@FUZZ
@given(
    st.integers(-1, 0x801),
    st.binary(max_size=9),
    st.booleans(),
    st.booleans(),
)
def test_random_frames_raise_only_decode_error(
    arb_id: int, data: bytes, from_host: bool, remote: bool
) -> None:
    try:
        msg = cs.decode(arb_id, data, from_host=from_host, remote=remote)
    except CanSimpleDecodeError as exc:
        assert isinstance(exc, DecodeError | ValueError)
        return
    # Whatever decodes re-encodes onto the same id.
    assert cs.encode(msg)[0] == arb_id


def test_float_payload_is_little_endian_f32() -> None:
    _, data = cs.encode(cs.SetLimits(1, 10.0, 20.0))
    assert struct.unpack("<ff", data) == (10.0, 20.0)


MESSAGE_CLASSES = sorted(
    (
        cls
        for cls in vars(cs).values()
        if isinstance(cls, type)
        and issubclass(cls, cs.CanSimpleMessage)
        and cls is not cs.CanSimpleMessage
    ),
    key=lambda cls: cls.__name__,
)


@FUZZ
@given(
    st.sampled_from(MESSAGE_CLASSES),
    st.lists(
        st.integers(-(2**40), 2**40)
        | st.floats(allow_nan=False)
        | st.binary(max_size=6)
        | st.booleans(),
        max_size=8,
    ),
    st.booleans(),
)
def test_constructors_and_encoders_raise_only_value_or_type_error(
    kind: type[cs.CanSimpleMessage], args: list[object], from_host: bool
) -> None:
    """Any values: a message whose frame decodes back to the same bytes, or ValueError (a
    value that does not fit the wire format) / TypeError (wrong arity or type)."""
    try:
        msg = kind(*args)  # type: ignore[arg-type]
        arb_id, data = cs.encode(msg)
    except (ValueError, TypeError):
        return
    remote = isinstance(msg, cs.Request)
    for direction in (True, False):
        try:
            again = cs.decode(arb_id, data, from_host=direction, remote=remote and direction)
        except CanSimpleDecodeError:
            continue  # not a frame of that direction
        assert cs.encode(again) == (arb_id, data)


def test_address_refuses_a_float_serial_number_with_a_type_error() -> None:
    """Found by the constructor fuzzer: a float serial number leaked an AttributeError."""
    with pytest.raises(TypeError, match="serial_number must be an int"):
        cs.encode(cs.Address(0, 0, 0.0))  # type: ignore[arg-type]
