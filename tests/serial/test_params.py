"""``openel-async param``'s serial side in process: a Dynamixel X servo's and a Feetech
STS servo's control tables against the simulated servos on a pty (and a Dynamixel item as
dynamixel-sdk reads it)."""

from __future__ import annotations

from collections.abc import AsyncIterator

import anyio
import dynamixel_sdk as sdk
import pytest

from openel_async.errors import BadParameterError
from openel_serial import feetech as ft
from openel_serial.feetech_peers import SimFeetechBus, SimStsServo
from openel_serial.feetech_port import FeetechPort
from openel_serial.params_servo import ServoParameters
from openel_serial.peers import SimDynamixelBus
from openel_serial.port import DynamixelPort

from .conftest import BAUD, in_thread, make_servo


async def test_dynamixel_items_by_name_address_with_units(
    bus: SimDynamixelBus, port: DynamixelPort
) -> None:
    access = ServoParameters.dynamixel(port, 1)
    info = access.parameter("profile_velocity")
    assert access.parameter("Profile Velocity") is info
    assert access.parameter("112") is info
    assert (info.address, info.type, info.unit, info.storage) == (
        "112 (4 bytes)",
        "uint32",
        "rpm",
        "ram",
    )
    with anyio.fail_after(5):
        assert await access.read(info) == 400  # make_servo's profile velocity
        await access.write(info, 123)
        assert await access.read(info) == 123
        homing = access.parameter("Homing Offset")
        await access.write(homing, -100)  # the torque is off: the EEPROM takes it
        assert await access.read(homing) == -100
    assert bus.servos[1].get_raw(homing_item()) == -100
    assert access.parameter("Torque Enable").command
    assert access.parameter("Goal Position").command
    with pytest.raises(BadParameterError, match="Profile Velocity"):
        access.parameter("Profil Velocity")
    assert "Current Limit" not in {
        i.name for i in ServoParameters.dynamixel(port, 1, current=False).parameters()
    }


def homing_item():  # type: ignore[no-untyped-def]
    from openel_serial.dynamixel_table import XSeries

    return XSeries.HOMING_OFFSET


async def test_dynamixel_eeprom_needs_the_torque_off(
    bus: SimDynamixelBus, port: DynamixelPort
) -> None:
    access = ServoParameters.dynamixel(port, 2)
    limit = access.parameter("Velocity Limit")
    assert limit.storage == "eeprom"
    with anyio.fail_after(5):
        await port.write(2, 64, bytes((1,)))  # torque on, as a running machine has it
        blocker = await access.write_blocker(limit)
        assert blocker is not None and "torque" in blocker
        with pytest.raises(BadParameterError, match="torque off"):
            await access.write(limit, 300)
        assert bus.servos[2].torque_enabled  # nothing was changed
        await access.write(limit, 300, unblock=True)  # with consent: torque off, then write
        assert await access.read(limit) == 300
        assert await access.read(access.parameter("Torque Enable")) == 0  # left off
    assert await access.write_blocker(access.parameter("Profile Velocity")) is None


async def test_param_reads_what_dynamixel_sdk_reads_and_writes() -> None:
    """dynamixel-sdk on the simulated bus's pty first (reads Profile Acceleration, writes
    Profile Velocity), then our port: the same values, item for item."""
    async with SimDynamixelBus([make_servo(1, profile_acceleration=77)]) as bus:
        handler = sdk.PortHandler(bus.path)
        packet = sdk.PacketHandler(2.0)
        assert await in_thread(handler.openPort)
        try:
            await in_thread(lambda: handler.setBaudRate(BAUD))
            accel, result, _ = await in_thread(lambda: packet.read4ByteTxRx(handler, 1, 108))
            assert result == sdk.COMM_SUCCESS
            written = await in_thread(lambda: packet.write4ByteTxRx(handler, 1, 112, 55))
            assert written == (sdk.COMM_SUCCESS, 0)
        finally:
            handler.closePort()
        async with DynamixelPort(
            bus.path, baudrate=BAUD, return_delay=0.0, timeout_margin=0.1
        ) as port:
            access = ServoParameters.dynamixel(port, 1)
            with anyio.fail_after(5):
                assert await access.read(access.parameter("Profile Acceleration")) == accel == 77
                assert await access.read(access.parameter("Profile Velocity")) == 55


@pytest.fixture
async def sts() -> AsyncIterator[tuple[SimFeetechBus, FeetechPort]]:
    async with (
        SimFeetechBus([SimStsServo(1)]) as sim,
        FeetechPort(
            sim.path, baudrate=BAUD, return_delay=0.0, timeout_margin=0.1, poll_period=0.005
        ) as port,
    ):
        yield sim, port


async def test_feetech_eeprom_writes_go_through_the_lock(
    sts: tuple[SimFeetechBus, FeetechPort],
) -> None:
    sim, port = sts
    access = ServoParameters.sts(port, 1)
    temperature = access.parameter("max_temperature_limit")
    assert (temperature.address, temperature.storage, temperature.unit) == (
        "13 (1 byte)",
        "eeprom",
        "°C",
    )
    torque = access.parameter("Torque Limit")
    assert (torque.storage, torque.unit, torque.scale) == ("ram", "%", 0.1)
    with anyio.fail_after(5):
        await access.write(temperature, 65)
        assert await access.read(temperature) == 65
        offset = access.parameter("Homing Offset")  # sign-magnitude, bit 11
        await access.write(offset, -12)
        assert await access.read(offset) == -12
    servo = sim.servos[0]
    assert servo.locked  # locked again after the write
    servo.power_cycle()  # kept at power-off: written while unlocked
    assert servo.get(ft.STS.MAX_TEMPERATURE) == 65
    assert servo.get(ft.STS.HOMING_OFFSET) == -12
    assert access.parameter("Lock").command
