"""EDS, PDO maps and NMT against canopen-py, an independent CANopen implementation.

(a) canopen's ``LocalNode`` loaded from the shipped EDS, on python-can ``virtual``: OUR
    :func:`~openel_can.pdomap.configure_pdos` and SDO client map it for cyclic
    synchronous position, OUR NMT starts it; its TPDOs (sent on OUR SYNC) decode on our
    side and OUR RPDO lands in its object dictionary.
(b) canopen's ``RemoteNode`` loaded from the same EDS masters OUR simulated drive
    (:class:`~openel_can.sim.cia402.SimCia402Drive`) with its own ``pdo`` and ``sync``
    tooling: reads the dictionary by SDO, remaps and saves the PDOs, starts the node,
    produces SYNC, receives TPDOs and drives the CiA 402 state machine through a
    profile-position move by its RPDO -- on ``virtual`` and
(c) (a) and (b) through python-can's ``slcan`` interface on a pty, against our
    simulated slcan adapter (:class:`~openel_can.sim.slcan.SlcanAdapter`): our host bus
    on the pty and canopen's LocalNode on the adapter's CAN side; canopen's master on the
    pty and our drive hosted by the adapter.

canopen runs its own bus and notifier thread; its blocking calls run in a worker thread.
Every wait is bounded (canopen's SDO response timeout, ``wait_for_reception`` timeouts,
``fail_after``, polling deadlines).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from typing import Any, TypeVar

import anyio
import canopen
import pytest
from canopen.pdo.base import PdoMap

from openel_can import CanBus, SdoClient
from openel_can import canopen as co
from openel_can import cia402 as ds
from openel_can.od import SHIPPED_EDS, load_od
from openel_can.pdomap import configure_pdos, default_pdos
from openel_can.sim.cia402 import SimCia402Drive
from openel_can.sim.slcan import SlcanAdapter

from .conftest import Peers, canopen_network, in_thread, through_slcan

T = TypeVar("T")
NODE = 5
PS = ds.PowerState


@pytest.fixture
def network(channel: str) -> Iterator[canopen.Network]:
    with canopen_network(interface="virtual", channel=channel, receive_own_messages=False) as net:
        yield net


# -- (a) our master, canopen's LocalNode ------------------------------------------------------
class _LocalDrive:
    """Glue a device application would be: applies received RPDOs to the node's object
    dictionary and, on each SYNC, sends the synchronous TPDOs from it (canopen-py leaves
    both to the application)."""

    def __init__(self, node: canopen.LocalNode, network: canopen.Network) -> None:
        self.node = node
        self.network = network
        self.syncs = 0
        self.lock = threading.Lock()

    def start(self) -> None:
        """After NMT start: the PDO configuration the master wrote, from the node's own OD."""
        self.node.tpdo.read()
        self.node.rpdo.read()
        for rpdo in self.node.rpdo.map.values():
            if rpdo.enabled:
                rpdo.add_callback(self._apply)
        self.network.subscribe(co.SYNC_COB_ID, self._on_sync)

    def _apply(self, rpdo: PdoMap) -> None:
        for var in rpdo:
            self.node.set_data(var.index, var.subindex, var.get_data())

    def _on_sync(self, can_id: int, data: bytearray, timestamp: float) -> None:
        with self.lock:
            self.syncs += 1
        for tpdo in self.node.tpdo.map.values():
            if tpdo.enabled and tpdo.trans_type is not None and 1 <= tpdo.trans_type <= 240:
                for var in tpdo:
                    var.set_data(self.node.get_data(var.index, var.subindex))
                tpdo.transmit()


async def test_our_master_maps_and_starts_a_canopen_local_node(
    network: canopen.Network, host_bus: CanBus
) -> None:
    await _our_master(network, host_bus)


async def test_our_master_through_slcan_maps_and_starts_a_canopen_local_node() -> None:
    await through_slcan(_our_master)


async def _our_master(network: canopen.Network, host_bus: CanBus) -> None:
    local = canopen.LocalNode(NODE, str(SHIPPED_EDS))
    network.add_node(local)
    local.nmt.state = "PRE-OPERATIONAL"
    glue = _LocalDrive(local, network)
    od = load_od(SHIPPED_EDS, node_id=NODE)
    sdo = SdoClient(host_bus, NODE, timeout=0.5, od=od)
    with anyio.fail_after(10):
        assert await sdo.read("Manufacturer device name") == "OpenEL servo 402"
        rpdo1, tpdo1, tpdo2 = await configure_pdos(sdo, default_pdos("csp"))
    # canopen's node holds what we wrote (its SDO server's data store).
    assert local.sdo[0x1600][2].raw == 0x607A_0020 and local.sdo[0x1A00][0].raw == 3
    assert local.sdo[0x1800][1].raw == 0x185 and local.sdo[0x1400][2].raw == 1
    assert local.sdo[0x1401][1].raw & co.PDO_COB_ID_INVALID  # unused: disabled

    port = host_bus.attach([tpdo1.cob_id, tpdo2.cob_id], name="test-tpdos")
    try:
        await port.send(*co.encode(co.NmtControl(co.NmtCommand.START, NODE)))
        deadline = time.monotonic() + 2
        while local.nmt.state != "OPERATIONAL":
            assert time.monotonic() < deadline, local.nmt.state
            await anyio.sleep(0.001)
        await in_thread(glue.start)
        # The application's values, then our SYNC: TPDO1 and TPDO2 answer it.
        for name, value in [
            ("Statusword", 0x0237),
            ("Position actual value", -123_456),
            ("Torque actual value", -17),
            ("Velocity actual value", 4321),
            ("Modes of operation display", 8),
        ]:
            entry = od[name]
            local.set_data(entry.index, entry.subindex, entry.encode(value))
        got: dict[int, dict[str, int]] = {}
        with anyio.fail_after(2):
            await port.send(*co.encode(co.Sync()))
            while len(got) < 1:
                for frame in await port.receive():
                    pdo = tpdo1 if frame.arbitration_id == tpdo1.cob_id else tpdo2
                    got[frame.arbitration_id] = pdo.unpack(frame.data)
        assert got[0x185] == {
            "Statusword": 0x0237,
            "Position actual value": -123_456,
            "Torque actual value": -17,
        }
        # TPDO2 (statusword, mode display) is event-driven in the cyclic modes.
        assert [e.name for e in tpdo2.entries] == ["Statusword", "Modes of operation display"]
        assert local.sdo[0x1801][2].raw == 0xFF and tpdo2.transmission_type == 0xFF
        # Our RPDO1 (controlword + target position) lands in canopen's object dictionary.
        await port.send(
            rpdo1.cob_id, rpdo1.pack({"Controlword": 0x000F, "Target position": -987_654})
        )
        deadline = time.monotonic() + 2
        while local.sdo["Target position"].raw != -987_654:
            assert time.monotonic() < deadline
            await anyio.sleep(0.001)
        assert local.sdo["Controlword"].raw == 0x000F
    finally:
        port.close()


# -- (b), (c) canopen's RemoteNode masters our simulated drive ---------------------------------
def _wait(predicate: Callable[[], bool], what: str, timeout: float = 2.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise TimeoutError(f"canopen master: {what}")
        time.sleep(0.002)


def _master_profile_position(
    network: canopen.Network, remote: canopen.RemoteNode
) -> dict[str, Any]:
    """What a canopen-py user writes to run a CiA 402 drive: blocking, in a thread."""
    out: dict[str, Any] = {}
    # The dictionary by SDO (expedited and segmented).
    out["name"] = remote.sdo["Manufacturer device name"].raw
    out["vendor"] = remote.sdo["Identity object"]["Vendor-ID"].raw
    out["modes"] = remote.sdo["Supported drive modes"].raw
    remote.nmt.state = "PRE-OPERATIONAL"
    # Remap with canopen's pdo tooling: read the drive's configuration, change it, save.
    remote.tpdo.read()
    remote.rpdo.read()
    rpdo = remote.rpdo[1]
    rpdo.clear()
    rpdo.add_variable("Controlword")
    rpdo.add_variable("Target position")
    rpdo.trans_type = 0xFF
    rpdo.enabled = True
    tpdo = remote.tpdo[1]
    tpdo.clear()
    tpdo.add_variable("Statusword")
    tpdo.add_variable("Position actual value")
    tpdo.trans_type = 1  # every SYNC
    tpdo.enabled = True
    remote.tpdo[2].clear()
    remote.tpdo[2].add_variable("Velocity actual value")
    remote.tpdo[2].trans_type = 2  # every second SYNC
    remote.tpdo[2].enabled = True
    remote.rpdo.save()
    remote.tpdo.save()
    out["map"] = [remote.sdo[0x1A00][s].raw for s in range(3)]
    remote.nmt.state = "OPERATIONAL"
    network.sync.start(0.005)
    tpdo.wait_for_reception(timeout=1)
    remote.tpdo[2].wait_for_reception(timeout=1)

    def statusword() -> int:
        return int(tpdo["Statusword"].raw)

    def state() -> PS:
        return ds.state_from_statusword(statusword())

    def command(word: int) -> None:
        rpdo["Controlword"].raw = word
        rpdo.transmit()

    _wait(lambda: state() is PS.SWITCH_ON_DISABLED, "switch on disabled")
    for word, target in (
        (0x06, PS.READY_TO_SWITCH_ON),
        (0x07, PS.SWITCHED_ON),
        (0x0F, PS.OPERATION_ENABLED),
    ):
        command(word)
        _wait(lambda t=target: state() is t, f"{target.name} after {word:#x}")  # type: ignore[misc]
    out["states"] = "enabled"
    # Profile position by RPDO: target, new set-point, acknowledge, target reached.
    rpdo["Target position"].raw = 5_000
    command(0x1F)
    _wait(lambda: bool(statusword() & ds.StatusBit.SETPOINT_ACKNOWLEDGE), "set-point acknowledge")
    command(0x0F)
    _wait(
        lambda: (
            bool(statusword() & ds.StatusBit.TARGET_REACHED)
            and tpdo["Position actual value"].raw == 5_000
        ),
        "target reached",
        timeout=3,
    )
    out["position"] = tpdo["Position actual value"].raw
    out["periods"] = (tpdo.period, remote.tpdo[2].period)
    network.sync.stop()
    return out


def _check(out: dict[str, Any], sim: SimCia402Drive) -> None:
    assert out["name"] == "OpenEL servo 402" and out["vendor"] == 0x0E1A
    assert out["modes"] == 0b11_1000_1101  # pp pv tq csp csv cst
    assert out["map"] == [2, 0x6041_0010, 0x6064_0020]
    assert out["position"] == 5_000 and round(sim.position) == 5_000
    assert sim.power_state is PS.OPERATION_ENABLED and sim.nmt_state is co.NmtState.OPERATIONAL
    assert sim.od[(0x1600, 2)].value == 0x607A_0020 and sim.od[(0x1801, 2)].value == 2
    tpdo1_period, tpdo2_period = out["periods"]
    assert tpdo1_period is not None and tpdo2_period is not None
    assert tpdo2_period > tpdo1_period  # TPDO2 on every second SYNC


async def test_canopen_master_runs_our_simulated_drive(
    peers: Peers, network: canopen.Network
) -> None:
    sim = await peers.start(SimCia402Drive(NODE, heartbeat_ms=0))
    remote = canopen.RemoteNode(NODE, str(SHIPPED_EDS))
    network.add_node(remote)
    out = await in_thread(lambda: _master_profile_position(network, remote))
    _check(out, sim)


async def test_canopen_master_through_slcan_runs_our_simulated_drive() -> None:
    sim = SimCia402Drive(NODE, heartbeat_ms=0)
    with SlcanAdapter(peers=[sim]) as adapter:
        with canopen_network(
            interface="slcan", channel=adapter.port, bitrate=1_000_000, sleep_after_open=0
        ) as net:
            remote = canopen.RemoteNode(NODE, str(SHIPPED_EDS))
            net.add_node(remote)
            out = await in_thread(lambda: _master_profile_position(net, remote), limit=20)
        _check(out, sim)
    assert adapter.stats.errors == 0
