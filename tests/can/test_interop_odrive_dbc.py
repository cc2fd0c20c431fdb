"""CANSimple against ODrive's own DBC (odrive-cansimple-0.6.10.dbc from the odrive-can
package), read with cantools: an independent description of every frame.

* Every frame our ODriveAxis sends during a session (init with limits and trajectory
  limits, the three modes, NO_EXCITE, Clear_Errors, Estop) decodes with the DBC to the
  values we meant, and every poll is a remote frame on a message the ODrive sends.
* Frames encoded with the DBC (all messages, random signal values; heartbeats with axis
  states 15 and 16; Set_Limits) decode with our codec to the same values and re-encode
  to the same bytes.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import fields
from importlib import resources
from typing import Any

import anyio
import can
import cantools
import pytest
from cantools.database.can import Database, Message
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from openel_async import Request
from openel_can import CanBus, ODriveAxis
from openel_can import cansimple as cs
from openel_can.odrive import turns_to_rad
from openel_can.sim.odrive import SimODrive

from .conftest import Components, Peers, drain

NODE = 3  # the DBC describes axes 0..7
DB: Database = cantools.database.load_file(
    str(resources.files("odrive_can") / "dbc" / "odrive-cansimple-0.6.10.dbc")
)
MESSAGES: list[Message] = [m for m in DB.messages if m.name.startswith(f"Axis{NODE}_")]

#: Our dataclass field -> the DBC signal, per message class.
SIGNALS: Mapping[type[cs.CanSimpleMessage], Mapping[str, str]] = {
    cs.Version: {
        "protocol_version": "Protocol_Version",
        "hw_version_major": "Hw_Version_Major",
        "hw_version_minor": "Hw_Version_Minor",
        "hw_version_variant": "Hw_Version_Variant",
        "fw_version_major": "Fw_Version_Major",
        "fw_version_minor": "Fw_Version_Minor",
        "fw_version_revision": "Fw_Version_Revision",
        "fw_version_unreleased": "Fw_Version_Unreleased",
    },
    cs.Heartbeat: {
        "axis_error": "Axis_Error",
        "axis_state": "Axis_State",
        "procedure_result": "Procedure_Result",
        "trajectory_done": "Trajectory_Done_Flag",
    },
    cs.Estop: {},
    cs.EnterDfu: {},
    cs.ErrorStatus: {"active_errors": "Active_Errors", "disarm_reason": "Disarm_Reason"},
    cs.RxSdo: {"opcode": "Opcode", "endpoint_id": "Endpoint_ID", "value": "Value"},
    cs.TxSdo: {"endpoint_id": "Endpoint_ID", "value": "Value"},
    cs.Address: {"payload_node_id": "Node_ID", "serial_number": "Serial_Number"},
    cs.SetAxisState: {"state": "Axis_Requested_State"},
    cs.EncoderEstimates: {"pos": "Pos_Estimate", "vel": "Vel_Estimate"},
    cs.SetControllerMode: {"control_mode": "Control_Mode", "input_mode": "Input_Mode"},
    cs.SetInputPos: {"pos": "Input_Pos", "vel_ff": "Vel_FF", "torque_ff": "Torque_FF"},
    cs.SetInputVel: {"vel": "Input_Vel", "torque_ff": "Input_Torque_FF"},
    cs.SetInputTorque: {"torque": "Input_Torque"},
    cs.SetLimits: {"velocity_limit": "Velocity_Limit", "current_limit": "Current_Limit"},
    cs.SetTrajVelLimit: {"vel_limit": "Traj_Vel_Limit"},
    cs.SetTrajAccelLimits: {"accel_limit": "Traj_Accel_Limit", "decel_limit": "Traj_Decel_Limit"},
    cs.SetTrajInertia: {"inertia": "Traj_Inertia"},
    cs.Iq: {"setpoint": "Iq_Setpoint", "measured": "Iq_Measured"},
    cs.Temperature: {"fet": "FET_Temperature", "motor": "Motor_Temperature"},
    cs.Reboot: {"action": "Action"},
    cs.BusVoltageCurrent: {"voltage": "Bus_Voltage", "current": "Bus_Current"},
    cs.ClearErrors: {"identify": "Identify"},
    cs.SetAbsolutePosition: {"position": "Position"},
    cs.SetPosGain: {"pos_gain": "Pos_Gain"},
    cs.SetVelGains: {"vel_gain": "Vel_Gain", "vel_integrator_gain": "Vel_Integrator_Gain"},
    cs.Torques: {"target": "Torque_Target", "estimate": "Torque_Estimate"},
    cs.Powers: {"electrical": "Electrical_Power", "mechanical": "Mechanical_Power"},
}


def _from_host(message: Message) -> bool:
    return message.senders == ["Master"]


def _ours_as_dbc(msg: cs.CanSimpleMessage) -> dict[str, Any]:
    """Our decoded fields under the DBC's signal names, in the DBC's representation."""
    names = SIGNALS[type(msg)]
    out: dict[str, Any] = {}
    for f in fields(msg)[1:]:
        value = getattr(msg, f.name)
        if isinstance(value, bytes):
            value = int.from_bytes(value, "little")  # SDO value field: a raw u32 signal
        elif isinstance(value, bool):
            value = int(value)
        out[names[f.name]] = value
    return out


def _assert_same(ours: cs.CanSimpleMessage, dbc: Mapping[str, Any]) -> None:
    expected = {k: v for k, v in dbc.items() if not k.startswith("Reserved")}
    if isinstance(ours, cs.ClearErrors):  # our field is a flag; the DBC's a byte
        expected["Identify"] = int(bool(expected["Identify"]))
    got = _ours_as_dbc(ours)
    assert got.keys() == expected.keys(), type(ours)
    for name, value in expected.items():
        if isinstance(value, float) and math.isnan(value):
            assert math.isnan(got[name]), name
        else:
            assert got[name] == pytest.approx(value, rel=1e-12, abs=1e-12), name


def test_the_dbc_covers_every_message_we_decode() -> None:
    assert {m.frame_id & 0x1F for m in MESSAGES} == {int(c) for c in cs.CmdId}
    assert {m.frame_id for m in MESSAGES} == {(NODE << 5) | c for c in cs.CmdId}


# -- what our driver sends, decoded by the DBC -------------------------------------------------
async def test_every_frame_our_axis_sends_decodes_with_the_dbc(
    peers: Peers, host_bus: CanBus, components: Components, raw_bus: can.BusABC
) -> None:
    await peers.start(SimODrive(NODE, heartbeat_period=0.02))
    axis = await components.actuator(
        ODriveAxis(
            host_bus,
            NODE,
            heartbeat_period=0.02,
            velocity_limit=turns_to_rad(4.0),
            current_limit=12.5,
            traj_velocity=turns_to_rad(1.5),
            traj_acceleration=turns_to_rad(6.0),
        )
    )
    device = axis.device
    assert isinstance(device, ODriveAxis)
    device.set_feedforward(velocity=turns_to_rad(0.25), torque=0.125)
    await axis.set_value(turns_to_rad(0.5), Request.POSITION)
    device.set_feedforward()
    await axis.set_value(turns_to_rad(0.75), Request.VELOCITY)
    await axis.set_value(0.25, Request.TORQUE)
    await axis.get_value(Request.TORQUE_ACTUAL)
    await axis.set_value(0.0, Request.NO_EXCITE)
    await device.clear_errors()
    await device.estop()
    with anyio.fail_after(1):
        await anyio.sleep(0.05)  # let the last frames reach the raw bus

    frames = drain(raw_bus)
    by_id = {m.frame_id: m for m in MESSAGES}
    sent: list[tuple[str, dict[str, Any]]] = []
    polls: set[str] = set()
    for frame in frames:
        message = by_id.get(frame.arbitration_id)
        assert message is not None, f"{frame.arbitration_id:#x} is not in the DBC"
        if frame.is_remote_frame:
            assert not _from_host(message), message.name  # a poll of what the ODrive sends
            polls.add(message.name)
            continue
        if not _from_host(message):
            continue  # the simulated ODrive's own frames
        signals = DB.decode_message(frame.arbitration_id, frame.data, decode_choices=False)
        assert isinstance(signals, dict)
        assert len(frame.data) == message.length, message.name
        for name, value in signals.items():
            assert not (isinstance(value, float) and not math.isfinite(value)), (name, value)
        ours = cs.decode(frame.arbitration_id, frame.data, from_host=True)
        _assert_same(ours, signals)
        sent.append((message.name.removeprefix(f"Axis{NODE}_"), dict(signals)))

    names = [name for name, _ in sent]
    assert sent[names.index("Set_Limits")][1] == {"Velocity_Limit": 4.0, "Current_Limit": 12.5}
    assert sent[names.index("Set_Traj_Vel_Limit")][1] == {"Traj_Vel_Limit": 1.5}
    assert sent[names.index("Set_Traj_Accel_Limits")][1] == {
        "Traj_Accel_Limit": 6.0,
        "Traj_Decel_Limit": 6.0,
    }
    requested = [s["Axis_Requested_State"] for n, s in sent if n == "Set_Axis_State"]
    assert requested[0] == cs.AxisState.CLOSED_LOOP_CONTROL and requested[-1] == 1  # IDLE
    position = sent[names.index("Set_Input_Pos")][1]
    assert position["Input_Pos"] == pytest.approx(0.5)
    assert position["Vel_FF"] == pytest.approx(0.25) and position["Torque_FF"] == 0.125
    assert sent[names.index("Set_Input_Vel")][1]["Input_Vel"] == pytest.approx(0.75)
    assert sent[names.index("Set_Input_Torque")][1] == {"Input_Torque": 0.25}
    assert {"Clear_Errors", "Estop", "Set_Controller_Mode"} <= set(names)
    assert "Axis3_Heartbeat" in polls and "Axis3_Get_Torques" in polls


# -- frames encoded by the DBC, decoded by our codec -------------------------------------------
@pytest.mark.parametrize("state", [15, 16])
def test_heartbeat_with_a_state_newer_than_the_dbc(state: int) -> None:
    """0.6.11 reports axis states 15 and 16, which neither the 0.6.10 DBC nor our enum
    names: the frame is valid and the state an int."""
    message = DB.get_message_by_name(f"Axis{NODE}_Heartbeat")
    signals = {
        "Axis_Error": 0,
        "Axis_State": state,
        "Procedure_Result": 1,
        "Trajectory_Done_Flag": 1,
    }
    data = DB.encode_message(message.frame_id, signals)
    ours = cs.decode(message.frame_id, data, from_host=False)
    assert ours == cs.Heartbeat(NODE, 0, state, 1, True)
    assert type(ours.axis_state) is int  # type: ignore[attr-defined]
    assert cs.value_name(ours.axis_state) == f"unknown ({state})"  # type: ignore[attr-defined]
    assert cs.encode(ours) == (message.frame_id, data)


def test_set_limits_matches_the_dbc() -> None:
    message = DB.get_message_by_name(f"Axis{NODE}_Set_Limits")
    data = DB.encode_message(message.frame_id, {"Velocity_Limit": 2.5, "Current_Limit": 20.0})
    assert cs.decode(message.frame_id, data, from_host=True) == cs.SetLimits(NODE, 2.5, 20.0)
    assert cs.encode(cs.SetLimits(NODE, 2.5, 20.0)) == (message.frame_id, data)


def _raw_signal(signal: Any) -> st.SearchStrategy[int | float]:
    if signal.name.startswith("Reserved"):
        return st.just(0)
    if signal.name == "Identify":
        return st.integers(0, 1)  # our field is a flag
    if signal.is_float:
        return st.floats(width=32, allow_nan=False)
    bits = signal.length
    if signal.is_signed:
        return st.integers(-(1 << (bits - 1)), (1 << (bits - 1)) - 1)
    return st.integers(0, (1 << bits) - 1)


@st.composite
def dbc_frames(draw: st.DrawFn) -> tuple[Message, bytes]:
    message = draw(st.sampled_from(MESSAGES))
    raw = {s.name: draw(_raw_signal(s)) for s in message.signals}
    data = DB.encode_message(message.frame_id, raw, scaling=False, strict=False)
    return message, data


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(dbc_frames())
def test_every_dbc_message_decodes_with_our_codec(frame: tuple[Message, bytes]) -> None:
    message, data = frame
    from_host = _from_host(message)
    ours = cs.decode(message.frame_id, data, from_host=from_host)
    signals = DB.decode_message(message.frame_id, data, decode_choices=False)
    assert isinstance(signals, dict)
    _assert_same(ours, signals)
    arb_id, ours_data = cs.encode(ours)
    assert arb_id == message.frame_id
    assert ours_data == data[: len(ours_data)] and len(ours_data) == message.length
