"""``openel-async param``'s CAN side in process: a CiA 402 drive's objects by SDO, checked
against canopen-py (a ``LocalNode`` loaded from the same EDS answers our reads; what we
write lands in its dictionary), and an ODrive's endpoints by RxSdo/TxSdo against the
simulated ODrive."""

from __future__ import annotations

import math
import struct
from collections.abc import Iterator

import anyio
import canopen
import pytest

from openel_async.errors import BadParameterError
from openel_can import CanBus
from openel_can.od import SHIPPED_EDS, load_od
from openel_can.odrive import VEL_RAMP_RATE_ENDPOINT, WATCHDOG_TIMEOUT_ENDPOINT
from openel_can.odrive_endpoints import ENDPOINTS
from openel_can.params402 import CanOpenParameters
from openel_can.params_odrive import ODriveParameters
from openel_can.sim.odrive import SimODrive

from .conftest import Peers, canopen_network

NODE = 5


@pytest.fixture
def local_node(channel: str) -> Iterator[canopen.LocalNode]:
    with canopen_network(interface="virtual", channel=channel, receive_own_messages=False) as net:
        node = canopen.LocalNode(NODE, str(SHIPPED_EDS))
        net.add_node(node)
        yield node


async def test_every_object_reads_as_canopen_py_uploads_it(
    local_node: canopen.LocalNode, host_bus: CanBus
) -> None:
    """Each object our param read returns equals canopen-py's SDO upload of it from a
    LocalNode loaded from the same EDS (decoded by canopen-py's own ODVariable)."""
    access = CanOpenParameters(host_bus, NODE, load_od(SHIPPED_EDS, node_id=NODE), "test")
    compared = 0
    with anyio.fail_after(10):
        for info in access.parameters():
            if not info.readable:
                continue
            index, sub = (int(part, 16) for part in info.address.split(":"))
            try:
                raw = local_node.sdo.upload(index, sub)
            except canopen.SdoAbortedError:
                continue  # canopen-py holds no value for it (a domain...)
            variable = (
                local_node.sdo[index]
                if sub == 0 and not _is_record(local_node, index)
                else local_node.sdo[index][sub]
            )
            expected = variable.od.decode_raw(raw)
            got = await access.read(info)
            if isinstance(expected, float):
                assert math.isclose(got, expected, rel_tol=1e-6), info  # type: ignore[arg-type]
            else:
                assert got == expected, info
            compared += 1
    assert compared > 100


def _is_record(node: canopen.LocalNode, index: int) -> bool:
    return not isinstance(node.object_dictionary[index], canopen.objectdictionary.ODVariable)


async def test_a_write_lands_in_canopen_pys_dictionary(
    local_node: canopen.LocalNode, host_bus: CanBus
) -> None:
    access = CanOpenParameters(host_bus, NODE, load_od(SHIPPED_EDS, node_id=NODE), "test")
    info = access.parameter("Profile velocity")
    assert (info.address, info.type, info.access, info.unit) == (
        "0x6081:00",
        "UNSIGNED32",
        "rw",
        "inc/s",
    )
    assert access.parameter("6081") is info
    assert access.parameter("0x6081:0") is info
    assert access.parameter("PROFILE VELOCITY") is info
    with anyio.fail_after(5):
        await access.write(info, 12345)
        assert local_node.sdo[0x6081].raw == 12345
        assert await access.read(info) == 12345


def test_names_close_matches_commands_and_storage() -> None:
    od = load_od(SHIPPED_EDS, node_id=NODE)
    access = CanOpenParameters.__new__(CanOpenParameters)
    CanOpenParameters.__init__(access, _NoBus(), NODE, od, "test")  # type: ignore[arg-type]
    with pytest.raises(BadParameterError, match="Profile velocity"):
        access.parameter("Profile velocty")
    with pytest.raises(BadParameterError, match="sub-ind"):
        access.parameter("0x1018")  # a record: the dictionary names its sub-indices
    assert access.parameter("Controlword").command
    assert access.parameter("Target position").command
    assert access.parameter("Statusword").storage == "volatile"
    assert not any(i.address.startswith("0x000") for i in access.parameters())


class _NoBus(CanBus):
    """A bus never opened: the table is built without one."""

    def __init__(self) -> None:
        pass


async def test_odrive_endpoints_read_and_write_the_simulated_odrive(
    peers: Peers, host_bus: CanBus
) -> None:
    sim = await peers.start(SimODrive(3, vel_ramp_rate=7.5))
    access = ODriveParameters(host_bus, 3)
    ramp = access.parameter("axis0.controller.config.vel_ramp_rate")
    assert (ramp.address, ramp.type, ramp.unit) == (
        f"endpoint {VEL_RAMP_RATE_ENDPOINT}",
        "float",
        "turns/s²",
    )
    assert access.parameter("controller.config.vel_ramp_rate") is ramp  # axis0. left out
    assert access.parameter(str(VEL_RAMP_RATE_ENDPOINT)) is ramp
    with anyio.fail_after(5):
        assert await access.read(ramp) == 7.5
        timeout = access.parameter("axis0.config.watchdog_timeout")
        assert timeout.address == f"endpoint {WATCHDOG_TIMEOUT_ENDPOINT}"
        await access.write(timeout, 0.25)
        assert await access.read(timeout) == 0.25
        assert sim.watchdog_timeout == 0.25
        node_id = access.parameter("axis0.config.can.node_id")
        assert await access.read(node_id) == 3
        bandwidth = access.parameter("axis0.controller.config.input_filter_bandwidth")
        await access.write(bandwidth, 20.0)
        assert await access.read(bandwidth) == 20.0
        assert struct.unpack("<f", sim.endpoint_values[401])[0] == 20.0
        enable = access.parameter("axis0.config.enable_watchdog")
        await access.write(enable, True)
        assert await access.read(enable) is True
    assert access.parameter("axis0.requested_state").command
    with pytest.raises(BadParameterError, match="vel_limit"):
        access.parameter("vel_limt")


def test_the_endpoint_table() -> None:
    ids = [e.id for e in ENDPOINTS]
    assert ids == sorted(set(ids))
    names = {e.name: e for e in ENDPOINTS}
    assert names["axis0.controller.config.vel_ramp_rate"].id == VEL_RAMP_RATE_ENDPOINT
    assert names["axis0.config.watchdog_timeout"].id == WATCHDOG_TIMEOUT_ENDPOINT
    assert names["axis0.config.enable_watchdog"].type == "bool"
    assert len(ENDPOINTS) > 200
