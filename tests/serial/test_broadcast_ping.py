"""Dynamixel's broadcast PING (Protocol 2.0, instruction 0x01 to id 0xFE): every servo of the
bus answers in turn. Our port's ``broadcast_ping`` and dynamixel-sdk's ``broadcastPing`` find
the same servos on our simulated bus, and ``scan`` uses one broadcast where it is quicker than
a PING per id (a long id list), one PING per id where not."""

from __future__ import annotations

import dynamixel_sdk as sdk
import pytest

from openel_serial import dynamixel as dx
from openel_serial.peers import SimDynamixelBus
from openel_serial.port import DynamixelPort
from openel_serial.scan import scan

from .conftest import BAUD, in_thread, make_servo

pytestmark = pytest.mark.timeout(30)

IDS = (1, 100, 252)
MARGIN = 0.05


def bus_of_three() -> SimDynamixelBus:
    return SimDynamixelBus([make_servo(i, model_number=1060 if i == 100 else 1020) for i in IDS])


async def test_ours_and_the_sdks_broadcast_ping_find_every_servo() -> None:
    async with bus_of_three() as bus:
        async with DynamixelPort(bus.path, baudrate=BAUD, retries=0) as port:
            ours = await port.broadcast_ping()
        handler = sdk.PortHandler(bus.path)
        assert await in_thread(handler.openPort)
        try:
            assert await in_thread(lambda: handler.setBaudRate(BAUD))
            theirs, result = await in_thread(lambda: sdk.PacketHandler(2.0).broadcastPing(handler))
        finally:
            handler.closePort()
    assert result == sdk.COMM_SUCCESS
    assert sorted(ours) == sorted(theirs) == list(IDS)
    for dxl_id, info in ours.items():
        assert [info.model_number, info.firmware_version] == theirs[dxl_id]
    assert ours[100].model_number == 1060 and ours[1].model_number == 1020


async def test_scan_broadcasts_for_a_long_id_list_and_pings_a_short_one() -> None:
    # A margin of 50 ms, not the CLI's 5: the simulated servos answer from this loaded
    # machine's threads; the choice stays the same (10 PINGs of ~50 ms < one broadcast's
    # ~0.8 s < 253 PINGs).
    async with bus_of_three() as bus:
        long = await scan(bus.path, "dynamixel", (BAUD,), range(0, 253), timeout_margin=MARGIN)
        broadcasts = [m for m in bus.instructions if isinstance(m, dx.Ping)]
        assert broadcasts == [dx.Ping(dx.BROADCAST_ID)]  # one packet found all three
        bus.instructions.clear()
        short = await scan(bus.path, "dynamixel", (BAUD,), range(95, 105), timeout_margin=MARGIN)
        pings = [m for m in bus.instructions if isinstance(m, dx.Ping)]
        assert pings == [dx.Ping(i) for i in range(95, 105)]
    assert [s.servo_id for s in long.servos] == list(IDS)
    assert [s.model for s in long.servos] == ["XM430-W350", "XL430-W250", "XM430-W350"]
    assert [s.servo_id for s in short.servos] == [100]
