"""SDO against canopen-py, an independent CANopen implementation, on python-can ``virtual``.

* canopen's SDO **server** (``canopen.LocalNode``) with a 64-bit, a string and a 16-bit
  object; OUR :class:`~openel_can.sdo.SdoClient` uploads and downloads them, expedited
  and segmented.
* canopen's SDO **client** (``RemoteNode``) against OUR simulated CiA 402 drive:
  expedited, expedited without size, segmented both ways, block transfer refused with
  abort 0x05040001.

canopen runs its own bus and notifier thread; its blocking client calls run in a worker
thread. Every wait is bounded (canopen's own 0.3 s response timeout, ``fail_after``).
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Iterator
from typing import Any, TypeVar

import anyio
import canopen
import pytest
from canopen import objectdictionary as cod
from canopen.sdo import SdoAbortedError
from canopen.sdo import constants as sc

from openel_async import ComponentState
from openel_can import CanBus, Cia402Drive, SdoAbortError, SdoClient
from openel_can import canopen as co
from openel_can.sim.cia402 import ENERGY_LIMIT, OPERATING_TIME, SimCia402Drive

from .conftest import Components, Peers, canopen_network

T = TypeVar("T")
NODE = 5
NAME = "openel-async interop: a segmented string"


def _var(name: str, index: int, data_type: int, default: Any) -> cod.ODVariable:
    var = cod.ODVariable(name, index, 0)
    var.data_type = data_type
    var.access_type = "rw"
    var.default = default
    return var


@pytest.fixture
def network(channel: str) -> Iterator[canopen.Network]:
    with canopen_network(interface="virtual", channel=channel, receive_own_messages=False) as net:
        yield net


@pytest.fixture
def local_node(network: canopen.Network) -> canopen.LocalNode:
    od = cod.ObjectDictionary()
    od.add_object(_var("u64", 0x2000, cod.UNSIGNED64, 0x0123_4567_89AB_CDEF))
    od.add_object(_var("name", 0x2001, cod.VISIBLE_STRING, NAME))
    od.add_object(_var("u16", 0x2002, cod.UNSIGNED16, 0x1234))
    od.add_object(_var("i64", 0x2003, cod.INTEGER64, -5))
    node = canopen.LocalNode(NODE, od)
    network.add_node(node)
    return node


async def _in_thread(fn: Callable[[], T]) -> T:
    with anyio.fail_after(5):
        return await anyio.to_thread.run_sync(fn)


# -- our client, canopen's server -----------------------------------------------------------
async def test_our_client_uploads_from_canopen_server(
    host_bus: CanBus, local_node: canopen.LocalNode
) -> None:
    client = SdoClient(host_bus, NODE, timeout=0.5)
    u64 = co.ObjectEntry(0x2000, 0, co.DataType.UNSIGNED64)
    with anyio.fail_after(5):
        assert await client.read(u64) == 0x0123_4567_89AB_CDEF  # segmented: 8 bytes
        assert await client.upload(0x2001, 0) == NAME.encode()  # segmented: 40 bytes
        assert await client.read(co.ObjectEntry(0x2002, 0, co.DataType.UNSIGNED16)) == 0x1234
        assert await client.read(co.ObjectEntry(0x2003, 0, co.DataType.INTEGER64)) == -5
        with pytest.raises(SdoAbortError) as refused:
            await client.upload(0x2FFF, 0)
    assert refused.value.abort_code == co.SdoAbortCode.OBJECT_DOES_NOT_EXIST
    assert client.timeouts == 0 and client.segments == 2 + 6 + 2


async def test_our_client_downloads_to_canopen_server(
    host_bus: CanBus, local_node: canopen.LocalNode
) -> None:
    client = SdoClient(host_bus, NODE, timeout=0.5)
    with anyio.fail_after(5):
        await client.write(co.ObjectEntry(0x2000, 0, co.DataType.UNSIGNED64), 2**64 - 2)
        await client.write(co.ObjectEntry(0x2003, 0, co.DataType.INTEGER64), -(2**63))
        await client.download(0x2001, 0, b"fourteen bytes")  # 7 + 7: last segment full
        await client.write(co.ObjectEntry(0x2002, 0, co.DataType.UNSIGNED16), 0xBEEF)
    assert local_node.data_store[0x2000][0] == struct.pack("<Q", 2**64 - 2)
    assert local_node.data_store[0x2003][0] == struct.pack("<q", -(2**63))
    assert local_node.data_store[0x2001][0] == b"fourteen bytes"
    assert local_node.data_store[0x2002][0] == b"\xef\xbe"
    assert local_node.sdo[0x2000].raw == 2**64 - 2  # canopen reads what it stored


# -- canopen's client, our simulated drive --------------------------------------------------
def _drive_od() -> cod.ObjectDictionary:
    od = cod.ObjectDictionary()
    od.add_object(_var("operating time", OPERATING_TIME.index, cod.UNSIGNED64, 0))
    od.add_object(_var("energy limit", ENERGY_LIMIT.index, cod.INTEGER64, 0))
    od.add_object(_var("quick stop option", 0x605A, cod.INTEGER16, 0))
    od.add_object(_var("statusword", 0x6041, cod.UNSIGNED16, 0))
    return od


@pytest.fixture
def remote(network: canopen.Network) -> canopen.RemoteNode:
    node = canopen.RemoteNode(NODE, _drive_od())
    network.add_node(node)
    return node


async def test_canopen_client_against_sim_expedited_and_segmented(
    peers: Peers, remote: canopen.RemoteNode
) -> None:
    sim = await peers.start(SimCia402Drive(NODE))

    def talk() -> tuple[int, int, int]:
        statusword = remote.sdo[0x6041].raw  # expedited upload
        uptime = remote.sdo[OPERATING_TIME.index].raw  # segmented upload (0x41 + 2 segments)
        remote.sdo[ENERGY_LIMIT.index].raw = -(2**62) - 7  # segmented download
        energy = remote.sdo[ENERGY_LIMIT.index].raw
        # Segmented download of a 2-byte object (forced): the sim must accept that too.
        remote.sdo.download(0x605A, 0, b"\x01\x00", force_segment=True)
        return statusword, uptime, energy

    statusword, uptime, energy = await _in_thread(talk)
    assert statusword == sim.statusword()
    assert 0 < uptime < 60_000_000  # µs since the sim booted, read as one u64
    assert energy == -(2**62) - 7 and sim.od[(ENERGY_LIMIT.index, 0)].value == energy
    assert sim.od[(0x605A, 0)].value == 1


async def test_sim_accepts_expedited_download_without_size(
    peers: Peers, remote: canopen.RemoteNode
) -> None:
    """CiA 301: 0x22 (expedited, size not indicated) writes the object's own size."""
    sim = await peers.start(SimCia402Drive(NODE))
    request = bytes((sc.REQUEST_DOWNLOAD | sc.EXPEDITED,)) + struct.pack("<HB", 0x605A, 0)
    response = await _in_thread(lambda: remote.sdo.request_response(request + b"\x03\x00\xaa\xbb"))
    assert response[0] == sc.RESPONSE_DOWNLOAD
    assert struct.unpack_from("<HB", response, 1) == (0x605A, 0)
    assert sim.od[(0x605A, 0)].value == 3


@pytest.mark.parametrize("mode", ["rb", "wb"])
async def test_sim_refuses_block_transfer_with_an_abort(
    peers: Peers, remote: canopen.RemoteNode, mode: str
) -> None:
    sim = await peers.start(SimCia402Drive(NODE))
    before = sim.od[(ENERGY_LIMIT.index, 0)].value

    def block() -> None:
        with remote.sdo.open(ENERGY_LIMIT.index, 0, mode, size=8, block_transfer=True) as f:
            if mode == "wb":
                f.write(bytes(8))

    with pytest.raises(SdoAbortedError) as aborted:
        await _in_thread(block)
    assert aborted.value.code == co.SdoAbortCode.INVALID_COMMAND_SPECIFIER == 0x0504_0001
    assert sim.od[(ENERGY_LIMIT.index, 0)].value == before
    # The server is not left in a half-open transfer: a normal access works at once.
    assert await _in_thread(lambda: remote.sdo[ENERGY_LIMIT.index].raw) == before


async def test_sdo_abort_codes_agree_with_canopen() -> None:
    """Our abort-code table against canopen's constants, for the codes both name."""
    pairs = {
        "ABORT_TOGGLE_NOT_ALTERNATED": co.SdoAbortCode.TOGGLE_BIT_NOT_ALTERNATED,
        "ABORT_TIMED_OUT": co.SdoAbortCode.TIMEOUT,
        "ABORT_INVALID_COMMAND_SPECIFIER": co.SdoAbortCode.INVALID_COMMAND_SPECIFIER,
        "ABORT_NOT_IN_OD": co.SdoAbortCode.OBJECT_DOES_NOT_EXIST,
        "ABORT_GENERAL_ERROR": co.SdoAbortCode.GENERAL_ERROR,
    }
    for name, ours in pairs.items():
        assert getattr(sc, name) == ours, name


# -- the component stays healthy on a 64-bit object ------------------------------------------
async def test_drive_component_reads_and_writes_64_bit_objects(
    peers: Peers, host_bus: CanBus, components: Components
) -> None:
    """Before: the segmented answer was garbage, the client timed out, aborted 0x05040000
    and the component went to Error; writing leaked a bare ValueError."""
    await peers.start(SimCia402Drive(NODE))
    axis = await components.actuator(Cia402Drive(host_bus, NODE, heartbeat_ms=50))
    device = axis.device
    assert isinstance(device, Cia402Drive)
    with anyio.fail_after(5):
        assert await device.sdo.read(OPERATING_TIME) > 0
        await device.sdo.write(ENERGY_LIMIT, 2**63 - 1)
        assert await device.sdo.read(ENERGY_LIMIT) == 2**63 - 1
    assert axis.state is ComponentState.ACTIVE
    assert device.sdo.timeouts == 0
