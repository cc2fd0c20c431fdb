"""HAL4RT's Motor API on the CAN drives: ODriveAxis (CANSimple) and Cia402Drive (CANopen).

* Control modes: set_position / set_speed / set_torque switch the drive's mode (ODrive
  Set_Controller_Mode, CiA 402 0x6060); READY_TO_CONTROL de-energizes (ODrive IDLE,
  CiA 402 Switched on); the actual values come back through get_position/speed/torque.
* ``set_speed(speed, tm_acc)`` uses the drive's own ramp: ODrive VEL_RAMP with
  ``vel_ramp_rate`` written by RxSdo to the endpoint id of the firmware (a constructor
  parameter), CiA 402 profile velocity with 0x6083/0x6084; the simulated peers honour
  them, so the ramp takes tm_acc on the virtual bus. A later tm_acc = 0 restores the
  drive's own rate.
* Bad input: BadParameterError naming the parameter, nothing sent.
* Interop: every frame the ODrive axis sends for the modes and the ramp decodes with
  ODrive's DBC (cantools); canopen-py's SDO client reads back 0x6060/0x6083/0x6084 from the
  simulated drive after our driver wrote them.
* Identity: both are in the Device Kind ID registry with their profile and are created
  from a HALId (HalCreate) as Motors.

Real time on python-can ``virtual``; every wait bounded.
"""

from __future__ import annotations

import math
import struct
from importlib import resources

import anyio
import can
import canopen
import cantools
import pytest
from canopen import objectdictionary as cod

from openel_async import BadParameterError, ComponentState, HALError
from openel_async.device_profile import profile_of
from openel_async.device_registry import DeviceRegistry
from openel_async.ids import DeviceKind, HALId
from openel_async.motor import Motor, MotorControlMode
from openel_can import CanBus, Cia402Drive, ODriveAxis
from openel_can import cansimple as cs
from openel_can import cia402 as ds
from openel_can.odrive import VEL_RAMP_RATE_ENDPOINT, rad_to_turns
from openel_can.sim.cia402 import SimCia402Drive
from openel_can.sim.odrive import SimODrive

from .conftest import Components, Peers, drain, wait_until

ODRIVE_NODE = 3
CIA_NODE = 5
CPR = 10_000
HB = 0.02
Mode = MotorControlMode


def _odrive(bus: CanBus, **kwargs: object) -> ODriveAxis:
    kwargs.setdefault("heartbeat_period", HB)
    return ODriveAxis(bus, ODRIVE_NODE, **kwargs)  # type: ignore[arg-type]


def _sim_odrive(**kwargs: object) -> SimODrive:
    kwargs.setdefault("heartbeat_period", HB)
    return SimODrive(ODRIVE_NODE, **kwargs)  # type: ignore[arg-type]


def _cia(bus: CanBus, **kwargs: object) -> Cia402Drive:
    kwargs.setdefault("heartbeat_ms", 50)
    return Cia402Drive(bus, CIA_NODE, **kwargs)  # type: ignore[arg-type]


def _f32(value: float) -> float:
    (result,) = struct.unpack("<f", struct.pack("<f", value))
    return float(result)


# -- ODrive -------------------------------------------------------------------------------------
async def test_odrive_motor_modes_and_actual_values(
    peers: Peers, host_bus: CanBus, components: Components
) -> None:
    sim = await peers.start(_sim_odrive(vel_limit=50.0))
    motor = await components.enter(Motor(_odrive(host_bus)))
    assert motor.get_control_mode() is Mode.READY_TO_CONTROL
    with anyio.fail_after(3):
        await (await motor.set_position(0.5))  # rad: scale factor 2 pi per revolution
        assert motor.get_control_mode() is Mode.POSITION
        assert (sim.control_mode, sim.input_mode) == (
            cs.ControlMode.POSITION,
            cs.InputMode.TRAP_TRAJ,
        )
        assert await motor.get_position() == pytest.approx(0.5, abs=5e-3)
        await (await motor.set_speed(2.0))
        assert motor.get_control_mode() is Mode.SPEED
        assert sim.control_mode is cs.ControlMode.VELOCITY
        assert await motor.get_speed() == pytest.approx(2.0, abs=0.05)
        await (await motor.set_torque(0.01))
        assert motor.get_control_mode() is Mode.TORQUE
        assert sim.control_mode is cs.ControlMode.TORQUE
        assert await motor.get_torque() == pytest.approx(0.01, abs=1e-4)
        await motor.set_control_mode(Mode.READY_TO_CONTROL)
    assert motor.get_control_mode() is Mode.READY_TO_CONTROL
    await wait_until(lambda: sim.axis_state is cs.AxisState.IDLE, 1)


async def test_odrive_tm_acc_is_vel_ramp_with_vel_ramp_rate(
    peers: Peers, host_bus: CanBus, components: Components
) -> None:
    sim = await peers.start(_sim_odrive(vel_ramp_rate=8.0))
    motor = await components.enter(Motor(_odrive(host_bus)))
    with anyio.fail_after(3):
        motion = await motor.set_speed(3.0, tm_acc=0.5)  # rad/s from rest: 6 rad/s^2
        await wait_until(lambda: any(isinstance(m, cs.SetInputVel) for m in sim.commands))
        assert (sim.control_mode, sim.input_mode) == (
            cs.ControlMode.VELOCITY,
            cs.InputMode.VEL_RAMP,
        )
        assert sim.vel_ramp_rate == pytest.approx(_f32(rad_to_turns(6.0)), rel=1e-3)
        sdo = [m for m in sim.commands if isinstance(m, cs.RxSdo)]
        assert [(m.opcode, m.endpoint_id) for m in sdo] == [
            (cs.SdoOpcode.READ, VEL_RAMP_RATE_ENDPOINT),  # the ODrive's own rate, saved
            (cs.SdoOpcode.WRITE, VEL_RAMP_RATE_ENDPOINT),
        ]
        await anyio.sleep(0.25)
        assert await motor.get_speed() == pytest.approx(1.5, abs=0.4)  # half-way
        assert not motion.done()
        await motion
    took = (motion.reached_ns or 0) - motion.issued_ns
    assert 0.45e9 <= took <= 0.8e9
    assert await motor.get_speed() == pytest.approx(3.0, abs=0.05)
    with anyio.fail_after(3):  # tm_acc 0: the ODrive's own rate again
        await (await motor.set_speed(0.0))
    await wait_until(lambda: sim.vel_ramp_rate == 8.0)


async def test_odrive_endpoint_id_is_a_parameter_the_sim_honours(
    peers: Peers, host_bus: CanBus, components: Components
) -> None:
    sim = await peers.start(_sim_odrive(vel_ramp_rate_endpoint=1234))
    motor = await components.enter(Motor(_odrive(host_bus, vel_ramp_rate_endpoint=1234)))
    with anyio.fail_after(3):
        await (await motor.set_speed(-2.0, tm_acc=0.2))
    assert sim.vel_ramp_rate == pytest.approx(_f32(rad_to_turns(10.0)), rel=1e-3)


async def test_odrive_wrong_endpoint_id_is_a_clear_error_without_mode_change(
    peers: Peers, host_bus: CanBus, components: Components
) -> None:
    sim = await peers.start(_sim_odrive())  # knows endpoint 390 only
    motor = await components.enter(Motor(_odrive(host_bus, vel_ramp_rate_endpoint=77)))
    with anyio.fail_after(3), pytest.raises(HALError, match="vel_ramp_rate_endpoint"):
        await motor.set_speed(1.0, tm_acc=0.5)
    assert motor.state is ComponentState.ACTIVE
    assert sim.control_mode is cs.ControlMode.POSITION and sim.vel_ramp_rate == 8.0
    assert not [m for m in sim.commands if isinstance(m, cs.SetInputVel | cs.SetControllerMode)][
        1:
    ]  # only init's POSITION mode


@pytest.mark.parametrize("endpoint", [0, -1, 0x10000, True, 3.0, "390"])
def test_odrive_endpoint_parameter_is_checked(endpoint: object) -> None:
    bus = CanBus(interface="virtual", channel="unused")
    with pytest.raises(BadParameterError) as refused:
        ODriveAxis(bus, ODRIVE_NODE, vel_ramp_rate_endpoint=endpoint)  # type: ignore[arg-type]
    assert refused.value.parameter == "vel_ramp_rate_endpoint"


@pytest.mark.parametrize(
    ("call", "parameter"),
    [
        (lambda m: m.set_speed(1.0, tm_acc=-0.1), "tm_acc"),
        (lambda m: m.set_speed(1.0, tm_acc=math.nan), "tm_acc"),
        (lambda m: m.set_speed(1.0, tm_acc=1e-300), "tm_acc"),  # rate beyond float32
        (lambda m: m.set_speed(math.inf, tm_acc=1.0), "speed"),
        (lambda m: m.set_control_mode(7), "mode"),
    ],
)
async def test_odrive_bad_input_sends_nothing(
    peers: Peers,
    host_bus: CanBus,
    components: Components,
    raw_bus: can.BusABC,
    call: object,
    parameter: str,
) -> None:
    await peers.start(_sim_odrive())
    motor = await components.enter(Motor(_odrive(host_bus)))
    await anyio.sleep(0.02)
    drain(raw_bus)
    with pytest.raises(BadParameterError) as refused:
        await call(motor)  # type: ignore[operator]
    assert refused.value.parameter == parameter
    await anyio.sleep(0.02)
    sent = [m for m in drain(raw_bus) if m.arbitration_id & 0x1F not in _ODRIVE_TO_HOST]
    assert sent == [] and motor.get_control_mode() is Mode.READY_TO_CONTROL


_ODRIVE_TO_HOST = {int(cs.CmdId.HEARTBEAT), int(cs.CmdId.GET_ENCODER_ESTIMATES)}


async def test_odrive_frames_for_modes_and_ramp_decode_with_the_dbc(
    peers: Peers, host_bus: CanBus, components: Components, raw_bus: can.BusABC
) -> None:
    db = cantools.database.load_file(
        str(resources.files("odrive_can") / "dbc" / "odrive-cansimple-0.6.10.dbc")
    )
    await peers.start(_sim_odrive(vel_limit=50.0))
    motor = await components.enter(Motor(_odrive(host_bus)))
    await anyio.sleep(0.02)
    drain(raw_bus)
    with anyio.fail_after(3):
        await motor.set_speed(2.0, tm_acc=0.1)
        await motor.set_position(0.2)
        await motor.set_torque(0.01)
        await motor.set_control_mode(Mode.READY_TO_CONTROL)
    await anyio.sleep(0.02)
    decoded = []
    for frame in drain(raw_bus):
        message = db.get_message_by_frame_id(frame.arbitration_id)
        if message.senders != ["Master"] or frame.is_remote_frame:
            continue  # the ODrive's own frames, and polls
        decoded.append((message.name, message.decode(bytes(frame.data), decode_choices=False)))
    prefix = f"Axis{ODRIVE_NODE}_"
    names = [name.removeprefix(prefix) for name, _ in decoded]
    assert names == [
        "RxSdo",  # read the ODrive's vel_ramp_rate
        "Set_Controller_Mode",
        "RxSdo",  # write vel_ramp_rate
        "Set_Input_Vel",
        "Set_Controller_Mode",
        "Set_Input_Pos",
        "Set_Controller_Mode",
        "Set_Input_Torque",
        "Set_Axis_State",
    ]
    signals = [s for _, s in decoded]
    assert signals[0]["Opcode"] == 0 and signals[0]["Endpoint_ID"] == VEL_RAMP_RATE_ENDPOINT
    assert (signals[1]["Control_Mode"], signals[1]["Input_Mode"]) == (2, 2)  # VELOCITY, VEL_RAMP
    assert signals[2]["Opcode"] == 1 and signals[2]["Endpoint_ID"] == VEL_RAMP_RATE_ENDPOINT
    rate = struct.unpack("<f", int(signals[2]["Value"]).to_bytes(4, "little"))[0]
    assert rate == pytest.approx(rad_to_turns(20.0), rel=1e-2)  # ~2 rad/s in 0.1 s
    assert signals[3]["Input_Vel"] == pytest.approx(rad_to_turns(2.0), rel=1e-6)
    assert (signals[4]["Control_Mode"], signals[4]["Input_Mode"]) == (3, 5)  # POSITION, TRAP
    assert signals[5]["Input_Pos"] == pytest.approx(rad_to_turns(0.2), rel=1e-6)
    assert (signals[6]["Control_Mode"], signals[6]["Input_Mode"]) == (1, 1)  # TORQUE, PASS
    assert signals[7]["Input_Torque"] == pytest.approx(0.01, rel=1e-6)
    assert signals[8]["Axis_Requested_State"] == int(cs.AxisState.IDLE)


# -- CiA 402 ------------------------------------------------------------------------------------
async def test_cia402_motor_modes_and_actual_values(
    peers: Peers, host_bus: CanBus, components: Components
) -> None:
    sim = await peers.start(SimCia402Drive(CIA_NODE))
    motor = await components.enter(Motor(_cia(host_bus)))
    assert motor.get_control_mode() is Mode.READY_TO_CONTROL
    with anyio.fail_after(3):
        await (await motor.set_position(0.5))
        assert motor.get_control_mode() is Mode.POSITION
        assert sim.mode == ds.ModeOfOperation.PROFILE_POSITION
        assert await motor.get_position() == pytest.approx(0.5, abs=2e-3)
        await (await motor.set_speed(1.0))
        assert sim.mode == ds.ModeOfOperation.PROFILE_VELOCITY
        await anyio.sleep(0.03)  # the velocity comes in TPDO2, every 10 ms
        assert await motor.get_speed() == pytest.approx(1.0, abs=0.02)
        await (await motor.set_torque(0.0))
        assert sim.mode == ds.ModeOfOperation.PROFILE_TORQUE
        assert motor.get_control_mode() is Mode.TORQUE
        await motor.set_control_mode(Mode.READY_TO_CONTROL)
    assert motor.get_control_mode() is Mode.READY_TO_CONTROL
    await wait_until(lambda: sim.power_state is ds.PowerState.SWITCHED_ON, 1)


async def test_cia402_tm_acc_is_profile_acceleration_in_profile_velocity(
    peers: Peers, host_bus: CanBus, components: Components
) -> None:
    sim = await peers.start(SimCia402Drive(CIA_NODE, counts_per_rev=CPR))
    motor = await components.enter(Motor(_cia(host_bus)))
    own = (sim.od[(0x6083, 0)].value, sim.od[(0x6084, 0)].value)
    with anyio.fail_after(3):
        motion = await motor.set_speed(3.0, tm_acc=0.5)  # 6 rad/s^2
        accel = round(6.0 * CPR / math.tau)
        assert sim.mode == ds.ModeOfOperation.PROFILE_VELOCITY
        assert (sim.od[(0x6083, 0)].value, sim.od[(0x6084, 0)].value) == (accel, accel)
        assert sim.od[(0x60FF, 0)].value == round(3.0 * CPR / math.tau)
        await anyio.sleep(0.25)
        assert await motor.get_speed() == pytest.approx(1.5, abs=0.4)
        assert not motion.done()
        await motion
    took = (motion.reached_ns or 0) - motion.issued_ns
    assert 0.45e9 <= took <= 0.8e9
    with anyio.fail_after(3):  # back down in 0.25 s: the deceleration is the same rate
        await (await motor.set_speed(1.5, tm_acc=0.25))
        # from the actual speed (TPDO2, up to 10 ms old) to 1.5 rad/s in 0.25 s
        assert sim.od[(0x6084, 0)].value == pytest.approx(accel, rel=0.1)
        await (await motor.set_speed(0.0))  # tm_acc 0: the drive's own values again
    assert (sim.od[(0x6083, 0)].value, sim.od[(0x6084, 0)].value) == own


async def test_cia402_bad_tm_acc_sends_nothing(
    peers: Peers, host_bus: CanBus, components: Components, raw_bus: can.BusABC
) -> None:
    await peers.start(SimCia402Drive(CIA_NODE))
    motor = await components.enter(Motor(_cia(host_bus, tpdo_event_ms=1000, heartbeat_ms=1000)))
    await anyio.sleep(0.02)
    drain(raw_bus)
    for tm_acc in (-1.0, math.inf, 1e-30):  # the last: 0x6083 beyond UNSIGNED32
        with pytest.raises(BadParameterError) as refused:
            await motor.set_speed(1.0, tm_acc=tm_acc)
        assert refused.value.parameter == "tm_acc"
    sent = [m for m in drain(raw_bus) if m.arbitration_id - CIA_NODE in (0x200, 0x300, 0x600)]
    assert sent == [] and motor.get_control_mode() is Mode.READY_TO_CONTROL


def _cia_od() -> cod.ObjectDictionary:
    od = cod.ObjectDictionary()
    for name, index, data_type in (
        ("modes of operation", 0x6060, cod.INTEGER8),
        ("profile acceleration", 0x6083, cod.UNSIGNED32),
        ("profile deceleration", 0x6084, cod.UNSIGNED32),
    ):
        var = cod.ODVariable(name, index, 0)
        var.data_type = data_type
        var.access_type = "rw"
        od.add_object(var)
    return od


async def test_canopen_reads_back_what_the_ramp_wrote(
    peers: Peers, host_bus: CanBus, components: Components, channel: str
) -> None:
    await peers.start(SimCia402Drive(CIA_NODE, counts_per_rev=CPR))
    motor = await components.enter(Motor(_cia(host_bus)))
    with anyio.fail_after(3):
        await motor.set_speed(2.0, tm_acc=0.4)  # 5 rad/s^2
    network = canopen.Network()
    network.NOTIFIER_CYCLE = 0.05  # its receive timeout, which disconnect() waits out
    network.connect(interface="virtual", channel=channel, receive_own_messages=False)
    try:
        node = canopen.RemoteNode(CIA_NODE, _cia_od())
        network.add_node(node)

        def read_back() -> tuple[int, int, int]:
            return (node.sdo[0x6060].raw, node.sdo[0x6083].raw, node.sdo[0x6084].raw)

        with anyio.fail_after(5):
            values = await anyio.to_thread.run_sync(read_back)
    finally:
        network.disconnect()
    accel = round(5.0 * CPR / math.tau)
    assert values == (int(ds.ModeOfOperation.PROFILE_VELOCITY), accel, accel)


# -- identity: profiles and HalCreate ----------------------------------------------------------
@pytest.mark.parametrize(
    ("device_class", "vendor_id", "product_id"),
    [(ODriveAxis, 0x0D21, 0x0006), (Cia402Drive, 0x0402, 0x0192)],
)
def test_profiles_are_registered_with_a_native_ramp(
    device_class: type, vendor_id: int, product_id: int
) -> None:
    registry = DeviceRegistry.from_drivers()
    entry = registry.lookup(DeviceKind.MOTOR, vendor_id, product_id)
    assert entry.device_class is device_class and entry.driver == "can"
    data = entry.profile.to_dict()
    assert data["kind_name"] == "Motor" and data["attributes"]["velocity_ramp"] is True
    speed = entry.profile.command("SetSpeed")
    assert speed.supported and [p.name for p in speed.parameters] == ["speed", "tmAcc"]
    assert profile_of(device_class).to_dict() == data


async def test_hal_create_builds_a_motor_from_a_hal_id(peers: Peers, host_bus: CanBus) -> None:
    await peers.start(_sim_odrive())
    registry = DeviceRegistry.from_drivers()
    hal_id = HALId(int(DeviceKind.MOTOR), 0x0D21, 0x0006, 42)
    motor = registry.create(hal_id, host_bus, ODRIVE_NODE, heartbeat_period=HB)
    assert isinstance(motor, Motor) and motor.hal_id == hal_id
    async with motor:
        with anyio.fail_after(3):
            await (await motor.set_speed(1.0, tm_acc=0.1))
        assert motor.get_control_mode() is Mode.SPEED
